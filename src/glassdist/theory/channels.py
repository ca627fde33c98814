"""The analytical model passed through the shared evaluation stack (A2 + smoothing + A3)."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..scene import Scene, landing_jacobian
from .model import Prediction, nominal_mm_per_px, predict_displacement

__all__ = ["analysis_params", "carrier_period_mm", "predict_channels"]


def carrier_period_mm(scene: Scene) -> float:
    """Carrier period on the backdrop: the pitch for lines, pitch * sqrt(2) for a checkerboard."""
    p = scene.backdrop.pitch_mm
    return p if scene.backdrop.pattern == "lines" else p * math.sqrt(2.0)


def analysis_params(scene: Scene, params_file=None, **overrides):
    """Analyzer parameters for a scene: shipped defaults < ``scene.analysis`` < file < overrides.

    The pattern always follows the scene's backdrop. Returns an
    :class:`glassdist.analyzer.AnalyzerParams`; raises :class:`InputError` for
    unknown keys or bad values.
    """
    from ..analyzer.params import load_params

    from ..validation import load_mapping

    data = dict(scene.analysis)
    if params_file is not None:
        data.update(load_mapping(params_file, "parameter file", option="--params", fmt="json",
                                 expect="parameter: value pairs"))
    data["pattern"] = scene.backdrop.pattern
    return load_params(data, **overrides)


def predict_channels(
    scene: Scene,
    *,
    sigma_mm: float,
    detrend_degree: int,
    mm_per_px: float | None = None,
    valid: np.ndarray | None = None,
    projective: bool = True,
    prediction: Prediction | None = None,
):
    """Analytical displacement through the shared evaluation stack.

    Parameters
    ----------
    scene : Scene
    sigma_mm : float
        Reporting smoothing scale on the backdrop, mm.
    detrend_degree : int
        Total degree of the A2 polynomial.
    mm_per_px : float, optional
        Isotropic scale setting ``sigma_px``; default the camera's nominal
        backdrop scale (:func:`nominal_mm_per_px`). Give the analyzer's value for a
        like-for-like comparison.
    valid : ndarray of bool (H, W), optional
        Region to evaluate (intersected with the pixels the model covers); its connected
        parts are detrended and smoothed independently.
    projective : bool
        Differentiate with respect to backdrop mm through the exact glass-less
        pixel -> backdrop Jacobian (True) or the isotropic ``mm_per_px``.
    prediction : Prediction, optional
        Reuse an already computed :func:`predict_displacement`.

    Returns
    -------
    prediction : Prediction
    channels : glassdist.analyzer.Channels
    valid : ndarray of bool (H, W)
    """
    from ..analyzer.metrics import evaluate_displacement
    from ..analyzer.unwrap import label_regions

    pred = predict_displacement(scene) if prediction is None else prediction
    region = pred.valid if valid is None else (pred.valid & np.asarray(valid, bool))
    if not region.any():
        raise InputError("the analytical model has no valid pixel in the requested region")
    mpp = nominal_mm_per_px(scene) if mm_per_px is None else float(mm_per_px)
    # Connected parts of the region (e.g. the pane and the backdrop beside its frame) are
    # detrended and smoothed independently, as the Analyzer does with its regions.
    labels, _ = label_regions(region)
    ch = evaluate_displacement(
        np.nan_to_num(pred.displacement_mm),
        region,
        distance_m=scene.backdrop.distance_m,
        mm_per_px=mpp,
        detrend_degree=int(detrend_degree),
        sigma_mm=float(sigma_mm),
        jacobian=landing_jacobian(scene) if projective else None,
        labels=labels,
    )
    return pred, ch, region
