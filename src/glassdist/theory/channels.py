"""The analytical model passed through the shared evaluation stack (A2 + smoothing + A3)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..errors import InputError
from ..scene import Scene, landing_jacobian, pixel_directions, pixel_grid
from .model import Prediction, nominal_mm_per_px, predict_displacement

__all__ = ["analysis_params", "carrier_period_mm", "predict_channels", "read_params_file", "reflection_geometry"]


def reflection_geometry(scene: Scene):
    """The :class:`~glassdist.analyzer.reflection.ReflectionGeometry` of a scene viewed in reflection.

    D and C: the board's and the camera's distances to the pane's nominal front plane along
    its normal (C None when the camera lies in the board plane, within 1 mm); the
    incidence and the plane of incidence of the central pixel's line of sight (the
    direction of its in-plane component, from the board's +X towards +Y).
    """
    from ..analyzer.reflection import ReflectionGeometry

    pane, cam = scene.pane, scene.camera
    w = pane.rotation[:, 2]
    front = np.asarray(pane.center_mm, float) - 0.5 * pane.thickness_mm * w
    C_mm = float((front - np.asarray(cam.position_mm, float)) @ w)
    H, W = cam.shape
    a = pixel_directions(cam, W / 2, H / 2)
    ca = float(a @ w)
    perp = a - ca * w
    D_mm = float(front[2] - scene.backdrop_z_mm) / float(w[2])
    in_board = abs(C_mm - D_mm) < 1.0
    return ReflectionGeometry(
        distance_m=D_mm / 1000.0, camera_distance_m=None if in_board else C_mm / 1000.0,
        incidence_deg=math.degrees(math.acos(min(1.0, abs(ca)))),
        plane_deg=math.degrees(math.atan2(perp[1], perp[0])) if np.hypot(perp[0], perp[1]) > 1e-12 else 0.0,
    )


def _incidence(scene: Scene):
    """Angle of incidence and direction of the plane of incidence (deg, from +x towards +y) of every pixel's line of sight."""
    w = scene.pane.rotation[:, 2]
    a = pixel_directions(scene.camera, *pixel_grid(scene.camera))
    ca = np.clip(a @ w, -1.0, 1.0)
    perp = a - ca[..., None] * w
    return np.degrees(np.arccos(np.abs(ca))), np.degrees(np.arctan2(perp[..., 1], perp[..., 0]))


def carrier_period_mm(scene: Scene) -> float:
    """Carrier period on the backdrop: the pitch for lines and dots, pitch * sqrt(2) for a checkerboard."""
    p = scene.backdrop.pitch_mm
    return p * math.sqrt(2.0) if scene.backdrop.pattern == "checkerboard" else p


def read_params_file(params_file) -> dict:
    """The ``--params`` file of analyzer parameters as a mapping (JSON), read once for many scenes.

    Raises :class:`InputError` when it cannot be read or parsed; the values are checked where
    they meet a scene (:func:`analysis_params`).
    """
    from ..validation import load_mapping

    return load_mapping(params_file, "parameter file", option="--params", fmt="json", expect="parameter: value pairs")


def analysis_params(scene: Scene, params_file=None, **overrides):
    """Analyzer parameters for a scene: shipped defaults < ``scene.analysis`` < file < overrides.

    ``params_file``: a path (:func:`read_params_file`) or the mapping read from it, as
    :func:`glassdist.analyzer.params.load_params` takes either. The pattern always follows the
    scene's backdrop. Returns an :class:`glassdist.analyzer.AnalyzerParams`; raises
    :class:`InputError` for unknown keys or bad values.
    """
    from ..analyzer.params import load_params

    data = dict(scene.analysis)
    if params_file is not None:
        data.update(params_file if isinstance(params_file, Mapping) else read_params_file(params_file))
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
        Reporting smoothing scale on the backdrop, mm (in reflection: on the pane).
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
        In reflection the channels are the reflective power on the pane
        (:func:`glassdist.analyzer.reflection.power_from_strain` of the slope field's board
        strain, :func:`~glassdist.analyzer.reflection.slope_strain`, at the scene's
        :func:`reflection_geometry` and each pixel's own incidence); ``strain`` stays the board's.
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
    geom = reflection_geometry(scene) if scene.reflection else None
    board = 1.0 if geom is None else geom.magnification  # board mm per pane mm
    ch = evaluate_displacement(
        np.nan_to_num(pred.displacement_mm),
        region,
        distance_m=scene.backdrop.distance_m if geom is None else geom.effective_distance_m,
        mm_per_px=mpp,
        detrend_degree=int(detrend_degree),
        sigma_mm=float(sigma_mm) * board,
        jacobian=landing_jacobian(scene) if projective else None,
        labels=labels,
    )
    if geom is not None:
        from dataclasses import replace

        from ..analyzer.reflection import power_channels, power_from_strain, slope_strain

        theta, plane = _incidence(scene)
        r = geom.camera_distance_mm * np.tan(np.radians(theta))  # |v|: the camera's foot to the hit point
        v = (r * np.cos(np.radians(plane)), r * np.sin(np.radians(plane)))
        eps = slope_strain(ch.strain, np.nan_to_num(pred.displacement_mm), *v, geom)
        P = power_from_strain(eps * (1000.0 / geom.effective_distance_m), theta, plane)
        eff, shear, total, axis = power_channels(P)
        ch = replace(ch, phi_eff_mD=eff, phi_shear_mD=shear, phi_total_mD=total, axis_deg=axis)
    return pred, ch, region
