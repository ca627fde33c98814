"""Several captures registered and averaged: noise falls as 1/sqrt(n), moved cameras register, one image is analyze()."""

import numpy as np
import pytest
from scipy import ndimage

from glassdist import InputError, analyze, analyze_captures
from glassdist.analyzer.captures import sample_field
from glassdist.synthetic import synthetic_capture, wave_displacement

PITCH, MMPX, L = 5.0, 0.625, 2.0  # 8 px carrier period
SHAPE = (256, 320)
PARAMS = {"detrend_degree": 2}


def _shift_rotation(tx, ty, deg):
    """Camera moved: pixel r sees what the first camera saw at R r + t (centred pixels)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, tx], [s, c, ty], [0.0, 0.0, 1.0]])


def noise_reduction(method: str, *, shape=SHAPE, ns=(1, 2, 4, 8), noise_std=0.05, seed=100):
    """std of phi_eff (mD) on flat glass averaging n captures with independent noise, and the log-log slope.

    sigma = 1 carrier period keeps ~100 independent samples in the map; the n = 1 value is the
    RMS over every single capture (one capture's std scatters by ~5%).
    """
    params = {"detrend_degree": 2, "sigma_mm": PITCH}
    ref = synthetic_capture(shape, pitch_mm=PITCH, mm_per_px=MMPX).reference if method == "comparative" else None
    caps = [synthetic_capture(shape, pitch_mm=PITCH, mm_per_px=MMPX, noise_std=noise_std, rng=seed + i).image
            for i in range(max(ns))]
    singles = [analyze(c, pitch_mm=PITCH, distance_m=L, reference=ref, params=params) for c in caps]
    std = []
    for n in ns:
        if n == 1:
            std.append(float(np.sqrt(np.mean([np.var(r.phi_eff_mD[r.valid]) for r in singles]))))
        else:
            res = analyze_captures(caps[:n], pitch_mm=PITCH, distance_m=L, reference=ref, params=params)
            std.append(float(np.std(res.phi_eff_mD[res.valid])))
    return np.array(std), float(np.polyfit(np.log(ns), np.log(std), 1)[0])


@pytest.mark.parametrize("method", ["direct", "comparative"])
def test_noise_falls_as_one_over_sqrt_n(method):
    """Flat glass, independent noise per capture (a noise-free reference): std(phi_eff) ~ n^-0.5."""
    std, slope = noise_reduction(method)
    assert np.all(np.diff(std) < 0)
    assert slope == pytest.approx(-0.5, abs=0.06)


def test_one_image_is_analyze():
    cap = synthetic_capture(SHAPE, pitch_mm=PITCH, mm_per_px=MMPX, displacement=wave_displacement(0.3, 60.0, 25.0),
                            noise_std=0.02, rng=1)
    a = analyze(cap.image, pitch_mm=PITCH, distance_m=L, params=PARAMS)
    b = analyze_captures([cap.image], pitch_mm=PITCH, distance_m=L, params=PARAMS)
    for name in ("displacement_mm", "phi_eff_mD", "phi_shear_mD", "axis_deg"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert b.captures == () and "captures" not in b.summary()


@pytest.mark.parametrize("method", ["direct", "comparative"])
def test_moved_captures_register_and_average(method):
    """Camera moved by 0-1.8 carrier periods and rotated up to 0.4 deg: the average matches the truth better than one capture."""
    wave = wave_displacement(0.3, 60.0, 25.0)
    moves = [(0.0, 0.0, 0.0), (3.3, -1.7, 0.4), (-2.2, 2.9, -0.3), (12.5, 7.0, 0.2)]
    caps = [synthetic_capture(SHAPE, pitch_mm=PITCH, mm_per_px=MMPX, displacement=wave, homography=_shift_rotation(*m),
                              noise_std=0.05, rng=7 + i) for i, m in enumerate(moves)]
    truth = synthetic_capture(SHAPE, pitch_mm=PITCH, mm_per_px=MMPX, displacement=wave)
    tr = analyze(truth.image, pitch_mm=PITCH, distance_m=L, reference=truth.reference, params=PARAMS)
    ref = caps[0].reference if method == "comparative" else None
    one = analyze(caps[0].image, pitch_mm=PITCH, distance_m=L, reference=ref, params=PARAMS)
    avg = analyze_captures([c.image for c in caps], pitch_mm=PITCH, distance_m=L, reference=ref, params=PARAMS)
    # the shifts found: each capture's largest sample shift (px) includes its rotation about the centre
    shifts = [c["max_shift_px"] for c in avg.captures]
    for (tx, ty, deg), s in zip(moves, shifts):
        assert s == pytest.approx(np.hypot(tx, ty), abs=0.5 + abs(np.radians(deg)) * 210)
    inner = ndimage.binary_erosion(one.valid & tr.valid & avg.valid, iterations=30)
    err = {k: float(np.sqrt(np.mean((r.phi_eff_mD[inner] - tr.phi_eff_mD[inner]) ** 2))) for k, r in (("one", one), ("avg", avg))}
    assert err["avg"] < 0.85 * err["one"]  # 4 captures: 0.5 for pure noise; the truth's own noise-free error stays
    assert np.corrcoef(avg.phi_eff_mD[inner], tr.phi_eff_mD[inner])[0, 1] > 0.998
    assert np.mean(np.abs(avg.phi_eff_mD[inner])) == pytest.approx(np.mean(np.abs(tr.phi_eff_mD[inner])), rel=0.02)
    count = avg.capture_count
    assert count.max() == 4 and np.mean(count[inner] == 4) > 0.95
    assert avg.summary()["captures"][3]["capture"] == 4


def test_captures_of_different_size_or_none_are_input_errors():
    cap = synthetic_capture((96, 96), pitch_mm=PITCH, mm_per_px=MMPX)
    with pytest.raises(InputError, match="capture 2 is 64x96 px"):
        analyze_captures([cap.image, cap.image[:, :64]], pitch_mm=PITCH, distance_m=L)
    with pytest.raises(InputError, match="no image"):
        analyze_captures([], pitch_mm=PITCH, distance_m=L)


def test_sample_field_nan_aware():
    f = np.arange(30.0).reshape(5, 6)
    f[2, 3] = np.nan
    rows, cols = np.array([0.5, 2.0, 2.0, 1.0, 4.5]), np.array([0.5, 2.0, 2.9, 1.25, 1.0])
    v = sample_field(f, rows, cols)  # f is the plane 6 row + col (one sample missing)
    np.testing.assert_allclose(v[[0, 1, 3]], 6 * rows[[0, 1, 3]] + cols[[0, 1, 3]], atol=0.005)
    assert np.isnan(v[2]) and np.isnan(v[4])  # weight on the NaN sample; outside the field
    y, x = np.mgrid[0:40, 0:40]
    wave = np.sin(2 * np.pi * (x + 0.5 * y) / 8.0)  # 8 samples per period along x
    r, c = np.array([20.5, 10.25]), np.array([20.5, 30.75])
    np.testing.assert_allclose(sample_field(wave, r, c), np.sin(2 * np.pi * (c + 0.5 * r) / 8.0), atol=0.01)


def test_cli_analyze_several_images(tmp_path):
    import json

    import cv2

    from glassdist.cli import main

    wave = wave_displacement(0.3, 60.0, 25.0)
    paths = []
    for i, move in enumerate([(0.0, 0.0, 0.0), (2.5, -1.5, 0.2)]):
        cap = synthetic_capture(SHAPE, pitch_mm=PITCH, mm_per_px=MMPX, displacement=wave, homography=_shift_rotation(*move),
                                noise_std=0.02, rng=i)
        paths.append(tmp_path / f"cap{i}.png")
        assert cv2.imwrite(str(paths[-1]), (cap.image * 65535).astype(np.uint16))
    out = tmp_path / "out"
    code = main(["analyze", *map(str, paths), "--pitch-mm", str(PITCH), "--distance-m", str(L), "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [c["capture"] for c in summary["captures"]] == [1, 2]
    assert [c["image"] for c in summary["inputs"]["captures"]] == [str(p) for p in paths]
    with np.load(out / "result.npz") as npz:
        assert npz["capture_count"].max() == 2
    # one image: no capture record, as before
    code = main(["analyze", str(paths[0]), "--pitch-mm", str(PITCH), "--distance-m", str(L), "--out", str(tmp_path / "one")])
    one = json.loads((tmp_path / "one" / "summary.json").read_text())
    assert code == 0 and "captures" not in one and "captures" not in one["inputs"]
