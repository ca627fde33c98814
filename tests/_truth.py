"""An independent evaluation of a known displacement field: the truth the accuracy tests compare with.

The analyzer's own evaluation stack (``glassdist.analyzer.metrics``) is what these tests
check, so the truth is written out here from the definitions in the README ("Conventions",
"A2", "A3") and imports nothing from ``glassdist`` (``tests/test_truth_layout.py`` pins
that rule):

* A2 detrend, per region (README "A2"): each 4-connected part of the region on its own, the
  least-squares polynomial of total degree N (monomials x^i y^j, i + j <= N) fitted to each
  component over the part's samples in the detrend region the result documents
  (``detrend_region``: the whole analysis blocks; the region adds a ring of partial ones), and
  subtracted over the part (``numpy.linalg.lstsq``). Smoothing, likewise, per part.
* Reporting smoothing: Gaussian of standard deviation sigma_px = sigma_mm / mm_per_px,
  normalised by the region (normalised convolution, Knutsson & Westin 1993): order 0
  divides the filtered field by the filtered mask; order 1 fits a plane per sample with
  Gaussian weights (what the README states: "linear trends survive at region borders").
  Built on ``scipy.ndimage.gaussian_filter`` in the spatial domain (the analyzer filters
  in the Fourier domain).
* A3: centred differences (``numpy.gradient``) in pixels, turned into gradients with
  respect to backdrop mm through the inverse of the Jacobian dX/dr (or 1 / mm_per_px),
  eps = sym(grad delta), and the channels

  phi_eff = tr(eps) / L,  phi_shear = (2 / L) sqrt(((exx - eyy) / 2)^2 + exy^2),
  phi_total = ||eps||_F / L  (x 1000 for mD, L in m),

  axis = direction of largest stretch of the traceless part of eps, degrees in (-90, 90]
  from +x towards +y.
* Reflection (docs/user-guide/reflection.md "Definitions"): the reflective power of a height field
  Z(u, v) on the pane, Coddington's equations for a mirror written out,
  P = 2 [[Z_tt / cos theta, Z_ts], [Z_ts, Z_ss cos theta]], with the Hessian by centred
  differences of the analytic surface, t along the in-plane vector from the camera's foot
  to the point and tan theta = |v| / C.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["TruthChannels", "detrend", "smooth", "gradient_mm", "channels", "evaluate", "truth_for",
           "axis_difference_deg", "reflective_power", "reflected_channels"]


@dataclass(frozen=True)
class TruthChannels:
    """The truth's fields on the pixel grid of the displacement (NaN outside the region)."""

    phi_eff_mD: np.ndarray
    phi_shear_mD: np.ndarray
    phi_total_mD: np.ndarray
    axis_deg: np.ndarray
    displacement_detrended_mm: np.ndarray
    strain: np.ndarray


def detrend(field: np.ndarray, mask: np.ndarray, degree: int, fit_mask: np.ndarray | None = None) -> np.ndarray:
    """Subtract from ``field`` (h, w) over ``mask`` the least-squares polynomial of total degree ``degree``
    fitted over ``fit_mask`` (default ``mask``)."""
    fit = mask if fit_mask is None else fit_mask
    rows, cols = np.nonzero(fit)
    # pixel coordinates scaled to about [-1, 1] for a well-conditioned fit
    c0, r0, sc, sr = cols.mean(), rows.mean(), max(np.ptp(cols), 1) / 2.0, max(np.ptp(rows), 1) / 2.0

    def basis(r, c):
        x, y = (c - c0) / sc, (r - r0) / sr
        return np.column_stack([x**i * y**(n - i) for n in range(degree + 1) for i in range(n + 1)])

    coef = np.linalg.lstsq(basis(rows, cols), field[fit], rcond=None)[0]
    out = np.full(field.shape, np.nan)
    out[mask] = field[mask] - basis(*np.nonzero(mask)) @ coef
    return out


def smooth(field: np.ndarray, mask: np.ndarray, sigma_px: float, order: int = 1) -> np.ndarray:
    """Gaussian smoothing of ``field`` restricted to ``mask`` (normalised convolution of order 0 or 1).

    Order 1 solves, at every sample, the Gaussian-weighted least-squares plane
    a + b (x' - x) + c (y' - y) over the masked samples x' and returns a.
    """
    w = mask.astype(float)
    f = np.where(mask, field, 0.0)

    def g(a):
        return ndimage.gaussian_filter(a, sigma_px, mode="constant", cval=0.0, truncate=4.0)

    m0, mf = g(w), g(w * f)
    if order == 0:
        return np.where(mask, mf / np.where(mask, m0, 1.0), np.nan)
    rows, cols = np.indices(field.shape, dtype=float)
    x, y = cols - cols.mean(), rows - rows.mean()  # centred: moments stay small
    mx, my = g(w * x), g(w * y)
    mxx, mxy, myy = g(w * x * x), g(w * x * y), g(w * y * y)
    mxf, myf = g(w * x * f), g(w * y * f)
    # moments about each sample (x, y): sum w (x'-x)^k (y'-y)^l
    sx, sy = mx - x * m0, my - y * m0
    sxx = mxx - 2 * x * mx + x * x * m0
    syy = myy - 2 * y * my + y * y * m0
    sxy = mxy - x * my - y * mx + x * y * m0
    sxf, syf = mxf - x * mf, myf - y * mf
    A = np.stack([np.stack([m0, sx, sy], -1), np.stack([sx, sxx, sxy], -1), np.stack([sy, sxy, syy], -1)], -2)
    b = np.stack([mf, sxf, syf], -1)
    out = np.full(field.shape, np.nan)
    out[mask] = np.linalg.solve(A[mask], b[mask][..., None])[..., 0, 0]
    return out


def gradient_mm(field: np.ndarray, *, mm_per_px: float | None = None, jacobian: np.ndarray | None = None) -> np.ndarray:
    """grad field (h, w, 2, 2): ``[..., c, k] = d field_c / d X_k`` with X in backdrop mm (centred differences)."""
    G = np.empty(field.shape[:2] + (2, 2))
    for c in range(2):
        d_row, d_col = np.gradient(field[..., c])  # per pixel along rows (y) and columns (x)
        G[..., c, 0], G[..., c, 1] = d_col, d_row
    if jacobian is None:
        return G / mm_per_px
    return G @ np.linalg.inv(jacobian)  # d/dX = d/dr . (dX/dr)^-1


def channels(eps: np.ndarray, distance_m: float):
    """(phi_eff, phi_shear, phi_total) in mD and the axis in degrees, from eps (h, w, 2, 2)."""
    exx, eyy, exy = eps[..., 0, 0], eps[..., 1, 1], eps[..., 0, 1]
    k = 1000.0 / distance_m
    phi_eff = (exx + eyy) * k
    phi_shear = 2.0 * np.sqrt(((exx - eyy) / 2.0) ** 2 + exy**2) * k
    phi_total = np.sqrt(np.sum(eps**2, axis=(-2, -1))) * k
    # major eigenvector of the traceless part [[a, b], [b, -a]], a = (exx - eyy)/2, b = exy
    a, b = (exx - eyy) / 2.0, exy
    lam = np.sqrt(a * a + b * b)
    vx, vy = b, lam - a  # (A - lam I) v = 0 -> v = (b, lam - a), unless that vanishes
    flip = np.hypot(vx, vy) < 1e-12 * np.maximum(lam, 1e-300)
    vx, vy = np.where(flip, lam + a, vx), np.where(flip, b, vy)
    axis = np.degrees(np.arctan2(vy, vx))
    axis = np.where(axis > 90.0, axis - 180.0, axis)
    axis = np.where(axis <= -90.0, axis + 180.0, axis)
    return phi_eff, phi_shear, phi_total, axis


def evaluate(displacement_mm: np.ndarray, mask: np.ndarray, *, distance_m: float, mm_per_px: float,
             detrend_degree: int, sigma_mm: float, jacobian: np.ndarray | None = None,
             order: int = 1, fit_mask: np.ndarray | None = None) -> TruthChannels:
    """The truth's detrend, smoothing and channels of ``displacement_mm`` (h, w, 2) over ``mask``.

    Each 4-connected part of ``mask`` is detrended (fitted over its samples in ``fit_mask``,
    default ``mask``) and smoothed on its own; a part with fewer fit samples than monomials is
    left out (NaN).
    """
    mask = np.asarray(mask, bool)
    fit = mask if fit_mask is None else (np.asarray(fit_mask, bool) & mask)
    sigma_px = sigma_mm / mm_per_px
    pad = int(np.ceil(4.0 * sigma_px)) + 2  # the Gaussian's reach (truncate = 4): the crop changes nothing
    parts, _ = ndimage.label(mask)
    n_terms = (detrend_degree + 1) * (detrend_degree + 2) // 2
    sm = np.full(mask.shape + (2,), np.nan)
    done = np.zeros_like(mask)
    for k, box in enumerate(ndimage.find_objects(parts), 1):
        box = tuple(slice(max(b.start - pad, 0), b.stop + pad) for b in box)
        part = parts[box] == k
        if (fit[box] & part).sum() < n_terms:
            continue
        for c in range(2):
            det = detrend(displacement_mm[box][..., c], part, detrend_degree, fit[box] & part)
            sm[box][..., c][part] = smooth(det, part, sigma_px, order)[part]
        done[box] |= part
    grad = gradient_mm(sm, mm_per_px=mm_per_px, jacobian=jacobian)
    eps = 0.5 * (grad + np.swapaxes(grad, -1, -2))
    eff, shear, total, axis = channels(eps, distance_m)
    out = [eff, shear, total, axis, sm, eps]
    for a in out:
        a[~done] = np.nan
    return TruthChannels(*out)


def truth_for(cap, res, *, mask=None) -> TruthChannels:
    """The truth of a synthetic capture ``cap`` evaluated as the result ``res`` documents it.

    Same region (``res.valid``), detrend fitted on the same region (``res.detrend_region``),
    detrend degree, smoothing scale, distance and scale as the result, and the capture's own
    Jacobian (perspective).
    """
    return evaluate(cap.displacement_mm, res.valid if mask is None else mask, distance_m=res.distance_m,
                    mm_per_px=res.mm_per_px, detrend_degree=res.detrend_degree, sigma_mm=res.sigma_mm,
                    jacobian=cap.jacobian, fit_mask=res.detrend_region)


def axis_difference_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| for axes (modulo 180 degrees), in [0, 90]."""
    d = np.abs((np.asarray(a) - np.asarray(b)) % 180.0)
    return np.minimum(d, 180.0 - d)


def reflective_power(height, u_mm: np.ndarray, v_mm: np.ndarray, *, foot_mm: tuple[float, float],
                     camera_distance_mm: float, step_mm: float = 0.5) -> np.ndarray:
    """Coddington's reflective power P (1/mm, (u, v) frame, (..., 2, 2)) of the surface ``height(u, v)`` (mm).

    ``u_mm, v_mm``: the points on the pane; ``foot_mm``: the camera's foot on the pane (the
    foot of the perpendicular from the camera), ``camera_distance_mm``: C. Hessian by centred
    differences of ``height`` at ``step_mm``; t = (u - foot) / |u - foot| ((1, 0) at the foot),
    s = t turned by +90 deg, cos theta = C / sqrt(C^2 + |u - foot|^2);
    P_tt = 2 Z_tt / cos theta, P_ss = 2 Z_ss cos theta, P_ts = 2 Z_ts.
    """
    h = step_mm
    u, v = np.asarray(u_mm, float), np.asarray(v_mm, float)
    z0 = height(u, v)
    zuu = (height(u + h, v) - 2 * z0 + height(u - h, v)) / h**2
    zvv = (height(u, v + h) - 2 * z0 + height(u, v - h)) / h**2
    zuv = (height(u + h, v + h) - height(u + h, v - h) - height(u - h, v + h) + height(u - h, v - h)) / (4 * h * h)
    vx, vy = u - foot_mm[0], v - foot_mm[1]
    r = np.hypot(vx, vy)
    tu = np.where(r > 0, vx / np.where(r > 0, r, 1.0), 1.0)
    tv = np.where(r > 0, vy / np.where(r > 0, r, 1.0), 0.0)
    su, sv = -tv, tu
    cos_t = camera_distance_mm / np.sqrt(camera_distance_mm**2 + r * r)
    ztt = tu * tu * zuu + 2 * tu * tv * zuv + tv * tv * zvv
    zss = su * su * zuu + 2 * su * sv * zuv + sv * sv * zvv
    zts = tu * su * zuu + (tu * sv + tv * su) * zuv + tv * sv * zvv
    ptt, pss, pts = 2 * ztt / cos_t, 2 * zss * cos_t, 2 * zts
    # back to (u, v): P = Q^T [[ptt, pts], [pts, pss]] Q, Q rows t and s
    puu = tu * tu * ptt + 2 * tu * su * pts + su * su * pss
    pvv = tv * tv * ptt + 2 * tv * sv * pts + sv * sv * pss
    puv = tu * tv * ptt + (tu * sv + tv * su) * pts + su * sv * pss
    return np.stack([np.stack([puu, puv], -1), np.stack([puv, pvv], -1)], -2)


def reflected_channels(P: np.ndarray, mask: np.ndarray, sigma_px: float):
    """(phi_eff, phi_shear, phi_total) in mD and the axis of the power ``P`` (1/mm) smoothed over ``mask``.

    Each component is smoothed by :func:`smooth` (first-order normalised Gaussian of
    ``sigma_px`` on the pixel grid, over ``mask``); then the channels of :func:`channels`
    (P in 1/mm x 1000 is 1/m: ``channels(P * 1000, 1.0)`` gives mD). NaN outside ``mask``.
    """
    mask = np.asarray(mask, bool)
    S = np.empty(P.shape)
    for i, j in ((0, 0), (1, 1), (0, 1)):
        S[..., i, j] = smooth(P[..., i, j], mask, sigma_px, 1)
    S[..., 1, 0] = S[..., 0, 1]
    out = channels(np.nan_to_num(S) * 1000.0, 1.0)
    for a in out:
        a[~mask] = np.nan
    return out
