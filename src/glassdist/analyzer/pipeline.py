"""The Distortion Analyzer: Comparative and Direct methods (paper §2.2).

Comparative: F1-F4 against the analytic signal of a glass-less photograph, then A.
Direct: F1-F4 against a synthetic flat carrier (pass 1), Block I fits the
homography of the logical grid, and the distortion phase is taken against the
homography-warped carrier (pass 2, reusing pass 1's unwrapped phase), then A.

A1 (projective, default): carrier *i* measures the displacement along backdrop
grid axis *i* exactly, ``delta_i = p_c phi_i / (2 pi)`` (p_c the carrier period
on the backdrop), whatever the perspective; gradients are taken with respect to
backdrop mm through the Jacobian of the fitted homography, and the result is
rotated into the camera frame (x along columns, y along rows). A1 (isotropic,
the paper's reporting convention): dual-basis inverse ``(M^T)^{-1}`` and the
single scale ``mm_per_px = p_c sqrt(|f1||f2|)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy import ndimage

from .._version import __version__
from ..errors import AnalysisError, InputError
from . import fourier as F
from .homography import HomographyFit, apply_inverse, fit_homography, inverse_jacobian, logical_grid_points
from .metrics import channel_statistics, evaluate_displacement
from .params import AnalyzerParams, load_params
from .unwrap import label_regions, residues, unwrap

__all__ = ["AnalysisResult", "ReferenceModel", "analyze", "prepare_reference"]

log = logging.getLogger(__name__)


class _ImageGridField:
    """A result field kept on the analysis grid, upsampled to the image grid on first access and cached."""

    def __init__(self, name: str):
        self.name = name

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        val = _upsample_deferred(obj._deferred, self.name, obj.valid)
        obj.__dict__[self.name] = val  # frozen dataclass: cache beside, not through, __setattr__
        return val


@dataclass(frozen=True)
class AnalysisResult:
    """Everything the Analyzer measured, on the input image's pixel grid.

    Attributes
    ----------
    method : {'comparative', 'direct'}
    displacement_mm : ndarray (H, W, 2) float32
        delta (x, y) in backdrop mm, camera frame; NaN where invalid. Direct: relative
        to the homography baseline. Comparative: relative to the reference photo.
    displacement_detrended_mm : ndarray (H, W, 2) float32
        delta_* after A2 detrend and metric smoothing (the field differentiated by A3).
    phi_eff_mD, phi_shear_mD, phi_total_mD : ndarray (H, W) float32
        A3 channels, mD; NaN where invalid.
    axis_deg : ndarray (H, W) float32
        Astigmatism principal axis, degrees from +x towards +y, in (-90, 90].
    valid : ndarray (H, W) bool
    mm_per_px : float
        Isotropic scale ``p_c sqrt(|f1||f2|)``, backdrop mm per px.
    sigma_mm, detrend_degree, pitch_mm, distance_m
        The evaluation settings and the physical inputs.
    carrier_period_mm : float
        Carrier period on the backdrop (pitch for lines, pitch*sqrt(2) for checkerboards).
    carriers : CarrierPair
    homography : ndarray (3, 3) or None
        Direct: ``H`` from logical grid (carrier periods) to pixels.
    homography_fit : HomographyFit or None
    params : AnalyzerParams
    warnings : tuple of str
    version : str
    sampling_step_px : (float, float)
        Spacing of the internal demodulation grid.
    """

    method: str
    valid: np.ndarray
    mm_per_px: float
    sigma_mm: float
    detrend_degree: int
    pitch_mm: float
    distance_m: float
    carrier_period_mm: float
    carriers: F.CarrierPair
    homography: np.ndarray | None
    homography_fit: HomographyFit | None
    params: AnalyzerParams
    warnings: tuple[str, ...]
    version: str = __version__
    sampling_step_px: tuple[float, float] = (1.0, 1.0)
    n_regions: int = 1
    _deferred: dict | None = field(default=None, repr=False, compare=False)

    # The fields are carried on the analysis grid and brought to the image's pixel grid on
    # first use (then cached): at 24 Mpx each plane costs ~0.1 s of memory traffic alone,
    # and many callers (statistics on a line, a downsampled heatmap) need only some of them.
    displacement_mm = _ImageGridField("displacement_mm")
    phi_eff_mD = _ImageGridField("phi_eff_mD")
    phi_shear_mD = _ImageGridField("phi_shear_mD")
    phi_total_mD = _ImageGridField("phi_total_mD")
    displacement_detrended_mm = _ImageGridField("displacement_detrended_mm")
    axis_deg = _ImageGridField("axis_deg")

    @property
    def valid_fraction(self) -> float:
        return float(self.valid.mean())

    def statistics(self) -> dict:
        """Per-channel statistics over the valid region (see :func:`channel_statistics`)."""
        return {
            name: channel_statistics(getattr(self, name), self.valid)
            for name in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD")
        }

    def summary(self) -> dict:
        """JSON-serialisable record of the run (written as ``summary.json``)."""
        return {
            "glassdist_version": self.version,
            "method": self.method,
            "image_shape": list(self.valid.shape),
            "pitch_mm": self.pitch_mm,
            "pattern": self.params.pattern,
            "carrier_period_mm": self.carrier_period_mm,
            "distance_m": self.distance_m,
            "mm_per_px": self.mm_per_px,
            "sigma_mm": self.sigma_mm,
            "sigma_px": self.sigma_mm / self.mm_per_px,
            "detrend_degree": self.detrend_degree,
            "carriers": self.carriers.to_dict(),
            "homography": None if self.homography_fit is None else self.homography_fit.to_dict(),
            "valid_fraction": self.valid_fraction,
            "n_regions": self.n_regions,
            "sampling_step_px": list(self.sampling_step_px),
            "statistics": self.statistics(),
            # the smoothing actually used (the default, null, means 2 carrier periods)
            "parameters": {**self.params.resolved(), "sigma_mm": self.sigma_mm},
            "warnings": list(self.warnings),
            "conventions": {
                "displacement": "landing point on the backdrop with glass minus without, mm; [...,0]=x (columns), [...,1]=y (rows)",
                "phi_eff": "tr(sym grad delta)/L in mD, gradients w.r.t. backdrop mm; converging lens -> phi_eff < 0",
                "axis_deg": "astigmatism principal axis, degrees from +x towards +y (down)",
            },
        }


@dataclass(frozen=True)
class ReferenceModel:
    """State derived once from a glass-less reference photo and reused for every frame.

    Holds its spectrum-derived carriers, baseband signals and the homography of its
    (undistorted) grid, so each distorted frame then costs one FFT.
    """

    shape: tuple[int, int]
    carriers: F.CarrierPair
    covariances: tuple[np.ndarray, np.ndarray]
    grid: F.SamplingGrid
    baseband: tuple[np.ndarray, np.ndarray]
    modulation: tuple[np.ndarray, np.ndarray]
    homography: HomographyFit
    params: AnalyzerParams = field(repr=False)


# --------------------------------------------------------------------------- checks


def _check_physical(pitch_mm: float, distance_m: float) -> None:
    if not np.isfinite(pitch_mm) or pitch_mm <= 0:
        raise InputError(f"pitch must be a positive length in mm (got {pitch_mm}); pass --pitch-mm with the printed grid pitch")
    if not np.isfinite(distance_m) or distance_m <= 0:
        raise InputError(
            f"distance must be a positive length in m (got {distance_m}); pass --distance-m with the glass-to-grid distance L"
        )


def _check_image(img: np.ndarray, what: str, warn: list[str]) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim != 2:
        raise InputError(f"the {what} must be a 2-D grey image, got an array of shape {a.shape}")
    a = a.astype(np.float32, copy=False)
    if min(a.shape) < 32:
        raise InputError(f"the {what} is only {a.shape[1]}x{a.shape[0]} px; at least 32x32 px are needed")
    lo, hi = float(a.min()), float(a.max())  # also NaN-detecting: NaN propagates through min/max
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise InputError(f"the {what} contains NaN or infinite values")
    # Exposure statistics need no more than a regular subsample of a large photo.
    k = max(1, int(np.sqrt(a.size / 2_000_000)))
    a_s = a[::k, ::k]
    if hi - lo < 1e-3 or float(a_s.std()) < 2e-3:
        raise InputError(f"the {what} is blank (no contrast); check the exposure and that the grid is in view")
    sat = float(np.mean(a_s >= 0.999 * max(hi, 1e-12))) if hi >= 0.98 else 0.0
    dark = float(np.mean(a_s <= 1e-3))
    if sat > 0.7 or dark > 0.7:
        raise InputError(
            f"the {what} is {'saturated' if sat > 0.7 else 'black'} over {100 * max(sat, dark):.0f}% of its pixels; "
            "re-expose the photo so the grid lines and the background are both visible"
        )
    if sat > 0.02:
        warn.append(f"{what}: {100 * sat:.1f}% of pixels are saturated; phase near them is less reliable")
    if hi - lo < 0.08:
        warn.append(f"{what}: low contrast (intensity range {hi - lo:.3f}); expect a noisier result")
    return a


def _carrier_period_mm(pitch_mm: float, pattern: str) -> float:
    # Checkerboard fundamentals are the diagonal products of the two square waves: period s*sqrt(2).
    return pitch_mm * np.sqrt(2.0) if pattern == "checkerboard" else pitch_mm


# --------------------------------------------------------------------------- stages


def _covariances(carriers: F.CarrierPair, p: AnalyzerParams):
    kw = dict(sigma_along=p.bandpass_sigma_along, sigma_cross=p.bandpass_sigma_cross, isotropic=p.isotropic_bandpass)
    return (
        F.bandpass_covariance(carriers.k1, carriers.k2, **kw),
        F.bandpass_covariance(carriers.k2, carriers.k1, **kw),
    )


def _demodulation_blur_px2(carriers: F.CarrierPair, covs, p: AnalyzerParams) -> np.ndarray:
    """Spatial covariance (px^2) of the low-pass Block F applies to each phase map."""
    out = []
    for c, cov in zip((carriers.k1, carriers.k2), covs):
        s3 = p.smoothing_periods * c.period_px
        out.append(np.linalg.inv(cov) / (4 * np.pi**2) + s3**2 * np.eye(2))
    return np.array(out)


def _basebands(spec: F.Spectrum, carriers: F.CarrierPair, covs, grid: F.SamplingGrid):
    return tuple(F.baseband(spec, c, cov, grid) for c, cov in zip((carriers.k1, carriers.k2), covs))


def _modulation(b: np.ndarray, period_px: float, grid: F.SamplingGrid, p: AnalyzerParams) -> np.ndarray:
    """Local modulation G*|b| (same kernel as F3)."""
    sy, sx = grid.step
    s = p.smoothing_periods * period_px
    return F.gaussian_blur(np.abs(b), (s / sy, s / sx), truncate=3.5)


def _smooth_with_coherence(zs, ks, grid, p: AnalyzerParams, smoothed_abs=None):
    """F3 smoothing of each complex signal and its phase coherence |G*z| / G*|z| in [0, 1].

    ``smoothed_abs``: the G*|z| maps when already known (Direct Method: the modulation).
    """
    out, coh = [], []
    for i, (z, c) in enumerate(zip(zs, ks)):
        s = p.smoothing_periods * c.period_px
        zs_ = F.smooth_complex(z, s, grid)
        a = smoothed_abs[i] if smoothed_abs is not None else _modulation(z, c.period_px, grid, p)
        out.append(zs_)
        coh.append(np.abs(zs_) / np.maximum(a, 1e-30))
    return tuple(out), tuple(coh)


def _downsample_mask(mask: np.ndarray, grid: F.SamplingGrid) -> np.ndarray:
    import cv2

    if grid.is_full:
        return mask.astype(bool)
    h, w = grid.shape
    return cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.999


def _erode(valid: np.ndarray, margin_px: float, grid: F.SamplingGrid, edge_margin_px: float | None = None) -> np.ndarray:
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


def _quality(phases, coherences, mods, carriers, grid, p: AnalyzerParams, user_mask, warn: list[str]):
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
        valid &= _downsample_mask(user_mask, grid)
    valid = _erode(valid, p.border_periods * period, grid, p.edge_margin_periods * period)
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
    return labels > 0, labels, n


def _points_spacing(carriers: F.CarrierPair, grid: F.SamplingGrid) -> int:
    period = min(carriers.k1.period_px, carriers.k2.period_px)
    return max(1, int(round(period / min(grid.step))))


def _fit_grid_homography(UV, yy, xx, labels, n, carriers, grid, p: AnalyzerParams, warn: list[str]):
    """I1 + I2 over all regions, aligning each region's free integer grid offset to the largest.

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
    interior = _erode(np.ones(grid.shape, bool), 0.0, grid, p.border_periods * period)
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


def _polar_rotation(J: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(J)
    return u @ vt


def _image_grid_valid(valid: np.ndarray, grid: F.SamplingGrid, user_mask, fine_valid=None):
    """Valid region on the image grid, and the nearest-valid fill indices of the coarse fields.

    Invalid coarse samples are later filled with their nearest valid value before the
    upsampling (:func:`_upsample_one`), so it never mixes NaN into valid pixels near a border.
    """
    import cv2

    H, W = grid.full_shape
    if not valid.all() and valid.any():
        idx = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    else:
        idx = None
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


_FINAL_STEP_PX = 3.0  # step of the grid the last, bilinear upsampling starts from


def _bspline_upsample(f: np.ndarray, k: int, axis: int) -> np.ndarray:
    """Cubic B-spline interpolation of ``f`` at ``k`` times its density along ``axis``.

    Sample positions follow the area convention of :class:`~glassdist.analyzer.fourier.SamplingGrid`:
    fine sample ``j k + r`` sits at coarse coordinate ``j + (r + 1/2)/k - 1/2``. Each of the
    ``k`` phases is a fixed 4-tap combination of the spline coefficients (Unser 1999).
    """
    c = np.moveaxis(ndimage.spline_filter1d(f, order=3, axis=axis, mode="nearest", output=np.float32), axis, 0)
    n = c.shape[0]
    cp = np.concatenate([c[:1], c[:1], c, c[-1:], c[-1:]])  # coefficients beyond the edge: replicated
    out = np.empty((n * k,) + c.shape[1:], f.dtype)
    for r in range(k):
        t = (r + 0.5) / k - 0.5
        base = int(np.floor(t))
        u = t - base
        w = ((1 - u) ** 3 / 6, (3 * u**3 - 6 * u**2 + 4) / 6, (-3 * u**3 + 3 * u**2 + 3 * u + 1) / 6, u**3 / 6)
        lo = 2 + base - 1
        acc = out[r::k]
        np.multiply(cp[lo : lo + n], np.float32(w[0]), out=acc)
        for i in range(1, 4):
            acc += np.float32(w[i]) * cp[lo + i : lo + i + n]
    return np.moveaxis(out, 0, axis)


def _bspline_refine(f: np.ndarray, k: tuple[int, int]) -> np.ndarray:
    """``f`` (h, w[, c]) interpolated at ``k = (ky, kx)`` times its density, one plane at a time."""
    if k[0] <= 1 and k[1] <= 1:
        return f
    planes = [f] if f.ndim == 2 else [np.ascontiguousarray(f[..., c]) for c in range(f.shape[2])]
    out = []
    for p_ in planes:
        for axis in (0, 1):
            if k[axis] > 1:
                p_ = _bspline_upsample(p_, k[axis], axis)
        out.append(p_)
    return np.ascontiguousarray(out[0]) if f.ndim == 2 else np.stack(out, axis=-1)


def _upsample_one(f: np.ndarray, idx, grid: F.SamplingGrid, invalid: np.ndarray) -> np.ndarray:
    import cv2

    H, W = grid.full_shape
    f = np.ascontiguousarray(f, np.float32)  # (h, w) or (h, w, 2)
    if idx is not None:
        f = f[idx[0], idx[1]]
    if grid.is_full:
        up = f.copy()
    else:
        # Cubic B-spline to an intermediate grid of ~3 px step, then bilinear: the bilinear
        # error (h^2/8)|f''| is ~1% of a wave's amplitude at a 13 px step, ~0.05% at 3 px,
        # and the spline stage works on a grid ~10x smaller than the image.
        f = _bspline_refine(f, tuple(int(st // _FINAL_STEP_PX) for st in grid.step))
        # Into an array numpy allocated (large ones get huge pages): several times faster
        # than letting OpenCV allocate 0.1-0.2 GB of fresh pages.
        up = np.empty((H, W) + f.shape[2:], np.float32)
        cv2.resize(f, (W, H), dst=up, interpolation=cv2.INTER_LINEAR)
    # One plane at a time: a broadcast mask over the channel axis is ~20x slower.
    for plane in [up] if up.ndim == 2 else [up[..., c] for c in range(up.shape[2])]:
        np.copyto(plane, np.float32(np.nan), where=invalid)
    return up


def _upsample_deferred(deferred: dict | None, name: str, valid_full: np.ndarray) -> np.ndarray:
    if deferred is None or name not in deferred["fields"]:
        raise AttributeError(name)
    return _upsample_one(deferred["fields"][name], deferred["idx"], deferred["grid"], ~valid_full)


# Relative local-frequency deviation above which results degrade (ray-traced roller waves:
# right at 0.31, wrong from 0.41; docs/accuracy.md).
_DEVIATION_WARN = 0.35


def _frequency_deviation(phases: np.ndarray, valid: np.ndarray, carriers, step) -> float:
    """99th percentile over ``valid`` of |grad phi_i| / (2 pi |f_i|), the larger of the two carriers.

    The distortion phase's gradient is the local shift of the grid frequency; the
    bandpass passes a limited band around the carrier, so large shifts are attenuated
    (and beyond it the unwrap and the homography fail).
    """
    if valid.sum() < 16:
        return 0.0
    out = 0.0
    for i, c in enumerate(carriers):
        gy, gx = np.gradient(phases[..., i], step[0], step[1])
        g = np.hypot(gx, gy)[valid]
        g = g[np.isfinite(g)]
        if g.size:
            out = max(out, float(np.percentile(g, 99)) / (2 * np.pi * c.norm))
    return out


def _analysis_block(sigma_px: float, blur, grid: F.SamplingGrid, p: AnalyzerParams) -> int:
    """Block factor (1, 2 or 4) of the Block A grid: its step stays below half the residual smoothing."""
    if p.analysis_block != "auto":
        m = int(p.analysis_block)
        return m if grid.shape[0] % m == 0 and grid.shape[1] % m == 0 else 1
    worst = 0.0 if blur is None else max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
    residual = np.sqrt(max(sigma_px**2 - worst, 0.0))
    step = max(grid.step)
    h, w = grid.shape
    for m in (4, 2):
        if h % m == 0 and w % m == 0 and m * step <= residual / 2.0 and min(h, w) // m >= 16:
            return m
    return 1


# --------------------------------------------------------------------------- public API


def _resolve_params(params, pattern) -> AnalyzerParams:
    if isinstance(params, AnalyzerParams):
        return params if pattern is None else params.model_copy(update={"pattern": pattern})
    return load_params(params, pattern=pattern)


def prepare_reference(reference: np.ndarray, *, params: AnalyzerParams | dict | None = None, pattern: str | None = None) -> ReferenceModel:
    """Derive, once, everything the Comparative Method needs from a glass-less photo.

    Parameters
    ----------
    reference : ndarray (H, W)
        Glass-less photograph of the grid, grey in [0, 1].
    params : AnalyzerParams or dict, optional
    pattern : {'lines', 'checkerboard'}, optional
        Overrides ``params.pattern``.
    """
    p = _resolve_params(params, pattern)
    warn: list[str] = []
    ref = _check_image(reference, "reference", warn)
    spec = F.compute_spectrum(ref)
    carriers = F.find_carriers(spec, min_period_px=p.min_period_px)
    F._check_size(ref.shape, max(carriers.k1.period_px, carriers.k2.period_px))
    covs = _covariances(carriers, p)
    grid = F.sampling_grid(ref.shape, list(covs), p.decimation)
    bb = _basebands(spec, carriers, covs, grid)
    mods = tuple(_modulation(b, c.period_px, grid, p) for b, c in zip(bb, (carriers.k1, carriers.k2)))
    # Homography of the reference's own grid: the pixel -> backdrop Jacobian (A1, projective).
    zs, cohs = _smooth_with_coherence(bb, (carriers.k1, carriers.k2), grid, p, smoothed_abs=mods)
    wrapped = [np.angle(z) for z in zs]
    valid, labels, n = _quality(wrapped, cohs, mods, carriers, grid, p, None, [])
    if n == 0:
        raise InputError("the reference photo shows no usable grid region; check it is in focus and well exposed")
    yy, xx = grid.coords()
    psi = [unwrap(w, valid, labels, n, seed=p.ransac_seed) for w in wrapped]
    U = carriers.k1.fx * xx + carriers.k1.fy * yy + psi[0] / (2 * np.pi)
    V = carriers.k2.fx * xx + carriers.k2.fy * yy + psi[1] / (2 * np.pi)
    fit, _ = _fit_grid_homography((U, V), yy, xx, labels, n, carriers, grid, p, [])
    return ReferenceModel(ref.shape, carriers, covs, grid, bb, mods, fit, p)


def analyze(
    image: np.ndarray,
    *,
    pitch_mm: float,
    distance_m: float,
    reference: np.ndarray | ReferenceModel | None = None,
    params: AnalyzerParams | dict | None = None,
    mask: np.ndarray | None = None,
    pattern: str | None = None,
) -> AnalysisResult:
    """Measure the distortion field of a photo of a grid seen through glass.

    Parameters
    ----------
    image : ndarray (H, W)
        Grey photo in [0, 1] (see :func:`glassdist.io.read_image`), indexed (row, col).
    pitch_mm : float
        Printed grid pitch, mm (line spacing; square size for a checkerboard).
    distance_m : float
        Glass-to-backdrop distance L, m.
    reference : ndarray (H, W) or ReferenceModel, optional
        Glass-less photo: Comparative Method. None: Direct Method.
    params : AnalyzerParams or dict, optional
        Algorithm parameters (dict = overrides of the shipped defaults).
    mask : ndarray of bool (H, W), optional
        User region; False pixels are excluded.
    pattern : {'lines', 'checkerboard'}, optional
        Overrides ``params.pattern``.

    Returns
    -------
    AnalysisResult

    Raises
    ------
    InputError
        Bad physical inputs or images (blank, saturated, no grid, too small, size mismatch).
    AnalysisError
        No reliable region could be analysed.

    Notes
    -----
    Carrier *i* of the distorted photo has phase
    ``Phi_i(r) = 2 pi (e_i . X(r)) / p_c``, X(r) the backdrop point seen at r. The
    heterodyne against the reference (real or synthesised) leaves
    ``phi_i = 2 pi (e_i . delta) / p_c`` so that, exactly,

    .. math:: \\delta_i = \\frac{p_c}{2\\pi}\\,\\varphi_i .

    References
    ----------
    Paper §2.2; Takeda et al. (1982); Herraez et al. (2002); Fischler & Bolles (1981).
    """
    _check_physical(float(pitch_mm), float(distance_m))
    warn: list[str] = []
    if isinstance(reference, ReferenceModel):
        refm = reference
        p = refm.params if params is None and pattern is None else _resolve_params(params, pattern)
    elif reference is not None:
        p = _resolve_params(params, pattern)
        refm = None
    else:
        p = _resolve_params(params, pattern)
        refm = None
    img = _check_image(image, "image", warn)
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != img.shape:
            raise InputError(f"the mask is {mask.shape[1]}x{mask.shape[0]} px but the image is {img.shape[1]}x{img.shape[0]} px")
        if not mask.any():
            raise InputError("the mask excludes every pixel; non-zero mask pixels mark the region to analyse")
    if reference is not None and refm is None:
        ref_arr = np.asarray(reference)
        if ref_arr.shape != img.shape:
            raise InputError(
                f"the reference is {ref_arr.shape[1] if ref_arr.ndim > 1 else '?'}x{ref_arr.shape[0]} px but the image is "
                f"{img.shape[1]}x{img.shape[0]} px; both photos must come from the same camera position and size"
            )
        refm = prepare_reference(ref_arr, params=p)
    if refm is not None and refm.shape != img.shape:
        raise InputError(f"the reference is {refm.shape[1]}x{refm.shape[0]} px but the image is {img.shape[1]}x{img.shape[0]} px")
    p_c = _carrier_period_mm(float(pitch_mm), p.pattern)

    spec = F.compute_spectrum(img)
    if refm is None:
        method = "direct"
        carriers = F.find_carriers(spec, min_period_px=p.min_period_px)
        F._check_size(img.shape, max(carriers.k1.period_px, carriers.k2.period_px))
        covs = _covariances(carriers, p)
        grid = F.sampling_grid(img.shape, list(covs), p.decimation)
    else:
        method = "comparative"
        carriers, covs, grid = refm.carriers, refm.covariances, refm.grid
        own = F.find_carriers(spec, min_period_px=p.min_period_px)  # raises if the photo shows no grid
        del own
    ks = (carriers.k1, carriers.k2)
    if refm is None:
        # Direct: F3 applied in the spectral patch; coherence against the modulation G*|b|.
        pairs = [F.baseband(spec, c, cov, grid, smooth_sigma_px=p.smoothing_periods * c.period_px) for c, cov in zip(ks, covs)]
        del spec
        mods = [_modulation(b, c.period_px, grid, p) for (b, _), c in zip(pairs, ks)]
        zs = tuple(gb for _, gb in pairs)
        cohs = tuple(np.abs(z) / np.maximum(m_, 1e-30) for z, m_ in zip(zs, mods))
        del pairs
    else:
        bb = _basebands(spec, carriers, covs, grid)
        del spec
        mods = [_modulation(b, c.period_px, grid, p) for b, c in zip(bb, ks)]
        zs = tuple(b * np.conj(r) for b, r in zip(bb, refm.baseband))
        mods += list(refm.modulation)
        zs, cohs = _smooth_with_coherence(zs, ks, grid, p)  # F3
    wrapped = [np.angle(z) for z in zs]
    valid, labels, n = _quality(wrapped, cohs, mods, carriers, grid, p, mask, warn)
    if n:
        # Grid modulation: amplitude of the fundamental (|b| is half of it), intensity units.
        amp = 2.0 * min(float(np.median(m_[valid])) for m_ in mods[:2])
        if amp < 0.03:
            warn.append(f"low grid contrast (carrier amplitude {amp:.3f} of full scale); expect a noisier result")
    if n == 0:
        raise AnalysisError(
            "no region of the photo carries a reliable grid signal; check focus, exposure and that the grid fills the view"
        )
    psi = [unwrap(w, valid, labels, n, seed=p.ransac_seed) for w in wrapped]  # F4
    yy, xx = grid.coords()

    # Phases against the flat carrier (Direct pass 1) or the reference (Comparative).
    phases = np.stack(psi, axis=-1).astype(np.float32)
    del psi
    fit = None
    if method == "direct":
        U = carriers.k1.fx * xx + carriers.k1.fy * yy + phases[..., 0] / (2 * np.pi)
        V = carriers.k2.fx * xx + carriers.k2.fy * yy + phases[..., 1] / (2 * np.pi)
        fit, offsets = _fit_grid_homography((U, V), yy, xx, labels, n, carriers, grid, p, warn)  # Block I
        del U, V
        if n > 1:
            phases -= (2 * np.pi * offsets[labels]).astype(np.float32)
        H_jac = fit.matrix
    else:
        H_jac = refm.homography.matrix
    phases[~valid] = np.nan

    blur = _demodulation_blur_px2(carriers, covs, p) if p.compensate_demodulation_blur else None
    mm_per_px = p_c * float(np.sqrt(carriers.k1.norm * carriers.k2.norm))
    sigma_mm = p.sigma_mm if p.sigma_mm is not None else p.sigma_periods * p_c
    if blur is not None:
        s_px = sigma_mm / mm_per_px
        worst = max(float(np.max(np.linalg.eigvalsh(b))) for b in blur)
        if worst > s_px**2:
            warn.append(
                f"sigma_mm = {sigma_mm:.3g} mm ({s_px:.1f} px) is finer than the demodulation resolution "
                f"({np.sqrt(worst):.1f} px); the effective smoothing is coarser than requested"
            )
    # Block A runs on block means of the demodulation grid, as coarse as the reporting
    # smoothing allows (step <= sigma/2; the box blur joins the compensated budget).
    m = _analysis_block(sigma_mm / mm_per_px, blur, grid, p)
    agrid = F.block_grid(grid, m)
    valid_f = valid
    if m > 1:
        phases, fill = F.block_mean(phases, valid, m)
        hb, wb = agrid.shape
        block_label = labels.reshape(hb, m, wb * m).max(axis=1).reshape(hb, wb, m).max(axis=2)
        # Whole blocks only (their mean sits at the block centre); partial border blocks
        # get the smooth extrapolation from inside, and the fine mask trims them below.
        labels = np.where(fill >= 1.0, block_label, 0)
        valid = labels > 0
        report = ndimage.binary_dilation(valid, iterations=1) & (fill > 0)
        if blur is not None:
            blur = blur + (m * max(grid.step)) ** 2 / 12.0 * np.eye(2)
        yy, xx = agrid.coords()
    else:
        report = valid
    if fit is not None:
        # Pass 2, against the homography-warped carrier: phase += 2 pi (f . r - H^-1(r)). The
        # term is smooth (affine up to perspective), so on the Block A grid its value at the
        # block centre equals its block mean.
        u0, v0 = apply_inverse(fit.matrix, xx, yy)
        phases = phases + 2 * np.pi * np.stack(
            [carriers.k1.fx * xx + carriers.k1.fy * yy - u0, carriers.k2.fx * xx + carriers.k2.fy * yy - v0], axis=-1
        )
    deviation = _frequency_deviation(phases, valid, ks, agrid.step)
    if deviation > _DEVIATION_WARN:
        warn.append(
            f"strong distortion: the local grid frequency departs from the carrier by up to {100 * deviation:.0f}% "
            f"(results were reliable up to about {100 * _DEVIATION_WARN:.0f}% in tests); the result may be attenuated or wrong - "
            "use a finer grid, a shorter distance L or the Comparative Method"
        )
    if p.a1_mode == "projective":
        delta = phases * (p_c / (2 * np.pi))  # grid-frame components, exact
        J = p_c * inverse_jacobian(H_jac, xx, yy)
        hc, wc = agrid.shape
        R = _polar_rotation(J[hc // 2, wc // 2])
        ch = evaluate_displacement(
            delta, valid, distance_m=distance_m, mm_per_px=mm_per_px, detrend_degree=p.detrend_degree,
            sigma_mm=sigma_mm, jacobian=J, labels=labels, step_px=agrid.step, component_blur_px2=blur, frame_rotation=R,
            report_mask=report,
        )
        delta_cam = delta @ R
    else:
        M = np.array([ks[0].f / ks[0].norm, ks[1].f / ks[1].norm]).T  # columns: unit carriers
        proj_px = phases / (2 * np.pi * np.array([ks[0].norm, ks[1].norm]))
        d_px = proj_px @ np.linalg.inv(M)  # (M^T)^{-1} p in row-vector form
        delta_cam = d_px * mm_per_px
        iso_blur = None if blur is None else np.repeat((np.trace(blur, axis1=1, axis2=2).mean() / 2 * np.eye(2))[None], 2, 0)
        ch = evaluate_displacement(
            delta_cam, valid, distance_m=distance_m, mm_per_px=mm_per_px, detrend_degree=p.detrend_degree,
            sigma_mm=sigma_mm, labels=labels, step_px=agrid.step, component_blur_px2=iso_blur, report_mask=report,
        )

    fields = {
        "displacement_mm": delta_cam, "phi_eff_mD": ch.phi_eff_mD, "phi_shear_mD": ch.phi_shear_mD,
        "phi_total_mD": ch.phi_total_mD, "displacement_detrended_mm": ch.displacement_detrended_mm,
        "axis_deg": ch.axis_deg,
    }
    valid_c = report.copy()
    for f_ in fields.values():
        valid_c &= np.isfinite(f_) if f_.ndim == 2 else np.all(np.isfinite(f_), axis=-1)
    valid_full, idx = _image_grid_valid(valid_c, agrid, mask, fine_valid=valid_f if m > 1 else None)
    cover = float(valid_full[::4, ::4].mean())  # the reported region, as summary.json states it
    if cover < 0.75:
        warn.append(f"only {100 * cover:.0f}% of the image could be analysed (occlusion, frames, low contrast or blur)")
    for w in warn:
        log.warning(w)
    return AnalysisResult(
        method=method,
        valid=valid_full,
        mm_per_px=mm_per_px,
        sigma_mm=float(sigma_mm),
        detrend_degree=p.detrend_degree,
        pitch_mm=float(pitch_mm),
        distance_m=float(distance_m),
        carrier_period_mm=p_c,
        carriers=carriers,
        homography=None if fit is None else fit.matrix,
        homography_fit=fit,
        params=p,
        warnings=tuple(warn),
        sampling_step_px=agrid.step,
        n_regions=n,
        _deferred={"fields": fields, "idx": idx, "grid": agrid},
    )
