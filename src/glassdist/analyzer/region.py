"""Block F4's valid region: where the demodulated phase is trusted (paper §2.2, F4).

A sample of the demodulation grid is valid where both carriers are modulated (globally and
against their local level), the F3-smoothed signal is phase-coherent, the user mask allows
it, it lies far enough from excluded areas and from the image edges (the periodic FFT mixes
the opposite edge in), and no phase residue sits next to it. Connected parts of that region
are labelled: a frame or mullion splits the pane into regions unwrapped, detrended and
smoothed independently.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from . import fourier as F
from .params import AnalyzerParams
from .unwrap import label_regions, residues

__all__ = ["Region", "valid_region", "erode", "downsample_mask"]


@dataclass(frozen=True)
class Region:
    """The valid region on the demodulation grid.

    Attributes
    ----------
    valid : ndarray of bool (h, w)
        Trusted samples (``labels > 0``).
    labels : ndarray of int (h, w)
        Connected parts, 1..n by decreasing size; 0 outside.
    n : int
        Number of parts kept (those of at least ``min_region_fraction`` of the grid).
    """

    valid: np.ndarray
    labels: np.ndarray
    n: int


def downsample_mask(mask: np.ndarray, grid: F.SamplingGrid) -> np.ndarray:
    import cv2

    if grid.is_full:
        return mask.astype(bool)
    h, w = grid.shape
    return cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.999


def erode(valid: np.ndarray, margin_px: float, grid: F.SamplingGrid, edge_margin_px: float | None = None) -> np.ndarray:
    """Samples farther than ``margin_px`` (image px) from every invalid sample, and than
    ``edge_margin_px`` (default ``margin_px``) from the image edges."""
    import cv2

    sy, sx = grid.step
    edge = margin_px if edge_margin_px is None else edge_margin_px
    # Sample j sits at j*s + (s-1)/2 px; its distance to the edge is that plus 1/2 px.
    yv, xv = (np.arange(n) * st + st / 2.0 for n, st in zip(grid.shape, grid.step))
    H, W = grid.full_shape
    dy, dx = np.minimum(yv, H - yv), np.minimum(xv, W - xv)
    out = valid.copy()
    ry, rx = int(margin_px / sy), int(margin_px / sx)
    if margin_px > 0 and (ry or rx):
        # Erosion by the disc of radius margin_px: a sample stays when no excluded sample lies
        # within margin_px of it (its distance transform exceeds it). Samples excluded within
        # margin_px of the image edge are the edge's own (the periodic transform mixes the
        # opposite edge in there): the edge margin below handles them, they are not eroded from.
        band = (dy <= margin_px)[:, None] | (dx <= margin_px)[None, :]
        j, i = np.mgrid[-ry : ry + 1, -rx : rx + 1]
        disc = ((j * sy) ** 2 + (i * sx) ** 2 <= margin_px**2).astype(np.uint8)
        seed = (valid | band).view(np.uint8)
        out &= cv2.erode(seed, disc, borderType=cv2.BORDER_CONSTANT, borderValue=1).view(bool)
    out &= (dy > edge)[:, None]
    out &= (dx > edge)[None, :]
    return out


def valid_region(phases, coherences, mods, carriers, grid, p: AnalyzerParams, user_mask, warn: list[str]) -> Region:
    """Valid region on the sampling grid: modulation, coherence, user mask, border, residues.

    ``phases``: the wrapped phases ``angle(z)`` of the F3-smoothed signals.
    """
    import cv2

    valid = np.ones(grid.shape, bool)
    period = max(carriers.k1.period_px, carriers.k2.period_px)
    sy, sx = grid.step
    size = (max(3, int(4 * period / sy) | 1), max(3, int(4 * period / sx) | 1))
    box = np.ones(size, np.uint8)
    for m in mods:
        ref = np.percentile(m[::2, ::2], 75)
        valid &= m > p.modulation_threshold * ref
        # Against the local level (max over a few periods, smoothed): slow lighting changes pass,
        # a narrow opaque band (a frame or mullion blurred by the bandpass) does not.
        local = F.gaussian_blur(cv2.dilate(np.ascontiguousarray(m, np.float32), box, borderType=cv2.BORDER_REPLICATE),
                                (2 * period / sy, 2 * period / sx))
        valid &= m > p.local_modulation_threshold * local
    for coh in coherences:
        valid &= coh > p.coherence_threshold
    if user_mask is not None:
        valid &= downsample_mask(user_mask, grid)
    valid = erode(valid, p.border_periods * period, grid, p.edge_margin_periods * period)
    bad = np.zeros(grid.shape, bool)
    for ph in phases:
        bad |= residues(ph)
    if bad.any():
        bad = ndimage.binary_dilation(bad, iterations=1)
        frac = float((bad & valid).sum()) / max(valid.sum(), 1)
        if frac > 0.01:
            warn.append(f"{100 * frac:.1f}% of the region has phase residues (noise, occlusion or too strong distortion) and was excluded")
    valid &= ~bad
    min_size = int(p.min_region_fraction * valid.size)
    labels, n = label_regions(valid, max(min_size, 16))
    return Region(labels > 0, labels, n)
