"""Hostile and odd inputs a first-time user meets: each exits 0 or 2 with one line, never 1, never a raw warning."""

import csv
import json
import struct
import subprocess
import sys
import warnings
import zlib
from pathlib import Path

import numpy as np
import pytest

from conftest import EXAMPLES, REPO, run_cli
from glassdist.io import write_png16
from glassdist.synthetic import synthetic_capture, wave_displacement

_cli = run_cli  # in this process (conftest.run_cli)


def _one_line_exit_2(r):
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and "Warning:" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 0.2 Mpx photo of an 8 mm line grid (1 mm per px) and its reference."""
    d = tmp_path_factory.mktemp("small")
    cap = synthetic_capture((400, 500), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.5, 120.0, 20.0))
    write_png16(d / "img.png", cap.image)
    write_png16(d / "ref.png", cap.reference)
    return d


def test_validate_with_a_model_that_predicts_nothing_exits_2():
    """A scene whose model shows no distortion (e.g. a huge thickness) has no ratio to validate: exit 2, not
    ZeroDivisionError."""
    from types import SimpleNamespace

    from glassdist.errors import InputError
    from glassdist.virtual.validate import CHANNELS, compare

    rng = np.random.default_rng(0)
    shape = (40, 50)
    measured = SimpleNamespace(**{n: rng.normal(size=shape) for n in CHANNELS},
                               displacement_detrended_mm=rng.normal(size=(*shape, 2)))
    flat = SimpleNamespace(**{n: np.zeros(shape) for n in CHANNELS}, displacement_detrended_mm=np.zeros((*shape, 2)))
    with pytest.raises(InputError, match="predicts no"):
        compare(measured, flat, np.ones(shape, bool))
    assert compare(measured, measured, np.ones(shape, bool)).metrics["ratios"]  # a real model still compares


def test_a_yaml_scene_saved_as_txt_is_read_by_its_content(tmp_path):
    from glassdist.scene import load_scene

    src = REPO / "examples" / "scenes" / "mild_slab_aligned.yaml"
    txt = tmp_path / "scene.txt"
    txt.write_text(src.read_text())
    assert load_scene(txt) == load_scene(src)
    txt.write_text(src.read_text().replace("pixels: [1024, 768]", "pixels: [160, 120]"))  # a quick predict
    as_json = tmp_path / "scene2.txt"
    as_json.write_text(json.dumps(load_scene(src).model_dump(mode="json")))
    assert load_scene(as_json) == load_scene(src)
    r = _cli("predict", txt, "--out", tmp_path / "p")
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("threshold", [1e-300, 1e-9])
def test_a_tiny_ransac_threshold_gives_one_line_not_a_python_warning(small, tmp_path, threshold):
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"ransac_threshold_periods": threshold}))
    r = _cli("analyze", small / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--params", params, "--quiet",
             "--out", tmp_path / "o")
    assert "RuntimeWarning" not in r.stderr and "numerical:" not in r.stderr, r.stderr
    _one_line_exit_2(r)
    assert "ransac_threshold_periods" in r.stderr


@pytest.mark.parametrize("pitch_mm", [8, 50])
def test_a_huge_sigma_on_a_small_image_exits_2_with_the_bound_or_works(small, tmp_path, pitch_mm):
    r = _cli("analyze", small / "img.png", "--reference", small / "ref.png", "--pitch-mm", pitch_mm, "--distance-m", 10,
             "--sigma-mm", 8000, "--quiet", "--out", tmp_path / "o")
    if r.returncode == 2:
        _one_line_exit_2(r)
        assert "at most" in r.stderr and "mm" in r.stderr
    else:
        assert r.returncode == 0, r.stderr
        assert json.loads((tmp_path / "o" / "summary.json").read_text())["sigma_mm"] == 8000


def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG that declares ``width x height`` px (8-bit grey) and holds no pixel data: nothing is allocated."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
                     + chunk(b"IEND", b""))


def test_a_100_mpx_photo_never_prints_pillows_bomb_warning(tmp_path):
    from glassdist.io import camera_metadata, image_shape

    big = tmp_path / "big.png"
    _png_header_only(big, 12000, 8400)  # 100.8 Mpx, over Pillow's 89 Mpx warning level
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert image_shape(big) == (8400, 12000)
        assert camera_metadata(big) in (None, {})
    # over glassdist's own limit: one line, exit 2, and still no Pillow warning
    r = subprocess.run([sys.executable, "-m", "glassdist", "analyze", str(big), "--pitch-mm", "5", "--distance-m", "1",
                        "--out", str(tmp_path / "o")], capture_output=True, text=True,
                       env={**__import__("os").environ, "GLASSDIST_MAX_MEGAPIXELS": "50"})
    _one_line_exit_2(r)
    assert "DecompressionBomb" not in r.stderr and "megapixels" in r.stderr


@pytest.mark.slow
def test_batch_index_states_the_pitch_and_distance_a_spec_pins(tmp_path):
    manifest = tmp_path / "manifest.csv"
    manifest.write_text(f"id,image,spec\nw1,{EXAMPLES / 'site_pane.png'},{REPO / 'examples/insitu/contract_spec.json'}\n")
    r = _cli("batch", manifest, "--out", tmp_path / "out", "--no-progress")
    assert r.returncode in (0, 3), r.stderr
    protocol = json.loads((REPO / "examples/insitu/contract_spec.json").read_text())["protocol"]
    with open(tmp_path / "out" / "index.csv", newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["status"] == "done"
    assert float(row["pitch_mm"]) == protocol["pitch_mm"] and float(row["distance_m"]) == protocol["distance_m"]


def test_the_pane_outline_in_summary_is_compact_and_faithful():
    """One 'x,y x,y ...' string per polygon, within 1.5 px (+ rounding) of the traced outline."""
    import cv2

    from glassdist.acceptance.zones import pane_frame_from_region

    yy, xx = np.mgrid[0:600, 0:800]
    region = (np.hypot(xx - 400, (yy - 300) * 1.3) < 250) & ~((abs(xx - 400) < 40) & (yy > 420))
    frame = pane_frame_from_region(region, 0.5)
    record = frame.to_dict()
    (polygon,) = record["outline_px"]
    pts = np.array([[float(v) for v in p.split(",")] for p in polygon.split()])
    traced = frame.outline_px[0]
    assert len(pts) < len(traced) and len(json.dumps(record)) < 4000
    # every traced vertex lies within tolerance of the compact polygon's edges
    dist = [abs(cv2.pointPolygonTest(pts.astype(np.float32).reshape(-1, 1, 2), (float(x), float(y)), True))
            for x, y in traced]
    assert max(dist) <= 1.5 + 0.75
