"""``glassdist history``: list, filter, export and chart the recorded runs; the recording options of analyze."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..validation import Range, number_option
from .options import DB_HELP

__all__ = ["register", "run"]

_VALUE = number_option(Range(-1e12, 1e12))  # a finite value, mD or %

_DESCRIPTION = """List, filter and export the runs recorded in the history database (every analyze, batch pane,
web job and Python-API run), or draw a control chart of one statistic per lot: the lot's runs in order,
its mean and mean ± 3 sample standard deviations, runs beyond them in red. The value shown and charted
is --statistic over --zone (default phi_eff.p95_abs over the whole analysed region, zone 'all')."""


def register(subparsers):
    """Add the ``history`` sub-command."""
    p = subparsers.add_parser("history", help="list, filter, export and chart the recorded runs (per lot, per pane)",
                              description=_DESCRIPTION)
    p.add_argument("--db", metavar="PATH|URL", help=DB_HELP.replace("; 'off' records nothing", ""))
    p.add_argument("--pane-id", help="only this pane")
    p.add_argument("--lot", help="only this lot")
    p.add_argument("--site", help="only this site")
    p.add_argument("--operator", help="only this operator")
    p.add_argument("--source", choices=["cli", "batch", "web", "api"], help="only runs made this way")
    p.add_argument("--verdict", type=str.upper, choices=["PASS", "FAIL", "NONE"],
                   help="only this verdict (NONE: runs without a specification)")
    p.add_argument("--since", metavar="DATE", help="recorded on or after DATE (YYYY-MM-DD or YYYY-MM-DDTHH:MM, UTC)")
    p.add_argument("--until", metavar="DATE", help="recorded on or before DATE (a whole day when YYYY-MM-DD)")
    p.add_argument("--zone", help="zone of the statistic (a specification's zone name; default 'all': the whole "
                   "analysed region); runs without it are left out")
    p.add_argument("--statistic", metavar="CHANNEL.STAT", help="the value shown and charted, e.g. phi_eff.p95_abs "
                   "(default), phi_shear.max_abs, region.coverage_percent")
    p.add_argument("--above", type=_VALUE, metavar="X", help="only runs whose value is above X")
    p.add_argument("--below", type=_VALUE, metavar="X", help="only runs whose value is below X")
    p.add_argument("--failed-zone", metavar="ZONE", help="only runs that failed a check in this zone (e.g. edge)")
    p.add_argument("--limit", type=int, metavar="N", help="only the newest N runs")
    p.add_argument("--format", choices=["table", "csv", "json"], default="table", help="output (default: a table)")
    p.add_argument("--out", type=Path, metavar="FILE", help="write the csv/json export to FILE (a new file) "
                   "instead of the standard output")
    p.add_argument("--chart", type=Path, metavar="PNG", help="also draw the control chart of --statistic per lot "
                   "into PNG (a new file)")
    p.set_defaults(func=run)
    return p


def _new_file(path: Path, what: str) -> Path:
    from ..errors import InputError

    if path.exists():
        raise InputError(f"{what} '{path}' already exists; give a new file name (nothing is overwritten)")
    if not path.parent.is_dir():
        raise InputError(f"the folder of {what} '{path}' does not exist; create it or choose another path")
    return path


def _csv_text(records, columns) -> str:
    from ..fs import csv_text

    def cell(v):  # warnings: one cell, ';'-separated; protocol, measures: their JSON
        if isinstance(v, list) and all(isinstance(x, str) for x in v):
            return ";".join(v)
        if isinstance(v, (dict, list)):
            return json.dumps(v, sort_keys=True, allow_nan=False)
        return "" if v is None else v

    return csv_text(({k: cell(v) for k, v in r.items()} for r in records), columns)


def _table(records) -> str:
    cols = ("run", "recorded_utc", "pane_id", "lot", "site", "verdict", "value", "source")
    if not records:
        return "no recorded run matches\n"
    label = f"{records[0]['statistic']} ({records[0]['zone']})"
    rows = [[("" if r[c] is None else f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c])) for c in cols]
            for r in records]
    head = [c if c != "value" else label for c in cols]
    widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths)) for row in rows]
    return "\n".join(lines) + f"\n{len(records)} run(s)\n"


def run(args) -> int:
    """List / export / chart; exit 0, or 2 with one line (bad filter, unreadable database, existing file)."""
    from ..errors import InputError
    from ..fs import atomic_write_bytes, atomic_write_text
    from . import COLUMNS, HistoryFilter, locate, read_records

    flt = {k: getattr(args, k) for k in ("pane_id", "lot", "site", "operator", "source", "verdict", "since", "until",
                                         "zone", "statistic", "above", "below", "failed_zone", "limit")}
    HistoryFilter.of(**{k: v for k, v in flt.items() if v is not None})  # bad dates, statistics: exit 2 now
    if args.limit is not None and args.limit < 1:
        raise InputError("--limit must be at least 1")
    if args.out is not None:
        if args.format == "table":
            raise InputError("--out writes an export: add --format csv or --format json")
        _new_file(args.out, "the export")
    if args.chart is not None:
        _new_file(args.chart, "the chart")
    loc = locate(args.db)
    if loc is None:
        raise InputError("the history is off (GLASSDIST_DB=off); give --db PATH to read one")
    # records kept while the database could not be reached are written first
    records, flushed = read_records(args.db, {k: v for k, v in flt.items() if v is not None})
    if flushed.line():
        print(flushed.line(), file=sys.stderr)
    print(f"history: {len(records)} run(s) from '{loc}'" + (
        " (the default history file; --db PATH|URL or GLASSDIST_DB chooses another)" if loc.default else ""),
        file=sys.stderr)
    if args.format == "csv":
        text = _csv_text(records, COLUMNS)
    elif args.format == "json":
        text = json.dumps(records, indent=1, allow_nan=False) + "\n"
    else:
        text = _table(records)
    if args.out is not None:
        atomic_write_text(args.out, text)
        print(f"{len(records)} run(s) written to {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    if args.chart is not None:
        from ..report.figures import figure_png  # matplotlib: only for a chart
        from . import plot_trends, trends

        found = trends(records)
        label = f"{records[0]['statistic']} ({records[0]['zone']})" if records else "value"
        atomic_write_bytes(args.chart, figure_png(plot_trends(found, label=label)))
        n_out = sum(int(t.out.sum()) for t in found)
        print(f"control chart of {len(found)} lot(s), {n_out} run(s) beyond ±3σ: {args.chart}", file=sys.stderr)
    if not records and (loc.path is not None and not loc.path.exists()):
        print(f"note: no history database at '{loc}' yet (runs are recorded there as they are analysed)",
              file=sys.stderr)
    return 0
