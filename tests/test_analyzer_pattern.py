"""The backdrop pattern decided from the spectrum's harmonics (glassdist.analyzer.pattern), and --pattern auto."""

import json
import math

import numpy as np
import pytest

import glassdist
from conftest import DATA, REPO, needs_real_photos, run_cli
from glassdist.analyzer.pattern import detect_pattern
from glassdist.synthetic import synthetic_capture, wave_displacement


def _capture(pattern, rotation_deg, mm_per_px=0.25, seed=0):
    return synthetic_capture((400, 520), pitch_mm=2.0, mm_per_px=mm_per_px, pattern=pattern, rotation_deg=rotation_deg,
                             displacement=wave_displacement(0.3, 40.0, 15.0), noise_std=0.02, rng=seed)


@pytest.mark.parametrize("pattern", ["lines", "checkerboard"])
@pytest.mark.parametrize("rotation_deg", [0.0, 20.0, 45.0, 70.0])
@pytest.mark.parametrize("mm_per_px", [0.12, 0.25])
def test_each_pattern_is_told_at_any_rotation(pattern, rotation_deg, mm_per_px):
    ev = detect_pattern(_capture(pattern, rotation_deg, mm_per_px).image)
    assert ev.pattern == pattern, ev
    # the structure behind it: a line grid's harmonics along the carriers, a checkerboard's mixed odd ones
    strong, weak = (ev.along, ev.mixed) if pattern == "lines" else (ev.mixed, ev.along)
    assert strong >= 3 * weak


def test_a_sinusoidal_grid_is_ambiguous_and_auto_says_so():
    """No harmonics at all: the spectrum cannot tell; 'auto' warns and uses 'lines'."""
    y, x = np.mgrid[0:320, 0:320]
    image = 0.5 + 0.2 * np.cos(2 * np.pi * x / 8) + 0.2 * np.cos(2 * np.pi * y / 8)
    assert detect_pattern(image).pattern is None
    res = glassdist.analyze(image, pitch_mm=2.0, distance_m=1.0)
    assert res.params.pattern == "lines"
    assert any("does not tell a line grid from a checkerboard" in w for w in res.warnings), res.warnings


@pytest.mark.parametrize("pattern", ["lines", "checkerboard"])
def test_auto_gives_the_same_result_as_the_right_pattern(pattern):
    cap = _capture(pattern, 20.0)
    auto = glassdist.analyze(cap.image, pitch_mm=2.0, distance_m=1.0, reference=cap.reference)
    given = glassdist.analyze(cap.image, pitch_mm=2.0, distance_m=1.0, reference=cap.reference, pattern=pattern)
    assert auto.params.pattern == pattern and auto.summary()["pattern"] == pattern
    assert auto.mm_per_px == given.mm_per_px
    assert abs(auto.mm_per_px - cap.mm_per_px) < 0.01 * cap.mm_per_px  # the synthetic truth
    assert not any("pattern" in w for w in given.warnings)


def test_a_contradicted_pattern_gets_a_warning_naming_both():
    cap = _capture("checkerboard", 10.0)
    res = glassdist.analyze(cap.image, pitch_mm=2.0, distance_m=1.0, pattern="lines")
    assert any("'lines' was given" in w and "shows a checkerboard" in w for w in res.warnings), res.warnings


_cli = run_cli  # in this process (conftest.run_cli)


@pytest.mark.slow
@needs_real_photos
def test_bundled_checkerboard_photo_without_pattern(tmp_path):
    """The real waves photo, no --pattern: checkerboard, mm_per_px 0.7221 (pitch 5, distance 0.5); --pattern lines warns."""
    args = ["analyze", DATA / "distorted_waves.bmp", "--reference", DATA / "reference.png", "--pitch-mm", 5,
            "--distance-m", 0.5, "--detrend-degree", 3, "--quiet"]
    r = _cli(*args, "--out", tmp_path / "auto")
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "auto" / "summary.json").read_text())
    assert s["pattern"] == "checkerboard" and s["protocol"]["sources"]["pattern"] == "auto"
    assert round(s["mm_per_px"], 4) == 0.7221
    r = _cli(*args, "--pattern", "lines", "--out", tmp_path / "lines")
    assert r.returncode == 0, r.stderr
    lines = json.loads((tmp_path / "lines" / "summary.json").read_text())
    assert "checkerboard" in r.stderr and "'lines' was given" in r.stderr
    # the same carriers read with the line grid's period: lengths off by exactly sqrt(2)
    assert math.isclose(s["mm_per_px"] / lines["mm_per_px"], math.sqrt(2), rel_tol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["wavy_slab.yaml", "pillowed_igu.yaml", "mild_slab_rotated.yaml"])
def test_ray_traced_backdrops_are_told(scene):
    """Rendered through a pane by the exact tracer (blur, perspective, the pane's own distortion): the
    scene file's backdrop pattern is the truth."""
    from glassdist.render import render_scene
    from glassdist.scene import load_scene

    sc = load_scene(REPO / "examples" / "scenes" / scene).with_changes(camera={"pixels": [384, 288]})
    assert detect_pattern(render_scene(sc)).pattern == sc.backdrop.pattern
