"""phi_total = ||eps||_F / L on a pure shear: the off-diagonal strain counts twice in the Frobenius norm.

Paper §2.2.3 (A3): phi_total = ||eps||_F / L, eps = sym(grad delta), with delta in mm,
gradients with respect to backdrop mm and L in m (D; x 1000 for mD). On a pure shear
(eps_xx = eps_yy = 0) ||eps||_F^2 = eps_xy^2 + eps_yx^2 = 2 eps_xy^2, so phi_total =
sqrt(2) |eps_xy| / L, and phi_shear = 2 |eps_xy| / L: phi_total / phi_shear = 1 / sqrt(2)
exactly. A norm that counts the shear term once (eps_xx^2 + eps_yy^2 + eps_xy^2) reads
|eps_xy| / L, 0.707 of it; on a pure dilation the two agree, so only a shear can tell them
apart.
"""

import numpy as np
import pytest

from _truth import truth_for
from glassdist import analyze
from glassdist.analyzer.metrics import evaluate_displacement
from glassdist.synthetic import synthetic_capture, wave_displacement

L = 10.0  # m
PITCH = 8.0


def _channels(dx, dy, mm_per_px):
    d = np.stack([dx, dy], -1)
    return evaluate_displacement(d, np.ones(dx.shape, bool), distance_m=L, mm_per_px=mm_per_px, detrend_degree=0,
                                 sigma_mm=1e-6)


def test_uniform_simple_shear_reads_sqrt2_exy_over_L():
    """delta = a (Y, X): eps = [[0, a], [a, 0]], phi_total = sqrt(2) a / L exactly."""
    y, x = np.mgrid[0:60, 0:80].astype(float)
    X, Y = 2.0 * x, 2.0 * y  # backdrop mm, 2 mm per px
    a = 1e-3
    ch = _channels(a * Y, a * X, 2.0)
    assert np.allclose(ch.phi_eff_mD, 0.0, atol=1e-9)
    assert np.allclose(ch.phi_total_mD, np.sqrt(2) * a / L * 1000.0, rtol=1e-9)  # 0.1414 mD; 0.1 with eps_xy once
    assert np.allclose(ch.phi_shear_mD, 2 * a / L * 1000.0, rtol=1e-9)


def test_transverse_wave_pure_shear_closed_form():
    """delta_x = A sin(2 pi Y / Lambda), delta_y = 0: eps_xy = (pi A / Lambda) cos(2 pi Y / Lambda), nothing else.

    Centred differences on 100 px per wavelength read the cosine to (k h)^2 / 6 = 7e-4;
    tolerance 2e-3 of the peak.
    """
    h, w, s = 200, 120, 2.0
    y = np.arange(h, dtype=float)[:, None] * s + np.zeros((1, w))
    A, lam = 0.5, 200.0  # mm
    ch = _channels(A * np.sin(2 * np.pi * y / lam), np.zeros_like(y), s)
    exy = np.pi * A / lam * np.cos(2 * np.pi * y / lam)
    inner = (slice(2, -2), slice(2, -2))  # one-sided differences at the border
    peak = np.sqrt(2) * np.pi * A / lam / L * 1000.0
    np.testing.assert_allclose(ch.phi_total_mD[inner], (np.sqrt(2) * np.abs(exy) / L * 1000.0)[inner], atol=2e-3 * peak)
    np.testing.assert_allclose(ch.phi_eff_mD[inner], 0.0, atol=1e-9)
    strong = np.abs(exy[inner]) > 0.2 * np.abs(exy).max()
    ratio = ch.phi_total_mD[inner][strong] / ch.phi_shear_mD[inner][strong]
    np.testing.assert_allclose(ratio, 1 / np.sqrt(2), rtol=1e-6)


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_pure_shear_through_the_analysis(method):
    """A synthetic grid photo warped by a pure shear (a transverse wave): phi_total = phi_shear / sqrt(2).

    End to end (``analyze``): the wave runs along y and displaces along x (eps_xx = eps_yy =
    0). Where the shear is strong the measured eps_xx, eps_yy are small, so phi_total /
    phi_shear = 1 / sqrt(2); measured median 0.7071 / 0.7071 (Comparative / Direct); a norm
    with the shear term once reads 0.5. Against the independent truth (tests/_truth.py,
    full Frobenius norm) mean |phi_total| reads 1.0031 / 1.0185 of the truth's, the same as
    phi_shear to 1e-5 (the Direct Method's 1.9 % is its displacement here, not the norm):
    phi_total's ratio is held to phi_shear's within 0.5 %, and to 1 within 2 %.
    """
    cap = synthetic_capture((256, 320), pitch_mm=PITCH, mm_per_px=1.0,
                            displacement=wave_displacement(0.4, 120.0, 90.0, "transverse"), rotation_deg=15.0)
    assert np.abs(cap.displacement_mm[..., 1]).max() < 1e-12  # delta_y = 0: pure shear
    res = analyze(cap.image, pitch_mm=PITCH, distance_m=L, reference=cap.reference if method == "comparative" else None,
                  params={"sigma_mm": 16.0})
    t = res.trusted
    assert t.sum() > 20000
    total, shear = res.phi_total_mD[t], res.phi_shear_mD[t]
    strong = shear > 0.5 * np.percentile(shear, 99)
    assert strong.sum() > 2000
    assert np.median(total[strong] / shear[strong]) == pytest.approx(1 / np.sqrt(2), abs=0.01)
    assert np.median(np.abs(res.phi_eff_mD[t][strong]) / shear[strong]) < 0.05  # area unchanged
    tr = truth_for(cap, res)
    ratio = np.mean(np.abs(total)) / np.mean(np.abs(tr.phi_total_mD[t]))
    ratio_shear = np.mean(shear) / np.mean(tr.phi_shear_mD[t])
    assert ratio == pytest.approx(ratio_shear, rel=0.005), (ratio, ratio_shear)
    assert ratio == pytest.approx(1.0, abs=0.02), ratio
