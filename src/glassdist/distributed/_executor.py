"""Executors: run independent jobs here, one after the other, or on a Dask cluster."""

from __future__ import annotations

import contextlib
import logging
import os
import secrets
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from .._version import __version__
from ..errors import InputError

__all__ = ["Executor", "SerialExecutor", "DaskExecutor", "JobOutcome", "open_executor", "add_scheduler_options"]

logger = logging.getLogger(__name__)

_INSTALL = "install the extra with: pip install 'glassdist[distributed]'"
_SHARED = ("inputs and outputs must be on a filesystem every worker sees under the same path "
           "(see docs/user-guide/batches-and-dask.md)")


@dataclass(frozen=True)
class JobOutcome:
    """One finished job: its position in the submitted list, and its value or the exception it raised."""

    index: int
    value: Any = None
    error: BaseException | None = None


class Executor:
    """Runs ``fn(item)`` for independent items; subclasses decide where.

    Attributes
    ----------
    description : str
        Where the jobs run, for messages (``"this process"``, ``"Dask cluster at tcp://..."``).
    distributed : bool
        True when jobs run in other processes, possibly on other machines.
    """

    description = "this process"
    distributed = False

    def as_completed(self, fn: Callable, items: Iterable) -> Iterator[JobOutcome]:
        """Yield a :class:`JobOutcome` per item as its job finishes (an exception is an outcome, not raised)."""
        raise NotImplementedError

    def map(self, fn: Callable, items: Iterable) -> list:
        """``[fn(item) for item in items]`` in order; re-raises the first job's exception."""
        items = list(items)
        results: list = [None] * len(items)
        for outcome in self.as_completed(fn, items):
            if outcome.error is not None:
                raise outcome.error
            results[outcome.index] = outcome.value
        return results

    def check_paths(self, *, files: Iterable = (), folders: Iterable = (), cwd=None) -> None:
        """Raise :class:`InputError` unless every worker sees ``files``, can write in ``folders`` and sees ``cwd``."""


class SerialExecutor(Executor):
    """Jobs run in this process, in order (the default)."""

    def as_completed(self, fn, items):
        for i, item in enumerate(items):
            try:
                value = fn(item)
            except Exception as exc:  # noqa: BLE001 - handed to the caller as the job's outcome
                yield JobOutcome(i, error=exc)
            else:
                yield JobOutcome(i, value)


class DaskExecutor(Executor):
    """Jobs run as tasks of a Dask ``distributed`` client; results come back as the futures complete.

    Parameters
    ----------
    client : distributed.Client
    description : str
    """

    distributed = True

    def __init__(self, client, description: str):
        self.client = client
        self.description = description

    def as_completed(self, fn, items):
        from distributed import as_completed

        tag = uuid.uuid4().hex[:8]
        name = getattr(fn, "__name__", None) or getattr(getattr(fn, "func", None), "__name__", "job")
        futures = [self.client.submit(_on_worker, fn, item, pure=False, key=f"glassdist-{name}-{tag}-{i}")
                   for i, item in enumerate(items)]
        position = {f.key: i for i, f in enumerate(futures)}
        try:
            for future in as_completed(futures):
                i = position[future.key]
                if future.status == "finished":
                    yield JobOutcome(i, future.result())
                else:  # a job that raised, or whose worker died more often than the scheduler allows
                    yield JobOutcome(i, error=future.exception())
                future.release()
        finally:  # interrupted: nothing left running on the cluster
            pending = [f for f in futures if not f.done()]
            if pending:
                self.client.cancel(pending)

    def check_paths(self, *, files=(), folders=(), cwd=None):
        files = sorted({str(Path(f).absolute()) for f in files})
        token = secrets.token_hex(8)
        probes = []
        try:
            for folder in sorted({str(Path(d).absolute()) for d in folders}):
                probe = Path(folder) / f".glassdist-probe-{token}"
                probe.write_text(token, encoding="utf-8")
                probes.append(str(probe))
            cwd = None if cwd is None else str(Path(cwd).absolute())
            found = self.client.run(_probe_paths, files, probes, token, cwd, __version__)
        finally:
            for probe in probes:
                with contextlib.suppress(OSError):
                    os.unlink(probe)
        for worker, problem in sorted(found.items()):
            if problem:
                raise InputError(f"Dask worker {worker} {problem}")


def _on_worker(fn, item):
    """Run one job on a Dask worker, whose child processes get the environment of an ordinary one.

    A Dask nanny starts its worker with ``MALLOC_TRIM_THRESHOLD_=65536`` (it keeps the worker's
    memory small); a child ``glassdist`` process inheriting it runs ~1.5x slower (its large numpy
    buffers are handed back to the system and taken again). The thread limits (``OMP_NUM_THREADS=1``,
    ...) are kept: the parallelism is the workers'.
    """
    os.environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return fn(item)


def _probe_paths(files, probes, token, cwd, version):
    """On a worker: the first problem seeing the coordinator's paths, or ``None``."""
    import glassdist

    if glassdist.__version__ != version:
        return (f"runs glassdist {glassdist.__version__}, this machine {version}; "
                "install the same version on every worker")
    if cwd is not None and not os.path.isdir(cwd):
        return f"cannot see the working folder '{cwd}' (relative paths are read from it); {_SHARED}"
    for f in files:
        if not os.path.isfile(f):
            return f"cannot see the input '{f}' (it exists here); {_SHARED}"
    for probe in probes:
        folder = os.path.dirname(probe)
        try:
            with open(probe, encoding="utf-8") as fh:
                same = fh.read() == token
        except OSError:
            same = False
        if not same:
            return f"cannot see the output folder '{folder}' as this machine does; {_SHARED}"
        mine = f"{probe}-{os.getpid()}-{secrets.token_hex(4)}"
        try:
            with open(mine, "w", encoding="utf-8") as fh:
                fh.write(token)
            os.unlink(mine)
        except OSError as exc:
            return f"cannot write in the output folder '{folder}' ({exc.strerror}); give the workers write access"
    return None


@contextlib.contextmanager
def open_executor(scheduler: str | None = None, workers: int | None = None, *, worker_wait_s: float = 30.0):
    """The executor for the ``--scheduler`` / ``--workers`` options, closed on exit.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    workers : int, optional
        Start a local Dask cluster of this many single-threaded worker processes.
    worker_wait_s : float
        How long to wait for the scheduler's first worker. (The wait for the scheduler
        itself is Dask's ``distributed.comm.timeouts.connect``, 30 s unless configured,
        e.g. ``DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT=5s``.)

    Yields
    ------
    Executor
        :class:`SerialExecutor` when neither is given, else a :class:`DaskExecutor`.

    Raises
    ------
    InputError
        Both options given, ``workers < 1``, Dask not installed, scheduler unreachable or without workers.
    """
    if scheduler is None and workers is None:
        yield SerialExecutor()
        return
    if scheduler is not None and workers is not None:
        raise InputError("give either --scheduler (a running Dask cluster) or --workers (a local one), not both")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError(f"--scheduler and --workers need Dask; {_INSTALL}") from None
    if not logging.getLogger().isEnabledFor(logging.DEBUG):  # Dask's INFO chatter is not the user's business
        logging.getLogger("distributed").setLevel(logging.WARNING)
    with contextlib.ExitStack() as stack:
        if workers is not None:
            # no dashboard; the scheduler's HTTP endpoint on a free local port (8787 may be taken)
            cluster = stack.enter_context(LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}, silence_logs=logging.WARNING))
            client = stack.enter_context(Client(cluster))
            description = f"local Dask cluster of {workers} worker process(es)"
        else:
            try:
                client = stack.enter_context(Client(scheduler))
            except (OSError, TimeoutError, ValueError) as exc:
                first = (str(exc).splitlines() or [type(exc).__name__])[0]
                raise InputError(f"cannot reach the Dask scheduler at '{scheduler}' ({first}); start one with "
                                 "'dask scheduler' and workers with 'dask worker ADDRESS', or check the address") from None
            try:
                client.wait_for_workers(1, timeout=worker_wait_s)
            except TimeoutError:
                raise InputError(f"the Dask scheduler at '{scheduler}' has no worker after {worker_wait_s:g} s; "
                                 "start some with 'dask worker ADDRESS'") from None
            description = f"Dask cluster at {scheduler}"
        yield DaskExecutor(client, description)


def _at_least_one(text: str) -> int:
    import argparse

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number, got '{text}'") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text}")
    return n


def add_scheduler_options(parser) -> None:
    """Add ``--scheduler ADDRESS`` and ``--workers N`` (mutually exclusive) to a sub-command's parser."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the jobs on a running Dask scheduler (e.g. tcp://host:8786); inputs and --out "
                            "must be on a filesystem shared with its workers (needs glassdist[distributed])")
    group.add_argument("--workers", type=_at_least_one, metavar="N",
                       help="run the jobs on a local Dask cluster of N worker processes "
                            "(default: one after the other in this process)")
