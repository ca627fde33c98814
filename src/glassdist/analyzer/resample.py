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

__all__ = ["grid_fill_indices", "image_grid_valid", "bspline_upsample", "bspline_eval", "upsample_field",
           "upsample_field_rows", "upsample_labels", "axis_deviator", "axis_of_deviator", "upsample_axis", "upsample_axis_rows"]


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


def _bspline_weights(n: int, t: np.ndarray):
    """Sparse matrix (len(t), n) of cubic B-spline basis weights at coarse coordinates ``t``.

    Coefficients beyond the ends are the end coefficients replicated (as the ``nearest``
    prefilter assumes).
    """
    from scipy import sparse

    t = np.asarray(t, float)
    base = np.floor(t).astype(np.int64)
    u = t - base
    w = np.stack([(1 - u) ** 3 / 6, (3 * u**3 - 6 * u**2 + 4) / 6, (-3 * u**3 + 3 * u**2 + 3 * u + 1) / 6, u**3 / 6], 1)
    cols = np.clip(base[:, None] + np.arange(-1, 3)[None, :], 0, n - 1)
    rows = np.repeat(np.arange(t.size), 4)
    return sparse.csr_matrix((w.ravel().astype(np.float32), (rows, cols.ravel())), shape=(t.size, n))


def bspline_eval(f: np.ndarray, ty: np.ndarray | None, tx: np.ndarray | None) -> np.ndarray:
    """Cubic B-spline interpolation of a plane ``f`` (h, w) at coarse coordinates ``ty`` (rows) x ``tx`` (columns).

    Separable and exact (Unser 1999): prefilter, then the 4-tap basis along each axis, as
    sparse products; ``None`` leaves that axis as it is. Its mean transfer,
    ``sinc(S nu)^4 / ((2 + cos 2 pi S nu) / 3)`` per axis (S the sample step), is part of
    the instrument transfer Block A divides out (:mod:`glassdist.analyzer.transfer`).
    """
    c = _prefiltered_along_x(f, ty, tx)
    if ty is not None:
        c = np.asarray(_bspline_weights(c.shape[0], ty) @ c, np.float32)
    return np.ascontiguousarray(c)


def _prefiltered_along_x(f: np.ndarray, ty, tx) -> np.ndarray:
    """:func:`bspline_eval` up to its last product: the prefilter (along each axis evaluated), then x."""
    c = np.ascontiguousarray(f, np.float32)
    for axis, t in ((0, ty), (1, tx)):
        if t is not None:
            c = ndimage.spline_filter1d(c, order=3, axis=axis, mode="nearest", output=np.float32)
    if tx is not None:  # C order: the y product of every block of rows reads it as it is
        c = np.ascontiguousarray((_bspline_weights(c.shape[1], tx) @ c.T).T, np.float32)
    return c


def bspline_upsample(f: np.ndarray, k: int, axis: int) -> np.ndarray:
    """Cubic B-spline interpolation of ``f`` at ``k`` times its density along ``axis``.

    Sample positions follow the area convention of :class:`~glassdist.analyzer.fourier.SamplingGrid`:
    fine sample ``j k + r`` sits at coarse coordinate ``j + (r + 1/2)/k - 1/2``.
    """
    t = (np.arange(f.shape[axis] * k) + 0.5) / k - 0.5
    return bspline_eval(f, t if axis == 0 else None, t if axis == 1 else None)


def _filled(f: np.ndarray, idx) -> np.ndarray:
    """``f`` as float32 with each invalid sample replaced by its nearest valid one (``idx``)."""
    f = np.ascontiguousarray(f, np.float32)  # (h, w) or (h, w, 2)
    return f[idx[0], idx[1]] if idx is not None else f


def _planes(a: np.ndarray) -> list:
    return [a] if a.ndim == 2 else [a[..., c] for c in range(a.shape[2])]


def _mask_invalid(up: np.ndarray, invalid: np.ndarray) -> np.ndarray:
    # One plane at a time: a broadcast mask over the channel axis is ~20x slower.
    for plane in _planes(up):
        np.copyto(plane, np.float32(np.nan), where=invalid)
    return up


def upsample_field(f: np.ndarray, idx, grid: F.SamplingGrid, invalid: np.ndarray) -> np.ndarray:
    """A field of the analysis grid at every image pixel: cubic B-spline interpolation, NaN where ``invalid``.

    Invalid samples are first filled with their nearest valid value (``idx``), so that
    the spline never mixes NaN into valid pixels near a border.
    """
    H, W = grid.full_shape
    f = _filled(f, idx)
    if grid.is_full:
        up = f.copy()
    else:
        sy, sx = grid.step
        oy, ox = grid.offset
        ty, tx = (np.arange(H) - oy) / sy, (np.arange(W) - ox) / sx
        out = [bspline_eval(p_, ty, tx) for p_ in _planes(f)]
        up = out[0] if f.ndim == 2 else np.stack(out, axis=-1)
    return _mask_invalid(up, invalid)


def upsample_field_rows(f: np.ndarray, idx, grid: F.SamplingGrid, invalid: np.ndarray, block_rows: int):
    """:func:`upsample_field` one block of image rows at a time: yields ``(rows, block)``.

    ``rows`` is a ``slice`` of image rows and ``block`` the field on them, bit-identical to
    ``upsample_field(...)[rows]``: the spline's prefilter and its interpolation along x
    are done once on the coarse rows (``h x W`` values), then each block of image rows
    takes its 4-tap rows of the y interpolation. Peak memory is one block, whatever the
    image's size.
    """
    H, W = grid.full_shape
    f = _filled(f, idx)
    block_rows = max(1, int(block_rows))
    if grid.is_full:
        for r0 in range(0, H, block_rows):
            rows = slice(r0, min(H, r0 + block_rows))
            yield rows, _mask_invalid(f[rows].copy(), invalid[rows])
        return
    sy, sx = grid.step
    oy, ox = grid.offset
    ty, tx = (np.arange(H) - oy) / sy, (np.arange(W) - ox) / sx
    by = _bspline_weights(f.shape[0], ty)
    along_x = [_prefiltered_along_x(p_, ty, tx) for p_ in _planes(f)]
    for r0 in range(0, H, block_rows):
        rows = slice(r0, min(H, r0 + block_rows))
        b = by[rows]
        out = [np.ascontiguousarray(np.asarray(b @ c, np.float32)) for c in along_x]
        yield rows, _mask_invalid(out[0] if f.ndim == 2 else np.stack(out, axis=-1), invalid[rows])


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


def axis_deviator(axis_deg: np.ndarray, phi_shear: np.ndarray | None = None) -> np.ndarray:
    """``phi_shear * (cos 2a, sin 2a)``, (..., 2): the astigmatism as a field that can be interpolated.

    An axis is an angle modulo 180 deg, and it turns by 90 deg where the shear changes sign;
    interpolated directly, across the wrap or such a turn, it takes angles the field never
    has. Without ``phi_shear`` the doubled angle's unit vector.
    """
    # from the float32 values a stored result holds, so a field read back refines exactly as the analysis did
    a = np.radians(np.asarray(axis_deg, np.float32).astype(np.float64))
    s = 1.0 if phi_shear is None else np.asarray(phi_shear, np.float32).astype(np.float64)
    return np.stack([s * np.cos(2 * a), s * np.sin(2 * a)], axis=-1).astype(np.float32)


def axis_of_deviator(deviator: np.ndarray) -> np.ndarray:
    """Axis (deg, in (-90, 90], float32; NaN where the deviator is NaN) of :func:`axis_deviator`'s field."""
    axis = (0.5 * np.degrees(np.arctan2(deviator[..., 1], deviator[..., 0]))).astype(np.float32)
    return np.where(axis <= -90.0, axis + np.float32(180.0), axis)


def upsample_axis(axis_deg: np.ndarray, phi_shear, idx, grid: F.SamplingGrid, invalid: np.ndarray) -> np.ndarray:
    """:func:`upsample_field` for an axis field: its deviator (:func:`axis_deviator`) interpolated, then its angle."""
    return axis_of_deviator(upsample_field(axis_deviator(axis_deg, phi_shear), idx, grid, invalid))


def upsample_axis_rows(axis_deg: np.ndarray, phi_shear, idx, grid: F.SamplingGrid, invalid: np.ndarray, block_rows: int):
    """:func:`upsample_axis` one block of image rows at a time (as :func:`upsample_field_rows`): yields ``(rows, block)``."""
    for rows, block in upsample_field_rows(axis_deviator(axis_deg, phi_shear), idx, grid, invalid, block_rows):
        yield rows, axis_of_deviator(block)
