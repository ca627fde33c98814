"""Through the command line: verdicts and exit codes of analyze --spec, the report, and a killed-then-resumed batch."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import child_env, run_cli  # analyze in this process; the batches run as processes, their panes too


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """A small synthetic pane (a converging lens, -100 mD at its centre) and its reference."""
    from conftest import write_lens_pair

    root = write_lens_pair(tmp_path_factory.mktemp("photos"))
    spec = {"criteria": [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1000},
                         {"channel": "phi_shear", "statistic": "p95_abs", "max_mD": 1000}]}
    (root / "pass.json").write_text(json.dumps(dict(spec, name="lenient")))
    spec["criteria"].append({"channel": "phi_eff", "statistic": "max_abs", "max_mD": 5})
    (root / "fail.json").write_text(json.dumps(dict(spec, name="strict")))
    return root


def _analyze(photos, out, *extra):
    return run_cli("analyze", photos / "pane.png", "--reference", photos / "reference.png", "--pitch-mm", 2,
                   "--distance-m", 1, "--out", out, *extra)


def test_spec_fail_exits_3_with_report(photos, tmp_path):
    out = tmp_path / "fail"
    r = _analyze(photos, out, "--spec", photos / "fail.json", "--report", "--export")
    assert r.returncode == 3, r.stderr
    lines = r.stdout.splitlines()
    assert any(ln.startswith("FAIL  max |phi_eff| <= 5 mD") for ln in lines)
    assert "VERDICT: FAIL (2/3 criteria passed) spec 'strict'" in lines
    summary = json.loads((out / "summary.json").read_text())
    assert summary["verdict"]["result"] == "FAIL" and summary["method"] == "comparative"
    # the lens is converging: its centre reads phi_eff < 0, well beyond 5 mD
    assert summary["a4"]["statistics"]["phi_eff"]["max_abs"] > 20
    html = (out / "report.html").read_text(encoding="utf-8")
    assert hashlib.sha256((photos / "pane.png").read_bytes()).hexdigest() in html
    assert 'id="verdict">FAIL<' in html and html.count("data:image/png;base64,") >= 6
    for name in ("statistics.csv", "fields.npz", "tiff/phi_eff_mD.tif", "phi_eff.png", "input_region.png"):
        assert (out / name).is_file(), name


def test_spec_pass_exits_0(photos, tmp_path):
    r = _analyze(photos, tmp_path / "pass", "--spec", photos / "pass.json")
    assert r.returncode == 0, r.stderr
    assert "VERDICT: PASS (2/2 criteria passed) spec 'lenient'" in r.stdout
    assert not (tmp_path / "pass" / "report.html").exists()


def test_bad_spec_exits_2_before_any_work(photos, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"name": "x", "criteria": [{"channel": "phi_eff", "statistic": "p95", "max_mD": 1}]}))
    r = _analyze(photos, tmp_path / "never", "--spec", bad)
    assert r.returncode == 2
    assert r.stderr.startswith("glassdist: error: invalid specification") and r.stderr.count("\n") == 1
    assert "Traceback" not in r.stderr and not (tmp_path / "never").exists()


def _wait_for(path, proc, seconds=240, *, holds=lambda p: True):
    """Poll until ``path`` exists and ``holds(path)``, while the batch ``proc`` runs."""
    t0 = time.monotonic()
    while not (path.exists() and holds(path)):
        assert proc.poll() is None, "the batch ended before it could be interrupted"
        assert time.monotonic() - t0 < seconds, f"{path} never appeared"
        time.sleep(0.1)


def _indexed_done(index, pane_id):
    """Whether ``index`` (index.csv) lists ``pane_id`` as done (False while it is being rewritten)."""
    try:
        return any(r["id"] == pane_id and r["status"] == "done" for r in csv.DictReader(index.open()))
    except (OSError, csv.Error, KeyError):
        return False


def test_batch_killed_then_resumed(photos, tmp_path):
    manifest = tmp_path / "manifest.csv"
    manifest.write_text(
        "id,image,reference,pitch_mm,distance_m\n"
        f"first,{photos / 'pane.png'},{photos / 'reference.png'},2,1\n"
        f"second,{photos / 'pane.png'},,2,1\n"
        "missing,no_such_photo.png,,2,1\n"
    )
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "glassdist", "batch", str(manifest), "--out", str(out), "--no-progress",
           "--spec", str(photos / "pass.json")]
    proc = subprocess.Popen(cmd, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        # the pane is placed first, then the index rewritten: kill once the index lists it
        _wait_for(out / "index.csv", proc, holds=lambda p: _indexed_done(p, "first"))
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and the analysis it is running, mid-pane
    finally:
        proc.wait(timeout=60)
    idx = {r["id"]: r for r in csv.DictReader((out / "index.csv").open())}
    assert idx["first"]["status"] == "done" and idx["second"]["status"] == "pending"
    stamp = os.stat(out / "panes" / "first" / "pane.json").st_mtime_ns

    r = subprocess.run(cmd, env=child_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 4, r.stdout + r.stderr  # every pane ran but one could not be analysed
    assert "resuming: 1 pane(s) already done, 2 to analyse" in r.stdout
    assert os.stat(out / "panes" / "first" / "pane.json").st_mtime_ns == stamp  # not redone
    idx = {r["id"]: r for r in csv.DictReader((out / "index.csv").open())}
    assert [idx[i]["status"] for i in ("first", "second", "missing")] == ["done", "done", "error"]
    assert idx["first"]["verdict"] == idx["second"]["verdict"] == "PASS"
    assert idx["first"]["method"] == "comparative" and idx["second"]["method"] == "direct"
    assert "does not exist" in idx["missing"]["error"]
    assert not [p for p in (out / "panes").iterdir() if p.name.startswith(".tmp")]
    html = (out / "index.html").read_text()
    assert all(f'id="pane-{i}"' in html for i in ("first", "second", "missing"))
