"""Several captures of one pane, registered and averaged into one map (paper §3.3).

Repeated exposures, or exposures after small camera moves, of the same set-up: each
capture is measured up to the Block A grid (F1-F4, Block I), its displacement is carried
onto the first capture's grid through the grid homographies, the fields are averaged where
they are valid (a count map records how many captures each sample holds), and A1-A3 run
once on the average.

Why average the displacement and not the channels: the displacement (the unwrapped phase)
is linear in the noise of the photo, so its noise averages down as 1/sqrt(n); phi_shear and
phi_total are magnitudes, whose noise is rectified (E|noise| > 0) and would not average
away. Averaging the displacement and computing the channels once keeps every nonlinear step
after the average. (Averaging the photos themselves would need them resampled, which blurs
the grid, and fails once the camera moved.)

Registration. Capture *k* gives, at each sample, the logical grid coordinate (carrier
periods) that its line of sight lands on with the glass,
``U_k(r) = B_k^{-1}(r) + phi_k(r) / 2 pi`` (``B_k`` its baseline homography: the Direct
fit, or the reference's grid). A camera rotation maps every line of sight of capture 1 to
one of capture *k* through the homography of the backdrop plane,
``T_k = G_k o (P_k^{-1} (G_1^{-1} - o_k))`` with ``G`` each capture's grid homography,
``P_k`` the signed permutation between the two captures' carrier labels and ``o_k`` their
integer grid offset. Capture *k*'s displacement in capture 1's frame is then

.. math:: \\varphi_{k \\to 1}(\\mathbf r) = 2\\pi\\left[P_k\\,U_k(T_k\\mathbf r) + o_k - B_1^{-1}(\\mathbf r)\\right],

exact for rotations; a translation adds the parallax between the glass and the backdrop
planes. Each registered field has its degree-N trend removed before the average (the
captures' baselines differ by smooth projective fields, and the count changes across the
map); A2 detrends the average again.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Sequence

import numpy as np
from scipy import ndimage

from ..errors import InputError
from .analysis_grid import AnalysisGrid
from .homography import apply_inverse, fit_homography, logical_coordinates, logical_grid_points
from .metrics import masked_gaussian, polynomial_detrend
from .params import AnalyzerParams
from .pipeline import (
    Measurement,
    ReferenceModel,
    analyze,
    evaluate,
    measure,
    prepare_reference,
    resolve_params,
    result_of,
    routed_warnings,
)
from .plausibility import review_measurement
from .region import min_region_samples, trusted_on
from .result import AnalysisResult
from .unwrap import label_regions

__all__ = ["analyze_captures", "sample_field"]

log = logging.getLogger(__name__)


_PAD = 4  # samples of smooth extrapolation around a field before its spline is fitted


def _spline_ready(field: np.ndarray) -> np.ndarray:
    """``field`` padded by :data:`_PAD` samples, its NaN samples and the padding filled smoothly.

    A cubic B-spline through a field extended by constants (or mirrored) bends near its
    edges; first-order normalised convolution (:func:`~glassdist.analyzer.metrics.masked_gaussian`)
    continues it along its local plane instead, then the nearest value fills what is left.
    """
    f = np.pad(np.asarray(field, dtype=float), _PAD, constant_values=np.nan)
    bad = ~np.isfinite(f)
    if bad.any() and not bad.all():
        ext = masked_gaussian(f, (~bad).astype(float), (1.5 * _PAD) ** 2 * np.eye(2), min_weight=1e-6)
        f = np.where(bad, ext, f)
        still = ~np.isfinite(f)
        if still.any():
            idx = ndimage.distance_transform_edt(still, return_distances=False, return_indices=True)
            f = f[idx[0], idx[1]]
    return ndimage.spline_filter(np.nan_to_num(f), order=3, mode="nearest")


def _invalid_weight(field: np.ndarray, rows, cols) -> np.ndarray:
    bad = (~np.isfinite(np.asarray(field, dtype=float))).astype(float)
    return ndimage.map_coordinates(bad, [rows, cols], order=1, mode="constant", cval=1.0)


def sample_field(field: np.ndarray, rows: np.ndarray, cols: np.ndarray, *, max_invalid_weight: float = 0.0) -> np.ndarray:
    """Cubic B-spline samples of ``field`` (h, w) at fractional ``(rows, cols)``, NaN-aware.

    A sample is NaN where more than ``max_invalid_weight`` of its *bilinear* weight falls on
    NaN samples or outside the field. Linear interpolation would attenuate a wave of
    wavelength W sampled at step h by up to cos(pi h / W) between samples (3% at W = 8 h);
    the spline keeps it, and keeps a plane exactly (the field is continued along its local
    plane beyond its edges, see :func:`_spline_ready`).

    Parameters
    ----------
    field : ndarray (h, w)
        NaN marks invalid samples.
    rows, cols : ndarray
        Sample coordinates in index units (row 0 = first row).
    max_invalid_weight : float
        In [0, 1).

    Returns
    -------
    ndarray like ``rows`` (float64)
    """
    coef = _spline_ready(field)
    return _sample_ready(coef, _invalid_weight(field, rows, cols), rows, cols, max_invalid_weight)


def _sample_ready(coef, invalid_weight, rows, cols, max_invalid_weight):
    v = ndimage.map_coordinates(coef, [rows + _PAD, cols + _PAD], order=3, mode="nearest", prefilter=False)
    return np.where(invalid_weight > max(max_invalid_weight, 1e-9), np.nan, v)


def _phases(m: Measurement) -> np.ndarray:
    """The capture's phases (h, w, 2) on its analysis grid, NaN outside its valid region (whole blocks)."""
    return np.where(m.ag.valid[..., None], m.ag.phases, np.nan)


def _logical(m: Measurement):
    """``U_k`` (h, w, 2) on the capture's analysis grid, carrier periods (NaN where invalid)."""
    yy, xx = m.ag.grid.coords()
    u0, v0 = logical_coordinates(m.baseline, None if m.fit is None else m.fit.lens_model, xx, yy)
    return np.stack([u0, v0], axis=-1) + _phases(m) / (2 * np.pi)


def _grid_homography(m: Measurement, U: np.ndarray) -> np.ndarray:
    """``G``: logical grid -> pixels of the capture's own grid (Direct: Block I's fit; Comparative: fitted alike)."""
    if m.fit is not None:
        return m.fit.matrix
    p = m.inputs.params
    ks = (m.carriers.k1, m.carriers.k2)
    yy, xx = m.ag.grid.coords()
    ok = m.ag.valid & np.all(np.isfinite(U), axis=-1)
    spacing = max(1, int(round(min(k.period_px for k in ks) / min(m.ag.grid.step))))
    src, dst = logical_grid_points(U[..., 0], U[..., 1], yy, xx, ok, spacing)
    thr = p.ransac_threshold_periods * min(k.period_px for k in ks)
    return fit_homography(src, dst, threshold_px=thr, max_trials=p.ransac_max_trials, seed=p.ransac_seed).matrix


def _carrier_permutation(m1: Measurement, mk: Measurement) -> np.ndarray:
    """Signed permutation ``P`` with ``U_1 ~ P U_k + o`` (the captures may label their carriers differently)."""
    A1 = np.array([[m1.carriers.k1.fx, m1.carriers.k1.fy], [m1.carriers.k2.fx, m1.carriers.k2.fy]])
    Ak = np.array([[mk.carriers.k1.fx, mk.carriers.k1.fy], [mk.carriers.k2.fx, mk.carriers.k2.fy]])
    M = A1 @ np.linalg.inv(Ak)
    P = np.round(M)
    if not (np.all(np.isin(P, (-1.0, 0.0, 1.0))) and abs(abs(np.linalg.det(P)) - 1.0) < 1e-9 and np.abs(M - P).max() < 0.3):
        raise InputError(
            "the captures do not show the same grid (their carriers differ by more than a small camera move); "
            "pass photos of one set-up taken from about the same position"
        )
    return P


def _registered(m1: Measurement, U1_base: np.ndarray, G1: np.ndarray, mk: Measurement, Gk, offset, P, ready,
                sl=(slice(None), slice(None))) -> tuple:
    """Capture k's phases on capture 1's grid (rad, NaN where not covered) and the shift of each sample (px).

    ``sl``: a subsampling of capture 1's grid (``U1_base`` is given on it).
    """
    yy, xx = (a[sl] for a in m1.ag.grid.coords())
    u1, v1 = apply_inverse(G1, xx, yy)
    Pinv = np.linalg.inv(P)
    uk = Pinv[0, 0] * (u1 - offset[0]) + Pinv[0, 1] * (v1 - offset[1])
    vk = Pinv[1, 0] * (u1 - offset[0]) + Pinv[1, 1] * (v1 - offset[1])
    xk, yk = apply_inverse(np.linalg.inv(Gk), uk, vk)
    g = mk.ag.grid
    rows, cols = (yk - g.offset[0]) / g.step[0], (xk - g.offset[1]) / g.step[1]
    w = _invalid_weight(ready[2], rows, cols)
    ph = np.stack([_sample_ready(ready[c], w, rows, cols, 0.25) for c in range(2)], axis=-1)
    bu, bv = logical_coordinates(mk.baseline, None if mk.fit is None else mk.fit.lens_model, xk, yk)
    Uk = np.stack([bu, bv], axis=-1) + ph / (2 * np.pi)
    U = Uk @ P.T + np.asarray(offset, float)
    return 2 * np.pi * (U - U1_base), np.hypot(xk - xx, yk - yy)


def _aligned_to_first(ph: np.ndarray, first: np.ndarray, degree: int) -> np.ndarray:
    """``ph`` minus the degree-N polynomial that fits ``ph - first`` where both are valid.

    The registered fields differ from the first capture's by their noise and by a smooth
    residue of the registration (the grid homographies absorb slightly different parts of
    the distortion); the fit removes the residue and leaves the distortion itself alone.
    """
    both = np.all(np.isfinite(ph), axis=-1) & np.all(np.isfinite(first), axis=-1)
    own = np.all(np.isfinite(ph), axis=-1)
    if both.sum() < 4 * (degree + 1) ** 2:
        return ph
    h, w = own.shape
    yy, xx = np.mgrid[0:h, 0:w]
    x, y = (xx - w / 2.0) / (w / 2.0), (yy - h / 2.0) / (h / 2.0)
    A = np.stack([x**i * y**(n - i) for n in range(degree + 1) for i in range(n + 1)], axis=-1)
    coef, *_ = np.linalg.lstsq(A[both], (ph - first)[both], rcond=None)
    out = np.full_like(ph, np.nan)
    out[own] = ph[own] - A[own] @ coef
    return out


def _detrended(phases: np.ndarray, degree: int, step) -> np.ndarray:
    ok = np.all(np.isfinite(phases), axis=-1)
    if ok.sum() < 16:
        return np.full_like(phases, np.nan)
    return polynomial_detrend(phases, ok.astype(np.int32), degree, step)


def _register_capture(m1: Measurement, U1_base, G1, mk: Measurement, degree: int):
    """Capture k on capture 1's grid, with the grid offset that best matches capture 1's field.

    A periodic grid fixes the offset between two captures only modulo one period. Starting
    from the offset nearest the image centre's, neighbouring offsets (up to two periods
    away) are taken while they match capture 1's distortion clearly better: moves of more
    than half a period, up to about 2.5 periods, register on a distorted pane.
    """
    P = _carrier_permutation(m1, mk)
    H, W = m1.ag.grid.full_shape
    c = np.array([(W - 1) / 2.0]), np.array([(H - 1) / 2.0])
    Gk = _grid_homography(mk, _logical(mk))
    u1c = np.array(apply_inverse(G1, *c)).ravel()
    ukc = np.array(apply_inverse(Gk, *c)).ravel()
    o0 = np.round(u1c - P @ ukc)
    # Offsets are scored on every other sample (the fields are smooth on the analysis grid).
    sl = (slice(None, None, 2), slice(None, None, 2))
    step = tuple(2 * st for st in m1.ag.grid.step)
    ref = _detrended(_phases(m1)[sl], degree, step)
    ref[~trusted_on(m1.quality, m1.ag.grid.shape)[sl]] = np.nan  # scored where capture 1 is trusted
    own = _phases(mk)
    ready = [_spline_ready(own[..., c]) for c in range(2)] + [own[..., 0]]
    U1_sub = U1_base[sl]

    def trial(o):
        det = _detrended(_registered(m1, U1_sub, G1, mk, Gk, o, P, ready, sl)[0], degree, step)
        return det, np.all(np.isfinite(det), axis=-1) & np.all(np.isfinite(ref), axis=-1)

    def rms(det, on):
        return float(np.sqrt(np.mean((det[on] - ref[on]) ** 2)))

    # Descent over the integer offsets from the centre's: a neighbour replaces the current
    # offset when it matches capture 1's field more than 10% better on the samples both
    # cover (without distortion to match, flat glass, all match alike and the centre's stays).
    cur = o0
    cur_det, cur_on = trial(cur)
    for _ in range(4):
        moves = []
        for d in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            o = cur + d
            if np.abs(o - o0).max() > 2:
                continue
            det, on = trial(o)
            common = on & cur_on
            if common.sum() >= 16:
                ratio = rms(det, common) / max(rms(cur_det, common), 1e-30)
                if ratio < 0.9:
                    moves.append((ratio, o, det, on))
        if not moves:
            break
        _, cur, cur_det, cur_on = min(moves, key=lambda m_: m_[0])
    if cur_on.sum() < 0.25 * max(np.isfinite(ref[..., 0]).sum(), 1):
        raise InputError("a capture does not overlap the first one by a quarter of its area; pass captures of one set-up")
    ph, moved = _registered(m1, U1_base, G1, mk, Gk, cur, P, ready)
    return cur, P, ph, moved


def analyze_captures(
    images: Sequence[np.ndarray],
    *,
    pitch_mm: float,
    distance_m: float,
    reference: np.ndarray | ReferenceModel | None = None,
    params: AnalyzerParams | dict | None = None,
    mask: np.ndarray | None = None,
    pattern: str | None = None,
) -> AnalysisResult:
    """One map from several captures of the same set-up, registered and averaged.

    Parameters
    ----------
    images : sequence of ndarray (H, W)
        Grey photos in [0, 1] of the same pane and backdrop: repeated exposures, or small
        camera moves (rotations; translations add parallax between glass and backdrop).
        The first capture defines the frame of the result.
    pitch_mm, distance_m, reference, params, mask, pattern
        As for :func:`~glassdist.analyzer.analyze`; one reference (Comparative Method) and one
        mask (in each capture's pixels) serve every capture.

    Returns
    -------
    AnalysisResult
        On the first capture's grid, relative to the first capture's baseline (Direct: its
        homography; Comparative: the reference); the extra field
        ``capture_count`` holds how many captures each sample averages. A single image gives
        exactly :func:`~glassdist.analyzer.analyze`'s result.

    Notes
    -----
    The noise of the average falls as ``1/sqrt(n)`` where ``n`` captures overlap
    (``docs/multi_capture.md``). With the Comparative Method the reference photo's own
    noise is common to every capture and does not average down.

    References
    ----------
    Paper §3.3 (averaging over the residual geometric variability).
    """
    images = list(images)
    if not images:
        raise InputError("no image given; pass at least one photo")
    if len(images) == 1:
        return analyze(images[0], pitch_mm=pitch_mm, distance_m=distance_m, reference=reference, params=params,
                       mask=mask, pattern=pattern)
    _check_same_camera(images)
    with routed_warnings() as numerical:
        meas, warn = _measured_captures(images, pitch_mm, distance_m, reference, params, mask, pattern)
        refm = meas[0].inputs.reference  # the slips are the run's: checked on the first capture, as analyze does
        warn += tuple(review_measurement(np.shape(images[0]), None if refm is None else refm.grid_spread,
                                         meas[0].grid_spread,
                                         mm_per_px=meas[0].mm_per_px, distance_m=distance_m, pitch_mm=pitch_mm))
        total, count, records = _registered_sums(meas)
        ag, n, w_avg = _averaged_grid(meas[0], total, count, len(meas))
        warn += w_avg
        ev = evaluate(meas[0], ag, warn)
    for r in records:
        log.info("capture %(capture)d: grid offset %(grid_offset)s, largest shift %(max_shift_px).2f px", r)
    res = result_of(meas[0], ev, warn + ev.warnings + tuple(numerical),
                    extra_fields={"capture_count": count.astype(np.int16)}, n_regions=n)
    return replace(res, captures=tuple(records))


def _check_same_camera(images: list) -> None:
    """Raise :class:`~glassdist.errors.InputError` unless every capture has the first one's size.

    Parameters
    ----------
    images : list of ndarray (H, W)
        The captures, the first defining the frame.
    """
    shape = np.shape(images[0])
    for i, img in enumerate(images[1:], start=2):
        if np.shape(img) != shape:
            raise InputError(
                f"capture {i} is {np.shape(img)[1]}x{np.shape(img)[0]} px but the first is {shape[1]}x{shape[0]} px; "
                "captures of one set-up come from the same camera"
            )


def _measured_captures(images: list, pitch_mm: float, distance_m: float, reference, params, mask,
                       pattern) -> tuple[list[Measurement], tuple[str, ...]]:
    """Every capture measured up to its analysis grid (F1-F4, Block I), the reference prepared once.

    Parameters
    ----------
    images : list of ndarray (H, W)
        Grey photos in [0, 1].
    pitch_mm, distance_m, reference, params, mask, pattern
        As for :func:`analyze_captures`.
    Returns
    -------
    list of Measurement
        One per capture, in order.
    tuple of str
        The warnings: the first capture's as they are, a later capture's prefixed with its
        number and only when the first did not give the same one.
    """
    if reference is not None and not isinstance(reference, ReferenceModel):
        reference = prepare_reference(reference, params=resolve_params(params, pattern))
    meas = []
    warn: list[str] = []
    for i, img in enumerate(images, start=1):
        m = measure(img, pitch_mm, distance_m, reference, params, mask, pattern)
        meas.append(m)
        warn.extend(w if i == 1 else f"capture {i}: {w}" for w in m.warnings if i == 1 or w not in warn)
    return meas, tuple(warn)


def _registered_sums(meas: list[Measurement]) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Every capture's phases carried onto the first capture's grid and summed where valid.

    Parameters
    ----------
    meas : list of Measurement
        The captures, the first defining the frame.

    Returns
    -------
    total : ndarray (h, w, 2)
        Sum of the registered phases (rad) on the first capture's analysis grid.
    count : ndarray (h, w) of int32
        How many captures each sample sums.
    records : list of dict
        One per capture: grid offset, carrier permutation, largest shift (px, over the first
        capture's trusted samples) and valid fraction.
    """
    m1 = meas[0]
    degree = m1.inputs.params.detrend_degree
    yy, xx = m1.ag.grid.coords()
    U1_base = np.stack(logical_coordinates(m1.baseline, None if m1.fit is None else m1.fit.lens_model, xx, yy), axis=-1)
    G1 = _grid_homography(m1, _logical(m1))
    total = np.zeros(m1.ag.phases.shape)
    count = np.zeros(m1.ag.grid.shape, np.int32)
    first = _phases(m1)
    ok = np.all(np.isfinite(first), axis=-1)
    total[ok] += first[ok]
    count += ok
    records = [{"capture": 1, "grid_offset": [0, 0], "carrier_permutation": np.eye(2).tolist(), "max_shift_px": 0.0,
                "valid_fraction": float(ok.mean())}]
    trusted = trusted_on(m1.quality, m1.ag.grid.shape)  # shifts read where capture 1 is trusted
    for i, mk in enumerate(meas[1:], start=2):
        o, P, ph, moved = _register_capture(m1, U1_base, G1, mk, degree)
        ph = _aligned_to_first(ph, first, degree)
        ok = np.all(np.isfinite(ph), axis=-1)
        total[ok] += ph[ok]
        count += ok
        records.append({"capture": i, "grid_offset": [int(o[0]), int(o[1])], "carrier_permutation": (P + 0.0).tolist(),
                        "max_shift_px": float(np.nanmax(np.where(trusted, moved, np.nan))),
                        "valid_fraction": float(ok.mean())})
    return total, count, records


def _averaged_grid(m1: Measurement, total: np.ndarray, count: np.ndarray,
                   n_captures: int) -> tuple[AnalysisGrid, int, tuple[str, ...]]:
    """The first capture's analysis grid carrying the average of the registered phases.

    Parameters
    ----------
    m1 : Measurement
        The first capture.
    total, count : ndarray
        As returned by :func:`_registered_sums`.
    n_captures : int
        How many captures were summed.
    Returns
    -------
    ag : AnalysisGrid
        Average phases (rad, float32, NaN outside the region), its regions and the report mask.
    n : int
        Number of regions kept.
    warnings : tuple of str
        A warning when more than 5% of the averaged region misses a capture.
    """
    valid = count > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        avg = np.where(valid[..., None], total / np.maximum(count, 1)[..., None], np.nan).astype(np.float32)
    p = m1.inputs.params
    period = max(m1.carriers.k1.period_px, m1.carriers.k2.period_px)
    labels, n = label_regions(valid, min_region_samples(p, m1.ag.grid, period))
    valid = labels > 0
    avg[~valid] = np.nan
    # Reported: the averaged region and the first capture's partial border blocks around it
    # (smoothly extended, as for one capture).
    report = valid | (m1.ag.report & ndimage.binary_dilation(valid))
    ag = AnalysisGrid(m1.ag.grid, avg, valid, labels, report, None, m1.ag.transfer, m1.ag.passes, m1.ag.photo)
    partial = float(np.mean(count[valid] < n_captures)) if valid.any() else 0.0
    if partial > 0.05:
        return ag, n, (f"{100 * partial:.0f}% of the averaged region is covered by fewer than all "
                       f"{n_captures} captures (capture_count shows where)",)
    return ag, n, ()
