"""A2-A3: closed-form strain fields, detrending, smoothing, conventions.

These tests check the shared evaluation stack itself (``evaluate_displacement`` and its
parts), each against a closed form; the analyzer's accuracy tests compare it with the
independent truth of ``tests/_truth.py`` instead.
"""

import numpy as np
import pytest

from glassdist.analyzer.metrics import (
    channel_statistics,
    detrend_increment,
    evaluate_displacement,
    masked_gaussian,
    polynomial_detrend,
    strain_tensor,
)

L = 10.0


def _grid(h=60, w=80, s=2.0):
    y, x = np.mgrid[0:h, 0:w].astype(float)
    return x * s, y * s  # backdrop mm, mm_per_px = s


def _eval(dx, dy, s=2.0, **kw):
    d = np.stack([dx, dy], -1)
    kw.setdefault("detrend_degree", 0)
    kw.setdefault("sigma_mm", 1e-6)
    return evaluate_displacement(d, np.ones(dx.shape, bool), distance_m=L, mm_per_px=s, **kw)


def test_uniform_dilation_is_pure_power():
    X, Y = _grid()
    a = 1e-3
    ch = _eval(a * X, a * Y)
    assert np.allclose(ch.phi_eff_mD, 2 * a / L * 1000)
    assert np.allclose(ch.phi_shear_mD, 0, atol=1e-9)
    assert np.allclose(ch.phi_total_mD, np.sqrt(2) * a / L * 1000)


def test_pure_shear_is_pure_astigmatism_with_axis():
    X, Y = _grid()
    a = 1e-3
    ch = _eval(a * X, -a * Y)  # stretch along x, compress along y
    assert np.allclose(ch.phi_eff_mD, 0, atol=1e-9)
    assert np.allclose(ch.phi_shear_mD, 2 * a / L * 1000)
    assert np.allclose(ch.axis_deg, 0.0)
    ch = _eval(a * Y, a * X)  # simple shear: stretch along the diagonal x = y (+x towards +y)
    assert np.allclose(ch.phi_shear_mD, 2 * a / L * 1000)
    assert np.allclose(ch.axis_deg, 45.0)


def test_rigid_rotation_and_translation_read_zero():
    X, Y = _grid()
    t = 2e-3
    ch = _eval(-t * Y + 3.0, t * X - 1.0)
    for c in (ch.phi_eff_mD, ch.phi_shear_mD, ch.phi_total_mD):
        assert np.allclose(c, 0, atol=1e-9)


def test_converging_lens_sign_convention():
    # delta = -P L r (landing points pulled to the axis): phi_eff = -2P.
    X, Y = _grid()
    P = 0.004  # D
    r0 = np.array([X.mean(), Y.mean()])
    ch = _eval(-P * L * (X - r0[0]), -P * L * (Y - r0[1]))
    assert np.allclose(ch.phi_eff_mD, -2 * P * 1000)
    assert np.all(ch.phi_eff_mD < 0)


def test_jacobian_path_equals_isotropic_for_a_similarity():
    X, Y = _grid()
    d = np.stack([1e-3 * np.sin(X / 20), 2e-3 * np.cos(Y / 15)], -1)
    J = np.broadcast_to(2.0 * np.eye(2), X.shape + (2, 2))
    a = strain_tensor(d, mm_per_px=2.0)
    b = strain_tensor(d, jacobian=J)
    assert np.allclose(a, b)


def test_anisotropic_jacobian_exact_gradients():
    # Foreshortened view: 3 mm/px along x, 2 mm/px along y.
    h, w = 40, 50
    y, x = np.mgrid[0:h, 0:w].astype(float)
    X, Y = 3.0 * x, 2.0 * y
    a, b = 1e-3, -2e-3
    d = np.stack([a * X, b * Y], -1)
    J = np.broadcast_to(np.diag([3.0, 2.0]), (h, w, 2, 2))
    eps = strain_tensor(d, jacobian=J)
    assert np.allclose(eps[..., 0, 0], a) and np.allclose(eps[..., 1, 1], b)


@pytest.mark.parametrize("degree", [0, 1, 2, 4])
def test_detrend_removes_polynomials_of_its_degree_per_region(degree):
    X, Y = _grid(50, 60, 1.0)
    rng = np.random.default_rng(3)
    labels = np.ones(X.shape, int)
    labels[:, 30:] = 2
    f = np.zeros(X.shape)
    for r in (1, 2):
        c = rng.normal(size=(degree + 1, degree + 1))
        poly = sum(c[i, j] * (X / 50) ** i * (Y / 50) ** j for i in range(degree + 1) for j in range(degree + 1 - i))
        f[labels == r] = poly[labels == r]
    assert np.allclose(polynomial_detrend(f, labels, degree), 0, atol=1e-8)
    if degree >= 1:
        assert not np.allclose(polynomial_detrend(f, labels, degree - 1), 0, atol=1e-3)


@pytest.mark.parametrize("degree", [1, 3, 4])
def test_detrend_increment_is_the_top_degree_part_of_a_polynomial(degree):
    # f = (degree-N polynomial) + (a polynomial of exact degree N + 1 orthogonal to nothing in
    # particular) per region: raising N removes the rest of f, so the increment is f's degree-N
    # residual; on a field with NaN holes the identity with two separate detrends holds too.
    X, Y = _grid(50, 60, 1.0)
    rng = np.random.default_rng(5)
    labels = np.ones(X.shape, int)
    labels[:, 30:] = 2
    labels[:4] = 0
    f = np.zeros(X.shape)
    for r in (1, 2):
        c = rng.normal(size=(degree + 2, degree + 2))
        poly = sum(c[i, j] * (X / 50) ** i * (Y / 50) ** j for i in range(degree + 2) for j in range(degree + 2 - i))
        f[labels == r] = poly[labels == r]
    inc = detrend_increment(f, labels, degree)
    assert np.isnan(inc[labels == 0]).all()
    assert np.allclose(inc[labels > 0], polynomial_detrend(f, labels, degree)[labels > 0], atol=1e-8)
    noisy = f + rng.normal(size=f.shape)
    noisy[10:14, 5:9] = np.nan
    two = np.stack([noisy, -noisy], -1)
    inc = detrend_increment(two, labels, degree)
    want = polynomial_detrend(two, labels, degree) - polynomial_detrend(two, labels, degree + 1)
    ok = np.isfinite(want)
    assert np.allclose(inc[ok], want[ok], atol=1e-9) and np.abs(inc[ok]).max() > 1e-3


def test_masked_gaussian_keeps_linear_fields_and_matches_sigma():
    X, Y = _grid(80, 80, 1.0)
    w = np.ones(X.shape)
    w[:, :10] = 0
    lin = 0.3 * X - 0.1 * Y
    out = masked_gaussian(lin, w, 4.0**2 * np.eye(2))
    assert np.allclose(out[:, 10:], lin[:, 10:], atol=1e-6)
    # A sinusoid of wavelength 40 px is attenuated by exp(-2 pi^2 sigma^2 / 40^2).
    s = np.sin(2 * np.pi * X / 40.0)
    out = masked_gaussian(s, np.ones(X.shape), 4.0**2 * np.eye(2))
    expect = np.exp(-2 * np.pi**2 * 16 / 1600)
    assert np.ptp(out[20:60, 20:60]) / 2 == pytest.approx(expect, rel=2e-3)


@pytest.mark.parametrize("s", [30.0, 3.0])
def test_masked_gaussian_with_a_singular_covariance_smooths_along_one_direction(s):
    """A rank-one covariance (a kernel along (1, 1)) leaves a field constant along (1, 1) unchanged.

    s = 30 px reaches beyond the 40 x 50 field (the kernel sampled in space, regularised when
    singular); s = 3 px uses the continuous transfer. A kernel spread across (1, 1), or one
    whose regularisation is lost, blurs the 10 px wave across its crests.
    """
    y, x = np.mgrid[0:40, 0:50].astype(float)
    f = np.sin(2 * np.pi * (x - y) / 10.0)
    cov = s**2 * np.array([[1.0, 1.0], [1.0, 1.0]])  # (x, y) order, det = 0
    out = masked_gaussian(f, np.ones(f.shape), cov)[5:-5, 5:-5]  # (two corners see only themselves)
    assert np.all(np.isfinite(out))
    assert np.max(np.abs(out - f[5:-5, 5:-5])) < 1e-3  # measured 7e-16 (s = 30) and 7e-5 (s = 3)


def test_statistics():
    f = np.array([[1.0, -2.0], [np.nan, 4.0]])
    st = channel_statistics(f, np.array([[True, True], [True, False]]))
    assert st["mean_abs"] == pytest.approx(1.5) and st["max_abs"] == 2.0 and st["n_valid"] == 2


@pytest.mark.parametrize("case", ["normal32", "heavy_tail64", "ties", "raster_sorted"])
def test_percentile_is_numpys_bit_for_bit(case):
    """The bracketed selection returns numpy.percentile exactly, also where its sample misleads."""
    from glassdist.analyzer.metrics import percentile

    rng = np.random.default_rng(11)
    n = 700_001
    a = {
        "normal32": lambda: rng.normal(size=n).astype(np.float32),
        "heavy_tail64": lambda: np.abs(rng.standard_cauchy(n)),
        "ties": lambda: rng.integers(0, 4, n).astype(np.float32),
        # a strided sample of a sorted array is evenly spread: brackets near the ends clip
        "raster_sorted": lambda: np.sort(rng.random(n).astype(np.float32)),
    }[case]()
    before = a.copy()
    for q in (0.0, 5.0, 50.0, 95.0, 99.5, 100.0):
        assert percentile(a, q) == float(np.percentile(a, q))
    assert np.array_equal(a, before)


def test_gradients_of_a_lightly_smoothed_wave_are_those_of_the_smoothed_field():
    """sigma = 4 px: A3's five-point stencil would pass 1 - w^4/30 of the content the smoothing keeps, so the
    stack divides the x and y kernels by the stencil's transfer (the Notes of ``evaluate_displacement``).

    Closed form: delta = A (sin(k X), sin(k Y)) smoothed by the Gaussian of sigma reads
    phi_eff = A k exp(-k^2 sigma^2 / 2) (cos kX + cos kY) / L, phi_shear = A k g |cos kX - cos kY| / L.
    Interior only (4 sigma from the edges). Measured: 3.2e-4 of the peak at most (phi_eff); margin 1e-3 of
    the peak, which a kernel of the wrong axis or scale exceeds by far (a y kernel 1.5x: 0.25 of the peak).
    """
    s, sigma_mm, lam, A = 1.0, 4.0, 16.0, 0.05
    X, Y = _grid(128, 144, s)
    k = 2 * np.pi / lam
    ch = _eval(A * np.sin(k * X), A * np.sin(k * Y), s=s, sigma_mm=sigma_mm)
    g = np.exp(-0.5 * (k * sigma_mm) ** 2)
    eff = A * k * g * (np.cos(k * X) + np.cos(k * Y)) / L * 1000
    shear = A * k * g * np.abs(np.cos(k * X) - np.cos(k * Y)) / L * 1000
    inner = (slice(16, -16), slice(16, -16))
    peak = 2 * A * k * g / L * 1000
    assert np.max(np.abs(ch.phi_eff_mD[inner] - eff[inner])) < 1e-3 * peak
    assert np.max(np.abs(ch.phi_shear_mD[inner] - shear[inner])) < 1e-3 * peak


@pytest.mark.parametrize("shape", [(40, 20), (21, 26)])
def test_a_kernel_wider_than_the_data_is_centred_on_an_odd_fft_grid(shape):
    """A kernel reaching beyond the data is sampled on the FFT grid (here 75 x 45 and 44 x 54 samples, odd and even)
    with its offsets wrapped around the origin: the zeroth-order normalised convolution equals the direct sum over
    every pair of samples of a correlated Gaussian (x, y order covariance). Exactly (1e-14) where both axes span the
    data twice; on 40 rows the row axis is padded by the kernel's reach (4 sigma + 1) only, and the kernel's values
    from 37 to 39 rows off (5e-5 of its peak) wrap around: 1.6e-5 here. A kernel off by one sample (a wrong centre on
    an odd grid) is off by a tenth of the field's step."""
    from glassdist.analyzer.metrics import masked_gaussian

    h, w = shape
    rng = np.random.default_rng(7)
    field = rng.normal(size=shape) + 0.3 * np.arange(w)[None, :]
    weight = np.ones(shape)
    weight[3:6, 4:9] = 0.0
    cov = np.array([[100.0, 40.0], [40.0, 64.0]])  # px^2, (x, y)
    got = masked_gaussian(field, weight, cov, order=0)
    y, x = np.mgrid[0:h, 0:w]
    dx = x.ravel()[:, None] - x.ravel()[None, :]
    dy = y.ravel()[:, None] - y.ravel()[None, :]
    ci = np.linalg.inv(cov)
    k = np.exp(-0.5 * (ci[0, 0] * dx**2 + 2 * ci[0, 1] * dx * dy + ci[1, 1] * dy**2)) * weight.ravel()[None, :]
    want = (k @ field.ravel() / k.sum(axis=1)).reshape(shape)
    assert np.abs(got - want).max() < (3e-5 if shape == (40, 20) else 1e-12)


@pytest.mark.parametrize("data_shape, fft_shape", [((600, 900), (640, 960)), ((37, 51), (80, 120)), ((101, 130), (125, 135))])
def test_cropped_inverse_transform_equals_irfft2_bit_for_bit(data_shape, fft_shape):
    """Block A's inverse transforms skip the padding's rows: the kept samples equal scipy.fft.irfft2's exactly."""
    import scipy.fft as sfft

    from glassdist.analyzer.metrics import _irfft2_cropped

    rng = np.random.default_rng(7)
    a = rng.standard_normal((3,) + data_shape)
    spectra = sfft.rfft2(a, s=fft_shape, axes=(-2, -1)) * rng.random((fft_shape[0], fft_shape[1] // 2 + 1))
    want = sfft.irfft2(spectra, s=fft_shape, axes=(-2, -1))[:, : data_shape[0], : data_shape[1]]
    got = _irfft2_cropped(spectra.copy(), fft_shape, data_shape)
    assert got.shape == want.shape
    assert np.array_equal(got, want)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("order", [0, 1])
def test_moment_spectra_equal_the_padded_transform_of_the_stacked_moments(dtype, order):
    """The moments written into the padded array: the spectra of rfft2(stack(moments), s=shape), bit for bit."""
    import scipy.fft as sfft

    from glassdist.analyzer.metrics import _moment_spectra

    rng = np.random.default_rng(11)
    h, w, shape = 37, 51, (80, 120)
    field = rng.standard_normal((h, w)).astype(dtype)
    field[3, 4] = np.nan
    weight = (rng.random((h, w)) > 0.2).astype(float)
    got, xx, yy = _moment_spectra(field, weight, shape, order)
    f = np.where(weight > 0, np.nan_to_num(field), 0.0)
    wgt = (weight > 0).astype(float)
    arrays = [wgt, f]
    if order:
        arrays += [wgt * xx, wgt * yy, wgt * xx * xx, wgt * xx * yy, wgt * yy * yy, f * xx, f * yy]
    assert np.array_equal(got, sfft.rfft2(np.stack(arrays), s=shape, axes=(-2, -1)))
