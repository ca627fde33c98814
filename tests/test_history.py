"""The results history: what a run records, faults that must cost the run nothing, concurrent writers, queries."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import sqlite3
import subprocess
import sys
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest

from conftest import write_lens_pair
from glassdist.cli import main
from glassdist.history import HistoryFilter, open_store, query_runs, record_run, trends
from glassdist.history.models import REGION, SCHEMA_REVISION, Base
from glassdist.history.store import insert_runs, run_rows

PASS_SPEC = {"name": "loose", "protocol": {"distance_m": 1.0},
             "zones": [{"name": "edge", "edge_band_mm": 5}, {"name": "vision", "inset_mm": 5}],
             "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1000, "zone": "vision"}]}
# the lens reaches ~40 mD p95 in its vision zone: a 1 mD limit there fails, exit 3
FAIL_SPEC = {**PASS_SPEC, "name": "tight",
             "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1, "zone": "vision"}]}


@pytest.fixture(scope="module")
def pane(tmp_path_factory):
    """The small lens pair and two specifications (one passes, one fails its vision zone)."""
    root = write_lens_pair(tmp_path_factory.mktemp("history_pane"))
    (root / "pass.json").write_text(json.dumps(PASS_SPEC))
    (root / "fail.json").write_text(json.dumps(FAIL_SPEC))
    return root


@pytest.fixture()
def sqlite_db(tmp_path, monkeypatch):
    """A SQLite history file of the test's own (``GLASSDIST_DB``)."""
    path = tmp_path / "hist" / "history.sqlite"
    path.parent.mkdir()
    monkeypatch.setenv("GLASSDIST_DB", str(path))
    monkeypatch.setenv("GLASSDIST_DB_TIMEOUT_S", "0.5")
    return path


def _postgresql_database(request):
    """A new database on the server of ``GLASSDIST_TEST_PG_URL`` (dropped after the test); its URL."""
    import secrets

    import sqlalchemy as sa

    admin_url = os.environ.get("GLASSDIST_TEST_PG_URL")
    if not admin_url:
        pytest.skip("no PostgreSQL server: set GLASSDIST_TEST_PG_URL (scripts/test_postgres.sh starts one)")
    pytest.importorskip("psycopg", reason="the PostgreSQL history needs glassdist[postgresql]")
    url = sa.engine.make_url(admin_url)
    name = f"glassdist_test_{secrets.token_hex(4)}"
    admin = sa.create_engine(url, isolation_level="AUTOCOMMIT", poolclass=sa.pool.NullPool)
    with admin.connect() as conn:
        conn.execute(sa.text(f'CREATE DATABASE "{name}"'))

    def drop():
        with admin.connect() as conn:
            conn.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()

    request.addfinalizer(drop)
    return url.set(database=name).render_as_string(hide_password=False)


@pytest.fixture(params=["sqlite", "postgresql"])
def db(request, tmp_path, monkeypatch):
    """A history database of the test's own (``GLASSDIST_DB``): a SQLite file, or a PostgreSQL database
    when ``GLASSDIST_TEST_PG_URL`` names a server (skipped otherwise)."""
    if request.param == "sqlite":
        return request.getfixturevalue("sqlite_db")
    url = _postgresql_database(request)
    monkeypatch.setenv("GLASSDIST_DB", url)
    monkeypatch.setenv("GLASSDIST_DB_TIMEOUT_S", "0.5")
    return url


def _analyze(pane, out, *extra, spec="fail.json", quiet=True):
    return main(["analyze", str(pane / "pane.png"), "--reference", str(pane / "reference.png"), "--pitch-mm", "2",
                 "--distance-m", "1", "--spec", str(pane / spec), "--out", str(out), *(["-q"] if quiet else []),
                 *extra])


def _engine(db):
    import sqlalchemy as sa

    return sa.create_engine(f"sqlite:///{db}" if isinstance(db, Path) else db, poolclass=sa.pool.NullPool)


def _sql(db, query, **params):
    """Rows of plain SQL on the database (a reader independent of glassdist's), as dicts; JSON decoded."""
    import sqlalchemy as sa

    engine = _engine(db)
    try:
        with engine.connect() as conn:
            rows = [dict(r._mapping) for r in conn.execute(sa.text(query), params)]
    finally:
        engine.dispose()
    for r in rows:
        for k in ("protocol", "measures", "warnings"):
            if isinstance(r.get(k), str):
                r[k] = json.loads(r[k])
    return rows


def _rows(db):
    """Every run row."""
    return _sql(db, "SELECT * FROM runs ORDER BY id")


@pytest.fixture(scope="module")
def summary(pane, tmp_path_factory):
    """A real run's summary.json (for the tests that record without analysing again)."""
    out = tmp_path_factory.mktemp("history_summary") / "out"
    assert _analyze(pane, out, "--no-history", "--pane-id", "S-1", "--lot", "L-1") == 3
    return {**json.loads((out / "summary.json").read_text()), "_folder": str(out)}


def test_a_run_is_recorded_once_with_its_ids_hashes_protocol_verdict_and_zones(pane, db, tmp_path):
    out = tmp_path / "out"
    assert _analyze(pane, out, "--pane-id", "P-7", "--lot", "L42", "--site", "line 2", "--operator", "ana") == 3
    s = json.loads((out / "summary.json").read_text())
    (run,) = _rows(db)
    assert (run["pane_id"], run["lot"], run["site"], run["operator"], run["source"]) == ("P-7", "L42", "line 2", "ana", "cli")
    assert run["image_sha256"] == hashlib.sha256((pane / "pane.png").read_bytes()).hexdigest()
    assert run["reference_sha256"] == hashlib.sha256((pane / "reference.png").read_bytes()).hexdigest()
    assert Path(run["out_dir"]) == out.absolute() and run["exit_code"] == 3 and run["verdict"] == "FAIL"
    assert (run["method"], run["pitch_mm"], run["distance_m"], run["detrend_degree"]) == ("comparative", 2.0, 1.0, 2)
    assert run["sigma_mm"] == pytest.approx(s["sigma_mm"]) and run["protocol"] == s["protocol"]
    assert run["measures"] == s["measures"]
    checks = _sql(db, "SELECT criterion, zone, passed FROM checks WHERE run_id = :r ORDER BY id", r=run["id"])
    stats = {(r["zone"], r["channel"], r["statistic"]): r["value"] for r in _sql(
        db, "SELECT zone, channel, statistic, value FROM statistics WHERE run_id = :r", r=run["id"])}
    assert [c["criterion"] for c in checks] == [c["criterion"] for c in s["verdict"]["checks"]]
    assert [c["zone"] for c in checks if not c["passed"]] == ["vision"]  # the zone of the failed criterion
    # every finite per-zone statistic of summary.json, and the whole region's, under its zone
    for zone, z in s["zones"].items():
        for ch, values in z["statistics"].items():
            for name, v in values.items():
                if v is not None:
                    assert stats[(zone, ch, name)] == pytest.approx(v)
        assert stats[(zone, "region", "coverage_percent")] == pytest.approx(z["trusted_percent"])
    assert stats[(REGION, "phi_eff", "p95_abs")] == pytest.approx(s["a4"]["statistics"]["phi_eff"]["p95_abs"])


def test_a_rerun_is_a_new_row_and_earlier_rows_never_change(pane, db, tmp_path):
    assert _analyze(pane, tmp_path / "a", "--pane-id", "P-1", spec="pass.json") == 0
    first = _rows(db)
    assert _analyze(pane, tmp_path / "a", "--pane-id", "P-1", spec="pass.json") == 0
    rows = _rows(db)
    assert len(rows) == 2 and rows[0] == first[0] and rows[1]["id"] > rows[0]["id"]
    assert rows[1]["image_sha256"] == rows[0]["image_sha256"] and rows[1]["verdict"] == "PASS"


def test_no_history_and_off_record_nothing(pane, sqlite_db, tmp_path, monkeypatch, summary):
    db = sqlite_db
    assert _analyze(pane, tmp_path / "a", "--no-history") == 3
    assert not db.exists()
    monkeypatch.setenv("GLASSDIST_DB", "off")
    assert record_run(summary, exit_code=3, out_dir=tmp_path) is None
    assert not db.exists()


def test_the_default_database_is_in_the_data_folder_of_xdg_data_home(tmp_path, monkeypatch, summary):
    monkeypatch.delenv("GLASSDIST_DB")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert record_run(summary, exit_code=3, out_dir=tmp_path) == 1
    assert [r["pane_id"] for r in _rows(tmp_path / "xdg" / "glassdist" / "history.sqlite")] == ["S-1"]
    from glassdist.history import record

    line = record(summary, exit_code=3, out_dir=tmp_path).line()  # the console names the default file
    assert line == (f"history: recorded as run 2 in '{tmp_path / 'xdg' / 'glassdist' / 'history.sqlite'}' (the default "
                    "history file; --db PATH|URL or GLASSDIST_DB chooses another)")


def _read_only(path, monkeypatch):
    """Make the database file read-only; as root (whom permissions do not stop), open it through SQLite read-only."""
    if os.geteuid() != 0:
        path.chmod(0o444)
        path.parent.chmod(0o555)
        return
    from glassdist.history import store

    connect = store._sqlite_connect
    monkeypatch.setattr(store, "_sqlite_connect", lambda uri, timeout: connect(uri + "?mode=ro", timeout))


@pytest.mark.parametrize("fault", ["corrupted", "read-only", "missing folder", "locked"])
def test_a_broken_database_costs_the_run_nothing_but_one_warning_line(pane, summary, sqlite_db, tmp_path, monkeypatch,
                                                                        capsys, fault):
    db = sqlite_db
    base = Path(summary["_folder"])  # the same run without the history
    holder = None
    if fault == "corrupted":
        db.write_bytes(b"this is not a database\n" * 200)
    elif fault == "missing folder":
        monkeypatch.setenv("GLASSDIST_DB", str(tmp_path / "no such folder" / "history.sqlite"))
    else:
        assert record_run(summary, exit_code=3, out_dir=tmp_path / "first") == 1  # a good database with one run
        if fault == "read-only":
            _read_only(db, monkeypatch)
        else:  # another writer holds the write lock for longer than the busy timeout
            holder = sqlite3.connect(db, isolation_level=None)
            holder.execute("BEGIN IMMEDIATE")
    before = db.read_bytes() if db.exists() else None
    try:
        code = _analyze(pane, tmp_path / "out")
    finally:
        if holder is not None:
            holder.rollback()
            holder.close()
        db.parent.chmod(0o755)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3
    assert len(err) == 1 and err[0].startswith("warning: this run was not recorded in the history"), err
    base_summary = json.loads((base / "summary.json").read_text())
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(p.name for p in base.iterdir())
    assert summary["outputs"].keys() == base_summary["outputs"].keys()
    assert summary["statistics"] == base_summary["statistics"] and summary["verdict"] == base_summary["verdict"]
    if fault in ("corrupted", "read-only"):
        assert db.read_bytes() == before
    assert "its record is kept in" in err[0]  # the record waits in the spool
    if fault == "locked":  # the lock gone, the next run is recorded, and the one that waited with it
        assert _analyze(pane, tmp_path / "next") == 3
        assert [Path(r["out_dir"]).name for r in _rows(db)] == ["first", "next", "out"]


_KILLED_WRITER = """
import os, signal, sqlite3, sys
con = sqlite3.connect(sys.argv[1], isolation_level=None)
con.execute("BEGIN IMMEDIATE")
con.execute("INSERT INTO runs (recorded_utc, source, exit_code, pane_id) VALUES ('2020-01-01', 'cli', 0, 'ghost')")
con.execute("INSERT INTO statistics (run_id, zone, channel, statistic, value) "
            "VALUES (last_insert_rowid(), 'all', 'phi_eff', 'p95_abs', 1)")
print("in transaction", flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


_KILLED_WRITER_PG = """
import os, signal, sys
import sqlalchemy as sa
engine = sa.create_engine(sys.argv[1])
conn = engine.connect()
conn.execute(sa.text("SELECT pg_advisory_xact_lock(%d)"))  # the lock every writer takes first
conn.execute(sa.text("INSERT INTO runs (recorded_utc, source, exit_code, pane_id) VALUES ('2020-01-01', 'cli', 0, 'ghost')"))
print("in transaction", flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_writer_killed_mid_transaction_leaves_the_database_readable_and_the_next_run_recorded(db, summary, tmp_path,
                                                                                               monkeypatch):
    from glassdist.history.store import _PG_LOCK_KEY

    assert record_run(summary, exit_code=3, out_dir=tmp_path) == 1
    script = _KILLED_WRITER if isinstance(db, Path) else _KILLED_WRITER_PG % _PG_LOCK_KEY
    proc = subprocess.run([sys.executable, "-c", script, str(db)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == -9 and "in transaction" in proc.stdout, proc.stderr
    if isinstance(db, Path):
        with sqlite3.connect(db) as con:
            assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    # SQLite's lock went with the process; a server rolls back when it sees the client gone (a moment)
    monkeypatch.setenv("GLASSDIST_DB_TIMEOUT_S", "10")
    assert [r["pane_id"] for r in _rows(db)] == ["S-1"]  # the killed transaction left nothing
    warnings = []
    assert record_run(summary, exit_code=3, out_dir=tmp_path, warn=warnings.append) > 1  # (a server's ids may skip)
    assert warnings == [] and [r["pane_id"] for r in _rows(db)] == ["S-1", "S-1"]


def test_the_schema_is_the_alembic_revision_and_matches_the_models(db, summary, tmp_path):
    import sqlalchemy as sa

    record_run(summary, exit_code=3, out_dir=tmp_path)
    engine = _engine(db)
    with engine.connect() as conn:
        assert conn.execute(sa.text("SELECT version_num FROM alembic_version")).scalar() == SCHEMA_REVISION
        insp = sa.inspect(conn)
        for table in Base.metadata.sorted_tables:
            assert {c["name"] for c in insp.get_columns(table.name)} == set(table.columns.keys()), table.name
            assert {tuple(i["column_names"]) for i in insp.get_indexes(table.name)} == \
                {tuple(c.name for c in i.columns) for i in table.indexes}, table.name
    engine.dispose()


def test_a_database_of_a_newer_schema_is_refused_and_left_alone(db, summary, tmp_path):
    record_run(summary, exit_code=3, out_dir=tmp_path)
    engine = _engine(db)
    with engine.begin() as conn:
        conn.exec_driver_sql("UPDATE alembic_version SET version_num = '9999'")
    engine.dispose()
    before = _rows(db)
    warnings = []
    assert record_run(summary, exit_code=3, out_dir=tmp_path, warn=warnings.append) is None
    assert len(warnings) == 1 and "newer than this glassdist" in warnings[0] and "kept in" in warnings[0]
    assert _rows(db) == before
    assert main(["history"]) == 2  # nor read
    assert _rows(db) == before  # nor written by the reader's attempt to write what waits in the spool


def test_history_command_on_a_corrupted_database_is_one_line_exit_2(sqlite_db, capsys):
    sqlite_db.write_bytes(b"this is not a database\n" * 200)
    assert main(["history", "--db", str(sqlite_db)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a readable SQLite database" in err


# ---------------------------------------------------------------- queries, exports and the control chart

T0 = datetime(2026, 3, 2, 8, 0, 0)
#: lot A: 20 runs alternating 10 +- 0.1 mD and one at 30 mD (run 12); lot B: 5 runs at 50 mD + 1, 2, 3...
LOT_A = [10.0 + (0.1 if i % 2 else -0.1) for i in range(20)]
LOT_A.insert(11, 30.0)
LOT_B = [51.0, 52.0, 53.0, 54.0, 55.0]


def _synthetic(summary, value, lot, when, *, site="north", verdict="PASS", edge_failed=False):
    s = json.loads(json.dumps(summary))
    del s["_folder"]
    s["metadata"] = {"pane_id": f"{lot}-{when:%d%H%M}", "lot": lot, "site": site}
    s["a4"]["statistics"]["phi_eff"]["p95_abs"] = value
    s["zones"]["edge"]["statistics"]["phi_shear"]["max_abs"] = 2 * value
    s["verdict"]["result"] = verdict
    s["verdict"]["checks"] = [{"criterion": "p95 |phi_shear| in zone 'edge' <= 100 mD", "value": 2 * value,
                               "limit": 100.0, "unit": "mD", "comparison": "<=", "passed": not edge_failed}]
    return run_rows(s, exit_code=0 if verdict == "PASS" else 3, out_dir=Path("/x") / lot, recorded_utc=when)


@pytest.fixture()
def filled(db, summary):
    entries = [_synthetic(summary, v, "A", T0 + timedelta(hours=i)) for i, v in enumerate(LOT_A)]
    entries += [_synthetic(summary, v, "B", T0 + timedelta(days=3, hours=i), site="south", verdict="FAIL",
                           edge_failed=v > 52) for i, v in enumerate(LOT_B)]
    store = open_store(write=True)
    with store:
        insert_runs(store, entries)
    return db


def test_filters_select_exactly_the_runs_asked_for(filled):
    with open_store() as store:
        def ids(**kw):
            return [r["run"] for r in query_runs(store, HistoryFilter.of(**kw))]

        assert ids(lot="A") == list(range(1, 22))
        assert ids(site="south") == ids(verdict="FAIL") == list(range(22, 27))
        assert ids(since="2026-03-05") == list(range(22, 27))
        assert ids(until="2026-03-02") == list(range(1, 17))  # 08:00 + 0..15 h is still March 2nd
        assert ids(failed_zone="edge") == [24, 25, 26]  # 53, 54, 55 mD: 2x over the 100 mD edge limit
        assert ids(zone="edge", statistic="phi_shear.max_abs", above=106.5) == [25, 26]
        assert ids(statistic="phi_eff.p95_abs", below=10.0) == [i + 1 for i, v in enumerate(LOT_A) if v < 10]
        assert ids(limit=2) == [25, 26]
        rec = query_runs(store, HistoryFilter.of(lot="A", zone="edge", statistic="phi_shear.max_abs"))
    assert [r["value"] for r in rec] == pytest.approx([2 * v for v in LOT_A])
    assert [r["phi_eff_p95_abs_mD"] for r in rec] == pytest.approx(LOT_A)


def test_the_control_chart_marks_the_runs_beyond_three_sigma(filled):
    import statistics

    with open_store() as store:
        found = {t.lot: t for t in trends(query_runs(store, HistoryFilter()))}
    for lot, values in (("A", LOT_A), ("B", LOT_B)):
        mean, sd = statistics.fmean(values), statistics.stdev(values)
        t = found[lot]
        assert (t.mean, t.sigma) == pytest.approx((mean, sd))
        assert list(np.flatnonzero(t.out)) == [i for i, v in enumerate(values) if abs(v - mean) > 3 * sd]
    assert list(np.flatnonzero(found["A"].out)) == [11] and not found["B"].out.any()


def test_history_command_exports_csv_json_and_draws_the_chart(filled, tmp_path, capsys):
    assert main(["history", "--lot", "B", "--format", "json"]) == 0
    runs = json.loads(capsys.readouterr().out)
    assert [r["value"] for r in runs] == LOT_B and {r["lot"] for r in runs} == {"B"}
    out, chart = tmp_path / "a.csv", tmp_path / "a.png"
    assert main(["history", "--verdict", "pass", "--format", "csv", "--out", str(out), "--chart", str(chart)]) == 0
    err = capsys.readouterr().err
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert [float(r["value"]) for r in rows] == pytest.approx(LOT_A)
    assert chart.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "1 run(s) beyond ±3σ" in err
    assert main(["history", "--format", "csv", "--out", str(out)]) == 2  # never overwrites a file
    assert "already exists" in capsys.readouterr().err
    assert main(["history", "--since", "last monday"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert main(["history", "--statistic", "p95"]) == 2


def test_python_api_returns_records_without_pandas(filled, monkeypatch):
    import glassdist

    monkeypatch.setitem(sys.modules, "pandas", None)  # as where pandas is not installed
    runs = glassdist.history(lot="A", verdict="PASS")
    assert isinstance(runs, list) and [r["value"] for r in runs] == pytest.approx(LOT_A)
    with pytest.raises(ImportError):
        glassdist.history(lot="A", as_frame=True)
    with pytest.raises(glassdist.InputError, match="unknown history filter"):
        glassdist.history(colour="red")


def test_python_api_write_report_is_recorded_as_an_api_run(pane, db, tmp_path):
    import glassdist

    res = glassdist.analyze(str(pane / "pane.png"), pitch_mm=2.0, distance_m=1.0, reference=str(pane / "reference.png"))
    glassdist.write_report(res, tmp_path / "r", pane_id="P-9", lot="L9", image=pane / "pane.png")
    (run,) = glassdist.history(as_frame=False)
    assert (run["source"], run["pane_id"], run["lot"], run["verdict"]) == ("api", "P-9", "L9", None)
    assert Path(run["out_dir"]) == (tmp_path / "r").absolute()


def test_batch_records_each_pane_with_its_manifest_lot_into_db_and_not_with_no_history(tmp_path, monkeypatch,
                                                                                       sqlite_db):
    manifest = _tiny_panes(tmp_path / "in", 1, "L5")
    other = tmp_path / "other.sqlite"
    assert main(["batch", str(manifest), "--out", str(tmp_path / "b1"), "--no-progress", "--db", str(other)]) == 0
    assert os.environ["GLASSDIST_DB"] == str(sqlite_db)  # the batch's --db was for its panes only
    (run,) = _rows(other)
    assert (run["source"], run["pane_id"], run["lot"], run["job"]) == ("batch", "L5-0", "L5", str(tmp_path / "b1"))
    assert main(["batch", str(manifest), "--out", str(tmp_path / "b2"), "--no-progress", "--no-history"]) == 0
    assert len(_rows(other)) == 1 and not sqlite_db.exists()


def test_a_batch_says_which_panes_wait_in_the_spool_and_the_history_command_writes_them(tmp_path, own_data, capsys):
    manifest = _tiny_panes(tmp_path / "in", 2, "L6")
    db = tmp_path / "later" / "history.sqlite"  # its folder does not exist yet
    assert main(["batch", str(manifest), "--out", str(tmp_path / "b"), "--no-progress", "--db", str(db)]) == 0
    out = capsys.readouterr().out
    assert sum("this run was not recorded in the history" in line and "kept in" in line
               for line in out.splitlines()) == 2, out
    assert len(_spooled(tmp_path)) == 2
    pane = json.loads((tmp_path / "b" / "panes" / "L6-0" / "pane.json").read_text())
    assert pane["history"].startswith("warning: this run was not recorded")
    db.parent.mkdir()
    assert main(["history", "--db", str(db), "--format", "json"]) == 0
    runs = json.loads(capsys.readouterr().out)
    assert sorted(r["pane_id"] for r in runs) == ["L6-0", "L6-1"] and {r["source"] for r in runs} == {"batch"}
    assert {Path(r["out_dir"]) for r in runs} == {tmp_path / "b" / "panes" / "L6-0", tmp_path / "b" / "panes" / "L6-1"}
    assert _spooled(tmp_path) == []


# ---------------------------------------------------------------- concurrent writers


def _tiny_panes(root, n, lot):
    """``n`` tiny panes (64 x 64 px, each a slightly different lens) and their manifest."""
    from glassdist.io import write_png16
    from glassdist.synthetic import lens_displacement, synthetic_capture

    root.mkdir()
    lines = ["id,image,reference,pitch_mm,distance_m,sigma_mm,lot"]
    for i in range(n):
        cap = synthetic_capture((64, 64), pitch_mm=2.0, mm_per_px=0.25,
                                displacement=lens_displacement(0.02 + 0.005 * i, 1.0, radius_mm=4.0), rng=i)
        write_png16(root / f"p{i}.png", cap.image)
        write_png16(root / f"r{i}.png", cap.reference)
        lines.append(f"{lot}-{i},p{i}.png,r{i}.png,2,1,2,{lot}")
    (root / "manifest.csv").write_text("\n".join(lines) + "\n")
    return root / "manifest.csv"


@pytest.mark.slow
def test_concurrent_batches_and_dask_workers_record_every_pane_exactly_once(db, tmp_path, monkeypatch):
    pytest.importorskip("distributed", reason="the Dask batch needs glassdist[distributed]")
    monkeypatch.setenv("GLASSDIST_DB_TIMEOUT_S", "60")
    jobs = {"one": (4, []), "two": (4, []), "dask": (2, ["--workers", "2"])}
    procs = {}
    for name, (n, extra) in jobs.items():
        manifest = _tiny_panes(tmp_path / f"in-{name}", n, name)
        procs[name] = subprocess.Popen([sys.executable, "-m", "glassdist", "batch", str(manifest), "--out",
                                        str(tmp_path / name), "--no-progress", *extra],
                                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for name, proc in procs.items():
        log = proc.communicate(timeout=600)[0]
        assert proc.returncode == 0, log
    rows = _rows(db)
    for name, (n, _) in jobs.items():
        index = list(csv.DictReader((tmp_path / name / "index.csv").open()))
        assert [r["status"] for r in index] == ["done"] * n
        mine = [r for r in rows if r["job"] == str(tmp_path / name)]
        assert len(mine) == n
        assert sorted(r["pane_id"] for r in mine) == sorted(r["id"] for r in index)  # each exactly once
        for r in mine:
            assert (r["source"], r["lot"]) == ("batch", name)
            assert Path(r["out_dir"]) == tmp_path / name / "panes" / r["pane_id"]
            assert Path(r["out_dir"], "summary.json").is_file()
            summary = json.loads(Path(r["out_dir"], "summary.json").read_text())
            assert r["image_sha256"] == summary["inputs"]["image_sha256"]
    assert len(rows) == sum(n for n, _ in jobs.values())


# ---------------------------------------------------------------- the spool: a record never lost


def _spooled(tmp_path):
    """The spool files of the test's data folder (``XDG_DATA_HOME=tmp_path/data``)."""
    return sorted((tmp_path / "data" / "glassdist" / "spool").glob("*/*.json"))


@pytest.fixture()
def own_data(tmp_path, monkeypatch):
    """The user's data folder (and so the spool) of the test's own."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    return tmp_path / "data"


@pytest.mark.parametrize("fault", ["missing folder", "read-only"])
def test_an_unreachable_sqlite_history_keeps_the_record_and_the_next_run_writes_it_once(
        pane, own_data, tmp_path, monkeypatch, capsys, fault):
    db = tmp_path / "hist" / "history.sqlite"
    monkeypatch.setenv("GLASSDIST_DB", str(db))
    if fault == "read-only":
        db.parent.mkdir()
        assert record_run(_summary_of(pane, tmp_path), exit_code=3, out_dir=tmp_path / "first") == 1
        _read_only(db, monkeypatch)
    assert _analyze(pane, tmp_path / "lost?", "--pane-id", "P-S") == 3  # the run succeeds (its FAIL verdict)
    err = capsys.readouterr().err.strip().splitlines()
    (kept,) = _spooled(tmp_path)
    assert len(err) == 1 and err[0].startswith("warning: this run was not recorded") and str(kept) in err[0], err
    assert json.loads(kept.read_text())["target"] == str(db)
    # the database reachable again: the next run writes its record and the one that waited, which leaves the spool
    if fault == "missing folder":
        db.parent.mkdir()
    else:
        monkeypatch.undo()
        monkeypatch.setenv("XDG_DATA_HOME", str(own_data))
        monkeypatch.setenv("GLASSDIST_DB", str(db))
        db.parent.chmod(0o755)
        db.chmod(0o644)
    assert _analyze(pane, tmp_path / "next", "--pane-id", "P-N", spec="pass.json", quiet=False) == 0
    out = capsys.readouterr().out
    assert "history: recorded as run" in out and "1 record(s) that waited in the spool" in out and str(db) in out
    rows = _rows(db)
    assert sorted(r["pane_id"] for r in rows if r["pane_id"] != "S-1") == ["P-N", "P-S"] and _spooled(tmp_path) == []
    assert len({r["record_id"] for r in rows}) == len(rows)
    waited = next(r for r in rows if r["pane_id"] == "P-S")
    assert Path(waited["out_dir"]).name == "lost?" and waited["verdict"] == "FAIL"


def _summary_of(pane, tmp_path):
    out = tmp_path / "base"
    assert _analyze(pane, out, "--no-history", "--pane-id", "S-1") == 3
    return json.loads((out / "summary.json").read_text())


def test_a_writer_stopped_between_its_commit_and_the_spool_cleanup_writes_nothing_twice(pane, own_data, tmp_path,
                                                                                      monkeypatch, capsys):
    from glassdist.history import spool

    db = tmp_path / "hist" / "history.sqlite"
    monkeypatch.setenv("GLASSDIST_DB", str(db))
    summary = _summary_of(pane, tmp_path)
    warnings = []
    assert record_run(summary, exit_code=3, out_dir=tmp_path / "a", warn=warnings.append) is None  # no folder yet
    assert record_run(summary, exit_code=3, out_dir=tmp_path / "b", warn=warnings.append) is None
    assert len(warnings) == 2 and len(_spooled(tmp_path)) == 2
    db.parent.mkdir()
    with monkeypatch.context() as m:  # the records are committed, the process "dies" before removing their files
        m.setattr(spool, "discard", lambda paths: None)
        assert main(["history", "--format", "json"]) == 0
    assert [Path(r["out_dir"]).name for r in json.loads(capsys.readouterr().out)] == ["a", "b"]
    assert len(_spooled(tmp_path)) == 2  # still there
    assert record_run(summary, exit_code=3, out_dir=tmp_path / "c") == 3  # written again: skipped, files removed
    assert [Path(r["out_dir"]).name for r in _rows(db)] == ["a", "b", "c"] and _spooled(tmp_path) == []
    assert main(["history", "--format", "json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 3


def test_a_record_written_twice_is_one_row(db, summary, tmp_path):
    entry = run_rows(summary, exit_code=3, out_dir=tmp_path)
    with open_store(write=True) as store:
        first = insert_runs(store, [entry, entry])
    with open_store(write=True) as store:
        again = insert_runs(store, [entry])
    assert first == [first[0], first[0]] and again == first[:1] and len(_rows(db)) == 1


def test_a_missing_database_driver_keeps_the_record_until_it_is_installed(request, summary, own_data, tmp_path,
                                                                         monkeypatch):
    db = _postgresql_database(request)  # a SQLite history needs no driver of its own
    monkeypatch.setenv("GLASSDIST_DB", db)
    warnings = []
    with monkeypatch.context() as m:
        m.setitem(sys.modules, "psycopg", None)  # as where glassdist[postgresql] is not installed
        assert record_run(summary, exit_code=3, out_dir=tmp_path / "a", warn=warnings.append) is None
    assert len(warnings) == 1 and "driver is not installed" in warnings[0] and len(_spooled(tmp_path)) == 1
    assert "://" in warnings[0] and "glassdist@" in warnings[0]  # the URL it is for (a password would be masked)
    assert record_run(summary, exit_code=3, out_dir=tmp_path / "b") is not None
    assert sorted(Path(r["out_dir"]).name for r in _rows(db)) == ["a", "b"] and _spooled(tmp_path) == []


@pytest.fixture()
def stoppable_pg(tmp_path):
    """A PostgreSQL server of the test's own (scripts/test_postgres.sh), to stop and start again; ``(url, stop, resume)``.

    Runs where ``GLASSDIST_TEST_PG_URL`` says PostgreSQL is there (the CI's server is shared, never stopped)."""
    import tempfile

    if not os.environ.get("GLASSDIST_TEST_PG_URL"):
        pytest.skip("no PostgreSQL server: set GLASSDIST_TEST_PG_URL (scripts/test_postgres.sh starts one)")
    pytest.importorskip("psycopg", reason="the PostgreSQL history needs glassdist[postgresql]")
    script = Path(__file__).parents[1] / "scripts" / "test_postgres.sh"
    root = Path(tempfile.mkdtemp(prefix="gd-pg-"))  # short: a Unix socket's path is at most 107 bytes
    root.chmod(0o755)  # the server's own user must reach its folder
    folder = root / "pg"

    def call(cmd):
        return subprocess.run(["bash", str(script), cmd, str(folder)], capture_output=True, text=True, timeout=120,
                              check=True).stdout.strip()

    url = call("start")
    state = {"up": True}

    def stop():
        call("stop")
        state["up"] = False

    def resume():
        call("resume")
        state["up"] = True

    yield url, stop, resume
    if state["up"]:
        call("stop")
    subprocess.run(["rm", "-rf", str(root)], check=False)


def test_a_stopped_postgresql_server_keeps_the_record_and_writes_it_once_when_back(pane, stoppable_pg, own_data,
                                                                                  tmp_path, monkeypatch, capsys):
    url, stop, resume = stoppable_pg
    monkeypatch.setenv("GLASSDIST_DB", url)
    monkeypatch.setenv("GLASSDIST_DB_TIMEOUT_S", "2")
    assert _analyze(pane, tmp_path / "before", "--pane-id", "P-1", quiet=False) == 3
    assert "history: recorded as run 1" in capsys.readouterr().out
    stop()
    assert _analyze(pane, tmp_path / "down", "--pane-id", "P-2") == 3  # the run succeeds without its server
    err = capsys.readouterr().err.strip().splitlines()
    (kept,) = _spooled(tmp_path)
    assert len(err) == 1 and "not recorded in the history 'postgresql+psycopg://glassdist@" in err[0], err
    assert str(kept) in err[0] and (tmp_path / "down" / "summary.json").is_file()
    resume()
    assert main(["history", "--format", "json"]) == 0  # the reader that reaches it writes what waited
    io_ = capsys.readouterr()
    assert "1 record(s) that waited in the spool written" in io_.err
    assert [r["pane_id"] for r in json.loads(io_.out)] == ["P-1", "P-2"] and _spooled(tmp_path) == []
    assert _analyze(pane, tmp_path / "after", "--pane-id", "P-3") == 3
    rows = _rows(url)
    assert sorted(r["pane_id"] for r in rows) == ["P-1", "P-2", "P-3"]  # each once
    assert Path(next(r for r in rows if r["pane_id"] == "P-2")["out_dir"]) == (tmp_path / "down").absolute()


def test_an_old_database_is_upgraded_in_place_and_keeps_its_runs(summary, sqlite_db, tmp_path):
    """A history of schema 0001 (before record ids) gets the new columns; its runs stay as they were."""
    from alembic import command
    from alembic.config import Config

    from glassdist.history import store as store_module

    engine = _engine(sqlite_db)
    with engine.begin() as conn:
        cfg = Config()
        cfg.set_main_option("script_location", str(Path(store_module.__file__).with_name("migrations")))
        cfg.attributes["connection"] = conn
        command.upgrade(cfg, "0001")
        conn.exec_driver_sql("INSERT INTO runs (recorded_utc, source, exit_code, pane_id) "
                             "VALUES ('2025-01-01 00:00:00', 'cli', 0, 'old')")
    engine.dispose()
    assert record_run(summary, exit_code=3, out_dir=tmp_path) == 2
    rows = _rows(sqlite_db)
    assert [(r["pane_id"], r["record_id"] is None) for r in rows] == [("old", True), ("S-1", False)]
    assert rows[1]["trusted_percent"] == pytest.approx(summary["trusted_percent"])


# ---------------------------------------------------------------- the export's columns and the control chart


def _documented_columns() -> list[str]:
    """The column names of the table "What a run records" in docs/user-guide/history.md."""
    import re

    text = (Path(__file__).parents[1] / "docs" / "user-guide" / "history.md").read_text()
    table = text.split("## What a run records", 1)[1].split("\n\n", 2)[1]
    names = []
    for line in table.splitlines()[2:]:
        names += re.findall(r"`([a-z_0-9]+)`", line.split("|")[1])
    return names


def test_the_export_carries_every_documented_column_and_the_trusted_share(pane, db, tmp_path, capsys):
    from glassdist.history import COLUMNS

    documented = _documented_columns()
    assert {"reference", "reference_sha256", "protocol", "measures", "spec_sha256", "valid_percent"} <= set(documented)
    assert _analyze(pane, tmp_path / "out", "--pane-id", "P-E") == 3
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    capsys.readouterr()
    assert main(["history", "--format", "csv"]) == 0
    (row,) = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert main(["history", "--format", "json"]) == 0
    (rec,) = json.loads(capsys.readouterr().out)
    assert list(row) == list(rec) == list(COLUMNS)
    missing = [c for c in documented + ["trusted_percent"] if c not in COLUMNS]
    assert missing == []
    assert rec["reference"] == str((pane / "reference.png").absolute())
    assert rec["reference_sha256"] == hashlib.sha256((pane / "reference.png").read_bytes()).hexdigest()
    assert rec["spec_sha256"] == s["verdict"]["spec_sha256"] and rec["protocol"] == s["protocol"]
    assert rec["measures"] == s["measures"] and json.loads(row["measures"]) == s["measures"]
    # the trusted share (that the verdict judges) beside the measured share; they differ on this pane
    assert rec["trusted_percent"] == pytest.approx(s["trusted_percent"]) and float(row["trusted_percent"]) == \
        pytest.approx(s["trusted_percent"])
    assert rec["valid_percent"] == pytest.approx(s["measured_percent"])
    assert rec["trusted_percent"] < rec["valid_percent"]


def _chart_records(values, statistic="phi_eff.p95_abs", lot="L"):
    return [{"run": i + 1, "recorded_utc": f"2026-03-02T08:{i:02d}:00", "lot": lot, "pane_id": f"P-{i + 1:03d}",
             "statistic": statistic, "value": v} for i, v in enumerate(values)]


def test_control_limits_stay_inside_the_statistics_range():
    # a non-negative statistic spread widely near zero: mean - 3 s is below 0 mD
    (t,) = trends(_chart_records([1.0, 2.0, 40.0, 3.0, 1.0, 2.0]))
    assert t.mean - 3 * t.sigma < 0 and t.lower == 0.0 and t.upper == pytest.approx(t.mean + 3 * t.sigma)
    assert (t.unit, t.statistic, t.pane_ids[0]) == ("mD", "phi_eff.p95_abs", "P-001")
    (c,) = trends(_chart_records([99.0, 99.5, 100.0, 60.0, 99.9], statistic="region.coverage_percent"))
    assert c.upper == 100.0 and c.unit == "%" and c.lower == pytest.approx(c.mean - 3 * c.sigma)
    (m,) = trends(_chart_records([1.0, -2.0, 30.0, -3.0], statistic="phi_eff.mean"))  # signed: not clipped
    assert m.lower == pytest.approx(m.mean - 3 * m.sigma) and m.lower < 0


def test_the_control_chart_numbers_runs_in_integers_labelled_by_pane_with_units():
    from glassdist.history import plot_trends

    few = trends(_chart_records([1.0, 2.0, 40.0, 3.0, 1.0, 2.0]))
    fig = plot_trends(few, label="phi_eff.p95_abs (all)")
    ax = fig.axes[0]
    ticks = ax.get_xticks()
    assert list(ticks) == [1, 2, 3, 4, 5, 6] and [x.get_text() for x in ax.get_xticklabels()] == \
        [f"P-{i:03d}" for i in range(1, 7)]
    assert ax.get_ylabel() == "phi_eff.p95_abs (all) [mD]" and "σ = 15.6 mD" in ax.get_title(loc="left")
    dashed = [line.get_ydata()[0] for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert min(dashed) == 0.0  # the lower limit drawn at the statistic's bound, not at mean - 3 s < 0
    many = trends(_chart_records(list(np.linspace(10, 20, 200))))
    ax = plot_trends(many, label="v").axes[0]
    ticks = ax.get_xticks()
    assert len(ticks) <= 30 and all(float(x).is_integer() for x in ticks)
    assert [x.get_text() for x in ax.get_xticklabels()][:2] == ["P-001", f"P-{int(ticks[1]):03d}"]
