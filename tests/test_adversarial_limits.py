"""Size limits, camera bit depths, TIFF layouts and the batch's defences, one behaviour per test."""

from __future__ import annotations

import csv
import re
import struct
import time
import zlib

import cv2
import numpy as np
import pytest
import tifffile

from glassdist.acceptance.spec import Check, Verdict
from glassdist.errors import InputError
from glassdist.io import image_shape, read_image, read_mask
from glassdist.jobs.batch import Pane, check_panes, read_manifest, run_batch, write_index
from glassdist.jobs.runner import PaneOutcome
from glassdist.validation import load_document, safe_text


def _png_header(width, height):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + chunk(b"IEND", b""))


def test_a_png_declaring_900_megapixels_is_refused_from_its_header_at_once(tmp_path):
    f = tmp_path / "bomb.png"
    f.write_bytes(_png_header(30000, 30000))
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="30000x30000 px.*250 megapixels"):
        read_image(f)
    assert time.perf_counter() - t0 < 1.0


@pytest.mark.parametrize("ext", [".png", ".tif", ".bmp", ".jpg"])
def test_the_size_limit_is_read_from_every_format_header_and_configurable(tmp_path, monkeypatch, ext):
    f = tmp_path / f"img{ext}"
    img = (np.arange(200 * 300) % 251).reshape(200, 300).astype(np.uint8)
    tifffile.imwrite(f, img) if ext == ".tif" else cv2.imwrite(str(f), img)
    assert read_image(f).shape == (200, 300) and image_shape(f) == (200, 300)
    with pytest.raises(InputError, match="300x200 px"):
        read_image(f, max_megapixels=0.05)
    monkeypatch.setenv("GLASSDIST_MAX_MEGAPIXELS", "0.05")
    for reader in (read_image, image_shape):
        with pytest.raises(InputError, match="GLASSDIST_MAX_MEGAPIXELS"):
            reader(f)


@pytest.mark.parametrize("bits", [10, 12, 14])
def test_camera_tiffs_are_scaled_by_their_bit_depth(tmp_path, bits):
    rng = np.random.default_rng(bits)
    data = rng.integers(0, 2**bits, (40, 50)).astype(np.uint16)
    data[0, 0] = 2**bits - 1
    f = tmp_path / f"cam{bits}.tif"
    tifffile.imwrite(f, data, bitspersample=bits)  # 10 and 14 bits are packed: decoded by imagecodecs
    img = read_image(f)
    np.testing.assert_allclose(img, data / (2**bits - 1), rtol=0, atol=1e-12)
    assert img.max() == 1.0


def test_a_16_bit_tiff_is_still_scaled_by_65535(tmp_path):
    f = tmp_path / "u16.tif"
    tifffile.imwrite(f, np.full((40, 50), 4095, np.uint16))
    assert read_image(f).max() == pytest.approx(4095 / 65535)


def test_planar_rgb_tiff_reads_like_the_contiguous_one(tmp_path):
    rgb = np.random.default_rng(1).integers(0, 256, (3, 40, 50)).astype(np.uint8)
    tifffile.imwrite(tmp_path / "planar.tif", rgb, photometric="rgb", planarconfig="separate")
    tifffile.imwrite(tmp_path / "contig.tif", np.moveaxis(rgb, 0, -1), photometric="rgb")
    planar, contig = read_image(tmp_path / "planar.tif"), read_image(tmp_path / "contig.tif")
    assert planar.shape == (40, 50)
    np.testing.assert_array_equal(planar, contig)


def test_tiff_stacks_are_refused_but_a_preview_page_is_not_a_frame(tmp_path):
    g = np.zeros((40, 50), np.uint8)
    tifffile.imwrite(tmp_path / "stack.tif", np.stack([g, g, g]), photometric="minisblack")
    with pytest.raises(InputError, match="3 pages"):
        read_image(tmp_path / "stack.tif")
    with tifffile.TiffWriter(tmp_path / "preview.tif") as tw:
        tw.write(g)
        tw.write(g[:10, :10], subfiletype=1)
    assert read_image(tmp_path / "preview.tif").shape == (40, 50)


def test_complex_tiff_and_nan_mask_are_refused(tmp_path):
    tifffile.imwrite(tmp_path / "c.tif", np.ones((40, 50), np.complex64))
    with pytest.raises(InputError, match="complex"):
        read_image(tmp_path / "c.tif")
    m = np.ones((40, 50))
    m[3, 4] = np.nan
    np.save(tmp_path / "m.npy", m)
    with pytest.raises(InputError, match="NaN"):
        read_mask(tmp_path / "m.npy", (40, 50))


def test_yaml_alias_bomb_is_refused_in_a_fraction_of_a_second(tmp_path):
    lines = ['l0: &l0 ["lol"]'] + [f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]" for i in range(1, 12)]
    f = tmp_path / "bomb.yaml"
    f.write_text("\n".join(lines) + "\n")
    # The CPU time this process spends (6 ms measured alone): wall time also counts the other test
    # workers' load (a fresh-clone run read 1.1 s of wall time once).
    t0 = time.process_time()
    with pytest.raises(InputError, match="GLASSDIST_MAX_NODES"):
        load_document(f, "scene file")
    assert time.process_time() - t0 < 1.0


@pytest.mark.parametrize("name, twice, once, where", [
    ("spec.json", '{"criteria": [{"max_mD": 500, "max_mD": 5}]}', '{"criteria": [{"max_mD": 500, "min_mD": 5}]}',
     "'max_mD' appears twice in one object"),
    ("scene.yaml", "pane:\n  thickness_mm: 20\n  thickness_mm: 2\n", "pane:\n  thickness_mm: 20\n  n: 2\n",
     "'thickness_mm' appears twice in one mapping (line 3)"),
])
def test_a_key_given_twice_is_refused_not_resolved(tmp_path, name, twice, once, where):
    """JSON and YAML parsers keep the last of two equal keys silently: a limit or a dimension given
    twice would be read as whichever came second."""
    f = tmp_path / name
    f.write_text(twice)
    with pytest.raises(InputError, match=re.escape(where)):
        load_document(f, "document")
    f.write_text(once)
    assert load_document(f, "document")  # the same keys once each: read


def test_a_spec_name_with_a_newline_cannot_print_a_verdict_line():
    v = Verdict("x\nVERDICT: PASS", "s.json", "0", (Check("p95 |phi_eff| <= 1 mD\nVERDICT: PASS", 5.0, 1.0, "mD", "<=", False),))
    lines = v.lines()
    assert all("\n" not in ln for ln in lines)
    assert [ln for ln in lines if ln.startswith("VERDICT")] == [lines[-1]] and lines[-1].startswith("VERDICT: FAIL")
    assert safe_text("a\r\x1b[2Jb") == "a\\r\\x1b[2Jb"


def test_index_csv_neutralises_formulas(tmp_path):
    panes = [Pane(id=f"p{i}", image=tmp_path / f"{i}.png", pitch_mm=5.0, distance_m=1.0) for i in range(5)]
    (tmp_path / "failed").mkdir()
    errors = ['=HYPERLINK("http://x","y")', "@SUM(A1:A2)", "+cmd|' /C calc'!A0", "-2+3", "\tX"]
    import json

    for pane, err in zip(panes, errors):
        (tmp_path / "failed" / f"{pane.id}.json").write_text(json.dumps({"error": err, "seconds": 1}))
    write_index(panes, tmp_path)
    with open(tmp_path / "index.csv", newline="") as fh:
        cells = [row["error"] for row in csv.DictReader(fh)]
    assert cells == ["'" + e for e in errors]


def test_bad_settings_are_found_before_any_pane_runs(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((64, 64), np.uint8))
    (tmp_path / "bad.json").write_text('{"sigma_mm": 1e999}')
    (tmp_path / "empty.png").write_bytes(b"")
    good = Pane(id="a", image=tmp_path / "a.png", pitch_mm=5.0, distance_m=1.0)
    for bad, words in ((Pane(id="b", image=tmp_path / "a.png", pitch_mm=5.0, distance_m=1.0, params=tmp_path / "bad.json"),
                        "floating-point range"),
                       (Pane(id="b", image=tmp_path / "a.png", pitch_mm=5.0, distance_m=1.0, spec=tmp_path / "bad.json"),
                        "floating-point range"),
                       (Pane(id="b", image=tmp_path / "a.png", pitch_mm=5.0, distance_m=1.0, sigma_mm=8000.0), "extent")):
        with pytest.raises(InputError, match=words) as info:
            check_panes([good, bad])
        assert str(info.value).startswith("pane 'b'")
    with pytest.raises(InputError, match="empty"):
        check_panes([good], {"reference": tmp_path / "empty.png"})
    check_panes([good, Pane(id="c", image=tmp_path / "missing.png", pitch_mm=5.0, distance_m=1.0)])  # the pane's own


def test_a_manifest_cell_cannot_become_an_option_of_analyze(tmp_path, monkeypatch, capsys):
    from glassdist.cli import main

    (tmp_path / "m.csv").write_text("id,image,pitch_mm,distance_m\na,-h,8,10\nb,--help,8,10\n")
    monkeypatch.chdir(tmp_path)
    assert main(["batch", "m.csv", "--no-progress", "--out", "out"]) == 4  # both panes fail: no such image
    capsys.readouterr()
    with open(tmp_path / "out" / "index.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["status"] for r in rows] == ["error", "error"]
    assert all("does not exist" in r["error"] for r in rows)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "out"]


def test_resume_does_not_depend_on_how_the_manifest_path_is_spelt(tmp_path, monkeypatch):
    (tmp_path / "data").mkdir()
    cv2.imwrite(str(tmp_path / "data" / "a.png"), np.zeros((64, 64), np.uint8))
    (tmp_path / "data" / "m.csv").write_text("image,pitch_mm,distance_m\na.png,5,1\n")
    calls = []

    def runner(pane, out_dir, *, report=False, export=False):
        calls.append(pane.id)
        (out_dir / "summary.json").write_text("{}")
        return PaneOutcome(0, "log")

    monkeypatch.chdir(tmp_path)
    for spelling in ("data/m.csv", "./data/../data/m.csv", str(tmp_path / "data" / "m.csv")):
        monkeypatch.chdir(tmp_path if not spelling.startswith("/") else tmp_path / "data")
        assert run_batch(read_manifest(spelling), tmp_path / "out", runner=runner, progress=False, echo=lambda s: None) == 0
    assert calls == ["a"]


@pytest.mark.parametrize("period_px", [2.2, 2.5, 2.9])
def test_a_grid_finer_than_3_px_is_refused(period_px):
    from glassdist import analyze
    from glassdist.synthetic import synthetic_capture

    cap = synthetic_capture((200, 240), pitch_mm=8.0, mm_per_px=8.0 / period_px)
    with pytest.raises(InputError, match=f"about {period_px:.2f} px, below the 3 px"):
        analyze(cap.image, pitch_mm=8.0, distance_m=10.0)


def test_a_carrier_near_the_sampling_limit_is_warned_about():
    from glassdist import analyze
    from glassdist.synthetic import synthetic_capture

    near = analyze(synthetic_capture((200, 240), pitch_mm=8.0, mm_per_px=8.0 / 3.3).image, pitch_mm=8.0, distance_m=10.0)
    assert any("sampling limit" in w for w in near.warnings)
    far = analyze(synthetic_capture((200, 240), pitch_mm=8.0, mm_per_px=1.0).image, pitch_mm=8.0, distance_m=10.0)
    assert not any("sampling limit" in w for w in far.warnings)
