"""The command-line side of recording: ``--db``, ``--no-history``, and the context a batch or web child runs in."""

from __future__ import annotations

from pathlib import Path

__all__ = ["DB_HELP", "add_recording_options", "recording"]

DB_HELP = ("history database: a file path or a database URL (default: $GLASSDIST_DB, else "
           "~/.local/share/glassdist/history.sqlite); 'off' records nothing")


def add_recording_options(p) -> None:
    """``--db`` and ``--no-history`` on ``analyze``; a batch's or web app's child is given its context in its request
    (:class:`glassdist.jobs.request.RecordAs`, set as ``record_as`` by :func:`glassdist.cli.run_request`)."""
    p.add_argument("--db", metavar="PATH|URL", help=DB_HELP)
    p.add_argument("--no-history", action="store_true", help="do not record this run in the history database")
    p.set_defaults(record_as=None)


def recording(args):
    """The :class:`~glassdist.history.Recording` of a command-line run (False with ``--no-history``)."""
    from .store import Recording

    if args.no_history:
        return False
    ctx = {k: v for k, v in (args.record_as or {"source": "cli"}).items() if v is not None}
    for key in ("out_dir", "job") if ctx.get("source") == "batch" else ("out_dir",):
        if ctx.get(key):  # a batch's folders, relative to the folder the batch (and so this child) runs in
            ctx[key] = str(Path(ctx[key]).absolute())
    return Recording(db=args.db, **ctx)
