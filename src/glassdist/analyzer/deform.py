"""Block F, stage F5: iterative deformation of the reference (the demodulation follows the local grid).

Block F's bandpass and complex smoothing are centred on the global carrier. Where the
glass moves the local grid frequency away from it (a strong low-order displacement, or
short waves), the demodulation is no longer linear: the bandpass attenuates and clips the
sidebands, and the carriers leak into each other. Iterative deformation (Scarano 2002 in
PIV; Huang et al. 1993 in fringe analysis) removes the cause:

1. demodulate (F1-F4): the one-pass phases ``phi_i`` predict the field;
2. synthesise the reference warped by the prediction, ``sum_i cos(2 pi f_i . r + pred_i + own_i)``
   (``own_i``: the reference photo's own phase; zero in the Direct Method), at full
   resolution (:func:`warped_reference`);
3. demodulate it with the same filters and heterodyne the photo against it: the photo and
   the warped reference share their local frequencies, so the filters' non-linear response
   cancels and the heterodyne is the residual ``phi - pred``, small and measured linearly;
4. ``pred += residual``; repeat until the RMS update is below ``deformation_tolerance_periods``.

Growth. The one pass leaves out where its bandpass clipped the local grid (steep flanks of
strong waves, labelled beyond measurable distortion). F5 grows its measured region into them a
carrier period per pass (:func:`grow`): a sample joins where its residual against the reference
warped by the nearest measured prediction is coherent, small (the prediction is within a
fraction of a turn, so no whole period is lost) and the photo shows a grid there; it never
crosses a one-pass phase residue (a singularity of the grid itself) and never merges two of the
one pass's connected parts. Each grown sample is then
measured like the others; it stays measured only where its last update is below
:data:`GROWTH_MAX_LAST_UPDATE_PERIODS` (converged), and the final region is judged on the residual. Where the
one pass's grid is too coarse for the reach (:func:`deformation_grid`), F5 works on one with
twice its samples along each axis, so steep flanks do not alias into phase residues.

Photo passes (``deformation_photo_passes``; by default 6 in the Comparative Method, none in the
Direct Method). The warped reference keeps the photo's local frequency, of which the bandpass
passes only its gain. After its passes, F5 then deforms the photo itself back to the reference's
frame (:func:`deformed_photo`), where its grid sits at the carrier, demodulates that and reads the
residual back at the photo's samples (:func:`to_frame`), starting from the warped reference's field
low-passed. Where the photo shows what the reference never saw (:func:`off_frame`) or the deformed
photo draws from off the photo, the residual stays the warped reference's (docs/transfer_function.md,
"Photo deformation").

The phase handed on is ``pred + residual``: the filters' Gaussian ``G`` acts on the residual
only. In the linear regime each pass measures ``G (true - B pred)`` (``B`` the bilinear
interpolation by which the warped reference receives the prediction), so after ``n``
demodulations the output's transfer is ``(1 - (1 - G B)^n) / B`` (close to 1 wherever ``G``
is not small), without the one-pass non-linear losses; Block A divides it out
(:class:`~glassdist.analyzer.transfer.InstrumentTransfer`, ``passes``).

References
----------
Scarano (2002), Meas. Sci. Technol. 13, R1: iterative image deformation methods in PIV.
Huang, Fang & Seah (1993); Wildeman (2018), Exp. Fluids 59, 97 (checkerboard demodulation).
"""

from __future__ import annotations

import functools
import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import ndimage

from . import fourier as F
from .demodulate import (
    Demodulation,
    ReferenceModel,
    basebands,
    demodulation_blur_px2,
    frequency_deviation,
    modulation,
    smooth_with_coherence,
)
from .metrics import masked_gaussian
from .params import AnalyzerParams
from .region import PHASE_RESIDUE, Region, grid_seen
from .transfer import MIN_RESPONSE, gaussian_response

__all__ = [
    "F5Result", "compensated_deviation", "deformation_grid", "deformed_photo", "displacement_to_phase", "fill_nearest",
    "follow_local_grid",
    "grow", "low_passed", "off_frame", "own_phasors", "own_shift", "phase_to_displacement_px", "photo_passes",
    "photo_spline", "rms_update_periods", "to_frame", "to_grid", "warped_heterodyne", "warped_reference",
]

log = logging.getLogger(__name__)

#: Threads for the photo passes' full-resolution resampling (:func:`_spline_at`): the cores this process may use.
_THREADS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)

# A sample joins the measured region only where its wrapped residual is the true one with a
# margin for noise (|residual| well below pi, per carrier), rad.
GROWTH_MAX_RESIDUAL_RAD = 1.0
# A grown sample stays measured only where its last update is below this, carrier periods. Its passes
# started from the nearest measured prediction rather than from the one pass's G-smoothed phase, so the
# output transfer (1 - (1 - G B)^n) / B that Block A divides out holds for it only once converged: an
# unconverged short wave there reads low (a 2.5-period ripple under a dome, Direct, sigma 2 periods: 0.935
# of the truth over the grown samples with no such test, 1.016 with it; twice the converged F5's peak error).
GROWTH_MAX_LAST_UPDATE_PERIODS = 0.02


def _frequency_matrix(carriers: F.CarrierPair) -> np.ndarray:
    return np.array([carriers.k1.f, carriers.k2.f])  # rows f_i (cycles/px), columns (x, y)


def phase_to_displacement_px(phases: np.ndarray, carriers: F.CarrierPair) -> np.ndarray:
    """``u = -F^{-1} phi / (2 pi)`` (px, ``[..., 0]`` along columns), from phases (h, w, 2), rad.

    ``phi_i = -2 pi f_i . u``: the photo's carrier phase at ``r`` is the reference's at ``r - u``.
    """
    return -(phases / (2 * np.pi)) @ np.linalg.inv(_frequency_matrix(carriers)).T


def displacement_to_phase(u: np.ndarray, carriers: F.CarrierPair) -> np.ndarray:
    """``phi_i = -2 pi f_i . u`` (h, w, 2) from ``u`` (px)."""
    return -2 * np.pi * (u @ _frequency_matrix(carriers).T)


def fill_nearest(a: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``a`` (h, w[, c]) with its samples outside ``valid`` set to the nearest valid one (zeros when none is)."""
    return _filler(valid)(a)


def _filler(valid: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`fill_nearest` for one ``valid``, its nearest-sample indices found once (a pass loop reuses them)."""
    if valid.all():
        return lambda a: a
    if not valid.any():
        return np.zeros_like
    iy, ix = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return lambda a: a[iy, ix]


def deformation_grid(grid: F.SamplingGrid, max_deviation: float, period_px: float,
                     decimation: int | str) -> F.SamplingGrid:
    """The demodulation grid F5 works on: ``grid``, or one with twice its samples along each axis where the reach needs it.

    A local frequency ``max_deviation * |f|`` off the carrier turns the phase by
    ``2 pi max_deviation step / period`` per sample; near ``pi`` the samples alias it (phase
    residues on steep flanks). Where the step exceeds ``period / (4 max_deviation)`` (a quarter
    turn per sample, ``period_px`` the shorter carrier period), F5 halves it: its ``2 x 2``
    blocks are then the one pass's samples, and the Block A grid is the same. A user-set
    ``decimation`` is kept.
    """
    if decimation != "auto" or max(grid.step) <= period_px / (4.0 * max_deviation) or grid.is_full:
        return grid
    H, W = grid.full_shape
    h, w = grid.shape
    return F.SamplingGrid(grid.full_shape, (min(2 * h, H // 4 * 4), min(2 * w, W // 4 * 4)))


def to_grid(a: np.ndarray, src: F.SamplingGrid, dst: F.SamplingGrid, *, nearest: bool = False) -> np.ndarray:
    """``a`` (h, w[, c]) on ``src`` resampled onto ``dst`` (same image), bilinear or nearest sample.

    Both grids put sample ``i`` at ``(i + 1/2) step - 1/2`` px (:class:`~glassdist.analyzer.fourier.SamplingGrid`).
    """
    if src.shape == dst.shape:
        return a
    yy, xx = dst.coords()
    (oy, ox), (sy, sx) = src.offset, src.step
    fy, fx = (yy[:, 0] - oy) / sy, (xx[0] - ox) / sx
    if nearest:
        iy = np.clip(np.rint(fy).astype(int), 0, src.shape[0] - 1)
        ix = np.clip(np.rint(fx).astype(int), 0, src.shape[1] - 1)
        return a[iy[:, None], ix[None, :]]
    y0 = np.clip(np.floor(fy).astype(int), 0, src.shape[0] - 2)
    x0 = np.clip(np.floor(fx).astype(int), 0, src.shape[1] - 2)
    ty = np.clip(fy - y0, 0.0, 1.0).astype(np.float32)[:, None]
    tx = np.clip(fx - x0, 0.0, 1.0).astype(np.float32)[None, :]
    if a.ndim == 3:
        ty, tx = ty[..., None], tx[..., None]
    top = a[y0][:, x0] * (1 - tx) + a[y0][:, x0 + 1] * tx
    bottom = a[y0 + 1][:, x0] * (1 - tx) + a[y0 + 1][:, x0 + 1] * tx
    return (top * (1 - ty) + bottom * ty).astype(a.dtype)


def grow(measured: np.ndarray, coherent: np.ndarray, residual: np.ndarray, grid: F.SamplingGrid, reach_px: float,
         parts: np.ndarray | None = None) -> np.ndarray:
    """Samples that join the measured region in this pass (bool (h, w)).

    Within ``reach_px`` of ``measured``, coherent, and with a wrapped residual (h, w, 2) below
    :data:`GROWTH_MAX_RESIDUAL_RAD` on both carriers: there the prediction (the nearest
    measured one) is within a fraction of a turn of the field, so ``prediction + residual``
    continues the measured phase without a whole-period jump, and the next pass measures
    against a reference warped by it. ``parts`` (int (h, w), updated in place): the connected
    part of the one pass each measured sample grew from; a new sample takes its nearest
    measured sample's part, and none joins next to another part's sample: two parts the one pass
    kept apart never merge (where two fronts meet, across the band the one pass could not
    measure, nothing checks that their phases agree, and a seam with no end has no residue).
    """
    if measured.all() or not measured.any():
        return np.zeros_like(measured)
    dist, (iy, ix) = ndimage.distance_transform_edt(~measured, sampling=grid.step, return_indices=True)
    small = np.all(np.abs(residual) < GROWTH_MAX_RESIDUAL_RAD, axis=-1)
    new = (dist <= reach_px) & coherent & small & ~measured
    if parts is None or not new.any():
        return new
    lab = np.where(new, parts[iy, ix], parts)
    lab = np.where(measured | new, lab, 0)
    big = np.iinfo(np.int32).max
    hi = ndimage.maximum_filter(lab, size=3)
    lo = ndimage.minimum_filter(np.where(lab > 0, lab, big), size=3)
    new &= (hi == lab) & (lo == lab)
    parts[new] = lab[new]
    return new


def warped_reference(pred: np.ndarray, own: np.ndarray | None, grid: F.SamplingGrid, carriers: F.CarrierPair) -> np.ndarray:
    """The reference grid warped by the current displacement, as its two carriers (float32, full resolution).

    ``sum_i cos(2 pi f_i . r + pred_i(r) + own_i(r))``: ``pred`` (h, w, 2) (rad,
    continuous: the prediction) and ``own`` (h, w, 2) complex, the reference photo's own
    baseband ``exp(i own_i)`` (None: the flat carrier of the Direct Method), each on a grid of
    ``grid``'s image (their own sample counts: F5 may work on a finer grid than the reference's), both brought to
    the pixels by ``cv2.resize`` (bilinear: it maps the grid's sample positions exactly; its
    transfer, ``sinc^2`` per axis, is the ``B`` of the output's transfer in the module notes;
    the reference's phase is interpolated as a phasor, so its
    wraps do no harm). Demodulated by the same filters as the photo, it carries the same local
    frequencies and the same cross-talk between the two carriers, so the heterodyne of the two
    is the residual alone (the filters' non-linear effects cancel).
    """
    import cv2

    H, W = grid.full_shape
    y = np.arange(H, dtype=np.float32)[:, None]
    x = np.arange(W, dtype=np.float32)[None, :]
    out = np.zeros((H, W), np.float32)

    def up(a: np.ndarray) -> np.ndarray:
        return cv2.resize(np.ascontiguousarray(a, np.float32), (W, H), interpolation=cv2.INTER_LINEAR)

    for i, c in enumerate((carriers.k1, carriers.k2)):
        ph = up(pred[..., i])
        ax, ay = np.float32(2 * np.pi * c.fx), np.float32(2 * np.pi * c.fy)
        if own is None:
            re = im = None
        else:
            u = own[..., i] / np.maximum(np.abs(own[..., i]), 1e-30)
            re, im = up(u.real), up(u.imag)

        def block(rows: slice, ph: np.ndarray = ph, re: np.ndarray | None = re, im: np.ndarray | None = im,
                  ax: np.float32 = ax, ay: np.float32 = ay) -> None:
            p_ = ph[rows]
            p_ += ax * x
            p_ += ay * y[rows]
            if re is None or im is None:
                out[rows] += np.cos(p_)
                return
            # (cos ph re - sin ph im) / |re + i im|, in place
            r_, i_ = re[rows], im[rows]
            norm = r_ * r_
            norm += np.square(i_)
            np.sqrt(norm, out=norm)
            np.maximum(norm, np.float32(1e-6), out=norm)
            term = np.cos(p_)
            term *= r_
            i_ *= np.sin(p_, out=p_)
            term -= i_
            term /= norm
            out[rows] += term

        _by_rows(H, block)
    return out


# Fixed-point iterations of the inverse map w = u o (id + w): each multiplies the error by about the
# displacement gradient (under the 0.75 reach wherever F5 measures); on the strong ray-traced 2.5-period
# ripple 6 and 60 iterations read the same.
INVERSE_ITERATIONS = 6


def _grid_maps(grid: F.SamplingGrid, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cv2.remap maps (in ``grid``'s sample indices) of the points ``r + u(r)`` at ``grid``'s samples (u in px)."""
    h, w = grid.shape
    (sy, sx) = grid.step
    my, mx = np.mgrid[0:h, 0:w].astype(np.float32)
    return mx + np.float32(1.0 / sx) * u[..., 0], my + np.float32(1.0 / sy) * u[..., 1]


def _remap(a: np.ndarray, mx: np.ndarray, my: np.ndarray) -> np.ndarray:
    """``a`` (float32) read at the sample indices ``(my, mx)``, bilinear, edge samples replicated."""
    import cv2

    return cv2.remap(np.ascontiguousarray(a, np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def photo_spline(img: np.ndarray) -> np.ndarray:
    """The photo's cubic B-spline coefficients (float32, mirrored edges) for :func:`deformed_photo`.

    Computed once per analysis.
    """
    return ndimage.spline_filter(np.asarray(img, np.float32), order=3, output=np.float32, mode="mirror")


def deformed_photo(spline: np.ndarray, pred: np.ndarray, grid: F.SamplingGrid, carriers: F.CarrierPair
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The photo brought back to the reference's frame by the current displacement.

    ``img(r) = ref(r - u(r))`` (``u`` from the prediction ``pred`` (h, w, 2), rad, on ``grid``),
    so ``img(s + w(s)) = ref(s)`` with ``w = u o (id + w)``, solved on ``grid`` by fixed-point
    iteration (:data:`INVERSE_ITERATIONS`) and brought to the pixels by ``cv2.resize`` (bilinear,
    the ``B`` of the transfer, as in :func:`warped_reference`). Where the prediction holds, the
    deformed photo shows the grid at the carrier everywhere: the bandpass passes its whole signal,
    however far the glass moved the local frequency (image deformation, Scarano 2002; the warped
    reference instead keeps the photo's local frequency, of which the bandpass passes only its gain).

    The photo (``spline``: its :func:`photo_spline`) is resampled by its cubic B-spline: bilinear
    resampling turns a carrier's phase by up to ``0.008`` rad at an 8 px period (it varies with
    the fractional shift, so with the field: on a strong 8 px line-grid wave, Direct, the error
    against the truth went from 0.0018 to 0.0035 period), and OpenCV's bicubic (its 1/32 px
    tables) by 0.011-0.014 rad at a 14 px period.

    Returns
    -------
    deformed : ndarray (H, W), float32
    outside : ndarray of bool (h, w)
        Samples of ``grid`` (reference frame) whose ``s + w(s)`` lies off the photo: there the
        deformed photo is not the photo's.
    """
    return _deformed(spline, phase_to_displacement_px(pred, carriers).astype(np.float32), grid)


def _deformed(spline: np.ndarray, u: np.ndarray, grid: F.SamplingGrid) -> tuple[np.ndarray, np.ndarray]:
    """:func:`deformed_photo` from the displacement ``u`` (h, w, 2; px, float32) on ``grid``."""
    import cv2

    w = u
    for _ in range(INVERSE_ITERATIONS):
        mx, my = _grid_maps(grid, w)
        w = np.stack([_remap(u[..., i], mx, my) for i in range(2)], axis=-1)
    H, W = grid.full_shape
    yy, xx = grid.coords()
    tx, ty = xx + w[..., 0], yy + w[..., 1]
    outside = (tx < 0) | (tx > W - 1) | (ty < 0) | (ty > H - 1)
    wx: np.ndarray = cv2.resize(np.ascontiguousarray(w[..., 0]), (W, H), interpolation=cv2.INTER_LINEAR)
    wy: np.ndarray = cv2.resize(np.ascontiguousarray(w[..., 1]), (W, H), interpolation=cv2.INTER_LINEAR)
    wx += np.arange(W, dtype=np.float32)[None, :]
    wy += np.arange(H, dtype=np.float32)[:, None]
    return _spline_at(spline, wy, wx), outside


def _spline_at(spline: np.ndarray, wy: np.ndarray, wx: np.ndarray) -> np.ndarray:
    """The cubic B-spline of coefficients ``spline`` at ``(wy, wx)`` (float32), in row blocks on threads.

    Each output value is computed alone (``scipy.ndimage.map_coordinates`` releases the GIL), so
    the blocks give the same values as one call, on every core.
    """
    out = np.empty(wy.shape, np.float32)

    def block(rows: slice) -> None:
        ndimage.map_coordinates(spline, [wy[rows], wx[rows]], order=3, mode="mirror", prefilter=False, output=out[rows])

    _by_rows(wy.shape[0], block)
    return out


def _by_rows(n_rows: int, block: Callable[[slice], None]) -> None:
    """``block(rows)`` over ``n_rows`` rows in :data:`_THREADS` contiguous blocks of at least 64 rows, on threads.

    For element-wise work on full-resolution arrays (numpy's ufuncs and ``map_coordinates``
    release the GIL): each value is computed as in one call over all rows.
    """
    n = min(_THREADS, max(1, n_rows // 64))
    bounds = [slice(k * n_rows // n, (k + 1) * n_rows // n) for k in range(n)]
    if n == 1:
        block(bounds[0])
        return
    with ThreadPoolExecutor(n) as pool:
        list(pool.map(block, bounds))


def off_frame(pred: np.ndarray, grid: F.SamplingGrid, carriers: F.CarrierPair) -> np.ndarray:
    """Samples ``r`` of ``grid`` (photo frame) whose ``r - u(r)`` lies off the image: the backdrop the photo shows there
    lies beyond the reference's view, no sample of the deformed photo draws from it, and :func:`to_frame` reads
    the edge there (``pred`` (h, w, 2), rad, as for :func:`to_frame`)."""
    return _off_frame(phase_to_displacement_px(pred, carriers), grid)


def _off_frame(u: np.ndarray, grid: F.SamplingGrid) -> np.ndarray:
    """:func:`off_frame` from the displacement ``u`` (h, w, 2; px) on ``grid``."""
    H, W = grid.full_shape
    yy, xx = grid.coords()
    sx, sy = xx - u[..., 0], yy - u[..., 1]
    return (sx < 0) | (sx > W - 1) | (sy < 0) | (sy > H - 1)


def to_frame(z: np.ndarray, src: F.SamplingGrid, pred: np.ndarray, grid: F.SamplingGrid, carriers: F.CarrierPair) -> np.ndarray:
    """A signal measured in the reference's frame on ``src`` read at the photo's samples of ``grid``: ``z(r - u(r))``.

    ``z`` (h', w'), real or complex (bilinear; a complex one as its real and imaginary parts,
    so phase wraps do no harm); ``pred`` (h, w, 2), rad, the displacement the photo was deformed by, on ``grid``.
    """
    return _read(z, _frame_maps(src, phase_to_displacement_px(pred, carriers).astype(np.float32), grid))


_Maps = tuple[np.ndarray, np.ndarray]


def _frame_maps(src: F.SamplingGrid, u: np.ndarray, grid: F.SamplingGrid) -> _Maps:
    """The remap maps (``src``'s sample indices) of ``r - u(r)`` at ``grid``'s samples (``u`` float32, px), for :func:`_read`.

    A pass reads several signals across the same displacement: the maps are made once for all of them.
    """
    yy, xx = grid.coords()
    (oy, ox), (sy, sx) = src.offset, src.step
    mx = ((xx[0][None, :] - u[..., 0] - ox) / sx).astype(np.float32)
    my = ((yy[:, 0][:, None] - u[..., 1] - oy) / sy).astype(np.float32)
    return mx, my


def _read(z: np.ndarray, maps: _Maps) -> np.ndarray:
    """:func:`to_frame` through maps made by :func:`_frame_maps`."""
    mx, my = maps
    if not np.iscomplexobj(z):
        return _remap(z, mx, my)
    return (_remap(z.real, mx, my) + 1j * _remap(z.imag, mx, my)).astype(np.complex64)



def compensated_deviation(phases: np.ndarray, valid: np.ndarray, carriers: F.CarrierPair, step: tuple[float, float],
                          blur_px2: np.ndarray) -> float:
    """The local grid frequency's departure from the carrier with the demodulation's own blur divided out.

    :func:`~glassdist.analyzer.demodulate.frequency_deviation` (99th percentile of
    ``|grad phi_i| / (2 pi |f_i|)``) of the one-pass phases (h, w, 2), rad, on a grid of
    ``step`` px, after dividing each phase's spectrum by the response ``G_i`` of the
    Gaussian stages it went through (``blur_px2[i]``, spatial covariance px^2,
    :func:`~glassdist.analyzer.demodulate.demodulation_blur_px2`) where ``G_i`` is at least
    :data:`~glassdist.analyzer.transfer.MIN_RESPONSE` (what Block A's compensation restores)
    and discarding it beyond. The one-pass phase of a wave a few carrier periods long is
    attenuated by ``G_i`` while the non-linearity of the demodulation follows the photo's own
    local frequency: F5's trigger reads the field the report will carry, not the attenuated
    one. Each phase is first detrended by its least-squares plane over ``valid`` and extended
    by mirror symmetry (the FFT's wrap-around then adds no step at the border); samples
    outside ``valid`` take the nearest valid one's phase.
    """
    if valid.sum() < 16:
        return 0.0
    h, w = valid.shape
    filled = fill_nearest(np.nan_to_num(phases.astype(np.float64)), valid)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    A = np.stack([np.ones(int(valid.sum())), xx[valid], yy[valid]], 1)
    fy = np.fft.fftfreq(2 * h, d=step[0])[:, None]
    fx = np.fft.rfftfreq(2 * w, d=step[1])[None, :]
    out = np.empty(filled.shape)
    for i in range(2):
        c = np.linalg.lstsq(A, filled[..., i][valid], rcond=None)[0]
        plane = c[0] + c[1] * xx + c[2] * yy
        ext = np.pad(filled[..., i] - plane, ((0, h), (0, w)), mode="symmetric")
        g = gaussian_response(blur_px2[i], fy, fx)
        gain = np.where(g >= MIN_RESPONSE, 1.0 / np.maximum(g, MIN_RESPONSE), 0.0)
        out[..., i] = np.fft.irfft2(np.fft.rfft2(ext) * gain, s=ext.shape)[:h, :w] + plane
    return frequency_deviation(out, valid, (carriers.k1, carriers.k2), step)


# --------------------------------------------------------------------------- the F5 loop


@dataclass(frozen=True)
class F5Result:
    """F5's outcome, all on ``demod.grid``.

    Attributes
    ----------
    demod : Demodulation
        The demodulation whose phase is ``predictor + residual`` (``passes``: the demodulations
        summed, the one pass included; ``photo_passes`` and ``restart_sigma_px``: the photo passes).
    residual : list of ndarray (h, w)
        The last residual phases per carrier, rad (the local-frequency test of F4).
    region_mods : list of ndarray (h, w)
        The modulations over the bandpass's gain at the local frequency (photo's, then reference's).
    beyond : ndarray of bool (h, w)
        Samples whose local frequency is beyond the bandpass's reach.
    measured : Region
        The region the predictor was measured on (one-pass labels elsewhere).
    grown : ndarray of bool (h, w)
        The samples F5 grew into.
    """

    demod: Demodulation
    residual: list[np.ndarray]
    region_mods: list[np.ndarray]
    beyond: np.ndarray
    measured: Region
    grown: np.ndarray


@dataclass(frozen=True)
class _Warped:
    """The warped reference's passes (:func:`_converge`): the predictor, the last residual and what it was read from."""

    pred: np.ndarray
    residual: np.ndarray
    signals: tuple[np.ndarray, ...]
    coherences: tuple[np.ndarray, ...]
    reference_basebands: tuple[np.ndarray, ...]
    measured: np.ndarray
    grown: np.ndarray
    passes: int


def follow_local_grid(spectrum: F.Spectrum, img: np.ndarray, refm: ReferenceModel | None, demod: Demodulation,
                      region: Region, phases: np.ndarray, p: AnalyzerParams,
                      contrast: Callable[[F.SamplingGrid], np.ndarray]) -> F5Result | None:
    """F5: iterative deformation of the reference (module docstring).

    ``spectrum``: the photo's spectrum (:attr:`Demodulation.spectrum`, the one FFT of the photo); ``img``: the
    photo (its photo passes deform it). Returns None when no pass is needed (``deformation_passes`` 0, or the
    one-pass local frequency, the demodulation's blur divided out (:func:`compensated_deviation`), within
    ``deformation_min_deviation`` of the carrier), else an :class:`F5Result`: the demodulation whose phase is
    ``predictor + residual`` (transfer in :mod:`~glassdist.analyzer.transfer`), on a grid fine enough for the
    reach (:func:`deformation_grid`), and the region the predictor was measured on: the one-pass region grown by
    up to ``deformation_growth_passes`` passes (:func:`grow`), then up to ``deformation_passes`` passes to
    converge. ``contrast(grid)``: the photo's local contrast on ``grid``
    (:func:`~glassdist.analyzer.region.local_contrast`); the growth enters only where it shows a grid
    (:func:`~glassdist.analyzer.region.grid_seen`).
    """
    ks = demod.carriers
    if p.deformation_passes == 0 or img is None or region.n == 0:
        return None
    covs = demod.covariances
    if compensated_deviation(phases, region.valid, ks, demod.grid.step,
                             demodulation_blur_px2(ks, covs, p)) <= p.deformation_min_deviation:
        return None
    period = max(ks.k1.period_px, ks.k2.period_px)
    grid = deformation_grid(demod.grid, p.deformation_max_deviation, min(ks.k1.period_px, ks.k2.period_px), p.decimation)
    own = None if refm is None else np.stack(refm.baseband, axis=-1)  # the reference's own phase (its lens, its print)
    bb_img = basebands(spectrum, ks, covs, grid)
    assert region.quality is not None
    first = to_grid(region.quality, demod.grid, grid, nearest=True)
    w = _converge(bb_img, own, demod, region, phases, grid, first, p, contrast)
    pred, res = w.pred, w.residual
    # A grown sample started from its neighbours' prediction, not from the one pass's G-smoothed phase, so the
    # documented transfer holds for it only once it has converged: kept where its last update is small.
    late = w.grown & (np.sqrt(np.sum(phase_to_displacement_px(res, ks) ** 2, axis=-1)) / period
                      > GROWTH_MAX_LAST_UPDATE_PERIODS)
    measured = w.measured & ~late
    grown = w.grown & ~late
    # The last residual was measured against the reference warped by pred: phi = pred + residual,
    # the converged field (the filters' Gaussian acts on the residual only; after n demodulations
    # the linear transfer is (1 - (1 - G B)^n) / B, transfer.InstrumentTransfer).
    phase = pred + res
    n_photo, restart_px = 0, 0.0
    # the photo's modulation on F5's grid, computed once, only where something needs it
    img_mods = functools.cache(lambda: tuple(modulation(b, c.period_px, grid, p) for b, c in zip(bb_img, (ks.k1, ks.k2))))
    photo_max = p.photo_passes_for(refm is not None)
    photo_mods: list[np.ndarray] = []
    if photo_max > 0:
        # The photo passes start from the field low-passed: what it carries beyond the filters' passband
        # no pass can see, and the deformation would fold it into what they do see.
        restart_px = p.deformation_photo_restart_periods * period
        phase, n_photo, photo_mods = photo_passes(img, refm, demod, bb_img, own, low_passed(phase, measured, grid, restart_px),
                                                  measured, grid, p, photo_max, img_mods)
    total = tuple((np.abs(z) * np.exp(1j * phase[..., i])).astype(np.complex64) for i, z in enumerate(w.signals))
    if grid is demod.grid:
        mods = list(demod.mods)
    else:  # the photo's on F5's grid, the reference's brought to it
        mods = list(img_mods()) + [to_grid(m_, demod.grid, grid) for m_ in demod.mods[2:]]
    # The bandpass's gain at the local frequency, read off the warped reference (a uniform grid
    # of amplitude 1/2 per carrier): the photo's modulation is judged against it (a faint grid where the gain
    # explains it is not occluded), and where the gain is below its value at
    # deformation_max_deviation off the carrier the signal is beyond reach.
    gain = [modulation(r, c.period_px, grid, p) / np.float32(0.5) for r, c in zip(w.reference_basebands, (ks.k1, ks.k2))]
    floor = float(np.exp(-0.5 * (p.deformation_max_deviation / p.bandpass_sigma_along) ** 2))
    beyond = np.any([g_ < floor for g_ in gain], axis=0)
    region_mods = [m_ / np.maximum(g_, floor) for m_, g_ in zip(mods[:2], gain)] + mods[2:]
    if n_photo:  # the noise goes as one over the modulation the last pass measured at (photo_passes)
        mods = photo_mods + mods[2:]
    out = Demodulation(demod.method, ks, covs, grid, total, w.coherences, tuple(mods), demod.noise_std,
                       passes=w.passes + 1, photo_passes=n_photo, restart_sigma_px=restart_px)
    return F5Result(out, list(res.transpose(2, 0, 1)), region_mods, beyond,
                    Region(measured, measured.astype(np.int32), 1, first), grown)


def _converge(bb_img: tuple[np.ndarray, ...], own: np.ndarray | None, demod: Demodulation, region: Region,
              phases: np.ndarray, grid: F.SamplingGrid, first: np.ndarray, p: AnalyzerParams,
              contrast: Callable[[F.SamplingGrid], np.ndarray]) -> _Warped:
    """F5's passes against the warped reference: the growth, then the passes to converge (:func:`follow_local_grid`)."""
    ks, covs = demod.carriers, demod.covariances
    period = max(ks.k1.period_px, ks.k2.period_px)
    pred = to_grid(fill_nearest(np.nan_to_num(phases), region.valid), demod.grid, grid)
    measured = to_grid(region.valid, demod.grid, grid, nearest=True)
    # A phase residue of the one pass is a singularity of the grid itself (a dislocation, a tear), not a
    # frequency the bandpass clipped: no continuous prediction crosses it, so the growth goes around it.
    growable = first != PHASE_RESIDUE
    if p.deformation_growth_passes > 0:
        growable &= grid_seen(contrast(grid), measured, period, grid)
    # the one pass's connected parts: the growth never merges two (grow)
    parts = np.where(measured, to_grid(region.labels, demod.grid, grid, nearest=True), 0).astype(np.int32)
    grown = np.zeros_like(measured)
    growth_left, converging, k = p.deformation_growth_passes, 0, 0
    while True:
        k += 1
        het, bb_ref = warped_heterodyne(bb_img, pred, own, grid, ks, covs)
        zs, cohs = smooth_with_coherence(het, (ks.k1, ks.k2), grid, p)
        del het
        res = np.stack([np.angle(z) for z in zs], axis=-1)
        coherent = np.all([c_ > p.coherence_threshold for c_ in cohs], axis=0)
        ok = coherent & measured
        step = rms_update_periods(res, ok, ks, period)
        new = grow(measured, coherent & growable, res, grid, period, parts) if growth_left > 0 else np.zeros_like(measured)
        growth_left = growth_left - 1 if new.any() else 0
        converging += 0 if new.any() else 1
        log.debug("F5 pass %d: RMS update %.4f period, %d samples grown", k, step, int(new.sum()))
        if not new.any() and (step < p.deformation_tolerance_periods or converging >= p.deformation_passes):
            break
        upd = ok | new
        measured |= new
        grown |= new
        pred = pred + fill_nearest(np.where(upd[..., None], res, 0.0), upd)
    return _Warped(pred, res, zs, cohs, bb_ref, measured, grown, k)


def warped_heterodyne(bb_img: tuple[np.ndarray, ...], pred: np.ndarray, own: np.ndarray | None, grid: F.SamplingGrid,
                      ks: F.CarrierPair, covs: tuple[np.ndarray, np.ndarray],
                      ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """F5's heterodyne of the photo's basebands ``bb_img`` against the reference warped by ``pred``.

    Returns the heterodynes and that reference's basebands.
    """
    bb_ref = basebands(F.compute_spectrum(warped_reference(pred, own, grid, ks)), ks, covs, grid)
    return tuple(b * np.conj(r) for b, r in zip(bb_img, bb_ref)), bb_ref


def rms_update_periods(res: np.ndarray, where: np.ndarray, ks: F.CarrierPair, period: float) -> float:
    """RMS displacement of the residual phases ``res`` (h, w, 2) over ``where``, carrier periods (0 where empty)."""
    if not where.any():
        return 0.0
    # converted on the whole grid, then selected: an (n, 2) @ (2, 2) product goes through BLAS, several times
    # slower than the stacked (h, w, 2) one, with the same values
    return float(np.sqrt(np.mean(np.sum(phase_to_displacement_px(res, ks)[where] ** 2, axis=-1)))) / period


def low_passed(phase: np.ndarray, measured: np.ndarray, grid: F.SamplingGrid, sigma_px: float) -> np.ndarray:
    """``phase`` (h, w, 2) smoothed by a Gaussian of ``sigma_px`` over the measured samples (normalised), filled beyond them."""
    w = measured.astype(float)
    out = np.stack([masked_gaussian(phase[..., i], w, sigma_px**2 * np.eye(2), grid.step, order=0) for i in range(2)],
                   axis=-1)
    return fill_nearest(np.where(measured[..., None], out, 0.0), measured)


_OwnPhasors = tuple[list[np.ndarray], list[np.ndarray]]


def own_phasors(refm: ReferenceModel | None, src: F.SamplingGrid, grid: F.SamplingGrid,
                ks: F.CarrierPair) -> _OwnPhasors | None:
    """The reference's own phasors: ``(on src, at grid's samples)``, each per carrier; None in the Direct Method."""
    if refm is None:
        return None
    unit = [b / np.maximum(np.abs(b), 1e-30) for b in refm.baseband]
    return unit, [to_frame(o, src, np.zeros(grid.shape + (2,), np.float32), grid, ks) for o in unit]


def own_shift(own: _OwnPhasors | None, src: F.SamplingGrid, q: np.ndarray, grid: F.SamplingGrid,
              ks: F.CarrierPair) -> np.ndarray | float:
    """``own(r - u(r)) - own(r)`` (rad, (h, w, 2) on ``grid``): the reference's own phase across the displacement.

    ``own``: :func:`own_phasors` (its phasors on ``src`` and at ``grid``'s samples); ``q = -2 pi F u``
    (rad), the displacement in phase units. The Comparative phase at ``r`` is the photo's there less the
    reference's there, ``own(r - u) - own(r) - 2 pi F u``: it differs from ``q`` wherever the
    reference's own grid is not uniform (its perspective, its lens), by this. 0 in the Direct Method.
    """
    if own is None:
        return 0.0
    return _own_shift_at(own, _frame_maps(src, phase_to_displacement_px(q, ks).astype(np.float32), grid))


def _own_shift_at(own: _OwnPhasors | None, maps: _Maps) -> np.ndarray | float:
    """:func:`own_shift` through the maps of the displacement (:func:`_frame_maps`, from ``own``'s grid)."""
    if own is None:
        return 0.0
    unit, here = own
    return np.stack([np.angle(_read(o, maps) * np.conj(h)) for o, h in zip(unit, here)], axis=-1)


# Fixed-point iterations from the Comparative phase to the displacement: each multiplies the error by
# the reference's relative frequency deviation across the displacement (a few percent).
_OWN_ITERATIONS = 4


def photo_passes(img: np.ndarray, refm: ReferenceModel | None, demod: Demodulation, bb_img: tuple[np.ndarray, ...],
                 own: np.ndarray | None, pred: np.ndarray, measured: np.ndarray, grid: F.SamplingGrid,
                 p: AnalyzerParams, max_passes: int, img_mods: Callable[[], tuple[np.ndarray, ...]],
                 ) -> tuple[np.ndarray, int, list[np.ndarray]]:
    """F5's last passes: the photo deformed back to the reference's frame (:func:`deformed_photo`).

    ``pred``: the warped reference's field, low-passed (:func:`low_passed`). Each pass
    demodulates the deformed photo on F5's grid with the same filters, against the reference's own
    basebands brought to that grid (Comparative; the flat carrier in the Direct Method), and reads
    the residual at the photo's samples (:func:`to_frame`). The deformation needs the displacement
    itself, ``q = -2 pi F u``; the Comparative phase ``pred`` carries the reference's own phase
    across it as well (:func:`own_shift`), so ``q`` is solved from ``pred`` first and ``pred``
    rebuilt from ``q`` at the end. Near where the deformed photo draws from off the photo, and
    near the photo's samples that show what the reference does not (:func:`off_frame`), the
    residual is the warped reference's (:func:`_edge_residual`).

    Returns ``(phase, passes, mods)``: the output phase ``pred + residual`` (rad, (h, w, 2) on
    ``grid``, the Comparative phase as F4 unwraps it), the passes run (up to ``max_passes``,
    :meth:`~glassdist.analyzer.params.AnalyzerParams.photo_passes_for`, fewer once the RMS update is
    below ``deformation_tolerance_periods``) and the modulation the last pass measured at, per
    carrier, read at the photo's samples: the deformed photo's (its grid at the carrier, so the
    bandpass's whole amplitude), the photo's own (``img_mods()``) where the residual is the warped
    reference's. The phase noise goes as one over it, not over the photo's at its local frequency.
    """
    ks = demod.carriers
    covs = demod.covariances
    period = max(ks.k1.period_px, ks.k2.period_px)
    reach_px = 3.0 * float(np.sqrt(np.max(np.linalg.eigvalsh(demodulation_blur_px2(ks, covs, p)))))
    own_ph = own_phasors(refm, demod.grid, grid, ks)
    q = pred
    for _ in range(_OWN_ITERATIONS if refm is not None else 0):
        q = pred - own_shift(own_ph, demod.grid, q, grid, ks)
    ref_bb = None if refm is None else [to_grid(r, demod.grid, grid) for r in refm.baseband]
    spline = photo_spline(img)

    def smoothed(zs: tuple[np.ndarray, ...]) -> list[np.ndarray]:  # F3 on the heterodynes (no coherence needed)
        return [F.smooth_complex(z, p.smoothing_periods * c.period_px, grid) for z, c in zip(zs, (ks.k1, ks.k2))]

    fill = _filler(measured)  # the same samples every pass
    n = 0
    while True:
        n += 1
        u = phase_to_displacement_px(q, ks)  # one displacement, read by every step of the pass
        u32 = u.astype(np.float32)
        deformed, outside = _deformed(spline, u32, grid)
        bb = basebands(F.compute_spectrum(deformed), ks, covs, grid)
        del deformed
        zs = smoothed(bb if ref_bb is None else tuple(b * np.conj(r) for b, r in zip(bb, ref_bb)))
        maps = _frame_maps(grid, u32, grid)
        res = np.stack([np.angle(_read(z, maps)) for z in zs], axis=-1)
        share: np.ndarray | float = 1.0
        off = _off_frame(u, grid)
        if outside.any() or off.any():
            share = _edge_share(outside, off, maps, grid, reach_px)
            own_maps = maps if demod.grid == grid or own_ph is None else _frame_maps(demod.grid, u32, grid)
            het, _ = warped_heterodyne(bb_img, q + _own_shift_at(own_ph, own_maps), own, grid, ks, covs)
            res = share * res + (1.0 - share) * np.stack([np.angle(z) for z in smoothed(het)], axis=-1)
        step = rms_update_periods(res, measured, ks, period)
        log.debug("F5 photo pass %d: RMS update %.4f period", n, step)
        if n >= max_passes or step < p.deformation_tolerance_periods:
            mods = [_read(modulation(b, c.period_px, grid, p), maps) for b, c in zip(bb, (ks.k1, ks.k2))]
            if np.ndim(share):  # blended with the photo's own where the residual is the warped reference's
                w_ = np.squeeze(share, -1)
                mods = [w_ * m_ + (1.0 - w_) * m0 for m_, m0 in zip(mods, img_mods())]
            mods = [m_.astype(np.float32) for m_ in mods]
            q = q + res
            return q + own_shift(own_ph, demod.grid, q, grid, ks), n, mods
        q = q + fill(np.where(measured[..., None], res, 0.0))


def _edge_share(outside: np.ndarray, off: np.ndarray, maps: _Maps, grid: F.SamplingGrid, reach_px: float) -> np.ndarray:
    """The deformed photo's share of a photo pass's residual, (h, w, 1) in [0, 1].

    None within ``reach_px`` (three of Block F's kernel widths) of where it draws from off the photo
    (reference frame, ``outside``) or of where the photo shows what the reference does not (photo
    frame, ``off``), all beyond twice that. Elsewhere the residual is the warped reference's: both
    measure ``G (true - B pred)``, so every sample's transfer counts the same passes (without it,
    each pass added the edge's residual there).
    """
    def ramp(mask: np.ndarray) -> np.ndarray:
        return np.clip(ndimage.distance_transform_edt(~mask, sampling=grid.step) / reach_px - 1.0, 0.0, 1.0)

    share = np.ones(grid.shape, np.float32)
    if outside.any():
        share = _read(ramp(outside).astype(np.float32), maps)
    if off.any():
        share = np.minimum(share, ramp(off).astype(np.float32))
    return share[..., None]
