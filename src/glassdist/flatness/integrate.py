"""Height from slope: a least-squares integrator on a masked grid (the region and its holes).

The height ``Z`` on the samples of a region is the least-squares solution of the
finite-difference equations between 4-neighbours inside the region,

.. math::

   \\frac{Z_{i,j+1} - Z_{i,j}}{s_x} = \\frac{g^x_{i,j} + g^x_{i,j+1}}{2}, \\qquad
   \\frac{Z_{i+1,j} - Z_{i,j}}{s_y} = \\frac{g^y_{i,j} + g^y_{i+1,j}}{2},

one equation per neighbour pair with both samples in the region (the zonal estimator of
Southwell 1980): a sample on a border or beside a hole takes part through the pairs it has,
and no value is assumed outside the region. The normal equations ``A^T A Z = A^T b`` are a
graph Laplacian, singular by one constant per 4-connected part of the region, and
consistent (each difference row sums to zero, so ``A^T b`` has no component along those
constants). Up to :data:`DIRECT_MAX_SAMPLES` samples each part is pinned at one sample and the
system solved by a sparse direct factorisation (``scipy.sparse.linalg.splu``, a symmetric
ordering); above, by conjugate gradients (``scipy.sparse.linalg.cg``, relative residual 1e-10)
preconditioned by the Neumann Laplacian of the full rectangle, inverted by a type-II DCT
(``scipy.fft.dctn``): the masked operator differs from it only at the borders and holes, so
the iterations stay few (``benchmarks/bench_flatness.py``: 3.6 s against 11.1 s for the direct
solve on a 600 x 800 grid with a hole and an island, the two within 7e-10 of the height's
spread), the direct solve should they not converge. Each part's mean is then removed.

The trapezoidal pairing is second-order: a sinusoid of wavenumber ``k`` sampled every ``s`` comes back
scaled by ``(k s / 2) / tan(k s / 2) ~ 1 - (k s)^2 / 12``
(-0.4 % at 30 samples per wavelength, -3.3 % at 10).

Why not Frankot-Chellappa (the FFT projection on integrable gradients): it assumes the slope
field periodic over a full rectangle; a region with borders that are not periodic, and with
holes, leaks the jumps at the borders into the whole height (ringing, a bias at the edges
where the pane's edges are). The masked least squares has no such assumption, and
with a curl-free slope it is exact up to the discretisation.

References
----------
Southwell, W. H. (1980). Wave-front estimation from wave-front slope measurements.
*J. Opt. Soc. Am.* 70(8), 998-1006.
Harker, M. and O'Leary, P. (2008). Least squares surface reconstruction from measured
gradient fields. *CVPR 2008*.
Frankot, R. T. and Chellappa, R. (1988). A method for enforcing integrability in shape from
shading algorithms. *IEEE Trans. PAMI* 10(4), 439-451.
"""

from __future__ import annotations

import numpy as np
from scipy import fft, ndimage, sparse
from scipy.sparse.linalg import LinearOperator, cg, splu

__all__ = ["DIRECT_MAX_SAMPLES", "integrate_slope", "integrate_slopes"]

#: Region size (samples) up to which the direct factorisation is used, between the sizes where each is the
#: faster (benchmarks/flatness_results.json: direct 0.45 s, CG 1.14 s at 25k samples; 1.84 s and 1.35 s at 100k).
DIRECT_MAX_SAMPLES = 60_000


def _solve_cg(normal, b: np.ndarray, mask: np.ndarray, sy: float, sx: float, maxiter: int = 2000):
    """Conjugate gradients on the masked normal equations, preconditioned by the DCT-inverted Neumann
    Laplacian of the full rectangle (module notes); None when they do not converge."""
    h, w = mask.shape
    lam = ((2 - 2 * np.cos(np.pi * np.arange(h) / h)) / sy**2)[:, None] + \
        ((2 - 2 * np.cos(np.pi * np.arange(w) / w)) / sx**2)[None, :]
    lam[0, 0] = 1.0  # the constant: left out below
    buf = np.zeros(mask.shape)

    def precondition(r):
        buf[:] = 0.0
        buf[mask] = r
        c = fft.dctn(buf, type=2, norm="ortho")
        c /= lam
        c[0, 0] = 0.0
        return fft.idctn(c, type=2, norm="ortho")[mask]

    if not np.any(b):
        return np.zeros(b.size)
    z, info = cg(normal, b, M=LinearOperator(normal.shape, precondition), rtol=1e-10, maxiter=maxiter)
    return z if info == 0 else None


def integrate_slope(gx: np.ndarray, gy: np.ndarray, mask: np.ndarray, step_mm) -> np.ndarray:
    """Least-squares height of a slope field over a masked grid (module notes).

    Parameters
    ----------
    gx, gy : ndarray (h, w)
        Slopes ``dZ/dx`` (along columns) and ``dZ/dy`` (along rows), dimensionless
        (height per mm); read only where ``mask`` (must be finite there).
    mask : ndarray (h, w) bool
        The region; holes and several parts allowed.
    step_mm : (float, float)
        Sample spacing ``(s_y, s_x)`` along rows and columns, mm.

    Returns
    -------
    ndarray (h, w) float64
        Height, mm of height per unit slope x mm (slopes in mrad give µm), mean zero over each
        4-connected part of the region; NaN outside it. A part of one sample reads 0.

    Raises
    ------
    ValueError
        Shapes differ, the step is not positive, or a slope inside the region is not finite.
    """
    gx, gy = np.asarray(gx, float), np.asarray(gy, float)
    if gx.ndim != 2 or gy.ndim != 2:
        raise ValueError(f"gx, gy and mask must be 2-D of one shape, got {gx.shape}, {gy.shape}, {np.shape(mask)}")
    return integrate_slopes(gx[None], gy[None], mask, step_mm)[0]


def integrate_slopes(gx: np.ndarray, gy: np.ndarray, mask: np.ndarray, step_mm) -> np.ndarray:
    """:func:`integrate_slope` of ``k`` slope fields on one region: ``gx, gy`` of shape (k, h, w), the
    system built (and, up to :data:`DIRECT_MAX_SAMPLES`, factorised) once; returns (k, h, w)."""
    gx, gy = np.asarray(gx, float), np.asarray(gy, float)
    mask = np.asarray(mask, bool)
    if gx.ndim != 3 or gx.shape[1:] != mask.shape or gy.shape != gx.shape or mask.ndim != 2:
        raise ValueError(f"gx, gy and mask must be 2-D of one shape, got {gx.shape[1:]}, {gy.shape[1:]}, {mask.shape}")
    sy, sx = (float(s) for s in step_mm)
    if not (sy > 0 and sx > 0):
        raise ValueError(f"step_mm must be positive, got {step_mm!r}")
    if not (np.isfinite(gx[:, mask]).all() and np.isfinite(gy[:, mask]).all()):
        raise ValueError("the slopes must be finite inside the mask")
    k = gx.shape[0]
    out = np.full(gx.shape, np.nan)
    n = int(np.count_nonzero(mask))
    if n == 0:
        return out
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[mask] = np.arange(n)
    rows, cols, vals, rhs = [], [], [], []
    m = 0
    for axis, s, g in ((1, sx, gx), (0, sy, gy)):
        a = (slice(None), slice(None, -1)) if axis == 1 else (slice(None, -1), slice(None))
        b = (slice(None), slice(1, None)) if axis == 1 else (slice(1, None), slice(None))
        pair = mask[a] & mask[b]
        i0, i1 = index[a][pair], index[b][pair]
        npair = i0.size
        eq = np.arange(m, m + npair)
        rows += [eq, eq]
        cols += [i1, i0]
        vals += [np.full(npair, 1.0 / s), np.full(npair, -1.0 / s)]
        rhs.append(0.5 * (g[:, a[0], a[1]][:, pair] + g[:, b[0], b[1]][:, pair]))
        m += npair
    A = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, n))
    normal = (A.T @ A).tocsr()
    B = np.asarray(A.T @ np.concatenate(rhs, axis=1).T)  # (n, k)
    labels, nparts = ndimage.label(mask)
    Z = np.empty((n, k))
    todo = list(range(k))
    if n > DIRECT_MAX_SAMPLES:
        solved = [_solve_cg(normal, B[:, j], mask, sy, sx) for j in range(k)]
        for j, z in enumerate(solved):
            if z is not None:
                Z[:, j] = z
        todo = [j for j, z in enumerate(solved) if z is None]
    if todo:  # one sample of each 4-connected part pinned to 0: the system becomes definite
        anchors = index[mask][np.unique(labels[mask], return_index=True)[1]]
        pin = sparse.csr_matrix((np.ones(nparts), (anchors, anchors)), shape=(n, n))
        lu = splu((normal + pin).tocsc(), permc_spec="MMD_AT_PLUS_A")  # symmetric: a symmetric ordering
        Z[:, todo] = lu.solve(np.ascontiguousarray(B[:, todo]))
    lab = labels[mask]
    for j in range(k):
        means = ndimage.mean(Z[:, j], lab, np.arange(1, nparts + 1))
        out[j][mask] = Z[:, j] - np.asarray(means)[lab - 1]
    return out
