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

import numpy as np
from scipy import ndimage

from . import fourier as F

__all__ = [
    "deformation_grid", "deformed_photo", "displacement_to_phase", "fill_nearest", "grow", "off_frame",
    "phase_to_displacement_px", "photo_spline", "to_frame", "to_grid", "warped_reference",
]

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
    if valid.all():
        return a
    if not valid.any():
        return np.zeros_like(a)
    idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return a[idx[0], idx[1]]


def deformation_grid(grid: F.SamplingGrid, max_deviation: float, period_px: float, decimation) -> F.SamplingGrid:
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

    def up(a):
        return cv2.resize(np.ascontiguousarray(a, np.float32), (W, H), interpolation=cv2.INTER_LINEAR)

    for i, c in enumerate((carriers.k1, carriers.k2)):
        ph = up(pred[..., i])
        ph += np.float32(2 * np.pi * c.fx) * x
        ph += np.float32(2 * np.pi * c.fy) * y
        if own is None:
            out += np.cos(ph)
            continue
        u = own[..., i] / np.maximum(np.abs(own[..., i]), 1e-30)
        re, im = up(u.real), up(u.imag)
        norm = np.sqrt(re * re + im * im)
        np.maximum(norm, np.float32(1e-6), out=norm)
        out += (np.cos(ph) * re - np.sin(ph) * im) / norm
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
    """The photo's cubic B-spline coefficients (float32, mirrored edges) for :func:`deformed_photo`, computed once per analysis."""
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
    import cv2

    u = phase_to_displacement_px(pred, carriers).astype(np.float32)
    w = u
    for _ in range(INVERSE_ITERATIONS):
        mx, my = _grid_maps(grid, w)
        w = np.stack([_remap(u[..., i], mx, my) for i in range(2)], axis=-1)
    H, W = grid.full_shape
    yy, xx = grid.coords()
    tx, ty = xx + w[..., 0], yy + w[..., 1]
    outside = (tx < 0) | (tx > W - 1) | (ty < 0) | (ty > H - 1)
    wx = cv2.resize(np.ascontiguousarray(w[..., 0]), (W, H), interpolation=cv2.INTER_LINEAR)
    wy = cv2.resize(np.ascontiguousarray(w[..., 1]), (W, H), interpolation=cv2.INTER_LINEAR)
    wx += np.arange(W, dtype=np.float32)[None, :]
    wy += np.arange(H, dtype=np.float32)[:, None]
    out = ndimage.map_coordinates(spline, [wy, wx], order=3, mode="mirror", prefilter=False, output=np.float32)
    return out, outside


def off_frame(pred: np.ndarray, grid: F.SamplingGrid, carriers: F.CarrierPair) -> np.ndarray:
    """Samples ``r`` of ``grid`` (photo frame) whose ``r - u(r)`` lies off the image: the backdrop the photo shows there
    lies beyond the reference's view, no sample of the deformed photo draws from it, and :func:`to_frame` reads
    the edge there (``pred`` (h, w, 2), rad, as for :func:`to_frame`)."""
    u = phase_to_displacement_px(pred, carriers)
    H, W = grid.full_shape
    yy, xx = grid.coords()
    sx, sy = xx - u[..., 0], yy - u[..., 1]
    return (sx < 0) | (sx > W - 1) | (sy < 0) | (sy > H - 1)


def to_frame(z: np.ndarray, src: F.SamplingGrid, pred: np.ndarray, grid: F.SamplingGrid, carriers: F.CarrierPair) -> np.ndarray:
    """A signal measured in the reference's frame on ``src`` read at the photo's samples of ``grid``: ``z(r - u(r))``.

    ``z`` (h', w'), real or complex (bilinear; a complex one as its real and imaginary parts,
    so phase wraps do no harm); ``pred`` (h, w, 2), rad, the displacement the photo was deformed by, on ``grid``.
    """
    u = phase_to_displacement_px(pred, carriers).astype(np.float32)
    yy, xx = grid.coords()
    (oy, ox), (sy, sx) = src.offset, src.step
    mx = ((xx[0][None, :] - u[..., 0] - ox) / sx).astype(np.float32)
    my = ((yy[:, 0][:, None] - u[..., 1] - oy) / sy).astype(np.float32)
    if not np.iscomplexobj(z):
        return _remap(z, mx, my)
    return (_remap(z.real, mx, my) + 1j * _remap(z.imag, mx, my)).astype(np.complex64)

