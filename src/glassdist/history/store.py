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

__all__ = ["HistoryUnavailable", "Location", "Recording", "data_dir", "locate", "open_store", "record_run",
           "run_rows", "insert_runs", "describe_failure", "Store"]

#: values of ``GLASSDIST_DB`` / ``--db`` that turn the history off
OFF = ("off", "none", "0", "false", "no")
#: schema revisions this glassdist can read and upgrade from, oldest first
KNOWN_REVISIONS = ("0001",)
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
        database's names are kept: ``valid_percent`` holds the summary's ``measured_percent``).
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
        "valid_percent": _finite(summary.get("measured_percent")), "measures": summary.get("measures"),
        "warnings": warnings, "out_dir": recording.out_dir or _path(out_dir, cwd),
        "glassdist_version": summary.get("glassdist_version") or __version__,
    }
    checks = []
    for c in verdict.get("checks") or []:
        zone = _ZONE_IN_CRITERION.search(str(c.get("criterion", "")))
        checks.append({"criterion": str(c.get("criterion", "")), "zone": zone.group(1) if zone else None,
                       "value": _finite(c.get("value")), "limit": _finite(c.get("limit")), "unit": c.get("unit"),
                       "passed": bool(c.get("passed")), "note": c.get("note") or None})
    stats = _stat_rows(REGION, a4.get("statistics"))
    for name, z in (summary.get("zones") or {}).items():
        stats += _stat_rows(str(name), z.get("statistics"))
        cov = _finite(z.get("trusted_percent"))
        if cov is not None:
            stats.append({"zone": str(name), "channel": "region", "statistic": "coverage_percent", "value": cov})
    return run, checks, stats


def insert_runs(store: Store, entries) -> list[int]:
    """Insert ``(run, checks, statistics)`` row sets (:func:`run_rows`) in one transaction; their new ids.

    The schema is checked (created, upgraded) in the same transaction, so a writer never
    sees a half-made database; the rows go in as bulk inserts (one statement per table).
    """
    from sqlalchemy import insert
    from sqlalchemy.orm import Session

    from .models import CheckRow, Run, StatisticRow

    entries = list(entries)
    with Session(store.engine) as session, session.begin():
        _ensure_schema(session.connection(), store.location)
        ids = list(session.scalars(insert(Run).returning(Run.id, sort_by_parameter_order=True),
                                   [run for run, _, _ in entries]))
        for model, k in ((CheckRow, 1), (StatisticRow, 2)):
            rows = [{**row, "run_id": rid} for rid, entry in zip(ids, entries) for row in entry[k]]
            if rows:
                session.execute(insert(model), rows)
        return ids


def describe_failure(exc: BaseException) -> str:
    """One line on why the history could not be used (no traceback, no SQL)."""
    if isinstance(exc, HistoryUnavailable):
        return str(exc)
    orig = getattr(exc, "orig", None) or exc
    text = str(orig).splitlines()[0] if str(orig) else type(orig).__name__
    if "locked" in text or "busy" in text:
        return f"the database stayed locked by another writer for {_timeout_s():g} s ({text})"
    if "not a database" in text or "malformed" in text:
        return f"the file is not a readable SQLite database ({text}); move it aside to start a new history"
    if "readonly" in text or "read-only" in text:
        return f"the database is read-only ({text})"
    return f"{type(orig).__name__}: {text}"


def record_run(summary: dict, *, exit_code: int, out_dir, recording: Recording = Recording(), warn=None) -> int | None:
    """Record one run in the history; never raises: a failure is one warning line.

    Called by the output stage once the run's files are written, so that a history that
    cannot be written (locked past the timeout, read-only, corrupted, missing folder)
    costs the run nothing but the warning: its folder and exit status stay its own.

    Parameters
    ----------
    summary : dict
        The run's ``summary.json`` content, as written.
    exit_code : int
    out_dir : path
    recording : Recording
    warn : callable, optional
        Receives the warning line (default: printed on stderr).

    Returns
    -------
    int or None
        The new run's id; None when the history is off or could not be written.
    """
    if not recording.enabled:
        return None
    warn = warn or (lambda line: print(line, file=sys.stderr))
    where = recording.db if recording.db is not None else os.environ.get("GLASSDIST_DB", "")
    try:
        loc = locate(recording.db)
        if loc is None:
            return None
        where = str(loc)
        entry = run_rows(summary, exit_code=exit_code, out_dir=out_dir, recording=recording)
        store = open_store(recording.db, write=True)
        with store:
            return insert_runs(store, [entry])[0]
    except Exception as exc:  # noqa: BLE001 - the history never costs a run its outputs or exit status
        warn(f"warning: this run was not recorded in the history '{where}': {describe_failure(exc)} "
             "(its outputs are complete; see docs/user-guide/history.md, or --no-history)")
        return None
