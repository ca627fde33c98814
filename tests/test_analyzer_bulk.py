"""The bulk channel on synthetic displacements of known uniform strain (closed forms, no renders)."""

import numpy as np
import pytest

from glassdist.analyzer.bulk import bulk_channel, pinned_strain

H, W, STEP, MM_PER_PX, L_M = 60, 80, (4.0, 4.0), 0.5, 2.0


def _field(E, noise_mm=0.0, seed=0):
    """delta = E X (X: backdrop mm about the view's centre) on an H x W grid of STEP px, plus white noise."""
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    yy, xx = yy * STEP[0], xx * STEP[1]
    X = np.stack([xx - xx.mean(), yy - yy.mean()], -1) * MM_PER_PX
    d = X @ np.asarray(E).T
    if noise_mm:
        d = d + np.random.default_rng(seed).normal(0.0, noise_mm, d.shape)
    return d, xx, yy


def _bulk(d, xx, yy, **kw):
    ok = np.ones((H, W), bool)
    J = np.broadcast_to(MM_PER_PX * np.eye(2), (H, W, 2, 2))
    return bulk_channel(d, ok, ok.astype(int), degree=2, step_px=STEP, jacobian=J, frame_rotation=None,
                        distance_m=L_M, sigma_px=0.5, xx=xx, yy=yy, **kw)


def test_uniform_strain_reads_its_sphere_cylinder_and_axis():
    """A uniform strain: phi_eff = tr E / L, phi_shear = 2 |deviator| / L, axis = atan2(E_xy, (E_xx - E_yy)/2) / 2."""
    E = np.array([[-3e-3, 1e-3], [1e-3, -1e-3]])
    b = _bulk(*_field(E))
    k = 1000.0 / L_M
    half = 0.5 * (E[0, 0] - E[1, 1])
    assert b.phi_eff_mD == pytest.approx(np.trace(E) * k, rel=1e-6)
    assert b.phi_shear_mD == pytest.approx(2 * np.hypot(half, E[0, 1]) * k, rel=1e-6)
    assert b.axis_deg == pytest.approx(0.5 * np.degrees(np.arctan2(E[0, 1], half)), abs=1e-6)
    # a base strain (the pinned Direct Method's) adds to the polynomial's
    more = _bulk(*_field(E), base_strain=np.broadcast_to(np.diag([1e-3, 1e-3]), (H, W, 2, 2)))
    assert more.phi_eff_mD == pytest.approx((np.trace(E) + 2e-3) * k, rel=1e-6)


def test_uncertainty_is_the_slope_error_of_the_residual():
    """White noise of 0.002 mm: the stated sigma is sqrt(2) s_r / sqrt(n var(X)) / L (X in backdrop mm), and
    it matches the scatter of phi_eff over 40 seeded realisations within 0.8-1.25."""
    E = np.diag([-2e-3, -2e-3])
    reads, sigmas = [], []
    for seed in range(40):
        d, xx, yy = _field(E, noise_mm=0.002, seed=seed)
        b = _bulk(d, xx, yy)
        reads.append(b.phi_eff_mD)
        sigmas.append(b.phi_eff_sigma_mD)
    d, xx, yy = _field(E, noise_mm=0.002, seed=0)
    X = np.stack([xx.ravel(), yy.ravel()], -1) * MM_PER_PX
    resid = d.reshape(-1, 2) - np.c_[np.ones(H * W), X, X**2, X[:, :1] * X[:, 1:]] @ np.linalg.lstsq(
        np.c_[np.ones(H * W), X, X**2, X[:, :1] * X[:, 1:]], d.reshape(-1, 2), rcond=None)[0]
    s_r = np.sqrt(np.mean(resid**2))
    expect = np.sqrt(2.0) * s_r / np.sqrt(H * W * np.mean(np.var(X, axis=0))) * 1000.0 / L_M
    assert sigmas[0] == pytest.approx(expect, rel=0.02)
    assert 0.8 <= np.std(reads) / np.median(sigmas) <= 1.25


def test_pinned_strain_of_a_known_scale_and_stretch():
    """The baseline's own strain against the glass-less scale Z/f: a Jacobian (Z/f)(I + eps) Q reads eps
    (symmetric eps, any rotation Q)."""
    eps = np.array([[2e-3, -5e-4], [-5e-4, -1e-3]])
    t = np.radians(25.0)
    Q = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    Z, f = 15000.0, 8000.0
    J = (Z / f) * (np.eye(2) + eps) @ Q
    assert np.allclose(pinned_strain(J, focal_px=f, board_distance_mm=Z), eps, atol=1e-12)
