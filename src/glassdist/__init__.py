"""glassdist: see-through optical distortion of architectural glass.

Measure, from a photograph of a printed grid seen through a pane, the apparent
displacement of the grid and its two optical-power channels (sphere-equivalent
power phi_eff and cylinder-equivalent astigmatism phi_shear, in millidiopters).

Conventions (used everywhere in the package)
--------------------------------------------
* Images are indexed ``(row, col)``; ``x`` runs along columns (left to right),
  ``y`` along rows (top to bottom).
* Lengths are in mm, the glass-to-backdrop distance ``L`` in m, optical power in mD.
* Displacement ``delta(pixel)`` = point where that pixel's line of sight lands on
  the backdrop with the glass minus where it lands without it, in backdrop mm,
  components ``[..., 0] = x``, ``[..., 1] = y``.
* ``phi_eff = tr(eps) / L`` with ``eps = sym(grad delta)`` taken with respect to
  backdrop mm: a converging lens reads ``phi_eff < 0``.
"""

import logging
from typing import TYPE_CHECKING

from ._lazy import lazy_exports
from ._version import __version__

# A library prints nothing: its warnings are on the results, its log records go to the
# handlers the application configures (the command line's), never to logging's
# last-resort handler on stderr.
logging.getLogger(__name__).addHandler(logging.NullHandler())

# Public names and the module that holds each. They load on first use (PEP 562), so that
# ``glassdist --help``, a refused input and each batch pane's process do not pay for
# the analysis, plotting and database stacks they never touch.
_HOMES = {
    "AnalysisResult": ".analyzer",
    "AnalyzerParams": ".analyzer",
    "analyze": ".analyzer",
    "analyze_reflection": ".analyzer",
    "ReflectionGeometry": ".analyzer",
    "analyze_captures": ".analyzer",
    "channel_statistics": ".analyzer",
    "evaluate_displacement": ".analyzer",
    "load_params": ".analyzer",
    "prepare_reference": ".analyzer",
    "evaluate_spec": "._api",
    "write_report": "._api",
    "view": "._api",
    "compare": "._api",
    "AnalysisError": ".errors",
    "GlassdistError": ".errors",
    "InputError": ".errors",
    "read_image": ".io",
    "read_mask": ".io",
    "load_result": ".storage",
    "write_outputs": ".storage",
}


# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from ._api import compare, evaluate_spec, view, write_report
    from .analyzer import (
        AnalysisResult,
        AnalyzerParams,
        ReflectionGeometry,
        analyze,
        analyze_captures,
        analyze_reflection,
        channel_statistics,
        evaluate_displacement,
        load_params,
        prepare_reference,
    )
    from .errors import AnalysisError, GlassdistError, InputError
    from .io import read_image, read_mask
    from .storage import load_result, write_outputs
# --- end of the typed names ---

_lazy_getattr, _lazy_dir = lazy_exports(__name__, _HOMES)


def __getattr__(name):
    # ``glassdist.history`` is the subpackage, itself callable as the function that reads the runs
    # (``glassdist.history(lot="42")``): one object whether it is reached by attribute or by
    # ``import glassdist.history.store``, loaded on first use like every other public name
    if name == "history":
        import importlib

        return importlib.import_module(".history", __name__)
    return _lazy_getattr(name)


def __dir__():
    return sorted({*_lazy_dir(), "history"})

__all__ = [
    "history",
    "write_outputs",
    "load_result",
    "__version__",
    "analyze",
    "analyze_reflection",
    "ReflectionGeometry",
    "analyze_captures",
    "evaluate_spec",
    "write_report",
    "view",
    "compare",
    "prepare_reference",
    "AnalysisResult",
    "AnalyzerParams",
    "load_params",
    "evaluate_displacement",
    "channel_statistics",
    "read_image",
    "read_mask",
    "GlassdistError",
    "InputError",
    "AnalysisError",
]
