"""Block I: logical-grid recovery (I1) and RANSAC homography (I2), Direct Method.

The homography ``H`` maps logical grid coordinates ``(U, V)`` -- measured in
carrier periods along carrier 1 and carrier 2 -- to camera pixels ``(x, y)``
(x along columns, y along rows). Its inverse gives, at every pixel, the grid
coordinate an undistorted pinhole capture of the flat backdrop would show there:
the synthetic reference of the Direct Method.

References
----------
Fischler & Bolles (1981), Comm. ACM 24, 381 (RANSAC). Hartley & Zisserman (2004),
Multiple View Geometry, ch. 4 (homography estimation). Paper §2.2, Block I.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import AnalysisError
from . import fourier as F
from .params import AnalyzerParams
from .region import erode

__all__ = [
    "HomographyFit", "logical_grid_points", "fit_homography", "fit_grid_homography", "apply_inverse", "inverse_jacobian",
]


@dataclass(frozen=True)
class HomographyFit:
    """Result of I2.

    Attributes
    ----------
    matrix : ndarray (3, 3)
        ``H``: homogeneous ``(U, V, 1) -> (x, y, 1)`` (normalised so ``H[2, 2] = 1``).
    inlier_fraction : float
    n_points : int
    rms_inlier_px : float
        RMS reprojection error of the inliers, px.
    """

    matrix: np.ndarray
    inlier_fraction: float
    n_points: int
    rms_inlier_px: float

    def to_dict(self) -> dict:
        return {
            "matrix": self.matrix.tolist(),
            "inlier_fraction": self.inlier_fraction,
            "n_points": self.n_points,
            "rms_inlier_px": self.rms_inlier_px,
        }


def logical_grid_points(
    U: np.ndarray, V: np.ndarray, y: np.ndarray, x: np.ndarray, valid: np.ndarray, spacing: int,
    max_points: int = 40_000,
) -> tuple[np.ndarray, np.ndarray]:
    """I1: subsample (logical grid, pixel) pairs at about one point per carrier period.

    Parameters
    ----------
    U, V : ndarray (h, w)
        Logical grid coordinates (carrier periods) at the samples.
    y, x : ndarray (h, w)
        Pixel coordinates of the samples.
    valid : ndarray of bool (h, w)
    spacing : int
        Subsampling step on the sample grid (>= 1).

    Returns
    -------
    src : ndarray (n, 2)
        ``(U, V)`` pairs.
    dst : ndarray (n, 2)
        ``(x, y)`` pixel positions.
    """
    s = max(int(spacing), 1)
    # One point per carrier period, but no more than ~max_points: 8 parameters need far fewer.
    s = max(s, int(np.ceil(np.sqrt(valid.sum() / max_points))))
    sl = (slice(s // 2, None, s), slice(s // 2, None, s))
    m = valid[sl]
    src = np.stack([U[sl][m], V[sl][m]], axis=1)
    dst = np.stack([x[sl][m], y[sl][m]], axis=1)
    return src, dst


def fit_homography(
    src: np.ndarray, dst: np.ndarray, *, threshold_px: float, max_trials: int = 2000, seed: int = 0
) -> HomographyFit:
    """I2: RANSAC homography from logical grid ``src`` to pixels ``dst``.

    Parameters
    ----------
    src, dst : ndarray (n, 2)
    threshold_px : float
        Inlier threshold on the reprojection error, px (a fraction of the carrier
        period: points displaced by the optical wave fall outside it).
    max_trials : int
    seed : int
        Seed of RANSAC's sampler (OpenCV's estimator, which refines the
        consensus set by Levenberg-Marquardt).

    Raises
    ------
    AnalysisError
        With fewer than 8 points or when no consensus is found.
    """
    if len(src) < 8:
        raise AnalysisError(
            f"only {len(src)} reliable grid points for the homography; the valid region is too small - "
            "photograph more of the grid through the pane or use the Comparative Method (--reference)"
        )
    import cv2

    cv2.setRNGSeed(int(seed))
    H, inl = cv2.findHomography(
        src.astype(np.float64),
        dst.astype(np.float64),
        cv2.RANSAC,
        ransacReprojThreshold=float(threshold_px),
        maxIters=int(max_trials),
        confidence=0.999,
    )
    if H is None or inl is None or int(inl.sum()) < 4:
        raise AnalysisError(
            "RANSAC found no homography consistent with the grid; the pattern may be too distorted or "
            "occluded - use the Comparative Method (--reference) or a larger ransac_threshold_periods"
        )
    inliers = inl.ravel().astype(bool)
    # Tighten: least-squares refits on the points closest to the consensus plane, so the
    # few wave-displaced points that happen to fall inside the threshold weigh less.
    for frac in (0.5, 0.35):
        res = _reproj_error(H, src, dst)
        core = res < frac * threshold_px
        if core.sum() < max(8, 0.2 * inliers.sum()):
            break
        H2, _ = cv2.findHomography(src[core].astype(np.float64), dst[core].astype(np.float64), 0)
        if H2 is None:
            break
        H = H2
    H = H / H[2, 2]
    err = _reproj_error(H, src, dst)
    inliers = err < threshold_px
    rms = float(np.sqrt(np.mean(err[inliers] ** 2)))
    return HomographyFit(H, float(inliers.mean()), int(len(src)), rms)


def _reproj_error(H: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    p = np.c_[src, np.ones(len(src))] @ H.T
    return np.linalg.norm(p[:, :2] / p[:, 2:3] - dst, axis=1)


def apply_inverse(H: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(U, V) = H^{-1}(x, y)``: logical grid coordinates of pixels, carrier periods."""
    G = np.linalg.inv(H)
    w = G[2, 0] * x + G[2, 1] * y + G[2, 2]
    u = (G[0, 0] * x + G[0, 1] * y + G[0, 2]) / w
    v = (G[1, 0] * x + G[1, 1] * y + G[1, 2]) / w
    return u, v


def inverse_jacobian(H: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Jacobian of ``H^{-1}``: ``J[..., a, b] = d(U, V)_a / d(x, y)_b``, carrier periods per px.

    Returns
    -------
    ndarray (..., 2, 2)
    """
    G = np.linalg.inv(H)
    w = G[2, 0] * x + G[2, 1] * y + G[2, 2]
    u = (G[0, 0] * x + G[0, 1] * y + G[0, 2]) / w
    v = (G[1, 0] * x + G[1, 1] * y + G[1, 2]) / w
    J = np.empty(np.shape(x) + (2, 2))
    J[..., 0, 0] = (G[0, 0] - u * G[2, 0]) / w
    J[..., 0, 1] = (G[0, 1] - u * G[2, 1]) / w
    J[..., 1, 0] = (G[1, 0] - v * G[2, 0]) / w
    J[..., 1, 1] = (G[1, 1] - v * G[2, 1]) / w
    return J


def _points_spacing(carriers: F.CarrierPair, grid: F.SamplingGrid) -> int:
    period = min(carriers.k1.period_px, carriers.k2.period_px)
    return max(1, int(round(period / min(grid.step))))


# Block I's grid points keep this many carrier periods from the image edges.
_INTERIOR_PERIODS = 1.5


def fit_grid_homography(UV, yy, xx, labels, n, carriers, grid, p: AnalyzerParams, warn: list[str]):
    """I1 + I2 over all regions, aligning each region's free integer grid offset to the largest.

    ``UV``: logical grid coordinates (carrier periods) on the demodulation grid ``(yy, xx)``;
    ``labels``/``n``: the valid region's parts (:class:`~glassdist.analyzer.region.Region`).

    Returns the fit and, per region label (index 0 unused), the integer offsets (periods)
    subtracted from U and V.
    """
    U, V = UV
    spacing = _points_spacing(carriers, grid)
    period = max(carriers.k1.period_px, carriers.k2.period_px)
    thr = p.ransac_threshold_periods * min(carriers.k1.period_px, carriers.k2.period_px)
    # Grid points from the interior only: near the image edges the phase of a single photo
    # is less certain (the Comparative Method cancels that against its reference, Block I
    # cannot), and a homography tilted by them would leave a ramp in the displacement.
    interior = erode(np.ones(grid.shape, bool), 0.0, grid, _INTERIOR_PERIODS * period)
    if (labels[interior] == 1).sum() < 0.5 * (labels == 1).sum():
        interior = np.ones(grid.shape, bool)  # small images: keep every point
    src, dst = logical_grid_points(U, V, yy, xx, (labels == 1) & interior, spacing)
    fit = fit_homography(src, dst, threshold_px=thr, max_trials=p.ransac_max_trials, seed=p.ransac_seed)
    offsets = np.zeros((n + 1, 2))
    if n > 1:
        U = U.copy()
        V = V.copy()
        u0, v0 = apply_inverse(fit.matrix, xx, yy)
        for r in range(2, n + 1):
            sel = labels == r
            offsets[r] = np.round(np.median(U[sel] - u0[sel])), np.round(np.median(V[sel] - v0[sel]))
            U[sel] -= offsets[r, 0]
            V[sel] -= offsets[r, 1]
        src, dst = logical_grid_points(U, V, yy, xx, (labels > 0) & interior, spacing)
        fit = fit_homography(src, dst, threshold_px=thr, max_trials=p.ransac_max_trials, seed=p.ransac_seed)
    if fit.inlier_fraction < 0.1:
        warn.append(
            f"only {100 * fit.inlier_fraction:.0f}% of grid points fit the homography; strong distortion or "
            "lens distortion may bias the Direct Method's baseline"
        )
    return fit, offsets
