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
from ..plausibility import grid_spread, review_measurement
from ..validation import DISTANCE_M, PITCH_MM, check_number
from . import deform as D
from . import fourier as F
from .bulk import DIRECT_BULK_REASON, BulkChannel, bulk_channel, pinned_strain
from .homography import HomographyFit, fit_grid_homography, logical_coordinates, logical_jacobian
from .lens import LensCalibration
from .metrics import (
    detrend_increment, evaluate_displacement, inverse_2x2, masked_gaussian, polynomial_detrend, strain_tensor,
)
from .transfer import InstrumentTransfer, dirichlet_response
from .params import AnalyzerParams, given_settings, load_params
from .pattern import settle_pattern
from .region import (
    ANALYSED, BEYOND_RANGE, FRAGMENT, LOW_MODULATION, PHASE_RESIDUE, Region, beyond_range_warning, contamination_px,
    downsample_mask, excluded_area_warning, grid_seen, guard_band, local_contrast, pixel_quality, trim_edges, valid_region, within,
)
from .resample import image_grid_valid
from .result import AnalysisResult
from .uncertainty import (channel_uncertainty, deformation_channel_gain, deformation_noise_gains, displacement_sigma,
                          gradient_covariance, noise_std, phase_variance)
from .unwrap import unwrap

__all__ = ["AnalysisResult", "ReferenceModel", "analyze", "calibrate_from_photo", "prepare_reference"]

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
    noise_std: float = float("nan")
    grid_spread: float = float("nan")  # glassdist.plausibility.grid_spread: the swapped-pair check


# --------------------------------------------------------------------------- checks


def _check_physical(pitch_mm: float, distance_m: float) -> None:
    # finite and within the physical ranges of the validation layer (a 1e-300 m distance gives NaN channels)
    check_number(pitch_mm, "pitch_mm (--pitch-mm, the printed grid pitch)", PITCH_MM)
    check_number(distance_m, "distance_m (--distance-m, the glass-to-grid distance L)", DISTANCE_M)


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


def _bandpass_px2(covs) -> np.ndarray:
    """Spatial covariance (px^2) of each carrier's Gaussian bandpass of frequency covariance ``cov``: ``cov^-1 / (4 pi^2)``."""
    return np.array([np.linalg.inv(cov) / (4 * np.pi**2) for cov in covs])


def _demodulation_blur_px2(carriers: F.CarrierPair, covs, p: AnalyzerParams) -> np.ndarray:
    """Spatial covariance (px^2) of the low-pass Block F applies to each phase map: the bandpass, then the complex smoothing."""
    s3 = [p.smoothing_periods * c.period_px for c in (carriers.k1, carriers.k2)]
    return _bandpass_px2(covs) + np.array([s**2 * np.eye(2) for s in s3])


def _margins(carriers: F.CarrierPair, covs, p: AnalyzerParams, direct: bool) -> tuple[float, float]:
    """Contamination margins (px) at excluded areas and at the image edges.

    Given in carrier periods by ``border_periods``/``edge_margin_periods``, else derived
    from Block F's kernel for ``margin_phase_error_periods``
    (:func:`~glassdist.analyzer.region.contamination_px`). At the image edges the derived
    margin has a floor: the wrap-around of the periodic FFT is an unrelated signal of full
    amplitude that the reference cancels only where both photos see the same pattern there
    (not after a camera move, not where the glass distorts the edge), and edge samples
    enter the A2 fit of the whole region. Measured: with the derived ~2 px alone, the
    reduced pitch experiment's interior Direct-vs-Comparative phi_shear reads 3.5 % (2.9 %
    from 0.5 period), a moved capture registers one period off, and synthetic Direct round
    trips lose phi_shear correlation (0.975-0.981, >= 0.997 from 0.5 period; the Direct
    Method keeps 0.75, its value before the margins were derived).
    """
    period = max(carriers.k1.period_px, carriers.k2.period_px)
    derived = contamination_px(_demodulation_blur_px2(carriers, covs, p), p.margin_phase_error_periods)
    derived_edge = max(derived, (_DIRECT_EDGE_PERIODS if direct else _EDGE_PERIODS) * period)
    border = derived if p.border_periods is None else p.border_periods * period
    edge = derived_edge if p.edge_margin_periods is None else p.edge_margin_periods * period
    return float(border), float(edge)


_EDGE_PERIODS = 0.5
_DIRECT_EDGE_PERIODS = 0.75


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


def _analysis_block(sigma_px: float, blur, grid: F.SamplingGrid, p: AnalyzerParams, passes: int = 1,
                    photo: tuple[int, float] = (0, 0.0)) -> int:
    """Block factor (1, 2 or 4) of the Block A grid: as coarse as two bounds allow.

    Its step stays below half the residual smoothing (what the phi maps need), and its block
    means keep at least :data:`BLOCK_MIN_RESPONSE` of the displacement at the frequency where
    the demodulation (``passes`` demodulations, then ``photo``: F5's photo passes and the sigma of
    the low-pass they start from, px) passes half of it (what the displacement output
    needs: F5's passes widen the demodulation's passband, and 4 x 4 means of its finer grid
    would cut into it).
    """
    if p.analysis_block != "auto":
        m = int(p.analysis_block)
        return m if grid.shape[0] % m == 0 and grid.shape[1] % m == 0 else 1
    worst = 0.0 if blur is None else max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
    residual = np.sqrt(max(sigma_px**2 - worst, 0.0))
    step = max(grid.step)
    h, w = grid.shape
    nu = None if blur is None else _half_response_frequency(InstrumentTransfer(
        blur, fine_step_px=grid.step, passes=passes, photo_passes=photo[0], restart_sigma_px=photo[1]))
    for m in (4, 2):
        if h % m == 0 and w % m == 0 and m * step <= residual / 2.0 and min(h, w) // m >= 16:
            if nu is None or float(dirichlet_response(m, step, nu)) >= BLOCK_MIN_RESPONSE:
                return m
    return 1


#: Least response of Block A's block means (Dirichlet kernel) at the frequency where the demodulation
#: passes half the displacement: about four blocks per wavelength there. On the waves photo the one
#: pass's 2 x 2 means of its 4.06 px grid keep 0.94 (4 x 4: 0.72); after F5's four or ten demodulations
#: on its 2.03 px grid 4 x 4 means keep 0.81 or 0.73, 2 x 2 means 0.96 or 0.94.
BLOCK_MIN_RESPONSE = 0.9


def _half_response_frequency(tr: InstrumentTransfer) -> float:
    """The frequency (cycles/px) where the demodulation's response first falls below one half, the highest along either axis for either carrier."""
    f = np.linspace(0.0, 0.5, 2001)
    zero = np.zeros_like(f)
    out = 0.0
    for i in range(2):
        for fy, fx in ((f, zero), (zero, f)):
            below = np.nonzero(tr.demodulation(i, fy, fx) < 0.5)[0]
            out = max(out, float(f[below[0]]) if below.size else 0.5)
    return out


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
    noise_std: float = float("nan")
    passes: int = 1  # demodulations the phase sums (F5's iterative deformation; 1: one pass)
    photo_passes: int = 0  # F5's photo passes after those, from their field low-passed by restart_sigma_px
    restart_sigma_px: float = 0.0


@dataclass(frozen=True)
class _AnalysisGrid:
    """Unwrapped phases (rad, per carrier, pass 2 applied for Direct) on the Block A grid.

    ``valid``/``labels`` describe whole blocks; ``report`` adds the partial border blocks the
    fine mask trims later; ``fine_valid`` is the demodulation-grid region when blocks were formed;
    ``transfer`` is the instrument's transfer for each phase map (None: not compensated).
    """

    grid: F.SamplingGrid
    phases: np.ndarray
    valid: np.ndarray
    labels: np.ndarray
    report: np.ndarray
    fine_valid: np.ndarray | None
    transfer: InstrumentTransfer | None
    passes: int = 1  # demodulations the phases sum (F5), its photo passes included
    photo: tuple[int, float] = (0, 0.0)  # F5's photo passes and the sigma (px) of the low-pass they start from


@dataclass(frozen=True)
class _F5:
    """F5's outcome: its demodulation, residual phases, modulations over the bandpass gain, the samples beyond
    reach, the region its predictor was measured on (one-pass labels elsewhere) and the samples it grew (all on
    ``demod.grid``)."""

    demod: _Demodulation
    residual: list
    region_mods: list
    beyond: np.ndarray
    measured: Region
    grown: np.ndarray


# --------------------------------------------------------------------------- stages


def _checked_inputs(image, pitch_mm, distance_m, reference, params, mask, pattern, warn: list[str]) -> _Inputs:
    """Physical inputs, image, mask and reference checked; the reference prepared once."""
    _check_physical(float(pitch_mm), float(distance_m))
    if isinstance(reference, ReferenceModel):
        p = reference.params if params is None and pattern is None else _resolve_params(params, pattern)
    else:
        p = _resolve_params(params, pattern)
    img = _check_image(image, "image", warn)
    p = settle_pattern(p, img, warn)  # 'auto' decided from the photo, a given pattern checked against it
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


def _demodulate(img: np.ndarray, refm: ReferenceModel | None, p: AnalyzerParams,
                like: _Demodulation | None = None) -> _Demodulation:
    """F1-F3: one FFT of the photo, the carriers (its own, or the reference's), heterodyne, F3.

    ``like``: an earlier demodulation whose carriers, filters and grid are reused (F5's passes).
    """
    spec = F.compute_spectrum(img)
    if like is not None and refm is None:
        carriers, covs, grid = like.carriers, like.covariances, like.grid
    elif refm is None:
        carriers = F.find_carriers(spec, min_period_px=p.min_period_px)
        F.check_image_size(img.shape, max(carriers.k1.period_px, carriers.k2.period_px))
        covs = _covariances(carriers, p)
        grid = F.sampling_grid(img.shape, list(covs), p.decimation)
    else:
        carriers, covs, grid = refm.carriers, refm.covariances, refm.grid
        if like is None:
            F.find_carriers(spec, min_period_px=p.min_period_px)  # raises if the photo shows no grid
    ks = (carriers.k1, carriers.k2)
    noise = like.noise_std if like is not None else noise_std(spec, carriers)
    if refm is None:
        # Direct: F3 applied in the spectral patch; coherence against the modulation G*|b|.
        pairs = [F.baseband(spec, c, cov, grid, smooth_sigma_px=p.smoothing_periods * c.period_px) for c, cov in zip(ks, covs)]
        del spec
        mods = [_modulation(b, c.period_px, grid, p) for (b, _), c in zip(pairs, ks)]
        zs = tuple(gb for _, gb in pairs)
        cohs = tuple(np.abs(z) / np.maximum(m_, 1e-30) for z, m_ in zip(zs, mods))
        return _Demodulation("direct", carriers, covs, grid, zs, cohs, mods, noise)
    bb = _basebands(spec, carriers, covs, grid)
    del spec
    mods = [_modulation(b, c.period_px, grid, p) for b, c in zip(bb, ks)]
    zs = tuple(b * np.conj(r) for b, r in zip(bb, refm.baseband))
    mods += list(refm.modulation)
    zs, cohs = _smooth_with_coherence(zs, ks, grid, p)  # F3
    return _Demodulation("comparative", carriers, covs, grid, zs, cohs, mods, noise)


def _region(demod: _Demodulation, p: AnalyzerParams, mask, warn: list[str], margins, residual=None, mods=None,
            beyond=None, contrast=None, first: Region | None = None) -> Region:
    """F4's valid region of a demodulation.

    After F5: ``residual`` (its residual phases, for the local-frequency test), ``mods`` (the
    modulations over the bandpass's gain at the local frequency), ``beyond`` (where that
    gain is out of reach) and ``first``, the region its predictor was measured on: the region is
    restricted to it and its branch cuts drawn on what is left
    (:func:`~glassdist.analyzer.region.within`). ``contrast``: the photo's local contrast, for the
    cause of an exclusion.
    """
    wrapped = [np.angle(z) for z in demod.signals]
    region = valid_region(wrapped, demod.coherences, demod.mods if mods is None else mods, demod.carriers, demod.grid,
                          p, mask, warn, margin_px=margins[0], edge_margin_px=margins[1], deviation_phases=residual,
                          beyond=beyond, contrast=contrast, cuts=first is None)
    return region if first is None else within(region, first, p, wrapped)


def _follow_local_grid(img, refm: ReferenceModel | None, demod: _Demodulation, region: Region, phases: np.ndarray,
                       p: AnalyzerParams, contrast):
    """F5: iterative deformation of the reference (:mod:`~glassdist.analyzer.deform`).

    Returns None when no pass is needed (``deformation_passes`` 0, or the one-pass local
    frequency within ``deformation_min_deviation`` of the carrier), else an :class:`_F5`: the
    demodulation whose phase is ``predictor + residual`` (its ``passes``: the demodulations
    summed, the one-pass one included; transfer in :mod:`~glassdist.analyzer.transfer`), on a
    grid fine enough for the reach (:func:`~glassdist.analyzer.deform.deformation_grid`), and
    the region the predictor was measured on: the one-pass region grown by up to
    ``deformation_growth_passes`` passes (:func:`~glassdist.analyzer.deform.grow`), then up to
    ``deformation_passes`` passes to converge. ``contrast(grid)``: the photo's local contrast on
    ``grid`` (:func:`~glassdist.analyzer.region.local_contrast`); the growth enters only where it
    shows a grid (:func:`~glassdist.analyzer.region.grid_seen`).
    """
    ks = demod.carriers
    if p.deformation_passes == 0 or img is None or region.n == 0:
        return None
    if _frequency_deviation(phases, region.valid, (ks.k1, ks.k2), demod.grid.step) <= p.deformation_min_deviation:
        return None
    covs = demod.covariances
    period = max(ks.k1.period_px, ks.k2.period_px)
    grid = D.deformation_grid(demod.grid, p.deformation_max_deviation, min(ks.k1.period_px, ks.k2.period_px), p.decimation)
    own = None if refm is None else np.stack(refm.baseband, axis=-1)  # the reference's own phase (its lens, its print)
    bb_img = _basebands(F.compute_spectrum(img), ks, covs, grid)
    pred = D.to_grid(D.fill_nearest(np.nan_to_num(phases), region.valid), demod.grid, grid)
    measured = D.to_grid(region.valid, demod.grid, grid, nearest=True)
    first = D.to_grid(region.quality, demod.grid, grid, nearest=True)
    # A phase residue of the one pass is a singularity of the grid itself (a dislocation, a tear), not a
    # frequency the bandpass clipped: no continuous prediction crosses it, so the growth goes around it.
    growable = first != PHASE_RESIDUE
    if p.deformation_growth_passes > 0:
        growable &= grid_seen(contrast(grid), measured, period, grid)
    # the one pass's connected parts: the growth never merges two (deform.grow)
    parts = np.where(measured, D.to_grid(region.labels, demod.grid, grid, nearest=True), 0).astype(np.int32)
    grown = np.zeros_like(measured)
    growth_left, converging, k = p.deformation_growth_passes, 0, 0
    while True:
        k += 1
        het, bb_ref = _warped_heterodyne(bb_img, pred, own, grid, ks, covs)
        zs, cohs = _smooth_with_coherence(het, (ks.k1, ks.k2), grid, p)
        del het
        res = np.stack([np.angle(z) for z in zs], axis=-1)
        coherent = np.all([c_ > p.coherence_threshold for c_ in cohs], axis=0)
        ok = coherent & measured
        step = _rms_update_periods(res, ok, ks, period)
        new = D.grow(measured, coherent & growable, res, grid, period, parts) if growth_left > 0 else np.zeros_like(measured)
        growth_left = growth_left - 1 if new.any() else 0
        converging += 0 if new.any() else 1
        log.debug("F5 pass %d: RMS update %.4f period, %d samples grown", k, step, int(new.sum()))
        if not new.any() and (step < p.deformation_tolerance_periods or converging >= p.deformation_passes):
            break
        upd = ok | new
        measured |= new
        grown |= new
        pred = pred + D.fill_nearest(np.where(upd[..., None], res, 0.0), upd)
    # A grown sample started from its neighbours' prediction, not from the one pass's G-smoothed phase, so the
    # documented transfer holds for it only once it has converged: kept where its last update is small.
    late = grown & (np.sqrt(np.sum(D.phase_to_displacement_px(res, ks) ** 2, axis=-1)) / period
                    > D.GROWTH_MAX_LAST_UPDATE_PERIODS)
    measured &= ~late
    grown &= ~late
    # The last residual was measured against the reference warped by pred: phi = pred + residual,
    # the converged field (the filters' Gaussian acts on the residual only; after n demodulations
    # the linear transfer is (1 - (1 - G B)^n) / B, transfer.InstrumentTransfer).
    phase = pred + res
    n_photo, restart_px = 0, 0.0
    held: list = []

    def img_mods():  # the photo's modulation on F5's grid, computed once, only where something needs it
        if not held:
            held.extend(_modulation(b, c.period_px, grid, p) for b, c in zip(bb_img, (ks.k1, ks.k2)))
        return held

    photo_max = p.photo_passes_for(refm is not None)
    if photo_max > 0:
        # The photo passes start from the field low-passed: what it carries beyond the filters' passband
        # no pass can see, and the deformation would fold it into what they do see.
        restart_px = p.deformation_photo_restart_periods * period
        phase, n_photo, photo_mods = _photo_passes(img, refm, demod, bb_img, own,
                                                   _low_passed(phase, measured, grid, restart_px), measured, grid, p,
                                                   photo_max, img_mods)
    total = [(np.abs(z) * np.exp(1j * phase[..., i])).astype(np.complex64) for i, z in enumerate(zs)]
    if grid is demod.grid:
        mods = list(demod.mods)
    else:  # the photo's on F5's grid, the reference's brought to it
        mods = list(img_mods()) + [D.to_grid(m_, demod.grid, grid) for m_ in demod.mods[2:]]
    # The bandpass's gain at the local frequency, read off the warped reference (a uniform grid
    # of amplitude 1/2 per carrier): the photo's modulation is judged against it (a faint grid where the gain
    # explains it is not occluded), and where the gain is below its value at
    # deformation_max_deviation off the carrier the signal is beyond reach.
    gain = [_modulation(r, c.period_px, grid, p) / np.float32(0.5) for r, c in zip(bb_ref, (ks.k1, ks.k2))]
    floor = float(np.exp(-0.5 * (p.deformation_max_deviation / p.bandpass_sigma_along) ** 2))
    beyond = np.any([g_ < floor for g_ in gain], axis=0)
    region_mods = [m_ / np.maximum(g_, floor) for m_, g_ in zip(mods[:2], gain)] + mods[2:]
    if n_photo:  # the noise goes as one over the modulation the last pass measured at (_photo_passes)
        mods = photo_mods + mods[2:]
    out = _Demodulation(demod.method, ks, covs, grid, tuple(total), cohs, mods, demod.noise_std, passes=k + 1,
                        photo_passes=n_photo, restart_sigma_px=restart_px)
    return _F5(out, list(res.transpose(2, 0, 1)), region_mods, beyond, Region(measured, measured.astype(np.int32), 1, first),
               grown)


def _warn_sampling(carriers: F.CarrierPair, warn: list[str]) -> None:
    """A carrier period under 3.5 px may be the alias of a grid finer than 2 px per period.

    A grid of frequency f > 0.5 cycles/px shows at 1 - f; for 1 - f < 1/3 (the carrier band)
    that is a period of 3 to 3.5 px for true periods of 1.4 to 1.5 px, read at the wrong scale.
    """
    short = min(carriers.k1.period_px, carriers.k2.period_px)
    if short < 3.5:
        warn.append(
            f"the grid's carrier period is only {short:.2f} px, near the sampling limit: a grid finer than 2 px per "
            "period would show at this period and give a wrong mm_per_px; check the scale, or photograph the grid larger"
        )


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


def _direct_baseline(phases, demod: _Demodulation, region: Region, p: AnalyzerParams, warn: list[str],
                     lens: LensCalibration | None = None) -> HomographyFit:
    """Block I (pass 1): homography (and camera lens) of the logical grid; each region's integer offset removed from ``phases``."""
    carriers = demod.carriers
    yy, xx = demod.grid.coords()
    U = carriers.k1.fx * xx + carriers.k1.fy * yy + phases[..., 0] / (2 * np.pi)
    V = carriers.k2.fx * xx + carriers.k2.fy * yy + phases[..., 1] / (2 * np.pi)
    fit, offsets = fit_grid_homography((U, V), yy, xx, region.labels, region.n, carriers, demod.grid, p, warn, lens=lens)
    if 0.1 <= fit.inlier_fraction < _MIN_INLIERS:
        warn.append(
            f"Direct Method: only {100 * fit.inlier_fraction:.0f}% of the grid points lie within "
            f"{p.ransac_threshold_periods:g} period of the fitted homography (inlier RMS {fit.rms_inlier_px:.2f} px): the "
            "baseline is weakly determined (strong distortion, or the camera's lens distortion), and results are relative "
            "to it; take a glass-less reference (Comparative Method) where possible"
        )
    if region.n > 1:
        phases -= (2 * np.pi * offsets[region.labels]).astype(np.float32)
    return fit


# Block I's fit is called weak below this inlier fraction (below 0.1 Block I warns itself). A roller
# wave of 0.375 carrier period amplitude keeps 30% of the points as inliers (the outliers are the
# signal); a rig whose lens the homography cannot follow was seen at 20%.
_MIN_INLIERS = 0.25
# The Direct Method's statistics are called N-dependent when mean or p95 |phi_eff| over the trusted
# region moves by more than this share between degree N and N + 1 (the bundled photos' Direct-Comparative
# agreement target).
_N_MOVE_WARN = 0.05


def _warn_n_dependence(meas, ag: _AnalysisGrid, ch, ks, warn: list[str]) -> None:
    """Direct: warn when the trusted-region statistics move between detrend degree N and N + 1.

    The Direct Method's baseline (Block I) leaves whatever the camera and the glass share
    with a homography and the lens model to the degree-N detrend; where that matters, raising
    N changes the result. Block A is linear, and A2 at N + 1 removes exactly
    ``Q = P_{N+1} delta - P_N delta`` more than at N (:func:`~glassdist.analyzer.metrics.detrend_increment`,
    a polynomial of degree N + 1 per region), so ``phi_eff(N + 1) = phi_eff(N) - phi_eff[G * Q]``.
    The second term is the trace of Q's strain smoothed by a plain Gaussian of the reporting
    sigma (order-0 normalised convolution), not by Block A's whole kernel (the instrument
    transfer's inverse and the stencil corrections, which act on a polynomial's high
    derivatives only): the estimate costs a polynomial fit and one smoothing instead of a
    second Block A (3.3 s of an 8 s analysis at 24 Mpx). Against that second Block A, on the
    bundled photos and synthetic waves at N = 1-4, the estimated mean and p95 |phi_eff| at
    N + 1 differ by under 0.2 % of the statistic, and by 2.3 % at most (the waves photo, N = 4:
    its p95), against the 5 % move the warning keys on. Mean and p95 |phi_eff| over the
    analysis-grid samples farther than the guard band from the region's border are compared
    (``_N_MOVE_WARN``, and at least 0.01 mD).
    """
    n = meas.inputs.params.detrend_degree
    move = _n_move(meas, ag, ch, ks)
    if move is None:
        return
    s0, s1, what = move
    if abs(s1 - s0) > _N_MOVE_WARN * s0 and abs(s1 - s0) > 0.01:
        warn.append(
            f"Direct Method with detrend degree {n}: the result depends on N - {what} |phi_eff| moves from "
            f"{s0:.3g} to {s1:.3g} mD ({100 * (s1 - s0) / s0:+.0f}%) with --detrend-degree {n + 1}: a distortion the "
            "homography and the lens model leave (an uncalibrated camera lens, or glass curved over the whole view) - "
            "calibrate the lens (--lens-photo, --camera-file) or use the Comparative Method"
        )


def _beyond_guard(meas, ag: _AnalysisGrid) -> np.ndarray:
    """Analysis-grid samples farther than the guard band from the region's border (the trusted pixels' rule)."""
    return ndimage.distance_transform_edt(np.pad(ag.valid, 1), sampling=ag.grid.step)[1:-1, 1:-1] > meas.guard_px


# The Direct Method's reading is compared with its floor on the rig (the calibration photo read the same
# way) when the floor's mean |phi_eff| reaches this share of the pane's: above it the board and the camera
# move the pane's statistics by a visible amount (the bundled photos' board: 14 % of the waves' reading,
# which still agree with the Comparative within 3 %; 70 % of the floating ring's, which reads 22 % high).
_FLOOR_SHARE_WARN = 0.1


def _warn_rig_floor(meas, ag: _AnalysisGrid, ch, warn: list[str]) -> None:
    """Direct: warn when the calibration photo's own reading is a sizeable share of the pane's.

    :attr:`~glassdist.analyzer.lens.LensCalibration.floor` holds the calibration photo (no
    glass) read by the Direct Method at the same detrend degree, smoothing and L; it is
    compared, as mean |phi_eff|, with the pane's over the analysis-grid samples farther than
    the guard band from the region's border (those of :func:`_warn_n_dependence`), where the
    floor stands above the calibration photo's own noise (twice its median
    ``phi_eff_sigma_mD``; a perfect rendered board reads 0.6 of it) and only where the
    detrend degrees match (another degree reads another floor; L is scaled, phi ~ 1 / L).
    """
    cal = meas.fit.lens
    floor = {} if cal is None else cal.floor
    if not floor or floor["detrend_degree"] != meas.inputs.params.detrend_degree:
        return
    scale = floor["distance_m"] / meas.distance_m  # phi scales as 1 / L
    f = floor["mean_abs_phi_eff_mD"] * scale
    a = np.abs(ch.phi_eff_mD[_beyond_guard(meas, ag) & np.isfinite(ch.phi_eff_mD)])
    if a.size < 64:
        return
    m = float(np.mean(a))
    # A floor at the photo's own noise (mean |noise| is 0.8 of its sigma) says nothing about the rig.
    if f > _FLOOR_SHARE_WARN * m and floor["mean_abs_phi_eff_mD"] > 2.0 * floor["phi_eff_sigma_mD"]:
        warn.append(
            f"Direct Method: the calibration photo (no glass), read the same way, shows mean |phi_eff| {f:.3g} mD "
            f"(p95 {floor['p95_abs_phi_eff_mD'] * scale:.3g} mD, noise "
            f"{floor['phi_eff_sigma_mD'] * scale:.2g} mD), {100 * f / m:.0f}% of this "
            f"pane's {m:.3g} mD: the board (its print, its flatness) or the camera departs from the perfect grid and "
            "the lens model by that much, and the Direct Method reads it as glass - use the Comparative Method, or a "
            "flatter, finer-printed board"
        )


def _plain_phi_eff(delta_mm: np.ndarray, jacobian, meas, ag: _AnalysisGrid) -> np.ndarray:
    """phi_eff (mD) of a displacement on the analysis grid by Block A's rule without its transfer: the strain
    through ``jacobian`` (None: ``mm_per_px``), its trace over L, smoothed by a plain Gaussian of the
    reporting sigma (order-0 normalised convolution). What the Direct Method's checks read a trend with
    (:func:`_n_move`, :func:`_warn_lens_takes_power`); NaN where the strain is.
    """
    eps = strain_tensor(delta_mm, ag.grid.step, mm_per_px=meas.mm_per_px, jacobian=jacobian)
    phi = (eps[..., 0, 0] + eps[..., 1, 1]) * (1000.0 / meas.distance_m)  # phi_eff is the trace (metrics)
    sigma_px = meas.sigma_mm / meas.mm_per_px
    return masked_gaussian(phi, np.isfinite(phi).astype(float), sigma_px**2 * np.eye(2), ag.grid.step, order=0)


# The Direct Method says what the camera lens fitted from the photo takes for itself when, read as glass,
# it would reach this share of the pane's own reading (mean |phi_eff|), and at least 0.01 mD.
_LENS_SHARE_WARN = 1.0


def _warn_lens_takes_power(meas, ag: _AnalysisGrid, ch, warn: list[str]) -> None:
    """Direct: warn when the lens fitted from the photo holds more centred power than the pane reads.

    A camera lens's distortion and glass power centred on the optical axis have one form
    (docs/lens_calibration.md); Block I's checks (:func:`~glassdist.analyzer.homography.refit_with_lens`)
    say so when the residual shows it, but a centred feature that fills the view passes them and
    is taken whole for the lens (a Gaussian lens wider than the view reads 0.093 of its truth).
    The photo cannot tell the two; what it can tell is how much is at stake: the
    lens's own displacement relative to the bare homography, ``p_c (H^-1(L^-1(r)) - H^-1(r))``
    (what Direct pass 2 removed with the lens), read as glass by Block A's rule (degree-N
    detrend per region, then :func:`_plain_phi_eff` through the baseline's Jacobian). Where
    its mean |phi_eff| reaches the pane's (over the samples beyond the guard band), the reading
    rests on the lens being the camera's, and a warning gives both figures. Only for a lens fitted from the photo and applied: a calibration
    photo or a camera file pins the lens.
    """
    fit = meas.fit
    lens = fit.lens_model
    if lens is None or fit.lens.source != "self" or meas.inputs.params.a1_mode != "projective":
        return
    p = meas.inputs.params
    ok = _beyond_guard(meas, ag) & np.isfinite(ch.phi_eff_mD)
    if ok.sum() < 64:
        return
    p_c = meas.inputs.carrier_period_mm
    yy, xx = ag.grid.coords()
    u1, v1 = logical_coordinates(fit.matrix, lens, xx, yy)
    u0, v0 = logical_coordinates(fit.matrix, None, xx, yy)
    d = np.stack([u1 - u0, v1 - v0], axis=-1) * p_c
    d = polynomial_detrend(d, np.where(ag.valid, ag.labels, 0), p.detrend_degree, ag.grid.step)
    phi = _plain_phi_eff(d, p_c * logical_jacobian(meas.baseline, lens, xx, yy), meas, ag)
    ok &= np.isfinite(phi)
    if ok.sum() < 64:
        return
    held, m = float(np.mean(np.abs(phi[ok]))), float(np.mean(np.abs(ch.phi_eff_mD[ok])))
    if held >= _LENS_SHARE_WARN * m and held > 0.01:
        warn.append(
            f"Direct Method: the camera lens fitted from the photo holds a radial distortion centred on the optical axis "
            f"that, read as glass, is mean |phi_eff| {held:.3g} mD, against this pane's {m:.3g} mD: the photo cannot tell "
            "a camera lens from glass power centred on the optical axis, and this reading takes it for the lens's - "
            "confirm with a calibration photo or a camera file (--lens-photo, --camera-file), or use the Comparative Method"
        )


def _n_move(meas, ag: _AnalysisGrid, ch, ks):
    """``(s0, s1, what)``: the statistic (mean or p95 |phi_eff|, mD) that moves most from N to N + 1, or None.

    See :func:`_warn_n_dependence`; None where fewer than 64 samples take part or N >= 8.
    """
    p = meas.inputs.params
    n = p.detrend_degree
    if n >= 8 or ag.valid.sum() < 64:
        return None
    a = ch.phi_eff_mD
    ok = _beyond_guard(meas, ag) & np.isfinite(a)
    if ok.sum() < 64:
        return None
    delta, jac = _components(ag, ks, meas.baseline, p, meas.inputs.carrier_period_mm, meas.mm_per_px,
                             lens=meas.fit.lens_model)
    labels = np.where(ag.valid, ag.labels, 0)
    b = a - _plain_phi_eff(detrend_increment(delta, labels, n, ag.grid.step), jac, meas, ag)
    ok &= np.isfinite(b)
    if ok.sum() < 64:
        return None
    a, b = np.abs(a[ok]), np.abs(b[ok])
    stats = [(float(np.mean(a)), float(np.mean(b)), "mean"), (float(np.percentile(a, 95)), float(np.percentile(b, 95)), "p95")]
    return max(stats, key=lambda t: abs(t[1] - t[0]) / max(t[0], 1e-12))


def _smoothing_mm(demod: _Demodulation, p: AnalyzerParams, p_c: float, mm_per_px: float, warn: list[str]):
    """The reporting smoothing (mm) and the Gaussian demodulation blur (px^2 per carrier) to compensate."""
    blur = _demodulation_blur_px2(demod.carriers, demod.covariances, p) if p.compensate_demodulation_blur else None
    sigma_mm = p.sigma_mm if p.sigma_mm is not None else p.sigma_periods * p_c
    if blur is not None:
        s_px = sigma_mm / mm_per_px
        worst = max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
        if worst > s_px**2:
            warn.append(
                f"sigma_mm = {sigma_mm:.3g} mm ({s_px:.1f} px) is finer than the demodulation resolution "
                f"({np.sqrt(worst):.1f} px = {np.sqrt(worst) * mm_per_px:.3g} mm); the effective smoothing is "
                f"{np.sqrt(worst) * mm_per_px:.3g} mm along the least resolved direction (summary.json: effective_sigma_mm)"
            )
    return float(sigma_mm), blur


def _warped_heterodyne(bb_img, pred: np.ndarray, own, grid: F.SamplingGrid, ks: F.CarrierPair, covs):
    """F5's heterodyne of the photo's basebands ``bb_img`` against the reference warped by ``pred``, and that reference's basebands."""
    bb_ref = _basebands(F.compute_spectrum(D.warped_reference(pred, own, grid, ks)), ks, covs, grid)
    return tuple(b * np.conj(r) for b, r in zip(bb_img, bb_ref)), bb_ref


def _rms_update_periods(res: np.ndarray, where: np.ndarray, ks: F.CarrierPair, period: float) -> float:
    """RMS displacement of the residual phases ``res`` (h, w, 2) over ``where``, carrier periods (0 where empty)."""
    if not where.any():
        return 0.0
    return float(np.sqrt(np.mean(np.sum(D.phase_to_displacement_px(res[where], ks) ** 2, axis=-1)))) / period


def _low_passed(phase: np.ndarray, measured: np.ndarray, grid: F.SamplingGrid, sigma_px: float) -> np.ndarray:
    """``phase`` (h, w, 2) smoothed by a Gaussian of ``sigma_px`` over the measured samples (normalised), filled beyond them."""
    w = measured.astype(float)
    out = np.stack([masked_gaussian(phase[..., i], w, sigma_px**2 * np.eye(2), grid.step, order=0) for i in range(2)],
                   axis=-1)
    return D.fill_nearest(np.where(measured[..., None], out, 0.0), measured)


def _own_phasors(refm: ReferenceModel | None, src: F.SamplingGrid, grid: F.SamplingGrid, ks: F.CarrierPair):
    """The reference's own phasors: ``(on src, at grid's samples)``, each per carrier; None in the Direct Method."""
    if refm is None:
        return None
    unit = [b / np.maximum(np.abs(b), 1e-30) for b in refm.baseband]
    return unit, [D.to_frame(o, src, np.zeros(grid.shape + (2,), np.float32), grid, ks) for o in unit]


def _own_shift(own, src: F.SamplingGrid, q: np.ndarray, grid: F.SamplingGrid, ks: F.CarrierPair) -> np.ndarray | float:
    """``own(r - u(r)) - own(r)`` (rad, (h, w, 2) on ``grid``): the reference's own phase across the displacement.

    ``own``: :func:`_own_phasors` (its phasors on ``src`` and at ``grid``'s samples); ``q = -2 pi F u``
    (rad), the displacement in phase units. The Comparative phase at ``r`` is the photo's there less the
    reference's there, ``own(r - u) - own(r) - 2 pi F u``: it differs from ``q`` wherever the
    reference's own grid is not uniform (its perspective, its lens), by this. 0 in the Direct Method.
    """
    if own is None:
        return 0.0
    unit, here = own
    return np.stack([np.angle(D.to_frame(o, src, q, grid, ks) * np.conj(h)) for o, h in zip(unit, here)], axis=-1)


# Fixed-point iterations from the Comparative phase to the displacement: each multiplies the error by
# the reference's relative frequency deviation across the displacement (a few percent).
_OWN_ITERATIONS = 4


def _photo_passes(img, refm: ReferenceModel | None, demod: _Demodulation, bb_img, own, pred: np.ndarray,
                  measured: np.ndarray, grid: F.SamplingGrid, p: AnalyzerParams, max_passes: int, img_mods):
    """F5's last passes: the photo deformed back to the reference's frame (:func:`~glassdist.analyzer.deform.deformed_photo`).

    ``pred``: the warped reference's field, low-passed (:func:`_low_passed`). Each pass
    demodulates the deformed photo on F5's grid with the same filters, against the reference's own
    basebands brought to that grid (Comparative; the flat carrier in the Direct Method), and reads
    the residual at the photo's samples (:func:`~glassdist.analyzer.deform.to_frame`).
    The deformation needs the displacement itself, ``q = -2 pi F u``; the Comparative phase
    ``pred`` carries the reference's own phase across it as well (:func:`_own_shift`), so ``q``
    is solved from ``pred`` first and ``pred`` rebuilt from ``q`` at the end (without it the
    ray-traced strong lens read 0.14 px off the truth on its perspective side instead of 0.07).
    Within three kernel widths (Block F's, its longest axis) of where the deformed photo draws
    from off the photo, and of the photo's samples that show what the reference does not (``r - u(r)``
    off the image, :func:`~glassdist.analyzer.deform.off_frame`: no deformed sample draws from them,
    and the read-back there is the edge's), the residual is the warped reference's (``bb_img``: the
    photo's basebands on ``grid``; ``own``: the reference's, as in :func:`_follow_local_grid`),
    blended over as much again: both measure ``G (true - B pred)``, so every sample's transfer
    counts the same passes. Without the second part, each pass added the edge's residual there: the
    ray-traced 0.75 mm wavy slab (displaced by up to 25 px) drifted by 0.07 points of φ_eff per pass
    through the detrend (1.0065 after 2, 1.0110 after 8; now 1.0046 and 1.0037).

    Returns ``(phase, passes, mods)``: the output phase ``pred + residual`` (rad, (h, w, 2) on
    ``grid``, the Comparative phase as F4 unwraps it), the passes run (up to ``max_passes``,
    :meth:`~glassdist.analyzer.params.AnalyzerParams.photo_passes_for`, fewer once the RMS update is
    below ``deformation_tolerance_periods``)
    and the modulation the last pass measured at, per carrier, read at the photo's samples: the
    deformed photo's (its grid at the carrier, so the bandpass's whole amplitude), the photo's own
    where the residual is the warped reference's (``img_mods()``: the photo's on ``grid``, per carrier,
    computed once by the caller). The phase noise goes as one over it, not over
    the photo's at its local frequency (the strong wave of ``test_analyzer_quality``, Direct:
    its x displacement scattered 0.80 of a sigma predicted from the photo's, 12 captures).
    """
    ks = demod.carriers
    covs = demod.covariances
    period = max(ks.k1.period_px, ks.k2.period_px)
    reach_px = 3.0 * float(np.sqrt(np.max(np.linalg.eigvalsh(_demodulation_blur_px2(ks, covs, p)))))
    own_ph = _own_phasors(refm, demod.grid, grid, ks)
    q = pred
    for _ in range(_OWN_ITERATIONS if refm is not None else 0):
        q = pred - _own_shift(own_ph, demod.grid, q, grid, ks)
    ref_bb = None if refm is None else [D.to_grid(r, demod.grid, grid) for r in refm.baseband]
    spline = D.photo_spline(img)

    def smoothed(zs):  # F3 on the heterodynes, as in the warped reference's passes (no coherence needed here)
        return [F.smooth_complex(z, p.smoothing_periods * c.period_px, grid) for z, c in zip(zs, (ks.k1, ks.k2))]

    n = 0
    while True:
        n += 1
        deformed, outside = D.deformed_photo(spline, q, grid, ks)
        bb = _basebands(F.compute_spectrum(deformed), ks, covs, grid)
        del deformed
        zs = smoothed(bb if ref_bb is None else tuple(b * np.conj(r) for b, r in zip(bb, ref_bb)))
        res = np.stack([np.angle(D.to_frame(z, grid, q, grid, ks)) for z in zs], axis=-1)
        share = 1.0
        off = D.off_frame(q, grid, ks)
        if outside.any() or off.any():
            # the deformed photo's share: none within reach_px of where it draws from off the photo (reference
            # frame) or of where the photo shows what the reference does not (photo frame), all beyond twice that;
            # the warped reference's residual, of the Comparative phase, is off as an update of q by the
            # reference's relative frequency deviation across the displacement (a few percent of a small update)
            def ramp(mask):
                return np.clip(ndimage.distance_transform_edt(~mask, sampling=grid.step) / reach_px - 1.0, 0.0, 1.0)

            share = np.ones(grid.shape, np.float32)
            if outside.any():
                share = D.to_frame(ramp(outside).astype(np.float32), grid, q, grid, ks)
            if off.any():
                share = np.minimum(share, ramp(off).astype(np.float32))
            share = share[..., None]
            het, _ = _warped_heterodyne(bb_img, q + _own_shift(own_ph, demod.grid, q, grid, ks), own, grid, ks, covs)
            res = share * res + (1.0 - share) * np.stack([np.angle(z) for z in smoothed(het)], axis=-1)
        step = _rms_update_periods(res, measured, ks, period)
        log.debug("F5 photo pass %d: RMS update %.4f period", n, step)
        if n >= max_passes or step < p.deformation_tolerance_periods:
            mods = [D.to_frame(_modulation(b, c.period_px, grid, p), grid, q, grid, ks) for b, c in zip(bb, (ks.k1, ks.k2))]
            if np.ndim(share):  # blended with the photo's own where the residual is the warped reference's
                w_ = np.squeeze(share, -1)
                mods = [w_ * m_ + (1.0 - w_) * m0 for m_, m0 in zip(mods, img_mods())]
            mods = [m_.astype(np.float32) for m_ in mods]
            q = q + res
            return q + _own_shift(own_ph, demod.grid, q, grid, ks), n, mods
        q = q + D.fill_nearest(np.where(measured[..., None], res, 0.0), measured)


def _to_analysis_grid(phases, region: Region, grid: F.SamplingGrid, sigma_px: float, blur, p: AnalyzerParams,
                      passes: int = 1, photo: tuple[int, float] = (0, 0.0)) -> _AnalysisGrid:
    """Block means of the demodulation grid, as coarse as the reporting smoothing and the demodulation's passband allow.

    The block step stays below half the residual smoothing, and the block means keep the
    displacement the demodulation resolves (:func:`_analysis_block`). The instrument transfer
    (Gaussian demodulation blur, block means, interpolation to the pixel grid) goes with
    the phases, for Block A to divide it out.
    """
    m = _analysis_block(sigma_px, blur, grid, p, passes, photo)
    agrid = grid if m == 1 else F.block_grid(grid, m)
    transfer = None if blur is None else InstrumentTransfer(
        blur, fine_step_px=grid.step, block=m, interp_step_px=None if agrid.is_full else agrid.step, passes=passes,
        photo_passes=photo[0], restart_sigma_px=photo[1],
    )
    passes = passes + photo[0]
    if m == 1:
        return _AnalysisGrid(grid, phases, region.valid, region.labels, region.valid, None, transfer, passes, photo)
    phases, fill = F.block_mean(phases, region.valid, m)
    hb, wb = agrid.shape
    block_label = region.labels.reshape(hb, m, wb * m).max(axis=1).reshape(hb, wb, m).max(axis=2)
    # Whole blocks only (their mean sits at the block centre); partial border blocks
    # get the smooth extrapolation from inside, and the fine mask trims them below.
    labels = np.where(fill >= 1.0, block_label, 0)
    valid = labels > 0
    report = ndimage.binary_dilation(valid, iterations=1) & (fill > 0)
    return _AnalysisGrid(agrid, phases, valid, labels, report, region.valid, transfer, passes, photo)


def _direct_pass2(ag: _AnalysisGrid, carriers: F.CarrierPair, fit: HomographyFit) -> np.ndarray:
    """Phases against the homography-warped carrier: phase += 2 pi (f . r - H^-1(L^-1(r))).

    ``L`` is the camera lens's distortion when Block I calibrated it (else the identity).
    The term is smooth (affine up to perspective and the lens), so on the Block A grid its
    value at the block centre equals its block mean.
    """
    yy, xx = ag.grid.coords()
    u0, v0 = logical_coordinates(fit.matrix, fit.lens_model, xx, yy)
    return ag.phases + 2 * np.pi * np.stack(
        [carriers.k1.fx * xx + carriers.k1.fy * yy - u0, carriers.k2.fx * xx + carriers.k2.fy * yy - v0], axis=-1
    )


def _warn_deviation(ag: _AnalysisGrid, ks, method: str, p: AnalyzerParams, warn: list[str]) -> None:
    deviation = _frequency_deviation(ag.phases, ag.valid, ks, ag.grid.step)
    limit = p.deformation_max_deviation if p.deformation_passes > 0 else _DEVIATION_WARN
    if deviation > limit and not any(w.startswith("strong distortion") for w in warn):
        advice = "use a finer grid or a shorter distance L" + (" or the Comparative Method" if method == "direct" else "")
        warn.append(
            f"strong distortion: the local grid frequency departs from the carrier by up to {100 * deviation:.0f}% "
            f"(results were reliable up to about {100 * limit:.0f}% in tests); the result may be attenuated or wrong - "
            f"{advice}"
        )


def _components(ag: _AnalysisGrid, ks, H_jac, p: AnalyzerParams, p_c, mm_per_px, lens=None):
    """A1: the displacement (mm) Block A evaluates and the Jacobian its gradients take (None: ``mm_per_px``).

    ``"projective"``: grid-frame components ``phases * p_c / (2 pi)`` with ``dX/dr`` of the
    baseline (and lens); else camera-frame components from the carriers, isotropic scale.
    """
    if p.a1_mode == "projective":
        yy, xx = ag.grid.coords()
        return ag.phases * (p_c / (2 * np.pi)), p_c * logical_jacobian(H_jac, lens, xx, yy)
    M = np.array([ks[0].f / ks[0].norm, ks[1].f / ks[1].norm]).T  # columns: unit carriers
    proj_px = ag.phases / (2 * np.pi * np.array([ks[0].norm, ks[1].norm]))
    return (proj_px @ np.linalg.inv(M)) * mm_per_px, None  # (M^T)^{-1} p in row-vector form


def _channels(ag: _AnalysisGrid, ks, H_jac, p: AnalyzerParams, p_c, mm_per_px, sigma_mm, distance_m, lens=None):
    """A1-A3: displacement in backdrop mm (camera frame) and the channels, on the analysis grid.

    Returns ``(delta_cam, Channels, A1)``: ``A1`` holds what maps the phases to them (for the
    uncertainty): ``T`` (mm per rad, component frame), ``W`` (px per mm), ``R`` (component
    frame -> camera frame, or None), ``blur`` (px^2 per component, compensated by the
    metric smoothing, or None).
    """
    common = dict(distance_m=distance_m, mm_per_px=mm_per_px, detrend_degree=p.detrend_degree, sigma_mm=sigma_mm,
                  labels=ag.labels, step_px=ag.grid.step, report_mask=ag.report)
    delta, J = _components(ag, ks, H_jac, p, p_c, mm_per_px, lens)
    if J is not None:
        hc, wc = ag.grid.shape
        R = _polar_rotation(J[hc // 2, wc // 2])
        ch = evaluate_displacement(delta, ag.valid, jacobian=J, transfer=ag.transfer, frame_rotation=R, **common)
        a1 = {"T": p_c / (2 * np.pi) * np.eye(2), "W": inverse_2x2(J), "R": R, "blur": None if ag.transfer is None else ag.transfer.gaussian_px2}
        return delta @ R, ch, a1
    M = np.array([ks[0].f / ks[0].norm, ks[1].f / ks[1].norm]).T
    delta_cam = delta
    tr = ag.transfer
    iso_blur = None
    if tr is not None:  # camera-frame components mix both carriers: their mean blur, isotropic
        g = tr.gaussian_px2
        iso_blur = np.repeat((np.trace(g, axis1=1, axis2=2).mean() / 2 * np.eye(2))[None], 2, 0)
        tr = replace(tr, gaussian_px2=iso_blur)
    ch = evaluate_displacement(delta_cam, ag.valid, transfer=tr, **common)
    T = mm_per_px * np.linalg.inv(M).T / (2 * np.pi * np.array([ks[0].norm, ks[1].norm]))[None, :]
    return delta_cam, ch, {"T": T, "W": np.eye(2) / mm_per_px, "R": None, "blur": iso_blur}


@dataclass(frozen=True)
class _PhaseNoise:
    """Phase noise levels ``s^2 / (2 |b|^2)`` per carrier on the Block A grid (rad^2 px^2), and the filters they went through."""

    photo: tuple[np.ndarray, np.ndarray]
    reference: tuple[np.ndarray, np.ndarray] | None  # independent of the photo's; None: Direct Method
    blur: np.ndarray  # (2, 2, 2): per carrier, spatial covariance (px^2) of the low-pass up to that grid
    bandpass: np.ndarray  # (2, 2, 2): that of the bandpass alone (F5's reference term)


def _phase_noise(demod: _Demodulation, refm, agrid: F.SamplingGrid, p: AnalyzerParams) -> _PhaseNoise:
    """The photo's and the reference's phase noise levels on the Block A grid and Block F's filters (:class:`_PhaseNoise`)."""
    m = demod.grid.shape[0] // agrid.shape[0]
    ones = np.ones(demod.grid.shape, np.float32)

    def level(s, mods):
        out = []
        for mod in mods:
            w_ = (s**2 / (2 * np.maximum(mod.astype(np.float64), 1e-12) ** 2)).astype(np.float32)
            out.append(F.block_mean(w_, ones, m)[0] if m > 1 else w_)
        return tuple(out)

    blur = _demodulation_blur_px2(demod.carriers, demod.covariances, p)
    if m > 1:
        blur = blur + (m * max(demod.grid.step)) ** 2 / 12.0 * np.eye(2)
    return _PhaseNoise(level(demod.noise_std, demod.mods[:2]),
                       None if refm is None else level(refm.noise_std, demod.mods[2:4]),
                       blur, _bandpass_px2(demod.covariances))


def _uncertainty(ag: _AnalysisGrid, phase_noise: _PhaseNoise, ch, a1: dict, sigma_px: float, distance_m: float) -> dict:
    """Standard uncertainties of the displacement and the channels from the image noise (registered fields).

    The phase noise (:func:`_phase_noise`) through Block F's kernel (and the block means),
    times F5's gains when its passes ran, gives the displacement's; through the whole chain,
    the metric smoothing included, and the differentiation, the channels'
    (:mod:`~glassdist.analyzer.uncertainty`).
    """
    blur, photo, ref, bandpass = phase_noise.blur, phase_noise.photo, phase_noise.reference, phase_noise.bandpass
    tr = ag.transfer
    var, grad_cov = [], []
    for i in range(2):
        g_photo, g_ref = (1.0, 1.0) if tr is None else deformation_noise_gains(tr, i, bandpass[i])
        g_chan = 1.0 if tr is None or ref is None else deformation_channel_gain(tr, i, bandpass[i],
                                                                                tr.effective_sigma_px(sigma_px))
        var.append(phase_variance(photo[i] * np.float32(g_photo) + (0.0 if ref is None else ref[i] * np.float32(g_ref)),
                                  blur[i]))
        metric = sigma_px**2 * np.eye(2)
        if a1["blur"] is not None:  # the metric smoothing tops the demodulation blur up to sigma
            ev, V = np.linalg.eigh(metric - a1["blur"][i])
            metric = (V * np.clip(ev, 0.0, None)) @ V.T
        white = photo[i] if ref is None else photo[i] + ref[i] * np.float32(g_chan)
        grad_cov.append(gradient_covariance(white, blur[i] + metric))
    disp = displacement_sigma(tuple(var), a1["T"], a1["R"])
    strain = ch.strain if a1["R"] is None else a1["R"] @ ch.strain @ a1["R"].T  # back to the component frame
    unc = channel_uncertainty(tuple(grad_cov), a1["T"], a1["W"], strain, distance_m)
    out = {"phi_eff_sigma_mD": unc.phi_eff_sigma_mD, "phi_shear_sigma_mD": unc.phi_shear_sigma_mD,
           "displacement_sigma_mm": disp}
    for f_ in out.values():
        f_[~ag.report] = np.nan
    return out


def _result_fields(delta_cam, ch) -> dict:
    """The registered fields (:data:`~glassdist.analyzer.result.FIELDS`) on the analysis grid."""
    return {
        "displacement_mm": delta_cam, "phi_eff_mD": ch.phi_eff_mD, "phi_shear_mD": ch.phi_shear_mD,
        "phi_total_mD": ch.phi_total_mD, "displacement_detrended_mm": ch.displacement_detrended_mm,
        "axis_deg": ch.axis_deg,
    }


def _reported_region(fields: dict, ag: _AnalysisGrid, mask, edge_px: float, warn: list[str]):
    """The valid region on the image grid (where every field is finite, outside the image-edge margin) and the fill indices."""
    valid_c = ag.report.copy()
    for f_ in fields.values():
        valid_c &= np.isfinite(f_) if f_.ndim == 2 else np.all(np.isfinite(f_), axis=-1)
    valid_full, idx = image_grid_valid(valid_c, ag.grid, mask, fine_valid=ag.fine_valid)
    trim_edges(valid_full, edge_px)
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
    # Underflow (tiny spectral powers squared) is harmless and not reported.
    with warnings.catch_warnings(record=True) as caught, np.errstate(all="warn", under="ignore"):
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
        p = settle_pattern(p, ref, warn) if p.pattern == "auto" else p  # a given one is checked on the photo
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
        border, edge = _margins(carriers, covs, p, direct=False)
        region = valid_region(wrapped, cohs, mods, carriers, grid, p, None, [], margin_px=border, edge_margin_px=edge)
        if region.n == 0:
            raise InputError("the reference photo shows no usable grid region; check it is in focus and well exposed")
        yy, xx = grid.coords()
        psi = [unwrap(w, region.valid, region.labels, region.n, seed=p.ransac_seed) for w in wrapped]
        U = carriers.k1.fx * xx + carriers.k1.fy * yy + psi[0] / (2 * np.pi)
        V = carriers.k2.fx * xx + carriers.k2.fy * yy + psi[1] / (2 * np.pi)
        fit, _ = fit_grid_homography((U, V), yy, xx, region.labels, region.n, carriers, grid, p, [])
        noise = noise_std(spec, carriers)
    return ReferenceModel(ref.shape, carriers, covs, grid, bb, mods, fit, p, tuple(warn), noise,
                          grid_spread(None, carriers, spectrum=spec))


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
    lens: LensCalibration | None = None,
    camera_distance_m: float | None = None,
    camera: dict | None = None,
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
    lens : LensCalibration, optional
        Direct Method: the camera lens's distortion, known beforehand (a calibration photo,
        :func:`calibrate_from_photo`, or a camera file,
        :func:`~glassdist.analyzer.lens.calibration_from_camera_file`); Block I then fits the
        homography through it. None: the lens is fitted from the photo (``params.lens_model``).
    camera_distance_m : float, optional
        Direct Method: the camera's distance from the pane along its normal, m, the camera
        facing the pane. With a camera file's ``lens`` (its focal length) it pins the
        magnification, and the bulk channel is reported (:mod:`glassdist.analyzer.bulk`).
    camera : dict, optional
        The photo's EXIF facts (:func:`glassdist.io.camera_metadata`; read from the file when
        ``image`` is a path): a focal length and subject distance cross-check the measured
        scale against ``pitch_mm`` (:mod:`glassdist.plausibility`).

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
    image, reference, params, mask, sources = _api_inputs(image, reference, params, mask, detrend_degree, sigma_mm)
    sources["given"] = given_settings(params, pattern=pattern, fallback=getattr(reference, "params", None))
    if camera_distance_m is not None:
        camera_distance_m = check_number(camera_distance_m, "camera_distance_m (--camera-distance-m, camera to pane)",
                                         DISTANCE_M)
    warn: list[str] = []
    with _routed_warnings(warn):
        meas = _measure(image, pitch_mm, distance_m, reference, params, mask, pattern, warn, lens=lens)
        refm = meas.inputs.reference
        warn.extend(review_measurement(image, None if refm is None else refm.grid_spread, meas.carriers,
                                       mm_per_px=meas.mm_per_px, distance_m=distance_m, pitch_mm=pitch_mm,
                                       camera=sources.get("camera") if camera is None else camera))
        del image  # Block A needs no photo: freed here unless the caller keeps it (the command line does not)
        evaluated = _evaluate(meas, meas.ag, warn)
    res = _result(meas, evaluated, warn, camera_distance_m=camera_distance_m)
    return replace(res, sources=sources)


def _api_inputs(image, reference, params, mask, detrend_degree, sigma_mm):
    """Photos and mask given as paths read; ``detrend_degree`` / ``sigma_mm`` merged into the parameters.

    Also returns the files read (:attr:`AnalysisResult.sources`): each path with the SHA-256 of
    the bytes decoded, and the photo's EXIF camera.
    """
    from ..io import read_sources

    image, reference, mask, sources = read_sources(image, reference, mask)
    settings = {k: v for k, v in (("detrend_degree", detrend_degree), ("sigma_mm", sigma_mm)) if v is not None}
    if settings:
        if params is None and isinstance(reference, ReferenceModel):
            params = reference.params
        if isinstance(params, AnalyzerParams):
            params = {**params.model_dump(exclude_unset=True), **settings}
        else:
            params = load_params(params, **settings)
    return image, reference, params, mask, sources


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
    quality: np.ndarray
    label_grid: F.SamplingGrid
    margin_px: tuple[float, float]
    guard_px: float
    noise_std: tuple[float, float | None]
    phase_noise: _PhaseNoise


def _measure(image, pitch_mm, distance_m, reference, params, mask, pattern, warn: list[str], lens=None) -> _Measurement:
    """Inputs, F1-F4, Block I (Direct) and the Block A grid with its phases (pass 2 applied).

    ``baseline``: the homography the phases are relative to in the logical frame (Direct:
    the fit; Comparative: the reference's own grid, which also gives the A1 Jacobian).
    """
    inp = _checked_inputs(image, pitch_mm, distance_m, reference, params, mask, pattern, warn)
    p, p_c = inp.params, inp.carrier_period_mm
    demod = _demodulate(inp.image, inp.reference, p)
    carriers = demod.carriers
    _warn_sampling(carriers, warn)
    margins = _margins(carriers, demod.covariances, p, direct=demod.method == "direct")
    first: list[str] = []
    held: dict = {}

    def contrast(grid=demod.grid):  # the photo's local contrast, computed once per grid, only when an exclusion needs its cause
        if grid.shape not in held:
            held[grid.shape] = local_contrast(inp.image, max(carriers.k1.period_px, carriers.k2.period_px), grid)
        return held[grid.shape]

    region = _region(demod, p, inp.mask, first, margins, contrast=contrast)
    _check_region(region, demod.mods, first)
    phases = _unwrapped_phases(demod, region, p)  # F4
    f5 = _follow_local_grid(inp.image, inp.reference, demod, region, phases, p, contrast)  # F5
    if f5 is not None:
        f5_warn: list[str] = []
        f5_region = _region(f5.demod, p, inp.mask, f5_warn, margins, f5.residual, f5.region_mods, f5.beyond,
                            lambda: contrast(f5.demod.grid), first=f5.measured)
        if f5_region.n == 0:  # nothing F5 could measure: the one pass stands
            f5 = None
    if f5 is None:
        warn.extend(first)
    else:
        # Where the one-pass local frequency was already beyond the bandpass, what F5 still cannot
        # measure there (no predictor to follow, or one that ran out of reach) is beyond reach: neither occluded,
        # a residue of the grid itself nor a stray fragment.
        lost = np.isin(f5_region.quality, (LOW_MODULATION, PHASE_RESIDUE, FRAGMENT)) & (f5.measured.quality == BEYOND_RANGE)
        # A sample F5 grew into showed a coherent grid: where its modulation then fails, the bandpass's gain
        # at its local frequency does, not an occlusion.
        lost |= (f5_region.quality == LOW_MODULATION) & f5.grown
        f5_region.quality[lost] = BEYOND_RANGE
        demod, region = f5.demod, f5_region
        warn.extend(f5_warn)
        _check_region(region, demod.mods, warn)
        phases = _unwrapped_phases(demod, region, p)
    fit = _direct_baseline(phases, demod, region, p, warn, lens) if demod.method == "direct" else None
    H_jac = fit.matrix if fit is not None else inp.reference.homography.matrix
    phases[~region.valid] = np.nan
    mm_per_px = p_c * float(np.sqrt(carriers.k1.norm * carriers.k2.norm))
    w_areas = excluded_area_warning(region.quality, inp.mask, demod.grid, max(carriers.k1.period_px, carriers.k2.period_px),
                                    mm_per_px)
    if w_areas:
        warn.append(w_areas)
    sigma_mm, blur = _smoothing_mm(demod, p, p_c, mm_per_px, warn)
    sigma_px = sigma_mm / mm_per_px
    ag = _to_analysis_grid(phases, region, demod.grid, sigma_px, blur, p, passes=demod.passes,
                           photo=(demod.photo_passes, demod.restart_sigma_px))
    del phases
    if fit is not None:
        ag = replace(ag, phases=_direct_pass2(ag, carriers, fit))
    guard_px = float(p.guard_band_sigmas * sigma_px)
    quality = guard_band(region.quality, demod.grid, guard_px)
    noise = (demod.noise_std, inp.reference.noise_std if inp.reference is not None else None)
    phase_noise = _phase_noise(demod, inp.reference, ag.grid, p)
    label_grid = demod.grid
    del demod
    inp = replace(inp, image=None)  # several captures are held at once: not their photos
    return _Measurement(inp, carriers, fit, H_jac, mm_per_px, sigma_mm, ag, region.n, float(pitch_mm), float(distance_m),
                        quality, label_grid, margins, guard_px, noise, phase_noise)


def _evaluate(meas: _Measurement, ag: _AnalysisGrid, warn: list[str]):
    """A1-A3 on the phases of ``ag`` (the measurement's own, or an average of several).

    Returns ``(ag, fields, valid_full, idx)`` for :func:`_result`.
    """
    p, p_c, carriers = meas.inputs.params, meas.inputs.carrier_period_mm, meas.carriers
    ks = (carriers.k1, carriers.k2)
    _warn_deviation(ag, ks, "direct" if meas.fit is not None else "comparative", p, warn)
    delta_cam, ch, a1 = _channels(ag, ks, meas.baseline, p, p_c, meas.mm_per_px, meas.sigma_mm, meas.distance_m,
                                  lens=None if meas.fit is None else meas.fit.lens_model)
    if meas.fit is not None:
        _warn_n_dependence(meas, ag, ch, ks, warn)
        _warn_rig_floor(meas, ag, ch, warn)
        _warn_lens_takes_power(meas, ag, ch, warn)
    fields = _result_fields(delta_cam, ch)
    fields.update(_uncertainty(ag, meas.phase_noise, ch, a1, meas.sigma_mm / meas.mm_per_px, meas.distance_m))
    valid_full, idx = _reported_region(fields, ag, meas.inputs.mask, meas.margin_px[1], warn)
    _warn_few_trusted(meas.quality, meas.label_grid, meas.inputs.mask, warn)
    return ag, fields, valid_full, idx


def _bulk(meas: _Measurement, ag: _AnalysisGrid, fields: dict, camera_distance_m: float | None = None) -> BulkChannel:
    """The bulk channel (:mod:`glassdist.analyzer.bulk`).

    Comparative Method: measured. Direct Method: only where the magnification is pinned (a
    camera file's focal length, and ``camera_distance_m``, the camera facing the pane): the
    baseline's own strain (:func:`~glassdist.analyzer.bulk.pinned_strain`) plus what the
    degree-N polynomial of the Direct displacement holds; otherwise why it is not identifiable.
    """
    p = meas.inputs.params
    base = pinned = None
    if meas.fit is not None:
        cal = meas.fit.lens
        focal = None if cal is None or not cal.identifiable else cal.focal_px
        if camera_distance_m is None or focal is None:
            missing = [w for w, gone in (("the camera's focal length (a camera file)", focal is None),
                                         ("the camera-to-pane distance", camera_distance_m is None)) if gone]
            return BulkChannel(None, None, None, None, None, p.detrend_degree, {},
                               f"{DIRECT_BULK_REASON}; missing here: {' and '.join(missing)}")
        if p.a1_mode != "projective":
            return BulkChannel(None, None, None, None, None, p.detrend_degree, {},
                               "the pinned Direct bulk channel needs the projective A1 (a1_mode 'projective')")
        board_mm = (camera_distance_m + meas.distance_m) * 1000.0
        k = 1000.0 / meas.distance_m
        pinned = {"camera_distance_m": float(camera_distance_m), "focal_px": float(focal),
                  "phi_eff_mD_per_cm_of_distance": float(2.0 * 10.0 / board_mm * k),
                  "phi_eff_mD_per_percent_of_focal_length": float(2.0 * 0.01 * k)}
    yy, xx = ag.grid.coords()
    delta = fields["displacement_mm"]
    if p.a1_mode == "projective":
        lens = None if pinned is None else meas.fit.lens_model  # the Direct baseline is seen through the lens
        J = meas.inputs.carrier_period_mm * logical_jacobian(meas.baseline, lens, xx, yy)
        if pinned is not None:
            base = pinned_strain(J, focal_px=pinned["focal_px"], board_distance_mm=board_mm)
        hc, wc = ag.grid.shape
        R = _polar_rotation(J[hc // 2, wc // 2])
        delta = delta @ R.T  # back to the component frame
    else:
        J, R = np.broadcast_to(meas.mm_per_px * np.eye(2), xx.shape + (2, 2)), None
    return bulk_channel(delta, ag.valid, ag.labels, degree=p.detrend_degree, step_px=ag.grid.step, jacobian=J,
                        frame_rotation=R, distance_m=meas.distance_m, sigma_px=meas.sigma_mm / meas.mm_per_px, xx=xx, yy=yy,
                        guard_px=meas.guard_px, base_strain=base, pinned=pinned)


# Share of the requested region below which the trusted pixels (quality label 0) are called few.
_FEW_TRUSTED = 0.01


def _warn_few_trusted(quality: np.ndarray, grid: F.SamplingGrid, mask, warn: list[str]) -> None:
    """Warn when no or few samples are trusted: the statistics are then null or cover little."""
    in_mask = np.ones(grid.shape, bool) if mask is None else downsample_mask(mask, grid)
    share = float(np.count_nonzero((quality == ANALYSED) & in_mask)) / max(int(np.count_nonzero(in_mask)), 1)
    if share == 0.0:
        warn.append(
            "no pixel is trusted (quality label 0): every measured pixel lies within the guard band of an excluded area "
            "or the image edge, so the statistics are null and a specification cannot pass; the maps are still written"
        )
    elif share < _FEW_TRUSTED:
        warn.append(f"only {100 * share:.2f}% of the region is trusted (quality label 0): the statistics cover few pixels")


def _result(meas: _Measurement, evaluated, warn: list[str], *, extra_fields: dict | None = None,
            n_regions: int | None = None, camera_distance_m: float | None = None) -> AnalysisResult:
    """The :class:`AnalysisResult` of :func:`_evaluate`'s output (``extra_fields``: more registered fields)."""
    ag, fields, valid_full, idx = evaluated
    p = meas.inputs.params
    # stated from the pixel labels the result and its quality legend count (computed once, kept)
    q_px = pixel_quality(meas.quality, meas.label_grid, valid_full, meas.inputs.mask, meas.margin_px[1]) \
        if np.any(meas.quality == BEYOND_RANGE) else None
    w_beyond = None if q_px is None else beyond_range_warning(q_px, p)
    warn = [*warn, w_beyond] if w_beyond else warn
    for w in warn:
        log.warning(w)
    res = AnalysisResult(
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
        demodulation_step_px=meas.label_grid.step,
        effective_sigma_mm=meas.sigma_mm if ag.transfer is None else ag.transfer.effective_sigma_px(meas.sigma_mm / meas.mm_per_px) * meas.mm_per_px,
        n_regions=meas.n_regions if n_regions is None else n_regions,
        demodulations=ag.passes,
        photo_passes=ag.photo[0],
        restart_sigma_px=ag.photo[1],
        margin_px=meas.margin_px,
        guard_px=meas.guard_px,
        noise_std=meas.noise_std,
        bulk=_bulk(meas, ag, fields, camera_distance_m),
        _deferred={"fields": {**fields, "quality": meas.quality, **(extra_fields or {})}, "idx": idx, "grid": ag.grid,
                   "fit_valid": np.ascontiguousarray(ag.valid),
                   "label_grid": meas.label_grid, "mask": meas.inputs.mask},
    )
    if q_px is not None:
        res.__dict__["quality"] = q_px  # the cache of the result's pixel-grid field
    return res


def calibrate_from_photo(image, *, pitch_mm: float, pattern: str | None = None, params=None,
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
    if image_shape is not None and tuple(np.shape(image)[:2]) != tuple(image_shape):
        h, w = np.shape(image)[:2]
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
