"""Block I: a known homography plus a wave plus outliers."""

import numpy as np
import pytest

from glassdist.analyzer.homography import apply_inverse, fit_homography, inverse_jacobian
from glassdist.errors import AnalysisError


def _truth():
    return np.array([[9.5, 1.2, 40.0], [-0.8, 10.3, 25.0], [2e-4, -3e-4, 1.0]])


def test_ransac_recovers_homography_despite_wave_and_outliers():
    rng = np.random.default_rng(7)
    H = _truth()
    U, V = np.meshgrid(np.arange(0, 60, 1.0), np.arange(0, 45, 1.0))
    src = np.stack([U.ravel(), V.ravel()], 1)
    p = np.c_[src, np.ones(len(src))] @ H.T
    dst = p[:, :2] / p[:, 2:]
    # Local optical wave on a quarter of the field (the signal), plus 5% gross outliers.
    wave = (src[:, 0] > 40) * 3.0 * np.sin(src[:, 1] / 3.0)
    dst[:, 0] += wave
    out = rng.random(len(dst)) < 0.05
    dst[out] += rng.normal(20, 10, (out.sum(), 2))  # e.g. a reflection: biased gross errors
    fit = fit_homography(src, dst, threshold_px=0.5, seed=0)
    q = np.c_[src, np.ones(len(src))] @ fit.matrix.T
    err = np.linalg.norm(q[:, :2] / q[:, 2:] - p[:, :2] / p[:, 2:], axis=1)
    # Wave points that cross zero inside the threshold are legitimately inliers and pull the
    # fit slightly; 0.15 px over the whole 600x450 px field, against a 3 px wave and 30 px outliers.
    assert np.max(err) < 0.15
    import cv2

    H_ls, _ = cv2.findHomography(src, dst, 0)  # plain least squares, no consensus
    q = np.c_[src, np.ones(len(src))] @ H_ls.T
    err_ls = np.linalg.norm(q[:, :2] / q[:, 2:] - p[:, :2] / p[:, 2:], axis=1)
    assert np.max(err_ls) > 5 * np.max(err)
    assert 0.6 < fit.inlier_fraction < 0.85
    again = fit_homography(src, dst, threshold_px=0.5, seed=0)
    assert np.array_equal(again.matrix, fit.matrix)  # seeded: reproducible


def test_inverse_and_its_jacobian():
    H = _truth()
    x, y = np.array([100.0, 300.0]), np.array([50.0, 200.0])
    u, v = apply_inverse(H, x, y)
    p = H @ np.array([u, v, np.ones(2)])
    assert np.allclose(p[:2] / p[2], [x, y])
    J = inverse_jacobian(H, x, y)
    e = 1e-4
    u1, v1 = apply_inverse(H, x + e, y)
    assert np.allclose(J[:, 0, 0], (u1 - u) / e, rtol=1e-4)
    assert np.allclose(J[:, 1, 0], (v1 - v) / e, rtol=1e-4)


def test_too_few_points_is_a_clear_error():
    with pytest.raises(AnalysisError, match="grid points"):
        fit_homography(np.zeros((3, 2)), np.zeros((3, 2)), threshold_px=1.0)


def test_inverse_jacobian_is_the_derivative_of_the_inverse_map():
    """Under perspective (a projective row), both rows of d(U, V)/d(x, y) against centred differences of H^-1."""
    H = np.array([[8.0, 0.5, 3.0], [-0.4, 7.5, 2.0], [2e-3, -1e-3, 1.0]])
    x, y = np.meshgrid(np.linspace(0.0, 300.0, 7), np.linspace(0.0, 200.0, 5))
    J = inverse_jacobian(H, x, y)
    h = 1e-3
    for b, (dx, dy) in enumerate(((h, 0.0), (0.0, h))):
        plus, minus = np.array(apply_inverse(H, x + dx, y + dy)), np.array(apply_inverse(H, x - dx, y - dy))
        for a in range(2):
            np.testing.assert_allclose(J[..., a, b], (plus[a] - minus[a]) / (2 * h), rtol=1e-6, atol=1e-12)
