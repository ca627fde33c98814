"""Surface slope and height of the pane's front face from a reflection result.

In reflection the board displacement is set by the front face's slope
(:mod:`glassdist.analyzer.reflection`, "Deformed pane"): to first order

.. math::

   \\delta = M(v)\\,\\nabla Z, \\qquad M(v) = 2 D \\left(I + \\frac{v v^T}{C^2}\\right),

``2 D / cos^2(theta)`` along the plane of incidence and ``2 D`` across it (at normal
incidence ``delta = 2 D grad Z``: a slope ``s`` deflects the reflected ray by ``2 s``), ``v`` the
in-plane vector from the camera's foot to the point, ``tan(theta) = |v| / C``. Its inverse,

.. math:: \\nabla Z = M^{-1} \\delta = \\frac{1}{2 D}\\left(I - \\frac{v v^T}{C^2 + |v|^2}\\right)\\delta,

gives the slope at each sample of the analysis grid from the measured board displacement
``displacement_mm`` (before the A2 detrend and the metric smoothing: the slope is detrended
here, at degree N - 1, so that the height, its integral, is detrended at degree N). The
height term ``2 Z v / C`` of the landing shift is left out (relative size
``|v| |Z| / (C D |grad Z|)``: 0.6 % at 500 mm off the camera's foot for a 0.1 mm, 300 mm
wave, D = C = 2 m). The height is the masked least-squares integral of the slope
(:func:`glassdist.flatness.integrate.integrate_slope`), then detrended at degree N over the
region.

Frame and scale: ``x`` along the image columns, ``y`` along the rows, pane mm. The pane mm
per pixel are the result's ``mm_per_px`` (board mm / m), and at oblique incidence, with the
plane of incidence along an image axis, ``mm_per_px / sqrt(cos theta)`` along it and
``mm_per_px sqrt(cos theta)`` across (the foreshortening :func:`glassdist.measures.standard_measures`
uses): a mean scale over the view, the keystone of an oblique view left out.

What the detrend and the method leave: the Direct Method's displacement is relative to the
homography baseline, which takes a uniform slope (a tilt), a uniform curvature (a bow: a
change of scale of the board's image) and its keystone terms; the Comparative Method's is
relative to the flat reference surface, and keeps them but for the degree-N detrend.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .integrate import integrate_slope

__all__ = [
    "SurfaceFields",
    "landing_slope",
    "pane_step_mm",
    "polynomial_detrend",
    "surface_fields",
    "with_surface_fields",
]


@dataclass(frozen=True)
class SurfaceFields:
    """The front face's slope and height on the analysis grid of a reflection result.

    Attributes
    ----------
    slope_mrad : ndarray (h, w, 2) float32
        ``(dZ/dx, dZ/dy)``, mrad (µm per mm), trend of degree N - 1 removed; NaN outside the region.
    height_um : ndarray (h, w) float32
        Height ``Z`` (away from the camera), µm, detrended at degree N; NaN outside the region.
    slope_sigma_mrad : ndarray (h, w, 2) float32 or None
        Standard uncertainty of ``slope_mrad`` from the image noise (the displacement's,
        through ``M^{-1}``); None when the result has none.
    region : ndarray (h, w) bool
        The samples integrated and detrended over.
    step_mm : (float, float)
        Pane mm per sample along rows and columns.
    detrend_degree : int
        N: the height's detrend degree (the slope's is N - 1; none for N = 0, the mean of the height removed).
    """

    slope_mrad: np.ndarray
    height_um: np.ndarray
    slope_sigma_mrad: np.ndarray | None
    region: np.ndarray
    step_mm: tuple[float, float]
    detrend_degree: int


def landing_slope(displacement_mm: np.ndarray, vx_mm, vy_mm, geometry,
                  sigma_mm: np.ndarray | None = None):
    """Slope ``grad Z = M^{-1} delta`` of the front face from the board displacement (module notes).

    Parameters
    ----------
    displacement_mm : ndarray (..., 2)
        Board displacement ``delta``, board mm, image frame.
    vx_mm, vy_mm : ndarray (...)
        In-plane vector from the camera's foot to each sample, pane mm
        (:meth:`~glassdist.analyzer.reflection.ReflectionGeometry.foot_offset_mm`).
    geometry : ReflectionGeometry
        The capture geometry (:class:`glassdist.analyzer.reflection.ReflectionGeometry`): ``distance_m``
        and ``camera_distance_mm`` are read.
    sigma_mm : ndarray (..., 2), optional
        Standard uncertainty of each component of ``delta`` (independent), board mm.

    Returns
    -------
    slope : ndarray (..., 2)
        ``(dZ/dx, dZ/dy)``, dimensionless.
    slope_sigma : ndarray (..., 2) or None
        ``sqrt(sum_j (M^{-1})_{ij}^2 sigma_j^2)``.
    """
    C, D = geometry.camera_distance_mm, 1000.0 * geometry.distance_m
    vx, vy = np.asarray(vx_mm, float), np.asarray(vy_mm, float)
    d = np.asarray(displacement_mm, float)
    q = 1.0 / (C * C + vx * vx + vy * vy)
    mxx, myy, mxy = (1 - vx * vx * q) / (2 * D), (1 - vy * vy * q) / (2 * D), -vx * vy * q / (2 * D)
    slope = np.stack([mxx * d[..., 0] + mxy * d[..., 1], mxy * d[..., 0] + myy * d[..., 1]], -1)
    if sigma_mm is None:
        return slope, None
    s = np.asarray(sigma_mm, float)
    sig = np.stack([np.hypot(mxx * s[..., 0], mxy * s[..., 1]), np.hypot(mxy * s[..., 0], myy * s[..., 1])], -1)
    return slope, sig


def pane_step_mm(result) -> tuple[float, float]:
    """Pane mm per analysis-grid sample ``(s_y, s_x)`` of a reflection result (module notes, "Frame and scale")."""
    sy, sx = result.analysis_grid.step
    step = (sy * result.mm_per_px, sx * result.mm_per_px)
    optics = result.optics
    f = math.sqrt(math.cos(math.radians(optics.incidence_deg)))
    psi = math.radians(optics.plane_of_incidence_deg)
    if abs(math.sin(psi)) < 1e-9:
        return step[0] * f, step[1] / f
    if abs(math.cos(psi)) < 1e-9:
        return step[0] / f, step[1] * f
    return step


def polynomial_detrend(field: np.ndarray, mask: np.ndarray, degree: int, step_mm) -> np.ndarray:
    """``field`` less its least-squares polynomial of total degree ``degree`` over ``mask`` (NaN outside).

    Monomials ``x^i y^j``, ``i + j <= degree``, in pane coordinates centred and scaled to about
    [-1, 1] over the mask (a well-conditioned fit); ``degree < 0``: nothing removed.
    """
    out = np.full(field.shape, np.nan)
    if degree < 0 or not mask.any():
        out[mask] = field[mask]
        return out
    r, c = np.nonzero(mask)
    y, x = r * step_mm[0], c * step_mm[1]
    x = (x - x.mean()) / max(np.ptp(x) / 2, 1e-12)
    y = (y - y.mean()) / max(np.ptp(y) / 2, 1e-12)
    A = np.column_stack([x**i * y**(n - i) for n in range(degree + 1) for i in range(n + 1)])
    coef = np.linalg.lstsq(A, field[mask], rcond=None)[0]
    out[mask] = field[mask] - A @ coef
    return out


def surface_fields(result, geometry) -> SurfaceFields:
    """Slope and height of the front face from a reflection result (module notes).

    Parameters
    ----------
    result : AnalysisResult
        A reflection result (``optics`` set, :func:`glassdist.analyzer.reflection.reflect_result`).
    geometry : ReflectionGeometry
        Its capture geometry (:class:`glassdist.analyzer.reflection.ReflectionGeometry`).

    Returns
    -------
    SurfaceFields
        On the result's analysis grid, over the samples inside its reported region with a
        finite displacement.
    """
    optics = result.optics
    if optics is None or optics.optics != "reflection":
        raise ValueError("surface_fields needs a reflection result (optics = reflection)")
    fields = result.grid_fields()
    d = np.asarray(fields["displacement_mm"], float)
    region = np.asarray(result.grid_valid, bool) & np.isfinite(d).all(-1)
    sy, sx = pane_step_mm(result)
    yy, xx = result.analysis_grid.coords()
    H, W = result.valid.shape
    # pane mm from the view's centre, per pixel: the sample spacing over the grid step
    py, px = sy / result.analysis_grid.step[0], sx / result.analysis_grid.step[1]
    vx, vy = geometry.foot_offset_mm((xx - W / 2) * px, (yy - H / 2) * py)
    sig = fields.get("displacement_sigma_mm")
    slope, slope_sig = landing_slope(np.nan_to_num(d), vx, vy, geometry,
                                     None if sig is None else np.nan_to_num(np.asarray(sig, float)))
    N = int(result.detrend_degree)
    g = [polynomial_detrend(slope[..., c], region, N - 1, (sy, sx)) for c in range(2)]
    z = integrate_slope(np.where(region, g[0], 0.0), np.where(region, g[1], 0.0), region, (sy, sx))
    z = polynomial_detrend(np.nan_to_num(z), region, max(N, 0), (sy, sx))
    slope_mrad = np.stack(g, -1) * 1000.0
    nan = ~region
    if slope_sig is not None:
        slope_sig = slope_sig * 1000.0
        slope_sig[nan] = np.nan
        slope_sig = slope_sig.astype(np.float32)
    return SurfaceFields(slope_mrad.astype(np.float32), (z * 1000.0).astype(np.float32), slope_sig, region,
                         (sy, sx), N)


def with_surface_fields(result, geometry):
    """``result`` (a reflection result of capture geometry ``geometry``) with ``surface_slope_mrad``, ``surface_height_um`` (and ``surface_slope_sigma_mrad``
    when the displacement has an uncertainty) among its fields; a transmission result unchanged."""
    optics = result.optics
    if optics is None or optics.optics != "reflection":
        return result
    s = surface_fields(result, geometry)
    extra = {"surface_slope_mrad": s.slope_mrad, "surface_height_um": s.height_um}
    if s.slope_sigma_mrad is not None:
        extra["surface_slope_sigma_mrad"] = s.slope_sigma_mrad
    return result.with_grid_fields({**result.grid_fields(), **extra})
