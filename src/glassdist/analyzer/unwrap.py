"""Block F, stage F4: quality map and phase unwrapping.

The unwrapping itself is scikit-image's reliability-sorted (quality-guided)
unwrapper (Herraez et al. 2002); this module decides *where* the wrapped phase
can be trusted and removes the per-region 2 pi ambiguity.

References
----------
Herraez, Burton, Lalor & Gdeisat (2002), Appl. Opt. 41, 7437.
Goldstein, Zebker & Werner (1988), Radio Science 23, 713 (phase residues).
Itoh (1982), Appl. Opt. 21, 2470 (sampling condition). Paper §2.2 F4.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.restoration import unwrap_phase

__all__ = ["wrap", "residues", "unwrap", "label_regions"]


def wrap(phase: np.ndarray) -> np.ndarray:
    """Wrap a phase to [-pi, pi] (the nearest multiple of 2 pi removed; keeps float32 as float32)."""
    return phase - (2 * np.pi) * np.rint(phase * (1 / (2 * np.pi)))


def residues(phase: np.ndarray) -> np.ndarray:
    """Pixels touching a phase residue (a 2x2 loop whose wrapped differences do not sum to 0).

    Parameters
    ----------
    phase : ndarray (h, w)
        Wrapped phase, rad.

    Returns
    -------
    ndarray of bool, (h, w)
        True on the four corners of every residue loop.
    """
    dh = wrap(np.diff(phase, axis=1))  # wrapped differences along rows, (h, w-1)
    dv = wrap(np.diff(phase, axis=0))  # and along columns, (h-1, w)
    # Each 2x2 loop: top edge left -> right, right edge down, bottom edge back, left edge up.
    circ = dh[:-1, :] + dv[:, 1:]
    circ -= dh[1:, :]
    circ -= dv[:, :-1]
    loop = np.abs(circ) > np.pi  # the sum is a multiple of 2 pi: 0 or +-2 pi
    out = np.zeros(phase.shape, bool)
    out[:-1, :-1] |= loop
    out[1:, :-1] |= loop
    out[:-1, 1:] |= loop
    out[1:, 1:] |= loop
    return out


def label_regions(valid: np.ndarray, min_size: int = 1) -> tuple[np.ndarray, int]:
    """4-connected regions of ``valid`` (the unwrapper's neighbourhood); regions smaller than ``min_size`` dropped.

    Returns
    -------
    labels : ndarray of int, 0 = invalid, 1..n = regions by decreasing size
    n : int
    """
    labels, n = ndimage.label(valid)
    if n == 0:
        return labels, 0
    sizes = np.bincount(labels.ravel())[1:]
    order = np.argsort(sizes)[::-1]
    keep = order[sizes[order] >= max(min_size, 1)]
    lut = np.zeros(n + 1, dtype=np.int32)
    lut[keep + 1] = np.arange(1, keep.size + 1)
    return lut[labels], int(keep.size)


_COARSE_UNWRAP_MIN_SAMPLES = 30_000  # the coarse unwrap keeps at least this many samples


def _unwrap_coarse(phase: np.ndarray, valid: np.ndarray, seed: int, k: int) -> np.ndarray | None:
    """Unwrap every k-th sample, then snap each sample to the 2 pi multiple nearest that estimate.

    The demodulated phase is smooth on the scale of the sampling grid (it was
    low-passed at a fraction of the carrier period), so the 2 pi multiples can be
    decided on a k x coarser grid at 1/k^2 of the cost. Returns None when the
    snapped result is not consistent (a neighbour difference beyond pi), in which
    case the caller unwraps at a finer step.
    """
    sub = phase[k // 2 :: k, k // 2 :: k]
    vsub = valid[k // 2 :: k, k // 2 :: k]
    if vsub.sum() < 16:
        return None
    un_c = np.asarray(unwrap_phase(np.ma.masked_array(sub, mask=~vsub), rng=seed).filled(np.nan), dtype=phase.dtype)
    if not vsub.all():
        idx = ndimage.distance_transform_edt(~vsub, return_distances=False, return_indices=True)
        un_c = un_c[idx[0], idx[1]]
    est = np.repeat(np.repeat(un_c, k, axis=0), k, axis=1)
    est = np.pad(est, ((0, max(0, phase.shape[0] - est.shape[0])), (0, max(0, phase.shape[1] - est.shape[1]))), mode="edge")
    est = est[: phase.shape[0], : phase.shape[1]]
    un = phase + 2 * np.pi * np.round((est - phase) / (2 * np.pi))
    un[~valid] = np.nan
    with np.errstate(invalid="ignore"):
        bad = (np.abs(np.diff(un, axis=0)) > np.pi).any() or (np.abs(np.diff(un, axis=1)) > np.pi).any()
    return None if bad else un


def unwrap(phase: np.ndarray, valid: np.ndarray, labels: np.ndarray, n_regions: int, *, seed: int = 0) -> np.ndarray:
    """Quality-guided unwrapping of a wrapped phase inside ``valid``.

    Each connected region is unwrapped independently and its free multiple of
    2 pi chosen so that its median lies in (-pi, pi] (the smallest displacement
    consistent with the data). NaN outside ``valid``.

    Parameters
    ----------
    phase : ndarray (h, w)
        Wrapped phase, rad.
    valid, labels, n_regions
        Trusted pixels and their regions (:func:`label_regions`).
    seed : int
        Seed of the unwrapper's tie-breaking generator (results are reproducible).
    """
    out = np.full(phase.shape, np.nan, dtype=np.result_type(phase.dtype, np.float32))
    if n_regions == 0:
        return out
    un = None
    # Coarsest first; each falls back to the next when inconsistent. A consistent snapped
    # result is the same whatever k, so the step changes the cost, not the answer.
    for k in (8, 4, 2):
        if un is None and phase.size >= _COARSE_UNWRAP_MIN_SAMPLES * k * k:
            un = _unwrap_coarse(phase, valid, seed, k)
    if un is None:
        masked = np.ma.masked_array(phase, mask=~valid)
        un = np.asarray(unwrap_phase(masked, rng=seed).filled(np.nan), dtype=out.dtype)
    for r in range(1, n_regions + 1):
        sel = labels == r
        if not sel.any():
            continue
        med = np.median(un[sel])
        un[sel] -= 2 * np.pi * np.round(med / (2 * np.pi))
    out[valid] = un[valid]
    return out
