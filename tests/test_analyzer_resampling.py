"""The fast paths of the Analyzer against their plain definitions.

OpenCV filters, the disc erosion, block means and the B-spline upsampling of the result
fields replace slower SciPy/NumPy formulations; each is checked against that formulation
(or the analytic field) with a stated tolerance.
"""

import numpy as np
import pytest
from scipy import ndimage

from glassdist.analyzer import fourier as F
from glassdist.analyzer.region import erode
from glassdist.analyzer.resample import bspline_upsample


@pytest.mark.parametrize("sigma", [(0.8, 0.8), (4.8, 3.1), (0.0, 2.0)])
def test_gaussian_blur_equals_scipy(sigma):
    rng = np.random.default_rng(1)
    a = rng.random((120, 170), dtype=np.float32)
    z = (rng.random((120, 170)) + 1j * rng.random((120, 170))).astype(np.complex64)
    for x in (a, z):
        ref = ndimage.gaussian_filter(x, sigma, mode="nearest", truncate=3.5)
        out = F.gaussian_blur(x, sigma, truncate=3.5)
        assert out.dtype == x.dtype and out.shape == x.shape
        assert np.abs(out - ref).max() < 1e-5


@pytest.mark.parametrize("margin", [2.0, 7.5, 12.0])
@pytest.mark.parametrize("edge", [0.0, 5.0, 13.0])
def test_disc_erosion_equals_distance_transform(margin, edge):
    rng = np.random.default_rng(2)
    valid = ndimage.binary_opening(rng.random((90, 130)) > 0.2, iterations=2)
    grid = F.SamplingGrid((270, 520), (90, 130))  # anisotropic step (3, 4) px
    # distance of sample j to the image edge: (j + 1/2) steps, from either side
    dy = np.minimum(np.arange(90) + 0.5, 90 - np.arange(90) - 0.5) * 3
    dx = np.minimum(np.arange(130) + 0.5, 130 - np.arange(130) - 0.5) * 4
    # excluded samples within `margin` of the image edge belong to the edge: not eroded from
    band = (dy[:, None] <= margin) | (dx[None, :] <= margin)
    padded = np.pad(valid | band, 1, constant_values=True)  # outside the image: not an excluded area
    ref = valid & (ndimage.distance_transform_edt(padded, sampling=grid.step)[1:-1, 1:-1] > margin)
    ref &= (dy[:, None] > edge) & (dx[None, :] > edge)
    assert np.array_equal(erode(valid, margin, grid, edge), ref)


def test_block_mean_equals_numpy():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(64, 48, 2)).astype(np.float32)
    w = rng.random((64, 48)) > 0.3
    a[~w] = np.nan
    mean, fill = F.block_mean(a, w, 4)
    wt = w.reshape(16, 4, 12, 4).astype(float)
    s = (np.nan_to_num(a).reshape(16, 4, 12, 4, 2) * wt[..., None]).sum(axis=(1, 3))
    n = wt.sum(axis=(1, 3))
    assert np.allclose(fill, n / 16)
    ok = n > 0
    assert np.allclose(mean[ok], (s / n[..., None])[ok], atol=1e-5)


@pytest.mark.parametrize("k", [2, 3, 4])
def test_bspline_upsampling_reproduces_a_smooth_field(k):
    """Samples at the area-convention positions of a coarse grid, interpolated k x along each axis."""
    S = 13.0  # coarse step, px
    h, w = 40, 50
    field = lambda y, x: np.sin(2 * np.pi * x / 300.0 + 0.3) * np.cos(2 * np.pi * y / 240.0)  # noqa: E731
    yc = np.arange(h) * S + (S - 1) / 2
    xc = np.arange(w) * S + (S - 1) / 2
    f = field(yc[:, None], xc[None, :]).astype(np.float32)
    g = bspline_upsample(bspline_upsample(f, k, 0), k, 1)
    s = S / k
    yf = np.arange(h * k) * s + (s - 1) / 2
    xf = np.arange(w * k) * s + (s - 1) / 2
    truth = field(yf[:, None], xf[None, :])
    # The edge extension's influence decays as 0.27^n over n coarse samples (Unser 1999).
    inner = (slice(8 * k, -8 * k), slice(8 * k, -8 * k))
    assert g.shape == (h * k, w * k)
    assert np.abs(g[inner] - truth[inner]).max() < 1e-4  # bilinear from the coarse grid: ~1e-2


@pytest.mark.parametrize("block_rows", [1, 97, 400, 5000])
@pytest.mark.parametrize("components", [1, 2])
def test_row_blocks_are_bit_identical_to_the_whole_upsampling(block_rows, components):
    from glassdist.analyzer.resample import grid_fill_indices, upsample_field, upsample_field_rows

    rng = np.random.default_rng(7)
    grid = F.SamplingGrid((997, 1201), (150, 180))
    f = rng.normal(size=(150, 180, components)).astype(np.float32)[..., 0 if components == 1 else slice(None)]
    valid = np.ones((150, 180), bool)
    valid[:10] = False
    valid[50:60, 30:90] = False
    f[~valid] = np.nan
    idx = grid_fill_indices(valid)
    invalid = rng.random((997, 1201)) < 0.1
    whole = upsample_field(f, idx, grid, invalid)
    blocks = list(upsample_field_rows(f, idx, grid, invalid, block_rows))
    assert [b[0].start for b in blocks] == list(range(0, 997, block_rows))
    assert np.array_equal(np.concatenate([b for _, b in blocks]), whole, equal_nan=True)


def test_axis_reaches_the_pixel_grid_as_a_doubled_angle():
    """An astigmatism whose shear changes sign (the axis turns by 90 deg) and whose axis crosses the +-90 deg wrap:
    the pixel-grid axis is the analytic one wherever the shear is at least half its peak (measured 0.008 deg), and
    stays in (-90, 90]. Interpolating the angle itself is off by tens of degrees there."""
    from glassdist.analyzer.resample import upsample_axis, upsample_field

    grid = F.SamplingGrid((240, 320), (60, 80))  # 4 px step
    rows, cols = grid.coords()

    def tensor(y, x):
        # a 1-D wave of shear, sign-changing every 40 px, about an axis that turns slowly through 90 deg
        s = np.sin(2 * np.pi * x / 80.0)
        turn = np.radians(70.0 + 40.0 * y / 240.0)
        return s * np.cos(2 * turn), s * np.sin(2 * turn)

    c2, s2 = tensor(rows, cols)
    shear = np.hypot(c2, s2)
    axis = 0.5 * np.degrees(np.arctan2(s2, c2))
    axis = np.where(axis <= -90, axis + 180, axis)
    invalid = np.zeros((240, 320), bool)
    up = upsample_axis(axis, shear, None, grid, invalid)
    Y, X = np.mgrid[0:240, 0:320].astype(float)
    tc, ts = tensor(Y, X)
    true_axis = 0.5 * np.degrees(np.arctan2(ts, tc))
    strong = np.hypot(tc, ts) >= 0.5
    strong[:8], strong[-8:], strong[:, :8], strong[:, -8:] = False, False, False, False  # the spline's edge rows
    err = (up - true_axis + 90.0) % 180.0 - 90.0
    assert up.min() > -90.0 and up.max() <= 90.0
    assert np.abs(err[strong]).max() < 0.05
    plain = (upsample_field(axis, None, grid, invalid) - true_axis + 90.0) % 180.0 - 90.0
    assert np.abs(plain[strong]).max() > 10.0  # the angle itself cannot be interpolated
