"""Standard measures (roll wave, angular deviation, grid-line slope, equivalent power) against closed forms."""

import json

import numpy as np
import pytest

from glassdist.analyzer.metrics import evaluate_displacement
from glassdist.measures import (
    ARCMIN_PER_RAD,
    angular_deviation,
    equivalent_power,
    grid_line_slope,
    line_profile,
    roll_wave,
    standard_measures,
)
from glassdist.synthetic import lens_displacement, wave_displacement


def _grid(h, w, sy, sx):
    y, x = np.mgrid[0:h, 0:w].astype(float)
    return x * sx, y * sy


def _field(fn, X, Y):
    dx, dy = fn(X, Y)
    return np.stack([np.broadcast_to(dx, X.shape), np.broadcast_to(dy, X.shape)], -1).astype(float)


def _angle_diff(a, b):
    """Difference of two directions defined modulo 180 degrees."""
    return abs((a - b + 90.0) % 180.0 - 90.0)


# --------------------------------------------------------------------------- roll wave


@pytest.mark.parametrize("direction_deg", [0.0, 30.0, 90.0, -60.0, 135.0, 7.0])
def test_roll_wave_recovers_period_direction_amplitude(direction_deg):
    sy, sx = 2.5, 2.0
    X, Y = _grid(200, 240, sy, sx)
    period, amp, L = 80.0, 0.3, 5.0
    clean = _field(wave_displacement(amp, period, direction_deg), X, Y)
    clean[(X - 120) ** 2 + (Y - 150) ** 2 < 60**2] = np.nan  # a masked hole (leaks in a plain FFT)
    rng = np.random.default_rng(3)
    d = clean + rng.normal(0.0, 0.01, clean.shape)
    rw = roll_wave(d, step_mm=(sy, sx), distance_m=L)
    assert rw.period_mm == pytest.approx(period, rel=0.005)
    assert _angle_diff(rw.direction_deg, direction_deg) < 0.3
    assert -90.0 < rw.direction_deg <= 90.0
    assert rw.amplitude_mm == pytest.approx(amp, rel=0.01)
    power = 2 * np.pi * amp / period / L * 1000.0  # mD along the roll direction
    assert rw.power_amplitude_mD == pytest.approx(power, rel=0.01)
    assert rw.explained_fraction > 0.99
    # the observed peak-to-valley (percentiles of the field itself) carries the noise: noise-free field
    rw0 = roll_wave(clean, step_mm=(sy, sx), distance_m=L)
    assert rw0.displacement_pv_mm == pytest.approx(2 * amp, rel=0.01)
    assert rw0.power_pv_mD == pytest.approx(2 * power, rel=0.01)


def test_roll_wave_power_is_phi_eff_of_the_wave():
    """For a longitudinal wave the roll-direction power is the phi_eff amplitude (and phi_shear's)."""
    s = 2.0
    X, Y = _grid(150, 150, s, s)
    period, amp, L = 60.0, 0.2, 3.0
    d = _field(wave_displacement(amp, period, 40.0), X, Y)
    ch = evaluate_displacement(d, np.ones(X.shape, bool), distance_m=L, mm_per_px=s, detrend_degree=0, sigma_mm=1e-6)
    rw = roll_wave(d, step_mm=s, distance_m=L)
    inner = ch.phi_eff_mD[5:-5, 5:-5]
    assert rw.power_amplitude_mD == pytest.approx(0.5 * (inner.max() - inner.min()), rel=0.01)


def test_roll_wave_picks_the_wave_with_most_power():
    """Two waves: the short one carries more power (2 pi A / Lambda) though less displacement."""
    s = 2.0
    X, Y = _grid(200, 200, s, s)
    long_ = _field(wave_displacement(0.4, 200.0, 0.0), X, Y)  # power ~ 0.0126
    short = _field(wave_displacement(0.2, 40.0, 60.0), X, Y)  # power ~ 0.0314
    rw = roll_wave(long_ + short, step_mm=s, distance_m=1.0)
    assert rw.period_mm == pytest.approx(40.0, rel=0.01)
    assert _angle_diff(rw.direction_deg, 60.0) < 0.5


def test_roll_wave_flat_field_has_no_wave():
    rng = np.random.default_rng(0)
    d = rng.normal(0.0, 0.01, (100, 100, 2))
    rw = roll_wave(d, step_mm=2.0, distance_m=1.0)
    assert rw.explained_fraction < 0.05


# --------------------------------------------------------------------------- line profiles


def test_line_profile_samples_the_field_along_a_line():
    sy, sx = 2.5, 2.0
    X, Y = _grid(120, 150, sy, sx)
    f = np.sin(2 * np.pi * (X * 0.8 + Y * 0.6) / 90.0)
    origin = (100.0, -50.0)
    prof = line_profile(f, step_mm=(sy, sx), start_mm=(110.0, -40.0), end_mm=(350.0, 200.0), spacing_mm=1.0, origin_mm=origin)
    assert prof.s_mm[0] == 0.0 and prof.s_mm[-1] == pytest.approx(np.hypot(240.0, 240.0))
    truth = np.sin(2 * np.pi * ((prof.x_mm - origin[0]) * 0.8 + (prof.y_mm - origin[1]) * 0.6) / 90.0)
    assert np.nanmax(np.abs(prof.values - truth)) < 1e-3  # cubic spline (bilinear: (h^2/8)|f''| ~ 0.005)
    assert np.all(np.isfinite(prof.values))
    # vector field, a masked sample and a point outside the field
    g = np.stack([f, -f], -1)
    g[40, 50] = np.nan
    p2 = line_profile(g, step_mm=(sy, sx), start_mm=(50 * sx, 40 * sy), end_mm=(-10.0, 40 * sy))
    assert p2.values.shape == (p2.s_mm.size, 2)
    ok = np.all(np.isfinite(p2.values), axis=1)
    assert not ok[0]  # the masked sample
    np.testing.assert_array_equal(ok[1:], p2.x_mm[1:] >= 0.0)  # inside the field


# --------------------------------------------------------------------------- angular deviation


def test_angular_deviation_of_a_linear_field_is_the_closed_form():
    """delta = c + K r (a thin prism plus a thin lens with astigmatism): exact angles and rates."""
    sy, sx = 3.0, 2.0
    X, Y = _grid(80, 90, sy, sx)
    c = np.array([0.5, -0.3])
    K = np.array([[-2e-3, 5e-4], [3e-4, 1e-3]])
    L, g = 2.0, 10.0  # g / 2 = 1.67 rows, 2.5 columns: interpolated
    delta = lambda x, y: (c[0] + K[0, 0] * x + K[0, 1] * y, c[1] + K[1, 0] * x + K[1, 1] * y)  # noqa: E731
    d = _field(delta, X, Y)
    ad = angular_deviation(d, step_mm=(sy, sx), distance_m=L, gauge_mm=g)
    Lmm = 1000.0 * L
    np.testing.assert_allclose(ad.angle_arcmin, np.arctan(np.hypot(d[..., 0], d[..., 1]) / Lmm) * ARCMIN_PER_RAD, rtol=1e-12)
    np.testing.assert_allclose(ad.angle_x_arcmin, np.arctan(d[..., 0] / Lmm) * ARCMIN_PER_RAD, rtol=1e-12)
    rx = (np.arctan(delta(X + g / 2, Y)[0] / Lmm) - np.arctan(delta(X - g / 2, Y)[0] / Lmm)) * ARCMIN_PER_RAD
    ry = (np.arctan(delta(X, Y + g / 2)[1] / Lmm) - np.arctan(delta(X, Y - g / 2)[1] / Lmm)) * ARCMIN_PER_RAD
    okx, oky = np.isfinite(ad.rate_x_arcmin), np.isfinite(ad.rate_y_arcmin)
    # defined exactly where both gauge ends lie inside the field
    assert np.array_equal(okx, (X - g / 2 >= 0) & (X + g / 2 <= X.max()))
    assert np.array_equal(oky, (Y - g / 2 >= 0) & (Y + g / 2 <= Y.max()))
    np.testing.assert_allclose(ad.rate_x_arcmin[okx], rx[okx], rtol=1e-9)
    np.testing.assert_allclose(ad.rate_y_arcmin[oky], ry[oky], rtol=1e-9)
    # small angles: rate = g * phi_ss (g in m, phi in 1/m)
    assert np.nanmean(ad.rate_x_arcmin) == pytest.approx(g * 1e-3 * K[0, 0] / L * ARCMIN_PER_RAD, rel=1e-4)


def test_angular_deviation_rate_of_a_thin_lens():
    """A lens of P = 0.1 D (phi_eff = -200 mD) over g = 4 mm: |rate| = P g = 4e-4 rad = 1.375 arcmin.

    With the sign of a converging lens.
    """
    s = 2.0
    X, Y = _grid(60, 60, s, s)
    P, L, g = 0.1, 5.0, 4.0
    d = _field(lens_displacement(P, L, center_mm=(60.0, 60.0)), X, Y)
    ad = angular_deviation(d, step_mm=s, distance_m=L, gauge_mm=g)
    expected = -P * g * 1e-3 * ARCMIN_PER_RAD
    assert expected == pytest.approx(-1.375, abs=1e-3)
    np.testing.assert_allclose(ad.rate_x_arcmin[np.isfinite(ad.rate_x_arcmin)], expected, rtol=1e-4)
    np.testing.assert_allclose(ad.rate_y_arcmin[np.isfinite(ad.rate_y_arcmin)], expected, rtol=1e-4)
    st = ad.statistics()
    assert st["rate_max_arcmin"] == pytest.approx(abs(expected), rel=1e-4)
    assert st["gauge_mm"] == g


def test_angular_deviation_rejects_bad_arguments():
    d = np.zeros((10, 10, 2))
    with pytest.raises(ValueError, match="gauge_mm"):
        angular_deviation(d, step_mm=1.0, distance_m=1.0, gauge_mm=0.0)
    with pytest.raises(ValueError, match="distance_m"):
        angular_deviation(d, step_mm=1.0, distance_m=-1.0, gauge_mm=4.0)
    with pytest.raises(ValueError, match="shape"):
        angular_deviation(d[..., 0], step_mm=1.0, distance_m=1.0, gauge_mm=4.0)


# --------------------------------------------------------------------------- grid-line slope


def _slope_closed_form(amp, period, k_deg, p_deg, t_deg):
    """max |m| of lines along t for delta = A sin(2 pi k.r / Lambda) p: G = (2 pi A / Lambda) cos(.) p k^T."""
    k = np.array([np.cos(np.radians(k_deg)), np.sin(np.radians(k_deg))])
    p = np.array([np.cos(np.radians(p_deg)), np.sin(np.radians(p_deg))])
    t = np.array([np.cos(np.radians(t_deg)), np.sin(np.radians(t_deg))])
    n = np.array([-t[1], t[0]])
    g = 2 * np.pi * amp / period
    a, b = g * (n @ p) * (k @ t), g * (n @ p) * (k @ n)
    return max(abs(a / (1 + b)), abs(a / (1 - b)))


def test_grid_line_slope_of_a_transverse_wave():
    """Horizontal lines under delta_y = A sin(2 pi x / Lambda): max slope 2 pi A / Lambda exactly, N = Lambda / (2 pi A)."""
    s = 1.0
    X, Y = _grid(50, 200, s, s)
    amp, period = 2.0, 50.0
    d = _field(wave_displacement(amp, period, 0.0, polarization="transverse"), X, Y)
    gl = grid_line_slope(d, step_mm=s)
    assert gl.directions_deg == (0.0, 90.0)
    assert gl.max_slopes[0] == pytest.approx(2 * np.pi * amp / period, rel=1e-4)
    assert gl.one_in_n[0] == pytest.approx(period / (2 * np.pi * amp), rel=1e-4)  # "1 in 3.98"
    assert gl.max_slopes[1] < 1e-12 and gl.one_in_n[1] > 1e12  # vertical lines stay straight
    assert gl.worst_one_in_n == gl.one_in_n[0]
    # sign: delta_y rises with x (down the image) -> the seen line goes up: m = -d delta_y / dx
    assert gl.slopes[0][25, 50] == pytest.approx(-2 * np.pi * amp / period, rel=1e-3)


@pytest.mark.parametrize("k_deg, p_deg", [(30.0, 30.0), (30.0, 120.0), (17.0, 80.0), (-50.0, -50.0)])
def test_grid_line_slope_of_rotated_waves(k_deg, p_deg):
    s = 1.0
    X, Y = _grid(160, 160, s, s)
    amp, period = 1.5, 45.0
    k = np.array([np.cos(np.radians(k_deg)), np.sin(np.radians(k_deg))])
    p = np.array([np.cos(np.radians(p_deg)), np.sin(np.radians(p_deg))])
    w = amp * np.sin(2 * np.pi * (k[0] * X + k[1] * Y) / period)
    d = np.stack([w * p[0], w * p[1]], -1)
    gl = grid_line_slope(d, step_mm=s, directions_deg=(0.0, 90.0, 45.0))
    for t_deg, m in zip((0.0, 90.0, 45.0), gl.max_slopes):
        assert m == pytest.approx(_slope_closed_form(amp, period, k_deg, p_deg, t_deg), rel=0.005, abs=1e-9)


# --------------------------------------------------------------------------- equivalent power


def test_equivalent_power_of_a_converging_lens():
    s = 2.0
    X, Y = _grid(60, 60, s, s)
    P, L = 0.05, 4.0  # 50 mD lens
    d = _field(lens_displacement(P, L, center_mm=(60.0, 60.0)), X, Y)
    ch = evaluate_displacement(d, np.ones(X.shape, bool), distance_m=L, mm_per_px=s, detrend_degree=0, sigma_mm=1e-6)
    assert np.allclose(ch.phi_eff_mD, -2 * P * 1000.0)
    ep = equivalent_power(ch.phi_eff_mD)
    assert ep.mean_mD == pytest.approx(P * 1000.0) and ep.min_mD == pytest.approx(P * 1000.0)
    assert ep.max_mD == pytest.approx(P * 1000.0) and ep.p95_abs_mD == pytest.approx(P * 1000.0)
    assert "-phi_eff/2" in ep.convention
    assert np.isnan(equivalent_power(np.full((3, 3), np.nan)).mean_mD)


# --------------------------------------------------------------------------- on an analysis


def test_standard_measures_of_an_analysis_find_the_roll_wave():
    import glassdist
    from glassdist.synthetic import synthetic_capture

    pitch, mmpx, L = 5.0, 0.625, 2.0
    cap = synthetic_capture((384, 384), pitch_mm=pitch, mm_per_px=mmpx,
                            displacement=wave_displacement(0.3, 60.0, 25.0))
    res = glassdist.analyze(cap.image, pitch_mm=pitch, distance_m=L, reference=cap.reference,
                            params={"detrend_degree": 1, "sigma_mm": 5.0})
    m = standard_measures(res, gauge_mm=4.0)
    assert m.roll_wave.period_mm == pytest.approx(60.0, rel=0.01)
    assert _angle_diff(m.roll_wave.direction_deg, 25.0) < 1.0
    # amplitude of the field smoothed at sigma: A exp(-2 pi^2 sigma^2 / Lambda^2)
    assert m.roll_wave.amplitude_mm == pytest.approx(0.3 * np.exp(-2 * np.pi**2 * 25.0 / 3600.0), rel=0.03)
    summary = json.loads(json.dumps(m.to_dict(), allow_nan=True))
    assert set(summary) >= {"roll_wave", "angular_deviation", "grid_line_slope", "equivalent_power", "field"}
    assert summary["angular_deviation"]["gauge_mm"] == 4.0


def test_result_profile_in_backdrop_and_pane_mm():
    import glassdist
    from glassdist.acceptance.zones import pane_frame_from_corners
    from glassdist.measures import result_profile
    from glassdist.synthetic import synthetic_capture

    pitch, mmpx, L = 5.0, 0.625, 2.0
    H, W = 256, 320
    cap = synthetic_capture((H, W), pitch_mm=pitch, mm_per_px=mmpx, displacement=wave_displacement(0.3, 60.0, 0.0))
    res = glassdist.analyze(cap.image, pitch_mm=pitch, distance_m=L, reference=cap.reference,
                            params={"detrend_degree": 1, "sigma_mm": 5.0})
    # along the middle row, backdrop mm from the top-left pixel centre
    row = H // 2
    prof = result_profile(res, "phi_eff_mD", start_mm=(40 * mmpx, row * mmpx), end_mm=(280 * mmpx, row * mmpx))
    cols = np.rint(prof.x_mm / mmpx).astype(int)
    on_px = np.abs(prof.x_mm / mmpx - cols) < 1e-6
    np.testing.assert_allclose(prof.values[on_px], res.phi_eff_mD[row, cols[on_px]],
                               atol=0.02 * np.nanmax(np.abs(res.phi_eff_mD)))
    # a pane frame: the image's corner pixels as a pane of 1.25 pane mm per px; the same line in both frames
    frame = pane_frame_from_corners([(0, 0), (W - 1, 0), (W - 1, H - 1), (0, H - 1)], (400.0 * (W - 1) / W, 320.0 * (H - 1) / H),
                                    (H, W))
    pane = result_profile(res, "displacement_detrended_mm", start_mm=(80.0, 160.0), end_mm=(320.0, 160.0), frame=frame,
                          spacing_mm=1.25 * 8)
    backdrop = result_profile(res, "displacement_detrended_mm", start_mm=(64 * mmpx, 128 * mmpx),
                              end_mm=(256 * mmpx, 128 * mmpx), spacing_mm=8 * mmpx)
    assert pane.values.shape == backdrop.values.shape == (25, 2)
    np.testing.assert_allclose(pane.values, backdrop.values, atol=1e-6)


def test_measures_rows_state_units_and_conventions():
    from glassdist.report.html import measures_rows

    s = 2.0
    X, Y = _grid(100, 100, s, s)
    d = (_field(wave_displacement(0.2, 50.0, 0.0, polarization="transverse"), X, Y)
         + _field(wave_displacement(0.1, 40.0, 90.0), X, Y))
    gl = grid_line_slope(d, step_mm=s)
    m = {
        "field": "test", "step_mm": [s, s],
        "roll_wave": roll_wave(d, step_mm=s, distance_m=1.0).to_dict(),
        "angular_deviation": angular_deviation(d, step_mm=s, distance_m=1.0, gauge_mm=4.0).statistics(),
        "grid_line_slope": gl.statistics(),
        "equivalent_power": equivalent_power(np.full((4, 4), -20.0)).to_dict(),
    }
    rows = dict(measures_rows(m))
    assert f"1 in {gl.one_in_n[0]:.3g} (lines at 0°)" in rows["grid-line slope (ASTM F2156)"]
    assert "period 40 mm along 90°" in rows["roll wave (ASTM C1651 quantities)"]
    sphere = rows["sphere-equivalent power P = −φ_eff/2"]
    assert "mean 10 mD" in sphere and "-phi_eff/2" in sphere
    assert "change over 4 mm" in rows["angular deviation (ECE R43 / ISO 3538)"]


def test_analyze_writes_the_measures_to_summary_and_report(tmp_path):
    import cv2

    from glassdist.cli import main
    from glassdist.synthetic import synthetic_capture

    cap = synthetic_capture((256, 320), pitch_mm=5.0, mm_per_px=0.625, displacement=wave_displacement(0.3, 60.0, 25.0))
    img, ref = tmp_path / "img.png", tmp_path / "ref.png"
    assert cv2.imwrite(str(img), (cap.image * 65535).astype(np.uint16))
    assert cv2.imwrite(str(ref), (cap.reference * 65535).astype(np.uint16))
    out = tmp_path / "out"
    code = main(["analyze", str(img), "--reference", str(ref), "--pitch-mm", "5", "--distance-m", "2",
                 "--sigma-mm", "5", "--detrend-degree", "1", "--report", "--out", str(out)])
    assert code == 0
    m = json.loads((out / "summary.json").read_text())["measures"]
    assert m["roll_wave"]["period_mm"] == pytest.approx(60.0, rel=0.01)
    assert m["angular_deviation"]["gauge_mm"] == 4.0 and m["grid_line_slope"]["worst_one_in_n"] > 1
    assert "-phi_eff/2" in m["equivalent_power"]["convention"]
    html = (out / "report.html").read_text()
    assert 'id="standard-measures"' in html and "1 in " in html and "P = −φ_eff/2" in html
