"""The command-line contract: outputs, and one-line errors for bad input."""

import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import EXAMPLES, run_cli
from glassdist.io import write_png16
from glassdist.synthetic import synthetic_capture, wave_displacement

_cli = run_cli  # in this process; _child where a process of its own is the point


def _child(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "glassdist", *map(str, args)], capture_output=True, text=True, cwd=cwd)


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    d = tmp_path_factory.mktemp("photos")
    cap = synthetic_capture((240, 300), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.5, 120.0, 20.0))
    write_png16(d / "img.png", cap.image)
    write_png16(d / "ref.png", cap.reference)
    write_png16(d / "small_ref.png", cap.reference[:200, :200])
    write_png16(d / "blank.png", np.full((200, 200), 0.5))
    write_png16(d / "white.png", np.ones((200, 200)))
    write_png16(d / "noise.png", np.random.default_rng(0).random((200, 200)))
    write_png16(d / "tiny.png", cap.image[:40, :40])
    (d / "bad_params.json").write_text(json.dumps({"detrend_degre": 3}))
    (d / "not_json.json").write_text("{detrend_degree: 3")
    return d


def test_analyze_writes_the_contract(photos, tmp_path):
    out = tmp_path / "out"
    r = _cli("analyze", photos / "img.png", "--reference", photos / "ref.png", "--pitch-mm", 8, "--distance-m", 10,
             "--sigma-mm", 16, "--out", out, "--fields", "pixel")
    assert r.returncode == 0, r.stderr
    with np.load(out / "result.npz") as z:  # the documented pixel-grid file
        assert z["displacement_mm"].shape == (240, 300, 2) and z["displacement_detrended_mm"].shape == (240, 300, 2)
        for k in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD", "axis_deg", "valid"):
            assert z[k].shape == (240, 300)
        assert z["valid"].dtype == bool
        for k in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD", "axis_deg"):
            assert np.all(np.isnan(z[k][~z["valid"]])) and np.all(np.isfinite(z[k][z["valid"]]))
        pixel = {k: z[k] for k in z.files}
    # the default, compact layout: the same fields, brought to the pixel grid by load_result
    from glassdist import load_result

    r = _cli("analyze", photos / "img.png", "--reference", photos / "ref.png", "--pitch-mm", 8, "--distance-m", 10,
             "--sigma-mm", 16, "--out", tmp_path / "compact")
    assert r.returncode == 0, r.stderr
    stored = load_result(tmp_path / "compact")
    assert stored.layout == "analysis" and stored.fields["phi_eff_mD"].shape[0] < 240
    assert (tmp_path / "compact" / "result.npz").stat().st_size < (out / "result.npz").stat().st_size / 4
    back = stored.to_pixel_grid()
    for k in ("displacement_mm", "displacement_detrended_mm", "phi_eff_mD", "phi_shear_mD", "phi_total_mD",
              "axis_deg", "valid"):
        np.testing.assert_array_equal(back[k], pixel[k], err_msg=k)
    s = json.loads((out / "summary.json").read_text())
    assert s["method"] == "comparative"
    assert s["parameters"]["sigma_mm"] == 16.0 and s["glassdist_version"]
    for ch in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD"):
        assert set(s["statistics"][ch]) >= {"mean_abs", "std", "p95_abs", "max_abs"}
    assert (out / "phi_eff.png").exists() and (out / "phi_shear.png").exists()
    # Direct method, same options otherwise
    r = _cli("analyze", photos / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--out", tmp_path / "direct")
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "direct" / "summary.json").read_text())
    assert s["method"] == "direct" and len(s["homography"]["matrix"]) == 3


def test_module_and_console_script_agree(photos):
    r = _child("--version")
    assert r.returncode == 0 and "glassdist" in r.stdout


BAD = [
    (["analyze", "missing.png", "--pitch-mm", 8, "--distance-m", 10], "does not exist"),
    (["analyze", "{d}/img.png", "--pitch-mm", 0, "--distance-m", 10], "must be positive"),
    (["analyze", "{d}/img.png", "--pitch-mm", 8, "--distance-m", -2], "must be positive"),
    (["analyze", "{d}/blank.png", "--pitch-mm", 8, "--distance-m", 10], "blank"),
    (["analyze", "{d}/white.png", "--pitch-mm", 8, "--distance-m", 10], "blank|saturated"),
    (["analyze", "{d}/noise.png", "--pitch-mm", 8, "--distance-m", 10], "no grid"),
    (["analyze", "{d}/tiny.png", "--pitch-mm", 8, "--distance-m", 10], "too small|at least"),
    (["analyze", "{d}/img.png", "--reference", "{d}/small_ref.png", "--pitch-mm", 8, "--distance-m", 10], "same"),
    (["analyze", "{d}/img.png", "--params", "{d}/bad_params.json", "--pitch-mm", 8, "--distance-m", 10],
     "unknown key 'detrend_degre'"),
    (["analyze", "{d}/img.png", "--params", "{d}/not_json.json", "--pitch-mm", 8, "--distance-m", 10], "not valid JSON"),
    (["analyze", "{d}/img.png", "--mask", "{d}/tiny.png", "--pitch-mm", 8, "--distance-m", 10], "same size"),
]


@pytest.mark.parametrize("args,message", BAD)
def test_bad_input_gives_one_line_error(photos, tmp_path, args, message):
    import re

    out = tmp_path / "out"
    r = _cli(*[a.format(d=photos) if isinstance(a, str) else a for a in args], "--out", out)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr  # no usage block either
    assert re.search(message, lines[0]), lines[0]
    assert not out.exists()  # a refused run leaves no folder behind, not even an empty one


def test_refused_run_keeps_an_existing_folder_and_its_files(photos, tmp_path):
    out = tmp_path / "existing"
    out.mkdir()
    (out / "notes.txt").write_text("site notes")
    r = _cli("analyze", photos / "blank.png", "--pitch-mm", 8, "--distance-m", 10, "--out", out / "run")
    assert r.returncode == 2 and not (out / "run").exists()
    r = _cli("analyze", photos / "blank.png", "--pitch-mm", 8, "--distance-m", 10, "--out", out)
    assert r.returncode == 2 and sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "site notes"


def test_output_path_that_is_a_file_is_refused_and_untouched(photos, tmp_path):
    f = tmp_path / "precious.txt"
    f.write_text("keep me")
    r = _cli("analyze", photos / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--out", f)
    assert r.returncode == 2 and "existing file" in r.stderr and "Traceback" not in r.stderr
    assert f.read_text() == "keep me"


def test_bundled_example_runs(tmp_path):
    r = _cli("analyze", EXAMPLES / "factory_pane_clean.png", "--reference", EXAMPLES / "factory_reference.png",
             "--pattern", "checkerboard", "--pitch-mm", 10, "--distance-m", 1, "--out", tmp_path / "clean")
    assert r.returncode == 0, r.stderr


# ---------------------------------------------------------------- option errors: one line, exit 2

def _main_error(capsys, argv):
    from glassdist.cli import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and err.endswith("\n"), err  # no usage block
    return lines[0]


OPTION_ERRORS = [
    (["analyze", "img.png", "--pitch-mm", "-5", "--distance-m", "1", "--out", "o"], "analyze",
     "argument --pitch-mm: must be positive, got -5"),
    (["analyze", "img.png", "--pitch-mm", "5", "--distance-m", "0", "--out", "o"], "analyze",
     "argument --distance-m: must be positive, got 0"),
    (["analyze", "img.png", "--pitch-mm", "five", "--distance-m", "1", "--out", "o"], "analyze",
     "argument --pitch-mm: must be a number, got 'five'"),
    (["analyze", "img.png", "--pitch-mm", "5", "--out", "o"], "analyze",
     "the following arguments are required: --distance-m"),
    (["analyze", "img.png", "--pitch-mm", "5", "--distance-m", "1", "--out", "o", "--bogus"], "analyze",
     "unrecognized arguments: --bogus"),
    (["batch", "m.csv"], "batch", "the following arguments are required: --out"),
    (["validate", "s.yaml", "--method", "both", "--out", "o"], "validate", "argument --method: invalid choice: 'both'"),
    (["nosuch"], None, "argument COMMAND: invalid choice: 'nosuch'"),
]


@pytest.mark.parametrize("argv,command,message", OPTION_ERRORS)
def test_option_errors_are_one_line(capsys, argv, command, message):
    prog = "glassdist" if command is None else f"glassdist {command}"
    line = _main_error(capsys, argv)
    assert line.startswith(f"{prog}: error: {message}") and line.endswith(f" (see {prog} --help)"), line


def test_every_command_reports_option_errors_in_one_line(capsys):
    from glassdist.cli import build_parser

    commands = build_parser()._commands.choices
    assert {"analyze", "batch", "render", "predict", "validate", "cycles-setup", "experiment"} <= set(commands)
    for command in commands:
        line = _main_error(capsys, [command, "--no-such-option"])
        assert line.startswith(f"glassdist {command}: error: ") and line.endswith(f"(see glassdist {command} --help)")


def test_option_error_from_the_console(tmp_path):
    r = _child("analyze", "img.png", "--pitch-mm", -5, "--distance-m", 1, "--out", tmp_path / "o")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == ("glassdist analyze: error: argument --pitch-mm: must be positive, got -5 "
                        "(see glassdist analyze --help)\n")
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------- re-running into the same folder

def _files(folder):
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_rerun_removes_only_the_previous_runs_own_leftovers(photos, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    spec = tmp_path / "strict.json"
    spec.write_text(json.dumps({"name": "strict", "criteria": [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 0.001}]}))
    base = ["analyze", photos / "img.png", "--reference", photos / "ref.png", "--pitch-mm", 8, "--distance-m", 10, "--out", out]
    r = _cli(*base, "--spec", spec, "--report", "--export")
    assert r.returncode == 3, r.stderr
    first = _files(out)
    assert {"report.html", "fields.npz", "tiff/valid.tif", "mask_phi_eff_0.001mD.png", "notes.txt"} <= set(first)
    s = json.loads((out / "summary.json").read_text())
    assert sorted(s["outputs"]) == [f for f in first if f not in ("notes.txt", "summary.json")]
    assert s["outputs"]["result.npz"]["size"] == (out / "result.npz").stat().st_size
    assert s["outputs"]["result.npz"]["sha256"] == hashlib.sha256((out / "result.npz").read_bytes()).hexdigest()
    # the user appends to fields.npz after the first run: it is no longer the file glassdist wrote
    with (out / "fields.npz").open("ab") as fh:
        fh.write(b"appended by the user")

    r = _cli(*base)  # no spec, no report, no exports
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["verdict"] is None
    left = _files(out)
    assert not [f for f in left if f == "report.html" or f.startswith(("mask_", "tiff"))]
    assert not (out / "tiff").exists()  # the folder it emptied
    assert "notes.txt" in left and (out / "notes.txt").read_text() == "mine"
    assert "fields.npz" in left  # changed since glassdist wrote it: kept
    assert sorted(s["outputs"]) == [f for f in left if f not in ("notes.txt", "summary.json", "fields.npz")]
    assert "removed from" in r.stdout and "report.html" in r.stdout


def _record(*paths):
    return {"size": sum(p.stat().st_size for p in paths),
            "sha256": hashlib.sha256(b"".join(p.read_bytes() for p in paths)).hexdigest()}


def test_recorded_outputs_never_leave_the_folder(tmp_path):
    from glassdist.storage.folder import recorded_outputs, remove_outputs

    out = tmp_path / "out"
    (out / "sub").mkdir(parents=True)
    outside = tmp_path / "outside.txt"
    for f in (outside, out / "a.png", out / "sub" / "b.png"):
        f.write_text("x")
    (out / "link.png").symlink_to(outside)
    rec = _record(out / "a.png")
    listed = {"../outside.txt": rec, str(outside): rec, "link.png": rec, "sub/../a.png": rec, "a.png": rec,
              "sub/b.png": rec, "missing.png": rec, "summary.json": rec, "sub": rec}
    (out / "summary.json").write_text(json.dumps({"glassdist_version": "0", "outputs": listed}))
    record = recorded_outputs(out)
    assert record == {"a.png": rec, "sub/b.png": rec}
    assert remove_outputs(out, record, list(listed)) == (["a.png", "sub/b.png"], [])
    assert outside.read_text() == "x" and (out / "link.png").is_symlink() and not (out / "sub").exists()
    (out / "summary.json").write_text(json.dumps({"outputs": {"link.png": rec}}))  # not a glassdist summary
    assert recorded_outputs(out) == {}


def test_crafted_summary_never_deletes_an_unrelated_file(tmp_path):
    """Cleanup removes a file only when it still has the SHA-256 its run recorded: sizes alone are not enough."""
    from glassdist.storage.folder import recorded_outputs, remove_outputs

    out = tmp_path / "out"
    out.mkdir()
    precious, old_style = out / "thesis.pdf", out / "notes.txt"
    precious.write_bytes(b"precious bytes")
    old_style.write_text("mine")
    crafted = {"thesis.pdf": {"size": precious.stat().st_size, "sha256": "0" * 64},  # right size, wrong hash
               "notes.txt": old_style.stat().st_size}  # the old size-only form
    (out / "summary.json").write_text(json.dumps({"glassdist_version": "0", "outputs": crafted}))
    record = recorded_outputs(out)
    assert remove_outputs(out, record, ["thesis.pdf", "notes.txt"]) == ([], [])
    assert precious.read_bytes() == b"precious bytes" and old_style.read_text() == "mine"


def test_result_npz_has_the_usual_permissions(photos, tmp_path):
    import os
    import stat

    out = tmp_path / "out"
    r = _cli("analyze", photos / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--out", out)
    assert r.returncode == 0, r.stderr
    umask = os.umask(0)
    os.umask(umask)
    for name in ("result.npz", "summary.json", "statistics.csv", "phi_eff.png"):
        assert stat.S_IMODE((out / name).stat().st_mode) == 0o666 & ~umask, name


# ---------------------------------------------------------------- the output folder: lock, debris, inputs

def test_second_run_into_a_locked_folder_exits_2(photos, tmp_path):
    fcntl = pytest.importorskip("fcntl")
    import os

    out = tmp_path / "out"
    out.mkdir()
    fd = os.open(out, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # as a run in progress holds it
        r = _child("analyze", photos / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--out", out)
    finally:
        os.close(fd)
    assert r.returncode == 2 and "another glassdist run is writing to" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not any(out.iterdir())


def test_debris_of_a_killed_run_is_removed_and_nothing_else(photos, tmp_path):
    import os

    out = tmp_path / "out"
    out.mkdir()
    dead = out / ".result.npz.4194301.0badc0de.tmp"  # a killed run's temporary file (no such process)
    alive = out / f".phi_eff.png.{os.getppid()}.0badc0de.tmp"  # a live process: not provably debris
    other = out / ".notes.txt.4194301.0badc0de.tmp"  # not a name glassdist writes
    for f in (dead, alive, other):
        f.write_bytes(b"x" * 10)
    r = _cli("analyze", photos / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--out", out)
    assert r.returncode == 0, r.stderr
    assert not dead.exists() and alive.exists() and other.exists()
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp") and p not in (alive, other)]


def test_a_run_stopped_half_way_takes_back_its_files_and_the_next_run_goes_through(photos, tmp_path, monkeypatch):
    """An internal error while the figures are drawn: exit 1, the files the run had written are gone
    (the earlier run's untouched ones stay), and the same command then succeeds in that folder."""
    from glassdist.cli import main
    from glassdist.storage import writer

    out = tmp_path / "out"
    args = ["analyze", str(photos / "img.png"), "--pitch-mm", "8", "--distance-m", "10", "--out", str(out)]
    assert main([*args, "--sigma-mm", "30"]) == 0
    earlier = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix == ".png"}

    def broken(*a, **k):
        raise RuntimeError("a figure failed")

    monkeypatch.setattr(writer, "run_figures", broken)
    assert main(args) == 1  # another sigma: a different result.npz and statistics
    assert not (out / "result.npz").exists() and not (out / "statistics.csv").exists()
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.suffix == ".png"} == earlier
    monkeypatch.undo()
    assert main(args) == 0
    assert json.loads((out / "summary.json").read_text())["outputs"].keys() >= {"result.npz", "phi_eff.png"}


@pytest.mark.parametrize("name", ["phi_eff.png", "summary.json"])
def test_an_input_named_like_an_output_is_never_overwritten(photos, tmp_path, name):
    import shutil

    folder = tmp_path / "inputs"
    folder.mkdir()
    if name.endswith(".png"):
        shutil.copy(photos / "img.png", folder / name)
        args = ["analyze", folder / name, "--pitch-mm", 8, "--distance-m", 10]
    else:
        shutil.copy(photos / "img.png", folder / "img.png")
        (folder / name).write_text(json.dumps({"name": "s", "criteria": [
            {"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1000}]}))
        args = ["analyze", folder / "img.png", "--pitch-mm", 8, "--distance-m", 10, "--spec", folder / name]
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    r = _cli(*args, "--out", folder)
    assert r.returncode == 2 and "would be overwritten" in r.stderr and "Traceback" not in r.stderr
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
