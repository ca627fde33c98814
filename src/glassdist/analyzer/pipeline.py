"""The Distortion Analyzer: Comparative and Direct methods (paper §2.2).

Comparative: F1-F4 against the analytic signal of a glass-less photograph, then A.
Direct: F1-F4 against a synthetic flat carrier (pass 1), Block I fits the
homography of the logical grid, and the distortion phase is taken against the
homography-warped carrier (pass 2, reusing pass 1's unwrapped phase), then A.

A1 (projective, default): carrier *i* measures the displacement along backdrop
grid axis *i* exactly, ``delta_i = p_c phi_i / (2 pi)`` (p_c the carrier period
on the backdrop), whatever the perspective; gradients are taken with respect to
backdrop mm through the Jacobian of the fitted homography, and the result is
rotated into the camera frame (x along columns, y along rows). A1 (isotropic,
the paper's reporting convention): dual-basis inverse ``(M^T)^{-1}`` and the
single scale ``mm_per_px = p_c sqrt(|f1||f2|)``.
"""

from __future__ import annotations

import logging
import os
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import ndimage

from ..errors import AnalysisError, InputError
from . import fourier as F
from .homography import HomographyFit, apply_inverse, fit_grid_homography, inverse_jacobian
from .metrics import evaluate_displacement
from .params import AnalyzerParams, load_params
from .region import Region, valid_region
from .resample import image_grid_valid
from .result import AnalysisResult
from .unwrap import unwrap

__all__ = ["AnalysisResult", "ReferenceModel", "analyze", "prepare_reference"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReferenceModel:
    """State derived once from a glass-less reference photo and reused for every frame.

    Holds its spectrum-derived carriers, baseband signals and the homography of its
    (undistorted) grid, so each distorted frame then costs one FFT.
    """

    shape: tuple[int, int]
    carriers: F.CarrierPair
    covariances: tuple[np.ndarray, np.ndarray]
    grid: F.SamplingGrid
    baseband: tuple[np.ndarray, np.ndarray]
    modulation: tuple[np.ndarray, np.ndarray]
    homography: HomographyFit
    params: AnalyzerParams = field(repr=False)
    warnings: tuple[str, ...] = ()


# --------------------------------------------------------------------------- checks


def _check_physical(pitch_mm: float, distance_m: float) -> None:
    if not np.isfinite(pitch_mm) or pitch_mm <= 0:
        raise InputError(f"pitch must be a positive length in mm (got {pitch_mm}); pass --pitch-mm with the printed grid pitch")
    if not np.isfinite(distance_m) or distance_m <= 0:
        raise InputError(
            f"distance must be a positive length in m (got {distance_m}); pass --distance-m with the glass-to-grid distance L"
        )


def _check_image(img: np.ndarray, what: str, warn: list[str]) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim != 2:
        raise InputError(f"the {what} must be a 2-D grey image, got an array of shape {a.shape}")
    a = a.astype(np.float32, copy=False)
    if min(a.shape) < 32:
        raise InputError(f"the {what} is only {a.shape[1]}x{a.shape[0]} px; at least 32x32 px are needed")
    lo, hi = float(a.min()), float(a.max())  # also NaN-detecting: NaN propagates through min/max
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise InputError(f"the {what} contains NaN or infinite values")
    # Exposure statistics need no more than a regular subsample of a large photo.
    k = max(1, int(np.sqrt(a.size / 2_000_000)))
    a_s = a[::k, ::k]
    if hi - lo < 1e-3 or float(a_s.std()) < 2e-3:
        raise InputError(f"the {what} is blank (no contrast); check the exposure and that the grid is in view")
    sat = float(np.mean(a_s >= 0.999 * max(hi, 1e-12))) if hi >= 0.98 else 0.0
    dark = float(np.mean(a_s <= 1e-3))
    if sat > 0.7 or dark > 0.7:
        raise InputError(
            f"the {what} is {'saturated' if sat > 0.7 else 'black'} over {100 * max(sat, dark):.0f}% of its pixels; "
            "re-expose the photo so the grid lines and the background are both visible"
        )
    if sat > 0.02:
        warn.append(f"{what}: {100 * sat:.1f}% of pixels are saturated; phase near them is less reliable")
    if hi - lo < 0.08:
        warn.append(f"{what}: low contrast (intensity range {hi - lo:.3f}); expect a noisier result")
    return a


def _carrier_period_mm(pitch_mm: float, pattern: str) -> float:
    # Checkerboard fundamentals are the diagonal products of the two square waves: period s*sqrt(2).
    return pitch_mm * np.sqrt(2.0) if pattern == "checkerboard" else pitch_mm


# --------------------------------------------------------------------------- stage helpers


def _covariances(carriers: F.CarrierPair, p: AnalyzerParams):
    kw = dict(sigma_along=p.bandpass_sigma_along, sigma_cross=p.bandpass_sigma_cross, isotropic=p.isotropic_bandpass)
    return (
        F.bandpass_covariance(carriers.k1, carriers.k2, **kw),
        F.bandpass_covariance(carriers.k2, carriers.k1, **kw),
    )


def _demodulation_blur_px2(carriers: F.CarrierPair, covs, p: AnalyzerParams) -> np.ndarray:
    """Spatial covariance (px^2) of the low-pass Block F applies to each phase map."""
    out = []
    for c, cov in zip((carriers.k1, carriers.k2), covs):
        s3 = p.smoothing_periods * c.period_px
        out.append(np.linalg.inv(cov) / (4 * np.pi**2) + s3**2 * np.eye(2))
    return np.array(out)


def _basebands(spec: F.Spectrum, carriers: F.CarrierPair, covs, grid: F.SamplingGrid):
    return tuple(F.baseband(spec, c, cov, grid) for c, cov in zip((carriers.k1, carriers.k2), covs))


def _modulation(b: np.ndarray, period_px: float, grid: F.SamplingGrid, p: AnalyzerParams) -> np.ndarray:
    """Local modulation G*|b| (same kernel as F3)."""
    sy, sx = grid.step
    s = p.smoothing_periods * period_px
    return F.gaussian_blur(np.abs(b), (s / sy, s / sx), truncate=3.5)


def _smooth_with_coherence(zs, ks, grid, p: AnalyzerParams, smoothed_abs=None):
    """F3 smoothing of each complex signal and its phase coherence |G*z| / G*|z| in [0, 1].

    ``smoothed_abs``: the G*|z| maps when already known (Direct Method: the modulation).
    """
    out, coh = [], []
    for i, (z, c) in enumerate(zip(zs, ks)):
        s = p.smoothing_periods * c.period_px
        zs_ = F.smooth_complex(z, s, grid)
        a = smoothed_abs[i] if smoothed_abs is not None else _modulation(z, c.period_px, grid, p)
        out.append(zs_)
        coh.append(np.abs(zs_) / np.maximum(a, 1e-30))
    return tuple(out), tuple(coh)


def _polar_rotation(J: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(J)
    return u @ vt


# Relative local-frequency deviation above which results degrade (ray-traced roller waves:
# right at 0.31, wrong from 0.41; docs/accuracy.md).
_DEVIATION_WARN = 0.35


def _frequency_deviation(phases: np.ndarray, valid: np.ndarray, carriers, step) -> float:
    """99th percentile over ``valid`` of |grad phi_i| / (2 pi |f_i|), the larger of the two carriers.

    The distortion phase's gradient is the local shift of the grid frequency; the
    bandpass passes a limited band around the carrier, so large shifts are attenuated
    (and beyond it the unwrap and the homography fail).
    """
    if valid.sum() < 16:
        return 0.0
    out = 0.0
    for i, c in enumerate(carriers):
        gy, gx = np.gradient(phases[..., i], step[0], step[1])
        g = np.hypot(gx, gy)[valid]
        g = g[np.isfinite(g)]
        if g.size:
            out = max(out, float(np.percentile(g, 99)) / (2 * np.pi * c.norm))
    return out


def _analysis_block(sigma_px: float, blur, grid: F.SamplingGrid, p: AnalyzerParams) -> int:
    """Block factor (1, 2 or 4) of the Block A grid: its step stays below half the residual smoothing."""
    if p.analysis_block != "auto":
        m = int(p.analysis_block)
        return m if grid.shape[0] % m == 0 and grid.shape[1] % m == 0 else 1
    worst = 0.0 if blur is None else max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
    residual = np.sqrt(max(sigma_px**2 - worst, 0.0))
    step = max(grid.step)
    h, w = grid.shape
    for m in (4, 2):
        if h % m == 0 and w % m == 0 and m * step <= residual / 2.0 and min(h, w) // m >= 16:
            return m
    return 1


def _resolve_params(params, pattern) -> AnalyzerParams:
    if isinstance(params, AnalyzerParams):
        return params if pattern is None else params.model_copy(update={"pattern": pattern})
    return load_params(params, pattern=pattern)


# --------------------------------------------------------------------------- stage results


@dataclass(frozen=True)
class _Inputs:
    """Checked inputs of one analysis."""

    image: np.ndarray
    mask: np.ndarray | None
    reference: ReferenceModel | None
    params: AnalyzerParams
    carrier_period_mm: float


@dataclass(frozen=True)
class _Demodulation:
    """F1-F3: carriers, the F3-smoothed heterodyned signals, their coherence and the modulations.

    ``mods`` holds G*|b| of the distorted photo's two carriers, then (Comparative) the reference's.
    """

    method: str
    carriers: F.CarrierPair
    covariances: tuple[np.ndarray, np.ndarray]
    grid: F.SamplingGrid
    signals: tuple[np.ndarray, np.ndarray]
    coherences: tuple[np.ndarray, np.ndarray]
    mods: list


@dataclass(frozen=True)
class _AnalysisGrid:
    """Unwrapped phases (rad, per carrier, pass 2 applied for Direct) on the Block A grid.

    ``valid``/``labels`` describe whole blocks; ``report`` adds the partial border blocks the
    fine mask trims later; ``fine_valid`` is the demodulation-grid region when blocks were formed.
    """

    grid: F.SamplingGrid
    phases: np.ndarray
    valid: np.ndarray
    labels: np.ndarray
    report: np.ndarray
    fine_valid: np.ndarray | None
    blur_px2: np.ndarray | None


# --------------------------------------------------------------------------- stages


def _checked_inputs(image, pitch_mm, distance_m, reference, params, mask, pattern, warn: list[str]) -> _Inputs:
    """Physical inputs, image, mask and reference checked; the reference prepared once."""
    _check_physical(float(pitch_mm), float(distance_m))
    if isinstance(reference, ReferenceModel):
        p = reference.params if params is None and pattern is None else _resolve_params(params, pattern)
    else:
        p = _resolve_params(params, pattern)
    img = _check_image(image, "image", warn)
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != img.shape:
            raise InputError(f"the mask is {mask.shape[1]}x{mask.shape[0]} px but the image is {img.shape[1]}x{img.shape[0]} px")
        if not mask.any():
            raise InputError("the mask excludes every pixel; non-zero mask pixels mark the region to analyse")
    refm = reference if isinstance(reference, ReferenceModel) else None
    if reference is not None and refm is None:
        ref_arr = np.asarray(reference)
        if ref_arr.shape != img.shape:
            raise InputError(
                f"the reference is {ref_arr.shape[1] if ref_arr.ndim > 1 else '?'}x{ref_arr.shape[0]} px but the image is "
                f"{img.shape[1]}x{img.shape[0]} px; both photos must come from the same camera position and size"
            )
        refm = prepare_reference(ref_arr, params=p)
    if refm is not None and refm.shape != img.shape:
        raise InputError(f"the reference is {refm.shape[1]}x{refm.shape[0]} px but the image is {img.shape[1]}x{img.shape[0]} px")
    if refm is not None:
        warn.extend(refm.warnings)
    return _Inputs(img, mask, refm, p, _carrier_period_mm(float(pitch_mm), p.pattern))


def _demodulate(img: np.ndarray, refm: ReferenceModel | None, p: AnalyzerParams) -> _Demodulation:
    """F1-F3: one FFT of the photo, the carriers (its own, or the reference's), heterodyne, F3."""
    spec = F.compute_spectrum(img)
    if refm is None:
        carriers = F.find_carriers(spec, min_period_px=p.min_period_px)
        F.check_image_size(img.shape, max(carriers.k1.period_px, carriers.k2.period_px))
        covs = _covariances(carriers, p)
        grid = F.sampling_grid(img.shape, list(covs), p.decimation)
    else:
        carriers, covs, grid = refm.carriers, refm.covariances, refm.grid
        F.find_carriers(spec, min_period_px=p.min_period_px)  # raises if the photo shows no grid
    ks = (carriers.k1, carriers.k2)
    if refm is None:
        # Direct: F3 applied in the spectral patch; coherence against the modulation G*|b|.
        pairs = [F.baseband(spec, c, cov, grid, smooth_sigma_px=p.smoothing_periods * c.period_px) for c, cov in zip(ks, covs)]
        del spec
        mods = [_modulation(b, c.period_px, grid, p) for (b, _), c in zip(pairs, ks)]
        zs = tuple(gb for _, gb in pairs)
        cohs = tuple(np.abs(z) / np.maximum(m_, 1e-30) for z, m_ in zip(zs, mods))
        return _Demodulation("direct", carriers, covs, grid, zs, cohs, mods)
    bb = _basebands(spec, carriers, covs, grid)
    del spec
    mods = [_modulation(b, c.period_px, grid, p) for b, c in zip(bb, ks)]
    zs = tuple(b * np.conj(r) for b, r in zip(bb, refm.baseband))
    mods += list(refm.modulation)
    zs, cohs = _smooth_with_coherence(zs, ks, grid, p)  # F3
    return _Demodulation("comparative", carriers, covs, grid, zs, cohs, mods)


def _check_region(region: Region, mods, warn: list[str]) -> None:
    """No analysable region is an error; a faint grid a warning."""
    if region.n == 0:
        raise AnalysisError(
            "no region of the photo carries a reliable grid signal; check focus, exposure and that the grid fills the view"
        )
    # Grid modulation: amplitude of the fundamental (|b| is half of it), intensity units.
    amp = 2.0 * min(float(np.median(m_[region.valid])) for m_ in mods[:2])
    if amp < 0.03:
        warn.append(f"low grid contrast (carrier amplitude {amp:.3f} of full scale); expect a noisier result")


def _unwrapped_phases(demod: _Demodulation, region: Region, p: AnalyzerParams) -> np.ndarray:
    """F4: the wrapped phases of the F3 signals unwrapped per region, (h, w, 2) float32 rad."""
    psi = [unwrap(np.angle(z), region.valid, region.labels, region.n, seed=p.ransac_seed) for z in demod.signals]
    return np.stack(psi, axis=-1).astype(np.float32)


def _direct_baseline(phases, demod: _Demodulation, region: Region, p: AnalyzerParams, warn: list[str]) -> HomographyFit:
    """Block I (pass 1): homography of the logical grid; each region's integer offset removed from ``phases``."""
    carriers = demod.carriers
    yy, xx = demod.grid.coords()
    U = carriers.k1.fx * xx + carriers.k1.fy * yy + phases[..., 0] / (2 * np.pi)
    V = carriers.k2.fx * xx + carriers.k2.fy * yy + phases[..., 1] / (2 * np.pi)
    fit, offsets = fit_grid_homography((U, V), yy, xx, region.labels, region.n, carriers, demod.grid, p, warn)
    if region.n > 1:
        phases -= (2 * np.pi * offsets[region.labels]).astype(np.float32)
    return fit


def _smoothing_mm(demod: _Demodulation, p: AnalyzerParams, p_c: float, mm_per_px: float, warn: list[str]):
    """The reporting smoothing (mm) and the demodulation blur (px^2 per carrier) to compensate."""
    blur = _demodulation_blur_px2(demod.carriers, demod.covariances, p) if p.compensate_demodulation_blur else None
    sigma_mm = p.sigma_mm if p.sigma_mm is not None else p.sigma_periods * p_c
    if blur is not None:
        s_px = sigma_mm / mm_per_px
        worst = max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
        if worst > s_px**2:
            warn.append(
                f"sigma_mm = {sigma_mm:.3g} mm ({s_px:.1f} px) is finer than the demodulation resolution "
                f"({np.sqrt(worst):.1f} px); the effective smoothing is coarser than requested"
            )
    return float(sigma_mm), blur


def _to_analysis_grid(phases, region: Region, grid: F.SamplingGrid, sigma_px: float, blur, p: AnalyzerParams) -> _AnalysisGrid:
    """Block means of the demodulation grid, as coarse as the reporting smoothing allows.

    The block step stays below half the residual smoothing; the box blur joins the
    compensated budget.
    """
    m = _analysis_block(sigma_px, blur, grid, p)
    if m == 1:
        return _AnalysisGrid(grid, phases, region.valid, region.labels, region.valid, None, blur)
    agrid = F.block_grid(grid, m)
    phases, fill = F.block_mean(phases, region.valid, m)
    hb, wb = agrid.shape
    block_label = region.labels.reshape(hb, m, wb * m).max(axis=1).reshape(hb, wb, m).max(axis=2)
    # Whole blocks only (their mean sits at the block centre); partial border blocks
    # get the smooth extrapolation from inside, and the fine mask trims them below.
    labels = np.where(fill >= 1.0, block_label, 0)
    valid = labels > 0
    report = ndimage.binary_dilation(valid, iterations=1) & (fill > 0)
    if blur is not None:
        blur = blur + (m * max(grid.step)) ** 2 / 12.0 * np.eye(2)
    return _AnalysisGrid(agrid, phases, valid, labels, report, region.valid, blur)


def _direct_pass2(ag: _AnalysisGrid, carriers: F.CarrierPair, fit: HomographyFit) -> np.ndarray:
    """Phases against the homography-warped carrier: phase += 2 pi (f . r - H^-1(r)).

    The term is smooth (affine up to perspective), so on the Block A grid its value at the
    block centre equals its block mean.
    """
    yy, xx = ag.grid.coords()
    u0, v0 = apply_inverse(fit.matrix, xx, yy)
    return ag.phases + 2 * np.pi * np.stack(
        [carriers.k1.fx * xx + carriers.k1.fy * yy - u0, carriers.k2.fx * xx + carriers.k2.fy * yy - v0], axis=-1
    )


def _warn_deviation(ag: _AnalysisGrid, ks, method: str, warn: list[str]) -> None:
    deviation = _frequency_deviation(ag.phases, ag.valid, ks, ag.grid.step)
    if deviation > _DEVIATION_WARN:
        advice = "use a finer grid or a shorter distance L" + (" or the Comparative Method" if method == "direct" else "")
        warn.append(
            f"strong distortion: the local grid frequency departs from the carrier by up to {100 * deviation:.0f}% "
            f"(results were reliable up to about {100 * _DEVIATION_WARN:.0f}% in tests); the result may be attenuated or wrong - "
            f"{advice}"
        )


def _channels(ag: _AnalysisGrid, ks, H_jac, p: AnalyzerParams, p_c, mm_per_px, sigma_mm, distance_m):
    """A1-A3: displacement in backdrop mm (camera frame) and the channels, on the analysis grid.

    Returns ``(delta_cam, Channels)``.
    """
    yy, xx = ag.grid.coords()
    common = dict(distance_m=distance_m, mm_per_px=mm_per_px, detrend_degree=p.detrend_degree, sigma_mm=sigma_mm,
                  labels=ag.labels, step_px=ag.grid.step, report_mask=ag.report)
    if p.a1_mode == "projective":
        delta = ag.phases * (p_c / (2 * np.pi))  # grid-frame components, exact
        J = p_c * inverse_jacobian(H_jac, xx, yy)
        hc, wc = ag.grid.shape
        R = _polar_rotation(J[hc // 2, wc // 2])
        ch = evaluate_displacement(delta, ag.valid, jacobian=J, component_blur_px2=ag.blur_px2, frame_rotation=R, **common)
        return delta @ R, ch
    M = np.array([ks[0].f / ks[0].norm, ks[1].f / ks[1].norm]).T  # columns: unit carriers
    proj_px = ag.phases / (2 * np.pi * np.array([ks[0].norm, ks[1].norm]))
    d_px = proj_px @ np.linalg.inv(M)  # (M^T)^{-1} p in row-vector form
    delta_cam = d_px * mm_per_px
    blur = ag.blur_px2
    iso_blur = None if blur is None else np.repeat((np.trace(blur, axis1=1, axis2=2).mean() / 2 * np.eye(2))[None], 2, 0)
    return delta_cam, evaluate_displacement(delta_cam, ag.valid, component_blur_px2=iso_blur, **common)


def _result_fields(delta_cam, ch) -> dict:
    """The registered fields (:data:`~glassdist.analyzer.result.FIELDS`) on the analysis grid."""
    return {
        "displacement_mm": delta_cam, "phi_eff_mD": ch.phi_eff_mD, "phi_shear_mD": ch.phi_shear_mD,
        "phi_total_mD": ch.phi_total_mD, "displacement_detrended_mm": ch.displacement_detrended_mm,
        "axis_deg": ch.axis_deg,
    }


def _reported_region(fields: dict, ag: _AnalysisGrid, mask, warn: list[str]):
    """The valid region on the image grid (where every field is finite) and the fill indices."""
    valid_c = ag.report.copy()
    for f_ in fields.values():
        valid_c &= np.isfinite(f_) if f_.ndim == 2 else np.all(np.isfinite(f_), axis=-1)
    valid_full, idx = image_grid_valid(valid_c, ag.grid, mask, fine_valid=ag.fine_valid)
    cover = float(valid_full[::4, ::4].mean())  # the reported region, as summary.json states it
    if mask is not None:  # an intentional mask is not a loss: the share of the region asked for
        cover = float(np.count_nonzero(valid_full[::4, ::4]) / max(np.count_nonzero(mask[::4, ::4]), 1))
    where = "the image" if mask is None else "the masked region"
    if cover < 0.75:
        warn.append(f"only {100 * cover:.0f}% of {where} could be analysed (occlusion, frames, low contrast or blur)")
    return valid_full, idx


@contextmanager
def _routed_warnings(warn: list[str]):
    """Numerical warnings raised inside the analysis join the result's warnings (not stderr)."""
    with warnings.catch_warnings(record=True) as caught, np.errstate(all="warn"):
        warnings.simplefilter("always")
        yield
    seen = set()
    for w in caught:
        text = f"numerical: {w.category.__name__}: {w.message}"
        if text not in seen:
            seen.add(text)
            warn.append(text)


# --------------------------------------------------------------------------- public API


def prepare_reference(reference: np.ndarray, *, params: AnalyzerParams | dict | None = None, pattern: str | None = None) -> ReferenceModel:
    """Derive, once, everything the Comparative Method needs from a glass-less photo.

    Parameters
    ----------
    reference : ndarray (H, W)
        Glass-less photograph of the grid, grey in [0, 1].
    params : AnalyzerParams or dict, optional
    pattern : {'lines', 'checkerboard'}, optional
        Overrides ``params.pattern``.

    Returns
    -------
    ReferenceModel
        Carriers, basebands, modulations and the homography of the reference's own grid;
        its exposure warnings go into every result analysed against it.
    """
    p = _resolve_params(params, pattern)
    warn: list[str] = []
    with _routed_warnings(warn):
        ref = _check_image(reference, "reference", warn)
        spec = F.compute_spectrum(ref)
        carriers = F.find_carriers(spec, min_period_px=p.min_period_px)
        F.check_image_size(ref.shape, max(carriers.k1.period_px, carriers.k2.period_px))
        covs = _covariances(carriers, p)
        grid = F.sampling_grid(ref.shape, list(covs), p.decimation)
        bb = _basebands(spec, carriers, covs, grid)
        mods = tuple(_modulation(b, c.period_px, grid, p) for b, c in zip(bb, (carriers.k1, carriers.k2)))
        # Homography of the reference's own grid: the pixel -> backdrop Jacobian (A1, projective).
        zs, cohs = _smooth_with_coherence(bb, (carriers.k1, carriers.k2), grid, p, smoothed_abs=mods)
        wrapped = [np.angle(z) for z in zs]
        region = valid_region(wrapped, cohs, mods, carriers, grid, p, None, [])
        if region.n == 0:
            raise InputError("the reference photo shows no usable grid region; check it is in focus and well exposed")
        yy, xx = grid.coords()
        psi = [unwrap(w, region.valid, region.labels, region.n, seed=p.ransac_seed) for w in wrapped]
        U = carriers.k1.fx * xx + carriers.k1.fy * yy + psi[0] / (2 * np.pi)
        V = carriers.k2.fx * xx + carriers.k2.fy * yy + psi[1] / (2 * np.pi)
        fit, _ = fit_grid_homography((U, V), yy, xx, region.labels, region.n, carriers, grid, p, [])
    return ReferenceModel(ref.shape, carriers, covs, grid, bb, mods, fit, p, tuple(warn))


def analyze(
    image: np.ndarray | str | os.PathLike,
    *,
    pitch_mm: float,
    distance_m: float,
    reference: np.ndarray | ReferenceModel | str | os.PathLike | None = None,
    params: AnalyzerParams | dict | str | os.PathLike | None = None,
    mask: np.ndarray | str | os.PathLike | None = None,
    pattern: str | None = None,
    detrend_degree: int | None = None,
    sigma_mm: float | None = None,
) -> AnalysisResult:
    """Measure the distortion field of a photo of a grid seen through glass.

    Parameters
    ----------
    image : ndarray (H, W) or path
        Grey photo in [0, 1] (see :func:`glassdist.io.read_image`), indexed (row, col), or
        the path of the photo (read with :func:`glassdist.io.read_image`).
    pitch_mm : float
        Printed grid pitch, mm (line spacing; square size for a checkerboard).
    distance_m : float
        Glass-to-backdrop distance L, m.
    reference : ndarray (H, W), ReferenceModel or path, optional
        Glass-less photo: Comparative Method. None: Direct Method.
    params : AnalyzerParams, dict or path, optional
        Algorithm parameters (dict or JSON file = overrides of the shipped defaults).
    mask : ndarray of bool (H, W) or path, optional
        User region; False (zero) pixels are excluded.
    pattern : {'lines', 'checkerboard'}, optional
        Overrides ``params.pattern``.
    detrend_degree : int, optional
        Overrides ``params.detrend_degree`` (A2 polynomial degree N).
    sigma_mm : float, optional
        Overrides ``params.sigma_mm``: reporting smoothing scale on the backdrop, mm.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    InputError
        Bad physical inputs or images (blank, saturated, no grid, too small, size mismatch).
    AnalysisError
        No reliable region could be analysed.

    Notes
    -----
    Carrier *i* of the distorted photo has phase
    ``Phi_i(r) = 2 pi (e_i . X(r)) / p_c``, X(r) the backdrop point seen at r. The
    heterodyne against the reference (real or synthesised) leaves
    ``phi_i = 2 pi (e_i . delta) / p_c`` so that, exactly,

    .. math:: \\delta_i = \\frac{p_c}{2\\pi}\\,\\varphi_i .

    The stages: inputs checked, F1-F3 (:func:`_demodulate`), F4 valid region
    (:func:`~glassdist.analyzer.region.valid_region`) and unwrapping, Block I (Direct),
    the Block A grid, A1-A3 (:func:`_channels`), the result.

    References
    ----------
    Paper §2.2; Takeda et al. (1982); Herraez et al. (2002); Fischler & Bolles (1981).

    Examples
    --------
    A line grid of period 8 px (10 mm) seen through a small converging lens, 0.05 D at its
    centre (Comparative Method):

    >>> import numpy as np
    >>> from glassdist import analyze
    >>> from glassdist.synthetic import lens_displacement, synthetic_capture
    >>> cap = synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25,
    ...                         displacement=lens_displacement(0.05, 2.0, radius_mm=40.0))
    >>> res = analyze(cap.image, pitch_mm=10.0, distance_m=2.0, reference=cap.reference)
    >>> res.method, res.phi_eff_mD.shape
    ('comparative', (192, 256))
    >>> bool(res.phi_eff_mD[96, 128] < 0)  # a converging lens reads phi_eff < 0
    True
    """
    image, reference, params, mask = _api_inputs(image, reference, params, mask, detrend_degree, sigma_mm)
    warn: list[str] = []
    with _routed_warnings(warn):
        meas = _measure(image, pitch_mm, distance_m, reference, params, mask, pattern, warn)
        evaluated = _evaluate(meas, meas.ag, warn)
    return _result(meas, evaluated, warn)


def _api_inputs(image, reference, params, mask, detrend_degree, sigma_mm):
    """Photos and mask given as paths read; ``detrend_degree`` / ``sigma_mm`` merged into the parameters."""
    from ..io import read_image, read_mask

    if isinstance(image, (str, os.PathLike)):
        image = read_image(image)
    if isinstance(reference, (str, os.PathLike)):
        reference = read_image(reference)
    if isinstance(mask, (str, os.PathLike)):
        mask = read_mask(mask, np.shape(image))
    settings = {k: v for k, v in (("detrend_degree", detrend_degree), ("sigma_mm", sigma_mm)) if v is not None}
    if settings:
        if params is None and isinstance(reference, ReferenceModel):
            params = reference.params
        if isinstance(params, AnalyzerParams):
            params = {**params.model_dump(exclude_unset=True), **settings}
        else:
            params = load_params(params, **settings)
    return image, reference, params, mask


@dataclass(frozen=True)
class _Measurement:
    """One photo measured up to the Block A grid (everything A1-A3 needs)."""

    inputs: _Inputs
    carriers: F.CarrierPair
    fit: HomographyFit | None
    baseline: np.ndarray
    mm_per_px: float
    sigma_mm: float
    ag: _AnalysisGrid
    n_regions: int
    pitch_mm: float
    distance_m: float


def _measure(image, pitch_mm, distance_m, reference, params, mask, pattern, warn: list[str]) -> _Measurement:
    """Inputs, F1-F4, Block I (Direct) and the Block A grid with its phases (pass 2 applied).

    ``baseline``: the homography the phases are relative to in the logical frame (Direct:
    the fit; Comparative: the reference's own grid, which also gives the A1 Jacobian).
    """
    inp = _checked_inputs(image, pitch_mm, distance_m, reference, params, mask, pattern, warn)
    p, p_c = inp.params, inp.carrier_period_mm
    demod = _demodulate(inp.image, inp.reference, p)
    carriers = demod.carriers
    wrapped = [np.angle(z) for z in demod.signals]
    region = valid_region(wrapped, demod.coherences, demod.mods, carriers, demod.grid, p, inp.mask, warn)
    del wrapped
    _check_region(region, demod.mods, warn)
    phases = _unwrapped_phases(demod, region, p)  # F4
    fit = _direct_baseline(phases, demod, region, p, warn) if demod.method == "direct" else None
    H_jac = fit.matrix if fit is not None else inp.reference.homography.matrix
    phases[~region.valid] = np.nan
    mm_per_px = p_c * float(np.sqrt(carriers.k1.norm * carriers.k2.norm))
    sigma_mm, blur = _smoothing_mm(demod, p, p_c, mm_per_px, warn)
    ag = _to_analysis_grid(phases, region, demod.grid, sigma_mm / mm_per_px, blur, p)
    del phases, demod
    if fit is not None:
        ag = replace(ag, phases=_direct_pass2(ag, carriers, fit))
    inp = replace(inp, image=None)  # several captures are held at once: not their photos
    return _Measurement(inp, carriers, fit, H_jac, mm_per_px, sigma_mm, ag, region.n, float(pitch_mm), float(distance_m))


def _evaluate(meas: _Measurement, ag: _AnalysisGrid, warn: list[str]):
    """A1-A3 on the phases of ``ag`` (the measurement's own, or an average of several).

    Returns ``(ag, fields, valid_full, idx)`` for :func:`_result`.
    """
    p, p_c, carriers = meas.inputs.params, meas.inputs.carrier_period_mm, meas.carriers
    ks = (carriers.k1, carriers.k2)
    _warn_deviation(ag, ks, "direct" if meas.fit is not None else "comparative", warn)
    delta_cam, ch = _channels(ag, ks, meas.baseline, p, p_c, meas.mm_per_px, meas.sigma_mm, meas.distance_m)
    fields = _result_fields(delta_cam, ch)
    valid_full, idx = _reported_region(fields, ag, meas.inputs.mask, warn)
    return ag, fields, valid_full, idx


def _result(meas: _Measurement, evaluated, warn: list[str], *, extra_fields: dict | None = None,
            n_regions: int | None = None) -> AnalysisResult:
    """The :class:`AnalysisResult` of :func:`_evaluate`'s output (``extra_fields``: more registered fields)."""
    ag, fields, valid_full, idx = evaluated
    p = meas.inputs.params
    for w in warn:
        log.warning(w)
    return AnalysisResult(
        method="direct" if meas.fit is not None else "comparative",
        valid=valid_full,
        mm_per_px=meas.mm_per_px,
        sigma_mm=meas.sigma_mm,
        detrend_degree=p.detrend_degree,
        pitch_mm=meas.pitch_mm,
        distance_m=meas.distance_m,
        carrier_period_mm=meas.inputs.carrier_period_mm,
        carriers=meas.carriers,
        homography=None if meas.fit is None else meas.fit.matrix,
        homography_fit=meas.fit,
        params=p,
        warnings=tuple(warn),
        sampling_step_px=ag.grid.step,
        n_regions=meas.n_regions if n_regions is None else n_regions,
        _deferred={"fields": {**fields, **(extra_fields or {})}, "idx": idx, "grid": ag.grid},
    )
