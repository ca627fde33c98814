"""The Distortion Analyzer: Comparative and Direct methods (paper §2.2), as a straight sequence of stages.

Comparative: F1-F4 against the analytic signal of a glass-less photograph, then A.
Direct: F1-F4 against a synthetic flat carrier (pass 1), Block I fits the
homography of the logical grid, and the distortion phase is taken against the
homography-warped carrier (pass 2, reusing pass 1's unwrapped phase), then A.

The stages, each a module returning a frozen record that carries its own warnings:

1. inputs checked (:func:`checked_inputs`, an :class:`Inputs` record);
2. F1-F3 (:func:`~glassdist.analyzer.demodulate.demodulate`), F4's region and unwrapping
   (:func:`~glassdist.analyzer.demodulate.region`), F5 where the local grid departs from the
   carrier (:func:`~glassdist.analyzer.deform.follow_local_grid`);
3. Block I (Direct, :func:`~glassdist.analyzer.homography.fit_grid_homography`);
4. the Block A grid (:func:`~glassdist.analyzer.analysis_grid.to_analysis_grid`, Direct pass 2);
   steps 1-4 form a :class:`Measurement` (:func:`measure`);
5. A1 (:func:`~glassdist.analyzer.components.components`), A2-A3
   (:func:`~glassdist.analyzer.components.channels`), the Direct Method's checks
   (:mod:`~glassdist.analyzer.direct_checks`), the uncertainty
   (:func:`~glassdist.analyzer.uncertainty.field_uncertainty`): an :class:`Evaluation` (:func:`evaluate`);
6. the :class:`~glassdist.analyzer.result.AnalysisResult`, with the bulk channel
   (:func:`~glassdist.analyzer.bulk.measured_bulk`) and every stage's warnings in order (:func:`result_of`).

A1 (projective, default): carrier *i* measures the displacement along backdrop grid axis
*i* exactly, ``delta_i = p_c phi_i / (2 pi)`` (p_c the carrier period on the backdrop),
whatever the perspective (:mod:`~glassdist.analyzer.components`).
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import InputError
from ..validation import DISTANCE_M, PITCH_MM, check_number
from . import deform as D
from . import fourier as F
from .analysis_grid import (
    AnalysisGrid,
    direct_pass2,
    reported_region,
    reporting_smoothing,
    to_analysis_grid,
    trusted_warnings,
)
from .bulk import measured_bulk
from .components import Components, channels, components
from .demodulate import (
    Demodulation,
    LocalContrast,
    Margins,
    ReferenceModel,
    bandpass_px2,
    basebands,
    carrier_period_mm,
    checked_image,
    covariances,
    demodulate,
    demodulation_blur_px2,
    deviation_warnings,
    margins,
    modulation,
    read_inputs,
    region,
    region_warnings,
    sampling_warnings,
    smooth_with_coherence,
    unwrapped_phases,
)
from .direct_checks import DIRECT_CHECKS, DirectReading, beyond_guard
from .homography import HomographyFit, fit_grid_homography
from .lens import LensCalibration
from .params import AnalyzerParams, given_settings, load_params
from .pattern import settle_pattern
from .plausibility import grid_spread, review_measurement
from .region import (
    BEYOND_RANGE,
    FRAGMENT,
    LOW_MODULATION,
    PHASE_RESIDUE,
    Region,
    beyond_range_warning,
    excluded_area_warning,
    guard_band,
    pixel_quality,
    valid_region,
)
from .result import AnalysisResult
from .uncertainty import PhaseNoise, field_uncertainty, noise_std, phase_noise
from .unwrap import unwrap

__all__ = ["AnalysisResult", "ReferenceModel", "analyze", "prepare_reference"]

log = logging.getLogger(__name__)


# --------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class Inputs:
    """Checked inputs of one analysis, and the warnings the checks raised (exposure, pattern, the reference's)."""

    image: np.ndarray | None
    mask: np.ndarray | None
    reference: ReferenceModel | None
    params: AnalyzerParams
    carrier_period_mm: float
    warnings: tuple[str, ...] = ()


def resolve_params(params: AnalyzerParams | dict[str, Any] | str | os.PathLike[str] | None,
                   pattern: str | None) -> AnalyzerParams:
    """The analyzer parameters from a model, a dict of overrides or a JSON file, with ``pattern`` applied."""
    if isinstance(params, AnalyzerParams):
        return params if pattern is None else params.model_copy(update={"pattern": pattern})
    return load_params(params, pattern=pattern)


def checked_inputs(image: np.ndarray, pitch_mm: float, distance_m: float,
                   reference: np.ndarray | ReferenceModel | None, params: Any, mask: np.ndarray | None,
                   pattern: str | None) -> Inputs:
    """Physical inputs, image, mask and reference checked; the reference prepared once."""
    # finite and within the physical ranges of the validation layer (a 1e-300 m distance gives NaN channels)
    check_number(float(pitch_mm), "pitch_mm (the printed grid pitch)", PITCH_MM)
    check_number(float(distance_m), "distance_m (the glass-to-grid distance L)", DISTANCE_M)
    if isinstance(reference, ReferenceModel):
        p = reference.params if params is None and pattern is None else resolve_params(params, pattern)
    else:
        p = resolve_params(params, pattern)
    img, warn = checked_image(image, "image")
    settled = settle_pattern(p, img)  # 'auto' decided from the photo, a given pattern checked against it
    p = settled.params
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
    if refm is not None and settled.no_grid:  # the reference's carriers are used: the photo's F1 is the pattern check's
        raise InputError(settled.no_grid)
    warn += settled.warnings + (refm.warnings if refm is not None else ())
    return Inputs(img, mask, refm, p, carrier_period_mm(float(pitch_mm), p.pattern), warn)


# --------------------------------------------------------------------------- measurement (F1-F5, Block I, Block A grid)


@dataclass(frozen=True)
class Measurement:
    """One photo measured up to the Block A grid (everything A1-A3 needs), and the warnings on the way.

    ``baseline``: the homography the phases are relative to in the logical frame (Direct:
    the fit; Comparative: the reference's own grid, which also gives the A1 Jacobian).
    """

    inputs: Inputs
    carriers: F.CarrierPair
    fit: HomographyFit | None
    baseline: np.ndarray
    mm_per_px: float
    sigma_mm: float
    ag: AnalysisGrid
    n_regions: int
    pitch_mm: float
    distance_m: float
    quality: np.ndarray
    label_grid: F.SamplingGrid
    margin_px: tuple[float, float]
    guard_px: float
    noise_std: tuple[float, float | None]
    phase_noise: PhaseNoise
    warnings: tuple[str, ...] = ()
    grid_spread: float = float("nan")  # the photo's, for the swapped-pair check (Comparative Method)


@dataclass(frozen=True)
class _Demodulated:
    """F1-F5's outcome: the demodulation the phases come from, its region, the unwrapped phases and the warnings."""

    demod: Demodulation
    margins: Margins
    region: Region
    phases: np.ndarray
    warnings: tuple[str, ...]
    grid_spread: float = float("nan")


def _demodulated(inp: Inputs) -> _Demodulated:
    """F1-F4 once, then F5 where the local grid departs from the carrier (its region replaces the one pass's)."""
    p, img = inp.params, inp.image
    assert img is not None
    demod = demodulate(img, inp.reference, p)
    carriers = demod.carriers
    mg = margins(carriers, demod.covariances, p, direct=demod.method == "direct")
    first = sampling_warnings(carriers)
    contrast = LocalContrast(img, max(carriers.k1.period_px, carriers.k2.period_px))
    one, w_one = region(demod, p, inp.mask, mg, contrast=lambda: contrast(demod.grid))
    w_one += region_warnings(one, demod.mods)
    phases = unwrapped_phases(demod, one, p)  # F4
    assert demod.spectrum is not None
    # the photo's grid spread against the reference's (the swapped-pair check), from the same FFT
    spread = grid_spread(None, carriers, spectrum=demod.spectrum) if inp.reference is not None else float("nan")
    f5 = D.follow_local_grid(demod.spectrum, img, inp.reference, demod, one, phases, p, contrast)  # F5
    demod = replace(demod, spectrum=None)  # the photo's one FFT, read by F5 and the spread: no longer held
    if f5 is None:
        return _Demodulated(demod, mg, one, phases, first + w_one, spread)
    f5_region, w_f5 = region(f5.demod, p, inp.mask, mg, f5.residual, f5.region_mods, f5.beyond,
                             lambda: contrast(f5.demod.grid), first=f5.measured)
    if f5_region.n == 0:  # nothing F5 could measure: the one pass stands
        return _Demodulated(demod, mg, one, phases, first + w_one, spread)
    # Where the one-pass local frequency was already beyond the bandpass, what F5 still cannot
    # measure there (no predictor to follow, or one that ran out of reach) is beyond reach: neither occluded,
    # a residue of the grid itself nor a stray fragment.
    assert f5_region.quality is not None and f5.measured.quality is not None
    lost = np.isin(f5_region.quality, (LOW_MODULATION, PHASE_RESIDUE, FRAGMENT)) & (f5.measured.quality == BEYOND_RANGE)
    # A sample F5 grew into showed a coherent grid: where its modulation then fails, the bandpass's gain
    # at its local frequency does, not an occlusion.
    lost |= (f5_region.quality == LOW_MODULATION) & f5.grown
    f5_region.quality[lost] = BEYOND_RANGE
    w_f5 += region_warnings(f5_region, f5.demod.mods)
    return _Demodulated(f5.demod, mg, f5_region, unwrapped_phases(f5.demod, f5_region, p), first + w_f5, spread)


# Block I's fit is called weak below this inlier fraction (below 0.1 Block I warns itself). A roller
# wave of 0.375 carrier period amplitude keeps 30% of the points as inliers (the outliers are the
# signal); a rig whose lens the homography cannot follow was seen at 20%.
_MIN_INLIERS = 0.25


def _direct_baseline(phases: np.ndarray, demod: Demodulation, reg: Region, p: AnalyzerParams,
                     lens: LensCalibration | None = None) -> tuple[HomographyFit, tuple[str, ...]]:
    """Block I (pass 1): homography (and camera lens) of the logical grid, and its warnings.

    Each region's integer offset is removed from ``phases`` (in place).
    """
    carriers = demod.carriers
    yy, xx = demod.grid.coords()
    U = carriers.k1.fx * xx + carriers.k1.fy * yy + phases[..., 0] / (2 * np.pi)
    V = carriers.k2.fx * xx + carriers.k2.fy * yy + phases[..., 1] / (2 * np.pi)
    gf = fit_grid_homography((U, V), yy, xx, reg.labels, reg.n, carriers, demod.grid, p, lens=lens)
    fit, offsets, warn = gf.fit, gf.offsets, list(gf.warnings)
    if 0.1 <= fit.inlier_fraction < _MIN_INLIERS:
        warn.append(
            f"Direct Method: only {100 * fit.inlier_fraction:.0f}% of the grid points lie within "
            f"{p.ransac_threshold_periods:g} period of the fitted homography (inlier RMS {fit.rms_inlier_px:.2f} px): the "
            "baseline is weakly determined (strong distortion, or the camera's lens distortion), and results are relative "
            "to it; take a glass-less reference (Comparative Method) where possible"
        )
    if reg.n > 1:
        phases -= (2 * np.pi * offsets[reg.labels]).astype(np.float32)
    return fit, tuple(warn)


def measure(image: np.ndarray, pitch_mm: float, distance_m: float, reference: np.ndarray | ReferenceModel | None,
            params: Any, mask: np.ndarray | None, pattern: str | None,
            lens: LensCalibration | None = None) -> Measurement:
    """Inputs, F1-F5, Block I (Direct) and the Block A grid with its phases (pass 2 applied)."""
    inp = checked_inputs(image, pitch_mm, distance_m, reference, params, mask, pattern)
    p, p_c = inp.params, inp.carrier_period_mm
    dm = _demodulated(inp)
    demod, reg, phases, carriers = dm.demod, dm.region, dm.phases, dm.demod.carriers
    warn = inp.warnings + dm.warnings
    assert reg.quality is not None
    fit = None
    if demod.method == "direct":
        fit, w_fit = _direct_baseline(phases, demod, reg, p, lens)
        warn += w_fit
    if fit is not None:
        H_jac = fit.matrix
    else:
        assert inp.reference is not None
        H_jac = inp.reference.homography.matrix
    phases[~reg.valid] = np.nan
    mm_per_px = p_c * float(np.sqrt(carriers.k1.norm * carriers.k2.norm))
    w_areas = excluded_area_warning(reg.quality, inp.mask, demod.grid, max(carriers.k1.period_px, carriers.k2.period_px),
                                    mm_per_px)
    warn += (w_areas,) if w_areas else ()
    sigma_mm, blur, w_sigma = reporting_smoothing(demod.carriers, demod.covariances, p, p_c, mm_per_px)
    sigma_px = sigma_mm / mm_per_px
    ag = to_analysis_grid(phases, reg, demod.grid, sigma_px, blur, p, passes=demod.passes,
                          photo=(demod.photo_passes, demod.restart_sigma_px))
    del phases
    if fit is not None:
        ag = replace(ag, phases=direct_pass2(ag, carriers, fit))
    guard_px = float(p.guard_band_sigmas * sigma_px)
    quality = guard_band(reg.quality, demod.grid, guard_px)
    noise = (demod.noise_std, inp.reference.noise_std if inp.reference is not None else None)
    pn = phase_noise(demod.mods, noise, demod.grid, ag.grid, demodulation_blur_px2(carriers, demod.covariances, p),
                     bandpass_px2(demod.covariances))
    inp = replace(inp, image=None, warnings=())  # several captures are held at once: not their photos
    return Measurement(inp, carriers, fit, H_jac, mm_per_px, sigma_mm, ag, reg.n, float(pitch_mm), float(distance_m),
                       quality, demod.grid, dm.margins.as_tuple(), guard_px, noise, pn, warn + w_sigma,
                       dm.grid_spread)


# --------------------------------------------------------------------------- evaluation (Block A)


@dataclass(frozen=True)
class Evaluation:
    """A1-A3 on an analysis grid: the registered fields, the reported region on the image grid, and the warnings.

    ``fields``: the registered fields (:data:`~glassdist.analyzer.result.FIELDS`) on the
    analysis grid; ``valid_full``/``idx``: the reported region on the image grid and the fill
    indices (:func:`~glassdist.analyzer.resample.image_grid_valid`); ``components``: A1's
    displacement and Jacobian, computed once and read by the Direct checks and the bulk channel.
    """

    ag: AnalysisGrid
    fields: dict[str, np.ndarray]
    valid_full: np.ndarray
    idx: Any
    components: Components
    warnings: tuple[str, ...]


def _direct_warnings(meas: Measurement, ag: AnalysisGrid, phi_eff_mD: np.ndarray, comp: Components) -> tuple[str, ...]:
    """The Direct Method's checks of its baseline (:mod:`~glassdist.analyzer.direct_checks`), in order."""
    assert meas.fit is not None
    r = DirectReading(meas.inputs.params, meas.fit, meas.baseline, meas.inputs.carrier_period_mm, meas.mm_per_px,
                      meas.sigma_mm, meas.distance_m, ag, phi_eff_mD, beyond_guard(ag, meas.guard_px), comp)
    return tuple(w for w in (check(r) for check in DIRECT_CHECKS) if w)


def evaluate(meas: Measurement, ag: AnalysisGrid, prior: Sequence[str] = ()) -> Evaluation:
    """A1-A3 on the phases of ``ag`` (the measurement's own, or an average of several).

    ``prior``: the warnings raised so far (a strong-distortion warning is given once).
    """
    p, p_c, carriers = meas.inputs.params, meas.inputs.carrier_period_mm, meas.carriers
    ks = (carriers.k1, carriers.k2)
    method = "direct" if meas.fit is not None else "comparative"
    warn = deviation_warnings(ag.phases, ag.valid, ag.grid.step, ks, method, p, prior)
    comp = components(ag, ks, meas.baseline, p, p_c, meas.mm_per_px, None if meas.fit is None else meas.fit.lens_model)
    ev = channels(ag, comp, ks, p, p_c, meas.mm_per_px, meas.sigma_mm, meas.distance_m)
    ch = ev.channels
    if meas.fit is not None:
        warn += _direct_warnings(meas, ag, ch.phi_eff_mD, comp)
    fields = {
        "displacement_mm": ev.delta_cam, "phi_eff_mD": ch.phi_eff_mD, "phi_shear_mD": ch.phi_shear_mD,
        "phi_total_mD": ch.phi_total_mD, "displacement_detrended_mm": ch.displacement_detrended_mm,
        "axis_deg": ch.axis_deg,
    }
    fields.update(field_uncertainty(ag.report, ag.transfer, meas.phase_noise, ch.strain, ev.a1, meas.sigma_mm / meas.mm_per_px,
                                    meas.distance_m, (ag.labels, p.detrend_degree, ag.grid.step)))
    valid_full, idx, w_region = reported_region(fields, ag, meas.inputs.mask, meas.margin_px[1])
    warn += w_region + trusted_warnings(meas.quality, meas.label_grid, meas.inputs.mask)
    return Evaluation(ag, fields, valid_full, idx, comp, warn)


def result_of(meas: Measurement, ev: Evaluation, warn: Sequence[str], *,
              extra_fields: dict[str, np.ndarray] | None = None, n_regions: int | None = None,
              camera_distance_m: float | None = None) -> AnalysisResult:
    """The :class:`AnalysisResult` of an :class:`Evaluation` (``warn``: every stage's warnings, in order;
    ``extra_fields``: more registered fields)."""
    ag, fields, p = ev.ag, ev.fields, meas.inputs.params
    # stated from the pixel labels the result and its quality legend count (computed once, kept)
    q_px = pixel_quality(meas.quality, meas.label_grid, ev.valid_full, meas.inputs.mask, meas.margin_px[1]) \
        if np.any(meas.quality == BEYOND_RANGE) else None
    w_beyond = None if q_px is None else beyond_range_warning(q_px, p)
    warn = (*warn, w_beyond) if w_beyond else tuple(warn)
    for w in warn:
        log.warning(w)
    bulk = measured_bulk(fields["displacement_mm"], ag, ev.components, fit=meas.fit, params=p, distance_m=meas.distance_m,
                         mm_per_px=meas.mm_per_px, sigma_mm=meas.sigma_mm, guard_px=meas.guard_px,
                         camera_distance_m=camera_distance_m)
    res = AnalysisResult(
        method="direct" if meas.fit is not None else "comparative",
        valid=ev.valid_full,
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
        effective_sigma_mm=meas.sigma_mm if ag.transfer is None
        else ag.transfer.effective_sigma_px(meas.sigma_mm / meas.mm_per_px) * meas.mm_per_px,
        n_regions=meas.n_regions if n_regions is None else n_regions,
        demodulations=ag.passes,
        photo_passes=ag.photo[0],
        restart_sigma_px=ag.photo[1],
        margin_px=meas.margin_px,
        guard_px=meas.guard_px,
        noise_std=meas.noise_std,
        bulk=bulk,
        _deferred={"fields": {**fields, "quality": meas.quality, **(extra_fields or {})}, "idx": ev.idx, "grid": ag.grid,
                   "fit_valid": np.ascontiguousarray(ag.valid),
                   "label_grid": meas.label_grid, "mask": meas.inputs.mask},
    )
    if q_px is not None:
        res.__dict__["quality"] = q_px  # the cache of the result's pixel-grid field
    return res


@contextmanager
def routed_warnings() -> Iterator[list[str]]:
    """Numerical warnings raised inside the analysis, collected (not on stderr): the list yielded receives them at exit."""
    numerical: list[str] = []
    # Underflow (tiny spectral powers squared) is harmless and not reported.
    with warnings.catch_warnings(record=True) as caught, np.errstate(all="warn", under="ignore"):
        warnings.simplefilter("always")
        yield numerical
    seen = set()
    for w in caught:
        text = f"numerical: {w.category.__name__}: {w.message}"
        if text not in seen:
            seen.add(text)
            numerical.append(text)


# --------------------------------------------------------------------------- public API


def prepare_reference(reference: np.ndarray, *, params: AnalyzerParams | dict[str, Any] | None = None,
                      pattern: str | None = None) -> ReferenceModel:
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
    p = resolve_params(params, pattern)
    with routed_warnings() as numerical:
        ref, warn = checked_image(reference, "reference")
        if p.pattern == "auto":  # a given one is checked on the photo
            settled = settle_pattern(p, ref)
            p, warn = settled.params, warn + settled.warnings
        spec = F.compute_spectrum(ref)
        carriers = F.find_carriers(spec, min_period_px=p.min_period_px, image=ref)
        F.check_image_size(ref.shape, max(carriers.k1.period_px, carriers.k2.period_px))
        covs = covariances(carriers, p)
        grid = F.sampling_grid(ref.shape, list(covs), p.decimation)
        bb = basebands(spec, carriers, covs, grid)
        mods = tuple(modulation(b, c.period_px, grid, p) for b, c in zip(bb, (carriers.k1, carriers.k2)))
        # Homography of the reference's own grid: the pixel -> backdrop Jacobian (A1, projective).
        zs, cohs = smooth_with_coherence(bb, (carriers.k1, carriers.k2), grid, p, smoothed_abs=mods)
        wrapped = [np.angle(z) for z in zs]
        mg = margins(carriers, covs, p, direct=False)
        reg = valid_region(wrapped, cohs, mods, carriers, grid, p, None, [], margin_px=mg.border_px,
                           edge_margin_px=mg.edge_px)
        if reg.n == 0:
            raise InputError("the reference photo shows no usable grid region; check it is in focus and well exposed")
        yy, xx = grid.coords()
        psi = [unwrap(w, reg.valid, reg.labels, reg.n, seed=p.ransac_seed) for w in wrapped]
        U = carriers.k1.fx * xx + carriers.k1.fy * yy + psi[0] / (2 * np.pi)
        V = carriers.k2.fx * xx + carriers.k2.fy * yy + psi[1] / (2 * np.pi)
        fit = fit_grid_homography((U, V), yy, xx, reg.labels, reg.n, carriers, grid, p).fit
        noise = noise_std(spec, carriers)
    return ReferenceModel(ref.shape, carriers, covs, grid, bb, mods, fit, p, warn + tuple(numerical), noise,
                          grid_spread(None, carriers, spectrum=spec))


def analyze(
    image: np.ndarray | str | os.PathLike[str],
    *,
    pitch_mm: float,
    distance_m: float,
    reference: np.ndarray | ReferenceModel | str | os.PathLike[str] | None = None,
    params: AnalyzerParams | dict[str, Any] | str | os.PathLike[str] | None = None,
    mask: np.ndarray | str | os.PathLike[str] | None = None,
    pattern: str | None = None,
    detrend_degree: int | None = None,
    sigma_mm: float | None = None,
    lens: LensCalibration | None = None,
    camera_distance_m: float | None = None,
    camera: dict[str, Any] | None = None,
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
        scale against ``pitch_mm`` (:mod:`glassdist.analyzer.plausibility`).

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

    The stages (module docstring): inputs checked, F1-F5 (:mod:`~glassdist.analyzer.demodulate`,
    :mod:`~glassdist.analyzer.deform`), Block I (Direct), the Block A grid, A1-A3
    (:mod:`~glassdist.analyzer.components`), the result.

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
    img, ref, prm, msk, sources = read_inputs(image, reference, params, mask, detrend_degree, sigma_mm)
    sources["given"] = given_settings(prm, pattern=pattern, fallback=getattr(ref, "params", None))
    if camera_distance_m is not None:
        camera_distance_m = check_number(camera_distance_m, "camera_distance_m (camera to pane)", DISTANCE_M)
    with routed_warnings() as numerical:
        meas = measure(img, pitch_mm, distance_m, ref, prm, msk, pattern, lens=lens)
        refm = meas.inputs.reference
        slips = tuple(review_measurement(np.shape(img), None if refm is None else refm.grid_spread, meas.grid_spread,
                                         mm_per_px=meas.mm_per_px, distance_m=distance_m, pitch_mm=pitch_mm,
                                         camera=sources.get("camera") if camera is None else camera))
        del image, img  # Block A needs no photo: freed here unless the caller keeps it (the command line does not)
        ev = evaluate(meas, meas.ag, meas.warnings + slips)
    res = result_of(meas, ev, meas.warnings + slips + ev.warnings + tuple(numerical),
                    camera_distance_m=camera_distance_m)
    return replace(res, sources=sources)

