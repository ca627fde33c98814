"""Hostile input on every sub-command: the exit-status contract, one line, no traceback, nothing touched.

Each case runs ``glassdist.cli.main`` in-process (a few run the console command) on an input
built to break something: numbers out of range or not finite, documents that are deep, huge,
not UTF-8 or YAML alias bombs, scenes with NaN sizes or impossible geometry, images that are
empty, FIFOs, stacks or declare 30000 x 30000 px in their header, manifests that smuggle
options or formulas. For every case: exit status 2 (bad input), exactly one line on stderr
and no traceback, every input byte-identical afterwards, and no file or folder left behind.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import tifffile
import yaml

from conftest import run_cli
from glassdist.synthetic import synthetic_capture

IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0

SCENE = {
    "name": "tiny",
    "pane": {"size_mm": [1400, 1000], "thickness_mm": 20, "refractive_index": 1.52, "yaw_deg": 30,
             "deformation": {"both": [{"kind": "roller_wave", "amplitude_mm": 0.3, "wavelength_mm": 200}]}},
    "backdrop": {"pattern": "lines", "pitch_mm": 72.6, "line_width_mm": 18, "distance_m": 10},
    "camera": {"focal_length_mm": 300, "sensor_width_mm": 36, "pixels": [64, 48], "position_mm": [0, 0, -4000]},
    "analysis": {"detrend_degree": 2},
}


# ---------------------------------------------------------------- fixtures and helpers

@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A folder of valid inputs shared by the cases (each case checks they are left unchanged)."""
    d = tmp_path_factory.mktemp("inputs")
    img = synthetic_capture((96, 96), pitch_mm=8.0, mm_per_px=1.0).image
    for name in ("grid.png", "ref.png"):
        assert cv2.imwrite(str(d / name), np.round(img * 255).astype(np.uint8))
    (d / "params.json").write_text('{"detrend_degree": 2}')
    (d / "spec.json").write_text(json.dumps(
        {"name": "t", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 60}]}))
    (d / "scene.yaml").write_text(yaml.safe_dump(SCENE))
    (d / "manifest.csv").write_text("image,pitch_mm,distance_m\ngrid.png,8,10\n")
    return d


def _snapshot(folder: Path) -> dict:
    """Every entry under ``folder``: SHA-256 of regular files, the kind of anything else."""
    snap = {}
    for p in sorted(folder.rglob("*")):
        mode = p.lstat().st_mode
        if stat.S_ISREG(mode):
            try:
                snap[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
            except PermissionError:
                snap[str(p)] = "unreadable"
        else:
            snap[str(p)] = stat.filemode(mode)[0]
    return snap


def _run(argv):
    r = run_cli(*argv)
    return r.returncode, r.stdout, r.stderr


def refused(argv, *folders, code=2):
    """Run ``argv``: assert the exit status, one stderr line, no traceback, ``folders`` unchanged."""
    before = [_snapshot(f) for f in folders]
    got, out, err = _run(argv)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert got == code, f"exit {got}, expected {code}: {err[-500:]}"
    assert len(lines) == 1, err[-2000:]
    assert "Traceback" not in err and "Traceback" not in out
    assert len(lines[0]) < 3000
    assert [_snapshot(f) for f in folders] == before, "an input changed or a file was left behind"
    return lines[0]


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose header declares width x height px (8-bit grey), with a tiny deflate stream."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + chunk(b"IEND", b"")


# ---------------------------------------------------------------- numbers given as options

NUM_BAD = ["1e308", "5e-324", "inf", "-inf", "nan", "NaN", "Infinity", "1e999", "0", "-0", "-1", "1e-300",
           "abc", "", " ", "1,5", "0x10", "9" * 5000]
INT_BAD = ["1e308", "inf", "nan", "abc", "", "1.5", "-1", "9" * 5000, "0x10", "1e3"]


def _cmd(command, d, tmp):
    """A valid command line of ``command`` (inputs from ``d``, output under ``tmp``)."""
    out = ["--out", tmp / "out"]
    return {
        "analyze": ["analyze", d / "grid.png", "--pitch-mm", "8", "--distance-m", "10", *out],
        "batch": ["batch", d / "manifest.csv", "--no-progress", *out],
        "predict": ["predict", d / "scene.yaml", *out],
        "validate": ["validate", d / "scene.yaml", "--no-progress", *out],
        "render": ["render", d / "scene.yaml", "--no-progress", *out],
        "experiment": ["experiment", "parity", "--no-progress", *out],
        "sweep": ["sweep", d / "scene.yaml", "--vary", "backdrop.pitch_mm=72.6", "--no-progress", *out],
        "serve": ["serve", "--port", "8765"],
    }[command]


NUMBER_OPTIONS = [
    ("analyze", "--pitch-mm"), ("analyze", "--distance-m"), ("analyze", "--sigma-mm"),
    ("batch", "--pitch-mm"), ("batch", "--distance-m"), ("batch", "--sigma-mm"),
    ("predict", "--sigma-mm"), ("validate", "--sigma-mm"),
    ("experiment", "--scale"), ("experiment", "--sigma-mm"), ("serve", "--max-upload-mb"),
]
INT_OPTIONS = [
    ("analyze", "--detrend-degree"), ("batch", "--detrend-degree"), ("predict", "--detrend-degree"),
    ("validate", "--detrend-degree"), ("validate", "--spp"), ("validate", "--seed"),
    ("render", "--spp"), ("render", "--seed"), ("experiment", "--spp"), ("sweep", "--spp"),
    ("serve", "--port"), ("serve", "--max-jobs"),
]
OPTION_CASES = [(c, o, v) for c, o in NUMBER_OPTIONS for v in NUM_BAD] + [(c, o, v) for c, o in INT_OPTIONS for v in INT_BAD]


@pytest.mark.parametrize("command, option, value", OPTION_CASES,
                         ids=[f"{c}{o}={v[:12]!r}" for c, o, v in OPTION_CASES])
def test_numbers_out_of_range_are_refused(base, tmp_path, command, option, value):
    argv = _cmd(command, base, tmp_path)
    if option in argv:
        del argv[argv.index(option):argv.index(option) + 2]
    refused(argv + [f"{option}={value}"], base, tmp_path)


VARY_BAD = ["backdrop.pitch_mm=inf", "backdrop.pitch_mm=.inf", "backdrop.pitch_mm=.nan", "backdrop.pitch_mm=1e308",
            "backdrop.pitch_mm=5e-324", "backdrop.distance_m=1e-300", "pane.size_mm.0=.nan", "pane.size_mm.9=1",
            "pane.colour=green", "backdrop.pitch_mm=", "backdrop.pitch_mm", "=1,2", "backdrop.pitch_mm=[1, 2]",
            "camera.pixels.0=" + "9" * 5000, "pane.thickness_mm=-1", "analysis.sigma_mm=.inf",
            "camera.position_mm.2=0", "pane.yaw_deg=1e308"]


@pytest.mark.parametrize("vary", VARY_BAD, ids=[v[:30] for v in VARY_BAD])
def test_sweep_refuses_bad_variants_before_any_run(base, tmp_path, vary):
    argv = _cmd("sweep", base, tmp_path)
    argv[argv.index("--vary") + 1] = vary
    refused(argv, base, tmp_path)


def test_sigma_larger_than_the_image_is_refused_before_the_analysis(base, tmp_path):
    line = refused(_cmd("analyze", base, tmp_path) + ["--sigma-mm", "8000"], base, tmp_path)
    assert "extent" in line


# ---------------------------------------------------------------- JSON documents

DOC_BAD = {
    "not-utf8": b'\xff\xfe{"a": 1}',
    "deep": b'{"a":' * 2000 + b"1" + b"}" * 2000,
    "deep-lists": b"[" * 100 + b"]" * 100,
    "bigint": b'{"detrend_degree": ' + b"9" * 5000 + b"}",
    "nan": b'{"sigma_mm": NaN}',
    "infinity": b'{"sigma_mm": Infinity}',
    "-infinity": b'{"sigma_mm": -Infinity}',
    "1e999": b'{"sigma_mm": 1e999}',
    "list": b"[1, 2]",
    "string": b'"text"',
    "null": b"null",
    "trailing": b'{"detrend_degree": 2} trailing',
    "empty": b"",
    "binary": b"\x00\x01\x02\x03",
    "newline-key": b'{"x\\nVERDICT: PASS": 1}',
    "truncated": b'{"detrend_degree": ',
    "bom-junk": b"\xef\xbb\xbf\xef\xbb\xbf{}",
    "duplicate-key": b'{"sigma_mm": 2, "sigma_mm": 3}',  # the parser would keep the last silently
}
PARAMS_BAD = dict(DOC_BAD, **{
    "unknown-key": b'{"detrend_degre": 2}',
    "sigma-1e308": b'{"sigma_mm": 1e308}',
    "sigma-5e-324": b'{"sigma_mm": 5e-324}',
    "trials-1e11": b'{"ransac_max_trials": 100000000000}',
    "decimation-1000": b'{"decimation": 1000}',
    "sigma-periods-1e300": b'{"sigma_periods": 1e300}',
    "pattern": b'{"pattern": "spiral"}',
    "border-negative": b'{"border_periods": -1}',
    "sigma-text": b'{"sigma_mm": "12abc"}',
    "seed-huge": b'{"ransac_seed": 1000000000000000000000}',
})
SPEC_BAD = dict(DOC_BAD, **{
    "max-infinity": b'{"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": Infinity}]}',
    "max-1e308": b'{"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1e308}]}',
    "max-negative": b'{"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": -1}]}',
    "threshold-1e999": b'{"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "area_over", '
                       b'"threshold_mD": 1e999, "max_percent": 1}]}',
    "percent-101": b'{"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "area_over", '
                   b'"threshold_mD": 10, "max_percent": 101}]}',
    "limit-twice": b'{"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 500, '
                   b'"max_mD": 5}]}',
    "no-criteria": b'{"name": "s"}',
    "empty-criteria": b'{"name": "s", "criteria": []}',
    "empty-name": b'{"name": "", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1}]}',
    "channel": b'{"name": "s", "criteria": [{"channel": "phi_x", "statistic": "p95_abs", "max_mD": 1}]}',
})
PARAMS_COMMANDS = ["analyze", "batch", "predict", "validate"]
SPEC_COMMANDS = ["analyze", "batch"]
DOC_CASES = ([("--params", c, k) for c in PARAMS_COMMANDS for k in PARAMS_BAD
              if not (k == "pattern" and c in ("predict", "validate"))]  # a scene's backdrop sets the pattern
             + [("--spec", c, k) for c in SPEC_COMMANDS for k in SPEC_BAD])


@pytest.mark.parametrize("option, command, case", DOC_CASES, ids=[f"{c}{o}-{k}" for o, c, k in DOC_CASES])
def test_hostile_documents_are_refused(base, tmp_path, option, command, case):
    f = tmp_path / "doc.json"
    f.write_bytes((PARAMS_BAD if option == "--params" else SPEC_BAD)[case])
    line = refused(_cmd(command, base, tmp_path) + [option, f], base, tmp_path)
    assert "VERDICT" not in line or "\\n" in line


# ---------------------------------------------------------------- scenes

def _scene_text(mutate) -> str:
    data = json.loads(json.dumps(SCENE))
    mutate(data)
    return yaml.safe_dump(data)


def _set(path, value):
    def mutate(d):
        *keys, last = path
        for k in keys:
            d = d[k]
        d[last] = value
    return mutate


_BOMB = "".join(f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]\n" if i else 'l0: &l0 ["lol"]\n' for i in range(9))
SCENE_BAD = {
    "size-nan": _scene_text(_set(["pane", "size_mm"], [float("nan"), 1000])),
    "size-inf": _scene_text(_set(["pane", "size_mm"], [float("inf"), 1000])),
    "size-1e308": _scene_text(_set(["pane", "size_mm"], [1e308, 1000])),
    "amplitude-nan": _scene_text(_set(["pane", "deformation", "both", 0, "amplitude_mm"], float("nan"))),
    "amplitude-1e308": _scene_text(_set(["pane", "deformation", "both", 0, "amplitude_mm"], 1e308)),
    "wavelength-inf": _scene_text(_set(["pane", "deformation", "both", 0, "wavelength_mm"], float("inf"))),
    "distance-nan": _scene_text(_set(["backdrop", "distance_m"], float("nan"))),
    "distance-1e-300": _scene_text(_set(["backdrop", "distance_m"], 1e-300)),
    "pitch-1e308": _scene_text(_set(["backdrop", "pitch_mm"], 1e308)),
    "camera-inside-tilted-pane": _scene_text(lambda d: (d["pane"].update(yaw_deg=80, center_mm=[0, 0, 100]),
                                                        d["camera"].update(position_mm=[300, 0, 0]))),
    "faces-cross": _scene_text(_set(["pane", "deformation", "front"],
                                    [{"kind": "roller_wave", "amplitude_mm": 30, "wavelength_mm": 200}])),
    "pixels-huge": _scene_text(_set(["camera", "pixels"], [100_000_000, 10])),
    "pixels-bigint": _scene_text(_set(["camera", "pixels"], [10**300, 10])),
    "thickness-negative": _scene_text(_set(["pane", "thickness_mm"], -1)),
    "unknown-key": _scene_text(_set(["pane", "colour"], "green")),
    "spp-huge": _scene_text(_set(["render"], {"samples_per_pixel": 10**9})),
    "alias-bomb-in-analysis": yaml.safe_dump({k: v for k, v in SCENE.items() if k != "analysis"})
    + "analysis:\n  detrend_degree: 2\n"
    + "  bomb:\n" + "".join("    " + line + "\n" for line in _BOMB.splitlines()),
    "recursive-alias": yaml.safe_dump(SCENE) + "extra: &a [*a]\n",
    "deep": yaml.safe_dump(SCENE) + "deep: " + "[" * 60 + "]" * 60 + "\n",
    "python-tag": yaml.safe_dump(SCENE) + "evil: !!python/object/apply:os.system ['echo pwned']\n",
    "list": "- 1\n- 2\n",
    "empty": "",
    "syntax": "pane: [1, 2\n",
    "bigint-text": yaml.safe_dump(SCENE).replace("pitch_mm: 72.6", "pitch_mm: " + "9" * 5000),
    "inf-in-analysis": _scene_text(_set(["analysis", "sigma_mm"], float("inf"))),
    "name-twice": yaml.safe_dump(SCENE) + "name: again\n",
}
SCENE_BYTES = {"not-utf8": b"name: caf\xe9\n"}
SCENE_CASES = [(c, k) for c in ("render", "predict", "validate") for k in [*SCENE_BAD, *SCENE_BYTES]]


@pytest.mark.parametrize("command, case", SCENE_CASES, ids=[f"{c}-{k}" for c, k in SCENE_CASES])
def test_hostile_scenes_are_refused(base, tmp_path, command, case):
    f = tmp_path / "scene.yaml"
    if case in SCENE_BYTES:
        f.write_bytes(SCENE_BYTES[case])
    else:
        f.write_text(SCENE_BAD[case], encoding="utf-8")
    argv = _cmd(command, base, tmp_path)
    argv[1] = f
    refused(argv, base, tmp_path)


def test_scene_json_with_nan_is_refused(base, tmp_path):
    f = tmp_path / "scene.json"
    f.write_text(json.dumps(SCENE).replace('"amplitude_mm": 0.3', '"amplitude_mm": NaN'))
    refused(["predict", f, "--out", tmp_path / "out"], base, tmp_path)


# ---------------------------------------------------------------- images

def _fifo(f):
    os.mkfifo(f)


def _stack(f):
    tifffile.imwrite(f, np.zeros((3, 40, 50), np.uint16), photometric="minisblack")


IMAGE_BAD = {
    "empty.png": lambda f: f.write_bytes(b""),
    "garbage.png": lambda f: f.write_bytes(b"not an image at all" * 10),
    "missing.png": lambda f: None,
    "folder.png": lambda f: f.mkdir(),
    "fifo.png": _fifo,
    "declares-30000x30000.png": lambda f: f.write_bytes(_png_header(30000, 30000)),
    "declares-60000x60000.png": lambda f: f.write_bytes(_png_header(60000, 60000)),
    "stack.tif": _stack,
    "volume.tif": lambda f: tifffile.imwrite(f, np.zeros((2, 3, 40, 50), np.uint8), photometric="minisblack"),
    "complex.tif": lambda f: tifffile.imwrite(f, np.zeros((40, 50), np.complex64)),
    "text.tif": lambda f: f.write_text("II* but not really a TIFF"),
    "picture.gif": lambda f: f.write_bytes(b"GIF89a" + b"\0" * 20),
    "loop.png": lambda f: f.symlink_to(f),
    "header-only.png": lambda f: f.write_bytes(_png_header(64, 64)[:33]),
}
# problems that only the decoded pixels show (the batch's own check reads headers only)
IMAGE_DATA_BAD = {
    "nan.tif": lambda f: tifffile.imwrite(f, np.full((40, 50), np.nan, np.float32)),
    "inf.tif": lambda f: tifffile.imwrite(f, np.full((40, 50), np.inf, np.float32)),
    "truncated.png": lambda f: f.write_bytes(cv2.imencode(".png", np.zeros((64, 64), np.uint8))[1].tobytes()[:60]),
    "tiny.png": lambda f: cv2.imwrite(str(f), np.zeros((8, 8), np.uint8)),
}
IMAGE_SLOTS = ["image", "--reference", "--mask"]
# (a too small photo is refused by the analysis itself, after the output folder is made)
IMAGE_CASES = ([(s, k) for s in IMAGE_SLOTS for k in [*IMAGE_BAD, *IMAGE_DATA_BAD] if (s, k) != ("image", "tiny.png")]
               + [("batch --reference", k) for k in IMAGE_BAD])


@pytest.mark.parametrize("slot, case", IMAGE_CASES, ids=[f"{s}-{k}" for s, k in IMAGE_CASES])
def test_hostile_images_are_refused(base, tmp_path, monkeypatch, slot, case):
    src = tmp_path / "src"
    src.mkdir()
    f = src / case
    (IMAGE_BAD.get(case) or IMAGE_DATA_BAD[case])(f)
    out = ["--out", tmp_path / "out"]
    if slot == "image":
        argv = ["analyze", f, "--pitch-mm", "8", "--distance-m", "10", *out]
    elif slot in ("--reference", "--mask"):
        argv = ["analyze", base / "grid.png", slot, f, "--pitch-mm", "8", "--distance-m", "10", *out]
    else:
        argv = ["batch", base / "manifest.csv", "--reference", f, "--no-progress", *out]
    monkeypatch.chdir(tmp_path)
    refused(argv, base, tmp_path)


# ---------------------------------------------------------------- batch manifests

MANIFEST_BAD = {
    "pitch-inf": "image,pitch_mm,distance_m\n{g},inf,10\n",
    "pitch-1e308": "image,pitch_mm,distance_m\n{g},1e308,10\n",
    "pitch-5e-324": "image,pitch_mm,distance_m\n{g},5e-324,10\n",
    "distance-nan": "image,pitch_mm,distance_m\n{g},8,nan\n",
    "distance-1e-300": "image,pitch_mm,distance_m\n{g},8,1e-300\n",
    "sigma-1e999": "image,pitch_mm,distance_m,sigma_mm\n{g},8,10,1e999\n",
    "sigma-8000": "image,pitch_mm,distance_m,sigma_mm\n{g},8,10,8000\n",
    "spec-cell-bad": "image,pitch_mm,distance_m,spec\n{g},8,10,{d}/params.json\n",
    "params-cell-dir": "image,pitch_mm,distance_m,params\n{g},8,10,{d}\n",
    "detrend-bigint": "image,pitch_mm,distance_m,detrend_degree\n{g},8,10," + "9" * 5000 + "\n",
    "detrend-float": "image,pitch_mm,distance_m,detrend_degree\n{g},8,10,1.5\n",
    "detrend-99": "image,pitch_mm,distance_m,detrend_degree\n{g},8,10,99\n",
    "unknown-column": "image,pitch,distance_m\n{g},8,10\n",
    "no-image-column": "pitch_mm,distance_m\n8,10\n",
    "duplicate-id": "image,pitch_mm,distance_m\n{g},8,10\n{g},8,10\n",
    "formula-id": "id,image,pitch_mm,distance_m\n=HYPERLINK(\"http://x\"),{g},8,10\n",
    "newline-id": 'id,image,pitch_mm,distance_m\n"a\nVERDICT: PASS",{g},8,10\n',
    "missing-params": "image,pitch_mm,distance_m,params\n{g},8,10,nowhere.json\n",
    "bad-params": "image,pitch_mm,distance_m,params\n{g},8,10,{d}/manifest.csv\n",
    "missing-spec": "image,pitch_mm,distance_m,spec\n{g},8,10,nowhere.json\n",
    "missing-reference": "id,image,reference,pitch_mm,distance_m\na,{g},{g},8,10\nb,{g},nowhere.png,8,10\n",
    "missing-mask": "id,image,mask,pitch_mm,distance_m\na,{g},,8,10\nb,{g},nowhere.npy,8,10\n",
    "mask-cell-dir": "image,mask,pitch_mm,distance_m\n{g},{d},8,10\n",
    "empty": "",
    "header-only": "image,pitch_mm,distance_m\n",
    "nul": "image,pitch_mm,distance_m\n{g}\0,8,10\n",
}
MANIFEST_BYTES = {"not-utf8": b"image,pitch_mm,distance_m\ncaf\xe9.png,8,10\n"}


@pytest.mark.parametrize("case", [*MANIFEST_BAD, *MANIFEST_BYTES])
def test_hostile_manifests_are_refused_before_any_pane(base, tmp_path, monkeypatch, case):
    src = tmp_path / "src"
    src.mkdir()
    cv2.imwrite(str(src / "small.png"), np.zeros((40, 40), np.uint8))
    m = src / "m.csv"
    if case in MANIFEST_BYTES:
        m.write_bytes(MANIFEST_BYTES[case])
    else:
        m.write_text(MANIFEST_BAD[case].format(g=base / "grid.png", d=base, t=src))
    monkeypatch.chdir(src)
    refused(["batch", "m.csv", "--no-progress", "--out", tmp_path / "out"], base, tmp_path)


def test_oversized_documents_are_refused_from_their_size(base, tmp_path, monkeypatch):
    monkeypatch.setenv("GLASSDIST_MAX_DOCUMENT_BYTES", "1000")
    monkeypatch.setenv("GLASSDIST_MAX_CSV_BYTES", "1000")
    big = tmp_path / "big.json"
    big.write_text('{"detrend_degree": 2, "$comment": "' + "x" * 5000 + '"}')
    for argv in (_cmd("analyze", base, tmp_path) + ["--params", big], _cmd("analyze", base, tmp_path) + ["--spec", big],
                 _cmd("predict", base, tmp_path) + ["--params", big]):
        assert "MiB" in refused(argv, base, tmp_path)
    m = tmp_path / "m.csv"
    m.write_text("image,pitch_mm,distance_m\n" + f"{base / 'grid.png'},8,10\n" * 100)
    refused(["batch", m, "--out", tmp_path / "out"], base, tmp_path)


# ---------------------------------------------------------------- render, cycles-setup

@pytest.mark.parametrize("case", ["existing-file", "the-scene", "exact-engine"])
def test_save_blend_never_overwrites(base, tmp_path, case):
    other = tmp_path / "mine.blend"
    other.write_bytes(b"BLENDER user file")
    target = {"existing-file": other, "the-scene": base / "scene.yaml", "exact-engine": tmp_path / "new.blend"}[case]
    engine = "exact" if case == "exact-engine" else "cycles"
    refused(["render", base / "scene.yaml", "--engine", engine, "--save-blend", target, "--out", tmp_path / "out"],
            base, tmp_path)


@pytest.mark.parametrize("case", ["missing", "folder", "not-executable", "not-python"])
def test_cycles_setup_with_a_bad_python(tmp_path, monkeypatch, case):
    monkeypatch.delenv("GLASSDIST_CYCLES_PYTHON", raising=False)
    monkeypatch.delenv("GLASSDIST_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    py = tmp_path / "python3.11"
    if case == "folder":
        py.mkdir()
    elif case == "not-executable":
        py.write_text("#!/bin/sh\n")
    elif case == "not-python":
        py.write_text("#!/bin/sh\nexit 3\n")
        py.chmod(0o755)
    before = _snapshot(tmp_path)
    code, _, err = _run(["cycles-setup", "--python", py])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert {k: v for k, v in _snapshot(tmp_path).items() if "/cache" not in k} == before


# ---------------------------------------------------------------- the console command itself

CONSOLE = [
    ["analyze", "{t}/fifo.png", "--pitch-mm", "8", "--distance-m", "10", "--out", "{t}/out"],
    ["analyze", "{d}/grid.png", "--pitch-mm", "inf", "--distance-m", "10", "--out", "{t}/out"],
    ["render", "{t}/bomb.yaml", "--out", "{t}/out"],
    ["batch", "{t}/m.csv", "--no-progress", "--out", "{t}/out"],
]


@pytest.mark.parametrize("argv", CONSOLE, ids=["fifo", "inf", "alias-bomb", "params-in-manifest"])
def test_console_command_refuses_in_one_line(base, tmp_path, argv):
    os.mkfifo(tmp_path / "fifo.png")
    (tmp_path / "bomb.yaml").write_text(SCENE_BAD["alias-bomb-in-analysis"])
    (tmp_path / "m.csv").write_text(f"image,pitch_mm,distance_m,params\n{base / 'grid.png'},8,10,{tmp_path / 'bomb.yaml'}\n")
    before = _snapshot(base), _snapshot(tmp_path)
    r = subprocess.run([sys.executable, "-m", "glassdist", *[a.format(d=base, t=tmp_path) for a in argv]],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    assert (_snapshot(base), _snapshot(tmp_path)) == before
