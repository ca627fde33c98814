"""Every ``Examples`` section of the package runs (doctest): the documented calls keep working.

All modules of ``glassdist`` are collected; one whose import needs an optional extra that
is not installed is skipped. Any other ImportError (a broken import inside glassdist, a
missing core dependency) fails. The examples run with ``ELLIPSIS`` and ``NORMALIZE_WHITESPACE``.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil
import sys

import pytest

import glassdist

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE

#: Entry points whose docstrings must carry a runnable example ("module:name").
DOCUMENTED = [
    "glassdist:analyze",
    "glassdist.analyzer.fourier:find_carriers",
    "glassdist.analyzer.params:load_params",
    "glassdist.io:read_image",
    "glassdist.scene.model:load_scene",
    "glassdist.render:render_scene",
    "glassdist.render.tracer:landing_points",
    "glassdist.theory.model:predict_displacement",
]


def _modules() -> list[str]:
    found = [info.name for info in pkgutil.walk_packages(glassdist.__path__, "glassdist.")]
    return ["glassdist"] + sorted(n for n in found if not n.endswith(".__main__"))


#: Top-level modules of the optional extras (pyproject.toml: distributed, web, browser-tests).
OPTIONAL = {"dask", "distributed", "fastapi", "uvicorn", "multipart", "python_multipart", "jinja2", "playwright"}


def _import(name: str):
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if (exc.name or "").split(".")[0] in OPTIONAL:  # an optional extra not installed
            pytest.skip(f"{name} needs what is not installed: {exc}")
        raise


def test_a_broken_import_inside_glassdist_is_not_a_skip(monkeypatch):
    """A module of glassdist that fails to import fails the test, rather than skipping it."""
    monkeypatch.setitem(sys.modules, "glassdist._broken_for_test", None)  # importing it raises ImportError
    with pytest.raises(ImportError):
        _import("glassdist._broken_for_test")
    monkeypatch.setitem(sys.modules, "playwright", None)
    with pytest.raises(pytest.skip.Exception):
        _import("playwright")


@pytest.mark.parametrize("name", _modules())
def test_examples_run(name):
    module = _import(name)
    runner = doctest.DocTestRunner(optionflags=FLAGS)
    for test in doctest.DocTestFinder(exclude_empty=True).find(module, name):
        runner.run(test)  # failures are printed with the example and what it returned
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed (see the output)"


@pytest.mark.parametrize("entry", DOCUMENTED)
def test_entry_points_have_examples(entry):
    module, attr = entry.split(":")
    doc = getattr(_import(module), attr).__doc__ or ""
    assert "Examples\n" in doc and ">>>" in doc, f"{entry} has no runnable Examples section"
