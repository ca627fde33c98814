"""Block A, stages A2-A3: detrending, metric-anchored smoothing, strain and power channels.

This is the *evaluation stack* shared by the Analyzer and the analytical model
(paper §2 and §3.1): both routes hand a displacement field in mm to
:func:`evaluate_displacement`.

Conventions
-----------
* ``displacement_mm[..., 0]`` is delta_x (along columns), ``[..., 1]`` delta_y
  (along rows), in backdrop mm; delta = landing point with glass minus without.
* Samples may sit on a coarse grid: ``step_px = (sy, sx)`` is their spacing in
  image pixels.
* ``jacobian[..., a, b] = dX_a / dr_b`` maps an image step ``dr = (dx, dy)`` (px)
  to a backdrop step ``dX`` (mm), in the frame of the displacement components.
  Without it the isotropic ``mm_per_px`` is used.
* Channels, with eps = sym(grad delta) taken with respect to backdrop mm and L in m:

  .. math::

     \\phi_{eff} = \\mathrm{tr}(\\varepsilon)/L, \\quad
     \\phi_{shear} = \\frac{2}{L}\\sqrt{\\left(\\frac{\\varepsilon_{xx}-\\varepsilon_{yy}}{2}\\right)^2
     + \\varepsilon_{xy}^2}, \\quad \\phi_{total} = \\lVert\\varepsilon\\rVert_F / L,

  reported in mD (x 1000). A converging lens gives phi_eff < 0
  (P_sph,eq = -phi_eff/2 in the far-background limit).
* ``axis_deg``: direction of largest stretch of the astigmatism (major
  eigenvector of the traceless part of eps), degrees in (-90, 90], measured from
  +x (columns) towards +y (rows, down).

The A2 detrend itself lives in :mod:`~glassdist.analyzer.detrend`, the statistics of a channel in
:mod:`~glassdist.analyzer.field_statistics`; their names are re-exported here.

References
----------
Paper §2.2.2-2.2.3 (A2, metric-anchored smoothing, A3).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
import scipy.fft as sfft

from .detrend import detrend_increment, polynomial_detrend
from .field_statistics import channel_statistics, percentile, percentile_bracket, streamed_statistics
from .transfer import MIN_RESPONSE, difference_response

__all__ = [
    "Channels",
    "streamed_statistics",
    "percentile_bracket",
    "polynomial_detrend",
    "detrend_increment",
    "masked_gaussian",
    "masked_filter",
    "strain_tensor",
    "inverse_2x2",
    "channels_from_strain",
    "evaluate_displacement",
    "channel_statistics",
    "percentile",
    "derivative",
]


@dataclass(frozen=True)
class Channels:
    """Output of the evaluation stack (arrays on the input sample grid, NaN where invalid).

    Attributes
    ----------
    phi_eff_mD, phi_shear_mD, phi_total_mD : ndarray (h, w)
        Sphere-equivalent power, cylinder-equivalent astigmatism, Frobenius total, mD.
    axis_deg : ndarray (h, w)
        Principal axis of the astigmatism, degrees.
    displacement_detrended_mm : ndarray (h, w, 2)
        delta_* after detrending and smoothing, mm (the field that is differentiated).
    strain : ndarray (h, w, 2, 2)
        eps = sym(grad delta_*), dimensionless.
    """

    phi_eff_mD: np.ndarray
    phi_shear_mD: np.ndarray
    phi_total_mD: np.ndarray
    axis_deg: np.ndarray
    displacement_detrended_mm: np.ndarray
    strain: np.ndarray


def _gaussian_transfer(shape, cov_idx: np.ndarray) -> np.ndarray:
    """Continuous Gaussian transfer (covariance in samples^2) on the rfft2 grid of ``shape``."""
    fy = sfft.fftfreq(shape[0])[:, None]
    fx = sfft.rfftfreq(shape[1])[None, :]
    q = cov_idx[0, 0] * fx**2 + 2 * cov_idx[0, 1] * fx * fy + cov_idx[1, 1] * fy**2
    return np.exp(-2 * np.pi**2 * q)


#: Samples kept beyond the Gaussian's reach for the short non-Gaussian correction kernel.
_CORRECTION_SUPPORT = 12


def _fft_shape(data_shape, cov_idx: np.ndarray, with_correction: bool):
    """``(shape, wide)``: the FFT shape of :func:`_kernel_spectrum`, and whether the kernel reaches beyond the data."""
    sd = np.sqrt(np.maximum([cov_idx[1, 1], cov_idx[0, 0]], 0.0))  # (rows, cols), samples
    extra = _CORRECTION_SUPPORT if with_correction else 0
    reach = [int(np.ceil(4.0 * s)) + 1 + extra for s in sd]
    if not any(r > n for r, n in zip(reach, data_shape)):
        return (sfft.next_fast_len(data_shape[0] + reach[0]), sfft.next_fast_len(data_shape[1] + reach[1], real=True)), False
    return tuple(sfft.next_fast_len(min(n + r, 2 * n + 2 * extra + 2), real=(i == 1))
                 for i, (n, r) in enumerate(zip(data_shape, reach))), True


def _kernel_spectrum(data_shape, cov_idx: np.ndarray, step_px, correction):
    """FFT shape and kernel transfer (rfft2 layout) for a linear convolution of ``data_shape`` samples.

    The FFT is at most about twice the data along each axis, whatever the kernel's width:
    a kernel reaching beyond the data is sampled in space (only its values within the
    data's extent can act on it) and transformed; a narrower one uses the continuous
    Gaussian transfer on a grid padded by its reach. The cost therefore does not grow
    with sigma.
    """
    shape, wide = _fft_shape(data_shape, cov_idx, correction is not None)
    if not wide:
        T = _gaussian_transfer(shape, cov_idx)
    else:
        # The kernel's samples on the periodic FFT grid (offsets wrapped to [-P/2, P/2)):
        # exact where the convolution of the data can reach.
        dy = (np.arange(shape[0]) + shape[0] // 2) % shape[0] - shape[0] // 2
        dx = (np.arange(shape[1]) + shape[1] // 2) % shape[1] - shape[1] // 2
        c = np.asarray(cov_idx, float)
        det = c[0, 0] * c[1, 1] - c[0, 1] ** 2
        if det <= 1e-12 * max(c[0, 0], c[1, 1], 1e-30) ** 2:
            c = c + 1e-6 * np.eye(2)
            det = c[0, 0] * c[1, 1] - c[0, 1] ** 2
        ci = np.array([[c[1, 1], -c[0, 1]], [-c[0, 1], c[0, 0]]]) / det
        X, Y = dx[None, :].astype(float), dy[:, None].astype(float)
        k = np.exp(-0.5 * (ci[0, 0] * X**2 + 2 * ci[0, 1] * X * Y + ci[1, 1] * Y**2))
        T = sfft.rfft2(k / k.sum(), workers=-1).real  # even kernel: real transfer
    if correction is not None:
        sy, sx = step_px
        fy = sfft.fftfreq(shape[0])[:, None] / sy  # cycles/px
        fx = sfft.rfftfreq(shape[1])[None, :] / sx
        T = T * correction(fy, fx)
    return shape, T


def masked_filter(
    field: np.ndarray, weight: np.ndarray, cov_px: np.ndarray, step_px=(1.0, 1.0), *, correction=None,
    min_weight: float = 0.02, order: int = 1,
):
    """Normalised convolution restricted to a region with the kernel ``G_cov * C``.

    The kernel's transfer is the Gaussian of covariance ``cov_px`` times
    ``correction(fy, fx)`` (frequencies in cycles/px; a short, even correction such as
    the inverse of a block mean or an interpolation, see
    :class:`glassdist.analyzer.transfer.InstrumentTransfer`). It is a linear operator:
    inside the region (farther than the kernel's reach from its border) the output is
    exactly the convolution of the field with that kernel.

    ``order=1`` (default) fits, at every sample, a plane by kernel-weighted least
    squares over the region (first-order normalised convolution): near the border linear
    trends are preserved exactly instead of being pulled towards the interior (which
    would bias the strain there). ``order=0`` is the classic ``K*(w f) / K*w``. Values are
    extrapolated smoothly outside the region (where the normalising weight exceeds
    ``min_weight``), which gives clean centred differences at borders; elsewhere NaN.

    The cost is that of a few FFTs of at most twice the field's size along each axis,
    independent of the kernel's width (a kernel wider than the region is sampled over
    the region's extent only). Several corrections (a list) filter the same field with
    each kernel from one forward transform of the moments.

    Parameters
    ----------
    field : ndarray (h, w)
    weight : ndarray (h, w)
        1 inside the region, 0 outside.
    cov_px : ndarray (2, 2)
        Gaussian covariance in image px^2, (x, y) order. Zero (and no correction) means
        no smoothing.
    step_px : (float, float)
        Sample spacing (sy, sx), px.
    correction : callable (fy, fx) -> ndarray, or list of (callable or None), optional
        Extra transfer multiplying the Gaussian's, frequencies in cycles/px.

    Returns
    -------
    ndarray (h, w), or a list of them (one per correction) when ``correction`` is a list.

    References
    ----------
    Knutsson & Westin (1993), "Normalized and differential convolution", CVPR.
    """
    many = isinstance(correction, (list, tuple))
    corrections = list(correction) if many else [correction]
    if not np.any(cov_px) and all(c is None for c in corrections):
        out = [np.where(weight > 0, field, np.nan) for _ in corrections]
        return out if many else out[0]
    sy, sx = step_px
    D = np.diag([1.0 / sx, 1.0 / sy])
    cov_idx = D @ np.asarray(cov_px, float) @ D
    h, w = np.shape(field)
    spectra = {}  # the moments' transforms, one per FFT shape (kernels with and without a correction)
    out = []
    for corr in corrections:
        shape, T = _kernel_spectrum((h, w), cov_idx, step_px, corr)
        if shape not in spectra:
            spectra[shape] = _moment_spectra(field, weight, shape, order)
        moment_spectra, xx, yy = spectra[shape]
        moments = _irfft2_cropped(moment_spectra * T, shape, (h, w))
        out.append(_normalised(moments, xx, yy, cov_idx, min_weight))
    return out if many else out[0]


def _moment_spectra(field, weight, shape, order):
    """Forward transforms (rfft2 of ``shape``) of the weighted moments of the normalised convolution.

    Order 1: ``w, w f, w x, w y, w x^2, w x y, w y^2, w f x, w f y`` (x, y about the centre,
    samples); order 0: ``w, w f``. Returns ``(spectra, xx, yy)`` (``xx``, ``yy`` None at order 0).
    """
    f = np.where(weight > 0, np.nan_to_num(field), 0.0)
    wgt = (weight > 0).astype(float)
    h, w = f.shape
    # The moments are written straight into the zero-padded array the transform reads.
    buf = np.zeros((9 if order >= 1 else 2,) + tuple(shape), np.result_type(f, wgt))
    m = buf[:, :h, :w]
    m[0], m[1] = wgt, f
    xx = yy = None
    if order >= 1:
        yy, xx = np.mgrid[0:h, 0:w].astype(float)
        xx -= w / 2.0
        yy -= h / 2.0
        np.multiply(wgt, xx, out=m[2])  # w x
        np.multiply(wgt, yy, out=m[3])  # w y
        for k, (a, b) in enumerate(((m[2], xx), (m[2], yy), (m[3], yy), (f, xx), (f, yy)), start=4):
            np.multiply(a, b, out=m[k])  # w x^2, w x y, w y^2, w f x, w f y
    return sfft.rfft2(buf, axes=(-2, -1), workers=-1, overwrite_x=True), xx, yy


def _irfft2_cropped(spectra: np.ndarray, shape, out_shape) -> np.ndarray:
    """``irfft2(spectra, s=shape)[..., :h, :w]`` (last two axes), the padding's rows not transformed back.

    The passes of :func:`scipy.fft.irfft2` on the same data, so the same values bit for bit: the
    columns' inverse transforms unscaled, then the kept rows' real ones, the whole ``1 / (ny nx)``
    applied once at the end (pocketfft's factor, computed in long double). ``spectra`` is overwritten.
    """
    h, w = out_shape
    cols = sfft.ifft(spectra, axis=-2, norm="forward", workers=-1, overwrite_x=True)[..., :h, :]
    out = sfft.irfft(cols, n=shape[1], axis=-1, norm="forward", workers=-1)[..., :w]
    out *= float(np.longdouble(1) / (int(shape[0]) * int(shape[1])))
    return out


def _normalised(moments, xx, yy, cov_idx, min_weight):
    """The filtered field from its filtered moments (:func:`_moment_spectra`'s, back in space)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        c1, cf = moments[0], moments[1]
        out = cf / c1
        if xx is not None:
            _plane_values(out, moments, xx, yy, cov_idx, min_weight)
    out[c1 < min_weight] = np.nan
    return out


def _less(a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``a - t``, written into ``t`` (a temporary): the moments are large, and a new array per step costs its page faults."""
    return np.subtract(a, t, out=t)


def _plane_values(out, moments, xx, yy, cov_idx, min_weight) -> None:
    """Order 1 of :func:`_normalised`: ``out`` set to the fitted plane's value where the plane is well determined.

    Each quantity is the closed form in its comment, by the same operations in the same order
    (only the temporaries are reused).
    """
    c1, cf, cx, cy, cxx, cxy, cyy, cxf, cyf = moments
    # Moments about each sample (shifted to its own position).
    sx_ = _less(cx, xx * c1)  # cx - xx c1
    sy_ = _less(cy, yy * c1)  # cy - yy c1
    sxx = _less(cxx, 2 * xx * cx)  # cxx - 2 xx cx + xx^2 c1
    sxx += xx**2 * c1
    sxy = _less(cxy, xx * cy)  # cxy - xx cy - yy cx + xx yy c1
    sxy -= yy * cx
    sxy += xx * yy * c1
    syy = _less(cyy, 2 * yy * cy)  # cyy - 2 yy cy + yy^2 c1
    syy += yy**2 * c1
    sxf = _less(cxf, xx * cf)  # cxf - xx cf
    syf = _less(cyf, yy * cf)  # cyf - yy cf
    # Weighted least-squares plane a + b x + c y about each sample: normal equations
    # [[c1, sx, sy], [sx, sxx, sxy], [sy, sxy, syy]] (a, b, c) = (cf, sxf, syf), of which
    # only a is needed (Cramer's rule, vectorised; 2x2 and 3x3 in closed form).
    c1s = np.maximum(c1, 1e-12)

    def schur(m, a, b, c1s=c1s):  # m - a b / c1s
        t = a * b
        t /= c1s
        return _less(m, t)

    a_, b_, d_ = schur(sxx, sx_, sx_), schur(sxy, sx_, sy_), schur(syy, sy_, sy_)
    lam_min = 0.5 * (a_ + d_) - np.hypot(0.5 * (a_ - d_), b_)  # Schur complement's smaller eigenvalue
    del a_, b_, d_
    # Only where the plane is well determined; else keep the zeroth-order value.
    good = (c1 > min_weight) & (lam_min > 0.05 * c1 * min(cov_idx[0, 0], cov_idx[1, 1]))
    del lam_min
    if not good.any():
        return
    m00 = sxx * syy  # sxx syy - sxy^2
    m00 -= sxy * sxy
    # det = c1 m00 - sx (sx syy - sxy sy) + sy (sx sxy - sxx sy); det0 the same with (cf, sxf, syf) for (c1, sx, sy)
    det = _cramer(c1, m00, sx_, sy_, sx_, sy_, sxx, sxy, syy)
    det0 = _cramer(cf, m00, sxf, syf, sx_, sy_, sxx, sxy, syy)
    out[good] = det0[good] / det[good]


def _cramer(a0, m00, p, q, sx_, sy_, sxx, sxy, syy):
    """``a0 m00 - sx (p syy - sxy q) + sy (p sxy - sxx q)``, with few temporaries."""
    r = a0 * m00
    t = p * syy
    t -= sxy * q
    t *= sx_
    r -= t
    np.multiply(p, sxy, out=t)
    t -= sxx * q
    np.multiply(sy_, t, out=t)
    r += t
    return r


def masked_gaussian(
    field: np.ndarray, weight: np.ndarray, cov_px: np.ndarray, step_px=(1.0, 1.0), *, min_weight: float = 0.02,
    order: int = 1,
) -> np.ndarray:
    """Gaussian smoothing restricted to a region (normalised convolution), any covariance.

    :func:`masked_filter` with a plain Gaussian kernel of covariance ``cov_px`` (px^2,
    (x, y) order): inside the region it equals the Gaussian convolution; near its border
    the first-order fit (``order=1``) preserves linear trends. Cost independent of sigma.
    """
    return masked_filter(field, weight, cov_px, step_px, min_weight=min_weight, order=order)


def derivative(f: np.ndarray, axis: int, h: float) -> np.ndarray:
    """Fourth-order centred difference (second order in the two outermost samples).

    On coarse sampling grids the 2-point centred difference would attenuate a wave of
    wavelength W by sin(x)/x, x = 2 pi h / W; the 5-point stencil is accurate to
    about x^4/30 (0.2% at x = 0.5).
    """
    g = np.gradient(f, h, axis=axis)
    n = f.shape[axis]
    if n >= 5:
        sl = lambda a, b: tuple(slice(a, b) if i == axis else slice(None) for i in range(f.ndim))  # noqa: E731
        inner = (-f[sl(4, None)] + 8 * f[sl(3, -1)] - 8 * f[sl(1, -3)] + f[sl(0, -4)]) / (12 * h)
        # Where the 5-point stencil reaches NaN, keep the 3-point value.
        g_in = g[sl(2, -2)]
        g[sl(2, -2)] = np.where(np.isfinite(inner), inner, g_in)
    return g


def inverse_2x2(M: np.ndarray) -> np.ndarray:
    """Inverses of a stack of 2 x 2 matrices ``(..., 2, 2)``, in closed form.

    A batched LAPACK ``inv`` costs ~10x more on the 10^5-10^6 matrices of an analysis grid.
    """
    det = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
    adj = np.stack([np.stack([M[..., 1, 1], -M[..., 0, 1]], -1), np.stack([-M[..., 1, 0], M[..., 0, 0]], -1)], -2)
    return adj / det[..., None, None]


def strain_tensor(
    displacement_mm: np.ndarray, step_px=(1.0, 1.0), *, mm_per_px: float | None = None, jacobian=None,
    for_gradient: tuple[np.ndarray, np.ndarray] | None = None,
):
    """A3: eps = sym(d delta / dX) by centred differences, X in backdrop mm.

    Parameters
    ----------
    displacement_mm : ndarray (h, w, 2)
    step_px : (float, float)
        Sample spacing (sy, sx), px.
    mm_per_px : float, optional
        Isotropic scale (used when ``jacobian`` is None).
    jacobian : ndarray (h, w, 2, 2), optional
        ``dX/dr`` (mm per px).
    for_gradient : (ndarray (h, w, 2), ndarray (h, w, 2)), optional
        The fields to difference along x and along y, when they differ from
        ``displacement_mm`` (each pre-filtered by the inverse of the stencil's transfer
        along its axis, see :func:`evaluate_displacement`).

    Returns
    -------
    ndarray (h, w, 2, 2)
    """
    d = displacement_mm
    dx_src, dy_src = (d, d) if for_gradient is None else for_gradient
    sy, sx = step_px
    G = np.empty(d.shape[:2] + (2, 2))
    for c in range(2):  # d delta_c / d(x, y) in px
        G[..., c, 1] = derivative(dy_src[..., c], 0, sy)
        G[..., c, 0] = derivative(dx_src[..., c], 1, sx)
    if jacobian is None:
        if mm_per_px is None:
            raise ValueError("strain_tensor needs mm_per_px or jacobian")
        grad = G / mm_per_px
    else:
        grad = G @ inverse_2x2(jacobian)
    return 0.5 * (grad + np.swapaxes(grad, -1, -2))


def channels_from_strain(eps: np.ndarray, distance_m: float):
    """A3 channels (mD) and astigmatism axis (deg) from the strain tensor (see module notes)."""
    exx, eyy, exy = eps[..., 0, 0], eps[..., 1, 1], 0.5 * (eps[..., 0, 1] + eps[..., 1, 0])
    scale = 1000.0 / distance_m
    phi_eff = (exx + eyy) * scale
    phi_shear = 2.0 * np.hypot(0.5 * (exx - eyy), exy) * scale
    phi_total = np.sqrt(exx**2 + eyy**2 + 2 * exy**2) * scale
    axis = 0.5 * np.degrees(np.arctan2(2 * exy, exx - eyy))
    axis = np.where(axis <= -90.0, axis + 180.0, axis)
    return phi_eff, phi_shear, phi_total, axis


def _stencil_kernels(sigma_px: float, step_px) -> dict:
    """Corrections the smoothing applies per output: ``"field"`` (none), and ``"x"``, ``"y"`` where needed.

    A3's stencil passes 1 - w^4/30 (w = 2 pi step nu) of the gradient: it is corrected where
    the smoothed field still holds content it would attenuate by more than 1e-4 (nu up to
    where G_sigma falls to 1e-3), as long as that content stays well below the stencil's
    cut-off (w < 2; a field smoothed less than that is differenced as it is): the fields
    differenced along x and y are then smoothed with the kernel divided by the stencil's
    transfer along that axis.
    """
    sy, sx = step_px
    w_max = 2.0 * np.pi * np.sqrt(np.log(1e3) / (2.0 * np.pi**2)) / max(sigma_px, 1e-9) * max(sy, sx)
    kernels: dict[str, Callable[[Any, Any], Any] | None] = {"field": None}
    if 1e-4 < w_max**4 / 30.0 and w_max < 2.0:
        kernels["x"] = lambda fy, fx: 1.0 / np.maximum(difference_response(sx, fx), MIN_RESPONSE)
        kernels["y"] = lambda fy, fx: 1.0 / np.maximum(difference_response(sy, fy), MIN_RESPONSE)
    return kernels


def _smooth_regions(field, labels, cov, step_px, corrections: dict, outs: dict) -> None:
    """Smooth ``field`` in each labelled region with each kernel (:func:`masked_filter`), into ``outs`` (views).

    A sample keeps its own region's value; outside every region, the first region whose
    extrapolation reaches it.
    """
    for r in range(1, int(labels.max(initial=0)) + 1):
        sel = labels == r
        if not sel.any():
            continue
        # every kernel from one transform of the region's moments
        filtered = masked_filter(field, sel.astype(float), cov, step_px, correction=list(corrections.values()))
        for key, s in zip(corrections, filtered):
            take = np.isfinite(s) & (np.isnan(outs[key]) | sel)
            outs[key][take] = s[take]


def _product(a, b):
    """The product of two transfers ``(fy, fx) -> ndarray`` (either may be None: the other alone)."""
    if a is None or b is None:
        return b if a is None else a
    return lambda fy, fx: a(fy, fx) * b(fy, fx)


def evaluate_displacement(
    displacement_mm: np.ndarray,
    valid: np.ndarray,
    *,
    distance_m: float,
    mm_per_px: float,
    detrend_degree: int,
    sigma_mm: float,
    jacobian: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    step_px=(1.0, 1.0),
    component_blur_px2: np.ndarray | None = None,
    frame_rotation: np.ndarray | None = None,
    report_mask: np.ndarray | None = None,
    transfer=None,
) -> Channels:
    """The shared evaluation stack: A2 detrend, metric-anchored smoothing, A3 channels.

    Parameters
    ----------
    displacement_mm : ndarray (h, w, 2)
        delta in mm (x, y components; see ``frame_rotation``).
    valid : ndarray of bool (h, w)
    distance_m : float
        Glass-to-backdrop distance L, m.
    mm_per_px : float
        Isotropic backdrop mm per image px; sets the smoothing
        ``sigma_px = sigma_mm / mm_per_px`` (and the gradients when ``jacobian`` is None).
    detrend_degree : int
        Total degree N of the A2 polynomial.
    sigma_mm : float
        Reporting smoothing scale on the backdrop, mm.
    jacobian : ndarray (h, w, 2, 2), optional
        ``dX/dr`` in the frame of the components (mm per px) for exact gradients
        with respect to backdrop mm under perspective.
    labels : ndarray of int (h, w), optional
        Regions detrended and smoothed independently (default: one region = ``valid``).
    step_px : (float, float)
        Sample spacing (sy, sx), px.
    component_blur_px2 : ndarray (2, 2, 2), optional
        Covariance (px^2, (x, y) order) of a Gaussian blur already applied to each
        component; it is subtracted from the smoothing so the total equals sigma.
        Ignored when ``transfer`` is given.
    frame_rotation : ndarray (2, 2), optional
        ``R`` with components given in a rotated frame: camera-frame delta = R^T delta.
        Channels are rotation invariant; the axis and the returned displacement are
        expressed in the camera frame.
    report_mask : ndarray of bool (h, w), optional
        Where results are reported (default ``valid``); a ring just outside
        ``valid`` receives the smooth first-order extrapolation of the field.
    transfer : glassdist.analyzer.transfer.InstrumentTransfer, optional
        The instrument's transfer for each component (the Analyzer's): the smoothing
        applies ``G_sigma / H_i`` so that the result is the true field convolved with the
        Gaussian of ``sigma_mm`` (see :mod:`glassdist.analyzer.transfer`).

    Returns
    -------
    Channels

    Notes
    -----
    The smoothing of component *i* is the linear operator :func:`masked_filter` with the
    Gaussian ``sigma^2 I - Sigma_i`` (``Sigma_i`` the Gaussian part of the instrument's
    blur, zero for a plain field) times the inverse of the instrument's non-Gaussian
    stages. Where the five-point differences of A3 would attenuate what the smoothing
    passes by more than 1e-4, the fields they difference along x and y are smoothed with
    the kernel divided by the stencil's transfer along that axis, so the gradients are
    those of the smoothed field, exactly.
    """
    valid = np.asarray(valid, bool)
    if labels is None:
        labels = valid.astype(np.int32)
    labels = np.where(valid, labels, 0)
    det = polynomial_detrend(displacement_mm, labels, detrend_degree, step_px)
    outs = _smoothed_components(det, labels, sigma_mm / mm_per_px, step_px, transfer, component_blur_px2)
    grad_src = (outs["x"], outs["y"]) if "x" in outs else None
    eps = strain_tensor(outs["field"], step_px, mm_per_px=mm_per_px, jacobian=jacobian, for_gradient=grad_src)
    inval = ~(valid if report_mask is None else np.asarray(report_mask, bool))
    return _camera_frame_channels(outs["field"], eps, distance_m, frame_rotation, inval)


def _smoothed_components(det: np.ndarray, labels: np.ndarray, sigma_px: float, step_px, transfer,
                         component_blur_px2: np.ndarray | None) -> dict:
    """The detrended field smoothed to ``sigma_px`` per component, and the stencil-corrected copies A3 differences.

    Parameters
    ----------
    det : ndarray (h, w, 2)
        Detrended displacement, mm.
    labels : ndarray of int (h, w)
        Regions smoothed independently (0: outside every region).
    sigma_px : float
        Reporting smoothing scale, px.
    step_px : (float, float)
        Sample spacing (sy, sx), px.
    transfer, component_blur_px2
        As for :func:`evaluate_displacement`.

    Returns
    -------
    dict of ndarray (h, w, 2)
        ``"field"``: the smoothed field (NaN where no region reaches); ``"x"``, ``"y"``: the
        fields to difference along x and y, where :func:`_stencil_kernels` asks for them.
    """
    s_eff = sigma_px if transfer is None else transfer.effective_sigma_px(sigma_px)
    kernels = _stencil_kernels(s_eff, step_px)
    outs = {k: np.full(det.shape, np.nan) for k in kernels}
    for c in range(2):
        if transfer is not None:
            cov = transfer.residual_cov_px2(c, sigma_px)
            base = transfer.component_correction(c)
        else:
            cov = sigma_px**2 * np.eye(2)
            if component_blur_px2 is not None:
                w, V = np.linalg.eigh(cov - component_blur_px2[c])
                cov = (V * np.clip(w, 0.0, None)) @ V.T
            base = None
        _smooth_regions(det[..., c], labels, cov, step_px, {k: _product(base, e) for k, e in kernels.items()},
                        {k: o[..., c] for k, o in outs.items()})
    return outs


def _camera_frame_channels(smooth: np.ndarray, eps: np.ndarray, distance_m: float, frame_rotation,
                           inval: np.ndarray) -> Channels:
    """A3 channels, with the strain and the displacement turned back to the camera frame, NaN at ``inval``.

    Parameters
    ----------
    smooth : ndarray (h, w, 2)
        Smoothed displacement in the components' frame, mm.
    eps : ndarray (h, w, 2, 2)
        Strain tensor in the components' frame.
    distance_m : float
        Glass-to-backdrop distance L, m.
    frame_rotation : ndarray (2, 2) or None
        As for :func:`evaluate_displacement`.
    inval : ndarray of bool (h, w)
        Where nothing is reported.

    Returns
    -------
    Channels
    """
    disp_out = smooth
    if frame_rotation is not None:
        R = np.asarray(frame_rotation)
        eps = R.T @ eps @ R
        disp_out = smooth @ R  # row-vector form of R^T delta
    phi_eff, phi_shear, phi_total, axis = channels_from_strain(eps, distance_m)
    for a in (phi_eff, phi_shear, phi_total, axis):
        a[inval] = np.nan
    disp_out = disp_out.copy()
    disp_out[inval] = np.nan
    eps[inval] = np.nan
    return Channels(phi_eff, phi_shear, phi_total, axis, disp_out, eps)
