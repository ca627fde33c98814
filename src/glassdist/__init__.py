"""glassdist: see-through optical distortion of architectural glass.

Measure, from a photograph of a printed grid seen through a pane, the apparent
displacement of the grid and its two optical-power channels (sphere-equivalent
power phi_eff and cylinder-equivalent astigmatism phi_shear, in millidiopters).

Conventions (used everywhere in the package)
-------------------------------------------
* Images are indexed ``(row, col)``; ``x`` runs along columns (left to right),
  ``y`` along rows (top to bottom).
* Lengths are in mm, the glass-to-backdrop distance ``L`` in m, optical power in mD.
* Displacement ``delta(pixel)`` = point where that pixel's line of sight lands on
  the backdrop with the glass minus where it lands without it, in backdrop mm,
  components ``[..., 0] = x``, ``[..., 1] = y``.
* ``phi_eff = tr(eps) / L`` with ``eps = sym(grad delta)`` taken with respect to
  backdrop mm: a converging lens reads ``phi_eff < 0``.
"""

from ._version import __version__
from .analyzer import (
    AnalysisResult,
    AnalyzerParams,
    analyze,
    analyze_reflection,
    ReflectionGeometry,
    analyze_captures,
    channel_statistics,
    evaluate_displacement,
    load_params,
    prepare_reference,
)
from ._api import evaluate_spec, write_report
from .errors import AnalysisError, GlassdistError, InputError
from .io import read_image, read_mask
from .storage import load_result, write_outputs
from .history import history

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
