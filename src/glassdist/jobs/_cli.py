"""``glassdist batch``: analyse many panes from a manifest CSV or a folder (see :mod:`glassdist.jobs.batch`)."""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path

from .._cli_shared import folder_option
from ..distributed import add_scheduler_options, open_executor
from ..validation import DISTANCE_M, PITCH_MM, SIGMA_MM, number_option, safe_text

logger = logging.getLogger(__name__)

_HELP = """Analyse many panes: SOURCE is a manifest CSV (one row per pane: image, reference, pitch_mm,
distance_m, ... ; relative paths from the manifest's folder) or a folder of photographs sharing the
options below. Each pane goes to OUT/panes/<id>/; OUT/index.csv and OUT/index.html list every pane.
Run the same command again to resume: finished panes are kept, failed and missing ones are (re)done.
Panes run one after the other in this process unless --workers N (a local Dask cluster) or
--scheduler ADDRESS (a running one; inputs and OUT on a shared filesystem) is given.
Exit status: 0 all panes analysed and passed (or no spec), 3 all analysed but some FAILED their
specification, 4 some panes could not be analysed (see OUT/failed/), 2 bad input."""


def register(subparsers):
    """Add the ``batch`` sub-command."""
    p = subparsers.add_parser("batch", help="analyse many panes (manifest CSV or folder), resumable",
                              description=_HELP)
    p.add_argument("source", metavar="MANIFEST.csv|FOLDER", help="manifest CSV or folder of images")
    p.add_argument("--out", type=folder_option, required=True, metavar="DIR",
                   help="batch output folder (new, empty, or to resume)")
    p.add_argument("--spec", metavar="SPEC.json", help="acceptance specification for panes without a 'spec' column")
    p.add_argument("--report", action="store_true", help="write an HTML report per pane")
    p.add_argument("--export", action="store_true", help="write NPZ and 32-bit TIFF fields per pane")
    p.add_argument("--pitch-mm", type=number_option(PITCH_MM), help="grid pitch, mm (default for panes without one)")
    p.add_argument("--distance-m", type=number_option(DISTANCE_M),
                   help="glass-to-grid distance L, m (default for panes without one)")
    p.add_argument("--reference", metavar="REF", help="glass-less reference photo (Comparative method) by default")
    p.add_argument("--pattern", choices=["auto", "lines", "checkerboard", "dots"],
                   help="grid pattern by default (default: auto, decided from each photo's spectrum)")
    p.add_argument("--params", metavar="PARAMS.json", help="analyzer parameters file by default")
    p.add_argument("--sigma-mm", type=number_option(SIGMA_MM), help="smoothing scale, mm, by default")
    p.add_argument("--detrend-degree", type=int, help="detrend polynomial degree by default")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--db", metavar="PATH|URL", help="history database every pane is recorded in (default: "
                   "$GLASSDIST_DB, else ~/.local/share/glassdist/history.sqlite)")
    p.add_argument("--no-history", action="store_true", help="do not record the panes in the history database")
    add_scheduler_options(p)
    p.set_defaults(func=run)
    return p


@contextlib.contextmanager
def _history_db(args):
    """``GLASSDIST_DB`` of ``--db`` / ``--no-history`` while the batch runs: every pane's analyze process reads it
    (here, or on the workers of a local cluster started meanwhile); restored afterwards."""
    if not args.no_history and args.db is None:
        yield
        return
    value = "off" if args.no_history else args.db if "://" in args.db else str(Path(args.db).absolute())
    old = os.environ.get("GLASSDIST_DB")
    os.environ["GLASSDIST_DB"] = value
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("GLASSDIST_DB", None)
        else:
            os.environ["GLASSDIST_DB"] = old


def run(args):
    """Run the batch; returns the exit status (see :mod:`glassdist.jobs.batch`)."""
    from ..errors import InputError
    from .batch import check_panes, pane_defaults, panes_from_folder, read_manifest, run_batch

    defaults = pane_defaults(
        pitch_mm=args.pitch_mm, distance_m=args.distance_m, reference=args.reference, pattern=args.pattern,
        params=args.params, spec=args.spec, sigma_mm=args.sigma_mm, detrend_degree=args.detrend_degree,
    )
    source = Path(args.source)
    if source.is_dir():
        panes = panes_from_folder(source, defaults)
    elif source.suffix.lower() == ".csv":
        panes = read_manifest(source, defaults)
    else:
        raise InputError(f"'{safe_text(source)}' is neither a folder nor a .csv manifest")
    check_panes(panes, defaults)
    with _history_db(args), open_executor(args.scheduler, args.workers) as executor:
        code = run_batch(panes, args.out, report=args.report, export=args.export, progress=not args.no_progress,
                         executor=executor)
    out = Path(args.out)
    print(f"index: {out / 'index.html'} ({out / 'index.csv'})")
    return code
