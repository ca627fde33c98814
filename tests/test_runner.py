"""Child glassdist processes (jobs.runner): forked from the child server, each behaves as ``python -m glassdist``."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import child_env, write_lens_pair
from glassdist.jobs import runner
from glassdist.jobs.runner import run_glassdist

pytestmark = pytest.mark.skipif(not runner._FORK_SAFE, reason="children fork from the server on Linux only")


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    root = tmp_path_factory.mktemp("pair")
    write_lens_pair(root)
    (root / "strict.json").write_text('{"name": "strict", "criteria": [{"channel": "phi_eff", '
                                      '"statistic": "max_abs", "max_mD": 1}]}')
    return root


def _forked_then_process(monkeypatch, make_args, **kw):
    """``run_glassdist(make_args(name))`` forked from the server (name "f"), then as ``python -m glassdist`` ("p")."""
    forked = run_glassdist(make_args("f"), **kw)
    assert runner._SERVER._proc is not None  # it went through the server
    monkeypatch.setenv("GLASSDIST_CHILD", "process")
    assert runner._SERVER.run(["--version"], dict(os.environ), None, None) is None
    process = run_glassdist(make_args("p"), **kw)
    monkeypatch.delenv("GLASSDIST_CHILD")
    return forked, process


def test_a_forked_child_reads_relative_paths_in_its_folder_and_exits_as_a_process(pair, tmp_path, monkeypatch):
    """Spec FAIL (exit 3) with the same output and the same result file; a refused input (exit 2) with the same line."""
    def analyze(name, *extra):
        return ["analyze", "pane.png", "--reference", "reference.png", "--pitch-mm", "2", "--distance-m", "1",
                "--pattern", "lines", "--spec", "strict.json", "--out", str(tmp_path / name), *extra]

    forked, process = _forked_then_process(monkeypatch, analyze, cwd=pair)
    assert forked.exit_code == process.exit_code == 3 and forked.error == process.error == ""
    assert "VERDICT: FAIL" in forked.log
    # the history line names the run's number in the shared history: the second run is the next one
    body = [re.sub(r"recorded as run \d+", "recorded as run N", o.log.split("\n", 1)[1].replace(str(tmp_path / n), "OUT"))
            for o, n in ((forked, "f"), (process, "p"))]
    assert body[0] == body[1]
    assert (tmp_path / "f" / "result.npz").read_bytes() == (tmp_path / "p" / "result.npz").read_bytes()
    forked, process = _forked_then_process(monkeypatch, lambda n: analyze(n, "--mask", "missing.png"), cwd=pair)
    assert forked.exit_code == process.exit_code == 2
    assert forked.error == process.error and "missing.png" in forked.error


def test_a_forked_child_sees_the_environment_of_the_call_not_of_the_server(pair, tmp_path, monkeypatch):
    """The server started before the variable was set; the child still honours it (a 1 px photo limit)."""
    run_glassdist(["--version"])  # the server is running
    monkeypatch.setenv("GLASSDIST_MAX_MEGAPIXELS", "0.000001")
    forked, process = _forked_then_process(monkeypatch, lambda n: [
        "analyze", str(pair / "pane.png"), "--pitch-mm", "2", "--distance-m", "1", "--out", str(tmp_path / n)])
    assert forked.exit_code == process.exit_code == 2
    assert forked.error.replace(str(tmp_path / "f"), "OUT") == process.error.replace(str(tmp_path / "p"), "OUT")
    assert "megapixel" in forked.error


def test_a_forked_child_past_its_time_is_stopped_and_the_next_one_runs(pair, tmp_path):
    args = ["analyze", str(pair / "pane.png"), "--pitch-mm", "2", "--distance-m", "1", "--out"]
    out = run_glassdist([*args, str(tmp_path / "o")], timeout_s=0.05)
    assert out.exit_code == 1 and "longer than 0.05 s" in out.error
    assert not (tmp_path / "o" / "summary.json").exists()
    assert run_glassdist([*args, str(tmp_path / "next")]).exit_code == 0
    assert (tmp_path / "next" / "summary.json").exists()


SCRIPT = """\
# no `if __name__ == "__main__"` guard: a child must never run this script again
import signal, sys
from pathlib import Path
from glassdist.jobs.batch import Pane, run_batch
signal.signal(signal.SIGINT, signal.default_int_handler)  # a background start may have ignored it
root = Path(sys.argv[1])
panes = [Pane(id=f"p{i}", image=root / "pane.png", reference=root / "reference.png", pitch_mm=2.0, distance_m=1.0)
         for i in range(3)]
try:
    sys.exit(run_batch(panes, root / "batch", progress=False))
except KeyboardInterrupt:
    print("interrupted", file=sys.stderr)
    sys.exit(130)
"""


def _write_large_pair(root):
    """``root/pane.png`` and ``root/reference.png``, 640 x 640 px: seconds a pane to analyse, so that
    a pane is surely still under way a fraction of a second after it started, on any machine."""
    from glassdist.io import write_png16
    from glassdist.synthetic import lens_displacement, synthetic_capture

    cap = synthetic_capture((640, 640), pitch_mm=2.0, mm_per_px=0.25,
                            displacement=lens_displacement(0.05, 1.0, radius_mm=28.0), rng=0)
    write_png16(root / "pane.png", cap.image)
    write_png16(root / "reference.png", cap.reference)


def _start_batch(root, **streams):
    """:data:`SCRIPT` started on the large pair in ``root``, in a process group of its own."""
    _write_large_pair(root)
    (root / "run.py").write_text(SCRIPT)
    env = {**child_env(), "GLASSDIST_DB": str(root / "history.sqlite")}
    return subprocess.Popen([sys.executable, str(root / "run.py"), str(root)], env=env, start_new_session=True,
                            **streams)


def _wait_for_the_second_pane(root, proc, why=lambda: ""):
    """Return once the first pane is written and the second has been under way for half a second."""
    deadline = time.monotonic() + 120
    while not (root / "batch" / "panes" / "p0" / "summary.json").exists():
        assert proc.poll() is None and time.monotonic() < deadline, why()
        time.sleep(0.05)
    time.sleep(0.5)


def test_ctrl_c_stops_a_batch_from_an_unguarded_script_with_its_children(tmp_path):
    """A user's script without a main guard: each pane runs once (no child re-runs the script); Ctrl-C
    during the second pane exits 130 with the first pane kept, and leaves no process behind."""
    proc = _start_batch(tmp_path, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _wait_for_the_second_pane(tmp_path, proc, proc.communicate)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert sorted(p.name for p in (tmp_path / "batch" / "panes").iterdir() if not p.name.startswith(".")) == ["p0"]
    with pytest.raises(ProcessLookupError):  # the server and the child were reaped before the script ended
        os.killpg(proc.pid, 0)


def test_the_server_ends_before_the_process_that_started_it(tmp_path):
    """A script that ran one command and ended: its server (and the child) were reaped before it
    ended, so nothing of its group is left, not even a zombie for a reaper a container may lack."""
    script = ("import sys\nfrom glassdist.jobs.runner import _SERVER, run_glassdist\n"
              "assert run_glassdist(['--version']).exit_code == 0 and _SERVER._proc is not None\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True, env=child_env(),
                            start_new_session=True)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 0, err
    with pytest.raises(ProcessLookupError):
        os.killpg(proc.pid, 0)


def test_a_forked_copy_does_not_keep_the_parents_server(tmp_path):
    """The script forks a copy that lives on (as a pool worker would) and ends: its server still
    sees its stdin close and ends at once, instead of after the 10 s the script waits before it
    kills it."""
    script = ("import os, sys, time\nfrom glassdist.jobs.runner import _SERVER, run_glassdist\n"
              "run_glassdist(['--version'])\n"
              "if os.fork() == 0:\n    time.sleep(60)\n    os._exit(0)\n"
              "print(_SERVER._proc.pid, flush=True)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, env=child_env(),
                            start_new_session=True)
    try:
        server = int(proc.stdout.readline())
        started = time.monotonic()
        proc.wait(timeout=60)
        assert time.monotonic() - started < 8  # well under the 10 s wait, whatever the machine's load
        assert proc.returncode == 0 and server not in _running(group=proc.pid)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the copy


def _running(*, group=None, parent=None):
    """Pids of the running (not zombie) processes of process group ``group``, or children of
    process ``parent``, from /proc."""
    field, wanted = (2, group) if group is not None else (1, parent)  # fields after the name: state, ppid, pgrp
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_bytes().rsplit(b")", 1)[1].split()
            if fields[0] != b"Z" and int(fields[field]) == wanted:
                found.append(int(stat.parent.name))
        except (OSError, ValueError, IndexError):
            continue
    return found


def test_a_batch_killed_outright_leaves_no_child_running(tmp_path):
    """SIGKILL, which no handler sees: the server sees its stdin close and stops the pane under way
    before it ends; no process of the batch runs on, and the second pane never completes."""
    proc = _start_batch(tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_for_the_second_pane(tmp_path, proc)
        proc.kill()  # the script alone, not its group
        proc.wait()
        deadline = time.monotonic() + 20
        while _running(group=proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _running(group=proc.pid) == []
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    written = sorted(p.relative_to(tmp_path / "batch") for p in (tmp_path / "batch").rglob("summary.json"))
    assert written == [Path("panes/p0/summary.json")]


@pytest.mark.parametrize("debug", [False, True])
def test_a_forked_child_reports_an_internal_error_as_a_process_does(pair, tmp_path, monkeypatch, debug):
    """Exit 1: one line without ``--debug``; with it, the traceback the interpreter would print
    (``main`` lets the exception through and the child prints it). The fault is planted in this
    process, which then forks the child body itself, as the server does."""
    import glassdist.analyzer as analyzer
    from glassdist import _childserver

    def fault(*args, **kwargs):
        raise RuntimeError("planted fault")

    monkeypatch.setattr(analyzer, "analyze", fault)
    paths = {k: str(tmp_path / k) for k in ("out", "err", "status")}
    args = (["--debug"] if debug else []) + ["analyze", str(pair / "pane.png"), "--pitch-mm", "2",
                                             "--distance-m", "1", "--out", str(tmp_path / "o")]
    pid = os.fork()
    if pid == 0:
        _childserver._child({"args": args, "env": dict(os.environ), "cwd": None, **paths})
    _, status = os.waitpid(pid, 0)
    err = Path(paths["err"]).read_text()
    assert os.waitstatus_to_exitcode(status) == 1 and Path(paths["status"]).read_text() == "1", err
    if debug:
        assert "Traceback (most recent call last)" in err and "RuntimeError: planted fault" in err
    else:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "internal error" in lines[0] and "planted fault" in lines[0], err


@pytest.mark.parametrize("how", ["forked", "process"])
def test_a_child_killed_from_outside_says_which_signal(tmp_path, monkeypatch, how):
    """SIGTERM sent to the running child: exit -15 and a line naming it, forked as from ``python -m glassdist``."""
    import threading

    _write_large_pair(tmp_path)
    if how == "process":
        monkeypatch.setenv("GLASSDIST_CHILD", "process")
        parent = os.getpid()
    else:
        run_glassdist(["--version"])  # the server is running
        parent = runner._SERVER._proc.pid
    before = set(_running(parent=parent))
    outcome = []
    worker = threading.Thread(target=lambda: outcome.append(run_glassdist(
        ["analyze", str(tmp_path / "pane.png"), "--pitch-mm", "2", "--distance-m", "1", "--out", str(tmp_path / "o")])))
    worker.start()
    deadline = time.monotonic() + 60
    while not (set(_running(parent=parent)) - before) and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(0.3)  # under way
    for pid in set(_running(parent=parent)) - before:
        os.kill(pid, signal.SIGTERM)
    worker.join(120)
    (out,) = outcome
    assert out.exit_code == -15, out.log
    assert out.error == "glassdist: error: the child process was killed by SIGTERM before it finished"


def test_a_typed_request_runs_as_its_command_line_forked_or_in_a_fresh_process(pair, tmp_path, monkeypatch):
    """run_request: the request (JSON) runs as its options do, forked or as ``python -m glassdist._childserver
    --request``: spec FAIL (exit 3) recorded with the request's context; a refused value (exit 2), one line."""
    from glassdist.history import HistoryFilter, open_store, query_runs
    from glassdist.jobs.request import AnalyzeRequest, RecordAs

    db = tmp_path / "history.sqlite"

    def request(name, **kw):
        return AnalyzeRequest(images=("pane.png",), reference="reference.png", pitch_mm=2.0, distance_m=1.0,
                              pattern="lines", spec="strict.json", out=tmp_path / name, db=str(db),
                              record_as=RecordAs(source="web", job=f"job-{name}"), **kw)

    forked = runner.run_request(request("f"), cwd=pair)
    monkeypatch.setenv("GLASSDIST_CHILD", "process")
    process = runner.run_request(request("p"), cwd=pair)
    bad = runner.run_request(request("b", sigma_mm=-1.0), cwd=pair)
    monkeypatch.delenv("GLASSDIST_CHILD")
    bad_forked = runner.run_request(request("c", sigma_mm=-1.0), cwd=pair)
    assert forked.exit_code == process.exit_code == 3 and "VERDICT: FAIL" in forked.log
    assert forked.log.startswith(f"$ {sys.executable} -m glassdist analyze --pitch-mm=2.0 --distance-m=1.0 ")
    assert (tmp_path / "f" / "result.npz").read_bytes() == (tmp_path / "p" / "result.npz").read_bytes()
    with open_store(str(db)) as store:
        runs = query_runs(store, HistoryFilter())
    assert sorted((r["source"], r["job"]) for r in runs) == [("web", "job-f"), ("web", "job-p")]
    assert bad.exit_code == bad_forked.exit_code == 2 and bad.error == bad_forked.error
    assert "--sigma-mm" in bad.error and "must be positive" in bad.error
