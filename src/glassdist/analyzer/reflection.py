"""Reflected distortion: the reflective power of a pane from a grid board seen in it.

Capture geometry
----------------
A grid board faces the pane, parallel to it, at the board-to-pane distance ``D``; the
camera looks at the board's reflection in the pane, from the board plane (through a
hole in the board, the usual set-up) or from ``C`` (the camera-to-pane distance) when
``--camera-distance-m`` says so. The line of sight meets the pane at incidence ``theta``;
``t`` is the tangential direction (the plane of incidence, on the pane) and ``s`` the
sagittal one. Pane heights ``Z`` point away from the camera.

Flat mirror (the reference). A ray from the camera at ``c`` (lateral position
``c_perp``, distance ``C``) meets the pane at ``p`` and, reflected, lands on the board at

.. math:: X = p\\,(1 + D/C) - (D/C)\\,c_\\perp = m\\,p + \\text{const}, \\qquad m = 1 + D/C,

a similarity at every incidence: a pane point ``x`` is seen at the board point ``m x``
(``m = 2`` with the camera in the board plane).

Deformed pane. With slopes ``g = grad Z`` the normal turns and the reflected direction
changes, to first order, by ``2 cos(theta) g`` in the pane plane and
``2 (a_perp . g)`` along the normal (``a`` the unit incident direction). Carried back
over the distance ``D`` to the board, the landing point moves by

.. math::

   \\delta_t = \\frac{2 D}{\\cos^2\\theta}\\,Z_t, \\qquad \\delta_s = 2 D\\,Z_s

(at normal incidence ``delta = 2 D grad Z``: a slope change ``s`` deflects the reflected
ray by ``2 s``). The height itself moves the mirror image of the camera by
``2 Z tan(theta)`` along ``t``: a term in the slope, not the curvature, that the
definition below leaves out (relative size ``tan(theta) cos^2(theta) / (D k)`` for a
wave of wavenumber ``k``: 0 at normal incidence, ~1 % at 30 deg, D = 2 m, 300 mm).

Reflective power (one convention with transmission). The power is the change of the
reflected ray's direction per unit width of the reflected beam at the pane: a tangential
beam width ``w_t = x_t cos(theta)`` and the angular deflections
``alpha_t = 2 Z_t``, ``alpha_s = 2 cos(theta) Z_s`` give Coddington's equations for a
mirror,

.. math::

   P = 2 \\begin{pmatrix} Z_{tt}/\\cos\\theta & Z_{ts} \\\\ Z_{ts} & Z_{ss}\\cos\\theta \\end{pmatrix}
   \\qquad (P = 2\\,\\mathrm{Hess}\\,Z \\text{ at normal incidence}),

``phi_eff = tr P``, ``phi_shear`` the difference of its principal powers,
``phi_total = ||P||_F`` (x 1000: mD for ``Z`` in m). A concave pane (a converging mirror)
has ``Z_tt, Z_ss < 0`` and reads ``phi_eff < 0``: the sign rule of transmission. A sphere
of radius ``R`` (m): principal powers ``2000/(R cos theta)`` and ``2000 cos(theta)/R`` mD.

From the measurement. The Analyzer measures the board displacement and its strain
``eps = sym grad_X delta`` with respect to board mm ``X``; pane mm are ``x = X / m``, so
``grad_x delta = m grad_X delta``. With the two relations above, in the ``(t, s)`` frame,

.. math::

   P_{tt} = \\frac{m\\cos\\theta}{D}\\,\\varepsilon_{tt}, \\quad
   P_{ss} = \\frac{m\\cos\\theta}{D}\\,\\varepsilon_{ss}, \\quad
   P_{ts} = \\frac{m\\cos\\theta}{D}\\,\\frac{2\\cos\\theta}{1 + \\cos^2\\theta}\\,\\varepsilon_{ts}

(the gradient of a mirror's landing shift is ``diag(1/cos^2 theta, 1)`` times a symmetric
matrix: its symmetric part gives ``P_ts`` back through the last factor). At normal
incidence ``P = (m / D) eps``: the transmission channels at the effective distance
``L = D / m`` (``D / 2`` with the camera in the board plane), which is how
:func:`analyze_reflection` runs the Analyzer before turning its strain into ``P``.

The frame. ``P`` is the reflected beam's vergence tensor in the beam's transverse frame
``(t', s)``, ``t'`` the tangential direction across the beam, identified with ``t`` on the
image: the camera sees the pane foreshortened by ``cos(theta)`` along ``t``, as the beam width
is, so the image frame and the beam frame agree up to a scale and the maps' axes are read
on the image. The tangential, sagittal and cross factors are checked against the exact
reflection of cylinders at 0-60 deg incidence turned 0-90 deg to the plane of incidence
(``tests/test_reflection_oblique.py``).

What a single photo cannot give: in the Direct Method a uniform power is a uniform change
of scale of the board's image, which the homography absorbs, and a power changing linearly
across the view is, to first order, its keystone (projective) terms; a whole-pane bow is
read by the Comparative Method (a flat reference surface at the same place). A wave with a
few periods in view is not orthogonal to those terms either: its map is right but for a
plane of power. And the Direct Method measures the photo's carrier phase against the
homography's analytic one, so the demodulation's own small phase error on the board's
image (of the order of 1e-3 carrier period, which a reference photo cancels) is read as
power; at the short effective distance of reflection (``D / m``) it is a floor of a few
tenths of a millidioptre (``tests/test_reflection_oblique.py``: p95 |phi_eff| of a flat pane).

References
----------
Coddington, H. (1829). *A Treatise on the Reflexion and Refraction of Light*.
Kingslake, R. and Johnson, R. B. (2010). *Lens Design Fundamentals*, 2nd ed., §4.3
(Coddington's equations; for a mirror, n' = -n).
ASTM C1651-11, *Standard Test Method for Measurement of Roll Wave Optical Distortion in
Heat-Treated Flat Glass* (roll wave in mD of reflective power).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..validation import DISTANCE_M, check_number
from .metrics import channels_from_strain

if TYPE_CHECKING:
    from .result import Optics

__all__ = [
    "ReflectionGeometry",
    "coddington_power",
    "power_from_strain",
    "slope_strain",
    "power_channels",
    "strain_from_channels",
    "reflect_result",
    "analyze_reflection",
    "noise_correlation_mm",
    "UNIFORM_POWER_NOTE",
]

#: What the Direct Method's summary says about a whole-pane (uniform) power.
UNIFORM_POWER_NOTE = (
    "Direct Method: a uniform reflective power is a uniform change of scale of the board's image, and a power "
    "changing linearly across the view its keystone, both absorbed by the homography; a whole-pane bow is read by "
    "the Comparative Method (a flat reference surface at the same place)"
)


@dataclass(frozen=True)
class ReflectionGeometry:
    """The capture geometry of a reflected-grid measurement.

    Attributes
    ----------
    distance_m : float
        Board-to-pane distance D, m (board parallel to the pane).
    camera_distance_m : float or None
        Camera-to-pane distance C, m; None: the camera sits in the board plane (C = D).
    incidence_deg : float
        Angle of incidence theta of the line of sight on the pane at the view's centre, deg;
        elsewhere it follows from the position on the pane (:meth:`incidence`).
    plane_deg : float
        Direction of the plane of incidence (the tangential direction t) in the image, deg
        from +x (columns) towards +y (rows).
    """

    distance_m: float
    camera_distance_m: float | None = None
    incidence_deg: float = 0.0
    plane_deg: float = 0.0

    def __post_init__(self):
        check_number(self.distance_m, "distance_m (the board-to-pane distance D)", DISTANCE_M)
        if self.camera_distance_m is not None:
            check_number(self.camera_distance_m, "camera_distance_m (the camera-to-pane distance C)",
                         DISTANCE_M)
        if not (math.isfinite(self.incidence_deg) and 0.0 <= self.incidence_deg < 80.0):
            raise InputError(f"incidence_deg must be in [0, 80) deg, got {self.incidence_deg!r}; "
                             "give the angle between the line of sight and the pane normal")
        if not math.isfinite(self.plane_deg):
            raise InputError(f"plane_deg must be a finite angle in deg, got {self.plane_deg!r}")

    @property
    def magnification(self) -> float:
        """``m = 1 + D / C``: board mm per pane mm (2 with the camera in the board plane)."""
        c = self.distance_m if self.camera_distance_m is None else self.camera_distance_m
        return 1.0 + self.distance_m / c

    @property
    def effective_distance_m(self) -> float:
        """``D / m``: the transmission distance whose channels equal ``P`` at normal incidence, m."""
        return self.distance_m / self.magnification

    @property
    def pinned_camera_distance_m(self) -> float | None:
        """The camera-to-pane distance to pin the Direct bulk channel with, m, or None (C not given).

        The bulk channel pins the magnification at the camera-to-board distance ``camera_distance_m +
        distance_m`` (:func:`glassdist.analyzer.bulk.measured_bulk`); a reflection run analyses at
        ``D / m`` while the board lies ``C + D`` from the camera along the reflected line of sight
        (the mirror unfolds the path): ``C + D - D / m``.
        """
        if self.camera_distance_m is None:
            return None
        return self.camera_distance_m + self.distance_m - self.effective_distance_m

    def incidence(self, dx_mm, dy_mm):
        """Angle of incidence and plane of incidence (deg) at pane points offset from the view's centre.

        Parameters
        ----------
        dx_mm, dy_mm : ndarray
            Offsets on the pane from the point seen at the view's centre, pane mm, along the
            image's x and y.

        Returns
        -------
        incidence_deg, plane_deg : ndarray
            With the board parallel to the pane, the in-plane vector from the camera's foot
            to the point is ``v = C tan(theta_0) t_0 + (dx, dy)``: ``tan(theta) = |v| / C``,
            the plane of incidence along ``v``.
        """
        vx, vy = self.foot_offset_mm(dx_mm, dy_mm)
        return np.degrees(np.arctan(np.hypot(vx, vy) / self.camera_distance_mm)), np.degrees(np.arctan2(vy, vx))

    @property
    def camera_distance_mm(self) -> float:
        """The camera-to-pane distance C, mm (D with the camera in the board plane)."""
        return 1000.0 * (self.distance_m if self.camera_distance_m is None else self.camera_distance_m)

    def foot_offset_mm(self, dx_mm: np.ndarray | float, dy_mm: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """In-plane vector ``v`` (pane mm) from the camera's foot on the pane to the points offset by ``(dx, dy)``
        from the one seen at the view's centre: ``v = C tan(theta_0) t_0 + (dx, dy)``."""
        r0 = self.camera_distance_mm * math.tan(math.radians(self.incidence_deg))
        a0 = math.radians(self.plane_deg)
        return r0 * math.cos(a0) + np.asarray(dx_mm, float), r0 * math.sin(a0) + np.asarray(dy_mm, float)

    def optics(self, notes: tuple[str, ...] = ()) -> Optics:
        """The result's record of this geometry (``summary.json`` ``optics``), with ``notes`` on what the channels mean."""
        from .result import Optics

        return Optics(board_distance_m=self.distance_m,
                      camera_distance_m=self.distance_m if self.camera_distance_m is None else self.camera_distance_m,
                      camera_in_board_plane=self.camera_distance_m is None, incidence_deg=self.incidence_deg,
                      plane_of_incidence_deg=self.plane_deg, magnification=self.magnification,
                      effective_distance_m=self.effective_distance_m, notes=notes)




def _tensor_in_frame(tu, tv, ptt, pss, pts):
    """``Q^T [[ptt, pts], [pts, pss]] Q`` with ``Q`` rows ``t = (tu, tv)``, ``s = (-tv, tu)``: back to (u, v)."""
    su, sv = -tv, tu
    puu = tu * tu * ptt + 2 * tu * su * pts + su * su * pss
    pvv = tv * tv * ptt + 2 * tv * sv * pts + sv * sv * pss
    puv = tu * tv * ptt + (tu * sv + tv * su) * pts + su * sv * pss
    return np.stack([np.stack([puu, puv], -1), np.stack([puv, pvv], -1)], -2)


def _components_ts(E, tu, tv):
    """``(E_tt, E_ss, E_ts)`` of symmetric tensors ``E`` (..., 2, 2) along ``t = (tu, tv)``, ``s = (-tv, tu)``."""
    exx, eyy, exy = E[..., 0, 0], E[..., 1, 1], 0.5 * (E[..., 0, 1] + E[..., 1, 0])
    su, sv = -tv, tu
    return (tu * tu * exx + 2 * tu * tv * exy + tv * tv * eyy,
            su * su * exx + 2 * su * sv * exy + sv * sv * eyy,
            tu * su * exx + (tu * sv + tv * su) * exy + tv * sv * eyy)


def coddington_power(hessian, incidence_deg, tangent=(1.0, 0.0)) -> np.ndarray:
    """Reflective power tensor of a mirror from its Hessian (Coddington), 1 / length of the Hessian.

    Parameters
    ----------
    hessian : (array_like, array_like, array_like)
        ``(Z_uu, Z_uv, Z_vv)`` in some in-plane frame ``(u, v)``, ``Z`` pointing away from
        the camera (1/mm gives P in 1/mm; x 1e6 for mD).
    incidence_deg : array_like
        Angle of incidence theta, deg.
    tangent : (array_like, array_like)
        Unit tangential direction ``t = (t_u, t_v)`` (the plane of incidence on the surface).

    Returns
    -------
    ndarray (..., 2, 2)
        ``P`` in the ``(u, v)`` frame:
        ``P = 2 Q^T [[Z_tt / cos theta, Z_ts], [Z_ts, Z_ss cos theta]] Q``, ``Q`` rows t and s.
    """
    huu, huv, hvv = (np.asarray(h, float) for h in hessian)
    tu, tv = (np.asarray(t, float) for t in tangent)
    c = np.cos(np.radians(np.asarray(incidence_deg, float)))
    H = np.stack([np.stack([huu, huv], -1), np.stack([huv, hvv], -1)], -2)
    ztt, zss, zts = _components_ts(H, tu, tv)
    return _tensor_in_frame(tu, tv, 2 * ztt / c, 2 * zss * c, 2 * zts)


def power_from_strain(strain: np.ndarray, incidence_deg, plane_deg) -> np.ndarray:
    """Reflective power ``P`` from the board strain (module notes), in the strain's scale times ``D / m``.

    Parameters
    ----------
    strain : ndarray (..., 2, 2)
        ``eps = sym grad_X delta`` in the image frame (x, y), X in board mm, scaled by
        ``1000 m / D`` (D in mm) for P in mD (or by ``m / D`` for P in 1/mm).
    incidence_deg, plane_deg : float or ndarray (...)
        Angle of incidence theta and direction of the plane of incidence (deg from +x
        towards +y) at each sample (:meth:`ReflectionGeometry.incidence`).

    Returns
    -------
    ndarray (..., 2, 2)
        ``P`` in the image frame:
        ``P_tt = cos(theta) eps_tt``, ``P_ss = cos(theta) eps_ss``,
        ``P_ts = cos(theta) 2 cos(theta) / (1 + cos^2 theta) eps_ts``.
    """
    E = np.asarray(strain, float)
    c = np.cos(np.radians(np.asarray(incidence_deg, float)))
    a = np.radians(np.asarray(plane_deg, float))
    tu, tv = np.cos(a), np.sin(a)
    ett, ess, ets = _components_ts(E, tu, tv)
    return _tensor_in_frame(tu, tv, c * ett, c * ess, c * (2 * c / (1 + c * c)) * ets)


def slope_strain(strain: np.ndarray, displacement_mm: np.ndarray, vx_mm, vy_mm, geometry: ReflectionGeometry):
    """The board strain of the slope field alone: the strain less the terms of the landing factor's variation.

    Parameters
    ----------
    strain : ndarray (..., 2, 2)
        ``eps = sym grad_X delta`` (X in board mm), dimensionless, image frame.
    displacement_mm : ndarray (..., 2)
        The board displacement ``delta`` it comes from, board mm, image frame.
    vx_mm, vy_mm : ndarray (...)
        In-plane vector from the camera's foot to each sample on the pane, pane mm
        (:meth:`ReflectionGeometry.foot_offset_mm`).
    geometry : ReflectionGeometry

    Returns
    -------
    ndarray (..., 2, 2)
        ``eps - sym((2 / C) v g^T) - (2 D / (m C^2)) (v . g) I`` with ``g = M^{-1} delta``.

    Notes
    -----
    The landing shift of a pane with slopes ``g = grad Z`` and heights ``Z`` is, to first
    order, ``delta = M(v) g + (2 Z / C) v`` with ``M(v) = 2 D (I + v v^T / C^2)`` (``2 D / cos^2
    theta`` along the plane of incidence ``t = v / |v|``, ``2 D`` across it: ``tan(theta) =
    |v| / C``) and ``2 Z tan(theta)`` the mirror image of the camera moving with the surface.
    The factor varies over the pane, so the gradient of ``delta`` with respect to pane mm
    ``x = X / m`` is not ``M Hess Z`` alone:

    .. math::

       \\nabla_x \\delta = M\\,\\mathrm{Hess}\\,Z + \\frac{2 m}{C}\\, v\\, g^T
           + \\frac{2 D}{C^2} (v \\cdot g)\\, I + \\frac{2 Z}{C} I .

    The two slope terms are removed here with ``g = M^{-1} delta`` (``M^{-1} = (I - v v^T /
    (C^2 + |v|^2)) / 2 D``); relative to the curvature term they are about
    ``2 tan(theta) cos^2(theta) (1 + m/2) / (D k)`` for a wave of wavenumber ``k`` (4 % at
    20 deg, D = 2 m, 400 mm), and off the axis at normal incidence they grow with the distance
    from the camera's foot. The height term, ``Z / (D C k^2 Z)`` relative (0.1 % for the
    same wave), is left out: it needs ``Z`` itself.
    """
    C, D, m = geometry.camera_distance_mm, 1000.0 * geometry.distance_m, geometry.magnification
    vx, vy = np.asarray(vx_mm, float), np.asarray(vy_mm, float)
    dx, dy = displacement_mm[..., 0], displacement_mm[..., 1]
    vd = (vx * dx + vy * dy) / (C * C + vx * vx + vy * vy)
    gx, gy = (dx - vx * vd) / (2 * D), (dy - vy * vd) / (2 * D)
    k = 2.0 / C
    iso = 2 * D / (m * C * C) * (vx * gx + vy * gy)
    cxx, cyy, cxy = k * vx * gx + iso, k * vy * gy + iso, 0.5 * k * (vx * gy + vy * gx)
    corr = np.stack([np.stack([cxx, cxy], -1), np.stack([cxy, cyy], -1)], -2)
    return np.asarray(strain, float) - corr


def power_channels(P: np.ndarray):
    """``(phi_eff, phi_shear, phi_total, axis_deg)`` of a power tensor (in its unit): trace,
    difference of the principal powers, Frobenius norm, axis of the larger principal power."""
    return channels_from_strain(np.asarray(P, float), 1000.0)


def strain_from_channels(phi_eff, phi_shear, axis_deg) -> np.ndarray:
    """The symmetric tensor ``(..., 2, 2)`` whose channels (:func:`power_channels`) are the ones given.

    Principal values ``(phi_eff +- phi_shear) / 2``, the larger along ``axis_deg``.
    """
    a = np.radians(np.asarray(axis_deg, float))
    mean, half = 0.5 * np.asarray(phi_eff, float), 0.5 * np.asarray(phi_shear, float)
    c2, s2 = np.cos(2 * a), np.sin(2 * a)
    xx, yy, xy = mean + half * c2, mean - half * c2, half * s2
    return np.stack([np.stack([xx, xy], -1), np.stack([xy, yy], -1)], -2)


def reflect_result(result, geometry: ReflectionGeometry):
    """The reflective-power result of an Analyzer run at ``distance_m = geometry.effective_distance_m``.

    Parameters
    ----------
    result : AnalysisResult
        From :func:`glassdist.analyze` with ``distance_m = D / m`` and the smoothing on the
        board (``sigma_mm`` = m x the pane's).
    geometry : ReflectionGeometry

    Returns
    -------
    AnalysisResult
        ``phi_eff_mD``, ``phi_shear_mD``, ``phi_total_mD``, ``axis_deg`` and the uncertainty
        maps in reflective power (:func:`power_from_strain`); ``mm_per_px`` and ``sigma_mm``
        in pane mm (board / m); ``distance_m`` = D; the incidence at each sample from its offset
        from the image centre (pane mm = pixels x ``mm_per_px`` / m, :meth:`ReflectionGeometry.incidence`);
        ``displacement_mm`` stays the measured board displacement; ``optics`` names the geometry.
    """
    if not math.isclose(result.distance_m, geometry.effective_distance_m, rel_tol=1e-9):
        raise ValueError("reflect_result needs the result of a run at distance_m = geometry.effective_distance_m")
    fields = result.grid_fields()
    m = geometry.magnification
    yy, xx = result.analysis_grid.coords()
    H, W = result.valid.shape
    pane_mm_per_px = result.mm_per_px / m
    dx_mm, dy_mm = (xx - W / 2) * pane_mm_per_px, (yy - H / 2) * pane_mm_per_px
    theta, plane = geometry.incidence(dx_mm, dy_mm)
    scale = 1000.0 / geometry.effective_distance_m  # the channels are eps x 1000 / L, L = D / m in m
    eps = strain_from_channels(fields["phi_eff_mD"], fields["phi_shear_mD"], fields["axis_deg"]) / scale
    eps = scale * slope_strain(eps, np.nan_to_num(fields["displacement_mm"].astype(float)),
                               *geometry.foot_offset_mm(dx_mm, dy_mm), geometry)
    eff, shear, total, axis = power_channels(power_from_strain(eps, theta, plane))
    finite = np.isfinite(fields["phi_eff_mD"])
    c = np.cos(np.radians(theta))
    for name, val in (("phi_eff_mD", eff), ("phi_shear_mD", shear), ("phi_total_mD", total), ("axis_deg", axis)):
        fields[name] = np.where(finite, val, np.nan).astype(fields[name].dtype)
    for name in ("phi_eff_sigma_mD", "phi_shear_sigma_mD"):  # the t and s channels scale by cos(theta)
        if name in fields:
            fields[name] = (fields[name] * c).astype(fields[name].dtype)
    notes: tuple[str, ...] = (
        "phi in reflective power on the pane (Coddington: P = 2 [[Z_tt/cos, Z_ts], [Z_ts, Z_ss cos]]); "
        "concave pane -> phi_eff < 0; mm_per_px and sigma_mm in pane mm; displacement_mm in board mm",)
    if result.method == "direct":
        notes += (UNIFORM_POWER_NOTE,)
    optics = geometry.optics(notes)
    eff_sigma = None if result.effective_sigma_mm is None else result.effective_sigma_mm / m
    from ..flatness.slope import with_surface_fields

    return with_surface_fields(result.with_grid_fields(  # with the front face's slope and height
        fields, distance_m=geometry.distance_m, mm_per_px=result.mm_per_px / m, sigma_mm=result.sigma_mm / m,
        effective_sigma_mm=eff_sigma, optics=optics,
    ), geometry, correlation_mm=noise_correlation_mm(result) / m)


def noise_correlation_mm(result) -> float:
    """Standard deviation of the Gaussian that correlates the displacement's noise, in the result's mm.

    ``displacement_mm`` carries Block F's low-pass (the bandpass, then the complex smoothing:
    :func:`glassdist.analyzer.demodulate.demodulation_blur_px2`), not the metric smoothing; white image
    noise through it is white noise through a Gaussian of that covariance. Returned: its isotropic
    standard deviation ``sqrt(tr C / 2)``, averaged over the two carriers, px x ``result.mm_per_px``.
    """
    from .demodulate import covariances, demodulation_blur_px2

    C = demodulation_blur_px2(result.carriers, covariances(result.carriers, result.params), result.params)
    return float(np.sqrt(np.mean(np.trace(C, axis1=1, axis2=2)) / 2.0)) * float(result.mm_per_px)


def analyze_reflection(image, *, pitch_mm: float, geometry: ReflectionGeometry, reference=None, params=None,
                       mask=None, pattern: str | None = None, detrend_degree: int | None = None,
                       sigma_mm: float | None = None, lens=None):
    """Measure the reflective power of a pane from a photo of a grid board reflected in it.

    Parameters
    ----------
    image, reference, params, mask, pattern, detrend_degree
        As for :func:`glassdist.analyze` (the reference: the same board reflected in a flat
        reference surface at the same place: Comparative Method; none: Direct Method).
    pitch_mm : float
        Pitch of the board's grid, mm.
    geometry : ReflectionGeometry
    sigma_mm : float, optional
        Reporting smoothing scale on the pane, mm (default: 2 carrier periods of the
        board's image, i.e. 2 p_c / m on the pane).
    lens : LensCalibration, optional
        The camera's lens (:func:`glassdist.analyzer.lens.calibration_from_camera_file`): with the
        Direct Method and ``geometry.camera_distance_m`` it pins the magnification, so that the
        bulk channel reads the pane's uniform curvature (:attr:`ReflectionGeometry.pinned_camera_distance_m`;
        the bow of :func:`glassdist.flatness.flatness_measures`).

    Returns
    -------
    AnalysisResult
        See :func:`reflect_result`.

    Examples
    --------
    A concave sphere of radius 20 m, camera in the board plane at D = 2 m, seen by a
    synthetic capture with the board displacement of the module notes:

    >>> import numpy as np
    >>> from glassdist.analyzer.reflection import ReflectionGeometry, analyze_reflection
    >>> from glassdist.synthetic import synthetic_capture
    >>> g = ReflectionGeometry(distance_m=2.0)
    >>> def sphere(X, Y):  # board mm -> board displacement 2 D (I + v v^T / C^2) grad Z at the pane point v = X / m
    ...     x, y = X / g.magnification, Y / g.magnification
    ...     k = -2 * 2000.0 / 20000.0 * (1 + (x * x + y * y) / 2000.0**2)
    ...     return k * x, k * y
    >>> cap = synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25, displacement=sphere)
    >>> res = analyze_reflection(cap.image, pitch_mm=10.0, geometry=g, reference=cap.reference, detrend_degree=0)
    >>> round(float(np.nanmedian(res.phi_eff_mD)))  # -4000 / R
    -200
    """
    from .params import AnalyzerParams, load_params
    from .pipeline import ReferenceModel, analyze

    m = geometry.magnification
    if not isinstance(params, AnalyzerParams):
        params = reference.params if params is None and isinstance(reference, ReferenceModel) else load_params(params)
    if sigma_mm is None and params.sigma_mm is not None:  # a parameter file's sigma_mm is on the pane too
        sigma_mm = params.sigma_mm
    board_sigma = None if sigma_mm is None else float(sigma_mm) * m
    pin = geometry.pinned_camera_distance_m if lens is not None and reference is None else None
    res = analyze(image, pitch_mm=pitch_mm, distance_m=geometry.effective_distance_m, reference=reference,
                  params=params, mask=mask, pattern=pattern, detrend_degree=detrend_degree, sigma_mm=board_sigma,
                  lens=lens, camera_distance_m=pin)
    return reflect_result(res, geometry)
