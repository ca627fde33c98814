"""The results history at scale: 10 000 recorded runs, a filtered query and one lot's control chart.

A temporary SQLite history is filled with synthetic runs shaped like real ones: each run's
rows come from :func:`glassdist.history.store.run_rows` on a ``summary.json``-like record
(the whole region and two zones, three channels, seven statistics each, the zones'
coverage, two checks), 50 lots of 200 runs over 100 days, three sites. Then, each timed
``--repeat`` times in this process (the median and the worst are reported):

* ``query``: :func:`~glassdist.history.query_runs` of one lot, one site, PASS only, since a
  date, with a zone's statistic as the value (what ``glassdist history --lot ... --zone
  vision --statistic phi_shear.p95_abs`` reads);
* ``query, one zone's statistic above a limit``: the runs of all lots whose
  ``vision`` ``phi_eff.p95_abs`` is over 45 mD;
* ``chart``: the query of one lot (200 runs), its control chart (:func:`trends`) and the
  PNG (:func:`plot_trends`, ``figure_png``): what ``glassdist history --lot L07 --chart``
  draws.

Target (issue 29): each under 1 s. The CPU time of this process is reported beside the wall
time, and the machine's load average with the results: on a shared machine the wall time
rises with the load, the CPU time much less.

Usage::

    python benchmarks/bench_history.py [--runs 10000] [--repeat 5] [--out docs/records/performance/history_results.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from glassdist.history import HistoryFilter, open_store, plot_trends, query_runs, trends
from glassdist.history.store import insert_runs, run_rows
from glassdist.report.figures import figure_png

STATS = ("mean_abs", "mean", "std", "p95_abs", "max_abs", "n_valid", "area_over_100")
CHANNELS = ("phi_eff", "phi_shear", "phi_total")


def synthetic_summary(rng, i, n_lots):
    """A summary.json-like record of run ``i``: lot drift, zones, two checks."""
    lot = i % n_lots
    level = 20 + lot * 0.5 + 3 * rng.standard_normal()

    def block(scale):
        return {ch: {s: float(abs(level * scale * (1 + 0.2 * k) + rng.standard_normal())) for k, s in enumerate(STATS)}
                for ch in CHANNELS}

    vision, edge = block(1.0), block(1.6)
    passed = vision["phi_eff"]["p95_abs"] < 45
    return {
        "metadata": {"pane_id": f"P{i:05d}", "lot": f"L{lot:02d}", "site": ("north", "south", "east")[i % 3],
                     "operator": "op"},
        "inputs": {"image": f"/data/P{i:05d}.png", "image_sha256": f"{i:064x}"},
        "method": "comparative", "pattern": "lines", "pitch_mm": 5.0, "distance_m": 1.0, "sigma_mm": 10.0,
        "detrend_degree": 2, "a4": {"statistics": block(1.2)}, "measured_percent": 95.0, "trusted_percent": 90.0,
        "zones": {"vision": {"statistics": vision, "trusted_percent": 97.0},
                  "edge": {"statistics": edge, "trusted_percent": 80.0}},
        "verdict": {"result": "PASS" if passed else "FAIL", "spec_name": "line spec", "checks": [
            {"criterion": "p95 |phi_eff| in zone 'vision' <= 45 mD", "value": vision["phi_eff"]["p95_abs"],
             "limit": 45.0, "unit": "mD", "passed": passed},
            {"criterion": "p95 |phi_shear| in zone 'edge' <= 80 mD", "value": edge["phi_shear"]["p95_abs"],
             "limit": 80.0, "unit": "mD", "passed": edge["phi_shear"]["p95_abs"] <= 80}]},
        "measures": {"roll_wave": {"power_pv_mD": level}}, "warnings": [],
    }


def fill(db, n_runs, n_lots, seed=0):
    rng = np.random.default_rng(seed)
    t0 = datetime(2026, 1, 1)
    step = timedelta(days=100) / n_runs
    t = time.perf_counter()
    with open_store(db, write=True) as store:
        for start in range(0, n_runs, 1000):
            insert_runs(store, [run_rows(synthetic_summary(rng, i, n_lots), exit_code=0, out_dir=f"/out/{i}",
                                         recorded_utc=t0 + i * step) for i in range(start, min(n_runs, start + 1000))])
    return time.perf_counter() - t


def timed(fn, repeat):
    """Wall and CPU time (this process) of ``fn()``: median and worst of ``repeat`` calls, and the value."""
    times, cpu, value = [], [], None
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        value = fn()
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return {"median_s": statistics.median(times), "max_s": max(times), "cpu_median_s": statistics.median(cpu)}, value


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--lots", type=int, default=50)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    ap.add_argument("--chart", type=Path, help="also keep the chart PNG")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "history.sqlite"
        fill_s = fill(db, args.runs, args.lots)
        with open_store(db) as store:
            flt = HistoryFilter.of(lot="L07", site="north", verdict="PASS", since="2026-01-20", zone="vision",
                                   statistic="phi_shear.p95_abs")
            q1, rows1 = timed(lambda: query_runs(store, flt), args.repeat)
            over = HistoryFilter.of(zone="vision", statistic="phi_eff.p95_abs", above=45)
            q2, rows2 = timed(lambda: query_runs(store, over), args.repeat)

            def chart():
                rows = query_runs(store, HistoryFilter.of(lot="L07"))
                found = trends(rows)
                return rows, found, figure_png(plot_trends(found, label="phi_eff.p95_abs (all)"))

            c, (rows3, found, png) = timed(chart, args.repeat)
        size_mb = db.stat().st_size / 2**20
    if args.chart:
        args.chart.write_bytes(png)
    import os

    results = {
        "load_average_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(),
        "runs": args.runs, "lots": args.lots, "database_MB": round(size_mb, 1), "fill_s": round(fill_s, 1),
        "query": {**q1, "rows": len(rows1)},
        "query, one zone's statistic above a limit": {**q2, "rows": len(rows2)},
        "chart": {**c, "rows": len(rows3), "beyond_3_sigma": int(found[0].out.sum())},
    }
    for key in ("query", "query, one zone's statistic above a limit", "chart"):
        r = results[key]
        print(f"{key:45s} {r['rows']:6d} rows  median {r['median_s'] * 1e3:7.1f} ms (CPU {r['cpu_median_s'] * 1e3:6.1f} ms)"
              f"  worst {r['max_s'] * 1e3:7.1f} ms  {'< 1 s' if r['max_s'] < 1 else 'OVER 1 s'}")
    print(f"{args.runs} runs in {results['database_MB']} MB, filled in {results['fill_s']} s")
    if args.out:
        args.out.write_text(json.dumps(results, indent=2) + "\n")
    return results


if __name__ == "__main__":
    main()
