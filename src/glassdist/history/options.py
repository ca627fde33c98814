"""The command-line side of recording: ``--db``, ``--no-history`` and the context a batch or web child is given."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

__all__ = ["DB_HELP", "add_recording_options", "recording", "record_as_args"]

DB_HELP = ("history database: a file path or a database URL (default: $GLASSDIST_DB, else "
           "~/.local/share/glassdist/history.sqlite); 'off' records nothing")
_RECORD_KEYS = ("source", "job", "out_dir")


def add_recording_options(p) -> None:
    """``--db``, ``--no-history`` (and the hidden ``--record-as`` of batch and web children) on ``analyze``."""
    p.add_argument("--db", metavar="PATH|URL", help=DB_HELP)
    p.add_argument("--no-history", action="store_true", help="do not record this run in the history database")
    p.add_argument("--record-as", type=_record_as, help=argparse.SUPPRESS)


def _record_as(text: str) -> dict:
    try:
        value = json.loads(text)
    except ValueError:
        value = None
    if not isinstance(value, dict) or set(value) - set(_RECORD_KEYS) or not all(
            isinstance(v, str) for v in value.values()):
        raise argparse.ArgumentTypeError(f"must be a JSON object of text values with keys among {', '.join(_RECORD_KEYS)}")
    return value


def recording(args):
    """The :class:`~glassdist.history.Recording` of a command-line run (False with ``--no-history``)."""
    from .store import Recording

    if args.no_history:
        return False
    ctx = dict(args.record_as or {"source": "cli"})
    for key in ("out_dir", "job") if ctx.get("source") == "batch" else ("out_dir",):
        if ctx.get(key):  # a batch's folders, relative to the folder the batch (and so this child) runs in
            ctx[key] = str(Path(ctx[key]).absolute())
    return Recording(db=args.db, **ctx)


def record_as_args(**context) -> list[str]:
    """The hidden ``--record-as`` option a batch or web child of ``glassdist analyze`` is given."""
    return [f"--record-as={json.dumps({k: str(v) for k, v in context.items() if v is not None})}"]
