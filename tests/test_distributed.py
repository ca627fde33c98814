"""Batches and sweeps on a local Dask cluster (2 worker processes) give the serial run's outputs."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import child_env

distributed = pytest.importorskip("distributed", reason="the distributed tests need glassdist[distributed]")

from glassdist.distributed import open_executor  # noqa: E402
from glassdist.errors import InputError  # noqa: E402
from glassdist.jobs.batch import Pane, run_batch  # noqa: E402

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"


def glassdist(*args, cwd=None, env=None):
    return subprocess.run([sys.executable, "-m", "glassdist", *map(str, args)], capture_output=True, text=True,
                          env={**child_env(), **(env or {})}, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def executor():
    """One local cluster for the module: 2 single-threaded worker processes (starting one costs seconds)."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import the test module
    with open_executor(workers=2) as ex:
        yield ex


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    """Small synthetic panes (lenses of three strengths) with their reference, and two specifications."""
    from glassdist.io import write_png16
    from glassdist.synthetic import lens_displacement, synthetic_capture

    root = tmp_path_factory.mktemp("photos")
    for i, power in enumerate((0.02, 0.05, 0.08)):
        cap = synthetic_capture((160, 160), pitch_mm=2.0, mm_per_px=0.25,
                                displacement=lens_displacement(power, 1.0, radius_mm=7.0), rng=i)
        write_png16(root / f"pane{i}.png", cap.image)
    write_png16(root / "reference.png", cap.reference)
    spec = {"name": "strict", "criteria": [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 5}]}
    (root / "strict.json").write_text(json.dumps(spec))
    (root / "manifest.csv").write_text(
        "id,image,reference,spec,pitch_mm,distance_m\n"
        "a,pane0.png,reference.png,,2,1\n"
        "c,pane2.png,,strict.json,2,1\n"
        "missing,no_such_photo.png,,,2,1\n"
    )
    return root


def _tree(out):
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())


def _without_timing(text, columns=("seconds", "finished_utc", "timings")):
    """A pane's or variant's JSON record, or an index CSV, less the wall-clock fields."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        rows = list(csv.DictReader(text.splitlines()))
        return [{k: v for k, v in r.items() if k not in columns} for r in rows]
    if "variants" in data:  # a sweep's index.json
        data["variants"] = [{k: v for k, v in r.items() if k not in columns} for r in data["variants"]]
    data = {k: v for k, v in data.items() if k not in columns}
    if isinstance(data.get("history"), str):  # the run's number in the shared history: the order the panes finished
        data["history"] = re.sub(r"recorded as run \d+", "recorded as run N", data["history"])
    return data


def _assert_same_outputs(serial, dask):
    """Every file the same bytes, except logs (they name the temporary folder) and the timings."""
    assert _tree(serial) == _tree(dask)
    for rel in _tree(serial):
        a, b = (serial / rel).read_bytes(), (dask / rel).read_bytes()
        if rel.endswith(".log") or rel.endswith("index.html"):
            continue  # the command line names the temporary folder; the HTML index has the time of writing
        if rel.endswith(("pane.json", "variant.json", "validation.json", "index.csv", "index.json")) or rel.startswith("failed"):
            assert _without_timing(a.decode()) == _without_timing(b.decode()), rel
        else:
            assert a == b, rel


def test_batch_on_dask_matches_the_serial_run(photos, tmp_path, executor):
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    r1 = glassdist("batch", photos / "manifest.csv", "--out", serial, "--no-progress")
    address = executor.client.scheduler.address
    r2 = glassdist("batch", photos / "manifest.csv", "--out", dask, "--no-progress", "--scheduler", address)
    assert r1.returncode == r2.returncode == 4, r1.stderr + r2.stderr  # one pane could not be analysed
    assert "analysing 3 pane(s) on the Dask cluster at tcp://" in r2.stdout
    done = [ln.split()[1:3] for ln in r2.stdout.splitlines() if ln.startswith("[")]
    assert sorted(done) == sorted(ln.split()[1:3] for ln in r1.stdout.splitlines() if ln.startswith("["))
    assert r1.stdout.splitlines()[-2] == r2.stdout.splitlines()[-2]  # the batch's closing count
    _assert_same_outputs(serial, dask)
    idx = {r["id"]: r for r in csv.DictReader((dask / "index.csv").open())}
    assert [idx[i]["status"] for i in "ac"] == ["done"] * 2 and idx["c"]["verdict"] == "FAIL"
    assert idx["missing"]["status"] == "error" and "does not exist" in idx["missing"]["error"]
    assert not list((dask / "panes").glob(".tmp*")) and not list(dask.glob("panes/.glassdist-probe*"))


def _quick_runner(pane, out_dir, **kw):
    """Stands in for analyze (the real one is compared above): a summary made from the input's bytes."""
    from glassdist.jobs.runner import PaneOutcome

    digest = sum(Path(pane.image).read_bytes()) % 1000
    summary = {"method": "direct", "measured_percent": 90.0, "a4": {"statistics": {"phi_eff": {"p95_abs": digest}}}}
    (Path(out_dir) / "summary.json").write_text(json.dumps(summary))
    return PaneOutcome(0, "log")


def _killing_runner(pane, out_dir, **kw):
    """The first time it meets pane 'b' it kills its own worker process, mid-pane."""
    marker = Path(out_dir).parent.parent / f"killed-{pane.id}"
    if pane.id == "b" and not marker.exists():
        (Path(out_dir) / "summary.json").write_text("half written")
        marker.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return _quick_runner(pane, out_dir, **kw)


def _panes(photos):
    ref = photos / "reference.png"
    return [Pane(id=i, image=photos / f"pane{n}.png", pitch_mm=2.0, distance_m=1.0, reference=r)
            for i, n, r in (("a", 0, ref), ("b", 1, ref), ("c", 2, None), ("d", 1, None))]


def test_a_killed_worker_loses_no_pane_and_the_batch_resumes(photos, tmp_path, executor):
    out, serial = tmp_path / "out", tmp_path / "serial"
    panes = _panes(photos)
    lines = []
    code = run_batch(panes, out, runner=_killing_runner, progress=False, echo=lines.append, executor=executor)
    assert Path(out / "killed-b").is_file()  # a worker died while it held pane 'b' ...
    assert code == 0, lines  # ... the scheduler ran 'b' again on a live worker
    (out / "killed-b").unlink()
    assert run_batch(panes, serial, runner=_quick_runner, progress=False, echo=lambda s: None) == 0
    _assert_same_outputs(serial, out)
    stamps = {p.id: os.stat(out / "panes" / p.id / "pane.json").st_mtime_ns for p in panes}

    again = []
    assert run_batch(panes, out, runner=_quick_runner, progress=False, echo=again.append, executor=executor) == 0
    assert again[0] == "resuming: 4 pane(s) already done, 0 to analyse"
    assert {p.id: os.stat(out / "panes" / p.id / "pane.json").st_mtime_ns for p in panes} == stamps


def test_interrupted_dask_batch_resumes_with_the_unfinished_panes(photos, tmp_path, executor):
    out = tmp_path / "out"
    panes = _panes(photos)

    def stop_after_first(line):
        if line.startswith("[1/"):
            raise KeyboardInterrupt  # Ctrl-C once the first pane is in place

    with pytest.raises(KeyboardInterrupt):
        run_batch(panes, out, runner=_quick_runner, progress=False, echo=stop_after_first, executor=executor)
    assert len([p for p in (out / "panes").iterdir() if not p.name.startswith(".tmp")]) == 1
    lines = []
    assert run_batch(panes, out, runner=_quick_runner, progress=False, echo=lines.append, executor=executor) == 0
    assert lines[0] == "resuming: 1 pane(s) already done, 3 to analyse"
    assert {r["status"] for r in csv.DictReader((out / "index.csv").open())} == {"done"}
    assert not list((out / "panes").glob(".tmp*"))


def test_workers_that_cannot_see_a_path_are_named(tmp_path, executor):
    with pytest.raises(InputError) as info:
        executor.check_paths(files=[tmp_path / "nowhere.png"])
    msg = str(info.value)
    assert msg.startswith("Dask worker tcp://127.0.0.1:") and "cannot see the input" in msg and "\n" not in msg
    executor.check_paths(files=[Path(__file__)], folders=[tmp_path], cwd=tmp_path)  # all visible: no error
    assert not list(tmp_path.iterdir())  # the probes are removed


def test_unreachable_scheduler_is_a_one_line_error(photos, tmp_path):
    r = glassdist("batch", photos / "manifest.csv", "--out", tmp_path / "o", "--scheduler", "tcp://127.0.0.1:9",
                  "--no-progress", env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "1s"})
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in r.stderr
    r = glassdist("batch", photos / "manifest.csv", "--out", tmp_path / "o", "--workers", "0")
    assert r.returncode == 2 and "--workers: must be at least 1" in r.stderr


def test_without_dask_the_options_say_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(InputError, match=r"need Dask; install the extra with: pip install 'glassdist\[distributed\]'"):
        with open_executor(workers=2):
            pass
    with open_executor() as ex:  # the default runs here and needs nothing
        assert not ex.distributed and ex.map(abs, [-1, 2]) == [1, 2]


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory):
    """The wavy slab at 256 x 192 px, 1 sample per pixel (a render costs about a second)."""
    import yaml

    data = yaml.safe_load((SCENES / "wavy_slab.yaml").read_text())
    data["camera"]["pixels"] = [256, 192]
    data["render"]["samples_per_pixel"] = 1
    path = tmp_path_factory.mktemp("scene") / "small.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_sweep_on_dask_matches_the_serial_sweep(small_scene, tmp_path, executor):
    from glassdist.virtual import parse_vary, run_sweep

    vary = parse_vary(["backdrop.pitch_mm=24.2,36.3", "analysis.sigma_mm=60"])
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    assert run_sweep(small_scene, vary, serial, progress=False, echo=lambda s: None) == 0
    lines = []
    assert run_sweep(small_scene, vary, dask, progress=False, echo=lines.append, executor=executor) == 0
    _assert_same_outputs(serial, dask)
    rows = list(csv.DictReader((dask / "index.csv").open()))
    assert [(r["id"], r["backdrop.pitch_mm"], r["analysis.sigma_mm"]) for r in rows] == [
        ("v000", "24.2", "60"), ("v001", "36.3", "60")]
    for r in rows:  # the rendered slab agrees with the analytical model
        assert r["status"] == "done" and abs(float(r["ratio_phi_eff"]) - 1) < 0.05, r
    scene = json.loads((dask / "scenes" / "v001.json").read_text())
    assert scene["backdrop"]["pitch_mm"] == 36.3 and scene["analysis"]["sigma_mm"] == 60
    assert json.loads((dask / "index.json").read_text())["variants"][1]["id"] == "v001"
    again = []
    assert run_sweep(small_scene, vary, dask, progress=False, echo=again.append, executor=executor) == 0
    assert again[0] == "resuming: 2 variant(s) already done, 0 to run"


@pytest.mark.parametrize("vary, words", [
    (["camera.distance_m=1,2"], "camera has no 'distance_m'"),
    (["backdrop.pitch_mm"], "must read KEY=V1,V2"),
    (["backdrop.pitch_mm=-1,5"], "invalid scene in variant backdrop.pitch_mm=-1"),
    (["analysis.no_such_param=1"], "variant analysis.no_such_param=1"),
    (["camera.position_mm.7=1"], "not an index of a 3-element list"),
])
def test_bad_sweeps_are_one_line_errors(small_scene, tmp_path, capsys, vary, words):
    from glassdist.cli import main

    code = main(["sweep", str(small_scene), *[a for v in vary for a in ("--vary", v)], "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "o").exists()  # nothing runs, nothing is written


def test_experiment_scenes_render_on_the_workers(small_scene, executor):
    from glassdist.experiments import RunOptions
    from glassdist.scene import load_scene

    scene = load_scene(small_scene)
    scenes = [scene, scene.with_changes(backdrop={"pitch_mm": 36.3})]
    remote = dict(RunOptions(executor=executor).render_each(scenes, reference=False))
    here = dict(RunOptions().render_each(scenes, reference=False))
    assert sorted(remote) == sorted(here) == [0, 1]
    for i in here:
        a, b = remote[i], here[i]
        assert a.scene == b.scene and (a.distorted == b.distorted).all()
        assert (a.truth.displacement_mm == b.truth.displacement_mm).all()
