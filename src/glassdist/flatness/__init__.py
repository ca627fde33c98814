"""Flatness of the pane's front face from a reflection result: slope, height and the fabricators' measures.

:mod:`~glassdist.flatness.slope` turns the board displacement into the front face's slope
and height (fields ``surface_slope_mrad``, ``surface_height_um`` of ``result.npz``),
:mod:`~glassdist.flatness.integrate` is the masked least-squares integrator, and
:mod:`~glassdist.flatness.measures` the measures in mm and µm (``summary.json["flatness"]``).
"""

from .integrate import integrate_slope, integrate_slopes
from .measures import (
    EdgeLift,
    FlatnessMeasures,
    RollerWaveHeight,
    astm_c1651_mD,
    edge_lift,
    edge_lifts,
    flatness_measures,
    roller_wave_height,
)
from .slope import (
    SurfaceFields,
    height_sigma,
    landing_slope,
    pane_step_mm,
    polynomial_detrend,
    surface_fields,
    with_surface_fields,
)

__all__ = [
    "EdgeLift", "FlatnessMeasures", "RollerWaveHeight", "SurfaceFields", "astm_c1651_mD", "edge_lift", "edge_lifts",
    "flatness_measures", "height_sigma", "integrate_slope", "integrate_slopes", "landing_slope", "pane_step_mm",
    "polynomial_detrend", "roller_wave_height", "surface_fields", "with_surface_fields",
]
