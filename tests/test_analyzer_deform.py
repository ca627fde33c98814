"""F5, iterative deformation of the reference: the demodulation follows the local grid.

The truth is the synthetic displacement smoothed by Block F's documented linear transfer
(a Gaussian per carrier, :func:`~glassdist.analyzer.pipeline._demodulation_blur_px2`),
applied here by ``scipy.ndimage.gaussian_filter`` (a line grid: each carrier's kernel is
axis-aligned and reads one displacement component).
"""

import numpy as np
import pytest
from scipy import ndimage

from glassdist import analyze
from glassdist.analyzer import deform as D
from glassdist.analyzer import fourier as F
from glassdist.analyzer.pipeline import _covariances, _demodulation_blur_px2
from glassdist.synthetic import synthetic_capture, wave_displacement

PITCH = 8.0  # mm, 1 mm/px: carrier period 8 px


@pytest.fixture(scope="module")
def strong_wave():
    # Peak strain 2 pi 4 / 80 = 0.31 of the carrier: the one-pass demodulation is no longer linear.
    return synthetic_capture((320, 400), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(4.0, 80.0, 30.0),
                             noise_std=0.01, rng=2)


def _error_periods(cap, res) -> np.ndarray:
    """Displacement error (carrier periods) against the truth through Block F's linear transfer, interior only."""
    ks = res.carriers
    blur = _demodulation_blur_px2(ks, _covariances(ks, res.params), res.params)
    kx = 0 if abs(ks.k1.fx) > abs(ks.k1.fy) else 1  # the carrier along x reads the x component
    t = cap.displacement_mm
    sm = np.stack([
        ndimage.gaussian_filter(t[..., 0], np.sqrt([blur[kx][1, 1], blur[kx][0, 0]]), mode="nearest"),
        ndimage.gaussian_filter(t[..., 1], np.sqrt([blur[1 - kx][1, 1], blur[1 - kx][0, 0]]), mode="nearest"),
    ], axis=-1)
    v = res.valid.copy()
    v[:32] = v[-32:] = False
    v[:, :32] = v[:, -32:] = False
    e = res.displacement_mm - sm
    e -= e[v].mean(axis=0)
    if res.method == "direct":  # relative to the fitted homography: an affine term per component is free
        yy, xx = np.nonzero(v)
        B = np.stack([np.ones_like(xx), xx, yy], axis=1).astype(float)
        for c in range(2):
            coef, *_ = np.linalg.lstsq(B, e[..., c][v], rcond=None)
            e[..., c][v] -= B @ coef
    return e[v] / PITCH


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_deformation_reads_a_strong_wave_through_the_linear_transfer(strong_wave, method):
    ref = strong_wave.reference if method == "comparative" else None
    runs = {n: analyze(strong_wave.image, pitch_mm=PITCH, distance_m=10.0, reference=ref,
                       params={"sigma_mm": 16.0, "detrend_degree": 1, "deformation_passes": n}) for n in (0, 3)}
    one, f5 = (_error_periods(strong_wave, runs[n]) for n in (0, 3))
    # One pass: 0.0054 period RMS, 0.016 at most (the bandpass's non-linear response); deformed: 0.0020, 0.0056.
    assert np.sqrt(np.mean(one**2)) > 0.004
    assert np.sqrt(np.mean(f5**2)) < 0.0023
    assert np.abs(f5).max() < 0.0065
    assert runs[3].valid.mean() >= runs[0].valid.mean() - 0.005


def test_smoothing_correction_is_the_gaussian_on_a_smooth_phase_and_zero_at_a_dislocation():
    grid = F.SamplingGrid((240, 300), (80, 100))
    yy, xx = grid.coords()
    cov = np.array([[30.0, 5.0], [5.0, 20.0]])
    # A quadratic phase: a kernel adds the curvature times its covariance, exactly: the Gaussian's
    # plus the bilinear interpolation's (a triangle of half-width one step: variance step^2 / 6).
    a, b, c = 2e-4, -1e-4, 3e-4
    P = a * xx**2 + b * xx * yy + c * yy**2 + 0.05 * xx
    corr = D.smoothing_correction(np.angle(np.exp(1j * P)), cov, grid)
    sy, sx = grid.step
    expect = a * (cov[0, 0] + sx**2 / 6) + b * cov[0, 1] + c * (cov[1, 1] + sy**2 / 6)
    inner = (slice(20, -20), slice(20, -20))
    assert np.allclose(corr[inner], expect, atol=1e-4)
    # A dislocation (phase winding 2 pi about a point): no correction within reach of the cut.
    th = np.arctan2(yy - 120.0, xx - 150.0)
    corr = D.smoothing_correction(th, cov, grid)
    near = np.hypot(yy - 120.0, xx - 150.0) < 10
    assert np.all(corr[near] == 0.0)


def test_phase_and_displacement_conversions_are_inverse_and_signed():
    pair = F.CarrierPair(F.Carrier(0.1, 0.02), F.Carrier(-0.03, 0.12))
    u = np.random.default_rng(0).normal(size=(5, 7, 2))
    ph = D.displacement_to_phase(u, pair)
    # The photo's carrier phase at r is the reference's at r - u: phi_i = -2 pi f_i . u.
    assert np.allclose(ph[..., 0], -2 * np.pi * (0.1 * u[..., 0] + 0.02 * u[..., 1]))
    assert np.allclose(D.phase_to_displacement_px(ph, pair), u)
