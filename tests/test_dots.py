"""Dot-lattice backdrops (``pattern='dots'``) and grids that fill only part of the frame.

A dot lattice of spacing p has its carriers along the lattice axes, of period p, as a line
grid of the same pitch: the two must read the same phi from the same glass. The carrier
search must find the carriers where the grid fills only part of the frame (a mirror in dark
surroundings), and ``auto`` must name the pattern. Images are small (at most 480 x 640 px).
"""

import numpy as np
import pytest
from scipy import ndimage

from _truth import truth_for
from glassdist import analyze
from glassdist.analyzer import fourier as F
from glassdist.analyzer.pattern import detect_pattern
from glassdist.synthetic import backdrop_pattern, synthetic_capture, wave_displacement

L = 10.0
PITCH = 8.0


def _figures(phi, where):
    a = np.abs(phi[where])
    a = a[np.isfinite(a)]
    return float(np.mean(a)), float(np.percentile(a, 95))


def _reads_its_truth(phi_eff_mD, truth_mD, trusted, pattern):
    """The result's mean |phi_eff| and p95 within 1 % of the truth's over ``trusted``; the result's figures."""
    got, want = _figures(phi_eff_mD, trusted), _figures(truth_mD, trusted)
    for g, w in zip(got, want):
        assert g == pytest.approx(w, rel=0.01), (pattern, got, want)
    return got


def _dots_read_as_lines(out):
    """The dot lattice's figures within 1 % of the line grid's."""
    for d, li in zip(out["dots"], out["lines"]):
        assert d == pytest.approx(li, rel=0.01), out


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_a_dot_lattice_reads_as_the_line_grid(method):
    """The same wave seen on a dot lattice and on a line grid: phi_eff mean |.| and p95 within 1 % of the truth.

    The truth is the independent evaluation (tests/_truth.py) on the region each result
    documents. Measured (mean, p95 over the truth): dots 0.999 / 0.999 (Comparative), 0.998 /
    0.998 (Direct), lines the same to 1e-4. Point-sampled sharp-edged dots at 8 px per period
    read 0.74: their harmonics beyond Nyquist alias onto the carriers (the synthetic dots are
    Gaussian, band-limited, as its lines are).
    """
    disp = wave_displacement(0.3, 140.0, 35.0)
    out = {}
    for pattern in ("dots", "lines"):
        cap = synthetic_capture((256, 320), pitch_mm=PITCH, mm_per_px=1.0, displacement=disp, pattern=pattern)
        ref = cap.reference if method == "comparative" else None
        res = analyze(cap.image, pitch_mm=PITCH, distance_m=L, reference=ref,
                      params={"sigma_mm": 16.0, "pattern": pattern})
        assert res.mm_per_px == pytest.approx(1.0, rel=0.01)
        tr = truth_for(cap, res)
        t = res.trusted
        assert t.mean() > 0.5
        out[pattern] = _reads_its_truth(res.phi_eff_mD, tr.phi_eff_mD, t, pattern)
    _dots_read_as_lines(out)


def _framed(pattern, fill, shape=(480, 640), period_px=11.0, rotation_deg=3.0, contrast=0.15, seed=0):
    """A grid on a bright board (``fill`` of the frame, off-centre) in a dark surround, blurred, with noise."""
    H, W = shape
    y, x = np.mgrid[0:H, 0:W].astype(float)
    board = backdrop_pattern(x, y, pitch_mm=period_px, pattern=pattern, rotation_deg=rotation_deg,
                             contrast=contrast)
    s = np.sqrt(fill)
    h, w = int(H * s), int(W * s)
    y0, x0 = (H - h) // 2 + 7, (W - w) // 2 + 11
    inside = np.zeros((H, W), bool)
    inside[y0 : y0 + h, x0 : x0 + w] = True
    img = np.where(inside, board, 0.02)
    img = ndimage.gaussian_filter(img, 1.2) + np.random.default_rng(seed).normal(0.0, 0.005, img.shape)
    return img


@pytest.mark.parametrize("pattern", ["dots", "lines"])
@pytest.mark.parametrize("fill", [0.4, 0.5, 0.6])
def test_carriers_found_where_the_grid_fills_part_of_the_frame(pattern, fill):
    """A weak grid on a board filling 40-60 % of a dark frame: both carriers within 1 % of the board's period.

    Without the apodised search (the outline's step alone) the strongest peaks are the
    outline's: the search fails or returns periods of 20-100 px. Measured: within 0.7 %,
    the angles within 0.3 deg.
    """
    img = _framed(pattern, fill)
    pair = F.find_carriers(F.compute_spectrum(img))
    periods = sorted((pair.k1.period_px, pair.k2.period_px))
    assert periods == pytest.approx([11.0, 11.0], rel=0.01), periods
    angles = sorted(a % 90.0 for a in (pair.k1.angle_deg, pair.k2.angle_deg))
    assert angles == pytest.approx([3.0, 3.0], abs=0.5), angles


@pytest.mark.parametrize("fill", [0.5, 1.0])
def test_carrier_search_reads_the_photo_or_its_spectrum_alike(fill):
    """``find_carriers(..., image=photo)`` reads the photo instead of transforming its spectrum back: same carriers.

    The two differ by the photo's mean (which no test of the apodised search sees) and by float32
    rounding: measured up to 1e-10 cycles/px apart (fill 0.4-0.6); bound 1e-6 (a thousandth of a bin at 640 px).
    """
    img = _framed("lines", fill).astype(np.float32)
    spec = F.compute_spectrum(img)
    assert (F._grid_filled_spectrum(spec, img) is None) == (fill == 1.0)
    a, b = F.find_carriers(spec), F.find_carriers(spec, image=img)
    assert np.allclose([a.k1.f, a.k2.f], [b.k1.f, b.k2.f], rtol=0, atol=1e-6)


def test_the_outline_fools_the_plain_search(monkeypatch):
    """The case the apodised search exists for: with it switched off, the outline's peaks win."""
    monkeypatch.setattr(F, "GRID_FILL_MIN", 0.0)
    img = _framed("dots", 0.5)
    try:
        pair = F.find_carriers(F.compute_spectrum(img))
    except Exception:
        return
    assert not np.allclose([pair.k1.period_px, pair.k2.period_px], 11.0, rtol=0.01)


def test_a_full_frame_grid_is_searched_on_its_own_spectrum():
    """A grid filling the frame (with a vignetting gradient) leaves the search as it was: no apodisation."""
    H, W = 240, 320
    y, x = np.mgrid[0:H, 0:W].astype(float)
    img = backdrop_pattern(x, y, pitch_mm=9.0, pattern="lines", rotation_deg=10.0)
    img *= 1.0 - 0.4 * ((x - W / 2) ** 2 + (y - H / 2) ** 2) / (W / 2) ** 2
    assert F._grid_filled_spectrum(F.compute_spectrum(img)) is None


@pytest.mark.parametrize("rotation_deg", [0.0, 20.0])
@pytest.mark.parametrize("fwhm", [0.15, 0.35])
def test_auto_names_dots_on_a_dot_lattice(rotation_deg, fwhm):
    """``auto`` names a dot lattice (Gaussian dots of FWHM 0.15 and 0.35 pitch), through a wave, at two rotations.

    Measured: diagonal energy 0.42-0.99 of the fundamentals (lines 0.01-0.15, checkerboards 0).
    """
    cap = synthetic_capture((256, 320), pitch_mm=2.0, mm_per_px=0.25, pattern="dots",
                            rotation_deg=rotation_deg, displacement=wave_displacement(0.05, 30.0, 20.0))
    y, x = np.mgrid[0:256, 0:320].astype(float)
    img = backdrop_pattern(x * 0.25, y * 0.25, pitch_mm=2.0, pattern="dots", rotation_deg=rotation_deg,
                           line_width=fwhm)
    for photo in (cap.image, img):
        ev = detect_pattern(photo)
        assert ev.pattern == "dots", ev
        assert ev.diagonal > 0.2


@pytest.mark.parametrize("pattern", ["lines", "checkerboard"])
@pytest.mark.parametrize("rotation_deg", [0.0, 20.0])
def test_auto_keeps_naming_lines_and_checkerboards(pattern, rotation_deg):
    """A line grid (line widths 0.1-0.35 pitch) and a checkerboard are named as before, not 'dots'."""
    y, x = np.mgrid[0:256, 0:320].astype(float)
    for width in (0.1, 0.25, 0.35):
        img = backdrop_pattern(x * 0.25, y * 0.25, pitch_mm=2.0, pattern=pattern, rotation_deg=rotation_deg,
                               line_width=width)
        assert detect_pattern(img).pattern == pattern, width


def test_auto_names_dots_on_a_board_in_a_dark_surround():
    """The partly filled frame: ``auto`` still names the dots (and the lines)."""
    assert detect_pattern(_framed("dots", 0.5, contrast=0.6)).pattern == "dots"
    assert detect_pattern(_framed("lines", 0.5, contrast=0.6)).pattern == "lines"


def test_a_given_dots_pattern_is_warned_only_where_the_scale_differs():
    """Lines and dots share the carrier period (the pitch): 'dots' given on a line grid changes no length and
    gets no warning; on a checkerboard (period pitch * sqrt(2)) it is warned."""
    from glassdist.analyzer.demodulate import carrier_period_mm
    from glassdist.analyzer.params import AnalyzerParams
    from glassdist.analyzer.pattern import settle_pattern

    assert carrier_period_mm(5.0, "dots") == carrier_period_mm(5.0, "lines") == 5.0
    y, x = np.mgrid[0:256, 0:320].astype(float)
    given = AnalyzerParams(pattern="dots")
    lines = backdrop_pattern(x * 0.25, y * 0.25, pitch_mm=2.0, pattern="lines")
    board = backdrop_pattern(x * 0.25, y * 0.25, pitch_mm=2.0, pattern="checkerboard")
    assert settle_pattern(given, lines).warnings == ()
    (warning,) = settle_pattern(given, board).warnings
    assert "checkerboard" in warning and "sqrt(2)" in warning


def _traced(pattern):
    """A 6 mm pane with a roller wave on its front, seen through by the exact tracer on a 320 x 240 camera."""
    from glassdist.scene import scene_from_dict

    board = {"lines": {"line_width_mm": 9.0}, "dots": {"dot_diameter_mm": 14.0}}[pattern]
    return scene_from_dict({
        "name": f"roller-{pattern}",
        "pane": {"size_mm": [1400, 1000], "thickness_mm": 6, "refractive_index": 1.52,
                 "deformation": {"front": [{"kind": "roller_wave", "amplitude_mm": 0.15, "wavelength_mm": 300.0,
                                            "direction_deg": 20.0}]}},
        "backdrop": {"pattern": pattern, "pitch_mm": 39.4, "distance_m": L, **board},
        "camera": {"focal_length_mm": 300, "sensor_width_mm": 36, "pixels": [320, 240], "position_mm": [0, 0, -4000]},
        "render": {"samples_per_pixel": 4, "seed": 4},
    })


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_a_ray_traced_dot_board_reads_as_the_line_grid(method):
    """The exact tracer's dot board (dots of 14 mm every 39.4 mm) and line grid through the same roller wave.

    phi_eff mean |.| and p95 of each within 1 % of the truth (tests/_truth.py on the landing
    points the tracer computes, on the region each result documents), and of each other.
    Measured (mean, p95 over the truth): Comparative dots 0.998 / 0.992, lines 0.998 / 0.992;
    Direct dots 1.000 / 0.999, lines 1.000 / 0.998.
    """
    from _truth import evaluate
    from glassdist.render import landing_points, render_scene
    from glassdist.scene import landing_jacobian

    out = {}
    for pattern in ("dots", "lines"):
        sc = _traced(pattern)
        img = render_scene(sc, engine="exact")
        ref = render_scene(sc, engine="exact", reference=True) if method == "comparative" else None
        assert detect_pattern(img).pattern == pattern
        res = analyze(img, pitch_mm=39.4, distance_m=L, reference=ref, params={"pattern": pattern})
        land = landing_points(sc)
        tr = evaluate(np.nan_to_num(land.displacement_mm), res.valid, distance_m=L, mm_per_px=res.mm_per_px,
                      detrend_degree=res.detrend_degree, sigma_mm=res.sigma_mm, jacobian=landing_jacobian(sc),
                      fit_mask=res.detrend_region)
        t = res.trusted & np.isfinite(tr.phi_eff_mD)
        assert t.mean() > 0.5
        out[pattern] = _reads_its_truth(res.phi_eff_mD, tr.phi_eff_mD, t, pattern)
    _dots_read_as_lines(out)


def test_a_dot_board_in_a_dark_surround_is_analysed_with_auto():
    """End to end (Direct, ``auto``): a flat dot board filling half a dark frame is named, scaled and analysed.

    Carrier period 11 px for a 5 mm pitch: 0.4545 mm/px. Measured: 'dots', 0.4555 mm/px (0.2 %),
    27 % of the frame analysed (the board less its borders), mean |phi_eff| 0.17 mD (the noise).
    """
    res = analyze(_framed("dots", 0.5, contrast=0.3), pitch_mm=5.0, distance_m=2.0)
    assert res.params.pattern == "dots"
    assert res.mm_per_px == pytest.approx(5.0 / 11.0, rel=0.01)
    assert 0.15 < res.valid.mean() < 0.5
