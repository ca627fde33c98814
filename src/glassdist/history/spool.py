"""The spool: a run's record kept on the local disk while its history database cannot be reached.

A record that cannot be written (the SQLite file's folder missing or read-only, the
server down, its driver not installed, the database locked past the timeout or of a
newer schema) is kept as one JSON file ``data_dir()/spool/<target>/<record_id>.json``,
written atomically (a temporary name, then a rename: a reader never sees a part), where
``<target>`` is a hash of the database it is for (the database itself, its password
hidden, is inside the file). The next run, or read (``glassdist history``), that reaches
that database writes every record waiting for it in the same transaction as its own
(:func:`glassdist.history.store.insert_runs`) and only then removes their files. The
record's id, the SHA-256 of its content, is unique in the database: a record already
there (a writer stopped between its commit and the removal of the file) is skipped, so
each record is written exactly once.
"""

from __future__ import annotations

import hashlib
import json
from datetime import datetime
from pathlib import Path

from ..fs import atomic_write_text

__all__ = ["target_folder", "keep", "waiting", "discard"]

#: the spool files' format (a later glassdist reads the records an older one kept)
FORMAT = 1


def target_folder(root: Path, location) -> Path:
    """The folder under the spool ``root`` of the records waiting for ``location`` (a ``Location``)."""
    return Path(root) / hashlib.sha256(str(location).encode("utf-8")).hexdigest()[:16]


def _encode(entry) -> dict:
    run, checks, stats = entry
    when = run.get("recorded_utc")
    return {"run": {**run, "recorded_utc": when.isoformat() if isinstance(when, datetime) else when},
            "checks": list(checks), "statistics": list(stats)}


def _decode(record: dict):
    run = dict(record["run"])
    if isinstance(run.get("recorded_utc"), str):
        run["recorded_utc"] = datetime.fromisoformat(run["recorded_utc"])
    return run, list(record["checks"]), list(record["statistics"])


def keep(root: Path, location, entry) -> Path:
    """Keep one record (``(run, checks, statistics)`` of :func:`~glassdist.history.store.run_rows`) for ``location``.

    ``root`` is the spool folder (:func:`glassdist.history.store.spool_dir`).

    Returns
    -------
    Path
        The spool file (its name is the record's id; keeping the same record twice
        rewrites the same file).

    Raises
    ------
    OSError
        The spool folder cannot be created or written.
    """
    folder = target_folder(root, location)
    folder.mkdir(parents=True, exist_ok=True)
    run = entry[0]
    name = run.get("record_id") or hashlib.sha256(json.dumps(_encode(entry), sort_keys=True).encode()).hexdigest()
    doc = {"format": FORMAT, "target": str(location), "record": _encode(entry)}
    return atomic_write_text(folder / f"{name}.json", json.dumps(doc, sort_keys=True, allow_nan=False) + "\n")


def waiting(root: Path, location) -> tuple[list[tuple[Path, tuple]], list[Path]]:
    """The records waiting for ``location``, oldest first, and the spool files that cannot be read (left alone).

    Returns
    -------
    records : list of (Path, entry)
        Each spool file and its ``(run, checks, statistics)``.
    unreadable : list of Path
        Files of this target's folder that are not a record of this glassdist's format.
    """
    folder = target_folder(root, location)
    if not folder.is_dir():
        return [], []
    found, bad = [], []
    for path in sorted(folder.glob("*.json")):
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
            if doc.get("format") != FORMAT or doc.get("target") != str(location):
                raise ValueError("another format or database")
            found.append((path, _decode(doc["record"])))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            bad.append(path)
    found.sort(key=lambda pe: (str(pe[1][0].get("recorded_utc")), pe[0].name))
    return found, bad


def discard(paths) -> None:
    """Remove spool files whose records are in the database (one already gone is fine: another writer took it)."""
    for path in paths:
        Path(path).unlink(missing_ok=True)
