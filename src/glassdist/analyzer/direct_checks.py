"""The Direct Method's checks of its own baseline: pure functions of the measured fields returning warnings.

The Direct Method takes the glass against a baseline fitted from the photo itself (Block I:
a homography and the camera lens model), so what the camera and the glass share with that
baseline is ambiguous. Each check here reads, from the fields Block A produced, how much the
reading rests on that baseline and returns a warning (a string) when it matters, or None:

* :func:`n_dependence_warning`: the trusted-region statistics move between detrend degree N
  and N + 1;
* :func:`rig_floor_warning`: the calibration photo's own reading is a sizeable share of the pane's;
* :func:`lens_power_warning`: the lens fitted from the photo holds more centred power than the pane reads;
* :func:`refused_lens_warning`: the lens fitted from the photo was not applied, and the bias it leaves if it is the camera's;
* :func:`baseline_take_warning`: the homography takes in part of a local feature (a lens region), and by how much.

They all look at the analysis-grid samples beyond the guard band from the region's border
(:func:`beyond_guard`, computed once by the caller and handed to each).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .analysis_grid import AnalysisGrid
from .components import Components
from .homography import HomographyFit, _lsq, logical_coordinates
from .lens import LensModel
from .metrics import detrend_increment, masked_gaussian, polynomial_detrend, strain_tensor
from .params import AnalyzerParams

__all__ = ["DIRECT_CHECKS", "DirectReading", "baseline_take_warning", "beyond_guard", "lens_power_warning",
           "n_dependence_warning", "n_move", "plain_phi_eff", "refused_lens_warning", "rig_floor_warning"]


@dataclass(frozen=True)
class DirectReading:
    """What the checks read: the Direct Method's measurement and its channels on the analysis grid.

    ``phi_eff_mD``: Block A's phi_eff; ``trusted``: the samples beyond the guard band
    (:func:`beyond_guard`); ``components``: A1's displacement and Jacobian (computed once).
    """

    params: AnalyzerParams
    fit: HomographyFit
    baseline: np.ndarray
    carrier_period_mm: float
    mm_per_px: float
    sigma_mm: float
    distance_m: float
    ag: AnalysisGrid
    phi_eff_mD: np.ndarray
    trusted: np.ndarray
    components: Components


def beyond_guard(ag: AnalysisGrid, guard_px: float) -> np.ndarray:
    """Analysis-grid samples farther than the guard band from the region's border (the trusted pixels' rule)."""
    return ndimage.distance_transform_edt(np.pad(ag.valid, 1), sampling=ag.grid.step)[1:-1, 1:-1] > guard_px


# The Direct Method's statistics are called N-dependent when mean or p95 |phi_eff| over the trusted
# region moves by more than this share between degree N and N + 1 (the bundled photos' Direct-Comparative
# agreement target).
_N_MOVE_WARN = 0.05


def n_dependence_warning(r: DirectReading) -> str | None:
    """Warn when the trusted-region statistics move between detrend degree N and N + 1.

    The Direct Method's baseline (Block I) leaves whatever the camera and the glass share
    with a homography and the lens model to the degree-N detrend; where that matters, raising
    N changes the result. Block A is linear, and A2 at N + 1 removes exactly
    ``Q = P_{N+1} delta - P_N delta`` more than at N (:func:`~glassdist.analyzer.metrics.detrend_increment`,
    a polynomial of degree N + 1 per region), so ``phi_eff(N + 1) = phi_eff(N) - phi_eff[G * Q]``.
    The second term is the trace of Q's strain smoothed by a plain Gaussian of the reporting
    sigma (order-0 normalised convolution, :func:`plain_phi_eff`), not by Block A's whole
    kernel (the instrument transfer's inverse and the stencil corrections act on a
    polynomial's high derivatives only): the estimate costs a polynomial fit and one
    smoothing instead of a second Block A. Mean and p95 |phi_eff| over the samples beyond
    the guard band are compared (``_N_MOVE_WARN``, and at least 0.01 mD).
    """
    n = r.params.detrend_degree
    move = n_move(r)
    if move is None:
        return None
    s0, s1, what = move
    if abs(s1 - s0) > _N_MOVE_WARN * s0 and abs(s1 - s0) > 0.01:
        return (
            f"Direct Method with detrend degree {n}: the result depends on N - {what} |phi_eff| moves from "
            f"{s0:.3g} to {s1:.3g} mD ({100 * (s1 - s0) / s0:+.0f}%) with detrend_degree {n + 1}: a distortion the "
            "homography and the lens model leave (an uncalibrated camera lens, or glass curved over the whole view) - "
            "calibrate the lens (lens: calibrate_from_photo, calibration_from_camera_file) or use the Comparative Method"
        )
    return None


def n_move(r: DirectReading) -> tuple[float, float, str] | None:
    """``(s0, s1, what)``: the statistic (mean or p95 |phi_eff|, mD) that moves most from N to N + 1, or None.

    See :func:`n_dependence_warning`; None where fewer than 64 samples take part or N >= 8.
    """
    n = r.params.detrend_degree
    ag = r.ag
    if n >= 8 or ag.valid.sum() < 64:
        return None
    a = r.phi_eff_mD
    ok = r.trusted & np.isfinite(a)
    if ok.sum() < 64:
        return None
    labels = np.where(ag.valid, ag.labels, 0)
    b = a - plain_phi_eff(detrend_increment(r.components.delta_mm, labels, n, ag.grid.step), r.components.jacobian, r)
    ok &= np.isfinite(b)
    if ok.sum() < 64:
        return None
    a, b = np.abs(a[ok]), np.abs(b[ok])
    stats = [(float(np.mean(a)), float(np.mean(b)), "mean"), (float(np.percentile(a, 95)), float(np.percentile(b, 95)), "p95")]
    return max(stats, key=lambda t: abs(t[1] - t[0]) / max(t[0], 1e-12))


def plain_phi_eff(delta_mm: np.ndarray, jacobian: np.ndarray | None, r: DirectReading) -> np.ndarray:
    """phi_eff (mD) of a displacement on the analysis grid by Block A's rule without its transfer.

    The strain through ``jacobian`` (None: ``mm_per_px``), its trace over L, smoothed by a plain
    Gaussian of the reporting sigma (order-0 normalised convolution). What the checks read a
    trend with; NaN where the strain is.
    """
    eps = strain_tensor(delta_mm, r.ag.grid.step, mm_per_px=r.mm_per_px, jacobian=jacobian)
    phi = (eps[..., 0, 0] + eps[..., 1, 1]) * (1000.0 / r.distance_m)  # phi_eff is the trace (metrics)
    sigma_px = r.sigma_mm / r.mm_per_px
    return masked_gaussian(phi, np.isfinite(phi).astype(float), sigma_px**2 * np.eye(2), r.ag.grid.step, order=0)


# The Direct Method's reading is compared with its floor on the rig (the calibration photo read the same
# way) when the floor's mean |phi_eff| reaches this share of the pane's: above it the board and the camera
# move the pane's statistics by a visible amount.
_FLOOR_SHARE_WARN = 0.1


def rig_floor_warning(r: DirectReading) -> str | None:
    """Warn when the calibration photo's own reading is a sizeable share of the pane's.

    :attr:`~glassdist.analyzer.lens.LensCalibration.floor` holds the calibration photo (no
    glass) read by the Direct Method at the same detrend degree, smoothing and L; it is
    compared, as mean |phi_eff|, with the pane's over the samples beyond the guard band,
    where the floor stands above the calibration photo's own noise (twice its median
    ``phi_eff_sigma_mD``) and only where the detrend degrees match (another degree reads
    another floor; L is scaled, phi ~ 1 / L).
    """
    cal = r.fit.lens
    floor = {} if cal is None else cal.floor
    if not floor or floor["detrend_degree"] != r.params.detrend_degree:
        return None
    scale = floor["distance_m"] / r.distance_m  # phi scales as 1 / L
    f = floor["mean_abs_phi_eff_mD"] * scale
    a = np.abs(r.phi_eff_mD[r.trusted & np.isfinite(r.phi_eff_mD)])
    if a.size < 64:
        return None
    m = float(np.mean(a))
    # A floor at the photo's own noise (mean |noise| is 0.8 of its sigma) says nothing about the rig.
    if f > _FLOOR_SHARE_WARN * m and floor["mean_abs_phi_eff_mD"] > 2.0 * floor["phi_eff_sigma_mD"]:
        return (
            f"Direct Method: the calibration photo (no glass), read the same way, shows mean |phi_eff| {f:.3g} mD "
            f"(p95 {floor['p95_abs_phi_eff_mD'] * scale:.3g} mD, noise "
            f"{floor['phi_eff_sigma_mD'] * scale:.2g} mD), {100 * f / m:.0f}% of this "
            f"pane's {m:.3g} mD: the board (its print, its flatness) or the camera departs from the perfect grid and "
            "the lens model by that much, and the Direct Method reads it as glass - use the Comparative Method, or a "
            "flatter, finer-printed board"
        )
    return None


# The Direct Method says what the camera lens fitted from the photo takes for itself when, read as glass,
# it would reach this share of the pane's own reading (mean |phi_eff|), and at least 0.01 mD.
_LENS_SHARE_WARN = 1.0


def _lens_as_glass(r: DirectReading, lens: LensModel) -> np.ndarray | None:
    """phi_eff (mD, analysis grid) of the displacement ``p_c (H^-1(L^-1(r)) - H^-1(r))`` of ``lens`` against the bare
    homography, read as glass by Block A's rule (degree-N detrend per region, :func:`plain_phi_eff` through the
    baseline's Jacobian); None where too few samples beyond the guard band take part."""
    ag = r.ag
    yy, xx = ag.grid.coords()
    u1, v1 = logical_coordinates(r.fit.matrix, lens, xx, yy)
    u0, v0 = logical_coordinates(r.fit.matrix, None, xx, yy)
    d = np.stack([u1 - u0, v1 - v0], axis=-1) * r.carrier_period_mm
    d = polynomial_detrend(d, np.where(ag.valid, ag.labels, 0), r.params.detrend_degree, ag.grid.step)
    phi = plain_phi_eff(d, r.components.jacobian, r)  # the baseline's Jacobian through the lens (A1, projective)
    return phi if (r.trusted & np.isfinite(r.phi_eff_mD) & np.isfinite(phi)).sum() >= 64 else None


# A lens fitted from the photo but not applied is named with its bias when, applied, it would move mean or p95
# |phi_eff| by more than this share of the reading (and by at least 0.01 mD).
_REFUSED_LENS_WARN = 0.03
#: least share of what a bare homography leaves that the fitted lens terms must explain for the refused lens's
#: bias to be stated: lens-free views read 0-5 % (a 12 % strain wave: 5 %), a k1 = -/+0.05 lens under glass
#: strong enough to refuse it 8-11 % (tests/test_direct_lens_bias), a judgement between the two
_REFUSED_LENS_MIN_GAIN = 0.065


def refused_lens_warning(r: DirectReading) -> str | None:
    """State the bias of a reading whose camera lens, fitted from the photo, Block I did not apply.

    Block I applies a lens fitted from the photo only where it stands out of the glass's own
    distortion (:func:`~glassdist.analyzer.homography.refit_with_lens`); under strong glass it
    is refused, and a real camera lens is then read as glass. A camera lens is a global radial
    form, which the degree-N detrend leaves above degree N (barrel or pincushion: the cubic
    ``k1 r^3``). What the photo does tell is the lens the joint fit found: its displacement
    against the bare homography read as glass (:func:`_lens_as_glass`), taken from the
    reading, gives the reading as it would be were that lens the camera's. Mean and p95
    |phi_eff| beyond the guard band are compared, the one that moves most named with its size
    (``_REFUSED_LENS_WARN``): the bias the reading carries if the lens is the camera's, and
    none if the fitted form is the glass's.
    """
    cal, p = r.fit.lens, r.params
    # refused for a radial profile that moves without part of the view (cal.consistency): by the photo's own
    # test the form is the glass's, not a camera lens's, and Block I's warning says so
    if cal is None or cal.source != "self" or cal.identifiable or cal.consistency or p.a1_mode != "projective":
        return None
    if not cal.gain >= _REFUSED_LENS_MIN_GAIN:  # the lens terms explain next to nothing: no lens form to speak of
        return None
    phi = _lens_as_glass(r, cal.model)
    if phi is None:
        return None
    ok = r.trusted & np.isfinite(r.phi_eff_mD) & np.isfinite(phi)
    a, b = np.abs(r.phi_eff_mD[ok]), np.abs(r.phi_eff_mD[ok] - phi[ok])
    stats = [(float(np.mean(a)), float(np.mean(b)), "mean"), (float(np.percentile(a, 95)), float(np.percentile(b, 95)), "p95")]
    s0, s1, what = max(stats, key=lambda t: abs(t[1] - t[0]) / max(t[1], 1e-12))
    if abs(s0 - s1) <= max(_REFUSED_LENS_WARN * s1, 0.01):
        return None
    return (
        f"Direct Method: the camera lens fitted from the photo was not applied ({cal.note}); if it is the camera's, "
        f"this reading is biased by {100 * (s0 - s1) / s1:+.0f}% ({what} |phi_eff| {s0:.3g} mD, {s1:.3g} mD with the "
        f"lens applied) - calibrate the lens (lens: calibrate_from_photo, calibration_from_camera_file) or use the "
        "Comparative Method"
    )


def lens_power_warning(r: DirectReading) -> str | None:
    """Warn when the lens fitted from the photo holds more centred power than the pane reads.

    A camera lens's distortion and glass power centred on the optical axis have one form
    (docs/lens_calibration.md); Block I's checks (:func:`~glassdist.analyzer.homography.refit_with_lens`)
    say so when the residual shows it, but a centred feature that fills the view passes them and
    is taken whole for the lens. The photo cannot tell the two; what it can tell is how much is
    at stake: the lens's own displacement relative to the bare homography,
    ``p_c (H^-1(L^-1(r)) - H^-1(r))`` (what Direct pass 2 removed with the lens), read as glass by
    Block A's rule (degree-N detrend per region, then :func:`plain_phi_eff` through the
    baseline's Jacobian). Where its mean |phi_eff| reaches the pane's (over the samples beyond
    the guard band), the reading rests on the lens being the camera's, and a warning gives both
    figures. Only for a lens fitted from the photo and applied: a calibration photo or a
    camera file pins the lens. A lens fitted from the photo and not applied: :func:`refused_lens_warning`.
    """
    fit, p = r.fit, r.params
    lens = fit.lens_model
    if lens is None or fit.lens is None or fit.lens.source != "self" or p.a1_mode != "projective":
        return refused_lens_warning(r)
    ok = r.trusted & np.isfinite(r.phi_eff_mD)
    if ok.sum() < 64:
        return None
    phi = _lens_as_glass(r, lens)
    if phi is None:
        return None
    ok &= np.isfinite(phi)
    held, m = float(np.mean(np.abs(phi[ok]))), float(np.mean(np.abs(r.phi_eff_mD[ok])))
    if held >= _LENS_SHARE_WARN * m and held > 0.01:
        return (
            f"Direct Method: the camera lens fitted from the photo holds a radial distortion centred on the optical axis "
            f"that, read as glass, is mean |phi_eff| {held:.3g} mD, against this pane's {m:.3g} mD: the photo cannot tell "
            "a camera lens from glass power centred on the optical axis, and this reading takes it for the lens's - "
            "confirm with a calibration photo or a camera file (lens: calibrate_from_photo, calibration_from_camera_file), "
            "or use the Comparative Method"
        )
    return None


# A local feature is one connected part of the samples reading more than this share of the p95 |phi_eff| ...
_LOCAL_LEVEL = 0.5
# ... holding at least this share of them and, grown by sigma, covering between these shares of the samples beyond the
# guard band.
_LOCAL_MAIN, _LOCAL_MIN, _LOCAL_MAX = 0.8, 0.05, 0.75
# The baseline refitted without it must keep at least this share of the valid samples.
_LOCAL_KEEP = 0.3
# The homography's take is stated when it moves mean or p95 |phi_eff| by more than this share (and 0.01 mD).
_TAKE_WARN = 0.03


def _local_feature(r: DirectReading) -> np.ndarray | None:
    """The samples of one compact feature standing out of the map (a lens region), grown by the reporting sigma, or None."""
    a = np.abs(r.phi_eff_mD)
    ok = r.trusted & np.isfinite(a)
    if ok.sum() < 64:
        return None
    high = ok & (a > _LOCAL_LEVEL * np.percentile(a[ok], 95))
    grow = max(1, int(round(r.sigma_mm / r.mm_per_px / min(r.ag.grid.step))))
    # grown by sigma first: a lens's centre and the ring of opposite power at its rim are one feature
    lab, n = ndimage.label(ndimage.binary_dilation(high, iterations=grow) & ok)
    if n == 0:
        return None
    main = lab == 1 + int(np.argmax(np.bincount(lab.ravel())[1:]))
    share = main.sum() / ok.sum()
    if (main & high).sum() < _LOCAL_MAIN * high.sum() or not _LOCAL_MIN <= share <= _LOCAL_MAX:
        return None
    return ndimage.binary_dilation(main, iterations=grow)


def baseline_take_warning(r: DirectReading) -> str | None:
    """State how much of a local feature (a lens region) the homography takes in.

    The homography is fitted to the whole view, and a feature covering a good part of it
    steers the fit: its uniform and linearly varying parts become the baseline's scale and
    keystone, and what the Direct Method reads inside it is short by that much. Where the map
    shows one compact feature (one connected part of the samples above ``_LOCAL_LEVEL`` of the
    p95 |phi_eff|, ``_LOCAL_MIN``-``_LOCAL_MAX`` of the view), the homography is refitted by least
    squares to the measured logical grid (the baseline's coordinates plus the phases) outside
    it, grown by the reporting sigma; the change of baseline, ``p_c (H_out^-1(r) - H^-1(r))``,
    read as glass by Block A's rule (degree-N detrend per region, :func:`plain_phi_eff`), taken
    from the reading gives the reading the glass around the feature would fix. The change of
    mean and p95 |phi_eff| beyond the guard band is stated where either exceeds ``_TAKE_WARN``.
    Only without a lens model applied (the refit is a bare homography).
    """
    fit, ag, p = r.fit, r.ag, r.params
    if fit.lens_model is not None or p.a1_mode != "projective":
        return None
    feature = _local_feature(r)
    if feature is None:
        return None
    yy, xx = np.broadcast_arrays(*ag.grid.coords())
    u0, v0 = logical_coordinates(fit.matrix, None, xx, yy)
    U, V = u0 + ag.phases[..., 0] / (2 * np.pi), v0 + ag.phases[..., 1] / (2 * np.pi)
    keep = ag.valid & ~feature & np.isfinite(U) & np.isfinite(V)
    if keep.sum() < max(64, _LOCAL_KEEP * ag.valid.sum()):
        return None
    H = _lsq(np.stack([U[keep], V[keep]], 1), np.stack([xx[keep], yy[keep]], 1))
    if H is None:
        return None
    u1, v1 = logical_coordinates(H, None, xx, yy)
    d = np.stack([u1 - u0, v1 - v0], axis=-1) * r.carrier_period_mm
    d = polynomial_detrend(d, np.where(ag.valid, ag.labels, 0), p.detrend_degree, ag.grid.step)
    phi = plain_phi_eff(d, r.components.jacobian, r)
    ok = r.trusted & np.isfinite(r.phi_eff_mD) & np.isfinite(phi)
    if ok.sum() < 64:
        return None
    a, b = np.abs(r.phi_eff_mD[ok]), np.abs(r.phi_eff_mD[ok] - phi[ok])
    (m0, m1), (q0, q1) = (float(np.mean(a)), float(np.mean(b))), (float(np.percentile(a, 95)), float(np.percentile(b, 95)))
    if max(abs(m0 - m1) - _TAKE_WARN * m1, abs(q0 - q1) - _TAKE_WARN * q1) <= 0 or max(abs(m0 - m1), abs(q0 - q1)) <= 0.01:
        return None
    return (
        f"Direct Method: the homography takes in part of a local feature covering {100 * feature.mean():.0f}% of the "
        f"analysis grid: this reading is biased by {100 * (m0 - m1) / m1:+.0f}% in mean |phi_eff| ({m0:.3g} mD, {m1:.3g} "
        f"mD against the homography of the glass around it) and {100 * (q0 - q1) / q1:+.0f}% in p95 |phi_eff| ({q0:.3g} "
        f"mD, {q1:.3g} mD) - use the Comparative Method, or a view with more glass around the feature"
    )


#: The Direct Method's checks, in the order their warnings are given.
DIRECT_CHECKS = (n_dependence_warning, rig_floor_warning, lens_power_warning, baseline_take_warning)
