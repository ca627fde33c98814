"""The view from anywhere: what ``glassdist analyze`` would report on a photo taken from another point.

From a capture's intrinsic reading (:mod:`glassdist.viewpoint.intrinsic`) the pane's
deflection ``dtheta = M_c^{-1} delta_c / L`` is carried to a photo taken ``Do`` from the pane
centre along a line of sight at ``theta`` to the pane normal (azimuth ``psi``), aimed at the
centre, the backdrop parallel to the pane ``Lo`` behind it (:func:`observer_camera`). For
each pixel of that photo, its line of sight ``a`` crosses the pane at ``x_p`` and

.. math::

   \\delta_o = L_o\\,M(\\mathbf a)\\,\\Delta\\theta(x_p), \\qquad
   X_o = O + (x_p - O)\\,\\frac{h + L_o}{h}, \\quad h = D_o\\cos\\theta,

with ``M`` the thin prism at that incidence projected over ``Lo / cos(alpha)``
(:func:`~glassdist.viewpoint.intrinsic.projection_matrix`, the ``K0`` and ``sec`` factors),
evaluated per pixel (its variation across the pane is kept). At the pane centre a unit
intrinsic power reads ``k m_t`` along the plane of incidence and ``k m_s`` across it,
``k = h / (h + Lo)``: 1.64 and 1.23 (over the normal reading) at 30 deg, 3.25 and 1.62 at 45
deg (Do 5 m, Lo 1 m); so a roller wave seen from its side is amplified more than one seen
along its crests, and the axis of a shear turns towards the plane of incidence.

The predicted photo is then read as ``analyze`` reads one: the A2 detrend of degree N in
its pixel coordinates, the smoothing ``S`` in its backdrop mm (isotropic in its pixels, at
the median scale ``sqrt |det dX/dr|``), the A3 channels with the exact Jacobian of its
glass-less view and ``L = Lo`` (:func:`glassdist.analyzer.metrics.evaluate_displacement`),
statistics over the photo's pixels that see the capture's trusted pane area
(:func:`glassdist.analyzer.metrics.channel_statistics`).

A prediction may smooth more than the capture resolved, never less: the capture's smoothing,
isotropic ``sigma Dc / (Dc + L)`` on the pane, is in the oblique photo's pixels an
elongated Gaussian (foreshortened along the plane of incidence); ``S`` finer than its longer
axis anywhere on the view is refused, and the photo's smoothing adds only what the capture's
lacks (``S^2 I - C`` in px^2, ``C`` that covariance at the view's centre).

Where it stops holding (each warned of): the predicted strain ``|eps| = phi Lo / 1000``
reaching a few per cent (the first-order reading of a photo); incidence beyond 60 deg (the
range over which the chain is checked against exact refraction, within 2 %,
``tests/test_viewpoint.py``); the pane's own deflection changing the projection factors by
more than 5 % (second order in the deflection, ``|d ln m_t / d alpha| |dtheta|``); a normal
view whose field reaches beyond 20 deg. Not modelled: the flat slab's lateral shift, which
varies with the incidence across an oblique view (for a 6 mm pane, a near-linear field that
a detrend of degree >= 1 takes out), the slab's lateral shift under slope (relative size
``d / (n Lo)``), and the capture's own field-angle variation of ``M`` (normal captures).
An oblique capture (its ``intrinsic`` records the angle) is met with the pane through its
own camera (:func:`~glassdist.viewpoint.intrinsic.pane_to_pixels`); its smoothing, elongated on
the pane, is carried as isotropic at its geometric mean.
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
    centre_factor,
    deflection_mrad,
    pane_coordinates,
    pane_to_pixels,
    projection_factors,
    projection_matrix,
)

__all__ = ["ViewPrediction", "capture_sigma_mm", "observer_camera", "predict_view", "stored_geometry", "trusted_pixels"]

#: Predicted strain above which the first-order model (and a real photo's analysis) stops holding.
STRAIN_LIMIT = 0.05
#: Observer field angle (normal viewing) above which the neglected variation of the projection factors grows, deg.
FIELD_ANGLE_LIMIT_DEG = 20.0
#: Incidence up to which the chain is validated against exact refraction (within 2 %, tests/test_viewpoint.py), deg.
INCIDENCE_LIMIT_DEG = 60.0
#: Relative change of the projection factors by the deflection itself above which the first order stops holding.
SECOND_ORDER_LIMIT = 0.05
#: Viewing angles refused (the pane seen nearly edge-on), deg.
MAX_VIEWING_ANGLE_DEG = 70.0


@dataclass(frozen=True)
class ViewPrediction:
    """What ``analyze`` would report on a photo from the observer's point.

    Attributes
    ----------
    phi_eff_mD, phi_shear_mD, phi_total_mD, axis_deg : ndarray (H, W)
        The predicted maps on the photo's pixel grid (:attr:`camera`; at normal incidence each
        pixel sees the pane point of the same capture pixel); NaN where invalid.
    displacement_detrended_mm : ndarray (H, W, 2)
        The predicted photo's detrended, smoothed displacement, its backdrop mm.
    valid, trusted : ndarray (H, W) bool
        The photo's pixels that see the capture's reported and trusted pane areas.
    statistics : dict
        Per channel, the statistics ``analyze`` writes (``mean_abs``, ``p95_abs``, ...).
    capture, observer : CaptureGeometry
    sigma_mm : float
        The photo's smoothing, its backdrop mm.
    detrend_degree : int
    mm_per_px : float
        The photo's backdrop mm per capture pixel.
    factor : float
        The predicted mean power over the intrinsic one at the pane centre,
        ``h / (h + Lo) (m_t + m_s) / 2`` (``Do / (Do + Lo)`` at normal incidence).
    viewing_angle_deg, viewing_azimuth_deg : float
    median_incidence_deg : float
        Over the photo's valid pixels.
    camera : dict
        The photo's pinhole (:func:`observer_camera`): ``position_mm``, ``yaw_deg``,
        ``pitch_deg``, ``focal_length_px``, ``pixels``, in the capture's pane frame.
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
    viewing_angle_deg: float
    viewing_azimuth_deg: float
    median_incidence_deg: float
    camera: dict
    warnings: tuple

    def summary(self) -> dict:
        """JSON-serialisable record (``summary.json`` of ``glassdist view``)."""
        return {
            "statistics": self.statistics,
            "view": {"observer_distance_m": self.observer.camera_distance_m,
                     "background_distance_m": self.observer.distance_m,
                     "viewing_angle_deg": self.viewing_angle_deg, "viewing_azimuth_deg": self.viewing_azimuth_deg,
                     "median_incidence_deg": self.median_incidence_deg, "factor": self.factor,
                     "camera": self.camera},
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
    theta = float(intr.get("viewing_angle_deg", 0.0))
    return CaptureGeometry(float(intr["camera_distance_m"]), float(s["distance_m"]),
                           float(intr.get("refractive_index", 1.52)), viewing_angle_deg=theta,
                           viewing_azimuth_deg=float(intr.get("viewing_azimuth_deg", 0.0)),
                           focal_length_px=intr.get("focal_length_px") if theta > 0 else None)


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


def observer_camera(observer_distance_m: float, viewing_angle_deg: float, viewing_azimuth_deg: float, shape,
                    pane_mm_per_px: float):
    """The predicted photo's camera: a pinhole ``Do`` from the pane centre along the line of sight, aimed at it.

    In the pane frame of the capture (origin the pane centre, x along the capture's columns,
    y along its rows, z the normal towards the backdrop), the line of sight to the centre is
    ``a = (sin theta cos psi, sin theta sin psi, cos theta)`` and the camera sits at
    ``-1000 Do a``, turned by ``yaw = atan2(a_x, a_z)``, ``pitch = -asin(a_y)`` (no roll: the
    camera convention of :mod:`glassdist.scene`). Same pixel count as the capture; the focal
    length gives the capture's pane mm per px at the pane centre across the plane of incidence.

    Returns
    -------
    glassdist.scene.Camera
    """
    from ..scene.model import Camera

    t, p = math.radians(viewing_angle_deg), math.radians(viewing_azimuth_deg)
    a = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
    H, W = shape
    sensor_mm = 36.0
    focal_px = 1000.0 * observer_distance_m / pane_mm_per_px
    return Camera(focal_length_mm=focal_px * sensor_mm / W, sensor_width_mm=sensor_mm, pixels=(int(W), int(H)),
                  position_mm=tuple(float(v) for v in -1000.0 * observer_distance_m * a),
                  yaw_deg=math.degrees(math.atan2(a[0], a[2])), pitch_deg=-math.degrees(math.asin(a[1])))


def _observer_rays(camera, background_distance_m: float):
    """Per pixel of ``camera``: unit line of sight, pane point (mm, the plane z = 0), and ``dX/dr`` on the backdrop."""
    from ..scene.geometry import pixel_directions, pixel_grid

    o = np.asarray(camera.position_mm, float)
    zb = 1000.0 * background_distance_m

    def land(col, row, z):
        d = pixel_directions(camera, col, row)
        return d, o[:2] + d[..., :2] * ((z - o[2]) / d[..., 2])[..., None]

    col, row = pixel_grid(camera)
    a, pane_pt = land(col, row, 0.0)
    J = np.stack([land(col + 0.5, row, zb)[1] - land(col - 0.5, row, zb)[1],
                  land(col, row + 0.5, zb)[1] - land(col, row - 0.5, zb)[1]], axis=-1)
    return a, pane_pt, J


def predict_view(stored, *, observer_distance_m: float, background_distance_m: float, viewing_angle_deg: float = 0.0,
                 viewing_azimuth_deg: float = 0.0, sigma_mm: float | None = None,
                 detrend_degree: int | None = None) -> ViewPrediction:
    """Predict ``analyze``'s reading of a photo taken ``Do`` from the pane with the backdrop ``Lo`` behind it.

    Parameters
    ----------
    stored : glassdist.storage.StoredResult
        :func:`glassdist.load_result` of a run with ``--camera-distance-m``.
    observer_distance_m, background_distance_m : float
        ``Do`` (observer to the pane centre, along the line of sight) and ``Lo`` (pane to
        backdrop, along the normal), m.
    viewing_angle_deg, viewing_azimuth_deg : float
        ``theta``, the line of sight's angle to the pane normal, in [0, 70); ``psi``, its
        azimuth: 0 puts the observer on the capture's -x side (image left) looking towards +x,
        90 on its -y side (image top) looking towards +y.
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
        No geometry in the result, a bad distance or angle, ``sigma_mm`` finer than the capture
        resolved.
    """
    from scipy import ndimage

    cap = stored_geometry(stored)
    Do = _check_distance(observer_distance_m, "--observer-distance-m")
    Lo = _check_distance(background_distance_m, "--background-distance-m")
    for value, option in ((viewing_angle_deg, "--viewing-angle-deg"), (viewing_azimuth_deg, "--viewing-azimuth-deg")):
        if not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise InputError(f"{option} must be a number of degrees, got {value!r}")
    theta, psi = float(viewing_angle_deg), float(viewing_azimuth_deg)
    if not 0.0 <= theta < MAX_VIEWING_ANGLE_DEG:
        raise InputError(f"--viewing-angle-deg {theta:g} is outside [0, {MAX_VIEWING_ANGLE_DEG:g}); give the angle "
                         "between the line of sight and the pane normal (the azimuth goes in --viewing-azimuth-deg)")
    n = cap.refractive_index
    s = stored.summary
    mpp_c = float(s["mm_per_px"])
    pane_px = mpp_c * cap.factor  # capture: pane mm per px
    sigma_c_pane = capture_sigma_mm(stored) * cap.factor
    N = int(s["detrend_degree"]) if detrend_degree is None else int(detrend_degree)
    if not 0 <= N <= 6:
        raise InputError(f"--detrend-degree must be an integer from 0 to 6, got {detrend_degree!r}")

    valid_c = np.asarray(stored.valid, bool)
    H, W = valid_c.shape
    trusted_c = trusted_pixels(stored) & valid_c
    delta_c = np.nan_to_num(np.asarray(stored.pixel_field("displacement_detrended_mm"), float))
    x, y = pane_coordinates(np.arange(H, dtype=float)[:, None], np.arange(W, dtype=float)[None, :], (H, W),
                            mm_per_px=mpp_c, geometry=cap)
    x, y = np.broadcast_arrays(x, y)
    dth_c = np.where(valid_c[..., None], deflection_mrad(delta_c, x, y, cap), 0.0)  # mrad, on the capture's pixels

    # the photo: its pixels' lines of sight, the pane points they cross, the capture pixels there
    cam = observer_camera(Do, theta, psi, (H, W), pane_px)
    a, pane_pt, J = _observer_rays(cam, Lo)
    coords = np.stack(pane_to_pixels(pane_pt[..., 0], pane_pt[..., 1], (H, W), mm_per_px=mpp_c, geometry=cap))

    def sample(f, order=1):
        return ndimage.map_coordinates(f, coords, order=order, mode="constant", cval=0.0)

    valid = sample(valid_c.astype(float)) > 1.0 - 1e-6
    trusted = valid & (sample(trusted_c.astype(float), order=0) > 0.5)
    dth = np.stack([sample(dth_c[..., 0]), sample(dth_c[..., 1])], axis=-1)
    # delta_o = Lo M_o dtheta, the thin prism at the photo's own incidence, on its pixel grid
    delta_o = Lo * (projection_matrix(a, n) @ dth[..., None])[..., 0]
    delta_o[~valid] = 0.0
    if not valid.any():
        raise InputError("from that point the photo sees none of the captured pane area; give a smaller "
                         "--viewing-angle-deg or a larger --observer-distance-m")
    scale = np.sqrt(np.abs(np.linalg.det(J)))
    mpp_o = float(np.median(scale[valid]))
    # the capture's smoothing, isotropic sigma_c_pane on the pane, as a covariance in the photo's px (dx_p / dr)
    h_mm = -float(cam.position_mm[2])
    Jp = J * (h_mm / (h_mm + 1000.0 * Lo))
    Jinv = np.linalg.inv(Jp)
    Cc = sigma_c_pane**2 * Jinv @ np.swapaxes(Jinv, -1, -2)
    reach = np.linalg.eigvalsh(Cc[valid])[:, -1]
    finest = math.sqrt(float(reach.max())) * mpp_o
    S = finest if sigma_mm is None else float(sigma_mm)
    if not (math.isfinite(S) and S > 0):
        raise InputError(f"--sigma-mm must be a positive number of mm, got {sigma_mm!r}")
    if S < finest * (1.0 - 1e-6):
        raise InputError(f"--sigma-mm {S:g} is finer than the capture resolved: from this point its smoothing is "
                         f"{finest:.4g} mm on the backdrop ({sigma_c_pane:.4g} mm on the pane); give --sigma-mm "
                         f"{finest:.4g} or more")
    # the capture's blur at the centre of the photo's view of it, taken off the photo's smoothing
    rows, cols = np.nonzero(valid)
    centre = (int(np.median(rows)), int(np.median(cols)))
    blur = np.broadcast_to(Cc[centre], (2, 2, 2)).copy()
    ch = evaluate_displacement(delta_o, valid, distance_m=Lo, mm_per_px=mpp_o, detrend_degree=N, sigma_mm=S,
                               jacobian=J, component_blur_px2=blur)
    stats = {name: channel_statistics(getattr(ch, name), trusted) for name in CHANNELS}
    warnings = []
    total = np.asarray(ch.phi_total_mD)[trusted]
    strain = float(np.nanmax(total)) * Lo / 1000.0 if total.size else 0.0
    if strain > STRAIN_LIMIT:
        warnings.append(f"the predicted strain reaches {strain:.3g} (phi_total {float(np.nanmax(total)):.3g} mD over "
                        f"Lo = {Lo:g} m): above {STRAIN_LIMIT:g} the first-order reading of a photo (the small-strain "
                        "A3 channels, and the demodulation that has to follow so stretched a pattern) stops holding; "
                        "a photo from there may not confirm the prediction")
    incidence = np.degrees(np.arccos(np.clip(a[..., 2], -1.0, 1.0)))
    inc = float(incidence[valid].max())
    # second order in the deflection: it turns the line of sight, and m_t with it, by d ln m_t / d alpha |dtheta|
    turn = float(np.abs(dth[valid]).max()) * 1e-3 * _log_slope(inc, n)
    if inc > INCIDENCE_LIMIT_DEG:
        warnings.append(f"the photo sees the captured pane area at up to {inc:.3g} deg incidence: beyond "
                        f"{INCIDENCE_LIMIT_DEG:g} deg the first-order chain (thin prism, sec projections) is not "
                        "validated against exact refraction")
    if turn > SECOND_ORDER_LIMIT:
        warnings.append(f"at {inc:.3g} deg incidence the pane's own deflection (up to "
                        f"{float(np.abs(dth[valid]).max()):.3g} mrad) changes the projection factors by "
                        f"{100 * turn:.2g} %: the small-angle (first-order) model stops holding there")
    if theta == 0.0 and inc > FIELD_ANGLE_LIMIT_DEG:
        warnings.append(f"the observer sees the captured pane area at up to {inc:.3g} deg off the normal: above "
                        f"{FIELD_ANGLE_LIMIT_DEG:g} deg the variation of the projection factors across the pane "
                        "(neglected) grows")
    camera = {"position_mm": list(cam.position_mm), "yaw_deg": cam.yaw_deg, "pitch_deg": cam.pitch_deg,
              "focal_length_px": cam.focal_length_px, "pixels": [W, H],
              "frame": "pane centre at the origin, x along the capture's columns, y along its rows, z the pane "
                       "normal towards the backdrop (glassdist.scene's camera convention)"}
    return ViewPrediction(ch.phi_eff_mD, ch.phi_shear_mD, ch.phi_total_mD, ch.axis_deg, ch.displacement_detrended_mm,
                          valid, trusted, stats, cap, CaptureGeometry(Do, Lo, n), S, N, mpp_o,
                          centre_factor(Do, Lo, theta, n), theta, psi, float(np.median(incidence[valid])), camera,
                          tuple(warnings))


def _log_slope(incidence_deg: float, n: float) -> float:
    """``d ln m_t / d alpha`` (per rad) at ``incidence_deg``: how fast the larger projection factor grows."""
    a, h = math.radians(incidence_deg), 1e-4
    return float(abs(math.log(projection_factors(a + h, n)[0] / projection_factors(max(a - h, 0.0), n)[0])) /
                 (a + h - max(a - h, 0.0)))
