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
from glassdist.history import HistoryFilter, Recording, open_store, query_runs, record_run, trends
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


def _analyze(pane, out, *extra, spec="fail.json"):
    return main(["analyze", str(pane / "pane.png"), "--reference", str(pane / "reference.png"), "--pitch-mm", "2",
                 "--distance-m", "1", "--spec", str(pane / spec), "--out", str(out), "-q", *extra])


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
    if fault == "locked":  # the lock gone, the next run is recorded
        assert _analyze(pane, tmp_path / "next") == 3
        assert [Path(r["out_dir"]).name for r in _rows(db)] == ["first", "next"]


_KILLED_WRITER = """
import os, signal, sqlite3, sys
con = sqlite3.connect(sys.argv[1], isolation_level=None)
con.execute("BEGIN IMMEDIATE")
con.execute("INSERT INTO runs (recorded_utc, source, exit_code, pane_id) VALUES ('2020-01-01', 'cli', 0, 'ghost')")
con.execute("INSERT INTO statistics (run_id, zone, channel, statistic, value) VALUES (last_insert_rowid(), 'all', 'phi_eff', 'p95_abs', 1)")
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
    assert len(warnings) == 1 and "newer than this glassdist" in warnings[0]
    assert _rows(db) == before
    assert main(["history"]) == 2  # nor read


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
