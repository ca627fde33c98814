"""Plausibility at the boundary: slips a valid input can carry warn, and no bundled example or ray-traced scene does.

The checks (:mod:`glassdist.analyzer.plausibility`): a glass-to-grid distance no camera could have seen
the photo's backdrop extent at (millimetres typed as metres), a reference that reads more
distorted than its photo (the two swapped), a measured scale the photo's EXIF contradicts (a
pitch in the wrong unit). Each is a warning on the result; every bundled example, example scene
and accuracy-set scene is analysed and none of them may raise one.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, run_cli
from glassdist import analyze
from glassdist.analyzer.plausibility import (
    EXIF_SCALE_FACTOR,
    MIN_VIEW_ANGLE_DEG,
    SWAP_RATIO,
    distance_warning,
    exif_scale_mm_per_px,
    exif_scale_warning,
    grid_spread,
    swap_warning,
    view_angle_deg,
)
from glassdist.io import write_png16
from glassdist.synthetic import lens_displacement, synthetic_capture

REAL = REPO.parent / "shared" / "data" / "real-checkerboard-water"
EXAMPLES = REPO / "examples"
#: The phrases that name each plausibility warning.
PLAUSIBILITY = ("implausible distance", "swapped", "scale mismatch")


def plausibility_warnings(warnings) -> list[str]:
    return [w for w in warnings if any(k in w for k in PLAUSIBILITY)]


@pytest.fixture(scope="module")
def lens_pair():
    """A strong converging lens (pitch 10 mm, 1.25 mm/px): the photo's grid bends, the reference's does not."""
    return synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25,
                             displacement=lens_displacement(0.4, 1.0, radius_mm=60.0), rng=0)


# --------------------------------------------------------------------------- distance


def test_view_angle_closed_form():
    # 1000 px of 1 mm seen from at least 10 m: 2 atan(0.5 / 10)
    assert view_angle_deg(1.0, (800, 1000), 10.0) == pytest.approx(math.degrees(2 * math.atan(0.05)), rel=1e-12)


def test_distance_warning_at_its_bound():
    """It fires just below the narrowest angle of view and not above it; the guess is L / 1000 where plausible."""
    shape, mm_per_px = (768, 1024), 0.722
    width_m = mm_per_px * 1024 / 1000
    at_bound = width_m / (2 * math.tan(math.radians(MIN_VIEW_ANGLE_DEG / 2)))  # L where the angle is the bound
    assert distance_warning(0.99 * at_bound, mm_per_px, shape) is None
    assert distance_warning(1.01 * at_bound, mm_per_px, shape) is not None
    w = distance_warning(500.0, mm_per_px, shape)
    assert "did you mean 0.5 m" in w and "millimetres typed as metres" in w
    for bad in (float("nan"), 0.0, -1.0):
        assert distance_warning(500.0, bad, shape) is None


def test_distance_in_millimetres_warns_on_the_command_line(tmp_path, lens_pair):
    """``--distance-m 500`` (0.5 m typed in mm) warns and names 0.5 m; ``--distance-m 0.5`` does not."""
    write_png16(tmp_path / "pane.png", lens_pair.image)
    write_png16(tmp_path / "ref.png", lens_pair.reference)
    base = ["analyze", tmp_path / "pane.png", "--reference", tmp_path / "ref.png", "--pitch-mm", "10", "-q"]
    slip = run_cli(*base, "--distance-m", "500", "--out", tmp_path / "slip")
    assert slip.returncode == 0, slip.stderr
    assert "implausible distance" in slip.stderr and "did you mean 0.5 m" in slip.stderr
    right = run_cli(*base, "--distance-m", "0.5", "--out", tmp_path / "right")
    assert right.returncode == 0 and not plausibility_warnings(right.stderr.splitlines()), right.stderr


def test_distance_in_millimetres_warns_in_python(lens_pair):
    res = analyze(lens_pair.image, reference=lens_pair.reference, pitch_mm=10.0, distance_m=500.0)
    assert any("did you mean 0.5 m" in w for w in res.warnings)
    assert not plausibility_warnings(analyze(lens_pair.image, pitch_mm=10.0, distance_m=0.5).warnings)


# --------------------------------------------------------------------------- swapped photo and reference


def test_swap_warning_rule():
    assert swap_warning(0.02, 0.02 * SWAP_RATIO * 1.01) is not None
    assert swap_warning(0.02, 0.02 * SWAP_RATIO * 0.99) is None
    assert swap_warning(0.001, 0.019) is None  # both below the noise floor of a regular grid
    assert swap_warning(float("nan"), 0.5) is None


def test_grid_spread_grows_with_the_distortion(lens_pair):
    from glassdist.analyzer import fourier as F

    c = F.find_carriers(F.compute_spectrum(lens_pair.reference))
    ref, photo = grid_spread(lens_pair.reference, c), grid_spread(lens_pair.image, c)
    assert ref < 0.01 and photo > 3 * 0.01, (ref, photo)


def test_swapped_synthetic_pair_warns(lens_pair):
    swapped = analyze(lens_pair.reference, reference=lens_pair.image, pitch_mm=10.0, distance_m=1.0)
    assert any("swapped" in w for w in swapped.warnings)
    right = analyze(lens_pair.image, reference=lens_pair.reference, pitch_mm=10.0, distance_m=1.0)
    assert not plausibility_warnings(right.warnings)


def _real(name):
    from glassdist.io import read_image

    path = REAL / name
    if not path.exists():
        pytest.skip(f"the real photos are not here ({REAL}): they live in the shared data folder, not the repository")
    return read_image(path, dtype=np.float32)


@pytest.mark.slow
def test_swapped_real_pair_warns():
    """The waves photo and its reference given the other way round warn 'swapped' (and read 20.8 mD, not 30.2)."""
    waves, ref = _real("distorted_waves.bmp"), _real("reference.png")
    kw = {"pitch_mm": 5.0, "distance_m": 0.5, "pattern": "checkerboard", "detrend_degree": 3}
    swapped = analyze(ref, reference=waves, **kw)
    assert [w for w in swapped.warnings if "swapped" in w], swapped.warnings
    assert not plausibility_warnings(analyze(waves, reference=ref, **kw).warnings)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["wavy_slab", "biconvex_lens_p64", "mild_slab_rotated"])
def test_swapped_rendered_pair_warns(name):
    """Ray-traced pairs given the other way round warn (the grid spreads 4 to 13 times the reference's at half size)."""
    from glassdist.experiments import scaled_scene
    from glassdist.render import render_scene
    from glassdist.scene import load_scene
    from glassdist.theory import analysis_params

    scene = scaled_scene(load_scene(EXAMPLES / "scenes" / f"{name}.yaml"), scale=0.5, spp=1)
    img, ref = render_scene(scene, engine="exact"), render_scene(scene, engine="exact", reference=True)
    res = analyze(ref, reference=img, pitch_mm=scene.backdrop.pitch_mm, distance_m=scene.backdrop.distance_m,
                  params=analysis_params(scene))
    assert any("swapped" in w for w in res.warnings), res.warnings


def test_grid_spread_on_the_real_photos():
    """The figures the swap test rests on: the waves photo spreads its grid's frequency 8 times the reference's;
    the floating ring, a local disturbance, hardly at all (so a swapped ring pair is not told)."""
    from glassdist.analyzer import fourier as F

    ref, waves, ring = _real("reference.png"), _real("distorted_waves.bmp"), _real("distorted_floating_ring.bmp")
    c = F.find_carriers(F.compute_spectrum(ref))
    s_ref, s_waves, s_ring = (grid_spread(a, c) for a in (ref, waves, ring))
    assert s_ref == pytest.approx(0.0164, abs=0.002)
    assert s_waves == pytest.approx(0.1385, abs=0.01)
    assert s_ring == pytest.approx(0.0185, abs=0.002)
    assert swap_warning(s_waves, s_ref) is None and swap_warning(s_ref, s_waves) is not None
    assert swap_warning(s_ring, s_ref) is None and swap_warning(s_ref, s_ring) is None


# --------------------------------------------------------------------------- EXIF scale


def _exif_photo(path, image, *, focal_mm=50.0, focal35_mm=50.0, subject_m=0.51):
    from PIL import Image

    im = Image.fromarray(np.round(255 * np.clip(image, 0, 1)).astype(np.uint8))
    exif = Image.Exif()
    sub = exif.get_ifd(0x8769)
    sub[0x920A], sub[0xA405], sub[0x9206] = focal_mm, int(focal35_mm), subject_m
    im.save(path, exif=exif, quality=95)
    return path


def test_exif_scale_closed_form():
    """35 mm-equivalent: pixel pitch 43.27 mm over the diagonal; focal-plane resolution: its own pitch."""
    shape = (192, 256)
    cam = {"focal_length_mm": 50.0, "focal_length_35mm_mm": 50.0, "subject_distance_m": 0.51}
    pitch = math.hypot(24, 36) / math.hypot(*shape)
    assert exif_scale_mm_per_px(cam, shape) == pytest.approx(pitch * (510 - 50) / 50, rel=1e-12)
    cam = {"focal_length_mm": 8.0, "subject_distance_m": 2.0, "focal_plane_px_per_mm": 250.0, "pixel_width": 512}
    assert exif_scale_mm_per_px(cam, shape) == pytest.approx(2 * (1 / 250) * (2000 - 8) / 8, rel=1e-12)
    for unknown in ({}, None, {**cam, "subject_distance_m": 0.0}, {**cam, "subject_distance_m": 4294967295.0}):
        assert exif_scale_mm_per_px(unknown, shape) is None
    assert exif_scale_warning(cam, EXIF_SCALE_FACTOR * 0.99 * exif_scale_mm_per_px(cam, shape), shape, 5) is None
    assert "scale mismatch" in exif_scale_warning(cam, EXIF_SCALE_FACTOR * 1.01 * exif_scale_mm_per_px(cam, shape), shape, 5)


def test_exif_contradicting_the_pitch_warns(tmp_path):
    """A photo whose EXIF implies 1.25 mm/px: the right pitch (10 mm) is quiet, 1 mm (cm typed as mm) warns."""
    cap = synthetic_capture((192, 256), pitch_mm=10.0, mm_per_px=1.25, rng=0)
    photo = _exif_photo(tmp_path / "pane.jpg", cap.image)
    right = analyze(photo, pitch_mm=10.0, distance_m=1.0)
    assert right.sources["camera"]["subject_distance_m"] == pytest.approx(0.51)
    assert not plausibility_warnings(right.warnings)
    wrong = analyze(photo, pitch_mm=1.0, distance_m=1.0)
    assert any("scale mismatch" in w and "pitch" in w for w in wrong.warnings), wrong.warnings
    # the command line reads the same EXIF and says the same
    out = run_cli("analyze", photo, "--pitch-mm", "1", "--distance-m", "1", "--out", tmp_path / "o", "-q")
    assert out.returncode == 0 and "scale mismatch" in out.stderr


# --------------------------------------------------------------------------- no false alarm


#: The bundled examples, as their READMEs run them (examples/*/README.md, README.md's Quick start), and the real
#: photographs (../shared/data) as the tests analyse them.
_IMG = "examples/images/"
BUNDLED = {
    "quick start (factory pane, Comparative)": [_IMG + "factory_pane.png", "--reference", _IMG + "factory_reference.png",
                                                "--pattern", "checkerboard", "--pitch-mm", "10", "--distance-m", "1"],
    "factory pane": [_IMG + "factory_pane.png", "--reference", _IMG + "factory_reference.png",
                     "--spec", "examples/factory/spec.json"],
    "factory clean pane": [_IMG + "factory_pane_clean.png", "--reference", _IMG + "factory_reference.png",
                           "--spec", "examples/factory/spec.json"],
    "in situ contract (site pane, Direct)": [_IMG + "site_pane.png", "--spec", "examples/insitu/contract_spec.json"],
    "reflection": ["examples/reflection/pane.png", "--reference", "examples/reflection/flat.png",
                   "--spec", "examples/reflection/spec.json"],
    "real waves, Comparative": [str(REAL / "distorted_waves.bmp"), "--reference", str(REAL / "reference.png"),
                                "--pattern", "checkerboard", "--pitch-mm", "5", "--distance-m", "0.5",
                                "--detrend-degree", "3"],
    "real ring, Comparative": [str(REAL / "distorted_floating_ring.bmp"), "--reference", str(REAL / "reference.png"),
                               "--pattern", "checkerboard", "--pitch-mm", "5", "--distance-m", "1"],
    "real waves, Direct": [str(REAL / "distorted_waves.bmp"), "--pitch-mm", "5", "--distance-m", "1",
                           "--pattern", "checkerboard", "--detrend-degree", "3"],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(BUNDLED))
def test_no_plausibility_warning_on_a_bundled_example(tmp_path, name):
    args = BUNDLED[name]
    if not (REPO / args[0]).exists():
        assert args[0].startswith(str(REAL)), f"{args[0]}: a bundled example is missing"
        pytest.skip(f"the real photographs are not in {REAL}")
    out = run_cli("analyze", *args, "--out", tmp_path / "out", "-q", cwd=REPO)
    assert out.returncode in (0, 3), out.stderr
    assert not plausibility_warnings(out.stderr.splitlines()), out.stderr


def _scene_warnings(scene, method: str) -> list[str]:
    from glassdist.analyzer import analyze_reflection
    from glassdist.render import render_scene
    from glassdist.theory import analysis_params, reflection_geometry

    img = render_scene(scene, engine="exact")
    ref = render_scene(scene, engine="exact", reference=True) if method == "comparative" else None
    p = analysis_params(scene)
    if scene.reflection:
        res = analyze_reflection(img, pitch_mm=scene.backdrop.pitch_mm, geometry=reflection_geometry(scene),
                                 reference=ref, params=p)
    else:
        res = analyze(img, pitch_mm=scene.backdrop.pitch_mm, distance_m=scene.backdrop.distance_m, reference=ref,
                      params=p)
    return plausibility_warnings(res.warnings)


SCENE_FILES = sorted((EXAMPLES / "scenes").glob("*.yaml"))
#: Scenes whose grid period would fall below the analysis's 3 px at half size: rendered at full size.
FULL_SIZE = {"dimple_reflection", "roller_wave_reflection"}


@pytest.mark.slow
@pytest.mark.parametrize("method", ["comparative", "direct"])
@pytest.mark.parametrize("path", SCENE_FILES, ids=[p.stem for p in SCENE_FILES])
def test_no_plausibility_warning_on_an_example_scene(path: Path, method):
    from glassdist.experiments import scaled_scene
    from glassdist.scene import load_scene

    scene = scaled_scene(load_scene(path), scale=1.0 if path.stem in FULL_SIZE else 0.5, spp=1)
    assert _scene_warnings(scene, method) == []


@pytest.mark.slow
@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_no_plausibility_warning_on_the_accuracy_set(method):
    """Every scene of ``glassdist experiment accuracy`` at half size, 1 sample per pixel."""
    from glassdist.experiments import scaled_scene
    from glassdist.experiments.accuracy import SCENES

    fired = {}
    for name, (_, build, _) in SCENES.items():
        found = _scene_warnings(scaled_scene(build(), scale=0.5, spp=1), method)
        if found:
            fired[name] = found
    assert fired == {}


def test_several_captures_warn_as_one(lens_pair):
    """``analyze_captures`` (``glassdist analyze A B ...``) checks the run's slips as ``analyze`` does."""
    from glassdist import analyze_captures

    rng = np.random.default_rng(1)
    images = [lens_pair.reference + rng.normal(0, 0.01, lens_pair.reference.shape) for _ in range(2)]
    res = analyze_captures(images, reference=lens_pair.image, pitch_mm=10.0, distance_m=500.0)
    assert any("did you mean 0.5 m" in w for w in res.warnings)
    assert any("swapped" in w for w in res.warnings)
