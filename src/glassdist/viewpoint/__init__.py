"""The pane's own distortion and the view from anywhere.

* :mod:`~glassdist.viewpoint.intrinsic`: a capture's reading brought to the pane's
  equivalent thin surface (net deflection on pane coordinates), free of the camera and
  backdrop distances.
* :mod:`~glassdist.viewpoint.view`: what ``analyze`` would report on a photo from another
  point (``glassdist view``).
* :mod:`~glassdist.viewpoint.compare`: two captures of one pane on the intrinsic axis
  (``glassdist compare``).
"""

from .compare import Comparison, compare_results
from .intrinsic import (
    DEFAULT_REFRACTIVE_INDEX,
    CaptureGeometry,
    IntrinsicReading,
    capture_factor,
    intrinsic_reading,
    projection_factors,
    projection_matrix,
    reference_factor,
)
from .view import ViewPrediction, predict_view

__all__ = ["DEFAULT_REFRACTIVE_INDEX", "CaptureGeometry", "Comparison", "IntrinsicReading", "ViewPrediction",
           "capture_factor", "compare_results", "intrinsic_reading", "predict_view", "projection_factors",
           "projection_matrix", "reference_factor"]
