"""Child ``glassdist`` processes and the job folders they write into: shared by batch, sweep and the web app.

* :func:`run_glassdist` runs ``glassdist ARGS`` in a child process of its own (this
  interpreter, this glassdist) and returns a :class:`PaneOutcome`; :func:`run_request`
  sends a typed request (:mod:`glassdist.jobs.request`) the same way. On Linux the child
  is forked from a server that has imported the stack once (:mod:`glassdist._childserver`:
  2.2-2.5 s of every fresh start saved); elsewhere, or with ``GLASSDIST_CHILD=process``,
  it is ``python -m glassdist ARGS``;
* :func:`prepare_job_folder`, :func:`lock_job_folder`: a job folder marked
  ``.glassdist-COMMAND``, held by one job at a time;
* :func:`place_folder`: a finished temporary folder renamed to its final name.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..storage import EXIT_SPEC_FAIL

__all__ = ["PaneOutcome", "lock_job_folder", "place_folder", "prepare_job_folder", "read_json", "run_request",
           "run_glassdist", "subprocess_runner"]

@dataclass(frozen=True)
class PaneOutcome:
    """What running one pane gave: ``exit_code`` of analyze (0, 3 = spec FAIL, else error), its log."""

    exit_code: int
    log: str = ""
    error: str = ""


def run_request(request, *, cwd=None, timeout_s=None):
    """Run a request of :mod:`glassdist.jobs.request` (``analyze``, ``validate``) in a child process of its own.

    The request goes to the child serialised (JSON), and the child runs it as its command runs
    its options (:func:`glassdist.cli.run_request`); ``cwd``, ``timeout_s`` and the outcome as
    for :func:`run_glassdist`, the log's first line the equivalent command.
    """
    return _run_child(request.options(), cwd, timeout_s, request=request.model_dump_json())


def run_glassdist(args, *, cwd=None, timeout_s=None):
    """Run ``python -m glassdist ARGS`` in a child process (this interpreter, this glassdist).

    Parameters
    ----------
    args : list of str
        Command-line arguments after ``glassdist``.
    cwd : path, optional
        Working folder of the child (default: this process's).
    timeout_s : float, optional
        Stop the child after this many seconds (an error outcome).

    Returns
    -------
    PaneOutcome
        Exit code, the command and its combined output, and the error line (last
        line of stderr) when the exit code is neither 0 nor 3 (spec FAIL).
    """
    return _run_child([str(a) for a in args], cwd, timeout_s)


def _run_child(args, cwd, timeout_s, request=None):
    """``glassdist ARGS``, or the serialised ``request`` (a JSON text) read from its stdin, in a child process."""
    env = _child_env()
    cmd = [sys.executable, "-m", "glassdist", *args]
    try:
        ran = _SERVER.run(args, env, cwd, timeout_s, request)
        if ran is None:  # no server here: a fresh interpreter
            fresh = cmd if request is None else [sys.executable, "-m", "glassdist._childserver", "--request"]
            proc = subprocess.run(fresh, capture_output=True, text=True, env=env, cwd=cwd, timeout=timeout_s,
                                  input=request)
            ran = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired:
        return PaneOutcome(1, f"$ {' '.join(cmd)}\n(stopped after {timeout_s:g} s)",
                           f"glassdist: error: the analysis took longer than {timeout_s:g} s and was stopped")
    code, out, err = ran
    if code < 0:  # killed by a signal: no line of its own says so
        err += f"glassdist: error: {_killed(-code)}\n"
    log = f"$ {' '.join(cmd)}\n{out}{err}"
    error = ""
    if code not in (0, EXIT_SPEC_FAIL):
        lines = [ln for ln in err.splitlines() if ln.strip()]
        error = lines[-1] if lines else f"glassdist exited with status {code}"
    return PaneOutcome(code, log, error)


def _killed(signum):
    """What to say of a child that signal ``signum`` killed."""
    import signal

    try:
        name = signal.Signals(signum).name
    except ValueError:
        name = f"signal {signum}"
    why = " (the system's out-of-memory killer sends it)" if name == "SIGKILL" else ""
    return f"the child process was killed by {name}{why} before it finished"


def _child_env():
    """This process's environment, with the folder this glassdist is imported from first on PYTHONPATH."""
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


_FORK_SAFE = sys.platform.startswith("linux")


class _ChildServer:
    """This process's :mod:`~glassdist._childserver`, started on first use; one request at a time.

    :meth:`run` returns ``(exit code, stdout, stderr)`` of a forked child, or None where no
    server can serve it (not Linux, ``GLASSDIST_CHILD=process``, another thread's request in
    flight, a server that failed): the caller then starts a fresh interpreter. Linux only: on
    macOS, system libraries that numpy and matplotlib load (Accelerate, CoreFoundation) are not
    safe to fork once loaded, which is why Python itself stopped forking there by default
    (3.8); Windows has no fork.
    """

    def __init__(self):
        import threading

        self._lock = threading.Lock()
        self._proc = None
        self._owner = None  # the pid that started it: a forked copy of this process starts its own
        self._failed = False

    def _start(self):
        proc = subprocess.Popen([sys.executable, "-m", "glassdist._childserver"], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=_child_env(), text=True,
                                bufsize=1)
        if json.loads(proc.stdout.readline() or "{}").get("ready") is not True:
            proc.kill()
            proc.wait()
            raise OSError("the child server did not start")
        if self._owner is None:
            import atexit

            atexit.register(self._close_at_exit)
        self._proc, self._owner = proc, os.getpid()

    def _stop(self):
        """Close the server's stdin: it stops its running children, reaps them and ends (else it is killed)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.stdin.close()
            proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        finally:
            proc.stdout.close()

    def _close_at_exit(self):
        """At interpreter exit: the server and its children end before this process does (no orphan)."""
        if self._owner == os.getpid():
            self._stop()

    def run(self, args, env, cwd, timeout_s, run_request=None):
        if not _FORK_SAFE or os.environ.get("GLASSDIST_CHILD") == "process" or self._failed:
            return None
        if not self._lock.acquire(blocking=False):
            return None
        try:
            if self._proc is None or self._owner != os.getpid() or self._proc.poll() is not None:
                self._proc = None
                try:
                    self._start()
                except (OSError, ValueError):
                    self._failed = True
                    return None
            try:
                return self._request(args, env, cwd, timeout_s, run_request)
            except subprocess.TimeoutExpired:  # the child was stopped after a complete exchange: the server serves on
                raise
            except BaseException:  # Ctrl-C may cut the exchange half-way: start afresh next time
                self._stop()
                raise
        finally:
            self._lock.release()

    def _request(self, args, env, cwd, timeout_s, run_request=None):
        import tempfile
        import time

        with tempfile.TemporaryDirectory(prefix="glassdist-child-") as tmp:
            paths = {k: str(Path(tmp) / k) for k in ("out", "err", "status")}
            request = {"args": args, "env": env, "cwd": None if cwd is None else str(Path(cwd).resolve()), **paths}
            if run_request is not None:
                request["request"] = run_request
            pid = self._ask(request).get("pid")
            if not isinstance(pid, int):
                self._stop()
                return None
            status = Path(paths["status"])

            def wait(seconds):
                """Whether the child ended (its status written, or gone) within ``seconds`` (None: no limit)."""
                deadline = None if seconds is None else time.monotonic() + seconds
                while not (status.exists() or not _alive(pid)):
                    if deadline is not None and time.monotonic() > deadline:
                        return False
                    time.sleep(0.02)
                return True

            try:
                if not wait(timeout_s):
                    _kill(pid)
                    raise subprocess.TimeoutExpired(args, timeout_s)
            except KeyboardInterrupt:  # Ctrl-C reached the child too: let it take back its files, then stop it
                wait(2.0)
                _kill(pid)
                raise
            text = [Path(paths[k]).read_text(encoding="utf-8", errors="replace") if Path(paths[k]).exists() else ""
                    for k in ("out", "err")]
            code = int(status.read_text()) if status.exists() else self._exit_status(pid)
        return code, text[0], text[1]

    def _exit_status(self, pid):
        """The exit status of child ``pid``, which ended without writing it (a signal killed it), from the server."""
        code = self._ask({"wait": pid}).get("exit")
        return code if isinstance(code, int) else -9  # unknown: what the kernel's out-of-memory killer sends

    def _ask(self, message):
        """One exchange with the server: ``message`` as a JSON line, its JSON line back ({} if it broke)."""
        try:
            self._proc.stdin.write(json.dumps(message) + "\n")
            return json.loads(self._proc.stdout.readline() or "{}")
        except (OSError, ValueError):
            return {}


def _alive(pid):
    """Whether process ``pid`` still runs (Linux: a zombie, ended but not yet reaped by the server, counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            return fh.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return False


def _kill(pid):
    """SIGKILL ``pid`` and wait (at most 10 s) until it has ended."""
    import signal
    import time

    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    deadline = time.monotonic() + 10.0
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.01)


_SERVER = _ChildServer()


def _let_go_of_the_parents_server():
    """In a forked copy of this process: point the copied pipe ends of the parent's server at
    /dev/null, so that the server still sees its stdin close when the parent ends (a copy that
    runs a command starts a server of its own). Lock-free on purpose: another thread may have
    held a pipe's buffer at the fork."""
    proc = _SERVER._proc
    if proc is None or proc.stdin is None or proc.stdout is None:
        return
    null = os.open(os.devnull, os.O_RDWR)
    try:
        for fd in (proc.stdin.fileno(), proc.stdout.fileno()):
            os.dup2(null, fd)
    finally:
        os.close(null)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_let_go_of_the_parents_server)


def subprocess_runner(pane, out_dir, *, report=False, export=False, cwd=None):
    """Run ``glassdist analyze`` for ``pane`` in a child process writing into ``out_dir``.

    ``cwd``: the child's working folder (relative paths of the pane are read from it).

    Returns
    -------
    PaneOutcome
        Exit code, combined output, and the error line (last line of stderr) on failure.
    """
    return run_request(pane.request(out_dir, report=report, export=export), cwd=cwd)


def read_json(path):
    """The JSON document at ``path``; None when it is missing or not valid JSON."""
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None


def prepare_job_folder(out, *, command="batch", folders=("panes", "failed")):
    """Create (or accept to resume) a job folder of ``glassdist COMMAND``, marked ``.glassdist-COMMAND``."""
    out = Path(out)
    marker = f".glassdist-{command}"
    if out.exists() and not out.is_dir():
        raise InputError(f"output path '{out}' is an existing file; give --out a folder path (new or existing)")
    if out.is_dir() and any(out.iterdir()) and not (out / marker).exists():
        raise InputError(f"output folder '{out}' is not empty and was not made by 'glassdist {command}'; "
                         "choose a new or empty folder so that no file of yours is replaced")
    try:
        for name in folders:
            (out / name).mkdir(parents=True, exist_ok=True)
        (out / marker).touch()
    except OSError as exc:
        raise InputError(f"cannot create output folder '{out}': {exc.strerror}; choose a writable location") from None
    return out


def lock_job_folder(out, *, command="batch"):
    """Hold an exclusive lock on the job folder (returns the open file), or raise InputError."""
    fh = open(out / f".glassdist-{command}", "a+")  # noqa: SIM115 - kept open for the batch's duration
    try:
        import fcntl

        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except ImportError:  # no advisory locks on this platform
        pass
    except OSError:
        fh.close()
        raise InputError(f"another 'glassdist {command}' is writing to '{out}'; wait for it or choose another --out")
    return fh


def place_folder(tmp, final):
    """Rename a complete temporary folder to its final name, replacing a stale result of other settings."""
    if final.exists():  # swap it out, then delete it
        old = final.parent / f".tmp-old-{final.name}-{os.getpid()}"
        os.rename(final, old)
        os.rename(tmp, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(tmp, final)
