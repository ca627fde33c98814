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
    "HomographyFit",
    "logical_grid_points",
    "fit_homography",
    "fit_grid_homography",
    "refit_undistorted",
    "apply_inverse",
    "inverse_jacobian",
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
    excluded_fraction : float
        Share of the fitted samples whose local strain stands out of the noise
        (weighed down by :func:`refit_undistorted`).
    """

    matrix: np.ndarray
    inlier_fraction: float
    n_points: int
    rms_inlier_px: float
    excluded_fraction: float = 0.0

    def to_dict(self) -> dict:
        return {
            "matrix": self.matrix.tolist(),
            "inlier_fraction": self.inlier_fraction,
            "n_points": self.n_points,
            "rms_inlier_px": self.rms_inlier_px,
            "excluded_fraction": self.excluded_fraction,
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


#: Least share of the view at the strain noise level for the robust refit to be kept.
_MIN_CLEAN = 0.3


def _local_frequency(U: np.ndarray, V: np.ndarray, valid: np.ndarray, step_px, period_px: float):
    """Gradients of the logical grid (carrier periods per px) smoothed over one carrier period; NaN where unknown."""
    from scipy import ndimage

    sy, sx = step_px
    s = (period_px / sy, period_px / sx)
    wgt = ndimage.gaussian_filter(valid.astype(float), s, mode="constant")
    out = []
    for f in (U, V):
        gy, gx = np.gradient(np.where(valid, f, np.nan), sy, sx)
        for g in (gx, gy):
            ok = np.isfinite(g)
            with np.errstate(invalid="ignore", divide="ignore"):
                gs = ndimage.gaussian_filter(np.where(ok, g, 0.0), s, mode="constant") / wgt
            out.append(np.where(ok & valid, gs, np.nan))
    return np.stack(out, axis=-1)  # (h, w, 4): dU/dx, dU/dy, dV/dx, dV/dy


def refit_undistorted(
    fit: HomographyFit, U: np.ndarray, V: np.ndarray, y: np.ndarray, x: np.ndarray, valid: np.ndarray, spacing: int, *,
    period_px: float, step_px: tuple[float, float], threshold_px: float,
) -> HomographyFit:
    """Refit the homography to the grid's local frequencies, robustly (Direct Method, Block I).

    RANSAC keeps the points within ``threshold_px`` of one consensus plane, but a smooth
    defect covering much of the view (a lens) leaves many of its points within that
    threshold, and the least-squares refit then absorbs part of the defect (the
    perspective terms bend to follow it). Here the map ``(x, y) -> (U, V) = H^{-1}`` is
    fitted instead to the *gradients* of the logical grid (the local carrier frequencies,
    the strain it implies), with a robust (soft-L1) loss whose scale is the noise of those
    gradients measured on the view itself: where a defect strains the grid its samples
    weigh little, wherever they lie, and the homography follows the undistorted part of
    the view. A distortion spread evenly over the view (a roller wave) pulls it equally
    both ways. The translation, which the gradients do not fix, is the median offset of
    the logical grid. No user input.

    Returns
    -------
    HomographyFit
        The refitted homography (``fit`` when the robust fit fails).
    """
    from scipy import ndimage
    from scipy.optimize import least_squares

    Jm = _local_frequency(U, V, valid, step_px, period_px)
    ok = valid & np.all(np.isfinite(Jm), axis=-1)
    s = max(int(spacing), 1)
    s = max(s, int(np.ceil(np.sqrt(ok.sum() / 20_000))))
    sl = (slice(s // 2, None, s), slice(s // 2, None, s))
    m = ok[sl]
    if m.sum() < 32:
        return fit
    xs, ys = x[sl][m], y[sl][m]
    Jp = Jm[sl][m] * period_px  # dimensionless
    Us, Vs = U[sl][m], V[sl][m]
    # Noise of the local frequencies: their departure from a smoother version of themselves.
    sy, sx = step_px
    sm = np.stack([ndimage.gaussian_filter(np.nan_to_num(Jm[..., i]), (2 * period_px / sy, 2 * period_px / sx)) for i in range(4)], -1)
    wsm = ndimage.gaussian_filter(ok.astype(float), (2 * period_px / sy, 2 * period_px / sx))
    with np.errstate(invalid="ignore", divide="ignore"):
        hf = (Jm - sm / wsm[..., None])[ok] * period_px
    noise = 1.4826 * float(np.median(np.abs(hf - np.median(hf, axis=0))))
    scale = max(3.0 * noise, 1e-4)
    # Normalised pixel coordinates keep the 8 parameters of comparable size.
    cx, cy = float(np.mean(xs)), float(np.mean(ys))
    L = float(max(np.ptp(xs), np.ptp(ys), 1.0)) / 2.0
    Tn = np.array([[1 / L, 0, -cx / L], [0, 1 / L, -cy / L], [0, 0, 1.0]])
    G0 = np.linalg.inv(fit.matrix) @ np.linalg.inv(Tn)  # logical = G0 (normalised pixel)
    G0 = G0 / G0[2, 2]
    xn, yn = (xs - cx) / L, (ys - cy) / L

    def model_jac(q):
        a, b, c, d, e, f, g, h = q
        w = g * xn + h * yn + 1.0
        u = (a * xn + b * yn + c) / w
        v = (d * xn + e * yn + f) / w
        return np.stack([(a - u * g) / w, (b - u * h) / w, (d - v * g) / w, (e - v * h) / w], -1) / L * period_px

    def resid(q):
        return (model_jac(q) - Jp).ravel()

    q0 = G0.ravel()[:8]
    try:
        sol = least_squares(resid, q0, loss="soft_l1", f_scale=scale, x_scale="jac", max_nfev=200)
    except (ValueError, np.linalg.LinAlgError):
        return fit
    if not sol.success or not np.all(np.isfinite(sol.x)):
        return fit
    Gn = np.append(sol.x, 1.0).reshape(3, 3)
    # The gradients fix the map up to a translation of the logical grid, U -> U - t, i.e.
    # rows 0 and 1 of G minus t times row 2: t is the median offset of the logical grid.
    w = Gn[2, 0] * xn + Gn[2, 1] * yn + 1.0
    for row, obs in ((0, Us), (1, Vs)):
        t = float(np.median((Gn[row, 0] * xn + Gn[row, 1] * yn + Gn[row, 2]) / w - obs))
        Gn[row] -= t * Gn[2]
    Hn = np.linalg.inv(Gn @ Tn)
    if not np.all(np.isfinite(Hn)) or abs(Hn[2, 2]) < 1e-12:
        return fit
    Hn = Hn / Hn[2, 2]
    # Keep the robust fit only where it finds an undistorted part of the view: many more
    # samples whose strain is at the noise level than under the RANSAC fit. A distortion
    # spread over the whole view (a roller wave) leaves few such samples under either fit,
    # and there the least-squares fit of the positions, which averages the wave over
    # whole periods, is the better baseline.
    clean0 = float(np.mean(np.abs(resid(q0)).reshape(-1, 4).max(axis=1) < 3 * scale))
    r = np.abs(resid(sol.x))
    clean = float(np.mean(r.reshape(-1, 4).max(axis=1) < 3 * scale))
    if clean < max(_MIN_CLEAN, clean0 + 0.1):
        return fit
    src, dst = logical_grid_points(U, V, y, x, valid, spacing)
    err = _reproj_error(Hn, src, dst)
    inl = err < threshold_px
    rms = float(np.sqrt(np.mean(err[inl] ** 2))) if inl.any() else float("nan")
    return HomographyFit(Hn, float(inl.mean()), int(len(src)), rms, 1.0 - clean)


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
    fit = refit_undistorted(
        fit, U, V, yy, xx, (labels > 0) & interior, spacing, period_px=period, step_px=grid.step, threshold_px=thr,
    )
    if fit.inlier_fraction < 0.1:
        warn.append(
            f"only {100 * fit.inlier_fraction:.0f}% of grid points fit the homography; strong distortion or "
            "lens distortion may bias the Direct Method's baseline"
        )
    return fit, offsets
