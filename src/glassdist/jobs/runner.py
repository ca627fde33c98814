"""Child ``glassdist`` processes and the job folders they write into: shared by batch, sweep and the web app.

* :func:`run_glassdist` runs ``python -m glassdist ARGS`` (this interpreter, this
  glassdist) and returns a :class:`PaneOutcome`;
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

__all__ = ["PaneOutcome", "lock_job_folder", "place_folder", "prepare_job_folder", "read_json", "run_glassdist",
           "subprocess_runner"]

@dataclass(frozen=True)
class PaneOutcome:
    """What running one pane gave: ``exit_code`` of analyze (0, 3 = spec FAIL, else error), its log."""

    exit_code: int
    log: str = ""
    error: str = ""


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
    import glassdist

    env = dict(os.environ)
    src = str(Path(glassdist.__file__).resolve().parent.parent)
    env["PYTHONPATH"] = src + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    cmd = [sys.executable, "-m", "glassdist", *args]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return PaneOutcome(1, f"$ {' '.join(cmd)}\n(stopped after {timeout_s:g} s)",
                           f"glassdist: error: the analysis took longer than {timeout_s:g} s and was stopped")
    log = f"$ {' '.join(cmd)}\n{proc.stdout}{proc.stderr}"
    error = ""
    if proc.returncode not in (0, EXIT_SPEC_FAIL):
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        error = lines[-1] if lines else f"glassdist exited with status {proc.returncode}"
    return PaneOutcome(proc.returncode, log, error)


def subprocess_runner(pane, out_dir, *, report=False, export=False, cwd=None):
    """Run ``glassdist analyze`` for ``pane`` in a child process writing into ``out_dir``.

    ``cwd``: the child's working folder (relative paths of the pane are read from it).

    Returns
    -------
    PaneOutcome
        Exit code, combined output, and the error line (last line of stderr) on failure.
    """
    return run_glassdist(pane.analyze_args(out_dir, report=report, export=export), cwd=cwd)


def read_json(path):
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
