"""The view from anywhere: what ``glassdist analyze`` would report on a photo taken from another point.

From a capture's intrinsic reading (:mod:`glassdist.viewpoint.intrinsic`) the pane's
deflection ``dtheta = M_c^{-1} delta_c / L`` is carried to an observer at ``Do`` from the
pane, the backdrop ``Lo`` behind it, on the pane normal through its centre and aimed at it
(normal incidence):

.. math::

   \\delta_o = L_o\\,M_o\\,\\Delta\\theta, \\qquad
   X_o = x_p\\,\\frac{D_o + L_o}{D_o},

so that on the axis ``phi_o = phi_int Do / (Do + Lo)``. The predicted photo is then read
as ``analyze`` reads one: the A2 detrend of degree N in its pixel coordinates (a
uniform scale of the capture's at normal incidence), the smoothing ``S`` in its backdrop
mm (isotropic in its pixels), the A3 channels with ``L = Lo``
(:func:`glassdist.analyzer.metrics.evaluate_displacement`), statistics over the
capture's trusted pixels (:func:`glassdist.analyzer.metrics.channel_statistics`).

A prediction may smooth more than the capture resolved, never less: the capture's
smoothing carried onto the pane, ``sigma Dc / (Dc + L)``, is at the observer's backdrop
``sigma Dc (Do + Lo) / ((Dc + L) Do)``; a finer ``S`` is refused, a coarser one adds
the Gaussian of ``sqrt(S^2 - that^2)``.

Where it stops holding (both warned of): where the predicted strain ``|eps| = phi Lo / 1000``
reaches a few per cent, the first-order reading of a photo (small-strain channels, a
demodulation following so stretched a pattern) does, although the deflection itself stays
small-angle; and where the observer's field angle over the captured area exceeds about
20 deg, the first-order use of the projection factors. Not modelled: the slab's lateral
shift (relative size ``d / (n Lo)``, growing for a backdrop close behind the pane) and the
thickened slab's own shift (``x^2 / (n Do Lo)`` of a wedge across the view).
Oblique viewing (``viewing_angle_deg`` other than 0) is not modelled yet and is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..analyzer.metrics import channel_statistics, evaluate_displacement
from ..analyzer.result import CHANNELS
from ..errors import InputError
from .intrinsic import (
    CaptureGeometry,
    _radial_frame,
    deflection_mrad,
    pane_coordinates,
    projection_factors,
)

__all__ = ["ViewPrediction", "capture_sigma_mm", "predict_view", "stored_geometry", "trusted_pixels"]

#: Predicted strain above which the first-order model (and a real photo's analysis) stops holding.
STRAIN_LIMIT = 0.05
#: Observer field angle above which the projection factors' first-order use is doubtful, deg.
FIELD_ANGLE_LIMIT_DEG = 20.0


@dataclass(frozen=True)
class ViewPrediction:
    """What ``analyze`` would report on a photo from the observer's point.

    Attributes
    ----------
    phi_eff_mD, phi_shear_mD, phi_total_mD, axis_deg : ndarray (H, W)
        The predicted maps on the capture's pixel grid (each pixel sees the same pane point
        in the predicted photo, up to its scale); NaN where invalid.
    displacement_detrended_mm : ndarray (H, W, 2)
        The predicted photo's detrended, smoothed displacement, its backdrop mm.
    valid, trusted : ndarray (H, W) bool
        The capture's reported and trusted regions.
    statistics : dict
        Per channel, the statistics ``analyze`` writes (``mean_abs``, ``p95_abs``, ...).
    capture, observer : CaptureGeometry
    sigma_mm : float
        The photo's smoothing, its backdrop mm.
    detrend_degree : int
    mm_per_px : float
        The photo's backdrop mm per capture pixel.
    factor : float
        ``Do / (Do + Lo)``: the predicted reading over the intrinsic one on the axis.
    warnings : tuple of str
    """

    phi_eff_mD: np.ndarray
    phi_shear_mD: np.ndarray
    phi_total_mD: np.ndarray
    axis_deg: np.ndarray
    displacement_detrended_mm: np.ndarray
    valid: np.ndarray
    trusted: np.ndarray
    statistics: dict
    capture: CaptureGeometry
    observer: CaptureGeometry
    sigma_mm: float
    detrend_degree: int
    mm_per_px: float
    factor: float
    warnings: tuple

    def summary(self) -> dict:
        """JSON-serialisable record (``summary.json`` of ``glassdist view``)."""
        return {
            "statistics": self.statistics,
            "view": {"observer_distance_m": self.observer.camera_distance_m,
                     "background_distance_m": self.observer.distance_m, "viewing_angle_deg": 0.0,
                     "viewing_azimuth_deg": 0.0, "factor": self.factor},
            "capture": {"camera_distance_m": self.capture.camera_distance_m, "distance_m": self.capture.distance_m,
                        "factor": self.capture.factor, "refractive_index": self.capture.refractive_index},
            "distance_m": self.observer.distance_m,
            "sigma_mm": self.sigma_mm,
            "detrend_degree": self.detrend_degree,
            "mm_per_px": self.mm_per_px,
            "warnings": list(self.warnings),
        }


def stored_geometry(stored) -> CaptureGeometry:
    """The capture geometry a stored result records (``summary.json`` ``intrinsic``); InputError without it."""
    s = stored.summary
    intr = s.get("intrinsic")
    if s.get("optics") is not None:
        raise InputError("this result was taken in reflection; the intrinsic reading and the view are for "
                         "transmission captures")
    if not intr:
        raise InputError("this result records no camera-to-pane distance; analyse the photo again with "
                         "--camera-distance-m Dc (the camera to the pane, m)")
    return CaptureGeometry(float(intr["camera_distance_m"]), float(s["distance_m"]),
                           float(intr.get("refractive_index", 1.52)))


def capture_sigma_mm(stored) -> float:
    """The smoothing the stored channels carry, backdrop mm (``sigma_mm``, or the instrument's resolution where coarser)."""
    s = stored.summary
    return float(max(s["sigma_mm"], s.get("effective_sigma_mm") or 0.0))


def trusted_pixels(stored) -> np.ndarray:
    """The pixels the stored statistics are over: quality label 0 (analysed), else the valid region."""
    if "quality" in stored.fields:
        return np.asarray(stored.pixel_field("quality")) == 0
    return np.asarray(stored.valid, bool)


def _check_distance(value, option: str) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InputError(f"{option} must be a positive number of metres, got {value!r}")
    return float(value)


def predict_view(stored, *, observer_distance_m: float, background_distance_m: float, viewing_angle_deg: float = 0.0,
                 viewing_azimuth_deg: float = 0.0, sigma_mm: float | None = None,
                 detrend_degree: int | None = None) -> ViewPrediction:
    """Predict ``analyze``'s reading of a photo taken from ``Do`` with the backdrop ``Lo`` behind the pane.

    Parameters
    ----------
    stored : glassdist.storage.StoredResult
        :func:`glassdist.load_result` of a run with ``--camera-distance-m``.
    observer_distance_m, background_distance_m : float
        ``Do`` (observer to pane, along the normal) and ``Lo`` (pane to backdrop), m.
    viewing_angle_deg, viewing_azimuth_deg : float
        The line of sight's angle to the pane normal and its azimuth; only 0 (normal) is
        modelled so far.
    sigma_mm : float, optional
        The photo's smoothing, its backdrop mm; default the capture's carried there (the finest
        allowed).
    detrend_degree : int, optional
        Default the capture's.

    Returns
    -------
    ViewPrediction

    Raises
    ------
    InputError
        No geometry in the result, a bad distance, an oblique view, ``sigma_mm`` finer than
        the capture resolved.
    """
    cap = stored_geometry(stored)
    Do = _check_distance(observer_distance_m, "--observer-distance-m")
    Lo = _check_distance(background_distance_m, "--background-distance-m")
    if not (isinstance(viewing_angle_deg, (int, float)) and math.isfinite(viewing_angle_deg)):
        raise InputError(f"--viewing-angle-deg must be a number of degrees, got {viewing_angle_deg!r}")
    if viewing_angle_deg != 0.0:
        raise InputError(f"--viewing-angle-deg {viewing_angle_deg:g}: oblique viewing is not modelled yet; "
                         "predict at normal incidence (leave --viewing-angle-deg out or give 0)")
    obs = CaptureGeometry(Do, Lo, cap.refractive_index)
    s = stored.summary
    mpp_c = float(s["mm_per_px"])
    sigma_c_pane = capture_sigma_mm(stored) * cap.factor
    finest = sigma_c_pane / obs.factor
    S = finest if sigma_mm is None else float(sigma_mm)
    if not (math.isfinite(S) and S > 0):
        raise InputError(f"--sigma-mm must be a positive number of mm, got {sigma_mm!r}")
    if S < finest * (1.0 - 1e-6):
        raise InputError(f"--sigma-mm {S:g} is finer than the capture resolved: from this point its smoothing is "
                         f"{finest:.4g} mm on the backdrop ({sigma_c_pane:.4g} mm on the pane); give --sigma-mm "
                         f"{finest:.4g} or more")
    N = int(s["detrend_degree"]) if detrend_degree is None else int(detrend_degree)
    if not 0 <= N <= 6:
        raise InputError(f"--detrend-degree must be an integer from 0 to 6, got {detrend_degree!r}")

    valid = np.asarray(stored.valid, bool)
    H, W = valid.shape
    delta = np.nan_to_num(np.asarray(stored.pixel_field("displacement_detrended_mm"), float))
    x, y = pane_coordinates(np.arange(H, dtype=float)[:, None], np.arange(W, dtype=float)[None, :], (H, W),
                            mm_per_px=mpp_c, geometry=cap)
    x, y = np.broadcast_arrays(x, y)
    # delta_o = Lo M_o dtheta, dtheta = M_c^-1 delta_c / L (mrad), in the (t, s) frame of each pixel
    dth = deflection_mrad(delta, x, y, cap)
    alpha_o, c, sn = _radial_frame(x, y, obs.camera_distance_m)
    mto, mso = projection_factors(alpha_o, cap.refractive_index)
    dt = Lo * mto * (c * dth[..., 0] + sn * dth[..., 1])
    ds = Lo * mso * (-sn * dth[..., 0] + c * dth[..., 1])
    delta_o = np.stack([c * dt - sn * ds, sn * dt + c * ds], axis=-1)
    mpp_o = mpp_c * cap.factor / obs.factor
    extra = math.sqrt(max(S * S - finest * finest, 0.0))
    ch = evaluate_displacement(delta_o, valid, distance_m=Lo, mm_per_px=mpp_o, detrend_degree=N,
                               sigma_mm=max(extra, 1e-3 * mpp_o))
    trusted = trusted_pixels(stored) & valid
    stats = {name: channel_statistics(getattr(ch, name), trusted) for name in CHANNELS}
    warnings = []
    total = np.asarray(ch.phi_total_mD)[trusted]
    strain = float(np.nanmax(total)) * Lo / 1000.0 if total.size else 0.0
    if strain > STRAIN_LIMIT:
        warnings.append(f"the predicted strain reaches {strain:.3g} (phi_total {float(np.nanmax(total)):.3g} mD over "
                        f"Lo = {Lo:g} m): above {STRAIN_LIMIT:g} the first-order reading of a photo (the small-strain "
                        "A3 channels, and the demodulation that has to follow so stretched a pattern) stops holding; "
                        "a photo from there may not confirm the prediction")
    fa = float(np.degrees(alpha_o[valid]).max()) if valid.any() else 0.0
    if fa > FIELD_ANGLE_LIMIT_DEG:
        warnings.append(f"the observer sees the captured pane area at up to {fa:.3g} deg off the normal: above "
                        f"{FIELD_ANGLE_LIMIT_DEG:g} deg the first-order projection factors stop holding")
    return ViewPrediction(ch.phi_eff_mD, ch.phi_shear_mD, ch.phi_total_mD, ch.axis_deg, ch.displacement_detrended_mm,
                          valid, trusted, stats, cap, obs, S, N, mpp_o, obs.factor, tuple(warnings))
