"""Bringing analysis-grid fields to the image's pixel grid.

Block A runs on a coarse grid (the demodulated signals are band-limited); a field is brought
to the input's pixel grid only when asked for: invalid coarse samples are first filled with
their nearest valid value (so no NaN is mixed into valid pixels near a border), then a cubic
B-spline refines the grid to a ~3 px step and a bilinear resize reaches the pixels.

References
----------
Unser (1999), IEEE Signal Processing Magazine 16(6): splines, a perfect fit for signal and
image processing.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from . import fourier as F

__all__ = ["grid_fill_indices", "image_grid_valid", "bspline_upsample", "bspline_refine", "upsample_field", "upsample_labels"]


def grid_fill_indices(valid: np.ndarray):
    """Index of the nearest valid sample of each coarse sample (``(2, h, w)``), None when all or none are valid."""
    if valid.all() or not valid.any():
        return None
    return ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)


def image_grid_valid(valid: np.ndarray, grid: F.SamplingGrid, user_mask, fine_valid=None):
    """Valid region on the image grid, and the nearest-valid fill indices of the coarse fields.

    Invalid coarse samples are later filled with their nearest valid value before the
    upsampling (:func:`upsample_field`), so it never mixes NaN into valid pixels near a border.
    """
    import cv2

    H, W = grid.full_shape
    idx = grid_fill_indices(valid)
    v = valid
    if fine_valid is not None:  # keep the border at the finer grid's resolution
        m = fine_valid.shape[0] // valid.shape[0]
        v = fine_valid & np.repeat(np.repeat(valid, m, axis=0), m, axis=1)
    if v.shape == (H, W):
        valid_full = v.copy()
    else:
        valid_full = cv2.resize(v.view(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST).view(bool)
    if user_mask is not None:
        valid_full &= user_mask
    return valid_full, idx


_FINAL_STEP_PX = 3.0  # step of the grid the last, bilinear upsampling starts from


def bspline_upsample(f: np.ndarray, k: int, axis: int) -> np.ndarray:
    """Cubic B-spline interpolation of ``f`` at ``k`` times its density along ``axis``.

    Sample positions follow the area convention of :class:`~glassdist.analyzer.fourier.SamplingGrid`:
    fine sample ``j k + r`` sits at coarse coordinate ``j + (r + 1/2)/k - 1/2``. Each of the
    ``k`` phases is a fixed 4-tap combination of the spline coefficients (Unser 1999).
    """
    c = np.moveaxis(ndimage.spline_filter1d(f, order=3, axis=axis, mode="nearest", output=np.float32), axis, 0)
    n = c.shape[0]
    cp = np.concatenate([c[:1], c[:1], c, c[-1:], c[-1:]])  # coefficients beyond the edge: replicated
    out = np.empty((n * k,) + c.shape[1:], f.dtype)
    for r in range(k):
        t = (r + 0.5) / k - 0.5
        base = int(np.floor(t))
        u = t - base
        w = ((1 - u) ** 3 / 6, (3 * u**3 - 6 * u**2 + 4) / 6, (-3 * u**3 + 3 * u**2 + 3 * u + 1) / 6, u**3 / 6)
        lo = 2 + base - 1
        acc = out[r::k]
        np.multiply(cp[lo : lo + n], np.float32(w[0]), out=acc)
        for i in range(1, 4):
            acc += np.float32(w[i]) * cp[lo + i : lo + i + n]
    return np.moveaxis(out, 0, axis)


def bspline_refine(f: np.ndarray, k: tuple[int, int]) -> np.ndarray:
    """``f`` (h, w[, c]) interpolated at ``k = (ky, kx)`` times its density, one plane at a time."""
    if k[0] <= 1 and k[1] <= 1:
        return f
    planes = [f] if f.ndim == 2 else [np.ascontiguousarray(f[..., c]) for c in range(f.shape[2])]
    out = []
    for p_ in planes:
        for axis in (0, 1):
            if k[axis] > 1:
                p_ = bspline_upsample(p_, k[axis], axis)
        out.append(p_)
    return np.ascontiguousarray(out[0]) if f.ndim == 2 else np.stack(out, axis=-1)


def upsample_field(f: np.ndarray, idx, grid: F.SamplingGrid, invalid: np.ndarray) -> np.ndarray:
    import cv2

    H, W = grid.full_shape
    f = np.ascontiguousarray(f, np.float32)  # (h, w) or (h, w, 2)
    if idx is not None:
        f = f[idx[0], idx[1]]
    if grid.is_full:
        up = f.copy()
    else:
        # Cubic B-spline to an intermediate grid of ~3 px step, then bilinear: the bilinear
        # error (h^2/8)|f''| is ~1% of a wave's amplitude at a 13 px step, ~0.05% at 3 px,
        # and the spline stage works on a grid ~10x smaller than the image.
        f = bspline_refine(f, tuple(int(st // _FINAL_STEP_PX) for st in grid.step))
        # Into an array numpy allocated (large ones get huge pages): several times faster
        # than letting OpenCV allocate 0.1-0.2 GB of fresh pages.
        up = np.empty((H, W) + f.shape[2:], np.float32)
        cv2.resize(f, (W, H), dst=up, interpolation=cv2.INTER_LINEAR)
    # One plane at a time: a broadcast mask over the channel axis is ~20x slower.
    for plane in [up] if up.ndim == 2 else [up[..., c] for c in range(up.shape[2])]:
        np.copyto(plane, np.float32(np.nan), where=invalid)
    return up


def upsample_labels(labels: np.ndarray, grid: F.SamplingGrid) -> np.ndarray:
    """Integer labels (h, w) on ``grid`` brought to the pixel grid by nearest sample (no mixing)."""
    import cv2

    H, W = grid.full_shape
    a = np.ascontiguousarray(labels)
    if a.shape == (H, W):
        return a.copy()
    dtype = a.dtype
    src = a.astype(np.int16 if a.dtype.itemsize > 1 or a.dtype.kind == "b" else np.uint8)
    return cv2.resize(src, (W, H), interpolation=cv2.INTER_NEAREST).astype(dtype, copy=False)
