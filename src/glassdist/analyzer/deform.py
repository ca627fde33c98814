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
import scipy.fft as sfft
from scipy import ndimage

from . import fourier as F

__all__ = ["phase_to_displacement_px", "displacement_to_phase", "fill_nearest", "warped_reference"]


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


def warped_reference(pred: np.ndarray, own: np.ndarray | None, grid: F.SamplingGrid, carriers: F.CarrierPair) -> np.ndarray:
    """The reference grid warped by the current displacement, as its two carriers (float32, full resolution).

    ``sum_i cos(2 pi f_i . r + pred_i(r) + own_i(r))``: ``pred`` (h, w, 2) on ``grid`` (rad,
    continuous: the prediction) and ``own`` (h, w, 2) complex, the reference photo's own
    baseband ``exp(i own_i)`` (None: the flat carrier of the Direct Method), both brought to
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
