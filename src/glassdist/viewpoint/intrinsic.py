"""The pane's own distortion: the intrinsic reading of a capture.

A capture reads the strain of the backdrop displacement, ``phi = sym(grad delta) / L``
(gradients with respect to backdrop mm). Both the camera-to-pane distance ``Dc`` and the
pane-to-backdrop distance ``L`` enter it. The pane's *equivalent thin surface* is the net
angular deflection it gives a ray at normal incidence, ``dtheta(x_p)`` (mrad) on pane
coordinates ``x_p`` (mm); its intrinsic channels are those of ``grad_x dtheta`` (mD),
what an orthographic observer at normal incidence reads with the backdrop at any
distance.

The geometric chain (paper §3.1, :mod:`glassdist.theory.model`), pane and backdrop
parallel, the camera on the pane normal through the pane centre (the image centre):

1. Pinhole projection. The line of sight through the pane point ``x_p`` lands on the
   backdrop at ``x_b = x_p (Dc + L) / Dc`` (central projection between parallel planes,
   exact), and meets the pane at the field angle ``alpha``, ``tan alpha = |x_p| / Dc``,
   in the plane of incidence along ``t = x_p / |x_p|`` (``s`` = ``t`` turned by +90 deg).
2. Thin prism (Spencer and Murty 1962, linearised). A wedge ``Delta g`` between the faces
   turns the ray by ``K0 Delta g``, ``K0 = n cos(beta) - cos(alpha)``, ``sin(beta) =
   sin(alpha) / n``; in the plane of incidence the angle of the ray turns by
   ``kappa_t Delta g_t``, ``kappa_t = K0 cos(alpha) + sin(alpha) sin(beta) (n^2 cos(beta) /
   cos(alpha) - n)``, across it by ``K0 Delta g_s``. At normal incidence both are
   ``(n - 1) Delta g =: dtheta``, the intrinsic deflection.
3. Projection on the backdrop (the ``sec alpha`` and ``sec^2 alpha`` factors). Over the
   path ``L / cos(alpha)``, ``delta_t = L sec^2(alpha) kappa_t / (n - 1) dtheta_t`` and
   ``delta_s = L sec(alpha) K0 / (n - 1) dtheta_s``, i.e. ``delta = L M dtheta`` with
   ``M = diag(m_t, m_s)`` in the ``(t, s)`` frame (:func:`projection_factors`; ``M -> I`` at
   ``alpha -> 0``).

Hence, neglecting the slow variation of ``M`` (second order in ``alpha`` times
``dtheta``), the capture's tensor ``E = 1000 sym(grad_b delta) / L`` (mD) and the
intrinsic tensor ``G = 1000 grad_p dtheta`` (mD, symmetric: ``dtheta`` is a gradient
field) are related, in the ``(t, s)`` frame, by

.. math::

   E_{ij} = k\\,\\frac{m_i + m_j}{2}\\,G_{ij}, \\qquad k = \\frac{D_c}{D_c + L},

so a thin lens of power ``P`` (``dtheta = -P x_p``) reads ``phi_eff = -2 P k`` in a
capture and ``-2 P`` intrinsically. The capture's smoothing ``sigma`` on the backdrop is
``sigma k`` on the pane.

Small-angle limits: first order in the deflection and the face slopes; the lateral
shift of the slab (``-d (1 - 1/n) grad h``, independent of ``L``, relative size
``d / (n L)``) is neglected, as is the change of ``M`` across the pane; ``n`` is the
glass's refractive index (default soda-lime, 1.52), entering only through
``M`` (a few per cent at 15 deg field angle, quadratically less near the axis).

Oblique captures (:class:`CaptureGeometry` with ``viewing_angle_deg``, the camera aimed at the
pane centre along ``a0``): each pixel's line of sight is met with the pane
(:func:`pane_coordinates`, which needs the focal length in px), the plane of incidence ``t``
and the incidence ``alpha`` are those of the line from the camera to that pane point, and
``k = h / (h + L)`` with ``h = Dc cos(theta)`` (pane and backdrop parallel: still a uniform
scale). The relation above holds unchanged (:func:`projection_matrix`). Two limits of the
capture itself remain: its smoothing, isotropic in its pixels, is elongated on the pane along
the plane of incidence (``pane_sigma_mm`` is then the geometric mean), and its detrend, a
polynomial in its pixels, is projective on the pane, so off the normal it takes a different
field out of the pane than a normal capture does. ``glassdist analyze`` reads an oblique
capture with ``--camera-angle-deg`` (or the angle the Direct homography gives,
:mod:`glassdist.viewpoint.pose`).

References
----------
Spencer, G. H. and Murty, M. V. R. K. (1962). *J. Opt. Soc. Am.* 52(6), 672-678.
Hecht, E. (2017). *Optics*, 5th ed., §5.5.
Paper §3.1 ("a fully panel-intrinsic metric is future work").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..analyzer.metrics import channel_statistics
from ..analyzer.reflection import power_channels, strain_from_channels
from ..errors import InputError

__all__ = [
    "DEFAULT_REFRACTIVE_INDEX",
    "INTRINSIC_FIELDS",
    "CaptureGeometry",
    "IntrinsicReading",
    "capture_factor",
    "intrinsic_members",
    "intrinsic_reading",
    "intrinsic_section",
    "pane_coordinates",
    "pane_to_pixels",
    "projection_factors",
    "projection_matrix",
    "reading_of_result",
    "reference_factor",
    "result_geometry",
    "transfer_tensor",
]

#: Soda-lime float glass.
DEFAULT_REFRACTIVE_INDEX = 1.52

#: The intrinsic maps, keys in ``result.npz``.
INTRINSIC_FIELDS = ("intrinsic_phi_eff_mD", "intrinsic_phi_shear_mD", "intrinsic_phi_total_mD", "intrinsic_axis_deg",
                    "intrinsic_phi_eff_sigma_mD", "intrinsic_phi_shear_sigma_mD")


@dataclass(frozen=True)
class CaptureGeometry:
    """Where a capture (or a predicted photo) was taken from.

    Attributes
    ----------
    camera_distance_m : float
        Camera (pinhole) to the pane centre along the line of sight, ``Dc``, m (along the
        normal at normal incidence).
    distance_m : float
        Pane to backdrop, ``L``, m.
    refractive_index : float
        The glass's ``n`` (enters the oblique factors of off-axis pixels only).
    viewing_angle_deg, viewing_azimuth_deg : float
        The line of sight to the pane centre: its angle ``theta`` to the normal and azimuth
        ``psi`` (``glassdist view``'s convention; 0: normal incidence).
    focal_length_px : float, optional
        The camera's focal length in px: needed off the normal, where pixels map to the pane
        projectively (:func:`pane_coordinates`).
    """

    camera_distance_m: float
    distance_m: float
    refractive_index: float = DEFAULT_REFRACTIVE_INDEX
    viewing_angle_deg: float = 0.0
    viewing_azimuth_deg: float = 0.0
    focal_length_px: float | None = None

    def __post_init__(self):
        for name in ("camera_distance_m", "distance_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive number of metres, got {v!r}")
        if not (1.0 < self.refractive_index < 3.0):
            raise InputError(f"refractive_index must lie in (1, 3), got {self.refractive_index!r}")
        if not (0.0 <= self.viewing_angle_deg < 70.0):
            raise InputError(f"the viewing angle must lie in [0, 70) deg, got {self.viewing_angle_deg!r}")
        if self.viewing_angle_deg > 0 and not (self.focal_length_px and self.focal_length_px > 0):
            raise InputError("an oblique capture needs the camera's focal length in px (focal_length_px) to place "
                             "its pixels on the pane")

    @property
    def sight_direction(self) -> np.ndarray:
        """The unit line of sight to the pane centre, ``(sin theta cos psi, sin theta sin psi, cos theta)``."""
        t, p = math.radians(self.viewing_angle_deg), math.radians(self.viewing_azimuth_deg)
        return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])

    @property
    def position_mm(self) -> np.ndarray:
        """The camera in the pane frame (origin the pane centre, z the normal towards the backdrop), mm."""
        return -1000.0 * self.camera_distance_m * self.sight_direction

    @property
    def factor(self) -> float:
        """``k = h / (h + L)``, ``h = Dc cos(theta)``: the pane-to-backdrop scale between parallel planes
        (:func:`capture_factor` at normal incidence)."""
        h = self.camera_distance_m * math.cos(math.radians(self.viewing_angle_deg))
        return capture_factor(h, self.distance_m)


def capture_factor(camera_distance_m, distance_m):
    """``Dc / (Dc + L)``: what a capture at normal incidence reads of a unit intrinsic power (on the axis).

    Examples
    --------
    >>> capture_factor(3.0, 1.0)
    0.75
    """
    return camera_distance_m / (camera_distance_m + distance_m)


def projection_factors(alpha_rad, n: float = DEFAULT_REFRACTIVE_INDEX):
    """``(m_t, m_s)``: backdrop displacement per ``L`` per intrinsic deflection, along and across the plane of incidence.

    ``m_t = sec^2(alpha) kappa_t / (n - 1)``, ``m_s = sec(alpha) K0 / (n - 1)`` (module notes,
    steps 2-3); both 1 at ``alpha = 0``.
    """
    a = np.asarray(alpha_rad, float)
    sa, ca = np.sin(a), np.cos(a)
    sb = sa / n
    cb = np.sqrt(1.0 - sb * sb)
    K0 = n * cb - ca
    kt = K0 * ca + sa * sb * (n * n * cb / ca - n)
    return kt / ((n - 1.0) * ca * ca), K0 / ((n - 1.0) * ca)


def projection_matrix(directions, n: float = DEFAULT_REFRACTIVE_INDEX):
    """``M`` (..., 2, 2): backdrop displacement per ``L`` per intrinsic deflection, ``delta = L M dtheta``, at any incidence.

    ``directions``: unit lines of sight (..., 3) in the pane frame (x, y along the pane, z its
    normal towards the backdrop). With ``t`` the in-plane direction of the line of sight
    (module notes, steps 2-3),

    .. math::

       M = \\frac{1}{(n - 1)\\cos\\alpha}\\left[K_0 I + \\tan\\alpha\\,\\sin\\beta
           \\left(\\frac{n^2\\cos\\beta}{\\cos\\alpha} - n\\right) t\\,t^T\\right],

    whose eigenvalues are ``(m_t, m_s)`` of :func:`projection_factors`; ``M = I`` at normal incidence.
    The deflection comes from the wedge ``Delta g = dtheta / (n - 1)`` through the thin prism,
    projected over the path ``L / cos(alpha)`` along the line of sight (the ``sec`` factors).
    """
    a = np.asarray(directions, float)
    ca = a[..., 2]
    sa = np.hypot(a[..., 0], a[..., 1])
    safe = np.where(sa > 1e-14, sa, 1.0)
    tx, ty = np.where(sa > 1e-14, a[..., 0] / safe, 1.0), np.where(sa > 1e-14, a[..., 1] / safe, 0.0)
    sb = sa / n
    cb = np.sqrt(1.0 - sb * sb)
    K0 = n * cb - ca
    c2 = (sa / ca) * sb * (n * n * cb / ca - n)
    t = np.stack([tx, ty], -1)
    M = K0[..., None, None] * np.eye(2) + c2[..., None, None] * t[..., :, None] * t[..., None, :]
    return M / ((n - 1.0) * ca)[..., None, None]


def centre_factor(distance_to_centre_m: float, background_distance_m: float, viewing_angle_deg: float = 0.0,
                  n: float = DEFAULT_REFRACTIVE_INDEX) -> float:
    """A reading's mean power per unit intrinsic power at the pane centre: ``h / (h + L) (m_t + m_s) / 2``.

    ``h = D cos(theta)``, the observer's height above the pane; ``Dc / (Dc + L)`` at normal
    incidence (:func:`capture_factor`).
    """
    h = distance_to_centre_m * math.cos(math.radians(viewing_angle_deg))
    mt, ms = projection_factors(math.radians(viewing_angle_deg), n)
    return float(h / (h + background_distance_m) * 0.5 * (mt + ms))


def reference_factor(capture: CaptureGeometry, reference) -> float:
    """``k``: a statistic at ``reference`` over the same at the capture's (normal) geometry, at the pane centre.

    ``reference``: a :class:`glassdist.acceptance.spec.ReferenceGeometry` (or any object with its
    attributes). ``k = F_ref / F_cap`` with ``F`` of :func:`centre_factor` (``1`` for the
    intrinsic reading). Exact for an isotropic power at normal incidence; off the normal the
    plane of incidence reads ``m_t``, across it ``m_s``, so ``k`` is the mean of the two and a
    distortion along one direction reads up to ``|m_t - m_s| / (m_t + m_s)`` more or less
    (``glassdist view`` predicts it in full).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> ref = SimpleNamespace(intrinsic=False, observer_distance_m=10.0, background_distance_m=3.0, viewing_angle_deg=0.0)
    >>> round(reference_factor(CaptureGeometry(3.0, 1.0), ref), 4)  # (10 / 13) / (3 / 4)
    1.0256
    """
    cap = centre_factor(capture.camera_distance_m, capture.distance_m, 0.0, capture.refractive_index)
    if getattr(reference, "intrinsic", False):
        return 1.0 / cap
    return centre_factor(reference.observer_distance_m, reference.background_distance_m,
                         reference.viewing_angle_deg, capture.refractive_index) / cap


def pane_coordinates(rows_px, cols_px, image_shape, *, mm_per_px: float, geometry: CaptureGeometry):
    """Pane coordinates ``(x_p, y_p)`` (mm, from the pane centre; x along the columns, y along the rows) of pixels.

    Normal incidence: ``x_p = (c - c0) mm_per_px Dc / (Dc + L)`` with ``c0 = (W - 1) / 2`` (the
    camera aimed at the pane centre). Oblique: the pixel's line of sight (pinhole at
    :attr:`CaptureGeometry.position_mm`, ``focal_length_px``, the camera convention of
    :mod:`glassdist.scene`, no roll) met with the pane plane. ``rows_px``, ``cols_px`` broadcast
    against each other.
    """
    H, W = image_shape
    rows, cols = np.broadcast_arrays(np.asarray(rows_px, float), np.asarray(cols_px, float))
    if geometry.viewing_angle_deg == 0.0:
        s = mm_per_px * geometry.factor
        return (cols - (W - 1) / 2.0) * s, (rows - (H - 1) / 2.0) * s
    from ..scene.geometry import pixel_directions
    from ..scene.model import Camera

    a0 = geometry.sight_direction
    cam = Camera(focal_length_mm=float(geometry.focal_length_px) * 36.0 / W, sensor_width_mm=36.0,
                 pixels=(int(W), int(H)), position_mm=tuple(float(v) for v in geometry.position_mm),
                 yaw_deg=math.degrees(math.atan2(a0[0], a0[2])), pitch_deg=-math.degrees(math.asin(a0[1])))
    d = pixel_directions(cam, cols + 0.5, rows + 0.5)
    o = geometry.position_mm
    t = -o[2] / d[..., 2]
    return o[0] + t * d[..., 0], o[1] + t * d[..., 1]


def pane_to_pixels(x_mm, y_mm, image_shape, *, mm_per_px: float, geometry: CaptureGeometry):
    """Capture pixel coordinates ``(rows, cols)`` of pane points: the inverse of :func:`pane_coordinates`.

    Off the normal the pane plane maps to the image by a homography (a pinhole between
    planes), fitted exactly to :func:`pane_coordinates` of a grid of pixels.
    """
    H, W = image_shape
    x, y = np.broadcast_arrays(np.asarray(x_mm, float), np.asarray(y_mm, float))
    if geometry.viewing_angle_deg == 0.0:
        s = mm_per_px * geometry.factor
        return y / s + (H - 1) / 2.0, x / s + (W - 1) / 2.0
    import cv2

    r, c = np.meshgrid(np.linspace(0, H - 1, 9), np.linspace(0, W - 1, 9), indexing="ij")
    px, py = pane_coordinates(r, c, image_shape, mm_per_px=mm_per_px, geometry=geometry)
    Hm, _ = cv2.findHomography(np.stack([px.ravel(), py.ravel()], -1), np.stack([c.ravel(), r.ravel()], -1), 0)
    q = Hm @ np.stack([x.ravel(), y.ravel(), np.ones(x.size)])
    return (q[1] / q[2]).reshape(x.shape), (q[0] / q[2]).reshape(x.shape)


def _radial_frame(x_mm, y_mm, geometry: CaptureGeometry):
    """Incidence (rad) and the in-plane direction ``t`` (cos, sin) of the lines of sight through pane points."""
    o = geometry.position_mm
    dx, dy = np.asarray(x_mm, float) - o[0], np.asarray(y_mm, float) - o[1]
    r = np.hypot(dx, dy)
    alpha = np.arctan2(r, -o[2])
    safe = np.where(r > 0, r, 1.0)
    return alpha, np.where(r > 0, dx / safe, 1.0), np.where(r > 0, dy / safe, 0.0)


def _rotate(T, c, s):
    """``Q T Q^T`` with ``Q`` rows ``t = (c, s)`` and ``s_hat = (-s, c)``: ``(x, y)`` -> ``(t, s)`` components."""
    Q = np.stack([np.stack([c, s], -1), np.stack([-s, c], -1)], -2)
    return Q @ T @ np.swapaxes(Q, -1, -2), Q


def transfer_tensor(T, m_from, m_to, c, s):
    """Carry a tensor between readings with factors ``m_from`` to ``m_to`` per ``(t, s)`` axis.

    ``T_ij (m_to,i + m_to,j) / (m_from,i + m_from,j)`` in the ``(t, s)`` frame.

    ``m_from``, ``m_to``: pairs ``(m_t, m_s)``; ``(1, 1)`` for the intrinsic reading.
    """
    Tl, Q = _rotate(T, c, s)
    ft = np.stack([np.stack([2 * m_to[0], m_to[0] + m_to[1]], -1), np.stack([m_to[0] + m_to[1], 2 * m_to[1]], -1)], -2)
    fr = np.stack([np.stack([2 * m_from[0], m_from[0] + m_from[1]], -1),
                   np.stack([m_from[0] + m_from[1], 2 * m_from[1]], -1)], -2)
    Tl = Tl * ft / fr
    return np.swapaxes(Q, -1, -2) @ Tl @ Q


@dataclass(frozen=True)
class IntrinsicReading:
    """The pane's intrinsic channels on the grid of the capture they come from (NaN where invalid).

    Attributes
    ----------
    phi_eff_mD, phi_shear_mD, phi_total_mD : ndarray
        Channels of ``G = 1000 grad_p dtheta``, mD (converging lens < 0).
    axis_deg : ndarray
        Axis of the larger principal value of ``G``, degrees from +x towards +y, (-90, 90].
    phi_eff_sigma_mD, phi_shear_sigma_mD : ndarray or None
        The capture's standard uncertainties carried over (``/ (k m)``, ``m`` the mean factor).
    x_mm, y_mm : ndarray
        Pane coordinates of the samples, mm from the pane centre.
    field_angle_deg : ndarray
        The capture's field angle at each sample, degrees.
    geometry : CaptureGeometry
    pane_sigma_mm : float
        The capture's smoothing carried onto the pane, ``sigma Dc / (Dc + L)``, mm.
    pane_mm_per_px : float
        Pane mm per capture pixel.
    """

    phi_eff_mD: np.ndarray
    phi_shear_mD: np.ndarray
    phi_total_mD: np.ndarray
    axis_deg: np.ndarray
    phi_eff_sigma_mD: np.ndarray | None
    phi_shear_sigma_mD: np.ndarray | None
    x_mm: np.ndarray
    y_mm: np.ndarray
    field_angle_deg: np.ndarray
    geometry: CaptureGeometry
    pane_sigma_mm: float
    pane_mm_per_px: float

    def maps(self) -> dict:
        """``{key: map}`` of :data:`INTRINSIC_FIELDS` held (float32), for ``result.npz``."""
        vals = (self.phi_eff_mD, self.phi_shear_mD, self.phi_total_mD, self.axis_deg, self.phi_eff_sigma_mD,
                self.phi_shear_sigma_mD)
        return {k: np.asarray(v, np.float32) for k, v in zip(INTRINSIC_FIELDS, vals) if v is not None}


def intrinsic_reading(phi_eff_mD, phi_shear_mD, axis_deg, *, rows_px, cols_px, image_shape, mm_per_px: float,
                      sigma_mm: float, geometry: CaptureGeometry, phi_eff_sigma_mD=None,
                      phi_shear_sigma_mD=None) -> IntrinsicReading:
    """The intrinsic reading of a capture's channels at normal incidence (module notes).

    Parameters
    ----------
    phi_eff_mD, phi_shear_mD, axis_deg : ndarray (h, w)
        The capture's channels (``glassdist analyze``), on a grid of image samples.
    rows_px, cols_px : ndarray
        Image coordinates of the samples (broadcasting to (h, w)): ``(h, 1)`` and ``(1, w)``.
    image_shape : (int, int)
        The photo's ``(H, W)``; its centre is the camera's foot on the pane.
    mm_per_px : float
        The capture's backdrop mm per px.
    sigma_mm : float
        The smoothing the capture's channels carry, backdrop mm.
    geometry : CaptureGeometry
    phi_eff_sigma_mD, phi_shear_sigma_mD : ndarray, optional
        The capture's standard uncertainties.

    Returns
    -------
    IntrinsicReading

    Examples
    --------
    A thin lens of 10 mD (``phi_eff = -20 mD`` intrinsically) read at Dc 3 m, L 1 m on the axis:

    >>> import numpy as np
    >>> g = CaptureGeometry(camera_distance_m=3.0, distance_m=1.0)
    >>> r = intrinsic_reading(np.array([[-15.0]]), np.array([[0.0]]), np.array([[0.0]]), rows_px=np.array([[1.0]]),
    ...                       cols_px=np.array([[1.0]]), image_shape=(3, 3), mm_per_px=1.0, sigma_mm=40.0, geometry=g)
    >>> float(r.phi_eff_mD[0, 0]), r.pane_sigma_mm
    (-20.0, 30.0)
    """
    k = geometry.factor
    x, y = pane_coordinates(rows_px, cols_px, image_shape, mm_per_px=mm_per_px, geometry=geometry)
    x, y = np.broadcast_arrays(x, y)
    alpha, c, s = _radial_frame(x, y, geometry)
    mt, ms = projection_factors(alpha, geometry.refractive_index)
    E = strain_from_channels(phi_eff_mD, phi_shear_mD, axis_deg)
    G = transfer_tensor(E, (mt, ms), (np.ones_like(mt), np.ones_like(ms)), c, s) / k
    eff, shear, total, axis = power_channels(G)
    bad = ~(np.isfinite(phi_eff_mD) & np.isfinite(phi_shear_mD))
    for a in (eff, shear, total, axis):
        a[bad] = np.nan
    m = 0.5 * (mt + ms)

    def carried(u):
        return None if u is None else np.asarray(u, float) / (k * m)

    return IntrinsicReading(eff, shear, total, axis, carried(phi_eff_sigma_mD), carried(phi_shear_sigma_mD), x, y,
                            np.degrees(alpha), geometry, float(sigma_mm) * k, float(mm_per_px) * k)


def intrinsic_section(reading: IntrinsicReading, trusted, sources: dict | None = None) -> dict:
    """The ``intrinsic`` section of ``summary.json``: per channel the statistics ``statistics`` holds
    (``intrinsic.phi_eff_mD.mean_abs``, ...), the noise floor, the geometry and the smoothing.

    ``trusted``: the pixels the capture's statistics are taken over (bool, the reading's grid).
    ``sources``: where the angle and the focal length came from (:class:`glassdist.viewpoint.pose.CapturePose`).
    """
    g = reading.geometry
    stats = {name: channel_statistics(getattr(reading, name[len("intrinsic_"):]), trusted)
             for name in INTRINSIC_FIELDS[:3]}
    noise = {}
    for name in ("phi_eff_sigma_mD", "phi_shear_sigma_mD"):
        u = getattr(reading, name)
        if u is not None:
            v = u[np.asarray(trusted, bool) & np.isfinite(u)]
            noise[name] = {"median": float(np.median(v)) if v.size else float("nan"),
                           "p95": float(np.percentile(v, 95)) if v.size else float("nan")}
    fa = reading.field_angle_deg[np.asarray(trusted, bool)]
    return {
        **{k[len("intrinsic_"):]: v for k, v in stats.items()},
        "noise_floor_mD": noise,
        "camera_distance_m": g.camera_distance_m,
        "distance_m": g.distance_m,
        "refractive_index": g.refractive_index,
        "incidence": "normal" if g.viewing_angle_deg == 0 else "oblique",
        "viewing_angle_deg": g.viewing_angle_deg,
        "viewing_azimuth_deg": g.viewing_azimuth_deg,
        "focal_length_px": g.focal_length_px,
        **(sources or {"angle_source": "assumed normal"}),
        "capture_factor": g.factor,
        "pane_sigma_mm": reading.pane_sigma_mm,
        "pane_mm_per_px": reading.pane_mm_per_px,
        "max_field_angle_deg": float(fa.max()) if fa.size else float("nan"),
        "fields": list(reading.maps()),
        "conventions": {
            "phi_eff": "tr(1000 grad_p dtheta) in mD, dtheta the pane's net deflection at normal incidence (rad), "
                       "gradients w.r.t. pane mm; converging lens -> phi_eff < 0",
            "pane_coordinates": "mm from the pane centre (the image centre), x along the columns, y along the rows",
        },
    }


def result_geometry(result, camera_distance_m: float, refractive_index: float = DEFAULT_REFRACTIVE_INDEX):
    """The :class:`CaptureGeometry` of an analysis (its ``distance_m``) taken ``camera_distance_m`` from the pane."""
    return CaptureGeometry(float(camera_distance_m), float(result.distance_m), float(refractive_index))


def _carried_sigma_mm(sigma_mm, effective_sigma_mm) -> float:
    return float(max(sigma_mm, effective_sigma_mm or 0.0))


def reading_of_result(result, camera_distance_m: float, *, on_grid: bool = False,
                      refractive_index: float = DEFAULT_REFRACTIVE_INDEX,
                      geometry: CaptureGeometry | None = None) -> IntrinsicReading:
    """:func:`intrinsic_reading` of an :class:`~glassdist.analyzer.AnalysisResult` (transmission).

    ``on_grid``: on the analysis grid (NaN outside its analysed samples, the layout of
    ``result.npz``), else on the photo's pixel grid (the grid of its statistics).
    ``geometry``: the capture's (oblique) geometry; default normal incidence at ``camera_distance_m``.
    """
    if geometry is None:
        geometry = result_geometry(result, camera_distance_m, refractive_index)
    held = {f.name for f in result.field_specs()}
    if on_grid:
        rows, cols = result.analysis_grid.coords()
        gv = np.asarray(result.grid_valid, bool)

        def get(name):
            if name not in held:
                return None
            f = np.array(result.grid_field(name), dtype=float)
            f[~gv] = np.nan
            return f
        rows, cols = rows[:, :1], cols[:1, :]
    else:
        H, W = result.valid.shape
        rows, cols = np.arange(H, dtype=float)[:, None], np.arange(W, dtype=float)[None, :]

        def get(name):
            return np.asarray(getattr(result, name), float) if name in held else None
    return intrinsic_reading(get("phi_eff_mD"), get("phi_shear_mD"), get("axis_deg"), rows_px=rows, cols_px=cols,
                             image_shape=result.valid.shape, mm_per_px=result.mm_per_px,
                             sigma_mm=_carried_sigma_mm(result.sigma_mm, result.effective_sigma_mm), geometry=geometry,
                             phi_eff_sigma_mD=get("phi_eff_sigma_mD"), phi_shear_sigma_mD=get("phi_shear_sigma_mD"))


def intrinsic_members(result, camera_distance_m: float, layout: str, geometry: CaptureGeometry | None = None):
    """``result.npz`` members ``(name, array, compress)`` of the intrinsic maps, in the run's ``layout``."""
    reading = reading_of_result(result, camera_distance_m, on_grid=layout == "analysis", geometry=geometry)
    for name, a in reading.maps().items():
        yield name, a, False


def deflection_mrad(displacement_mm, x_mm, y_mm, geometry: CaptureGeometry) -> np.ndarray:
    """The intrinsic deflection ``dtheta = M^{-1} delta / L`` (mrad, (..., 2), x and y) of a capture's displacement.

    ``displacement_mm``: backdrop mm (..., 2); ``x_mm``, ``y_mm``: the pane points of its samples.
    """
    alpha, c, s = _radial_frame(x_mm, y_mm, geometry)
    mt, ms = projection_factors(alpha, geometry.refractive_index)
    d = np.asarray(displacement_mm, float)
    dt = (c * d[..., 0] + s * d[..., 1]) / (mt * geometry.distance_m)
    ds = (-s * d[..., 0] + c * d[..., 1]) / (ms * geometry.distance_m)
    return np.stack([c * dt - s * ds, s * dt + c * ds], axis=-1)

