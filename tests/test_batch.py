"""Batch: manifest reading, resume after an interruption, failing panes, exit codes, index."""

from __future__ import annotations

import csv
import json
import os
import shutil

import pytest

from glassdist.errors import InputError
from glassdist.jobs.batch import (
    EXIT_PANE_ERRORS,
    Pane,
    pane_defaults,
    panes_from_folder,
    read_manifest,
    run_batch,
)
from glassdist.jobs.runner import PaneOutcome


class FakeRunner:
    """Stands in for ``glassdist analyze``: replays a real run's output folder; can fail or be interrupted on chosen panes.

    The folder is one of ``conftest.real_pane_outputs`` (a real analysis of a small lens, by
    verdict), so the index reads a real summary; only the runner's scheduling is staged.
    """

    outputs: dict = {}

    def __init__(self, *, interrupt=(), errors=(), verdicts=None):
        self.calls, self.interrupt, self.errors, self.verdicts = [], set(interrupt), set(errors), verdicts or {}

    def __call__(self, pane, out_dir, *, report=False, export=False):
        self.calls.append(pane.id)
        (out_dir / "result.npz").write_bytes(b"partial")
        if pane.id in self.interrupt:
            raise KeyboardInterrupt  # the batch is killed while this pane is half written
        if pane.id in self.errors:
            return PaneOutcome(2, "log", f"error: image file '{pane.image}' does not exist; check the path")
        verdict = self.verdicts.get(pane.id)
        shutil.copytree(self.outputs[verdict or "none"], out_dir, dirs_exist_ok=True)
        return PaneOutcome(3 if verdict == "FAIL" else 0, "log")


@pytest.fixture(autouse=True)
def _real_outputs(real_pane_outputs):
    FakeRunner.outputs = real_pane_outputs


def _panes(tmp_path, ids=("a", "b", "c")):
    return [Pane(id=i, image=tmp_path / f"{i}.png", pitch_mm=5.0, distance_m=1.5) for i in ids]


def _index(out):
    with (out / "index.csv").open() as fh:
        return {r["id"]: r for r in csv.DictReader(fh)}


def _run(panes, out, runner):
    return run_batch(panes, out, runner=runner, progress=False, echo=lambda s: None)


def test_resume_after_interruption_keeps_finished_panes(tmp_path):
    out = tmp_path / "out"
    panes = _panes(tmp_path)
    first = FakeRunner(interrupt={"b"})
    with pytest.raises(KeyboardInterrupt):
        _run(panes, out, first)
    assert first.calls == ["a", "b"]
    assert (out / "panes" / "a" / "pane.json").is_file()
    assert not (out / "panes" / "b").exists()  # no half-written pane under its final name
    idx = _index(out)
    assert [idx[i]["status"] for i in "abc"] == ["done", "pending", "pending"]
    stamp = os.stat(out / "panes" / "a" / "pane.json").st_mtime_ns
    summary_a = (out / "panes" / "a" / "summary.json").read_bytes()

    second = FakeRunner()
    assert _run(panes, out, second) == 0
    assert second.calls == ["b", "c"]  # a is not redone
    assert os.stat(out / "panes" / "a" / "pane.json").st_mtime_ns == stamp
    assert (out / "panes" / "a" / "summary.json").read_bytes() == summary_a
    idx = _index(out)
    assert sorted(idx) == ["a", "b", "c"] and {r["status"] for r in idx.values()} == {"done"}
    # the index's statistics are the real summary's
    real_summary = json.loads((FakeRunner.outputs["none"] / "summary.json").read_text())
    real = real_summary["a4"]
    for ch in ("phi_eff", "phi_shear"):
        for stat in ("mean_abs", "p95_abs", "max_abs"):
            assert float(idx["a"][f"{ch}_{stat}_mD"]) == pytest.approx(real["statistics"][ch][stat], rel=1e-3)
    for share in ("measured_percent", "trusted_percent"):
        assert float(idx["a"][share]) == pytest.approx(real_summary[share], rel=1e-3)
    assert idx["a"]["method"] == "comparative" and float(idx["a"]["sigma_mm"]) > 0
    assert not [p for p in (out / "panes").iterdir() if p.name.startswith(".tmp")]
    html = (out / "index.html").read_text()
    assert all(f'id="pane-{i}"' in html for i in "abc")

    third = FakeRunner()
    assert _run(panes, out, third) == 0 and third.calls == []


def test_stale_temporary_pane_of_a_killed_run_is_cleaned(tmp_path):
    out = tmp_path / "out"
    _run(_panes(tmp_path, ["a"]), out, FakeRunner())
    stale = out / "panes" / ".tmp-b-99999"
    stale.mkdir()
    (stale / "result.npz").write_bytes(b"half")
    runner = FakeRunner()
    _run(_panes(tmp_path, ["a", "b"]), out, runner)
    assert runner.calls == ["b"] and not stale.exists()


def test_failing_pane_is_reported_and_batch_goes_on(tmp_path):
    out = tmp_path / "out"
    panes = _panes(tmp_path)
    lines = []
    code = run_batch(panes, out, runner=FakeRunner(errors={"b"}), progress=False, echo=lines.append)
    assert code == EXIT_PANE_ERRORS == 4
    idx = _index(out)
    assert [idx[i]["status"] for i in "abc"] == ["done", "error", "done"]
    assert "does not exist" in idx["b"]["error"]
    assert json.loads((out / "failed" / "b.json").read_text())["exit_code"] == 2
    assert any(line.startswith("[2/3] b  ERROR") for line in lines)
    assert lines[-1] == "3 panes: 2 analysed (0 PASS, 0 FAIL, 2 without specification), 1 could not be analysed"

    retry = FakeRunner()
    assert _run(panes, out, retry) == 0
    assert retry.calls == ["b"]  # failed panes are retried, finished ones kept
    assert not (out / "failed" / "b.json").exists()


def test_a_pane_whose_runner_raises_is_an_error_not_a_crash(tmp_path):
    def broken(pane, out_dir, **kw):
        raise RuntimeError("boom")

    out = tmp_path / "out"
    assert _run(_panes(tmp_path, ["a"]), out, broken) == EXIT_PANE_ERRORS
    assert _index(out)["a"]["error"] == "RuntimeError: boom"


def test_spec_failure_gives_exit_3_and_verdicts_in_index(tmp_path):
    out = tmp_path / "out"
    code = _run(_panes(tmp_path), out, FakeRunner(verdicts={"a": "PASS", "b": "FAIL", "c": "PASS"}))
    assert code == 3
    assert [_index(out)[i]["verdict"] for i in "abc"] == ["PASS", "FAIL", "PASS"]


def test_changed_settings_redo_the_pane(tmp_path):
    out = tmp_path / "out"
    _run(_panes(tmp_path, ["a", "b"]), out, FakeRunner())
    changed = [Pane(id="a", image=tmp_path / "a.png", pitch_mm=6.0, distance_m=1.5),
               Pane(id="b", image=tmp_path / "b.png", pitch_mm=5.0, distance_m=1.5)]
    runner = FakeRunner()
    _run(changed, out, runner)
    assert runner.calls == ["a"]
    assert json.loads((out / "panes" / "a" / "pane.json").read_text())["pane"]["pitch_mm"] == "6.0"


def test_output_folder_rules(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("mine")
    with pytest.raises(InputError, match="existing file"):
        _run(_panes(tmp_path), f, FakeRunner())
    own = tmp_path / "own"
    own.mkdir()
    (own / "notes.csv").write_text("mine")
    with pytest.raises(InputError, match="not empty"):
        _run(_panes(tmp_path), own, FakeRunner())
    assert f.read_text() == "mine" and (own / "notes.csv").read_text() == "mine"


def test_manifest_paths_defaults_and_comments(tmp_path):
    (tmp_path / "m").mkdir()
    m = tmp_path / "m" / "manifest.csv"
    m.write_text(
        "id,image,reference,pitch_mm,distance_m,detrend_degree\n"
        "p1,img/one.png,ref.png,5,1.5,,,\n"  # empty trailing cells, as spreadsheets write them
        "# a comment row, with, more, commas, than, the, header\n"
        ",two.bmp,,,2.0,4\n"
    )
    (tmp_path / "m" / "ref.png").write_bytes(b"x")  # a reference cell must name a file (the image cell need not)
    panes = read_manifest(m, pane_defaults(pitch_mm=7.0, spec="spec.json"))
    assert [p.id for p in panes] == ["p1", "two"]
    assert panes[0].image == tmp_path / "m" / "img" / "one.png"
    assert panes[0].reference == tmp_path / "m" / "ref.png"
    assert panes[1].pitch_mm == 7.0 and panes[1].distance_m == 2.0 and panes[1].detrend_degree == 4
    assert panes[1].spec == (tmp_path.cwd() / "spec.json").absolute()  # option paths: from where the user is
    request = panes[1].request(tmp_path / "o", report=True)
    assert request.images == (tmp_path / "m" / "two.bmp",) and request.detrend_degree == 4 and request.report
    assert request.record_as is not None and request.record_as.source == "batch"
    assert request.record_as.out_dir == str(tmp_path / "two") and request.record_as.job == str(tmp_path.parent)
    # the child parses options as --name=value, the image last after '--' (a cell '-h' cannot become an option)
    args = request.options()
    assert args[0] == "analyze" and args[-2:] == ["--", str(tmp_path / "m" / "two.bmp")]
    assert "--detrend-degree=4" in args and "--report" in args and f"--out={tmp_path / 'o'}" in args
    assert type(request).model_validate_json(request.model_dump_json()) == request  # what the child reads back


@pytest.mark.parametrize(
    "text, words",
    [
        ("image,pitch,distance_m\na.png,5,1\n", "unknown column(s) pitch"),
        # where ',' is the decimal mark
        ("image;pitch_mm;distance_m\na.png;2,5;1\n", "separates its columns with ';', not commas"),
        ("image\tpitch_mm\tdistance_m\na.png\t5\t1\n", "separates its columns with '\\t', not commas"),
        # a duplicated column: the last one used to win silently (a pane analysed from the other photo)
        ("image,image,pitch_mm,distance_m\na.png,b.png,5,1\n", "column(s) image appear more than once"),
        # an unquoted comma in a path shifts every later cell
        ("image,pitch_mm,distance_m\npane,1.png,5,1\n", "line 2 has 4 cells but the header names 3 columns"),
        ("image,pitch_mm,distance_m\na.png,five,1\n", "line 2: 'pitch_mm' must be a number"),
        ("image,pitch_mm,distance_m\na.png,-5,1\n", "must be positive"),
        ("image,distance_m\na.png,1\n", "no 'pitch_mm'"),
        ("image,pitch_mm,distance_m\na.png,5,1\nsub/a.png,5,1\n", "pane id 'a' appears twice"),
        ("id,image,pitch_mm,distance_m\nbad id,a.png,5,1\n", "pane id 'bad id'"),
        ("pitch_mm,distance_m\n5,1\n", "no 'image' column"),
        ("image,pitch_mm,distance_m\n", "lists no pane"),
        ("id,image,reference,pitch_mm,distance_m\np1,a.png,,5,1\np2,a.png,no_ref.png,5,1\n",
         "line 3 (pane 'p2'): reference file"),
        ("id,image,mask,pitch_mm,distance_m\np1,a.png,no_mask.npy,5,1\n", "line 2 (pane 'p1'): mask file"),
    ],
)
def test_bad_manifests(tmp_path, text, words):
    m = tmp_path / "manifest.csv"
    m.write_text(text)
    with pytest.raises(InputError) as info:
        read_manifest(m)
    assert words in str(info.value) and "\n" not in str(info.value)
    if "file" in words:  # the missing file is named
        assert ("no_ref.png" if "reference" in words else "no_mask.npy") in str(info.value)
        assert "does not exist" in str(info.value)


def test_folder_source_skips_the_reference(tmp_path):
    for name in ("reference.png", "b.bmp", "a.png", "notes.txt"):
        (tmp_path / name).write_bytes(b"")
    panes = panes_from_folder(tmp_path, pane_defaults(pitch_mm=5.0, distance_m=1.0,
                                                      reference=tmp_path / "reference.png"))
    assert [p.id for p in panes] == ["a", "b"]
    with pytest.raises(InputError, match="no 'distance_m'"):
        panes_from_folder(tmp_path, pane_defaults(pitch_mm=5.0))


def test_two_batches_cannot_share_a_folder(tmp_path):
    fcntl = pytest.importorskip("fcntl")
    out = tmp_path / "out"
    _run(_panes(tmp_path, ["a"]), out, FakeRunner())
    with open(out / ".glassdist-batch", "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(InputError, match="another 'glassdist batch'"):
            _run(_panes(tmp_path, ["a", "b"]), out, FakeRunner())
    runner = FakeRunner()
    _run(_panes(tmp_path, ["a", "b"]), out, runner)
    assert runner.calls == ["b"]


def _index_out(tmp_path):
    out = tmp_path / "out"
    panes = _panes(tmp_path, ("factory_waves", "factory_ring", "insitu_waves_of_the_north_facade", "insitu_ring"))
    runner = FakeRunner(verdicts={"factory_waves": "FAIL", "factory_ring": "PASS"}, errors={"insitu_ring"})
    _run(panes, out, runner)
    return out


def test_index_columns_are_grouped_and_thumbnails_scale(tmp_path):
    html = (_index_out(tmp_path) / "index.html").read_text()
    # real result.npz files: thumbnails on one shared colour scale; a report link where a report was written
    assert html.count('<img class="thumb shared"') == 3 and 'width="' not in html  # sized by the style sheet
    assert _index(tmp_path / "out")["factory_waves"]["report"] == "panes/factory_waves/report.html"
    assert (tmp_path / "out" / "thumbs" / "factory_waves.png").is_file()
    assert '<th colspan="3">|phi_eff| (mD)</th>' in html and '<th colspan="3">|phi_shear| (mD)</th>' in html
    assert "img.thumb{display:block;width:96px;max-width:100%" in html


def test_index_fits_a_1200_px_window(tmp_path):
    import shutil
    import subprocess
    import tempfile

    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        pytest.skip("the layout check needs chromium on PATH (e.g. apt-get install chromium)")
    out = _index_out(tmp_path)
    probe = out / "probe.html"  # the index, reporting its scroll width into the DOM
    probe.write_text((out / "index.html").read_text().replace(
        "</body>", "<script>document.body.dataset.width = document.documentElement.scrollWidth + 'x'"
                   " + document.documentElement.clientWidth</script></body>"))
    with tempfile.TemporaryDirectory() as profile:
        r = subprocess.run(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}", "--window-size=1200,900",
             "--dump-dom", probe.as_uri()],
            check=True, capture_output=True, text=True, timeout=120,
        )
    import re

    scroll, client = map(int, re.search(r'data-width="(\d+)x(\d+)"', r.stdout).groups())
    assert client > 1000 and scroll <= client, (scroll, client)  # no horizontal scroll bar


def test_thumbnails_share_one_colour_scale_and_trend_groups_lots(tmp_path):
    import matplotlib.image
    import numpy as np

    from glassdist.jobs.index_figures import write_thumbnails, write_trend

    for pid, value in (("a", 10.0), ("b", 20.0)):
        d = tmp_path / "panes" / pid
        d.mkdir(parents=True)
        field = np.full((40, 60), value)
        valid = np.ones((40, 60), bool)
        valid[:5] = False
        np.savez(d / "result.npz", phi_eff_mD=field, valid=valid)
    thumbs, vmax = write_thumbnails(tmp_path, ["a", "b", "missing"])
    assert set(thumbs) == {"a", "b"} and vmax == pytest.approx(20.0)
    a, b = (matplotlib.image.imread(tmp_path / thumbs[k]) for k in ("a", "b"))
    assert a.shape[:2] == (40, 60)  # no axes, no margin: the field's own pixels
    # one scale: 10 mD is half-way to the top colour, 20 mD is the top colour; grey where not analysed
    assert not np.allclose(a[20, 30], b[20, 30]) and np.allclose(a[0, 0], b[0, 0])
    # the scale comes from trusted samples only: a biased guard band (label 6) does not stretch it,
    # in the pixel layout as in the compact one (quality on the pixel grid, fields on the analysis grid)
    d = tmp_path / "panes" / "c"
    d.mkdir(parents=True)
    field = np.full((40, 60), 15.0)
    field[:, :3] = 900.0
    quality = np.zeros((40, 60), np.uint8)
    quality[:, :3] = 6
    np.savez(d / "result.npz", phi_eff_mD=field, valid=np.ones((40, 60), bool), quality=quality)
    d = tmp_path / "panes" / "g"
    d.mkdir(parents=True)
    qpix = np.zeros((80, 120), np.uint8)
    qpix[:, :6] = 6
    np.savez(d / "result.npz", phi_eff_mD=field, grid_valid=np.ones((40, 60), bool), quality=qpix,
             grid_rows_px=np.arange(40) * 2.0 + 0.5, grid_cols_px=np.arange(60) * 2.0 + 0.5)
    for pane in ("c", "g"):
        assert write_thumbnails(tmp_path, [pane])[1] == pytest.approx(15.0), pane
    assert write_thumbnails(tmp_path, ["a", "b", "c"])[1] == pytest.approx(20.0)
    rows = [{"id": i, "lot": lot, "status": "done", "verdict": v, "phi_eff_p95_abs_mD": "5",
             "phi_shear_p95_abs_mD": "4"} for i, lot, v in (("a", "L1", "PASS"), ("b", "L2", "FAIL"))]
    assert write_trend(tmp_path, rows) == "trend.png" and (tmp_path / "trend.png").stat().st_size > 0
    assert write_trend(tmp_path, [dict(rows[0], status="pending")]) is None
