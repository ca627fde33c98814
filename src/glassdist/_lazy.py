"""Public names of a package that load on first use (PEP 562).

A package ``__init__`` that re-exports names from heavy submodules makes every import of
the package pay for them: ``glassdist --help``, a refused input and each batch pane's
child process would load the analysis, plotting and database stacks they never touch.
"""

from __future__ import annotations

import importlib
import threading

__all__ = ["lazy_exports", "import_in_background", "wait_background_imports"]

_THREADS: list[threading.Thread] = []


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


def import_in_background(*modules: str) -> threading.Thread:
    """Import ``modules`` in a daemon thread while the caller goes on (its numpy, OpenCV and FFT calls
    release the GIL, so the imports run on another core); returns the thread.

    For third-party stacks that the caller's next steps do not import (matplotlib's figure
    stack, SQLAlchemy) and leaf modules of glassdist's own that import nothing else of
    glassdist: two threads importing one module take turns on its import lock, and import
    cycles across the two threads are thereby kept out. A module that fails to import here
    is left alone; the caller's own import of it raises as it would have.
    """

    def run() -> None:
        for name in modules:
            try:
                importlib.import_module(name)
            except BaseException:  # noqa: BLE001 - the caller's own import reports it
                return

    thread = threading.Thread(target=run, name="glassdist-imports", daemon=True)
    thread.start()
    _THREADS.append(thread)
    return thread


def wait_background_imports() -> None:
    """Wait for the imports :func:`import_in_background` started (before a fork: a module lock a thread holds
    at that moment would be held for ever in the child)."""
    while _THREADS:
        _THREADS.pop().join()
