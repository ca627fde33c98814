"""The bulk channel: the pane-level sphere and cylinder that the A2 detrend removes.

The degree-N polynomial removed from each displacement component (Block A2) holds the
pane's own low-order shape (IGU pillowing, bow) together with what the baseline could not
take out. Its mean strain over the fitted region,

.. math::

   \\bar\\varepsilon = \\frac{1}{|\\Omega|}\\int_\\Omega \\mathrm{sym}\\,\\nabla_X p_N(\\delta)\\,dA,

read as φ_eff = tr ε̄ / L, φ_shear = (2/L) √(((ε̄_xx − ε̄_yy)/2)² + ε̄_xy²) and its axis
(mD, the conventions of :mod:`glassdist.analyzer.metrics`), is the bulk channel. Gradients
are taken with respect to backdrop mm through the A1 Jacobian.

Identifiability. The Comparative Method measures it directly (the reference fixes the
glass-less landing points). The Direct Method's baseline is a homography (and the lens): a
uniform power is a change of scale, which the homography absorbs, and a linear change of
power is a perspective term. Only a capture that pins the magnification (calibrated lens,
camera focal length and camera-to-pane distance) separates them; otherwise the Direct
Method reports why the bulk channel is not identifiable.

Pinned magnification (Direct Method, :func:`pinned_strain`). With the camera's focal length
``f`` (px), the normal distance ``Z = D + L`` from the camera to the board (camera-to-pane ``D``
plus glass-to-board ``L``) and the camera facing the pane squarely, a glass-less board point
lands at ``X_s = (Z / f) Q (r − c)`` (Q a rotation): ``Z / f`` board mm per px everywhere. The
fitted baseline (homography and lens) gives the board point seen at each pixel, ``X(r)``; with
``X = X_s + δ(X_s)``, ``dX/dr = (I + ∇δ) (Z / f) Q``, so the polar decomposition of
``M = (f / Z) dX/dr`` gives the baseline's own strain ``ε_H = (M Mᵀ)^{1/2} − I`` (∇δ symmetric).
The bulk strain is the mean of ε_H over the channel's region plus the mean strain of the
degree-N polynomial of the Direct displacement (what the baseline left). Its sensitivity to
the inputs is first order and large: ``dε = −dZ/Z`` and ``dε = df/f`` (isotropic), i.e.
φ_eff moves by ``2 (dZ/Z) / L`` and ``2 (df/f) / L`` (both reported, so that the user's own
tolerances on the distance and the focal length set the uncertainty). A camera turned from
the pane normal breaks the uniform glass-less scale: on the flat pillowed-IGU scene (Z = 15 m,
L = 10 m) turned by 2°, 3° and 5° the sphere reads 0.02, 0.11 and 0.63 mD off (cylinder 0.007,
0.035, 0.21 mD). The homography cannot tell such a turn from the glass (it reads a 5.5° "tilt"
on the pillowed pane seen squarely), so the channel assumes the camera faces the pane.

Uncertainty. The residual after the detrend, ``r``, is treated as noise correlated over the
reporting scale σ: the slope of a least-squares fit over ``n`` samples of positional
variance ``var(X)`` has variance ``s_r^2 / (n_eff var(X))`` with
``n_eff = n · min(1, ΔA / (4π σ^2))`` (ΔA the sample area), and the sphere (two slopes) and
cylinder follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .metrics import polynomial_detrend

__all__ = ["BulkChannel", "bulk_channel", "measured_bulk", "pinned_strain", "DIRECT_BULK_REASON"]

#: Why the Direct Method does not report the bulk channel.
DIRECT_BULK_REASON = (
    "not identifiable with the Direct Method: a uniform power is a change of scale, which the homography "
    "absorbs (and a linear change of power a perspective term); it needs a capture that pins the magnification "
    "(a camera file's focal length, lens, and the camera-to-pane distance, camera_distance_m, the camera "
    "facing the pane) or the Comparative Method"
)


@dataclass(frozen=True)
class BulkChannel:
    """Pane-level sphere and cylinder removed by the detrend (mD), or why it is not reported."""

    phi_eff_mD: float | None
    phi_shear_mD: float | None
    axis_deg: float | None
    phi_eff_sigma_mD: float | None
    phi_shear_sigma_mD: float | None
    degree: int
    region: dict
    reason: str = ""
    pinned: dict | None = None

    def to_dict(self) -> dict:
        """The channel as a JSON-ready mapping (summary.json's ``bulk``)."""
        d = {"phi_eff_mD": self.phi_eff_mD, "phi_shear_mD": self.phi_shear_mD, "axis_deg": self.axis_deg,
             "phi_eff_sigma_mD": self.phi_eff_sigma_mD, "phi_shear_sigma_mD": self.phi_shear_sigma_mD,
             "detrend_degree": self.degree, "region": self.region, "reason": self.reason}
        if self.pinned is not None:
            d["pinned"] = self.pinned
        return d


def pinned_strain(jacobian_mm_per_px: np.ndarray, *, focal_px: float, board_distance_mm: float) -> np.ndarray:
    """The baseline's own strain where the magnification is pinned (module docstring), (..., 2, 2).

    Parameters
    ----------
    jacobian_mm_per_px : ndarray (..., 2, 2)
        ``dX/dr`` of the baseline: board mm (component frame) per px.
    focal_px : float
        Focal length, px (square pixels).
    board_distance_mm : float
        Normal distance from the camera to the board, mm (camera-to-pane plus glass-to-board).
    """
    M = np.asarray(jacobian_mm_per_px, float) * (focal_px / board_distance_mm)
    A = M @ np.swapaxes(M, -1, -2)  # (I + eps)^2, symmetric positive definite
    rd = np.sqrt(np.abs(np.linalg.det(A)))[..., None, None]
    tr = (A[..., 0, 0] + A[..., 1, 1])[..., None, None]
    return (A + rd * np.eye(2)) / np.sqrt(tr + 2.0 * rd) - np.eye(2)  # closed-form 2 x 2 square root


def bulk_channel(delta_mm: np.ndarray, valid: np.ndarray, labels: np.ndarray, *, degree: int, step_px, jacobian,
                 frame_rotation, distance_m: float, sigma_px: float, xx: np.ndarray, yy: np.ndarray,
                 guard_px: float = 0.0, base_strain: np.ndarray | None = None, pinned: dict | None = None) -> BulkChannel:
    """The bulk channel of a displacement on the analysis grid (module docstring).

    Parameters
    ----------
    delta_mm : ndarray (h, w, 2)
        Displacement in the A1 component frame, mm (NaN outside ``valid``).
    valid, labels : ndarray (h, w)
        The region and its parts; the largest part (the pane, where a frame splits the view)
        is the one fitted and reported.
    degree : int
        The detrend's degree N (0: nothing but the mean removed, reported as 0).
    step_px : (float, float)
        Grid step (rows, cols), px.
    jacobian : ndarray (h, w, 2, 2)
        Backdrop mm per px of the component frame (``J[a, b] = dX_a / dr_b``).
    frame_rotation : ndarray (2, 2) or None
        Component frame -> camera frame (for the axis).
    distance_m : float
    sigma_px : float
        Reporting smoothing scale, px.
    xx, yy : ndarray (h, w)
        Pixel coordinates of the samples (the region's extent is reported).
    guard_px : float
        The polynomial is fitted on the samples farther than this from the region's border
        (the guard band of the trusted pixels): within it the smoothing kernel is cut by the
        border and the displacement is biased (on the ray-traced pillowed IGU the displacement
        over the whole region carries a sphere 4.7 % below the exact one, over the trusted
        pixels 0.2 %). Samples at ``guard_px`` and closer are left out when enough remain.
    base_strain : ndarray (h, w, 2, 2), optional
        Direct Method with the magnification pinned: the baseline's own strain per sample
        (:func:`pinned_strain`, component frame); its mean over the region is added to the
        polynomial's.
    pinned : dict, optional
        What pinned it (reported as :attr:`BulkChannel.pinned`).
    """
    from scipy import ndimage

    ok = valid & np.all(np.isfinite(delta_mm), axis=-1) & (labels > 0)
    if guard_px > 0:
        inner = ok & (ndimage.distance_transform_edt(np.pad(ok, 1), sampling=step_px)[1:-1, 1:-1] > guard_px)
        ok = inner if inner.sum() >= 16 else ok
    if ok.any():  # the pane: the largest part of the region (a frame or mullion splits it)
        ok &= labels == np.argmax(np.bincount(labels[ok].ravel()))
    region: dict[str, object] = {"samples": int(ok.sum()), "share_of_grid": float(ok.mean()), "guard_px": float(guard_px)}
    if ok.sum() < 16:
        return BulkChannel(None, None, None, None, None, degree, region, "too few samples")
    region.update({"x_px": [float(xx[ok].min()), float(xx[ok].max())], "y_px": [float(yy[ok].min()), float(yy[ok].max())]})
    lab = np.where(ok, labels, 0)
    d = np.where(ok[..., None], delta_mm, 0.0)
    resid = polynomial_detrend(d, lab, degree, step_px)
    removed = np.where(ok[..., None], d - resid, np.nan)
    sy, sx = step_px
    # (h, w, comp, px)
    g = np.stack([np.stack(list(np.gradient(removed[..., c], sy, sx, edge_order=2))[::-1], -1) for c in range(2)], -2)
    Jinv = np.linalg.inv(np.where(ok[..., None, None], jacobian, np.eye(2)))
    G = g @ Jinv  # d delta_a / dX_b, per backdrop mm
    gok = ok & np.all(np.isfinite(G), axis=(-2, -1))
    E = G[gok].mean(axis=0)
    E = 0.5 * (E + E.T)
    if base_strain is not None:
        B = base_strain[gok].mean(axis=0)
        E = E + 0.5 * (B + B.T)
    if frame_rotation is not None:
        E = frame_rotation.T @ E @ frame_rotation
    k = 1000.0 / distance_m
    half = 0.5 * (E[0, 0] - E[1, 1])
    eff = float(np.trace(E) * k)
    shear = float(2 * np.hypot(half, E[0, 1]) * k)
    axis = float(0.5 * np.degrees(np.arctan2(E[0, 1], half)))
    # uncertainty: residual as noise correlated over sigma_px
    J0 = np.median(np.abs(np.linalg.det(jacobian[ok]))) ** 0.5  # mm per px
    X = np.stack([xx[ok], yy[ok]], -1) * J0
    var_x = float(np.mean(np.var(X, axis=0)))
    s_r = float(np.sqrt(np.mean(resid[ok] ** 2)))
    n_eff = ok.sum() * min(1.0, sy * sx / (4 * np.pi * max(sigma_px, 1e-9) ** 2))
    s_slope = s_r / np.sqrt(max(n_eff, 1.0) * max(var_x, 1e-30))
    return BulkChannel(eff, shear, axis, float(np.sqrt(2.0) * s_slope * k), float(2.0 * s_slope * k), degree, region,
                       pinned=pinned)


def measured_bulk(delta_cam: np.ndarray, ag, comp, *, fit, params, distance_m: float, mm_per_px: float,
                  sigma_mm: float, guard_px: float, camera_distance_m: float | None = None) -> BulkChannel:
    """The bulk channel of one analysis, from its camera-frame displacement ``delta_cam`` (mm) on the analysis grid.

    Comparative Method (``fit`` None): measured. Direct Method (``fit``, a
    :class:`~glassdist.analyzer.homography.HomographyFit`): only where the magnification is
    pinned (a camera file's focal length, and ``camera_distance_m``, the camera facing the
    pane): the baseline's own strain (:func:`pinned_strain`) plus what the degree-N polynomial
    of the Direct displacement holds; otherwise why it is not identifiable. ``ag``: the
    :class:`~glassdist.analyzer.analysis_grid.AnalysisGrid`; ``comp``: A1's
    :class:`~glassdist.analyzer.components.Components` (its Jacobian and frame rotation).
    """
    p = params
    base = pinned = None
    if fit is not None:
        cal = fit.lens
        focal = None if cal is None or not cal.identifiable else cal.focal_px
        if camera_distance_m is None or focal is None:
            missing = [w for w, gone in (("the camera's focal length (a camera file)", focal is None),
                                         ("the camera-to-pane distance", camera_distance_m is None)) if gone]
            return BulkChannel(None, None, None, None, None, p.detrend_degree, {},
                               f"{DIRECT_BULK_REASON}; missing here: {' and '.join(missing)}")
        if p.a1_mode != "projective":
            return BulkChannel(None, None, None, None, None, p.detrend_degree, {},
                               "the pinned Direct bulk channel needs the projective A1 (a1_mode 'projective')")
        board_mm = (camera_distance_m + distance_m) * 1000.0
        k = 1000.0 / distance_m
        pinned = {"camera_distance_m": float(camera_distance_m), "focal_px": float(focal),
                  "phi_eff_mD_per_cm_of_distance": float(2.0 * 10.0 / board_mm * k),
                  "phi_eff_mD_per_percent_of_focal_length": float(2.0 * 0.01 * k)}
    yy, xx = ag.grid.coords()
    delta = delta_cam
    if p.a1_mode == "projective":
        J, R = comp.jacobian, comp.frame_rotation  # the Direct baseline seen through the lens
        if pinned is not None:
            base = pinned_strain(J, focal_px=pinned["focal_px"], board_distance_mm=board_mm)
        delta = delta @ R.T  # back to the component frame
    else:
        J, R = np.broadcast_to(mm_per_px * np.eye(2), xx.shape + (2, 2)), None
    return bulk_channel(delta, ag.valid, ag.labels, degree=p.detrend_degree, step_px=ag.grid.step, jacobian=J,
                        frame_rotation=R, distance_m=distance_m, sigma_px=sigma_mm / mm_per_px, xx=xx, yy=yy,
                        guard_px=guard_px, base_strain=base, pinned=pinned)
