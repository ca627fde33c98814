"""A process that has imported glassdist's stack once and forks a child per ``glassdist`` command.

Run as ``python -m glassdist._childserver`` by :mod:`glassdist.jobs.runner`, which
talks to it over its stdin and stdout, one JSON line each way:

* at start, after the imports, it writes ``{"ready": true}``;
* for each request ``{"args": [...], "env": {...}, "cwd": path or null, "out": path,
  "err": path, "status": path}`` it forks a child and writes ``{"pid": N}``. The child takes
  the request's environment and working folder, writes its stdout and stderr to ``out``
  and ``err``, runs ``glassdist ARGS`` (or, given ``"request"``, the serialised request of
  :mod:`glassdist.jobs.request`) and writes its exit status to ``status`` (written
  to a temporary name, then renamed: present means complete);
* for ``{"wait": N}``, asked of a child that ended without writing its status (a signal
  killed it), it reaps child N and writes ``{"exit": code}``, negative for a signal as
  :attr:`subprocess.Popen.returncode` is (null if N is not a child it holds).

A child is a process of its own, as ``python -m glassdist`` would be, without the 2.2-2.5 s
of imports a fresh interpreter pays (``-X importtime``: SQLAlchemy, matplotlib's figure
stack, scipy.fft). The server starts no thread of its own (the BLAS library's workers are
re-made in a child by the library's fork handlers), so forking it is safe; it ignores
Ctrl-C (its children do not) and ends when its stdin closes, i.e. when the process that
started it ends or closes it. It reaps its children itself, so that a child's pid stays
its own until then; when its stdin closes it stops any child still running and reaps it
before it ends: no child outlives the server, and none is left to a reaper that a
container may lack.
"""

from __future__ import annotations

import gc
import json
import os
import signal
import sys

#: Imported once in the server (what a small ``glassdist analyze`` imports). Not OpenCV: its import
#: starts a thread that a forked child would lack, with whatever state that thread held.
PRELOAD = ("glassdist.cli", "glassdist.analyzer.pipeline", "glassdist.storage.writer", "glassdist.report.maps",
           "glassdist.history.models", "glassdist.history.store", "glassdist.acceptance.assess", "glassdist.measures",
           "glassdist.analyzer.captures", "glassdist.analyzer.reflection", "glassdist.report.console",
           "scipy.optimize", "scipy.linalg", "matplotlib.backends.backend_agg")


def _warm() -> None:
    """What every child would otherwise pay again: the command parser's modules, and a first figure's
    fonts and mathtext (about 0.4 s of a small analysis)."""
    import numpy as np

    from glassdist.cli import build_parser
    from glassdist.report import figures

    build_parser()
    fig, _ = figures.plot_channel(np.zeros((4, 4)), None, vmax=1.0, title=r"$\phi_{eff}$", extent=(0, 1, 1, 0),
                                  axis_units="mm", px_axis=(1.0, 0.0))
    figures.figure_png(fig)


def _child(request: dict) -> None:
    """Body of a forked child: never returns."""
    code = 1
    try:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        os.environ.clear()
        os.environ.update(request["env"])
        if request.get("cwd"):
            os.chdir(request["cwd"])
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        for fd, key in ((1, "out"), (2, "err")):
            target = os.open(request[key], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(target, fd)
            os.close(target)
        sys.stdin = open(0, closefd=False)  # noqa: SIM115 - the process's own descriptors
        sys.stdout = open(1, "w", encoding="utf-8", errors="replace", buffering=1, closefd=False)  # noqa: SIM115
        sys.stderr = open(2, "w", encoding="utf-8", errors="replace", buffering=1, closefd=False)  # noqa: SIM115
        from glassdist.cli import exit_status, main, run_request_json

        try:
            code = run_request_json(request["request"]) if "request" in request else main(request["args"])
        except SystemExit as exc:  # argparse: --help, --version, option errors
            code = exit_status(exc)
        except KeyboardInterrupt:  # before main's own handler could see it
            code = 130
        except BaseException:  # what --debug lets through: the traceback, as the interpreter would print it
            import traceback

            traceback.print_exc()
            code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            tmp = request["status"] + ".tmp"
            with open(tmp, "w") as fh:
                fh.write(str(int(code)))
            os.rename(tmp, request["status"])
        finally:
            os._exit(int(code) & 0xFF)


def _reap(children: set, *, block: bool = False) -> None:
    """Collect the exit status of the ``children`` that ended (all of them with ``block``)."""
    for pid in list(children):
        try:
            done, _ = os.waitpid(pid, 0 if block else os.WNOHANG)
        except ChildProcessError:
            done = pid
        if done:
            children.discard(pid)


def serve() -> None:
    """Import the stack, say ready, then fork one child per request line until stdin closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for name in PRELOAD:
        __import__(name)
    _warm()
    # What is loaded now lives as long as the server: in a permanent generation, a child's garbage
    # collections no longer walk it (nor write to its pages, which the child then shares instead of
    # copying). The documented batch: 17.4 -> 16.1 s.
    gc.freeze()
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    requests = os.fdopen(os.dup(0), "r")
    reply.write(json.dumps({"ready": True}) + "\n")
    children: set[int] = set()
    for line in requests:
        request = json.loads(line)
        if "wait" in request:  # the exit status of a child that ended without writing its own (killed)
            code = None
            if request["wait"] in children:
                children.discard(request["wait"])
                try:
                    code = os.waitstatus_to_exitcode(os.waitpid(request["wait"], 0)[1])
                except ChildProcessError:
                    pass
            reply.write(json.dumps({"exit": code}) + "\n")
            continue
        _reap(children)
        pid = os.fork()
        if pid == 0:
            requests.close()
            reply.close()
            _child(request)
        children.add(pid)
        reply.write(json.dumps({"pid": pid}) + "\n")
    # stdin closed: the caller is done or gone; a child still running has no one left to report to
    for pid in children:
        try:
            os.kill(pid, signal.SIGKILL)  # unreaped, so the pid is still this child's
        except ProcessLookupError:
            pass
    _reap(children, block=True)


def run_one() -> int:
    """``python -m glassdist._childserver --request``: the serialised request on stdin, run once, without a server.

    Where no server serves :func:`glassdist.jobs.runner.run_request` (not Linux,
    ``GLASSDIST_CHILD=process``): the exit status is that of ``glassdist analyze``.
    """
    from glassdist.cli import exit_status, run_request_json

    try:
        return run_request_json(sys.stdin.read())
    except SystemExit as exc:  # argparse: option errors
        return exit_status(exc)


if __name__ == "__main__":
    sys.exit(run_one()) if sys.argv[1:] == ["--request"] else serve()
