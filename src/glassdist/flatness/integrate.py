"""Height from slope: a least-squares integrator on a masked grid (the region and its holes).

The height ``Z`` on the samples of a region is the least-squares solution of the
finite-difference equations between 4-neighbours inside the region,

.. math::

   \\frac{Z_{i,j+1} - Z_{i,j}}{s_x} = \\frac{g^x_{i,j} + g^x_{i,j+1}}{2}, \\qquad
   \\frac{Z_{i+1,j} - Z_{i,j}}{s_y} = \\frac{g^y_{i,j} + g^y_{i+1,j}}{2},

one equation per neighbour pair with both samples in the region (the zonal estimator of
Southwell 1980): a sample on a border or beside a hole takes part through the pairs it has,
and no value is assumed outside the region. The normal equations ``A^T A Z = A^T b`` are a
graph Laplacian, singular by one constant per 4-connected part of the region; each part is
pinned at one sample, solved by a sparse direct factorisation (``scipy.sparse.linalg.spsolve``),
and its mean removed. The trapezoidal pairing is second-order: a sinusoid of wavenumber ``k``
sampled every ``s`` comes back scaled by ``(k s / 2) / tan(k s / 2) ~ 1 - (k s)^2 / 12``
(-0.4 % at 30 samples per wavelength, -3.3 % at 10).

Why not Frankot-Chellappa (the FFT projection on integrable gradients): it assumes the slope
field periodic over a full rectangle; a region with borders that are not periodic, and with
holes, leaks the jumps at the borders into the whole height (ringing, a bias at the edges
that the edge-lift measure reads). The masked least squares has no such assumption, and
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
from scipy import ndimage, sparse
from scipy.sparse.linalg import spsolve

__all__ = ["integrate_slope"]


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
    mask = np.asarray(mask, bool)
    if gx.shape != mask.shape or gy.shape != mask.shape or mask.ndim != 2:
        raise ValueError(f"gx, gy and mask must be 2-D of one shape, got {gx.shape}, {gy.shape}, {mask.shape}")
    sy, sx = (float(s) for s in step_mm)
    if not (sy > 0 and sx > 0):
        raise ValueError(f"step_mm must be positive, got {step_mm!r}")
    if not (np.isfinite(gx[mask]).all() and np.isfinite(gy[mask]).all()):
        raise ValueError("the slopes must be finite inside the mask")
    out = np.full(mask.shape, np.nan)
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
        k = i0.size
        eq = np.arange(m, m + k)
        rows += [eq, eq]
        cols += [i1, i0]
        vals += [np.full(k, 1.0 / s), np.full(k, -1.0 / s)]
        rhs.append(0.5 * (g[a][pair] + g[b][pair]))
        m += k
    # one sample of each 4-connected part pinned to 0: the normal equations become definite
    labels, nparts = ndimage.label(mask)
    anchors = index[mask][np.unique(labels[mask], return_index=True)[1]]
    rows.append(np.arange(m, m + nparts))
    cols.append(anchors)
    vals.append(np.ones(nparts))
    rhs.append(np.zeros(nparts))
    A = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(m + nparts, n))
    z = spsolve((A.T @ A).tocsc(), A.T @ np.concatenate(rhs))
    lab = labels[mask]
    means = ndimage.mean(z, lab, np.arange(1, nparts + 1))
    out[mask] = z - np.asarray(means)[lab - 1]
    return out
