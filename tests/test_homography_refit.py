"""Block I's robust refit: the homography from the undistorted part of the view, bounded cost."""

import time

import numpy as np

from glassdist.analyzer import homography as hm
from glassdist.analyzer.homography import fit_homography, inverse_jacobian, logical_grid_points, refit_undistorted

PERIOD = 10.0  # carrier period, px
H_TRUE = np.array([[PERIOD, 0.6, 40.0], [-0.4, PERIOD * 1.02, 30.0], [1.5e-4, -1e-4, 1.0]])


def _logical_grid(displacement, shape=(300, 400), noise=0.002, seed=3):
    """(U, V) of a grid seen through H_TRUE, displaced by ``displacement(x, y)`` (px), with phase noise (periods)."""
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    dx, dy = displacement(x, y)
    u, v = hm.apply_inverse(H_TRUE, x - dx, y - dy)
    rng = np.random.default_rng(seed)
    return u + rng.normal(0, noise, shape), v + rng.normal(0, noise, shape), y, x


def _bump(radius, k, center=(200.0, 150.0)):
    """Displacement of a lens of compact support: k r (1 - r^2/R^2)^2 inside R, 0 outside (px)."""
    def fn(x, y):
        ex, ey = x - center[0], y - center[1]
        q = np.maximum(1 - (ex**2 + ey**2) / radius**2, 0.0)
        return k * ex * q**2, k * ey * q**2
    return fn


def _gaussian(sigma, k, center=(200.0, 150.0)):
    def fn(x, y):
        ex, ey = x - center[0], y - center[1]
        g = np.exp(-(ex**2 + ey**2) / (2 * sigma**2))
        return k * ex * g, k * ey * g
    return fn


def _jacobian_error(H, x, y):
    """Largest error of the fitted local frequencies over the view (dimensionless: x the period)."""
    return float(np.max(np.abs(inverse_jacobian(H, x, y) - inverse_jacobian(H_TRUE, x, y)))) * PERIOD


def _fits(displacement):
    U, V, y, x = _logical_grid(displacement)
    valid = np.ones(U.shape, bool)
    src, dst = logical_grid_points(U, V, y, x, valid, 10)
    ransac = fit_homography(src, dst, threshold_px=0.1 * PERIOD, seed=0)
    refit = refit_undistorted(ransac, U, V, y, x, valid, 10, period_px=PERIOD, step_px=(1.0, 1.0),
                              threshold_px=0.1 * PERIOD)
    return ransac, refit, x, y


def test_large_compact_lens_leaves_the_flat_glass_as_the_baseline():
    # A lens of radius 150 px (a 10% magnification at its centre) over ~55% of a 400 x 300 view.
    lens = _bump(150.0, 0.1)
    ransac, refit, x, y = _fits(lens)
    support = np.hypot(x - 200, y - 150) < 150
    assert 0.5 < support.mean() < 0.6
    # The refit follows the flat glass: its local frequencies match the true ones within 1e-4 of
    # the carrier frequency everywhere (RANSAC alone: ~2.4e-4; the lens strains the grid by up to
    # 10%), and it excludes the lens.
    assert _jacobian_error(refit.matrix, x, y) < 1e-4
    assert abs(refit.excluded_fraction - support.mean()) < 0.1


def test_lens_wider_than_the_view_is_averaged_not_followed_at_its_centre():
    # A Gaussian lens wider than the view: no flat glass. RANSAC's consensus is the lens's centre
    # (a magnification); the refit must do at least as well as a plain least-squares fit of all points.
    lens = _gaussian(170.0, 0.1)
    ransac, refit, x, y = _fits(lens)
    U, V, yy, xx = _logical_grid(lens)
    src, dst = logical_grid_points(U, V, yy, xx, np.ones(U.shape, bool), 10)
    lsq = hm._lsq(src, dst)
    e_refit, e_lsq, e_ransac = (_jacobian_error(H, x, y) for H in (refit.matrix, lsq, ransac.matrix))
    assert e_refit <= 1.05 * e_lsq, (e_refit, e_lsq, e_ransac)
    assert e_refit < 0.8 * e_ransac, (e_refit, e_lsq, e_ransac)


def test_flat_pane_is_unchanged_and_the_cost_is_bounded():
    # No defect: the refit is the true homography; on 4 Mpx of samples it looks at no more than
    # _MAX_REFIT_SAMPLES of them (0.1 s on one core at that size: bounded for any image).
    ransac, refit, x, y = _fits(lambda x, y: (0.0 * x, 0.0 * y))
    assert _jacobian_error(refit.matrix, x, y) < 1e-4
    U, V, y, x = _logical_grid(lambda x, y: (0.0 * x, 0.0 * y), shape=(1600, 2400), noise=0.0)
    S = hm._strain_samples(U, V, y, x, np.ones(U.shape, bool), (1.0, 1.0), PERIOD)
    assert len(S.src) <= hm._MAX_REFIT_SAMPLES
    t = time.perf_counter()
    refit_undistorted(ransac, U, V, y, x, np.ones(U.shape, bool), 10, period_px=PERIOD, step_px=(1.0, 1.0),
                      threshold_px=0.1 * PERIOD)
    assert time.perf_counter() - t < 2.0  # generous for shared CI cores
