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
from typing import Any

import numpy as np

from ..errors import AnalysisError
from . import fourier as F
from .lens import LensCalibration, LensModel, fit_lens_homography, radial_ambiguity, radial_consistency
from .params import AnalyzerParams
from .region import erode

__all__ = [
    "GridFit",
    "LensFitOptions",
    "LensRefit",
    "LogicalGrid",
    "HomographyFit",
    "logical_grid_points",
    "fit_homography",
    "fit_grid_homography",
    "refit_undistorted",
    "refit_with_lens",
    "apply_inverse",
    "inverse_jacobian",
    "logical_coordinates",
    "logical_jacobian",
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
    lens : LensCalibration or None
        The camera lens's distortion the baseline includes (:mod:`glassdist.analyzer.lens`):
        the pixel of ``(U, V)`` is then the distorted image of ``H(U, V)``.
    """

    matrix: np.ndarray
    inlier_fraction: float
    n_points: int
    rms_inlier_px: float
    excluded_fraction: float = 0.0
    lens: LensCalibration | None = None

    @property
    def lens_model(self) -> LensModel | None:
        """The lens model applied, or None."""
        return None if self.lens is None or not self.lens.identifiable else self.lens.model

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping."""
        return {
            "matrix": self.matrix.tolist(),
            "inlier_fraction": self.inlier_fraction,
            "n_points": self.n_points,
            "rms_inlier_px": self.rms_inlier_px,
            "excluded_fraction": self.excluded_fraction,
            "lens": None if self.lens is None else self.lens.to_dict(),
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
            "photograph more of the grid through the pane or use the Comparative Method (a reference photo)"
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
            "occluded - use the Comparative Method (a reference photo) or a larger ransac_threshold_periods"
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
    if inliers.sum() < 4:  # a threshold below the phase noise: no consensus to speak of
        raise AnalysisError(
            f"no grid point lies within the RANSAC threshold of {threshold_px:.3g} px; ransac_threshold_periods "
            "is too small for this photo's phase noise - use a larger one (default 0.1) or the Comparative Method"
        )
    rms = float(np.sqrt(np.mean(err[inliers] ** 2)))
    return HomographyFit(H, float(inliers.mean()), int(len(src)), rms)


#: Least share of the view at the strain noise level for it to be called undistorted.
_MIN_CLEAN = 0.3
#: Most samples of the logical grid the robust refit looks at (a regular subsample).
_MAX_REFIT_SAMPLES = 40_000
#: Gross errors (unwrapping slips of whole periods, occlusions) lie farther than this many
#: carrier periods from the averaging fit.
_GROSS_PERIODS = 1.0
#: Without an undistorted part, the averaging fit replaces RANSAC's only when it lowers the
#: view's mean strain below this share of RANSAC's.
_AVERAGE_GAIN = 0.8
#: ... and when it keeps at least this share of the grid points within the inlier threshold
#: (below it Block I calls a fit failed).
_MIN_AVERAGE_INLIERS = 0.1


@dataclass(frozen=True)
class _StrainSamples:
    """A regular subsample of the logical grid with its local frequencies (Block I, robust refit)."""

    src: np.ndarray  # (n, 2) logical (U, V), carrier periods
    dst: np.ndarray  # (n, 2) pixel (x, y)
    freq: np.ndarray  # (n, 4) dU/dx, dU/dy, dV/dx, dV/dy times the carrier period (dimensionless)
    tol: float  # strain at the noise level: 3 x the robust noise of ``freq`` (dimensionless)


def _strain_samples(U, V, y, x, valid, step_px, period_px: float) -> _StrainSamples | None:
    """Local frequencies of the logical grid on a regular subsample of at most ``_MAX_REFIT_SAMPLES``.

    The gradients (centred differences on the subsample, steps in px) are smoothed over
    about one carrier period (normalised by the smoothed mask); their noise is the robust
    (MAD) spread of their departure from a version smoothed twice as much, so the
    tolerance comes from the view itself.
    """
    from scipy import ndimage

    s = max(1, int(np.ceil(np.sqrt(valid.sum() / _MAX_REFIT_SAMPLES))))
    sl = (slice(s // 2, None, s), slice(s // 2, None, s))
    ok, sy, sx = valid[sl], step_px[0] * s, step_px[1] * s
    sig = (max(period_px / sy, 1.0), max(period_px / sx, 1.0))
    grads = [g for f in (U[sl], V[sl]) for g in np.gradient(np.where(ok, f, np.nan), sy, sx)[::-1]]
    fin = ok & np.all(np.isfinite(grads), axis=0)
    if fin.sum() < 32:
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        w1 = ndimage.gaussian_filter(fin.astype(float), sig, mode="constant")
        w2 = ndimage.gaussian_filter(fin.astype(float), (2 * sig[0], 2 * sig[1]), mode="constant")
        J = np.stack([ndimage.gaussian_filter(np.where(fin, g, 0.0), sig, mode="constant") / w1 for g in grads], -1)
        J2 = np.stack([ndimage.gaussian_filter(np.where(fin, j, 0.0), (2 * sig[0], 2 * sig[1]), mode="constant")
                       for j in np.moveaxis(J, -1, 0)], -1) / w2[..., None]
    hf = (J - J2)[fin] * period_px
    noise = 1.4826 * float(np.median(np.abs(hf - np.median(hf, axis=0))))
    return _StrainSamples(np.stack([U[sl][fin], V[sl][fin]], 1), np.stack([x[sl][fin], y[sl][fin]], 1),
                          J[fin] * period_px, max(3.0 * noise, 1e-4))


def _lsq(src: np.ndarray, dst: np.ndarray):
    """Plain least-squares homography (normalised DLT + Levenberg-Marquardt), or None."""
    import cv2

    if len(src) < 8:
        return None
    H, _ = cv2.findHomography(src.astype(np.float64), dst.astype(np.float64), 0)
    return None if H is None or not np.all(np.isfinite(H)) or abs(H[2, 2]) < 1e-12 else H / H[2, 2]


def _strain(H: np.ndarray, S: _StrainSamples, period_px: float) -> np.ndarray:
    """Largest departure of the samples' local frequencies from those of ``H^{-1}`` (dimensionless)."""
    J = inverse_jacobian(H, S.dst[:, 0], S.dst[:, 1]).reshape(-1, 4) * period_px
    return np.max(np.abs(J - S.freq), axis=1)


def _clean(H: np.ndarray, S: _StrainSamples, period_px: float) -> np.ndarray:
    """Samples whose local frequencies match those of ``H^{-1}`` within the noise (no strain)."""
    return _strain(H, S, period_px) < S.tol


def _mean_strain(H: np.ndarray, S: _StrainSamples, period_px: float) -> float:
    return float(np.mean(_strain(H, S, period_px)))


def _trimmed_lsq(S: _StrainSamples, period_px: float):
    """Least-squares homography of every sample but the gross errors (``_GROSS_PERIODS``), or None."""
    H = _lsq(S.src, S.dst)
    for _ in range(3):
        if H is None:
            return None
        keep = _reproj_error(H, S.src, S.dst) < _GROSS_PERIODS * period_px
        H = _lsq(S.src[keep], S.dst[keep])
    return H


def _refit_on_clean(H: np.ndarray, S: _StrainSamples, period_px: float):
    """Three least-squares refits on the samples without strain; the homography and their share."""
    for _ in range(3):
        m = _clean(H, S, period_px)
        H2 = _lsq(S.src[m], S.dst[m])
        if H2 is None:
            break
        H = H2
    return H, float(_clean(H, S, period_px).mean())


def refit_undistorted(
    fit: HomographyFit, U: np.ndarray, V: np.ndarray, y: np.ndarray, x: np.ndarray, valid: np.ndarray, spacing: int, *,
    period_px: float, step_px: tuple[float, float], threshold_px: float,
) -> HomographyFit:
    """Refit the homography on the undistorted part of the view, found by its strain (Direct Method, Block I).

    RANSAC keeps the largest set of points within ``threshold_px`` of one homography, but a
    lens that fills much of the view is itself nearly projective over its centre (a uniform
    power is a magnification), and its points can win the consensus. Here the local
    frequencies of the logical grid (its strain) decide instead. Starting from the RANSAC
    fit and from a least-squares fit of every point (gross errors, farther than
    ``_GROSS_PERIODS`` carrier period, trimmed), the samples whose local frequencies match
    the homography's within the measured noise are taken as undistorted and the
    homography is refitted to their positions by least squares, three times. When a
    candidate (RANSAC's fit itself, or either refit) leaves at least ``_MIN_CLEAN`` of the
    view undistorted, the one leaving the largest share wins; otherwise no glass in view
    is flat (a distortion spread over the whole view: a roller wave, a lens wider than the
    view) and the trimmed least-squares fit, which averages it, is kept. At most ``_MAX_REFIT_SAMPLES`` samples (a regular
    subsample): the cost is bounded whatever the image size. No user input.

    Parameters
    ----------
    fit : HomographyFit
        The RANSAC fit (:func:`fit_homography`).
    U, V : ndarray (h, w)
        Logical grid coordinates (carrier periods) on the sample grid.
    y, x : ndarray (h, w)
        Pixel coordinates of the samples.
    valid : ndarray of bool (h, w)
    spacing : int
        Step of the grid points for the reported inlier statistics.
    period_px : float
        Carrier period, px.
    step_px : (float, float)
        Sample grid step (rows, cols), px.
    threshold_px : float
        Inlier threshold of the reported statistics, px.

    Returns
    -------
    HomographyFit
        The refitted homography (``fit`` when the samples are too few); ``excluded_fraction``
        is the share of the samples with strain above the noise.
    """
    S = _strain_samples(U, V, y, x, valid, step_px, period_px)
    avg = None if S is None else _trimmed_lsq(S, period_px)
    if avg is None:
        return fit
    assert S is not None
    best, share = None, 0.0
    # RANSAC's fit as it is competes too: on a coarse grid (few, noisy samples) a refit on its
    # clean samples can drift to a homography that leaves less of the view clean
    candidates = [(fit.matrix, float(_clean(fit.matrix, S, period_px).mean()))]
    candidates += [_refit_on_clean(start, S, period_px) for start in (fit.matrix, avg)]
    for H, c in candidates:
        if c >= _MIN_CLEAN and c > share:
            best, share = H, c
    if best is None:
        best, share = avg, float(_clean(avg, S, period_px).mean())
    src, dst = logical_grid_points(U, V, y, x, valid, spacing)
    err = _reproj_error(best, src, dst)
    inl = err < threshold_px
    # No undistorted part: RANSAC's consensus stands unless it is a distorted patch (the centre
    # of a wide lens), which the rest of the view then strains clearly more than the average
    # does - and the average is a baseline at all (keeps _MIN_AVERAGE_INLIERS of the points).
    if best is avg and (inl.mean() < _MIN_AVERAGE_INLIERS or _mean_strain(avg, S, period_px)
                        >= _AVERAGE_GAIN * _mean_strain(fit.matrix, S, period_px)):
        return fit
    rms = float(np.sqrt(np.mean(err[inl] ** 2))) if inl.any() else float("nan")
    return HomographyFit(best, float(inl.mean()), int(len(src)), rms, 1.0 - share)


#: Most samples a lens fit uses (a regular subsample of those chosen): 12 parameters need far fewer.
_LENS_MAX_POINTS = 6000
#: Fewest samples a lens fit is made from.
_LENS_MIN_POINTS = 50
#: The lens is identifiable when its fitted samples reach out to this share of the radius the view's
#: samples reach (95th percentiles, from the principal point): a radial term is told from the
#: homography's scale only by its growth with radius.
_LENS_MIN_REACH = 0.7
#: The lens is applied when it removes at least this share of the mean squared residual a bare
#: homography leaves on the same samples (else no lens distortion stands out of the glass's).
_LENS_MIN_GAIN = 0.5
#: Ring means of the residual below this many carrier periods are not a feature (the demodulation's
#: own error on a chirped grid reaches ~0.005 period).
_AMBIGUITY_FLOOR_PERIODS = 0.01
#: Share of the residual energy radially symmetric about the principal point above which a centred,
#: radially symmetric feature is reported (glass and lens alike have that form).
_RADIAL_AMBIGUITY = 0.5
#: A camera lens's radial profile is global: refitted with the inner disc of the view left out it moves
#: by at most this share (modulo the scale the homography takes,
#: :func:`~glassdist.analyzer.lens.radial_profile_discrepancy`). Measured: the ray-traced camera lenses
#: (barrel, pincushion, moustache, with a lens region and a roller) 0.09 at most, the bundled photos'
#: camera 0.11 at most (eight variants of each, ``benchmarks/lens_photos.py --variants``); a glass lens
#: centred in a pinhole view (the pitch experiment's slanted biconvex lens) 0.29-0.77.
_LENS_CENTRED = 0.2
#: The same with one quadrant about the principal point left out: at most this share. Measured: the
#: ray-traced camera lenses 0.07 at most; the bundled waves photo's camera, through ring waves that
#: carry part of the radial term, 0.13-0.25 over eight variants that leave the pane as it is (a bound
#: of 0.2 refused three of them, and the Direct Method at N = 2 then read 1.38-1.41 of the Comparative
#: instead of 1.02-1.03); the flat pillowed IGU, whose view the joint fit takes for a lens, 0.41 (inner
#: disc 0.32); synthetic glass bumps above 0.2 are refused by ``_LENS_MIN_GAIN`` before this check
#: (``benchmarks/lens_consistency.py``).
_LENS_OFF_AXIS = 0.3


def _lens_strain(H: np.ndarray, lens: LensModel | None, S: _StrainSamples, period_px: float) -> np.ndarray:
    """Like :func:`_strain`, against the homography seen through ``lens``."""
    J = logical_jacobian(H, lens, S.dst[:, 0], S.dst[:, 1]).reshape(-1, 4) * period_px
    return np.max(np.abs(J - S.freq), axis=1)


def _lens_reproj(H: np.ndarray, lens: LensModel | None, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Residual vectors ``dst - lens(H(src))``, px, (n, 2)."""
    q = np.c_[src, np.ones(len(src))] @ H.T
    pu = q[:, :2] / q[:, 2:3]
    if lens is not None:
        pu = np.stack(lens.distort_px(pu[:, 0], pu[:, 1]), axis=1)
    return dst - pu


def _thin(m: np.ndarray) -> np.ndarray:
    """``m`` with at most ``_LENS_MAX_POINTS`` of its samples kept (a regular subsample)."""
    idx = np.flatnonzero(m)
    if len(idx) <= _LENS_MAX_POINTS:
        return m
    out = np.zeros_like(m)
    out[idx[:: int(np.ceil(len(idx) / _LENS_MAX_POINTS))]] = True
    return out


@dataclass(frozen=True)
class LogicalGrid:
    """The logical grid Block I fits: coordinates ``U, V`` (carrier periods) at the samples ``(y, x)`` (px).

    ``valid``: the samples fitted on; ``spacing``: the grid points' spacing (samples);
    ``period_px``: the carrier period; ``step_px``: the sample grid's step ``(dy, dx)``.
    """

    U: np.ndarray
    V: np.ndarray
    y: np.ndarray
    x: np.ndarray
    valid: np.ndarray
    spacing: int
    period_px: float
    step_px: tuple[float, float]


@dataclass(frozen=True)
class LensFitOptions:
    """How :func:`refit_with_lens` fits the lens: inlier threshold (px), image shape, and the optional terms."""

    threshold_px: float
    image_shape: tuple[int, int]
    tangential: bool = False
    principal_point: bool = False


@dataclass(frozen=True)
class LensRefit:
    """:func:`refit_with_lens`'s outcome: the fit and its warnings.

    The fit's ``lens`` is a :class:`~glassdist.analyzer.lens.LensCalibration`.
    """

    fit: HomographyFit
    warnings: tuple[str, ...] = ()


def refit_with_lens(fit: HomographyFit, g: LogicalGrid, opts: LensFitOptions, *,
                    known: LensCalibration | None = None) -> LensRefit:
    """Block I with the camera lens: homography and Brown distortion fitted jointly on the unstrained view.

    As :func:`refit_undistorted`, with the model of :mod:`glassdist.analyzer.lens` in place of
    the bare homography: starting from ``fit`` (no lens) and from a least-squares fit of
    every sample (gross errors, farther than ``_GROSS_PERIODS`` carrier period, trimmed), the
    samples whose local frequencies match the model's within the measured noise are taken as
    undistorted and the model is refitted to them, three times; the start leaving the larger
    share of the view unstrained (at least ``_MIN_CLEAN``) wins, else the fit of every sample.
    The lens is normalised by half the image diagonal about the image centre (the principal
    point, fitted too with ``opts.principal_point``).

    With a ``known`` lens (a calibration photo, a camera file) only the homography is fitted,
    through it, on the samples it leaves unstrained.

    The result carries a :class:`~glassdist.analyzer.lens.LensCalibration`; the lens is
    applied only where it passes :func:`_judged_lens`'s checks (identifiable, significant,
    global, not ambiguous with a centred feature), else ``fit`` is returned with a warning.
    """
    S = _strain_samples(g.U, g.V, g.y, g.x, g.valid, g.step_px, g.period_px)
    if S is None or len(S.src) < 2 * _LENS_MIN_POINTS:
        return LensRefit(fit)
    if known is not None:
        return LensRefit(_refit_through(fit, known, S, g.U, g.V, g.y, g.x, g.valid, g.spacing, g.period_px,
                                        opts.threshold_px))
    h, w = opts.image_shape
    center, scale = ((w - 1) / 2.0, (h - 1) / 2.0), float(np.hypot(w, h) / 2.0)
    kw = dict(center_px=center, scale_px=scale, tangential=opts.tangential, principal_point=opts.principal_point)
    best = _joint_fit(fit, S, g.period_px, kw)
    if best is None:
        return LensRefit(fit)
    return _judged_lens(fit, best, S, g, opts, center, scale)


@dataclass(frozen=True)
class _JointFit:
    """The joint homography-and-lens fit :func:`_joint_fit` keeps: model, its sigma, the samples it leaves unstrained."""

    H: np.ndarray
    lens: LensModel | None
    sigma: Any
    unstrained: np.ndarray
    share: float


def _joint_fit(fit: HomographyFit, S: _StrainSamples, period_px: float, kw: dict[str, Any]) -> _JointFit | None:
    """The two starts of :func:`refit_with_lens` (bare ``fit``, and the fit of every sample), refitted on the unstrained view."""

    def fit_on(m: np.ndarray, H: np.ndarray, lens: LensModel | None) -> Any:
        m = _thin(m)
        return fit_lens_homography(S.src[m], S.dst[m], H, start=None if lens is None else lens.distortion, **kw)

    keep = np.ones(len(S.src), bool)
    H, lens = fit.matrix, None
    for _ in range(3):
        H, lens, sig, _ = fit_on(keep, H, lens)
        keep = np.linalg.norm(_lens_reproj(H, lens, S.src, S.dst), axis=1) < _GROSS_PERIODS * period_px
        if keep.sum() < _LENS_MIN_POINTS:
            return None
    best = _JointFit(H, lens, sig, keep, 0.0)
    for H, lens in ((fit.matrix, None), (best.H, best.lens)):
        m = _lens_strain(H, lens, S, period_px) < S.tol
        for _ in range(3):
            if m.sum() < _LENS_MIN_POINTS:
                break
            H, lens, sig, _ = fit_on(m, H, lens)
            m = _lens_strain(H, lens, S, period_px) < S.tol
        share = float(m.mean())
        if lens is not None and share >= _MIN_CLEAN and share > best.share and m.sum() >= _LENS_MIN_POINTS:
            best = _JointFit(H, lens, sig, m, share)
    return best


_LENS_ADVICE = ("confirm with a calibration photo or a camera file (lens: calibrate_from_photo, calibration_from_camera_file), "
                "or use the Comparative Method")


def _judged_lens(fit: HomographyFit, best: _JointFit, S: _StrainSamples, g: LogicalGrid, opts: LensFitOptions,
                 center: tuple[float, float], scale: float) -> LensRefit:
    """The joint fit applied, or reported and not applied with a warning.

    Not identifiable when its fitted samples do not reach ``_LENS_MIN_REACH`` of the view's
    radius (a radial term is then a change of scale the homography takes). Ambiguous when the
    residual it leaves is radially symmetric about the principal point (``_RADIAL_AMBIGUITY`` of
    its energy, above the fit's own residual and ``_AMBIGUITY_FLOOR_PERIODS``): a centred
    radially symmetric feature cannot be told from the lens. Applied only where it removes
    ``_LENS_MIN_GAIN`` of the mean squared residual a bare homography leaves on the same
    samples, and where it is global: refitted without the inner disc of the view or without
    any quadrant (:func:`~glassdist.analyzer.lens.radial_consistency`), its radial profile moves
    by at most ``_LENS_CENTRED`` (inner disc) and ``_LENS_OFF_AXIS`` (quadrant).
    """
    H, lens, sig, m, share = best.H, best.lens, best.sigma, best.unstrained, best.share
    assert lens is not None  # the joint fit's starts each return a lens
    period_px = g.period_px

    def bare(cal: LensCalibration, *warn: str) -> LensRefit:  # the lens reported, not applied
        return LensRefit(HomographyFit(fit.matrix, fit.inlier_fraction, fit.n_points, fit.rms_inlier_px,
                                       fit.excluded_fraction, cal), warn)

    e = _lens_reproj(H, lens, S.src, S.dst)
    e2 = np.sum(e[m] ** 2, axis=1)
    rms = float(np.sqrt(np.mean(e2)))
    # A radially symmetric residual about the principal point: glass or lens, the grid cannot tell.
    gross = np.linalg.norm(e, axis=1) < _GROSS_PERIODS * period_px
    sym, sym_rms = radial_ambiguity(e[gross], S.dst[gross], center, scale,
                                    noise_px=max(_AMBIGUITY_FLOOR_PERIODS * period_px, 3 * rms if share else 0.0))
    ambiguous = (
        f"a radially symmetric distortion centred on the optical axis ({sym_rms:.2g} px RMS, {100 * sym:.0f}% of what the "
        "lens model leaves) has the form of a camera lens's own distortion, and the Direct Method cannot tell the two "
        "apart" if sym >= _RADIAL_AMBIGUITY else "")
    # Significance: the lens must explain most of what a bare homography leaves on the same samples
    # (a glass distortion over the whole view projects only partly on the lens's radial form).
    H0 = _lsq(S.src[m], S.dst[m])
    bare_ms = 0.0 if H0 is None else float(np.mean(_reproj_error(H0, S.src[m], S.dst[m]) ** 2))
    gain = 0.0 if H0 is None else max(0.0, 1.0 - float(np.mean(e2)) / max(bare_ms, 1e-30))
    if gain < _LENS_MIN_GAIN:
        cal = LensCalibration(lens, "self", sig, False, float(m.mean()), rms, None, gain=gain, note=(
            f"the lens terms explain {100 * gain:.0f}% of what a bare homography leaves (needs "
            f"{100 * _LENS_MIN_GAIN:.0f}%): no lens distortion stands out of the glass's own"))
        return bare(cal, *([f"{ambiguous}: it was kept as glass (no lens distortion stands out of it) - {_LENS_ADVICE}"]
                           if ambiguous else []))
    # Global form: the same radial profile must come out with the inner disc, or any quadrant, left out.
    mt = _thin(m)
    cons = radial_consistency(S.src[mt], S.dst[mt], H, lens, scale_px=scale, tangential=opts.tangential,
                              principal_point=opts.principal_point)
    bounds = {"inner": _LENS_CENTRED, "quadrants": _LENS_OFF_AXIS}
    key = max(bounds, key=lambda k: cons[k] / bounds[k])  # the check exceeded by the wider margin (ties: inner)
    if cons[key] > bounds[key]:
        centred, bound = key == "inner", bounds[key]
        what = ("a radially symmetric distortion centred on the optical axis has the form of a camera lens's own "
                "distortion, and the Direct Method cannot tell the two apart" if centred else
                "the radial term is carried by a local feature off the optical axis")
        note = (f"the lens fitted without the {'inner disc' if centred else 'worst quadrant'} of the view differs by "
                f"{100 * cons[key]:.0f}% (at most {100 * bound:.0f}% for a camera lens, whose distortion is global): "
                + what)
        return bare(LensCalibration(lens, "self", sig, False, float(m.mean()), rms, None, gain=gain, note=note,
                                    consistency=dict(cons)),
                    f"Block I did not apply the lens model fitted from the photo: {note}; it was kept as glass - {_LENS_ADVICE}")
    radius = np.linalg.norm(S.dst - np.asarray(center), axis=1)
    reach = float(np.percentile(radius[m], 95) / max(np.percentile(radius, 95), 1e-9))
    if reach < _LENS_MIN_REACH:
        note = (f"the unstrained part of the view reaches {100 * reach:.0f}% of the view's radius (needs "
                f"{100 * _LENS_MIN_REACH:.0f}%): the lens's growth with radius is not pinned")
        return bare(LensCalibration(lens, "self", sig, False, float(m.mean()), rms, None, gain=gain, note=note),
                    f"Block I could not calibrate the camera lens from the photo: {note}; the baseline is a bare "
                    "homography - give a calibration photo or a camera file "
                    "(lens: calibrate_from_photo, calibration_from_camera_file)")
    if ambiguous:  # the lens fit may hold part of it (its tail reaches the unstrained part): not applied
        note = "a centred radially symmetric feature and the camera lens cannot be separated from the photo alone"
        return bare(LensCalibration(lens, "self", sig, False, float(m.mean()), rms, None, gain=gain, note=note),
                    f"{ambiguous}: it was kept as glass and the lens model was not applied - {_LENS_ADVICE}")
    cal = LensCalibration(lens, "self", sig, True, float(m.mean()), rms, None, gain=gain, consistency=dict(cons))
    src, dst = logical_grid_points(g.U, g.V, g.y, g.x, g.valid, g.spacing)
    err = np.linalg.norm(_lens_reproj(H, lens, src, dst), axis=1)
    inl = err < opts.threshold_px
    rms_inl = float(np.sqrt(np.mean(err[inl] ** 2))) if inl.any() else float("nan")
    return LensRefit(HomographyFit(H, float(inl.mean()), int(len(src)), rms_inl, 1.0 - float(m.mean()), cal))


def _refit_through(fit: HomographyFit, known: LensCalibration, S: _StrainSamples, U, V, y, x, valid, spacing,
                   period_px: float, threshold_px: float) -> HomographyFit:
    """The homography through a known lens: least squares on the samples it leaves unstrained, three times."""
    lens = known.model
    H, m = fit.matrix, np.ones(len(S.src), bool)
    for _ in range(4):
        H, _, _, _ = fit_lens_homography(S.src[_thin(m)], S.dst[_thin(m)], H, center_px=lens.center_px,
                                         scale_px=lens.scale_px, start=lens.distortion, fix_distortion=True)
        m2 = _lens_strain(H, lens, S, period_px) < S.tol
        if m2.sum() < _LENS_MIN_POINTS:
            break
        m = m2
    src, dst = logical_grid_points(U, V, y, x, valid, spacing)
    err = np.linalg.norm(_lens_reproj(H, lens, src, dst), axis=1)
    inl = err < threshold_px
    rms_inl = float(np.sqrt(np.mean(err[inl] ** 2))) if inl.any() else float("nan")
    return HomographyFit(H, float(inl.mean()), int(len(src)), rms_inl, 1.0 - float(m.mean()), known)


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


def logical_coordinates(H: np.ndarray, lens: LensModel | None, x, y):
    """``(U, V)`` of the photo's pixels ``(x, y)``: ``H^{-1}`` of their undistorted position, carrier periods."""
    if lens is not None:
        x, y = lens.undistort_px(x, y)
    return apply_inverse(H, x, y)


def logical_jacobian(H: np.ndarray, lens: LensModel | None, x, y) -> np.ndarray:
    """Jacobian ``d(U, V) / d(x, y)`` of :func:`logical_coordinates` (carrier periods per px), ``(..., 2, 2)``.

    With a lens, the chain rule through the undistortion, whose Jacobian is the inverse of
    the distortion's at the undistorted point.
    """
    if lens is None:
        return inverse_jacobian(H, x, y)
    xu, yu = lens.undistort_px(x, y)
    s = lens.scale_px
    a, b, c, d = lens.distortion.jacobian((xu - lens.center_px[0]) / s, (yu - lens.center_px[1]) / s)
    det = a * d - b * c
    Ju = np.empty(np.shape(xu) + (2, 2))
    Ju[..., 0, 0], Ju[..., 0, 1], Ju[..., 1, 0], Ju[..., 1, 1] = d / det, -b / det, -c / det, a / det
    return inverse_jacobian(H, xu, yu) @ Ju


def _points_spacing(carriers: F.CarrierPair, grid: F.SamplingGrid) -> int:
    period = min(carriers.k1.period_px, carriers.k2.period_px)
    return max(1, int(round(period / min(grid.step))))


# Block I's grid points keep this many carrier periods from the image edges.
_INTERIOR_PERIODS = 1.5


# A part's offset is the rounded median of its logical coordinates against the largest part's
# homography: it is ambiguous once the glass moves the grid within a part by this many periods or more
# (5th to 95th percentile), since a whole-period offset and the glass's own displacement look alike.
_AMBIGUOUS_SPREAD_PERIODS = 1.0


def _ambiguous_offsets(spread: float, n: int, offsets: np.ndarray) -> str | None:
    """The warning when the parts' whole-period offsets cannot be told from the glass's displacement (Block I), else None.

    Measured: on the ray-traced 0.75 mm roller wave (the accuracy experiment, Direct) the region
    falls into five parts and the grid moves by up to 3.1 periods within them; refitted over every
    part with the offsets read from the largest part's homography (5, -4, 2, -3 periods), the
    baseline read phi_eff 23.5 % low, and fitted on the largest part alone (what Block I then does)
    15.4 % low. The bundled waves photo's two parts move by at most 0.86 period, and no other
    ray-traced scene of the experiment has more than one part but the pillowed IGU (0.05 period).
    """
    if spread < _AMBIGUOUS_SPREAD_PERIODS:
        return None
    # whole periods, as integers: a float -0.0 would print '-0'
    taken = ", ".join(f"({round(float(u)):d}, {round(float(v)):d})" for u, v in offsets[2:])
    return (
        f"Direct Method: the analysed region falls into {n} parts and the glass moves the grid by up to "
        f"{spread:.1f} carrier periods within them, so Block I cannot tell the parts' whole-period offsets "
        f"(taken as {taken} periods from the largest part's homography) from the glass's own displacement "
        "and fits the baseline on the largest part alone: its scale, and every phi with it, may still be off "
        "by far more than the stated uncertainty - use the Comparative Method (a glass-less reference)"
    )


@dataclass(frozen=True)
class GridFit:
    """:func:`fit_grid_homography`'s outcome: the fit, the offsets removed per region and Block I's warnings.

    ``offsets``: per region label (index 0 unused), the integer offsets (periods) subtracted from U and V.
    """

    fit: HomographyFit
    offsets: np.ndarray
    warnings: tuple[str, ...] = ()


def fit_grid_homography(UV, yy, xx, labels, n, carriers, grid, p: AnalyzerParams,
                        lens: LensCalibration | None = None) -> GridFit:
    """I1 + I2 over all regions, aligning each region's free integer grid offset to the largest.

    Where those offsets are ambiguous (:func:`_ambiguous_offsets`) the baseline is fitted
    on the largest part alone: the others join it only through offsets that may be wrong, and a
    wrong whole-period offset tilts and scales the homography fitted through it; each part is
    detrended on its own, so its offset does not enter its phi.

    ``UV``: logical grid coordinates (carrier periods) on the demodulation grid ``(yy, xx)``;
    ``labels``/``n``: the valid region's parts (:class:`~glassdist.analyzer.region.Region`);
    ``lens``: a camera lens known beforehand (else fitted per ``p.lens_model``, :func:`refit_with_lens`).

    Returns a :class:`GridFit`: the fit, per region label (index 0 unused) the integer offsets
    (periods) subtracted from U and V, and the warnings.
    """
    warn: list[str] = []
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
    fitted = labels > 0  # the parts the baseline is fitted on
    if n > 1:
        U = U.copy()
        V = V.copy()
        u0, v0 = apply_inverse(fit.matrix, xx, yy)
        spread = 0.0
        for r in range(1, n + 1):
            sel = labels == r
            du, dv = U[sel] - u0[sel], V[sel] - v0[sel]
            spread = max(spread, *(float(np.subtract(*np.percentile(d, [95, 5]))) for d in (du, dv)))
            if r > 1:
                offsets[r] = np.round(np.median(du)), np.round(np.median(dv))
                U[sel] -= offsets[r, 0]
                V[sel] -= offsets[r, 1]
        ambiguous = _ambiguous_offsets(spread, n, offsets)
        if ambiguous:
            warn.append(ambiguous)
            fitted = labels == 1
        else:
            src, dst = logical_grid_points(U, V, yy, xx, (labels > 0) & interior, spacing)
            fit = fit_homography(src, dst, threshold_px=thr, max_trials=p.ransac_max_trials, seed=p.ransac_seed)
    fit = refit_undistorted(
        fit, U, V, yy, xx, fitted & interior, spacing, period_px=period, step_px=grid.step, threshold_px=thr,
    )
    if p.lens_model != "none" or lens is not None:
        refit = refit_with_lens(
            fit, LogicalGrid(U, V, yy, xx, fitted & interior, spacing, period, grid.step),
            LensFitOptions(thr, grid.full_shape, "tangential" in p.lens_model, "center" in p.lens_model), known=lens,
        )
        fit = refit.fit
        warn.extend(refit.warnings)
    if fit.inlier_fraction < 0.1:
        warn.append(
            f"only {100 * fit.inlier_fraction:.0f}% of grid points fit the homography; strong distortion or "
            "lens distortion may bias the Direct Method's baseline"
        )
    return GridFit(fit, offsets, tuple(warn))
