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
from skimage.draw import line
from skimage.restoration import unwrap_phase

__all__ = ["wrap", "residues", "branch_cuts", "unwrap", "label_regions"]


def wrap(phase: np.ndarray) -> np.ndarray:
    """Wrap a phase to [-pi, pi] (the nearest multiple of 2 pi removed; keeps float32 as float32)."""
    return phase - (2 * np.pi) * np.rint(phase * (1 / (2 * np.pi)))


def _charges(phase: np.ndarray) -> np.ndarray:
    """Signed residue charge of every 2x2 loop of a wrapped phase, int8 (h-1, w-1): the loop's circulation / 2 pi."""
    dh = wrap(np.diff(phase, axis=1))  # wrapped differences along rows, (h, w-1)
    dv = wrap(np.diff(phase, axis=0))  # and along columns, (h-1, w)
    # Each 2x2 loop: top edge left -> right, right edge down, bottom edge back, left edge up.
    circ = dh[:-1, :] + dv[:, 1:]
    circ -= dh[1:, :]
    circ -= dv[:, :-1]
    return np.rint(circ * (1 / (2 * np.pi))).astype(np.int8)  # a multiple of 2 pi: 0, +-1, +-2 turns


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
    loop = _charges(phase) != 0
    out = np.zeros(phase.shape, bool)
    out[:-1, :-1] |= loop
    out[1:, :-1] |= loop
    out[:-1, 1:] |= loop
    out[1:, 1:] |= loop
    return out


#: Above this many charged holes each is cut straight to the border's excluded areas (:func:`branch_cuts`).
MAX_PAIRED_HOLES = 64


def branch_cuts(phases, valid: np.ndarray) -> np.ndarray:
    """Samples to remove from ``valid`` so that no loop inside it encloses a net phase residue.

    A hole in the region (a connected area of excluded samples, 8-connected: the unwrapper's
    4-connected paths cannot pass between diagonal neighbours) around which a wrapped phase
    winds by a whole turn holds a net residue charge: the sum of the charges of the 2x2 loops
    that touch it (discrete Stokes: the circulation along any loop of valid samples around it).
    Where the phase turned by more than half a turn between samples there (a steep flank at the
    edge of what the bandpass follows), it did so at the hole's rim; the unwrapper, going round
    the hole one way or the other, then puts a whole period on one side of a seam it chooses
    itself, anywhere in the region. Each charged hole is joined by a straight cut (Goldstein,
    Zebker & Werner 1988, here between holes instead of single residues) to the nearest other
    charged hole or to an excluded area that reaches the grid's border, until every hole is
    neutral on every phase: the seam then lies on the shortest cut, and the region around it is
    unwrapped without a whole-period jump. Above :data:`MAX_PAIRED_HOLES` charged holes each is
    cut to the border's excluded areas instead, all at once (bounded cost).

    Parameters
    ----------
    phases : sequence of ndarray (h, w)
        Wrapped phases, rad (each carrier's; none: no cut).
    valid : ndarray of bool (h, w)
        The region, residue samples already removed (every loop of four valid samples closes).

    Returns
    -------
    ndarray of bool (h, w)
        The cut samples (valid ones only; empty when no hole is charged).
    """
    h, w = valid.shape
    cut = np.zeros_like(valid)
    if len(phases) == 0 or valid.all() or not valid.any() or h < 2 or w < 2:
        return cut
    holes, n = ndimage.label(~valid, structure=np.ones((3, 3), bool))
    # each 2x2 loop with a charge has an excluded corner; all its excluded corners are 8-connected
    corner = np.maximum.reduce([holes[:-1, :-1], holes[1:, :-1], holes[:-1, 1:], holes[1:, 1:]])
    q = np.stack([np.bincount(corner.ravel(), weights=_charges(ph).ravel(), minlength=n + 1) for ph in phases], -1)
    q = np.rint(q).astype(np.int64)
    ground = np.zeros(n + 1, bool)
    ground[np.unique(np.concatenate([holes[0], holes[-1], holes[:, 0], holes[:, -1]]))] = True
    ground[0] = False
    q[ground] = 0
    # merged holes: each label's representative (charge and ground kept on it) and its bounding box, so
    # that a cut costs the neighbourhood it searches, not the whole grid
    root = np.arange(n + 1)
    box = np.zeros((n + 1, 4), np.int64)
    box[1:] = [(sl[0].start, sl[0].stop, sl[1].start, sl[1].stop) for sl in ndimage.find_objects(holes)]
    charged = np.flatnonzero(np.any(q[1:] != 0, axis=1)) + 1
    if charged.size > MAX_PAIRED_HOLES:
        return _cut_to_ground(holes, ground, charged, valid)
    while True:
        charged = np.flatnonzero(np.any(q[1:] != 0, axis=1)) + 1
        if charged.size == 0:
            return cut
        k = int(charged[0])
        live = ground | np.any(q != 0, axis=1)  # what a charged hole may discharge into
        live[[0, k]] = False
        if live[root[1:]].any():
            (y0, x0), (y1, x1) = _nearest_target(holes, root, live, k, box[k], r=8)
        else:  # nothing to discharge it into: the region around it is cut to the nearest image edge
            (y0, x0), (y1, x1) = _nearest_edge(holes, root, k, box[k])
        rr, cc = line(y0, x0, y1, x1)
        other = int(root[holes[y1, x1]]) if holes[y1, x1] > 0 else 0
        on = valid[rr, cc]
        cut[rr[on], cc[on]] = True
        # the cut joins the two holes into one: the merged charge is the sum (ground absorbs it)
        holes[rr[on], cc[on]] = k
        box[k] = _union(box[k], (rr.min(), rr.max() + 1, cc.min(), cc.max() + 1))
        if other > 0:
            root[root == other] = k
            box[k] = _union(box[k], box[other])
        if other == 0 or ground[other]:  # the image edge or an area at it
            ground[k] = True
            q[k] = 0
        else:
            q[k] += q[other]
        q[other] = 0


def _union(a, b) -> tuple:
    """The bounding box ``(y0, y1, x0, x1)`` (ends exclusive) of two boxes."""
    return min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])


def _cut_to_ground(holes, ground, charged, valid):
    """Each hole of ``charged`` cut straight to the nearest area at the grid's border (or the border itself), at once.

    Longer cuts than pairing charged holes with each other, at the cost of one distance transform:
    for a region riddled with charged holes (noise beyond what the residue test removes), where
    pairing them one at a time costs a transform of the neighbourhood each.
    """
    targets = ground[holes]
    targets[[0, -1], :] = targets[:, [0, -1]] = True
    dist, (iy, ix) = ndimage.distance_transform_edt(~targets, return_indices=True)
    cut = np.zeros_like(valid)
    for y0, x0 in ndimage.minimum_position(dist, labels=holes, index=charged):
        rr, cc = line(int(y0), int(x0), int(iy[y0, x0]), int(ix[y0, x0]))
        cut[rr, cc] = True
    return cut & valid


def _nearest_target(holes, root, live, k: int, box, r: int):
    """The sample of hole ``k`` nearest to a sample of another ``live`` hole, and that sample: ``((y0, x0), (y1, x1))``.

    Searched in ``k``'s bounding box widened by ``r`` samples, doubled until the nearest target lies
    within ``r`` (then nothing outside the window can be nearer) or the window is the whole grid.
    """
    h, w = holes.shape
    while True:
        ya, yb, xa, xb = max(box[0] - r, 0), min(box[1] + r, h), max(box[2] - r, 0), min(box[3] + r, w)
        lab = root[holes[ya:yb, xa:xb]]
        lab[holes[ya:yb, xa:xb] == 0] = 0
        targets = live[lab]
        whole = (ya, yb, xa, xb) == (0, h, 0, w)
        if targets.any():
            dist, (iy, ix) = ndimage.distance_transform_edt(~targets, return_indices=True)
            mine = np.flatnonzero((lab == k).ravel())
            a = mine[np.argmin(dist.ravel()[mine])]
            if dist.ravel()[a] <= r or whole:
                y0, x0 = divmod(int(a), xb - xa)
                return (ya + y0, xa + x0), (ya + int(iy[y0, x0]), xa + int(ix[y0, x0]))
        r *= 2


def _nearest_edge(holes, root, k: int, box):
    """The sample of hole ``k`` nearest to the grid's border, and its foot on the border: ``((y0, x0), (y1, x1))``."""
    h, w = holes.shape
    ya, yb, xa, xb = box
    ys, xs = np.nonzero((root[holes[ya:yb, xa:xb]] == k) & (holes[ya:yb, xa:xb] > 0))
    ys, xs = ys + ya, xs + xa
    d = np.stack([ys, h - 1 - ys, xs, w - 1 - xs])
    i, side = np.unravel_index(int(np.argmin(d.T)), (ys.size, 4))
    y0, x0 = int(ys[i]), int(xs[i])
    return (y0, x0), ((0, x0), (h - 1, x0), (y0, 0), (y0, w - 1))[side]

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
