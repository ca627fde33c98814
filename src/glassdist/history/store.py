"""Where the history lives, how it is opened, upgraded and written, and how a run becomes its rows.

The database
------------
:func:`locate` resolves, in this order: an explicit ``db`` (``--db PATH`` or a database
URL), the ``GLASSDIST_DB`` environment variable, and the user's data folder
(``$XDG_DATA_HOME/glassdist/history.sqlite``, by default
``~/.local/share/glassdist/history.sqlite``; ``~/Library/Application Support`` on macOS,
``%LOCALAPPDATA%`` on Windows). ``off`` (or ``none``, ``0``, ``false``) turns the history off.
A value with ``://`` is a SQLAlchemy URL (``postgresql+psycopg://user@host/db``), for
several stations writing to one history.

Writers and locks
-----------------
A SQLite file is used in WAL mode with a busy timeout (``GLASSDIST_DB_TIMEOUT_S``, default
10 s): readers never wait for a writer, and each run's record is one ``BEGIN IMMEDIATE``
transaction, so concurrent writers (several processes, Dask workers) queue for a few
milliseconds each. A writer killed in the middle of its transaction leaves nothing: SQLite
drops the uncommitted WAL frames and the operating system releases its locks. On
PostgreSQL each writer's transaction takes an advisory lock while it checks (and, the
first time, creates) the schema, and the same timeout bounds the connection and any lock
wait (``connect_timeout``, ``lock_timeout``); a killed client's transaction is rolled back
by the server.

The schema is versioned by Alembic (``migrations/versions``): every write checks the
database's revision in the same transaction and upgrades an older one first; a database of
a newer glassdist is refused, never altered.

A record that cannot be written
-------------------------------
:func:`record` never loses a run's record: when the database cannot be reached or written
it keeps the record in the spool (:mod:`~glassdist.history.spool`, under :func:`spool_dir`)
and says where; the next run or read that reaches the database writes it, once (each
record's ``record_id``, the SHA-256 of its content, is unique in the database and checked
in the writer's transaction).
"""

from __future__ import annotations

import math
import os
import re
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from ..errors import InputError

__all__ = ["HistoryUnavailable", "Location", "Recording", "Recorded", "SpoolFlush", "data_dir", "spool_dir",
           "locate", "open_store", "record", "record_run", "flush_spool", "run_rows", "record_id", "insert_runs",
           "describe_failure", "Store"]

#: values of ``GLASSDIST_DB`` / ``--db`` that turn the history off
OFF = ("off", "none", "0", "false", "no")
#: schema revisions this glassdist can read and upgrade from, oldest first
KNOWN_REVISIONS = ("0001", "0002")
_PG_LOCK_KEY = 0x6C617373  # advisory lock held while a PostgreSQL schema is created or upgraded
_ZONE_IN_CRITERION = re.compile(r"zone '([^']+)'")


class HistoryUnavailable(InputError):
    """The history database cannot be opened, read or written (one line saying why and what to do)."""


@dataclass(frozen=True)
class Location:
    """A resolved history database: its SQLAlchemy ``url``, the SQLite file ``path`` (None for a server)."""

    url: str
    path: Path | None
    default: bool = False

    def __str__(self) -> str:
        return str(self.path) if self.path is not None else _hide_password(self.url)


@dataclass(frozen=True)
class Recording:
    """How one run is recorded (:func:`glassdist.storage.writer.write_outputs` ``history=``).

    Attributes
    ----------
    db : str or path, optional
        The database (see :func:`locate`); None: ``GLASSDIST_DB``, else the user's data folder.
    source : {'cli', 'batch', 'web', 'api'}
        What ran the analysis.
    job : str, optional
        The web job's id, or the batch's output folder.
    out_dir : str, optional
        The folder the run's files end up in, when not the one they are written to (a batch
        pane is written to a temporary folder, then renamed).
    enabled : bool
        False: nothing is recorded (``--no-history``).
    """

    db: str | None = None
    source: str = "api"
    job: str | None = None
    out_dir: str | None = None
    enabled: bool = True


def data_dir() -> Path:
    """The user's data folder for glassdist (created by the first write, not here)."""
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Application Support"
    else:
        xdg = os.environ.get("XDG_DATA_HOME", "")
        base = Path(xdg) if os.path.isabs(xdg) else Path.home() / ".local" / "share"
    return base / "glassdist"


def spool_dir() -> Path:
    """Where records wait while their database cannot be reached: ``data_dir() / 'spool'``."""
    return data_dir() / "spool"


def locate(db=None) -> Location | None:
    """The history database to use, or None when the history is off.

    Parameters
    ----------
    db : str or path, optional
        A file path or a SQLAlchemy URL; ``off`` turns the history off. Default:
        ``GLASSDIST_DB``, else ``data_dir() / 'history.sqlite'``.
    """
    value = str(db) if db is not None else os.environ.get("GLASSDIST_DB", "")
    value = value.strip()
    if value.lower() in OFF:
        return None
    if not value:
        path = data_dir() / "history.sqlite"
        return Location(f"sqlite:///{path}", path, default=True)
    if "://" in value:
        if value.startswith("sqlite:///") and value != "sqlite:///:memory:":
            return Location(value, Path(value[len("sqlite:///"):]).expanduser().absolute())
        return Location(value, None)
    path = Path(value).expanduser().absolute()
    return Location(f"sqlite:///{path}", path)


def _hide_password(url: str) -> str:
    return re.sub(r"://([^:/@]+):[^@/]*@", r"://\1:***@", url)


def _timeout_s() -> float:
    try:
        value = float(os.environ.get("GLASSDIST_DB_TIMEOUT_S", "10"))
    except ValueError:
        return 10.0
    return value if math.isfinite(value) and value >= 0 else 10.0


def _engine(loc: Location, *, write: bool):
    """A SQLAlchemy engine on ``loc``: for SQLite, WAL and a busy timeout; writers begin IMMEDIATE."""
    from sqlalchemy import create_engine, event
    from sqlalchemy.pool import NullPool

    timeout = _timeout_s()
    if loc.path is None:
        args = {}
        if loc.url.startswith("postgresql"):  # wait for a lock, or for the server, no longer than a SQLite writer
            args = {"connect_timeout": max(1, round(timeout)), "options": f"-c lock_timeout={int(timeout * 1000)}"}
        return create_engine(loc.url, poolclass=NullPool, connect_args=args)
    from urllib.parse import quote

    uri = f"file:{quote(loc.path.as_posix())}" + ("" if write else "?mode=ro")
    engine = create_engine("sqlite://", poolclass=NullPool, creator=lambda: _sqlite_connect(uri, timeout))

    @event.listens_for(engine, "begin")
    def _begin(conn):  # the driver is in autocommit mode: glassdist says where transactions start
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")

    return engine


def _sqlite_connect(uri: str, timeout: float):
    import sqlite3

    con = sqlite3.connect(uri, uri=True, timeout=timeout, isolation_level=None, check_same_thread=False)
    con.execute(f"PRAGMA busy_timeout = {int(timeout * 1000)}")
    if "mode=ro" not in uri:
        con.execute("PRAGMA journal_mode = WAL")  # persistent; readers never wait for a writer
        con.execute("PRAGMA synchronous = NORMAL")  # safe in WAL mode: a crash loses no committed run
    con.execute("PRAGMA foreign_keys = ON")
    return con


def _prepare_file(loc: Location, *, write: bool) -> bool:
    """Check the SQLite file's folder (the default one is created); False when there is nothing to read yet."""
    if loc.path is None:
        return True
    folder = loc.path.parent
    if not folder.is_dir():
        if write and loc.default:
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise HistoryUnavailable(f"cannot create the folder '{folder}': {exc.strerror}") from None
        elif write:
            raise HistoryUnavailable(f"the folder '{folder}' does not exist")
        else:
            return False
    if not loc.path.exists():
        return write
    if loc.path.is_dir():
        raise HistoryUnavailable(f"'{loc.path}' is a folder, not a database file")
    return True


def _revision(conn) -> str | None:
    from sqlalchemy import inspect, text

    if not inspect(conn).has_table("alembic_version"):
        return None
    return conn.execute(text("SELECT version_num FROM alembic_version")).scalar()


def _upgrade(conn) -> None:
    """Bring the schema to the newest revision with Alembic, inside the caller's transaction."""
    from alembic import command
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", str(Path(__file__).with_name("migrations")))
    cfg.attributes["connection"] = conn
    command.upgrade(cfg, "head")


def _ensure_schema(conn, loc: Location) -> None:
    from .models import SCHEMA_REVISION

    if loc.path is None and conn.dialect.name == "postgresql":
        from sqlalchemy import text

        conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _PG_LOCK_KEY})
    current = _revision(conn)
    if current == SCHEMA_REVISION:
        return
    if current is not None and current not in KNOWN_REVISIONS:
        raise HistoryUnavailable(f"the database is of schema revision '{current}', newer than this glassdist's "
                                 f"('{SCHEMA_REVISION}'); upgrade glassdist to write to it")
    _upgrade(conn)


class Store:
    """An open history database (:func:`open_store`): ``engine`` and its :class:`Location`."""

    def __init__(self, loc: Location, engine, *, write: bool):
        self.location, self.engine, self.write = loc, engine, write

    def close(self) -> None:
        """Release the database connections."""
        self.engine.dispose()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def open_store(db=None, *, write: bool = False) -> Store | None:
    """Open the history database (see :func:`locate`); None when it is off, or has nothing to read yet.

    A writer's database is created (the default folder too) and brought to the current
    schema by its first :func:`insert_runs`; a reader's is opened read-only and never created.

    Raises
    ------
    HistoryUnavailable
        The folder is missing, the file is not a database (corrupted), the schema is newer
        than this glassdist's.
    """
    loc = locate(db)
    if loc is None or not _prepare_file(loc, write=write):
        return None
    engine = _engine(loc, write=write)
    if write:  # the schema is checked (and created) in each writer's own transaction: insert_runs
        return Store(loc, engine, write=True)
    try:
        with engine.connect() as conn:
            current = _revision(conn)
    except BaseException:
        engine.dispose()
        raise
    if current is None or current not in KNOWN_REVISIONS:
        engine.dispose()
        if current is None:
            return None
        raise HistoryUnavailable(f"the database is of schema revision '{current}', newer than this glassdist's; "
                                 "upgrade glassdist to read it")
    return Store(loc, engine, write=False)


def _finite(v):
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def _stat_rows(zone: str, statistics: dict) -> list[dict]:
    rows = []
    for channel, stats in (statistics or {}).items():
        for name, value in (stats or {}).items() if isinstance(stats, dict) else ():
            v = _finite(value)
            if v is not None:
                rows.append({"zone": zone, "channel": str(channel), "statistic": str(name), "value": v})
    return rows


def _flatness_row(summary: dict) -> dict:
    """A reflection run's roller-wave depth and largest edge lift (mm), recorded as channel ``flatness``."""
    flat = summary.get("flatness") or {}
    lifts = [abs(v) for v in (flat.get("edge_lift_mm") or {}).values() if isinstance(v, (int, float))]
    return {"roller_wave_peak_to_valley_mm": (flat.get("roller_wave") or {}).get("peak_to_valley_mm"),
            "edge_lift_max_mm": max(lifts) if lifts else None}


def _camera(meta: dict) -> str | None:
    cam = meta.get("camera")
    if not isinstance(cam, dict):
        return None
    text = " ".join(str(cam[k]) for k in ("make", "model") if cam.get(k))
    return text[:200] or None


def _path(value, base: Path | None) -> str | None:
    if value is None:
        return None
    p = Path(value)
    return str(p if p.is_absolute() or base is None else (base / p).absolute())


def run_rows(summary: dict, *, exit_code: int, out_dir, recording: Recording = Recording(),
             recorded_utc: datetime | None = None, cwd: Path | None = None) -> tuple[dict, list[dict], list[dict]]:
    """The rows one run adds: ``(run, checks, statistics)`` from its ``summary.json`` content (in memory).

    Parameters
    ----------
    summary : dict
        The summary the output stage wrote (``glassdist.storage.writer``).
    exit_code : int
        The run's exit status (0, or 3 on a specification FAIL).
    out_dir : path
        The run's output folder (``recording.out_dir`` takes precedence).
    recording : Recording
    recorded_utc : datetime, optional
        Default: now (UTC, stored without time zone).
    cwd : path, optional
        Folder relative input paths are relative to (default: the current one).

    Returns
    -------
    run : dict
        Columns of :class:`~glassdist.history.models.Run`.
    checks, statistics : list of dict
        Columns of :class:`~glassdist.history.models.CheckRow` and
        :class:`~glassdist.history.models.StatisticRow` (without ``run_id``); statistics of
        the whole analysed region under zone :data:`~glassdist.history.models.REGION`, a
        zone's ``trusted_percent`` as channel ``region``, statistic ``coverage_percent`` (the
        database's names are kept: ``valid_percent`` holds the summary's ``measured_percent``,
        ``trusted_percent`` its ``trusted_percent``); ``run['record_id']`` is :func:`record_id`.
    """
    from .. import __version__
    from .models import REGION

    cwd = Path.cwd() if cwd is None else Path(cwd)
    meta = summary.get("metadata") or {}
    inputs = summary.get("inputs") or {}
    verdict = summary.get("verdict") or {}
    a4 = summary.get("a4") or {}
    warnings = [str(w) for w in summary.get("warnings") or []]
    pane_warning = (summary.get("pane") or {}).get("warning")
    if pane_warning:
        warnings.append(str(pane_warning))
    when = recorded_utc or datetime.now(timezone.utc)
    run = {
        "recorded_utc": when.astimezone(timezone.utc).replace(tzinfo=None) if when.tzinfo else when,
        "source": recording.source, "job": recording.job,
        "pane_id": meta.get("pane_id"), "lot": meta.get("lot"), "site": meta.get("site"),
        "operator": meta.get("operator"), "camera": _camera(meta),
        "image": _path(inputs.get("image"), cwd), "image_sha256": inputs.get("image_sha256"),
        "reference": _path(inputs.get("reference"), cwd), "reference_sha256": inputs.get("reference_sha256"),
        "method": summary.get("method"), "pattern": summary.get("pattern"),
        "pitch_mm": _finite(summary.get("pitch_mm")), "distance_m": _finite(summary.get("distance_m")),
        "sigma_mm": _finite(summary.get("sigma_mm")), "detrend_degree": summary.get("detrend_degree"),
        "protocol": summary.get("protocol"), "verdict": verdict.get("result"), "spec_name": verdict.get("spec_name"),
        "spec_sha256": verdict.get("spec_sha256") or None, "exit_code": int(exit_code),
        "valid_percent": _finite(summary.get("measured_percent")),
        "trusted_percent": _finite(summary.get("trusted_percent")), "measures": summary.get("measures"),
        "warnings": warnings, "out_dir": recording.out_dir or _path(out_dir, cwd),
        "glassdist_version": summary.get("glassdist_version") or __version__,
    }
    checks = []
    for c in verdict.get("checks") or []:
        zone = _ZONE_IN_CRITERION.search(str(c.get("criterion", "")))
        checks.append({"criterion": str(c.get("criterion", "")), "zone": zone.group(1) if zone else None,
                       "value": _finite(c.get("value")), "limit": _finite(c.get("limit")), "unit": c.get("unit"),
                       "passed": bool(c.get("passed")), "note": c.get("note") or None})
    stats = _stat_rows(REGION, a4.get("statistics")) + _stat_rows(REGION, {"flatness": _flatness_row(summary)})
    for name, z in (summary.get("zones") or {}).items():
        stats += _stat_rows(str(name), z.get("statistics"))
        cov = _finite(z.get("trusted_percent"))
        if cov is not None:
            stats.append({"zone": str(name), "channel": "region", "statistic": "coverage_percent", "value": cov})
    run["record_id"] = record_id(run, checks, stats)
    return run, checks, stats


def record_id(run: dict, checks: list, stats: list) -> str:
    """The record's id: SHA-256 of its content (recording time and output folder included), as canonical JSON."""
    import hashlib
    import json

    content = [{k: v for k, v in run.items() if k != "record_id"}, checks, stats]
    text = json.dumps(content, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def insert_runs(store: Store, entries) -> list[int]:
    """Insert ``(run, checks, statistics)`` row sets (:func:`run_rows`) in one transaction; their ids.

    The schema is checked (created, upgraded) in the same transaction, so a writer never
    sees a half-made database; the rows go in as bulk inserts (one statement per table).
    A record whose ``record_id`` is already in the database (or earlier in ``entries``) is
    not inserted again: its id is the one recorded. Writers are serialised (SQLite's
    ``BEGIN IMMEDIATE``, PostgreSQL's advisory lock), so the check cannot race another
    writer; the unique index on ``record_id`` stands behind it.
    """
    from sqlalchemy import insert, select
    from sqlalchemy.orm import Session

    from .models import CheckRow, Run, StatisticRow

    entries = list(entries)
    keys = [run.get("record_id") for run, _, _ in entries]
    with Session(store.engine) as session, session.begin():
        _ensure_schema(session.connection(), store.location)
        known: dict[str, int] = {}
        wanted = sorted({k for k in keys if k})
        for i in range(0, len(wanted), 500):
            chunk = wanted[i:i + 500]
            known.update(session.execute(select(Run.record_id, Run.id).where(Run.record_id.in_(chunk))).all())
        new, seen = [], set(known)
        for k, entry in zip(keys, entries):
            if k is None or k not in seen:
                new.append(entry)
                if k is not None:
                    seen.add(k)
        new_ids = list(session.scalars(insert(Run).returning(Run.id, sort_by_parameter_order=True),
                                       [run for run, _, _ in new])) if new else []
        for model, k in ((CheckRow, 1), (StatisticRow, 2)):
            rows = [{**row, "run_id": rid} for rid, entry in zip(new_ids, new) for row in entry[k]]
            if rows:
                session.execute(insert(model), rows)
    fresh = iter(new_ids)
    ids, given = [], dict(known)
    for k in keys:
        if k is not None and k in given:
            ids.append(given[k])
        else:
            rid = next(fresh)
            ids.append(rid)
            if k is not None:
                given[k] = rid
    return ids


def describe_failure(exc: BaseException) -> str:
    """One line on why the history could not be used (no traceback, no SQL)."""
    if isinstance(exc, HistoryUnavailable):
        return str(exc)
    orig = getattr(exc, "orig", None) or exc
    text = str(orig).splitlines()[0] if str(orig) else type(orig).__name__
    if isinstance(orig, ImportError):
        return f"its database driver is not installed ({text}; for PostgreSQL: pip install 'glassdist[postgresql]')"
    if "locked" in text or "busy" in text:
        return f"the database stayed locked by another writer for {_timeout_s():g} s ({text})"
    if "not a database" in text or "malformed" in text:
        return f"the file is not a readable SQLite database ({text}); move it aside to start a new history"
    if "readonly" in text or "read-only" in text:
        return f"the database is read-only ({text})"
    return f"{type(orig).__name__}: {text}"


@dataclass(frozen=True)
class Recorded:
    """Where one run's record went (:func:`record`).

    Attributes
    ----------
    location : Location or None
        The database it is for; None when nothing is recorded (``off``).
    run_id : int, optional
        Its id in the database, when written there.
    spooled : Path, optional
        The spool file keeping it, when the database could not be written.
    reason : str, optional
        Why the database could not be written (or, with ``location`` None, why nothing
        is recorded).
    flushed : int
        Records that waited in the spool for this database, written with this one.
    """

    location: Location | None
    run_id: int | None = None
    spooled: Path | None = None
    reason: str | None = None
    flushed: int = 0

    @property
    def warning(self) -> bool:
        """The record did not reach its database (kept in the spool, or lost)."""
        return self.location is not None and self.run_id is None

    def line(self) -> str:
        """The console line naming where the record went (``warning: ...`` when it did not reach the database)."""
        if self.location is None:
            return f"history: this run is not recorded ({self.reason})"
        where = f"'{self.location}'"
        if self.run_id is not None:
            line = f"history: recorded as run {self.run_id} in {where}"
            if self.location.default:
                line += " (the default history file; --db PATH|URL or GLASSDIST_DB chooses another)"
            if self.flushed:
                line += f"; with it {self.flushed} record(s) that waited in the spool"
            return line
        if self.spooled is not None:
            return (f"warning: this run was not recorded in the history {where}: {self.reason}; its record is kept in "
                    f"'{self.spooled}' and is written there by the next run or 'glassdist history' that reaches it "
                    "(its outputs are complete; see docs/user-guide/history.md)")
        return (f"warning: this run was not recorded in the history {where}: {self.reason} (its outputs are complete; "
                "see docs/user-guide/history.md, or --no-history)")


def _write_waiting(loc: Location, db) -> tuple[int, int]:
    """Write the records waiting in the spool for ``loc``, then remove their files; ``(written, still waiting)``."""
    from . import spool

    pending, unreadable = spool.waiting(spool_dir(), loc)
    if pending:
        with open_store(db, write=True) as store:
            insert_runs(store, [entry for _, entry in pending])
        spool.discard(path for path, _ in pending)
    return len(pending), len(unreadable)


def record(summary: dict, *, exit_code: int, out_dir, recording: Recording | bool | None = None) -> Recorded:
    """Record one run in the history, or keep it in the spool; never raises.

    Called by the output stage once the run's files are written, so that a history that
    cannot be written (unreachable server, missing driver, missing or read-only folder,
    locked past the timeout, corrupted, of a newer schema) costs the run nothing: its
    record is kept in the spool (:mod:`~glassdist.history.spool`) and the returned
    :meth:`Recorded.line` says where. Records that waited in the spool for this database
    are written after this run's (in a transaction of their own, so that one that cannot
    be written never holds back the others' runs), each exactly once.

    Parameters
    ----------
    summary : dict
        The run's ``summary.json`` content, as written.
    exit_code : int
    out_dir : path
    recording : Recording or False, optional
        False (or ``enabled=False``): nothing recorded; None: ``Recording()``.

    Returns
    -------
    Recorded
    """
    if recording is None or recording is True:
        recording = Recording()
    if recording is False or not recording.enabled:
        return Recorded(None, reason="--no-history")
    where = recording.db if recording.db is not None else os.environ.get("GLASSDIST_DB", "")
    try:
        loc = locate(recording.db)
        if loc is None:
            return Recorded(None, reason=f"the history is off: {'--db' if recording.db is not None else 'GLASSDIST_DB'}"
                            f"={where}")
        entry = run_rows(summary, exit_code=exit_code, out_dir=out_dir, recording=recording)
    except Exception as exc:  # noqa: BLE001 - the history never costs a run its outputs or exit status
        return Recorded(Location(str(where), None), reason=describe_failure(exc))
    try:
        with open_store(recording.db, write=True) as store:
            run_id = insert_runs(store, [entry])[0]
    except Exception as exc:  # noqa: BLE001
        reason = describe_failure(exc)
        try:
            from . import spool

            return Recorded(loc, spooled=spool.keep(spool_dir(), loc, entry), reason=reason)
        except OSError as err:
            return Recorded(loc, reason=f"{reason}; nor could it be kept in the spool '{spool_dir()}' "
                            f"({err.strerror or err}), so it is lost")
    try:
        flushed, _ = _write_waiting(loc, recording.db)
    except Exception:  # noqa: BLE001 - they wait for the next run
        flushed = 0
    return Recorded(loc, run_id=run_id, flushed=flushed)


def record_run(summary: dict, *, exit_code: int, out_dir, recording: Recording = Recording(), warn=None) -> int | None:
    """Record one run in the history (:func:`record`); the new run's id, None when it is not in the database.

    A record that could not be written is kept in the spool, and ``warn`` receives the
    line saying where (default: printed on stderr).
    """
    outcome = record(summary, exit_code=exit_code, out_dir=out_dir, recording=recording)
    if outcome.warning:
        (warn or (lambda line: print(line, file=sys.stderr)))(outcome.line())
    return outcome.run_id


@dataclass(frozen=True)
class SpoolFlush:
    """The records waiting in the spool for one database: ``written`` now, ``waiting`` still (and why)."""

    location: Location | None
    written: int = 0
    waiting: int = 0
    reason: str | None = None

    def line(self) -> str | None:
        """A console line when there was anything to write, else None."""
        if self.written and not self.waiting:
            return f"history: {self.written} record(s) that waited in the spool written to '{self.location}'"
        if self.waiting:
            why = f": {self.reason}" if self.reason else " (unreadable spool files, left alone)"
            return (f"warning: {self.waiting} record(s) wait in the spool '{spool_dir()}' for '{self.location}'{why}; "
                    f"{self.written} written")
        return None


def flush_spool(db=None) -> SpoolFlush:
    """Write the records waiting in the spool for the database ``db`` (:func:`locate`); never raises."""
    from . import spool

    try:
        loc = locate(db)
    except Exception:  # noqa: BLE001
        return SpoolFlush(None)
    if loc is None:
        return SpoolFlush(None)
    try:
        written, unreadable = _write_waiting(loc, db)
    except Exception as exc:  # noqa: BLE001 - the records stay where they are
        pending, unreadable = spool.waiting(spool_dir(), loc)
        return SpoolFlush(loc, 0, len(pending) + len(unreadable), describe_failure(exc))
    return SpoolFlush(loc, written, unreadable)
