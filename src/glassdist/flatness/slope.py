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
from scipy import ndimage

from .integrate import integrate_slope, integrate_slopes

__all__ = [
    "HEIGHT_SIGMA_DRAWS",
    "SurfaceFields",
    "height_sigma",
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
    height_sigma_um : ndarray (h, w) float32 or None
        Standard uncertainty of ``height_um`` from the image noise (:func:`height_sigma`); None
        when the result has no displacement uncertainty.
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
    height_sigma_um: np.ndarray | None = None


#: noise draws of :func:`height_sigma` (the standard deviation of 8 draws is within 25 % of the true one, 1 sigma)
HEIGHT_SIGMA_DRAWS = 8


def height_sigma(slope_sigma: np.ndarray, region: np.ndarray, step_mm, degree: int, correlation_mm: float,
                 *, fit: np.ndarray | None = None, draws: int = HEIGHT_SIGMA_DRAWS, seed: int = 0) -> np.ndarray:
    """Standard uncertainty of the height from the slope's, propagated through the integrator (Monte Carlo).

    The height is a linear function of the slope (the degree N - 1 detrend, the masked least-squares
    integral, the degree-N detrend), but the slope's noise is correlated over the reporting smoothing,
    so its covariance does not follow from the per-sample uncertainty alone. Here the noise is
    modelled as white noise through a Gaussian of standard deviation ``correlation_mm``
    (the demodulation's low-pass, :func:`glassdist.analyzer.reflection.noise_correlation_mm`), scaled at
    each sample to ``slope_sigma``, independent between the components;
    ``draws`` such slope fields are taken through the same chain (one factorisation of the integrator,
    :func:`glassdist.flatness.integrate.integrate_slopes`) and the standard deviation of their heights
    is the uncertainty. Seeded: the same result gives the same map.

    Parameters
    ----------
    slope_sigma : ndarray (h, w, 2)
        Standard uncertainty of ``(dZ/dx, dZ/dy)``, dimensionless (or mrad: the result is then in µm).
    region : ndarray (h, w) bool
        The samples integrated and detrended over.
    step_mm : (float, float)
        Pane mm per sample along rows and columns.
    degree : int
        N, the height's detrend degree.
    correlation_mm : float
        Standard deviation of the Gaussian that correlates the slope's noise, pane mm.
    fit : ndarray (h, w) bool, optional
        The detrends' fit samples (:func:`polynomial_detrend`).

    Returns
    -------
    ndarray (h, w)
        In the slope's unit x mm; NaN outside ``region``.
    """
    rng = np.random.default_rng(seed)
    h, w = region.shape
    s = (max(correlation_mm / step_mm[0], 0.0), max(correlation_mm / step_mm[1], 0.0))
    delta = np.zeros((h, w))
    delta[h // 2, w // 2] = 1.0
    gain = float(np.sqrt(np.sum(ndimage.gaussian_filter(delta, s, mode="constant") ** 2)))  # unit variance after
    sig = np.nan_to_num(np.asarray(slope_sigma, float))
    g = ndimage.gaussian_filter(rng.standard_normal((draws, 2, h, w)), (0, 0, *s), mode="reflect") / gain
    g = g * np.moveaxis(sig, -1, 0)[None]
    g = np.stack([[np.nan_to_num(polynomial_detrend(g[j, c], region, degree - 1, step_mm, fit)) for c in range(2)]
                  for j in range(draws)])
    z = integrate_slopes(np.where(region, g[:, 0], 0.0), np.where(region, g[:, 1], 0.0), region, step_mm)
    z = np.stack([polynomial_detrend(np.nan_to_num(zj), region, max(degree, 0), step_mm, fit) for zj in z])
    out = np.full((h, w), np.nan)
    out[region] = np.std(z[:, region], axis=0, ddof=1)
    return out


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


def polynomial_detrend(field: np.ndarray, mask: np.ndarray, degree: int, step_mm,
                       fit: np.ndarray | None = None) -> np.ndarray:
    """``field`` less, on each 4-connected part of ``mask``, its least-squares polynomial of total degree ``degree``
    fitted over the part's samples in ``fit`` (NaN outside ``mask``).

    As the A2 detrend (:mod:`glassdist.analyzer.detrend`): one polynomial per connected part, fitted
    over the A2 fit's region (``fit``: the whole blocks of ``detrend_region``; None: the whole part) and
    extrapolated over the rest of the part (the ring of partial blocks along its border). A part with
    fewer fitted samples than monomials is fitted over all of its samples. Monomials ``x^i y^j``,
    ``i + j <= degree``, in pane coordinates centred and scaled to about [-1, 1] over the part (a
    well-conditioned fit); ``degree < 0``: nothing removed.
    """
    out = np.full(field.shape, np.nan)
    if degree < 0 or not mask.any():
        out[mask] = field[mask]
        return out
    labels, nparts = ndimage.label(mask)
    use = mask if fit is None else (np.asarray(fit, bool) & mask)
    nmono = (degree + 1) * (degree + 2) // 2
    for part in range(1, nparts + 1):
        sel = labels == part
        on = sel & use
        if np.count_nonzero(on) < nmono:
            on = sel
        r, c = np.nonzero(sel)
        y, x = r * step_mm[0], c * step_mm[1]
        x0, y0 = x.mean(), y.mean()
        sc = (max(np.ptp(x) / 2, 1e-12), max(np.ptp(y) / 2, 1e-12))
        A = np.column_stack([((x - x0) / sc[0])**i * ((y - y0) / sc[1])**(n - i)
                             for n in range(degree + 1) for i in range(n + 1)])
        coef = np.linalg.lstsq(A[on[sel]], field[on], rcond=None)[0]
        out[sel] = field[sel] - A @ coef
    return out


def surface_fields(result, geometry, *, correlation_mm: float | None = None) -> SurfaceFields:
    """Slope and height of the front face from a reflection result (module notes).

    Parameters
    ----------
    result : AnalysisResult
        A reflection result (``optics`` set, :func:`glassdist.analyzer.reflection.reflect_result`).
    geometry : ReflectionGeometry
        Its capture geometry (:class:`glassdist.analyzer.reflection.ReflectionGeometry`).
    correlation_mm : float, optional
        Standard deviation of the Gaussian that correlates the displacement's noise, pane mm (the
        demodulation's low-pass; :func:`glassdist.analyzer.reflection.noise_correlation_mm`): with it
        and the displacement's uncertainty, the height's uncertainty (:func:`height_sigma`).

    Returns
    -------
    SurfaceFields
        On the result's analysis grid, over the samples inside its reported region with a
        finite displacement; the detrends fitted as A2's, per connected part over the samples
        of ``detrend_region`` (:func:`polynomial_detrend`).
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
    iy = np.clip(np.rint(yy).astype(int), 0, H - 1)
    ix = np.clip(np.rint(xx).astype(int), 0, W - 1)
    fit = np.asarray(result.detrend_region, bool)[iy, ix] & region  # the A2 fit's samples on the grid
    g = [polynomial_detrend(slope[..., c], region, N - 1, (sy, sx), fit) for c in range(2)]
    z = integrate_slope(np.where(region, g[0], 0.0), np.where(region, g[1], 0.0), region, (sy, sx))
    z = polynomial_detrend(np.nan_to_num(z), region, max(N, 0), (sy, sx), fit)
    slope_mrad = np.stack(g, -1) * 1000.0
    nan = ~region
    z_sig = None
    if slope_sig is not None:
        slope_sig = slope_sig * 1000.0
        slope_sig[nan] = np.nan
        if correlation_mm is not None:
            z_sig = height_sigma(slope_sig, region, (sy, sx), N, correlation_mm, fit=fit).astype(np.float32)
        slope_sig = slope_sig.astype(np.float32)
    return SurfaceFields(slope_mrad.astype(np.float32), (z * 1000.0).astype(np.float32), slope_sig, region,
                         (sy, sx), N, z_sig)


def with_surface_fields(result, geometry, *, correlation_mm: float | None = None):
    """``result`` (a reflection result of capture geometry ``geometry``) with ``surface_slope_mrad``,
    ``surface_height_um`` (and ``surface_slope_sigma_mrad``, ``surface_height_sigma_um`` when the displacement
    has an uncertainty, the latter given ``correlation_mm``: :func:`surface_fields`) among its fields; a
    transmission result unchanged."""
    optics = result.optics
    if optics is None or optics.optics != "reflection":
        return result
    s = surface_fields(result, geometry, correlation_mm=correlation_mm)
    extra = {"surface_slope_mrad": s.slope_mrad, "surface_height_um": s.height_um}
    if s.slope_sigma_mrad is not None:
        extra["surface_slope_sigma_mrad"] = s.slope_sigma_mrad
    if s.height_sigma_um is not None:
        extra["surface_height_sigma_um"] = s.height_sigma_um
    return result.with_grid_fields({**result.grid_fields(), **extra})
