"""F1-F3: carriers, orientation, baseband demodulation."""

import numpy as np
import pytest

from glassdist.analyzer import fourier as F
from glassdist.errors import InputError
from glassdist.synthetic import synthetic_capture


def _two_cosines(shape, f1, f2, phase=(0.0, 0.0)):
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    return (
        0.5
        + 0.2 * np.cos(2 * np.pi * (f1[0] * x + f1[1] * y) + phase[0])
        + 0.2 * np.cos(2 * np.pi * (f2[0] * x + f2[1] * y) + phase[1])
    )


def test_carriers_sub_bin_precision_and_orientation():
    f1, f2 = (0.0912, 0.0131), (-0.0140, 0.0897)  # off-bin on a 480x640 image
    c = F.find_carriers(F.compute_spectrum(_two_cosines((480, 640), f1, f2)))
    found = sorted([tuple(np.round(np.abs(k.f), 6)) for k in (c.k1, c.k2)])
    expect = sorted([tuple(np.abs(f1)), tuple(np.abs(f2))])
    # Jacobsen refinement: well below 1e-3 bin (1 bin = 1/640 cycles/px).
    assert np.allclose(found, expect, atol=1e-3 / 640)
    assert np.linalg.det(c.matrix) > 0  # same handedness as the image frame


@pytest.mark.parametrize("rotation", [0.0, 17.0, 45.0])
def test_checkerboard_carriers_are_diagonal_with_period_sqrt2_square(rotation):
    cap = synthetic_capture((256, 256), pitch_mm=6.0, mm_per_px=1.0, pattern="checkerboard", rotation_deg=rotation)
    c = F.find_carriers(F.compute_spectrum(cap.image))
    for k in (c.k1, c.k2):
        assert k.period_px == pytest.approx(6.0 * np.sqrt(2.0), rel=2e-3)
    ang = abs(c.k1.angle_deg - c.k2.angle_deg) % 180
    assert min(ang, 180 - ang) == pytest.approx(90.0, abs=0.3)
    axes = {round((k.angle_deg - rotation - 45.0) % 90.0, 1) % 90.0 for k in (c.k1, c.k2)}
    assert all(min(a, 90 - a) < 0.5 for a in axes)


def test_line_grid_ignores_cross_term():
    # A crossed line grid has strong k1 + k2 cross terms at 45 deg; the carriers must be the fundamentals.
    cap = synthetic_capture((256, 320), pitch_mm=8.0, mm_per_px=1.0, pattern="lines", rotation_deg=3.0)
    c = F.find_carriers(F.compute_spectrum(cap.image))
    for k in (c.k1, c.k2):
        assert k.period_px == pytest.approx(8.0, rel=2e-3)


def test_noise_image_has_no_grid():
    rng = np.random.default_rng(1)
    with pytest.raises(InputError, match="no grid"):
        F.find_carriers(F.compute_spectrum(rng.random((200, 200))))


def test_baseband_phase_measures_a_shift_exactly():
    # A grid shifted by s px along carrier 1: the heterodyne phase is 2 pi f1 . s.
    f1, f2 = (0.1, 0.02), (-0.015, 0.11)
    a = _two_cosines((200, 240), f1, f2)
    shift = np.array([0.7, -0.3])  # px, (x, y)
    b = _two_cosines((200, 240), f1, f2, phase=(2 * np.pi * np.dot(f1, shift), 2 * np.pi * np.dot(f2, shift)))
    sa, sb = F.compute_spectrum(a), F.compute_spectrum(b)
    c = F.find_carriers(sa)
    covs = [F.bandpass_covariance(c.k1, c.k2, sigma_along=0.3, sigma_cross=0.22),
            F.bandpass_covariance(c.k2, c.k1, sigma_along=0.3, sigma_cross=0.22)]
    grid = F.sampling_grid(a.shape, covs)
    assert grid.shape[0] < a.shape[0]  # demodulated on a coarser grid
    for k, cov in zip((c.k1, c.k2), covs):
        z = F.baseband(sb, k, cov, grid) * np.conj(F.baseband(sa, k, cov, grid))
        inner = np.angle(z)[5:-5, 5:-5]
        assert np.allclose(inner, 2 * np.pi * np.dot(k.f, shift), atol=2e-3)


def test_sampling_grid_positions_match_area_resampling():
    g = F.SamplingGrid((100, 120), (25, 30))
    yy, xx = g.coords()
    assert g.step == (4.0, 4.0)
    assert yy[0, 0] == pytest.approx(1.5) and xx[0, 1] == pytest.approx(5.5)


def test_thin_lines_pick_the_fundamental_not_a_harmonic():
    from glassdist.synthetic import backdrop_pattern

    y, x = np.mgrid[0:256, 0:320].astype(float)
    img = backdrop_pattern(x, y, pitch_mm=12.0, line_width=0.1)  # lines 1.2 px wide: strong harmonics
    c = F.find_carriers(F.compute_spectrum(img))
    assert c.k1.period_px == pytest.approx(12.0, rel=2e-3) and c.k2.period_px == pytest.approx(12.0, rel=2e-3)


def test_opaque_object_does_not_outshine_the_grid():
    cap = synthetic_capture((300, 360), pitch_mm=8.0, mm_per_px=1.0)
    img = 0.5 + 0.06 * (cap.image - 0.5)
    img[100:250, 80:300] = 0.3  # large dark object with sharp edges
    c = F.find_carriers(F.compute_spectrum(img))
    assert c.k1.period_px == pytest.approx(8.0, rel=5e-3)


def test_frequency_modulated_carrier_is_found_at_its_mean_frequency():
    """A strong roller wave spreads a carrier into sidebands taller than the carrier bin
    (FM index 2: J1(2) = 0.58 > J0(2) = 0.22); the mean frequency must be found, not a sideband."""
    H, W = 480, 640
    y, x = np.mgrid[0:H, 0:W].astype(float)
    fx, fy, fm, beta = 0.125, 0.125, 12 / 640, 2.0
    img = 0.5 + 0.2 * np.cos(2 * np.pi * fx * x + beta * np.sin(2 * np.pi * fm * x)) + 0.2 * np.cos(2 * np.pi * fy * y)
    c = F.find_carriers(F.compute_spectrum(img))
    found = sorted(abs(k.fx) + abs(k.fy) for k in (c.k1, c.k2))
    assert found == pytest.approx([0.125, 0.125], abs=0.25 / 640)  # a sideband would be 12 bins off


def test_baseband_applies_the_rotated_gaussian_bandpass():
    """A tone off the carrier by delta comes out at 0.5 A exp(-delta^T Sigma^-1 delta / 2) (closed form).

    The bandpass covariance is anisotropic and rotated 30 deg, so its cross term decides the
    answer: the covariance mirrored (cross term of the other sign) would give 2.4x the amplitude.
    """
    H = W = 256
    y, x = np.mgrid[0:H, 0:W].astype(float)
    f0, d = np.array([32 / W, 12 / H]), np.array([2 / W, -1 / H])  # carrier and offset, whole bins (x, y)
    image = 0.5 + 0.4 * np.cos(2 * np.pi * ((f0[0] + d[0]) * x + (f0[1] + d[1]) * y))
    t = np.radians(30.0)
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    cov = R @ np.diag([0.012**2, 0.005**2]) @ R.T  # cycles^2/px^2, (x, y) order
    b = F.baseband(F.compute_spectrum(image), F.Carrier(f0[0], f0[1]), cov, F.sampling_grid((H, W), [cov]))
    expect = 0.2 * np.exp(-0.5 * d @ np.linalg.inv(cov) @ d)
    mirrored = 0.2 * np.exp(-0.5 * d @ np.linalg.inv(cov * np.array([[1, -1], [-1, 1]])) @ d)
    assert abs(mirrored / expect - 1) > 1.0
    np.testing.assert_allclose(np.abs(b), expect, rtol=1e-3)


def test_f3_smoothing_in_the_patch_is_the_gaussian_of_its_sigma():
    """F3 applied in the spectral patch (Direct Method): a tone delta off the carrier comes out of ``G * b`` at
    |b| exp(-2 pi^2 sigma^2 |delta|^2), the transfer of a Gaussian of sigma px (closed form): 0.805 of |b| at
    sigma = 12 px here, where a Gaussian of 0.8 sigma would leave 0.87."""
    H = W = 256
    y, x = np.mgrid[0:H, 0:W].astype(float)
    f0, d = np.array([32 / W, 12 / H]), np.array([2 / W, -1 / H])
    image = 0.5 + 0.4 * np.cos(2 * np.pi * ((f0[0] + d[0]) * x + (f0[1] + d[1]) * y))
    cov = np.diag([0.02**2, 0.02**2])
    b, gb = F.baseband(F.compute_spectrum(image), F.Carrier(f0[0], f0[1]), cov, F.sampling_grid((H, W), [cov]),
                       smooth_sigma_px=12.0)
    gain = np.exp(-2 * np.pi**2 * 12.0**2 * (d @ d))
    np.testing.assert_allclose(np.abs(gb), gain * np.abs(b), rtol=1e-3)
    assert gain == pytest.approx(0.805, abs=0.001)


@pytest.mark.parametrize("a1,a2,between", [(10.0, 170.0, 20.0), (-80.0, 70.0, 30.0), (0.0, 90.0, 90.0), (5.0, 65.0, 60.0),
                                            (-100.0, 100.0, 20.0)])
def test_angle_between_carriers_is_that_of_the_lines(a1, a2, between):
    """The recorded angle between the two carriers is that of the grid's lines: modulo 180 deg, at most 90."""
    k = [F.Carrier(0.1 * np.cos(np.radians(a)), 0.1 * np.sin(np.radians(a))) for a in (a1, a2)]
    assert F.CarrierPair(*k).to_dict()["angle_between_deg"] == pytest.approx(between)


def test_a_cross_term_stronger_than_the_second_family_is_not_taken_for_it():
    """Lines along k1, a weaker family along k2 (100 deg from it) and a cross-modulation term k1 + k2 stronger than
    k2 (50 deg from k1, so a candidate): k2 is the second carrier, not the cross term (paper §2.2 F1)."""
    H = W = 256
    y, x = np.mgrid[0:H, 0:W].astype(float)
    k1 = np.array([26 / W, 0.0])
    k2 = np.array([-4 / W, 25 / H])  # about 99 deg from k1, on whole bins
    tone = lambda k: np.cos(2 * np.pi * (k[0] * x + k[1] * y))  # noqa: E731
    image = 0.5 + 0.3 * tone(k1) + 0.08 * tone(k2) + 0.12 * tone(k1 + k2)
    pair = F.find_carriers(F.compute_spectrum(image))
    f1, f2 = np.array([pair.k1.fx, pair.k1.fy]), np.array([pair.k2.fx, pair.k2.fy])
    assert min(np.linalg.norm(f1 - k1), np.linalg.norm(f1 + k1)) < 0.2 / W
    assert min(np.linalg.norm(f2 - k2), np.linalg.norm(f2 + k2)) < 0.2 / W


@pytest.mark.parametrize("coarse", [(256, 256), (64, 64), (48, 80)])
def test_baseband_is_the_analytic_signal_at_the_grid_sample_positions(coarse):
    """A tone d off the carrier: b(r) = 0.2 g exp(2 pi i d . r) at each sample centre r of the grid (closed form),
    on the full grid and on coarser ones whose samples sit between pixels (offset (step - 1) / 2)."""
    H = W = 256
    y, x = np.mgrid[0:H, 0:W].astype(float)
    f0, d = np.array([32 / W, 12 / H]), np.array([2 / W, -1 / H])
    image = 0.5 + 0.4 * np.cos(2 * np.pi * ((f0[0] + d[0]) * x + (f0[1] + d[1]) * y))
    cov = np.diag([0.02**2, 0.02**2])
    grid = F.SamplingGrid((H, W), coarse)
    b = F.baseband(F.compute_spectrum(image), F.Carrier(f0[0], f0[1]), cov, grid)
    rows, cols = grid.coords()
    g = np.exp(-0.5 * d @ np.linalg.inv(cov) @ d)
    want = 0.2 * g * np.exp(2j * np.pi * (d[0] * cols + d[1] * rows))
    np.testing.assert_allclose(b, want, atol=2e-4 * 0.2)


def test_a_finer_grid_along_the_rows_alone_is_refused():
    """A family of lines 2.5 px apart running down the image (its peak on the spectrum's first row, ky = 0) beside a
    legitimate 8 px pair: the finer grid is seen and the photo refused, not read at the wrong scale."""
    from glassdist.errors import InputError

    H, W = 200, 240
    y, x = np.mgrid[0:H, 0:W].astype(float)
    tone = lambda fx, fy: np.cos(2 * np.pi * (fx * x + fy * y))  # noqa: E731
    a = np.radians(60.0)
    image = 0.5 + 0.1 * tone(0.0, 1 / 8) + 0.1 * tone(np.cos(a) / 8, np.sin(a) / 8) + 0.25 * tone(0.4, 0.0)
    with pytest.raises(InputError, match="about 2.50 px, below the 3 px"):
        F.find_carriers(F.compute_spectrum(image))


def test_the_carrier_band_runs_from_four_periods_across_the_image_to_the_finest_period():
    """A crossed grid of 5 periods across the image is found (the band starts at 4, below it is illumination), and
    a stronger 2.5 px family on the diagonal, finer than min_period_px, is never taken for a carrier."""
    H = W = 256
    y, x = np.mgrid[0:H, 0:W].astype(float)
    tone = lambda fx, fy: np.cos(2 * np.pi * (fx * x + fy * y))  # noqa: E731
    coarse = F.find_carriers(F.compute_spectrum(0.5 + 0.2 * tone(5 / W, 0.0) + 0.2 * tone(0.0, 5 / H)))
    assert sorted(round(k.period_px, 1) for k in (coarse.k1, coarse.k2)) == [51.2, 51.2]
    d = 0.4 / np.sqrt(2.0)  # 2.5 px, along the diagonal: inside the square |fx|, |fy| < 1/3
    image = 0.5 + 0.1 * tone(32 / W, 0.0) + 0.1 * tone(0.0, 32 / H) + 0.25 * tone(d, d)
    pair = F.find_carriers(F.compute_spectrum(image))
    assert sorted(round(k.period_px, 2) for k in (pair.k1, pair.k2)) == [8.0, 8.0]


def test_a_peak_is_a_5x5_maximum_beside_the_rows_and_columns_the_pooling_skips():
    """``_spectral_peaks`` returns 5x5 local maxima. Its 4x4 pooling skips the last H % 4 rows and
    W % 4 columns; a stronger bin there, three bins away (outside the 5x5 window; rows wrap), must not
    hide a peak."""
    work = np.zeros((67, 67))
    work[1, 20], work[65, 20] = 1.0, 2.0  # rows 1 and 65: three rows apart across the wrap
    work[30, 62], work[30, 65] = 1.0, 2.0  # columns 62 and 65: three columns apart
    got = set(F._spectral_peaks(work, 10).tolist())
    assert {1 * 67 + 20, 30 * 67 + 62} <= got


def test_a_harmonic_inside_the_carrier_band_is_not_a_finer_grid():
    """Thin lines whose second harmonic is stronger than their fundamental: with ``min_period_px``
    2.5 the harmonic (2.8 px) lies inside the carrier band, so the grid is read at its fundamental
    (5.6 px), not refused as finer than the band."""
    y, x = np.mgrid[0:480, 0:640].astype(float)
    img = 0.5 + 0.08 * np.cos(2 * np.pi * x / 5.6) + 0.2 * np.cos(2 * np.pi * x / 2.8) + 0.12 * np.cos(2 * np.pi * y / 6.0)
    c = F.find_carriers(F.compute_spectrum(img), min_period_px=2.5)
    assert sorted(k.period_px for k in (c.k1, c.k2)) == pytest.approx([5.6, 6.0], rel=1e-3)


def test_spectral_centroid_of_a_symmetric_sideband_comb_is_its_centre():
    """A carrier with equal sidebands at every offset up to 20 bins along ky: the power centroid lies
    on the carrier (the Gaussian-weighted window is symmetric about it, so no side is cut short)."""
    n = 256
    y, x = np.mgrid[0:n, 0:n].astype(float)
    img = np.cos(2 * np.pi * (26 * x + 10 * y) / n)
    for d in range(1, 21):
        for s in (1, -1):
            img += 0.4 * np.cos(2 * np.pi * (26 * x + (10 + s * d) * y) / n)
    cy, cx = F._spectral_centroid(F.compute_spectrum(img), 10.0, 26.0)
    assert (cy, cx) == pytest.approx((10.0, 26.0), abs=1e-3)


def test_the_auto_grid_carries_the_band_and_no_more():
    """The coarse grid spans +-4 standard deviations of the widest bandpass along each axis
    (no aliasing) and is the next multiple of 4 above that, no wider (its size is the cost of F3-F5)."""
    shape, sd = (1000, 1200), 0.02
    g = F.sampling_grid(shape, [np.diag([sd**2, (sd / 2) ** 2])])
    for n, N in zip(g.shape, shape):
        need = 2 * 4 * sd * N
        assert need <= n <= 2 * np.ceil(4 * sd * N) + 4
