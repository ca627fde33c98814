"""The per-pixel uncertainty of the channels takes off what the A2 detrend removes of the noise.

Two checks: the closed form (:func:`glassdist.analyzer.uncertainty.detrended_gradient_covariance`)
against a Monte Carlo of white noise through a polynomial detrend (``numpy.linalg.lstsq``), a
first-order normalised Gaussian (``tests/_truth.py``) and centred differences; and the
Analyzer's ``phi_eff_sigma_mD`` against the scatter of repeated single captures where sigma is
a fair part of the view (sigma = 3 carrier periods, N = 4: the prediction without the detrend
term read three times the scatter), both methods.
"""

import numpy as np
import pytest
from scipy import ndimage

from _truth import detrend, smooth


@pytest.mark.slow
def test_detrended_gradient_covariance_against_monte_carlo():
    from glassdist.analyzer.uncertainty import detrended_gradient_covariance

    h, w, sigma, degree = 48, 64, 8.0, 4
    region = np.ones((h, w), bool)
    region[:10, :16] = False  # a notch: the border term and the fit see it
    C = detrended_gradient_covariance(region.astype(int), degree, sigma, (1.0, 1.0))
    rng = np.random.default_rng(3)
    gx = []
    for _ in range(200):
        n = rng.normal(size=(h, w))
        s = smooth(detrend(n, region, degree), region, sigma, order=1)
        gx.append(np.gradient(np.where(region, s, 0.0), axis=1))
    emp = np.var(np.stack(gx), axis=0)
    # more than 2 sigma inside (past the guard band): closer, the centred difference of the smoothed values is
    # noisier than the local plane's slope
    inner = region & (ndimage.distance_transform_edt(np.pad(region, 1))[1:-1, 1:-1] > 2 * sigma)
    ratio = emp[inner] / C[..., 0, 0][inner]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.1)
    # the detrend's share is large here: without it (degree 0 removes the mean only, of no gradient)
    # the closed form is well above the scatter
    C0 = detrended_gradient_covariance(region.astype(int), 0, sigma, (1.0, 1.0))
    assert np.median(emp[inner] / C0[..., 0, 0][inner]) < 0.8


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_phi_eff_sigma_matches_the_scatter_at_large_sigma_and_degree(method):
    from glassdist import analyze
    from glassdist.synthetic import synthetic_capture, wave_displacement

    period, noise, n = 8.0, 0.02, 12
    disp = wave_displacement(0.05 * period, 12.0 * period, 25.0)
    rng = np.random.default_rng(0)
    vals, preds, trusted = [], [], None
    for _ in range(n):
        cap = synthetic_capture((160, 208), pitch_mm=period, mm_per_px=1.0, displacement=disp, noise_std=noise, rng=rng)
        res = analyze(cap.image, pitch_mm=period, distance_m=1.0, reference=cap.reference if method == "comparative" else None,
                      params={"sigma_mm": 3 * period, "detrend_degree": 4})
        trusted = res.trusted.copy() if trusted is None else trusted & res.trusted
        vals.append(res.phi_eff_mD.astype(float))
        preds.append(res.phi_eff_sigma_mD.astype(float))
    assert trusted.mean() > 0.1
    emp = np.std(np.stack(vals), axis=0, ddof=1)[trusted]
    pred = np.mean(np.stack(preds), axis=0)[trusted]
    assert 0.8 <= float(np.median(pred / emp)) <= 1.25
