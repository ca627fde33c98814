"""Batch analysis of many panes: manifest, resumable execution, summary index.

A batch reads panes from a manifest CSV (one row per pane, each with its own
pitch, distance and reference) or from a folder of photographs sharing the same
settings, runs ``glassdist analyze`` on each one in its own process, and writes::

    OUT/.glassdist-batch          marks the folder as a batch folder
    OUT/panes/<id>/               the pane's analyze outputs + pane.json (complete panes only)
    OUT/failed/<id>.json, .log    panes that could not be analysed (error line, full log)
    OUT/index.csv, OUT/index.html summary table of every pane (done, failed or pending)

Resuming
--------
Each pane is analysed into ``OUT/panes/.tmp-<id>-<pid>-<random>/`` and renamed to
``OUT/panes/<id>/`` only once complete, so an interrupted batch (killed, power
cut) never leaves a half-written pane. Running the same command again skips every
pane whose folder exists and whose fingerprint (settings, SHA-256 of the input
files, output options, glassdist version) is unchanged; failed panes are retried.
The index is rewritten (atomically) after every pane.

Exit codes of ``glassdist batch``
---------------------------------
``0`` every pane analysed and none failed its specification; ``3`` every pane
analysed, at least one specification FAIL; ``4`` at least one pane could not be
analysed (the others were; see ``OUT/failed/``); ``2`` bad input (manifest, a
reference or mask file it names that does not exist, options, parameter files and
specifications, output folder), found before any pane runs (:func:`read_manifest`,
:func:`check_panes`).

Manifest columns
----------------
``image`` (required), ``id``, ``reference``, ``pitch_mm``, ``distance_m``,
``pattern``, ``params``, ``mask``, ``spec``, ``sigma_mm``, ``detrend_degree``,
``site``, ``operator``, ``lot``. ``pitch_mm`` and ``distance_m`` may be left to a
pane's ``spec`` whose protocol pins them; ``id`` is passed as the pane ID, ``site``,
``operator`` and ``lot`` to the report and the history; ``lot`` also groups the index's
trend plot.
Empty cells take the value of the matching command-line option. Relative paths
are relative to the manifest's folder. Rows whose first cell starts with ``#``
are comments.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import secrets
import shutil
import time
from dataclasses import asdict, dataclass, fields
from datetime import datetime, timezone
from html import escape
from pathlib import Path

from ..errors import InputError
from ..fs import atomic_write_text, write_csv
from ..storage import EXIT_SPEC_FAIL
from ..validation import DISTANCE_M, PITCH_MM, SIGMA_MM, check_number, read_csv_rows, safe_text
from .runner import PaneOutcome, lock_job_folder, place_folder, prepare_job_folder, read_json, subprocess_runner

__all__ = [
    "EXIT_PANE_ERRORS",
    "Pane",
    "read_manifest",
    "panes_from_folder",
    "run_batch",
    "write_index",
    "pane_defaults",
    "check_panes",
]

logger = logging.getLogger(__name__)

#: exit status of ``glassdist batch`` when at least one pane could not be analysed
EXIT_PANE_ERRORS = 4

_IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg"}
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")


@dataclass(frozen=True)
class Pane:
    """One pane of a batch: its photograph and analysis settings (lengths mm, L in m)."""

    id: str
    image: Path
    pitch_mm: float | None
    distance_m: float | None
    reference: Path | None = None
    pattern: str | None = None
    params: Path | None = None
    mask: Path | None = None
    spec: Path | None = None
    sigma_mm: float | None = None
    detrend_degree: int | None = None
    site: str | None = None
    operator: str | None = None
    lot: str | None = None

    def request(self, out_dir, *, report=False, export=False):
        """The :class:`~glassdist.jobs.request.AnalyzeRequest` of this pane, writing into ``out_dir``.

        ``out_dir`` is the pane's temporary folder ``OUT/panes/.tmp-...``: the run is
        recorded in the history as a pane of the batch ``OUT``, in ``OUT/panes/<id>``.
        The pane's ``id`` is its pane ID; pitch and distance may be left to the pane's
        specification when its protocol pins them.
        """
        from .request import AnalyzeRequest, RecordAs

        panes = Path(out_dir).parent
        return AnalyzeRequest(
            images=(self.image,), out=Path(out_dir), reference=self.reference, pattern=self.pattern,
            params=self.params, mask=self.mask, spec=self.spec, pitch_mm=self.pitch_mm, distance_m=self.distance_m,
            sigma_mm=self.sigma_mm, detrend_degree=self.detrend_degree, pane_id=self.id, site=self.site,
            operator=self.operator, lot=self.lot, report=report, export=export,
            # recorded in the history as a pane of this batch, in the folder it is renamed to once complete
            record_as=RecordAs(source="batch", job=str(panes.parent), out_dir=str(panes / self.id)))

    def fingerprint(self, *, report=False, export=False):
        """SHA-256 of the settings, the input files' bytes, the output options and the version."""
        from .. import __version__

        h = hashlib.sha256()
        h.update(json.dumps({k: str(v) for k, v in asdict(self).items()}, sort_keys=True).encode())
        h.update(f"report={report};export={export};version={__version__}".encode())
        for path in (self.image, self.reference, self.mask, self.spec, self.params):
            if path is not None and Path(path).is_file():
                h.update(Path(path).read_bytes())
        return h.hexdigest()


# ---------------------------------------------------------------- reading panes

_FLOAT_COLS = ("pitch_mm", "distance_m", "sigma_mm")
_PATH_COLS = ("image", "reference", "params", "mask", "spec")
_COLUMNS = {f.name for f in fields(Pane)}


_RANGES = {"pitch_mm": PITCH_MM, "distance_m": DISTANCE_M, "sigma_mm": SIGMA_MM}


def _parse_cell(name, text, where):
    if name in _FLOAT_COLS:
        return check_number(text, f"{where}: '{name}'", _RANGES[name])
    if name == "detrend_degree":
        try:
            return int(text)
        except ValueError:
            raise InputError(f"{where}: 'detrend_degree' must be an integer, got '{safe_text(text, 40)}'") from None
    return text


def _make_pane(values, defaults, base, where):
    merged = {k: v for k, v in (defaults or {}).items() if v is not None}
    merged.update({k: v for k, v in values.items() if v is not None})
    if "image" not in merged:
        raise InputError(f"{where}: no 'image' given")
    for name in ("pitch_mm", "distance_m") if "spec" not in merged else ():  # a spec's protocol may pin them
        if name not in merged:
            opt = "--" + name.replace("_", "-")
            raise InputError(f"{where}: no '{name}'; add a '{name}' column or give {opt} for every pane")
    merged.setdefault("pitch_mm", None)
    merged.setdefault("distance_m", None)
    for name in _PATH_COLS:
        if merged.get(name) is not None:
            # resolved, so that a resumed batch finds its panes however the manifest path is spelt
            merged[name] = Path(os.path.realpath(Path(base) / Path(merged[name]).expanduser()))
    merged.setdefault("id", Path(merged["image"]).stem)
    if not _ID_RE.match(merged["id"]):
        raise InputError(f"{where}: pane id '{safe_text(merged['id'], 100)}' must be 1-100 letters, digits, '.', '_' or '-'")
    return Pane(**merged)


def read_manifest(path, defaults=None):
    """Read a batch manifest CSV.

    Parameters
    ----------
    path : path
        CSV file with a header row; columns as in the module docstring.
    defaults : dict, optional
        Values for empty cells or missing columns (from the command line), keyed
        like :class:`Pane`'s fields.

    Returns
    -------
    list of Pane

    Raises
    ------
    InputError
        Unknown column, unparsable or missing value, duplicate pane id, a ``reference`` or
        ``mask`` cell that names no readable file (a missing photo in an ``image`` cell is
        the pane's: its run reports it).
    """
    path = Path(path)
    header, rows = read_csv_rows(path, "manifest")
    unknown = sorted(set(header) - _COLUMNS)
    if unknown:
        raise InputError(f"manifest '{safe_text(path)}': unknown column(s) {safe_text(', '.join(unknown), 200)}; "
                         f"valid columns are {', '.join(sorted(_COLUMNS))}")
    if "image" not in header:
        raise InputError(f"manifest '{safe_text(path)}' has no 'image' column (first row must be the header)")
    panes = []
    for lineno, cells in rows:
        if next(iter(cells.values()), "").startswith("#"):
            continue
        where = f"manifest '{safe_text(path.name)}' line {lineno}"
        values = {k: _parse_cell(k, v, where) for k, v in cells.items() if v}
        pane = _make_pane(values, defaults, path.parent, where)
        _check_cell_files(pane, values, where)
        panes.append(pane)
    return _check_unique(panes, f"manifest '{path}'")


def _check_cell_files(pane, cells, where):
    """The reference and mask a manifest row names must be files (stat only); the row's image is the pane's."""
    from ..validation import check_input_file

    for name in ("reference", "mask"):
        if name in cells:
            try:
                check_input_file(getattr(pane, name), f"{name} file")
            except InputError as exc:
                raise InputError(f"{where} (pane '{pane.id}'): {exc}") from None


def panes_from_folder(folder, defaults=None):
    """Every image of a folder as a pane (sorted by name), sharing ``defaults``.

    The reference image given in ``defaults`` is not itself a pane.
    """
    folder = Path(folder)
    defaults = dict(defaults or {})
    ref = Path(defaults["reference"]).resolve() if defaults.get("reference") else None
    images = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES and p.is_file()
                    and p.resolve() != ref)
    if not images:
        raise InputError(f"folder '{folder}' holds no PNG/TIFF/BMP/JPEG image to analyse")
    panes = [_make_pane({"image": p}, defaults, Path.cwd(), f"image '{p.name}'") for p in images]
    return _check_unique(panes, f"folder '{folder}'")


def _check_unique(panes, where):
    seen = set()
    for p in panes:
        if p.id in seen:
            raise InputError(f"{where}: pane id '{p.id}' appears twice; give each pane a distinct 'id'")
        seen.add(p.id)
    if not panes:
        raise InputError(f"{where} lists no pane")
    return panes


def check_panes(panes, defaults=None):
    """Check the batch's settings before any pane is analysed.

    Every pane's numbers, parameter file and specification, and the image files given
    as command-line options (``defaults``: reference, mask) are validated the way
    ``glassdist analyze`` does, from the files' headers (no image is decoded), so that a
    bad option or document is a bad input of the batch (exit 2) found at once, not a
    failure of every pane (exit 4) found one analysis at a time. A pane's own photo
    (its ``image`` cell, a folder's images) is the pane's: a bad one fails that pane; the
    manifest's ``reference`` and ``mask`` cells were checked to name files by
    :func:`read_manifest`.

    Raises
    ------
    InputError
        The first problem, prefixed with the pane's id.
    """
    from ..acceptance.spec import load_spec
    from ..analyzer.params import load_params
    from ..io import image_shape
    from ..validation import check_input_file, check_sigma_extent

    options = {k: v for k, v in (defaults or {}).items() if k in ("reference", "mask") and v is not None}
    for name, path in options.items():
        if name == "mask" and Path(path).suffix.lower() == ".npy":
            check_input_file(path, "mask file", option="--mask")
        else:
            image_shape(path)
    params, specs = {}, set()
    for pane in panes:
        try:
            key = (pane.params, pane.pattern, pane.detrend_degree, pane.sigma_mm)
            if key not in params:
                params[key] = load_params(pane.params, pattern=pane.pattern, detrend_degree=pane.detrend_degree,
                                          sigma_mm=pane.sigma_mm)
            if pane.spec is not None and pane.spec not in specs:
                load_spec(pane.spec)
                specs.add(pane.spec)
            p = params[key]
            if p.sigma_mm is not None and pane.pitch_mm is not None and Path(pane.image).is_file():
                try:
                    hw = image_shape(pane.image)
                except InputError:
                    continue  # the pane's own image: its run reports it
                check_sigma_extent(p.sigma_mm, hw, pane.pitch_mm, pattern=p.pattern, min_period_px=p.min_period_px)
        except InputError as exc:
            raise InputError(f"pane '{pane.id}': {exc}") from None


# ---------------------------------------------------------------- running panes


def _execute_pane(job):
    """Run one pane into a new temporary folder, wherever this runs (here or on a Dask worker).

    ``job`` is ``(pane, panes_dir, runner, report, export, cwd)``; returns
    ``(tmp, PaneOutcome, seconds)``. The folder's name is new for every attempt, so
    that a retry after a worker was lost never shares it with the lost attempt's
    still-running child.
    """
    pane, panes_dir, runner, report, export, cwd = job
    tmp = Path(panes_dir) / f".tmp-{pane.id}-{os.getpid()}-{secrets.token_hex(3)}"
    here = tmp if cwd is None else Path(cwd) / tmp
    here.mkdir()
    t0 = time.monotonic()
    try:
        outcome = runner(pane, tmp, report=report, export=export, **({} if cwd is None else {"cwd": cwd}))
    except (KeyboardInterrupt, SystemExit):
        shutil.rmtree(here, ignore_errors=True)
        raise
    except Exception as exc:  # noqa: BLE001 - a pane that breaks is recorded and the batch goes on
        outcome = PaneOutcome(1, repr(exc), f"{type(exc).__name__}: {exc}")
    return tmp, outcome, time.monotonic() - t0


def _run_one(pane, out, runner, report, export):
    tmp, outcome, seconds = _execute_pane((pane, out / "panes", runner, report, export, None))
    return _record_pane(pane, out, tmp, outcome, seconds, report, export)


def _record_pane(pane, out, tmp, outcome, seconds, report, export):
    """Move a finished pane to ``panes/<id>/`` (or record its failure); returns its record."""
    final = out / "panes" / pane.id
    failed_json, failed_log = out / "failed" / f"{pane.id}.json", out / "failed" / f"{pane.id}.log"
    if outcome.exit_code not in (0, EXIT_SPEC_FAIL):
        shutil.rmtree(tmp, ignore_errors=True)
        atomic_write_text(failed_log, outcome.log)
        record = {"id": pane.id, "status": "error", "exit_code": outcome.exit_code, "error": outcome.error,
                  "image": str(pane.image), "seconds": round(seconds, 2),
                  "finished_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        atomic_write_text(failed_json, json.dumps(record, indent=2) + "\n")
        return record
    summary = read_json(tmp / "summary.json") or {}
    verdict = (summary.get("verdict") or {}).get("result")
    record = {
        "id": pane.id, "status": "done", "verdict": verdict, "exit_code": outcome.exit_code,
        "fingerprint": pane.fingerprint(report=report, export=export), "seconds": round(seconds, 2),
        "finished_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "pane": {k: (str(v) if v is not None else None) for k, v in asdict(pane).items()},
        "history": _history_line(outcome.log),
    }
    (tmp / "analyze.log").write_text(outcome.log, encoding="utf-8")
    (tmp / "pane.json").write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    place_folder(tmp, final)
    failed_json.unlink(missing_ok=True)
    failed_log.unlink(missing_ok=True)
    return record


_HISTORY_LINES = ("history: ", "warning: this run was not recorded in the history")


def _history_line(log: str) -> str | None:
    """Where the pane's record went, as its ``glassdist analyze`` said (the database, or the spool file keeping it)."""
    found = [line for line in log.splitlines() if line.startswith(_HISTORY_LINES)]
    return found[-1] if found else None


def _done_record(pane, out, report, export):
    record = read_json(out / "panes" / pane.id / "pane.json")
    if record and record.get("fingerprint") == pane.fingerprint(report=report, export=export):
        return record
    return None


def run_batch(panes, out, *, report=False, export=False, runner=None, progress=True, echo=print, executor=None):
    """Analyse every pane not already done, then write the index.

    Parameters
    ----------
    panes : list of Pane
    out : path
        Batch output folder (new, empty, or a previous batch's folder to resume).
    report, export : bool
        Passed to ``glassdist analyze`` as ``--report`` / ``--export``.
    runner : callable, optional
        ``runner(pane, out_dir, report=, export=) -> PaneOutcome``; default
        :func:`subprocess_runner`. With a distributed executor and relative paths it
        also receives ``cwd=`` (this process's working folder).
    progress : bool
        Show a progress bar (on stderr).
    echo : callable
        Receives one line per pane.
    executor : glassdist.distributed.Executor, optional
        Where the panes run (default: here, one after the other). On a Dask
        cluster each pane runs on a worker, which writes its temporary folder;
        this process checks first that every worker sees the inputs and ``out``,
        then moves finished panes into place and rewrites the index as the
        futures complete, so outputs, resuming and exit codes are the same.

    Returns
    -------
    int
        The batch exit code (0, :data:`~glassdist.storage.writer.EXIT_SPEC_FAIL` or
        :data:`EXIT_PANE_ERRORS`).
    """
    runner = runner or subprocess_runner
    out = prepare_job_folder(out)
    lock = lock_job_folder(out)
    records = {}
    try:
        for stale in (out / "panes").glob(".tmp-*"):  # left by an interrupted run
            shutil.rmtree(stale, ignore_errors=True)
        todo = []
        for pane in panes:
            rec = _done_record(pane, out, report, export)
            if rec is not None:
                records[pane.id] = rec
            else:
                todo.append(pane)
        if records:
            echo(f"resuming: {len(records)} pane(s) already done, {len(todo)} to analyse")
        write_index(panes, out, figures=False)
        cwd = _checked_workers(executor, todo, out, echo)
        _run_panes(panes, todo, out, records, runner, report, export, executor, cwd, progress, echo)
        write_index(panes, out)  # the final index: shared-scale thumbnails and the trend plot
    finally:
        lock.close()
    return _batch_exit_code(panes, records, echo)


def _checked_workers(executor, todo, out, echo):
    """The working folder the workers resolve relative paths in (None: all absolute, or no cluster).

    On a cluster, every worker is first checked to see the panes' input files and the
    ``panes`` folder (:meth:`~glassdist.distributed.Executor.check_paths` raises otherwise).
    """
    cwd = None
    if executor is not None and executor.distributed and todo:
        paths = [out] + [p for pane in todo for p in _input_paths(pane)]
        cwd = os.getcwd() if any(not Path(p).is_absolute() for p in paths) else None
        executor.check_paths(files=[p for p in paths[1:] if Path(p).is_file()], folders=[out / "panes"], cwd=cwd)
        echo(f"analysing {len(todo)} pane(s) on the {executor.description}")
    return cwd


def _run_panes(panes, todo, out, records, runner, report, export, executor, cwd, progress, echo):
    """Analyse the panes of ``todo`` (here, or as the cluster's futures complete), recording each in ``records``.

    Each finished pane is moved into place (:func:`_record_pane`), echoed, and the index
    rewritten, so an interrupted batch leaves an index of what is done.
    """
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=Console(stderr=True), disable=not progress, transient=True) as bar:
        task = bar.add_task("batch", total=len(panes), completed=len(records))

        def finished(pane, rec):
            records[pane.id] = rec
            label = rec.get("verdict") or ("analysed" if rec["status"] == "done" else "ERROR")
            tail = f": {safe_text(rec['error'])}" if rec["status"] == "error" else ""
            echo(f"[{len(records)}/{len(panes)}] {pane.id}  {label}  ({rec['seconds']:.1f} s){tail}")
            if (rec.get("history") or "").startswith("warning:"):  # its record waits in the spool: say so here too
                echo(f"  {pane.id}: {rec['history']}")
            write_index(panes, out, figures=False)
            bar.advance(task)

        if executor is None or not executor.distributed:
            for pane in todo:
                bar.update(task, description=f"analysing {pane.id}")
                finished(pane, _run_one(pane, out, runner, report, export))
        else:
            bar.update(task, description="analysing")
            jobs = [(pane, out / "panes", runner, report, export, cwd) for pane in todo]
            for done in executor.as_completed(_execute_pane, jobs):
                pane = todo[done.index]
                if done.error is None:
                    tmp, outcome, seconds = done.value
                else:  # the job itself was lost (e.g. its worker died more often than allowed)
                    tmp, seconds = out / "panes" / f".tmp-{pane.id}-lost", 0.0
                    outcome = PaneOutcome(1, repr(done.error), f"{type(done.error).__name__}: {done.error}")
                finished(pane, _record_pane(pane, out, tmp, outcome, seconds, report, export))
            for stale in (out / "panes").glob(".tmp-*"):  # of attempts lost with their worker
                shutil.rmtree(stale, ignore_errors=True)


def _batch_exit_code(panes, records, echo) -> int:
    """Echo the batch's tally and return its exit code (pane errors before specification failures)."""
    n_err = sum(r["status"] == "error" for r in records.values())
    verdicts = [r.get("verdict") for r in records.values() if r["status"] == "done"]
    echo(f"{len(panes)} panes: {len(verdicts)} analysed ({verdicts.count('PASS')} PASS, {verdicts.count('FAIL')} FAIL, "
         f"{verdicts.count(None)} without specification), {n_err} could not be analysed")
    if n_err:
        return EXIT_PANE_ERRORS
    if "FAIL" in verdicts:
        return EXIT_SPEC_FAIL
    return 0


def _input_paths(pane):
    return [p for p in (pane.image, pane.reference, pane.mask, pane.spec, pane.params) if p is not None]


# ---------------------------------------------------------------- the index

_INDEX_STATS = (("phi_eff", "mean_abs"), ("phi_eff", "p95_abs"), ("phi_eff", "max_abs"),
                ("phi_shear", "mean_abs"), ("phi_shear", "p95_abs"), ("phi_shear", "max_abs"))


def _index_rows(panes, out):
    rows = []
    for pane in panes:
        row = {"id": pane.id, "status": "pending", "verdict": "", "method": "", "image": str(pane.image),
               "reference": str(pane.reference or ""), "pitch_mm": pane.pitch_mm, "distance_m": pane.distance_m}
        row.update({"lot": pane.lot or "", "site": pane.site or "", "operator": pane.operator or "",
                    "spec": Path(pane.spec).stem if pane.spec else "", "spec_name": "", "detrend_degree": "",
                    "sigma_mm": ""})
        row.update({f"{c}_{s}_mD": "" for c, s in _INDEX_STATS})
        row.update({"measured_percent": "", "trusted_percent": "", "seconds": "", "report": "", "error": ""})
        done = read_json(out / "panes" / pane.id / "pane.json")
        failed = read_json(out / "failed" / f"{pane.id}.json")
        if done:
            summary = read_json(out / "panes" / pane.id / "summary.json") or {}
            a4 = summary.get("a4") or {}
            stats = a4.get("statistics") or {}
            row.update(status="done", verdict=done.get("verdict") or "", method=summary.get("method", ""),
                       seconds=done.get("seconds", ""), measured_percent=_round(summary.get("measured_percent")),
                       trusted_percent=_round(summary.get("trusted_percent")))
            row.update({f"{c}_{s}_mD": _round(stats.get(c, {}).get(s)) for c, s in _INDEX_STATS})
            row.update(spec_name=(summary.get("verdict") or {}).get("spec_name", ""),
                       detrend_degree=summary.get("detrend_degree", ""), sigma_mm=_round(summary.get("sigma_mm")),
                       # the values the analysis used: the manifest's, or those its specification pins
                       pitch_mm=summary.get("pitch_mm", pane.pitch_mm), distance_m=summary.get("distance_m", pane.distance_m))
            if (out / "panes" / pane.id / "report.html").is_file():
                row["report"] = f"panes/{pane.id}/report.html"
        elif failed:
            row.update(status="error", error=failed.get("error", ""), seconds=failed.get("seconds", ""))
        rows.append(row)
    return rows


def _round(v):
    return "" if v is None else f"{float(v):.4g}"


def write_index(panes, out, *, figures=True):
    """Write ``OUT/index.csv`` and ``OUT/index.html`` listing every pane with its status and statistics.

    With ``figures`` (the final index of a run), also the thumbnails on one shared colour
    scale and the per-lot trend plot (:mod:`glassdist.jobs.index_figures`); the indexes
    written while the batch runs link each pane's own heatmap instead.
    """
    out = Path(out)
    rows = _index_rows(panes, out)
    write_csv(out / "index.csv", rows)
    atomic_write_text(out / "index.html", _index_html(rows, out, figures=figures))
    return out / "index.csv", out / "index.html"


def _index_html(rows, out, *, figures=True):
    from .. import __version__
    from .index_figures import write_thumbnails, write_trend

    thumbs, vmax = write_thumbnails(out, [r["id"] for r in rows if r["status"] == "done"]) if figures else ({}, None)
    trend = write_trend(out, rows) if figures else None
    with_lot = any(r["lot"] for r in rows)

    counts = {s: sum(r["status"] == s for r in rows) for s in ("done", "error", "pending")}
    n_fail = sum(r["verdict"] == "FAIL" for r in rows)
    # Two header rows: the statistics grouped under their channel, so that the columns stay
    # narrow and the table (thumbnail included) fits a 1200 px wide window.
    channels = list(dict.fromkeys(c for c, _ in _INDEX_STATS))
    top = "".join(f'<th rowspan="2">{h}</th>' for h in ("pane",) + (("lot",) if with_lot else ())
                  + ("status", "verdict", "spec", "method", "N", "σ mm"))
    top += "".join(f'<th colspan="{sum(c == ch for c, _ in _INDEX_STATS)}">|{escape(ch)}| (mD)</th>' for ch in channels)
    top += "".join(f'<th rowspan="2">{h}</th>' for h in ("measured %", "trusted %", "s", "heatmap"))
    sub = "".join(f"<th>{escape(s.removesuffix('_abs'))}</th>" for _, s in _INDEX_STATS)
    body = ""
    for r in rows:
        pid = escape(r["id"])
        name = f'<a href="{escape(r["report"])}">{pid}</a>' if r["report"] else pid
        cls = "FAIL" if r["verdict"] == "FAIL" or r["status"] == "error" else r["verdict"] or r["status"]
        status = escape(r["status"]) + (f"<br><small>{escape(r['error'])}</small>" if r["error"] else "")
        thumb = ""
        if r["id"] in thumbs:  # shared colour scale, no axes
            thumb = (f'<a href="panes/{pid}/phi_eff.png"><img class="thumb shared" src="{escape(thumbs[r["id"]])}" '
                     'alt="phi_eff"></a>')
        elif r["status"] == "done" and (out / "panes" / r["id"] / "phi_eff.png").is_file():
            thumb = f'<a href="panes/{pid}/phi_eff.png"><img class="thumb" src="panes/{pid}/phi_eff.png" alt="phi_eff"></a>'
        spec = f'<span title="{escape(r["spec_name"])}">{escape(r["spec"])}</span>' if r["spec"] else ""
        cells = [name] + ([escape(r["lot"])] if with_lot else []) + [status, escape(r["verdict"]), spec,
                                                                    escape(r["method"]), escape(str(r["detrend_degree"])),
                                                                    escape(str(r["sigma_mm"]))]
        cells += [escape(str(r[f"{c}_{s}_mD"])) for c, s in _INDEX_STATS]
        cells += [escape(str(r["measured_percent"])), escape(str(r["trusted_percent"])), escape(str(r["seconds"])), thumb]
        body += f'<tr class="{escape(cls)}" id="pane-{pid}">' + "".join(f"<td>{c}</td>" for c in cells) + "</tr>\n"
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M:%S")
    scale = ""
    if thumbs:
        scale = (f'<p id="thumb-scale">Thumbnails: phi_eff on one colour scale for every pane, [-{vmax:.3g}, {vmax:.3g}] '
                 f'mD (the largest of the panes\' 99th percentiles of |phi_eff|); grey: not analysed.<br>'
                 '<img src="thumbs/colourbar.png" alt="colour scale of the thumbnails" style="max-width:400px"></p>')
    trend_html = ""
    if trend:
        trend_html = ('<h2>Trend</h2><p>p95 |phi_eff| and p95 phi_shear per pane in batch order, grouped by lot.</p>'
                      f'<img id="trend" src="{trend}" alt="per-lot trend" style="max-width:100%">')
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>glassdist batch index</title><style>
body{{font-family:system-ui,Arial,sans-serif;margin:1em}}table{{border-collapse:collapse;max-width:100%}}
td,th{{border:1px solid #ccc;padding:.2em .35em;text-align:left;vertical-align:middle;font-size:.86em}}
th{{background:#f2f2f2}}td:nth-child(-n+2){{overflow-wrap:anywhere;min-width:7em}}
img.thumb{{display:block;width:96px;max-width:100%;height:auto}}
tr.PASS td{{background:#f3fbf4}}tr.FAIL td{{background:#fff0ef}}tr.pending td{{color:#888}}
</style></head><body>
<h1>Batch index</h1>
<p>{len(rows)} panes: {counts['done']} analysed ({n_fail} failed their specification), {counts['error']} could not
be analysed, {counts['pending']} pending. Updated {stamp} UTC by glassdist {escape(__version__)}.
Machine-readable copy: <a href="index.csv">index.csv</a>.</p>
{scale}
<table><tr>{top}</tr><tr>{sub}</tr>
{body}</table>
{trend_html}</body></html>
"""


def pane_defaults(**values):
    """Command-line defaults for :func:`read_manifest` / :func:`panes_from_folder`.

    ``None`` values are unset; paths are resolved (relative to the current
    folder, where the user typed them), unlike manifest cells.
    """
    return {k: (Path(os.path.realpath(Path(v).expanduser())) if k in _PATH_COLS and v is not None else v)
            for k, v in values.items()}
