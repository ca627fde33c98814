"""Public names of a package that load on first use (PEP 562).

A package ``__init__`` that re-exports names from heavy submodules makes every import of
the package pay for them: ``glassdist --help``, a refused input and each batch pane's
child process would load the analysis, plotting and database stacks they never touch.
"""

from __future__ import annotations

import importlib

__all__ = ["lazy_exports"]


def lazy_exports(package: str, homes: dict[str, str]):
    """``(__getattr__, __dir__)`` for ``package`` whose public name ``n`` lives in module ``homes[n]``.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    homes : dict
        ``{public name: module}``, the module relative to the package (``".batch"``);
        ``".region:LABELS"`` exports the module's ``LABELS`` under the public name.

    Returns
    -------
    (callable, callable)
        Assign them to the package's ``__getattr__`` and ``__dir__``. A name is imported on
        first access and then kept in the package's namespace as a plain attribute.

    Notes
    -----
    Static tools do not run ``__getattr__``: each package also imports its lazy names under
    ``if TYPE_CHECKING:``, written from ``homes`` by ``scripts/lazy_stubs.py`` (and checked
    by ``tests/test_code_layout.py``), so that an IDE and mypy see the typed public API.
    """
    namespace = importlib.import_module(package).__dict__
    # kept for ``scripts/lazy_stubs.py`` and the test that the package's ``TYPE_CHECKING`` imports
    # (what an IDE and mypy see) name exactly these homes
    namespace["_LAZY_HOMES"] = dict(homes)

    def __getattr__(name):
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module, _, attr = home.partition(":")
        value = getattr(importlib.import_module(module, package), attr or name)
        namespace[name] = value
        return value

    def __dir__():
        return sorted(set(namespace) | set(homes))

    return __getattr__, __dir__
