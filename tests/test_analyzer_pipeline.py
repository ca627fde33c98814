"""End-to-end round trips of the Analyzer on synthetic captures with known displacement.

Tolerances: mean |phi| within 2% and map correlation >= 0.99 of the truth put through the
same evaluation stack (same N, sigma, region) on clean 400x520 images (carrier period 8 px),
compared over the trusted pixels (quality label 0, what statistics use); the reported
region (``valid``, which adds the guard band) is checked for coverage.
"""

import numpy as np
import pytest

from conftest import agreement, truth_channels
from glassdist import analyze
from glassdist.analyzer.region import LOW_MODULATION
from glassdist.synthetic import lens_displacement, synthetic_capture, wave_displacement

L = 10.0
PITCH = 8.0
PARAMS = {"detrend_degree": 2, "sigma_mm": 16.0}


def _run(cap, method, **kw):
    params = dict(PARAMS, **kw.pop("params", {}))
    ref = cap.reference if method == "comparative" else None
    return analyze(cap.image, pitch_mm=kw.pop("pitch_mm", PITCH), distance_m=L, reference=ref, params=params, **kw)


CASES = {
    "wave": dict(displacement=wave_displacement(0.6, 160.0, 0.0)),
    "oblique_wave_rotated_grid": dict(displacement=wave_displacement(0.6, 160.0, 10.0), rotation_deg=25.0),
    "lens": dict(displacement=lens_displacement(0.01, L, radius_mm=80.0)),
    "checkerboard": dict(displacement=wave_displacement(0.6, 160.0, 60.0), pattern="checkerboard", rotation_deg=45.0),
    "perspective": dict(
        displacement=wave_displacement(0.6, 160.0, 0.0),
        homography=np.array([[1.0, 0.05, 0.0], [0.02, 0.95, 0.0], [2e-4, 1e-4, 1.0]]),
    ),
}


@pytest.mark.parametrize("method", ["comparative", "direct"])
@pytest.mark.parametrize("case", list(CASES))
def test_round_trip_against_truth(case, method):
    kw = dict(CASES[case])
    pattern = kw.get("pattern", "lines")
    cap = synthetic_capture((400, 520), pitch_mm=PITCH, mm_per_px=1.0, **kw)
    res = _run(cap, method, params={"pattern": pattern})
    assert res.method == method
    tr = truth_channels(cap, res)
    assert res.valid.mean() > 0.85
    assert res.trusted.mean() > 0.5
    for ch in ("phi_eff_mD", "phi_shear_mD"):
        ratio, corr = agreement(getattr(res, ch), getattr(tr, ch), res.trusted)
        assert ratio == pytest.approx(1.0, abs=0.02), (ch, ratio)
        assert corr > 0.99, (ch, corr)


def test_noisy_capture_within_five_percent():
    cap = synthetic_capture((400, 520), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(0.6, 160.0, 20.0),
                            noise_std=0.08, rng=11)
    for method in ("comparative", "direct"):
        res = _run(cap, method)
        tr = truth_channels(cap, res)
        ratio, corr = agreement(res.phi_eff_mD, tr.phi_eff_mD, res.trusted)
        assert abs(ratio - 1) < 0.05 and corr > 0.95, (method, ratio, corr)


def test_displacement_sign_convention():
    # Landing points shifted by +0.9 mm along x and -0.5 mm along y (backdrop seen shifted).
    shift = (0.9, -0.5)
    cap = synthetic_capture((256, 320), pitch_mm=PITCH, mm_per_px=1.0,
                            displacement=lambda X, Y: (shift[0] + 0 * X, shift[1] + 0 * Y),
                            rotation_deg=20.0)
    res = _run(cap, "comparative")
    d = res.displacement_mm[res.valid]
    assert np.allclose(np.median(d, axis=0), shift, atol=0.01)


def test_converging_lens_reads_negative_power():
    # Uniform thin lens (far-background limit): delta = -P L r, phi_eff = -2P everywhere.
    P = 0.005
    cap = synthetic_capture((300, 360), pitch_mm=PITCH, mm_per_px=1.0, displacement=lens_displacement(P, L))
    res = _run(cap, "comparative", params={"detrend_degree": 0})
    phi = res.phi_eff_mD[res.valid]
    assert np.median(phi) == pytest.approx(-2 * P * 1000, rel=0.01)
    assert np.median(res.phi_shear_mD[res.valid]) < 0.05 * abs(np.median(phi))
    # A local converging lens seen by the Direct Method: negative power at its centre.
    cap = synthetic_capture((300, 360), pitch_mm=PITCH, mm_per_px=1.0, displacement=lens_displacement(P, L, radius_mm=50.0))
    res = _run(cap, "direct")
    assert res.phi_eff_mD[150, 180] < -0.5 * 2 * P * 1000


def test_rotation_and_pitch_invariance():
    disp = wave_displacement(0.5, 150.0, 15.0)
    means = []
    for rot, pitch in [(0.0, 8.0), (30.0, 8.0), (0.0, 6.0), (12.0, 10.0)]:
        cap = synthetic_capture((400, 480), pitch_mm=pitch, mm_per_px=1.0, displacement=disp, rotation_deg=rot)
        res = _run(cap, "direct", pitch_mm=pitch)
        tr = truth_channels(cap, res)
        means.append(np.nanmean(np.abs(res.phi_eff_mD[res.trusted])) / np.nanmean(np.abs(tr.phi_eff_mD[res.trusted])))
    assert np.ptp(means) < 0.02, means


def test_flat_glass_reads_near_zero_with_noise():
    cap = synthetic_capture((320, 400), pitch_mm=PITCH, mm_per_px=1.0, noise_std=0.03, rng=5)
    for method in ("comparative", "direct"):
        res = _run(cap, method)
        assert np.percentile(np.abs(res.phi_eff_mD[res.trusted]), 95) < 0.4, method


def test_frame_splits_regions_and_is_excluded():
    cap = synthetic_capture((300, 420), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(0.5, 150.0, 0.0))
    img = cap.image.copy()
    ref = cap.reference.copy()
    img[:, 200:230] = 0.15  # an opaque mullion
    ref[:, 200:230] = 0.15
    res = analyze(img, pitch_mm=PITCH, distance_m=L, reference=ref, params=PARAMS)
    m = int(res.margin_px[0])  # the contamination margin derived from the demodulation kernel
    assert m >= 2
    assert not res.valid[:, 200 - m : 230 + m].any()
    assert (res.quality[20:-20, 200:230] == LOW_MODULATION).all()  # the image edge's own label at the ends
    assert res.n_regions == 2
    assert res.valid[:, :190].mean() > 0.85 and res.valid[:, 240:].mean() > 0.85


def test_user_mask_is_respected():
    cap = synthetic_capture((256, 256), pitch_mm=PITCH, mm_per_px=1.0)
    mask = np.zeros(cap.image.shape, bool)
    mask[40:200, 30:220] = True
    res = analyze(cap.image, pitch_mm=PITCH, distance_m=L, params=PARAMS, mask=mask)
    assert not res.valid[~mask].any()
    assert res.valid[mask].mean() > 0.7


def test_results_are_deterministic():
    cap = synthetic_capture((200, 240), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(0.5, 100.0, 30.0))
    a = _run(cap, "direct")
    b = _run(cap, "direct")
    assert np.array_equal(a.phi_eff_mD, b.phi_eff_mD, equal_nan=True)


def test_narrow_frame_band_splits_regions():
    # A dark frame about one carrier period wide: the bandpass blurs it so that its modulation dip stays
    # above the global threshold; the local-level test must still cut the regions apart there.
    cap = synthetic_capture((300, 420), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(0.5, 150.0, 0.0))
    img = cap.image.copy()
    img[:, 205:214] = 0.05
    res = analyze(img, pitch_mm=PITCH, distance_m=L, params=PARAMS)
    assert res.n_regions == 2
    assert not res.valid[:, 205:214].any()
    # The global threshold alone misses it (the local-frequency limit, which the phase across
    # the band also exceeds, switched off too).
    off = analyze(img, pitch_mm=PITCH, distance_m=L,
                  params=dict(PARAMS, local_modulation_threshold=0.0, max_frequency_deviation=1.0))
    assert off.n_regions == 1


def test_distortion_beyond_the_measurable_range_is_flagged():
    """A wave whose strain (local frequency shift) exceeds the reach after image deformation
    (75% of the carrier) is not measured silently; a moderate one (~12%) raises no warning."""
    for amp, expect in ((3.0, False), (20.0, True)):  # peak strain 2 pi A / 160 mm: 0.12 and 0.79
        cap = synthetic_capture((400, 520), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(amp, 160.0, 0.0))
        comp = _run(cap, "comparative")
        direct = _run(cap, "direct")
        assert any("strong distortion" in w for w in comp.warnings) == expect, comp.warnings
        assert bool(direct.warnings) == expect, direct.warnings
