"""Contracts the adversarial tests do not reach: exit 1 and 130, the console script, inputs unchanged after success.

* Exit 1 (internal error): one line without ``--debug``, the traceback with it. The error
  is provoked in a real process by replacing the analysis with one that raises.
* Exit 130: a real SIGINT sent to a running ``glassdist analyze``.
* The ``glassdist`` console script (the environment's ``bin/glassdist``) is run.
* Every input, files and arrays, is byte-identical after each successful command
  (analyze, batch, render, validate, an experiment) and API call.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import glassdist
from conftest import REPO, write_lens_pair
from glassdist.cli import main
from glassdist.io import write_png16
from glassdist.scene import load_scene
from glassdist.synthetic import synthetic_capture, wave_displacement

SCRIPT = Path(sys.executable).parent / ("glassdist.exe" if os.name == "nt" else "glassdist")
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(Path(glassdist.__file__).parents[1]),
                                                   os.environ.get("PYTHONPATH", "")]))

#: Runs the command line with the analysis replaced (argv[1]: "raise" or "wait"), then its arguments.
# SIGINT's default action restored first: a suite started in the background (``cmd &`` in a
# non-interactive shell) hands its children SIGINT ignored, which a Ctrl-C at a terminal never is.
WRAPPER = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
import glassdist.analyzer as A
mode = sys.argv[1]
def fake(*a, **k):
    if mode == "raise":
        raise RuntimeError("planted fault")
    print("analysis started", file=sys.stderr, flush=True)
    time.sleep(60)
A.analyze = fake
from glassdist.cli import main
sys.exit(main(sys.argv[2:]))
"""


def _digest(paths) -> dict:
    out = {}
    for p in paths:
        p = Path(p)
        files = sorted(f for f in p.rglob("*") if f.is_file()) if p.is_dir() else [p]
        for f in files:
            out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """A lens pair (pane.png, reference.png), a mask, parameters and a specification, read-only."""
    d = write_lens_pair(tmp_path_factory.mktemp("inputs"))
    mask = np.ones((160, 160))
    mask[:, :10] = 0
    write_png16(d / "mask.png", mask)
    (d / "params.json").write_text(json.dumps({"detrend_degree": 2}))
    (d / "spec.json").write_text(json.dumps({"name": "loose", "criteria": [
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1e5}]}))
    return d


def _analyze_args(d, out):
    return ["analyze", str(d / "pane.png"), "--pitch-mm", "2", "--distance-m", "1", "--out", str(out)]


@pytest.mark.parametrize("debug", [False, True])
def test_internal_error_exits_1(pair, tmp_path, debug):
    args = (["--debug"] if debug else []) + _analyze_args(pair, tmp_path / "out")
    before = _digest([pair])
    r = subprocess.run([sys.executable, "-c", WRAPPER, "raise", *args], capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 1, r.stderr
    assert "planted fault" in r.stderr
    if debug:
        assert "Traceback (most recent call last)" in r.stderr and "RuntimeError: planted fault" in r.stderr
    else:
        assert "Traceback" not in r.stderr
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "internal error" in lines[0] and "--debug" in lines[0], r.stderr
    assert _digest([pair]) == before


def test_ctrl_c_exits_130(pair, tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", WRAPPER, "wait", *_analyze_args(pair, out)], stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True, env=ENV)
    try:
        for _ in range(50):  # whatever the command prints first, up to the analysis
            line = proc.stderr.readline()
            if not line or line.strip() == "analysis started":
                break
        assert line.strip() == "analysis started"
        proc.send_signal(signal.SIGINT)
        err = proc.communicate(timeout=60)[1]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    assert not [f for f in out.rglob("*") if f.name.endswith(".tmp")]  # no half-written file left


@pytest.mark.skipif(not SCRIPT.exists(), reason="the glassdist console script is not installed in this environment")
def test_console_script(pair, tmp_path):
    """The installed ``glassdist`` entry point: version, a real analysis (exit 0), bad input (exit 2, one line)."""
    r = subprocess.run([str(SCRIPT), "--version"], capture_output=True, text=True, env=ENV, timeout=60)
    assert r.returncode == 0 and r.stdout.startswith("glassdist"), r.stderr
    before = _digest([pair])
    out = tmp_path / "out"
    r = subprocess.run([str(SCRIPT), *_analyze_args(pair, out), "--reference", str(pair / "reference.png"), "-q"],
                       capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["method"] == "comparative"
    assert s["statistics"]["phi_eff_mD"]["mean_abs"] > 0
    assert _digest([pair]) == before
    r = subprocess.run([str(SCRIPT), *_analyze_args(pair, tmp_path / "bad"), "--distance-m", "-1"],
                       capture_output=True, text=True, env=ENV, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.skipif(not SCRIPT.exists(), reason="the glassdist console script is not installed in this environment")
def test_a_reader_that_leaves_stops_neither_a_batch_nor_an_analysis(pair, tmp_path):
    """``glassdist batch ... | head -1``: the pipe's reader is gone before the first line. Every pane is still
    analysed and indexed, and the exit status is the work's (0), not an internal error (it was 1: the
    batch stopped at its first printed line; ``analyze`` takes the same guard in ``cli.main``).
    Descriptors closed before the start: the work and its status too."""
    manifest = tmp_path / "manifest.csv"
    manifest.write_text("id,image,reference,pitch_mm,distance_m\n"
                        f"a,{pair / 'pane.png'},{pair / 'reference.png'},2,1\nb,{pair / 'pane.png'},,2,1\n")
    with open(tmp_path / "err", "w") as err:
        proc = subprocess.Popen([str(SCRIPT), "batch", str(manifest), "--out", str(tmp_path / "b"), "--no-progress"],
                                stdout=subprocess.PIPE, stderr=err, env=ENV)
        proc.stdout.close()  # the reader leaves before reading anything
        code = proc.wait(timeout=300)
    said = (tmp_path / "err").read_text()
    assert code == 0 and "BrokenPipe" not in said and "internal error" not in said, (code, said)
    index = (tmp_path / "b" / "index.csv").read_text().splitlines()
    assert [row.split(",")[1] for row in index[1:]] == ["done", "done"]
    # started with both descriptors closed (``>&- 2>&-``, as from some schedulers): the same (it was exit 1)
    closed = [*_analyze_args(pair, tmp_path / "c"), "--reference", str(pair / "reference.png")]
    shell = f'"{SCRIPT}" "$@" >&- 2>&-'
    assert subprocess.run(["bash", "-c", shell, "_", *closed], env=ENV, timeout=300).returncode == 0
    assert (tmp_path / "c" / "summary.json").is_file()
    bad = [*_analyze_args(pair, tmp_path / "d"), "--distance-m", "-1"]
    assert subprocess.run(["bash", "-c", shell, "_", *bad], env=ENV, timeout=300).returncode == 2


# ----- inputs unchanged after every successful command -----


def test_analyze_leaves_its_inputs_unchanged(pair, tmp_path):
    inputs = [pair / n for n in ("pane.png", "reference.png", "mask.png", "params.json", "spec.json")]
    before = _digest(inputs)
    code = main(_analyze_args(pair, tmp_path / "out") + [
        "--reference", str(pair / "reference.png"), "--mask", str(pair / "mask.png"), "--params",
        str(pair / "params.json"), "--spec", str(pair / "spec.json"), "--report", "--export", "-q"])
    assert code == 0
    assert _digest(inputs) == before
    # the Direct Method writing into the photos' own folder (its outputs beside the inputs)
    beside = tmp_path / "beside"
    beside.mkdir()
    for f in inputs:
        shutil.copy2(f, beside / f.name)
    before = _digest(sorted(beside.iterdir()))
    assert main(_analyze_args(beside, beside) + ["-q"]) == 0
    assert _digest([beside / f.name for f in inputs]) == before


def test_batch_leaves_its_inputs_unchanged(pair, tmp_path):
    manifest = tmp_path / "manifest.csv"
    manifest.write_text("id,image,reference,pitch_mm,distance_m,spec\n"
                        f"a,{pair / 'pane.png'},{pair / 'reference.png'},2,1,{pair / 'spec.json'}\n"
                        f"b,{pair / 'pane.png'},,2,1,\n")
    inputs = [manifest] + [pair / n for n in ("pane.png", "reference.png", "spec.json")]
    before = _digest(inputs)
    assert main(["batch", str(manifest), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    assert _digest(inputs) == before


def _tiny_scene(tmp_path) -> Path:
    scene = load_scene(REPO / "examples" / "scenes" / "wavy_slab.yaml").with_changes(
        camera={"pixels": [160, 120]}, backdrop={"pitch_mm": 96.8, "line_width_mm": 16},
        render={"samples_per_pixel": 1})
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(scene.model_dump(mode="json")))
    return path


def test_render_and_validate_leave_the_scene_unchanged(tmp_path):
    scene = _tiny_scene(tmp_path)
    before = _digest([scene])
    assert main(["render", str(scene), "--out", str(tmp_path / "r"), "--no-progress"]) == 0
    assert _digest([scene]) == before
    assert main(["validate", str(scene), "--method", "comparative", "--out", str(tmp_path / "v"), "--no-progress"]) == 0
    assert _digest([scene]) == before


def test_experiment_leaves_the_package_data_unchanged(tmp_path):
    """An experiment reads its scenes from the package and the examples: none of them changes."""
    inputs = [Path(glassdist.__file__).parent / "data", REPO / "examples" / "scenes"]
    before = _digest(inputs)
    assert main(["experiment", "accuracy", "--scenes", "flat_noisy", "--scale", "0.25", "--spp", "1",
                 "--no-progress", "--out", str(tmp_path)]) == 0
    assert _digest(inputs) == before


# ----- arrays passed to the Python API -----


def _frozen_copies(*arrays):
    return [np.array(a, copy=True) for a in arrays]


def _same(arrays, copies):
    return all(a.dtype == c.dtype and np.array_equal(a, c, equal_nan=True) for a, c in zip(arrays, copies))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_api_calls_leave_caller_arrays_unchanged(tmp_path, dtype):
    cap = synthetic_capture((160, 192), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.4, 90.0, 20.0),
                            noise_std=0.01, rng=1, dtype=dtype)
    img, ref = cap.image, cap.reference
    mask = np.ones(img.shape, bool)
    mask[:, :8] = False
    second = np.roll(img, 1, axis=1)
    arrays = [img, ref, mask, second]
    copies = _frozen_copies(*arrays)
    res = glassdist.analyze(img, pitch_mm=8.0, distance_m=10.0, reference=ref, mask=mask, params={"sigma_mm": 16.0})
    assert _same(arrays, copies)
    glassdist.analyze(img, pitch_mm=8.0, distance_m=10.0, params={"sigma_mm": 16.0})
    assert _same(arrays, copies)
    prepared = glassdist.prepare_reference(ref, params={"sigma_mm": 16.0})
    glassdist.analyze_captures([img, second], pitch_mm=8.0, distance_m=10.0, reference=prepared, params={"sigma_mm": 16.0})
    assert _same(arrays, copies)
    d = np.array(cap.displacement_mm, copy=True)
    d_copy = d.copy()
    glassdist.evaluate_displacement(d, mask, distance_m=10.0, mm_per_px=1.0, detrend_degree=2, sigma_mm=16.0)
    assert np.array_equal(d, d_copy) and _same([mask], [copies[2]])
    glassdist.channel_statistics(res.phi_eff_mD, res.trusted)
    fields = {k: np.array(getattr(res, k), copy=True) for k in ("phi_eff_mD", "displacement_mm", "valid")}
    glassdist.write_outputs(res, tmp_path / "out", image=img)
    assert _same(arrays, copies)
    assert all(np.array_equal(getattr(res, k), v, equal_nan=True) for k, v in fields.items())
