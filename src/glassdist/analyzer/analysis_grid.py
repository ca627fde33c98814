"""The Block A grid: the unwrapped phases as block means of the demodulation grid, with the instrument's transfer.

Block A differentiates the displacement; it needs no finer grid than the reporting smoothing
and the demodulation's passband allow. :func:`to_analysis_grid` forms block means as coarse as
those two bounds allow (:func:`analysis_block`) and hands the phases on in an
:class:`AnalysisGrid` record together with the instrument transfer
(:class:`~glassdist.analyzer.transfer.InstrumentTransfer`) Block A divides out. In the
Direct Method, pass 2 (:func:`direct_pass2`) then takes the phases against the
homography-warped carrier.

References
----------
Paper §2.2 (Block A, Direct Method pass 2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from . import fourier as F
from .demodulate import demodulation_blur_px2
from .homography import HomographyFit, logical_coordinates
from .params import AnalyzerParams
from .region import ANALYSED, Region, downsample_mask, trim_edges
from .resample import image_grid_valid
from .transfer import InstrumentTransfer, dirichlet_response

__all__ = ["BLOCK_MIN_RESPONSE", "AnalysisGrid", "analysis_block", "direct_pass2", "half_response_frequency",
           "reported_region", "reporting_smoothing", "to_analysis_grid", "trusted_warnings"]


@dataclass(frozen=True)
class AnalysisGrid:
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


#: Least response of Block A's block means (Dirichlet kernel) at the frequency where the demodulation
#: passes half the displacement: about four blocks per wavelength there.
BLOCK_MIN_RESPONSE = 0.9


def analysis_block(sigma_px: float, blur: np.ndarray | None, grid: F.SamplingGrid, p: AnalyzerParams,
                   passes: int = 1, photo: tuple[int, float] = (0, 0.0)) -> int:
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
    nu = None if blur is None else half_response_frequency(InstrumentTransfer(
        blur, fine_step_px=grid.step, passes=passes, photo_passes=photo[0], restart_sigma_px=photo[1]))
    for m in (4, 2):
        if h % m == 0 and w % m == 0 and m * step <= residual / 2.0 and min(h, w) // m >= 16:
            if nu is None or float(dirichlet_response(m, step, np.asarray(nu))) >= BLOCK_MIN_RESPONSE:
                return m
    return 1


def half_response_frequency(tr: InstrumentTransfer) -> float:
    """The frequency (cycles/px) where the demodulation's response first falls below one half.

    The highest along either axis for either carrier.
    """
    f = np.linspace(0.0, 0.5, 2001)
    zero = np.zeros_like(f)
    out = 0.0
    for i in range(2):
        for fy, fx in ((f, zero), (zero, f)):
            below = np.nonzero(tr.demodulation(i, fy, fx) < 0.5)[0]
            out = max(out, float(f[below[0]]) if below.size else 0.5)
    return out


def to_analysis_grid(phases: np.ndarray, region: Region, grid: F.SamplingGrid, sigma_px: float,
                     blur: np.ndarray | None, p: AnalyzerParams, passes: int = 1,
                     photo: tuple[int, float] = (0, 0.0)) -> AnalysisGrid:
    """Block means of the demodulation grid, as coarse as the reporting smoothing and the demodulation's passband allow.

    The block step stays below half the residual smoothing, and the block means keep the
    displacement the demodulation resolves (:func:`analysis_block`). The instrument transfer
    (Gaussian demodulation blur, block means, interpolation to the pixel grid) goes with
    the phases, for Block A to divide it out.
    """
    m = analysis_block(sigma_px, blur, grid, p, passes, photo)
    agrid = grid if m == 1 else F.block_grid(grid, m)
    transfer = None if blur is None else InstrumentTransfer(
        blur, fine_step_px=grid.step, block=m, interp_step_px=None if agrid.is_full else agrid.step, passes=passes,
        photo_passes=photo[0], restart_sigma_px=photo[1],
    )
    passes = passes + photo[0]
    if m == 1:
        return AnalysisGrid(grid, phases, region.valid, region.labels, region.valid, None, transfer, passes, photo)
    phases, fill = F.block_mean(phases, region.valid, m)
    hb, wb = agrid.shape
    block_label = region.labels.reshape(hb, m, wb * m).max(axis=1).reshape(hb, wb, m).max(axis=2)
    # Whole blocks only (their mean sits at the block centre); partial border blocks
    # get the smooth extrapolation from inside, and the fine mask trims them below.
    labels = np.where(fill >= 1.0, block_label, 0)
    valid = labels > 0
    report = ndimage.binary_dilation(valid, iterations=1) & (fill > 0)
    return AnalysisGrid(agrid, phases, valid, labels, report, region.valid, transfer, passes, photo)


def direct_pass2(ag: AnalysisGrid, carriers: F.CarrierPair, fit: HomographyFit) -> np.ndarray:
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


def reporting_smoothing(carriers: F.CarrierPair, covs: tuple[np.ndarray, np.ndarray], p: AnalyzerParams, p_c: float,
                        mm_per_px: float) -> tuple[float, np.ndarray | None, tuple[str, ...]]:
    """The reporting smoothing (mm), the Gaussian demodulation blur (px^2 per carrier) to compensate, and a warning.

    ``sigma_mm`` (else ``sigma_periods`` carrier periods ``p_c``); the blur is Block F's
    (:func:`~glassdist.analyzer.demodulate.demodulation_blur_px2`) where
    ``compensate_demodulation_blur``; the warning says when sigma is finer than it.
    """
    blur = demodulation_blur_px2(carriers, covs, p) if p.compensate_demodulation_blur else None
    sigma_mm = p.sigma_mm if p.sigma_mm is not None else p.sigma_periods * p_c
    warn: tuple[str, ...] = ()
    if blur is not None:
        s_px = sigma_mm / mm_per_px
        worst = max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
        if worst > s_px**2:
            warn = (
                f"sigma_mm = {sigma_mm:.3g} mm ({s_px:.1f} px) is finer than the demodulation resolution "
                f"({np.sqrt(worst):.1f} px = {np.sqrt(worst) * mm_per_px:.3g} mm); the effective smoothing is "
                f"{np.sqrt(worst) * mm_per_px:.3g} mm along the least resolved direction (summary.json: effective_sigma_mm)",
            )
    return float(sigma_mm), blur, warn


def reported_region(fields: dict[str, np.ndarray], ag: AnalysisGrid, mask: np.ndarray | None,
                     edge_px: float) -> tuple[np.ndarray, Any, tuple[str, ...]]:
    """The valid region on the image grid (every field finite, outside the image-edge margin), the fill indices, a warning.

    ``fields``: the registered fields on the analysis grid ``ag``
    (:class:`~glassdist.analyzer.analysis_grid.AnalysisGrid`); ``edge_px``: the image-edge margin.
    The warning says when under 75 % of the image (or of the masked region) is reported.
    """
    valid_c = ag.report.copy()
    for f_ in fields.values():
        valid_c &= np.isfinite(f_) if f_.ndim == 2 else np.all(np.isfinite(f_), axis=-1)
    valid_full, idx = image_grid_valid(valid_c, ag.grid, mask, fine_valid=ag.fine_valid)
    trim_edges(valid_full, edge_px)
    cover = float(valid_full[::4, ::4].mean())  # the reported region, as summary.json states it
    if mask is not None:  # an intentional mask is not a loss: the share of the region asked for
        cover = float(np.count_nonzero(valid_full[::4, ::4]) / max(int(np.count_nonzero(mask[::4, ::4])), 1))
    where = "the image" if mask is None else "the masked region"
    if cover < 0.75:
        return valid_full, idx, (f"only {100 * cover:.0f}% of {where} could be analysed (occlusion, frames, low "
                                 "contrast or blur)",)
    return valid_full, idx, ()


# Share of the requested region below which the trusted pixels (quality label 0) are called few.
_FEW_TRUSTED = 0.01


def trusted_warnings(quality: np.ndarray, grid: F.SamplingGrid, mask: np.ndarray | None) -> tuple[str, ...]:
    """Warn when no or few samples are trusted: the statistics are then null or cover little."""
    in_mask = np.ones(grid.shape, bool) if mask is None else downsample_mask(mask, grid)
    share = float(np.count_nonzero((quality == ANALYSED) & in_mask)) / max(int(np.count_nonzero(in_mask)), 1)
    if share == 0.0:
        return (
            "no pixel is trusted (quality label 0): every measured pixel lies within the guard band of an excluded area "
            "or the image edge, so the statistics are null and a specification cannot pass; the maps are still written",
        )
    if share < _FEW_TRUSTED:
        return (f"only {100 * share:.2f}% of the region is trusted (quality label 0): the statistics cover few pixels",)
    return ()
