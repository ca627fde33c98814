"""Branch 2 of the Virtual Pipeline: the Optical Theoretical Model (paper §3.1).

Pure functions of a :class:`glassdist.scene.Scene`: the first-order Snell
forward model of the deformed slab evaluated on the camera pixel grid
(:func:`predict_displacement`), independent of any rendered image, and its
passage through the shared evaluation stack (:func:`predict_channels`).
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

# --- typed names for static tools (scripts/lazy_stubs.py writes this block) ---
if TYPE_CHECKING:
    from .channels import analysis_params, carrier_period_mm, predict_channels, read_params_file, reflection_geometry
    from .model import Prediction, nominal_mm_per_px, predict_displacement, slab_shift
# --- end of the typed names ---

# loaded on first use: the sub-commands register without the analysis stack
__getattr__, __dir__ = lazy_exports(__name__, {
    **dict.fromkeys(("analysis_params", "carrier_period_mm", "predict_channels", "read_params_file", "reflection_geometry"),
                   ".channels"),
    **dict.fromkeys(("Prediction", "nominal_mm_per_px", "predict_displacement", "slab_shift"), ".model"),
})

__all__ = [
    "Prediction",
    "predict_displacement",
    "predict_channels",
    "reflection_geometry",
    "analysis_params",
    "read_params_file",
    "carrier_period_mm",
    "slab_shift",
    "nominal_mm_per_px",
]
