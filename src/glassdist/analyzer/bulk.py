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
camera focal length and camera-to-pane distance) separates them; the Direct Method reports
why the bulk channel is not identifiable instead.

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

__all__ = ["BulkChannel", "bulk_channel", "DIRECT_BULK_REASON"]

#: Why the Direct Method does not report the bulk channel.
DIRECT_BULK_REASON = (
    "not identifiable with the Direct Method: a uniform power is a change of scale, which the homography "
    "absorbs (and a linear change of power a perspective term); it needs a capture that pins the magnification "
    "(calibrated lens, camera focal length and camera-to-pane distance) or the Comparative Method"
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

    def to_dict(self) -> dict:
        return {"phi_eff_mD": self.phi_eff_mD, "phi_shear_mD": self.phi_shear_mD, "axis_deg": self.axis_deg,
                "phi_eff_sigma_mD": self.phi_eff_sigma_mD, "phi_shear_sigma_mD": self.phi_shear_sigma_mD,
                "detrend_degree": self.degree, "region": self.region, "reason": self.reason}


def bulk_channel(delta_mm: np.ndarray, valid: np.ndarray, labels: np.ndarray, *, degree: int, step_px, jacobian,
                 frame_rotation, distance_m: float, sigma_px: float, xx: np.ndarray, yy: np.ndarray,
                 guard_px: float = 0.0) -> BulkChannel:
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
    """
    from scipy import ndimage

    ok = valid & np.all(np.isfinite(delta_mm), axis=-1) & (labels > 0)
    if guard_px > 0:
        inner = ok & (ndimage.distance_transform_edt(np.pad(ok, 1), sampling=step_px)[1:-1, 1:-1] > guard_px)
        ok = inner if inner.sum() >= 16 else ok
    if ok.any():  # the pane: the largest part of the region (a frame or mullion splits it)
        ok &= labels == np.argmax(np.bincount(labels[ok].ravel()))
    region = {"samples": int(ok.sum()), "share_of_grid": float(ok.mean()), "guard_px": float(guard_px)}
    if ok.sum() < 16:
        return BulkChannel(None, None, None, None, None, degree, region, "too few samples")
    region.update({"x_px": [float(xx[ok].min()), float(xx[ok].max())], "y_px": [float(yy[ok].min()), float(yy[ok].max())]})
    lab = np.where(ok, labels, 0)
    d = np.where(ok[..., None], delta_mm, 0.0)
    resid = polynomial_detrend(d, lab, degree, step_px)
    removed = np.where(ok[..., None], d - resid, np.nan)
    sy, sx = step_px
    g = np.stack([np.stack(np.gradient(removed[..., c], sy, sx, edge_order=2)[::-1], -1) for c in range(2)], -2)  # (h, w, comp, px)
    Jinv = np.linalg.inv(np.where(ok[..., None, None], jacobian, np.eye(2)))
    G = g @ Jinv  # d delta_a / dX_b, per backdrop mm
    gok = ok & np.all(np.isfinite(G), axis=(-2, -1))
    E = G[gok].mean(axis=0)
    E = 0.5 * (E + E.T)
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
    return BulkChannel(eff, shear, axis, float(np.sqrt(2.0) * s_slope * k), float(2.0 * s_slope * k), degree, region)
