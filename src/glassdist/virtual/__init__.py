"""The Virtual Pipeline (paper §2, §3.1): both branches from one scene, compared.

:func:`validate_scene` renders the scene, runs the Distortion Analyzer, evaluates
the Optical Theoretical Model on the camera pixel grid, passes it through the
same evaluation stack and reports the paper's Table 2 figures
(:class:`Validation`). :func:`run_sweep` runs it on every combination of varied
scene values (``glassdist sweep``).
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .figure import validation_figure
    from .sweep import Variant, expand_variants, parse_vary, run_sweep, write_sweep_index
    from .validate import CHANNELS, Validation, compare, compare_with_scene, exact_truth, procrustes, validate_scene
# --- end of the typed names ---

# loaded on first use: the sub-commands register without the render and analysis stacks
__getattr__, __dir__ = lazy_exports(__name__, {
    "validation_figure": ".figure",
    **dict.fromkeys(("Variant", "expand_variants", "parse_vary", "run_sweep", "write_sweep_index"), ".sweep"),
    **dict.fromkeys(("CHANNELS", "Validation", "compare", "compare_with_scene", "exact_truth", "procrustes",
                     "validate_scene"), ".validate"),
})

__all__ = [
    "validate_scene",
    "compare",
    "compare_with_scene",
    "exact_truth",
    "procrustes",
    "Validation",
    "validation_figure",
    "CHANNELS",
    "Variant",
    "parse_vary",
    "expand_variants",
    "run_sweep",
    "write_sweep_index",
]
