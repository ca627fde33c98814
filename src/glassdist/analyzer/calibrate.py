"""The camera lens from a calibration photo (Block I's self-calibration on a photo without glass), above the pipeline.

The same analysis is the Direct Method's reading of a pane with no glass; its statistics are
kept as the rig's floor (:attr:`~glassdist.analyzer.lens.LensCalibration.floor`), which
:func:`~glassdist.analyzer.pipeline.analyze` compares a pane's reading with.
"""

from __future__ import annotations

import os
from typing import Any, cast

import numpy as np

from ..errors import InputError
from .lens import LensCalibration
from .params import AnalyzerParams, load_params
from .pipeline import analyze

__all__ = ["calibrate_from_photo"]


def calibrate_from_photo(image: np.ndarray | str | os.PathLike[str], *, pitch_mm: float, pattern: str | None = None,
                         params: AnalyzerParams | dict[str, object] | str | os.PathLike[str] | None = None,
                         image_shape: tuple[int, int] | None = None, distance_m: float = 1.0) -> LensCalibration:
    """The lens from a calibration photo: the same grid without glass, same camera and focus, any pose.

    Block I's self-calibration on a photo without glass, where the whole view is unstrained
    (:func:`glassdist.analyzer.homography.refit_with_lens`); the ``params.lens_model`` terms
    are fitted ("radial" when it is "none").

    The same analysis is the Direct Method's reading of a pane with no glass: whatever it
    shows is what the board (its print, its flatness) and the camera leave against the
    perfect grid and the lens model. Its mean and p95 |phi_eff| over the trusted pixels, at
    ``params``'s detrend degree and smoothing and at the pane's ``distance_m`` (phi scales
    as 1/L), are returned as :attr:`LensCalibration.floor`; :func:`analyze` compares the
    pane's reading with it.

    Raises
    ------
    InputError
        When the photo's size differs from ``image_shape`` (the photos to analyse), or the
        photo does not pin the lens (its grid does not reach out towards the corners).
    """
    shape = np.shape(cast(Any, image))  # a path has no shape (): read by analyze, refused here when a shape is given
    if image_shape is not None and tuple(shape[:2]) != tuple(image_shape):
        h, w = shape[:2]
        raise InputError(f"the calibration photo is {w}x{h} px but the photo is {image_shape[1]}x{image_shape[0]} px; "
                         "take it with the same camera at the same resolution")
    p = params if isinstance(params, AnalyzerParams) else load_params(params)
    if p.lens_model == "none":
        p = p.model_copy(update={"lens_model": "radial"})
    res = analyze(image, pitch_mm=pitch_mm, distance_m=distance_m, params=p, pattern=pattern)
    cal = res.homography_fit.lens if res.homography_fit is not None else None
    if cal is None or not cal.identifiable:
        why = "too few grid points" if cal is None else cal.note
        raise InputError(f"the calibration photo does not pin the lens ({why}); photograph the grid filling the view, "
                         "without glass")
    floor = {}
    stats = res.statistics()["phi_eff_mD"]
    if stats["n_valid"]:
        floor = {"mean_abs_phi_eff_mD": stats["mean_abs"], "p95_abs_phi_eff_mD": stats["p95_abs"],
                 "phi_eff_sigma_mD": res.noise_floor()["phi_eff_sigma_mD"]["median"],
                 "detrend_degree": p.detrend_degree, "distance_m": float(distance_m)}
    return LensCalibration(cal.model, "photo", cal.sigma, True, cal.fit_fraction, cal.rms_px, None, "", floor=floor)
