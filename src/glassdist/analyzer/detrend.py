"""Block A, stage A2: the polynomial detrend of a displacement field, per connected region (paper §2.2.2).

Each region's least-squares polynomial of total degree N in the sample coordinates (centred
and scaled per region, monomials by total degree) is removed from every component: what a
homography, the camera and a pane-level curvature leave is taken out before the channels
are formed. :func:`detrend_increment` gives what degree N + 1 removes beyond degree N.
"""

from __future__ import annotations

import numpy as np

__all__ = ["detrend_increment", "polynomial_detrend"]


def _monomials(x: np.ndarray, y: np.ndarray, degree: int) -> np.ndarray:
    """``x^i y^j`` (n, m) ordered by total degree ``i + j``, powers by repeated products."""
    xp, yp = [np.ones_like(x)], [np.ones_like(y)]
    for _ in range(degree):
        xp.append(xp[-1] * x)
        yp.append(yp[-1] * y)
    A = np.empty(x.shape + ((degree + 1) * (degree + 2) // 2,), dtype=np.result_type(x, y))
    k = 0
    for n in range(degree + 1):
        for i in range(n + 1):
            np.multiply(xp[i], yp[n - i], out=A[..., k])
            k += 1
    return A


def _polynomial_fits(field: np.ndarray, labels: np.ndarray, degrees, step_px) -> list[np.ndarray]:
    """Per region and component, the least-squares polynomials of each total degree in ``degrees``.

    One design matrix of the highest degree serves every degree (its monomials are ordered by
    total degree, so a lower degree's are its leading columns). Returns one array (h, w, c)
    per degree, NaN where ``labels == 0``.
    """
    top = max(degrees)
    fits = [np.full_like(field, np.nan) for _ in degrees]
    for r in range(1, int(labels.max(initial=0)) + 1):
        sel = labels == r
        iy, ix = np.nonzero(sel)  # the region's samples only: no coordinate grid of the whole field
        if iy.size == 0:
            continue
        x, y = ix * float(step_px[1]), iy * float(step_px[0])
        cx, cy = x.mean(), y.mean()
        s = max(np.ptp(x), np.ptp(y), 1.0) / 2.0
        A = _monomials((x - cx) / s, (y - cy) / s, top)
        vals = field[sel]
        ok = np.all(np.isfinite(vals), axis=1)
        Ao, vo = (A, vals) if ok.all() else (A[ok], vals[ok])
        if top <= 4:
            # Normal equations: coordinates scaled to [-1, 1] keep A^T A well conditioned at
            # these degrees, and they cost a fraction of an SVD on 1e5 samples.
            AtA, Atv = Ao.T @ Ao, Ao.T @ vo
        for out, d in zip(fits, degrees):
            m = (d + 1) * (d + 2) // 2
            if top <= 4:
                coef, *_ = np.linalg.lstsq(AtA[:m, :m], Atv[:m], rcond=None)
            else:
                coef, *_ = np.linalg.lstsq(Ao[:, :m], vo, rcond=None)
            out[sel] = A[:, :m] @ coef
    return fits


def _as_components(field: np.ndarray) -> tuple[np.ndarray, bool]:
    f = np.asarray(field, dtype=float)
    return (f[..., None], True) if f.ndim == 2 else (f, False)


def polynomial_detrend(field: np.ndarray, labels: np.ndarray, degree: int, step_px=(1.0, 1.0)) -> np.ndarray:
    """A2: subtract, per region and per component, the least-squares polynomial of total degree ``degree``.

    Parameters
    ----------
    field : ndarray (h, w) or (h, w, c)
    labels : ndarray of int (h, w)
        0 = excluded, 1..n = regions detrended independently.
    degree : int
        Total degree N (monomials x^i y^j with i + j <= N).
    step_px : (float, float)
        Sample spacing (sy, sx), px (only conditions the fit; the result is affine-invariant).

    Returns
    -------
    ndarray like ``field``; NaN where ``labels == 0``.
    """
    f, squeeze = _as_components(field)
    out = f - _polynomial_fits(f, labels, (degree,), step_px)[0]
    return out[..., 0] if squeeze else out


def detrend_increment(field: np.ndarray, labels: np.ndarray, degree: int, step_px=(1.0, 1.0)) -> np.ndarray:
    """What A2 at degree ``degree + 1`` removes beyond degree ``degree``: ``P_{N+1} f - P_N f``.

    ``P_N`` is the per-region least-squares projection on the polynomials of total degree N,
    so ``detrend_{N+1}(f) = detrend_N(f) - (P_{N+1} f - P_N f)`` exactly; the difference is a
    polynomial of degree N + 1 per region (arguments as :func:`polynomial_detrend`).
    """
    f, squeeze = _as_components(field)
    low, high = _polynomial_fits(f, labels, (degree, degree + 1), step_px)
    out = high - low
    return out[..., 0] if squeeze else out
