"""Scene sweeps: every combination of varied scene values through the Virtual Pipeline.

``glassdist sweep SCENE --vary camera.distance_m=... --vary backdrop.pitch_mm=... --out DIR``
writes one scene file per combination and runs ``glassdist validate`` on it (render,
Distortion Analyzer, analytical model, comparison) in its own process, here or on a
Dask worker (:mod:`glassdist.distributed`)::

    DIR/.glassdist-sweep          marks the folder as a sweep folder
    DIR/scenes/<id>.json          the variant's complete scene
    DIR/variants/<id>/            validate's outputs + variant.json (complete variants only)
    DIR/failed/<id>.json, .log    variants that could not be run (error line, full log)
    DIR/index.csv, DIR/index.json one row per variant: varied values, ratios, statistics

Like a batch, a variant is written to a temporary folder renamed into place when
complete, so running the same command again keeps the finished variants (same
scene, method, engine, samples and version) and runs the others.
Exit status: 0 every variant ran, 4 some could not (see ``DIR/failed/``), 2 bad input.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import logging
import os
import secrets
import shutil
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from .._version import __version__
from ..errors import InputError
from ..validation import safe_text

__all__ = ["Variant", "parse_vary", "expand_variants", "run_sweep", "write_sweep_index"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Variant:
    """One combination of a sweep: its id, the varied values (dotted key -> value) and its scene mapping."""

    id: str
    values: dict
    scene: dict

    def scene_text(self) -> str:
        """The scene as JSON text (what ``DIR/scenes/<id>.json`` holds)."""
        return json.dumps(self.scene, indent=2, sort_keys=True) + "\n"

    def fingerprint(self, *, method, engine, spp) -> str:
        """SHA-256 of the scene, the run options and the glassdist version."""
        h = hashlib.sha256(self.scene_text().encode())
        h.update(f"method={method};engine={engine};spp={spp};version={__version__}".encode())
        return h.hexdigest()


def parse_vary(texts) -> dict:
    """Parse ``--vary key=v1,v2,...`` options into ``{key: [values]}`` (values read as YAML scalars).

    Raises
    ------
    InputError
        Missing ``=``, empty key or value list, a key given twice.

    Examples
    --------
    >>> parse_vary(["backdrop.pitch_mm=24.2,48.4", "analysis.detrend_degree=2"])
    {'backdrop.pitch_mm': [24.2, 48.4], 'analysis.detrend_degree': [2]}
    """
    import yaml

    vary: dict = {}
    for text in texts:
        key, sep, values = text.partition("=")
        key = key.strip()
        if not sep or not key or not values.strip():
            raise InputError(f"--vary '{text}' must read KEY=V1,V2,... (e.g. backdrop.pitch_mm=24.2,48.4)")
        if key in vary:
            raise InputError(f"--vary key '{key}' is given twice; list all its values in one --vary")
        try:
            vary[key] = [yaml.safe_load(v.strip()) for v in values.split(",")]
        except (yaml.YAMLError, ValueError):  # ValueError: an integer of more than 4300 digits
            raise InputError(f"--vary '{safe_text(text, 80)}': a value cannot be read; "
                             "use numbers, words or true/false") from None
        if any(v is None or isinstance(v, (dict, list)) for v in vary[key]):
            raise InputError(f"--vary '{text}': every value must be a number, a word or true/false")
    if not vary:
        raise InputError("give at least one --vary KEY=V1,V2,...")
    return vary


def _set_dotted(data: dict, key: str, value):
    node = data
    parts = key.split(".")
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise InputError(f"--vary key '{key}': '{part}' is not an index of a {len(node)}-element list")
            part = int(part)
        elif not isinstance(node, dict) or (part not in node and not (parts[0] == "analysis" and i > 0)):
            where = ".".join(parts[:i]) or "the scene"
            keys = ", ".join(sorted(node)) if isinstance(node, dict) else "none"
            raise InputError(f"--vary key '{key}': {where} has no '{part}' (its keys: {keys}); "
                             "see docs/explanation/virtual-pipeline.md for the scene format")
        if last:
            node[part] = value
        else:
            if node[part] is None:  # an optional section left out of the scene
                node[part] = {}
            node = node[part]


def expand_variants(scene_path, vary: dict) -> list[Variant]:
    """Every combination of the varied values applied to a scene file (first key slowest).

    Parameters
    ----------
    scene_path : path
        Scene file (YAML/JSON).
    vary : dict
        ``{dotted key: [values]}``; keys address the scene's sections (``camera.distance_m``,
        ``backdrop.pitch_mm``, ``camera.position_mm.2``) or analyzer parameters
        (``analysis.sigma_mm``).

    Returns
    -------
    list of Variant
        Each checked as a scene and for its analyzer parameters.

    Raises
    ------
    InputError
        Unknown key, a combination that is not a valid scene or has invalid analyzer parameters.
    """
    from ..scene import load_scene, scene_from_dict
    from ..theory import analysis_params

    base = load_scene(scene_path).model_dump(mode="json")
    keys = list(vary)
    combos = list(itertools.product(*(vary[k] for k in keys)))
    width = max(3, len(str(len(combos) - 1)))
    variants = []
    for i, combo in enumerate(combos):
        data = copy.deepcopy(base)
        values = dict(zip(keys, combo))
        for k, v in values.items():
            _set_dotted(data, k, v)
        where = "variant " + ", ".join(f"{k}={v}" for k, v in values.items())
        scene = scene_from_dict(data, source=where)
        try:
            analysis_params(scene)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        variants.append(Variant(f"v{i:0{width}d}", values, scene.model_dump(mode="json")))
    return variants


def _execute_variant(job):
    """Run ``glassdist validate`` on one variant (its typed request) into a new temporary folder (here or on a worker)."""
    from ..jobs.runner import run_request

    request, variants_dir, vid, cwd = job
    tmp = Path(variants_dir) / f".tmp-{vid}-{os.getpid()}-{secrets.token_hex(3)}"
    (tmp if cwd is None else Path(cwd) / tmp).mkdir()
    t0 = time.monotonic()
    outcome = run_request(request.model_copy(update={"out": tmp}), cwd=cwd)
    return tmp, outcome, time.monotonic() - t0


def _read_json(path):
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None


def _finish_variant(v, out, tmp, outcome, seconds, fingerprint):
    from ..fs import atomic_write_text
    from ..jobs.runner import place_folder

    final = out / "variants" / v.id
    failed_json, failed_log = out / "failed" / f"{v.id}.json", out / "failed" / f"{v.id}.log"
    stamp = datetime.now(timezone.utc).isoformat(timespec="seconds")
    if outcome.exit_code != 0:
        shutil.rmtree(tmp, ignore_errors=True)
        atomic_write_text(failed_log, outcome.log)
        record = {"id": v.id, "status": "error", "values": v.values, "exit_code": outcome.exit_code,
                  "error": outcome.error, "seconds": round(seconds, 2), "finished_utc": stamp}
        atomic_write_text(failed_json, json.dumps(record, indent=2) + "\n")
        return record
    record = {"id": v.id, "status": "done", "values": v.values, "fingerprint": fingerprint,
              "seconds": round(seconds, 2), "finished_utc": stamp}
    (tmp / "validate.log").write_text(outcome.log, encoding="utf-8")
    (tmp / "variant.json").write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    place_folder(tmp, final)
    failed_json.unlink(missing_ok=True)
    failed_log.unlink(missing_ok=True)
    return record


def run_sweep(scene_path, vary: dict, out, *, method="direct", engine="exact", spp=None, executor=None,
              echo=print, progress=True) -> int:
    """Run ``glassdist validate`` on every combination of a scene sweep, then write the index.

    Parameters
    ----------
    scene_path : path
        Base scene file.
    vary : dict
        ``{dotted key: [values]}`` (:func:`parse_vary`).
    out : path
        Sweep folder (new, empty, or an earlier sweep's to resume).
    method : {'direct', 'comparative'}
    engine : str
        Render engine (``exact`` or ``cycles``).
    spp : int, optional
        Samples per pixel (default: each scene's).
    executor : glassdist.distributed.Executor, optional
        Where the variants run (default: here, one after the other).
    echo : callable
        Receives one line per variant.
    progress : bool
        Progress bar on stderr.

    Returns
    -------
    int
        0 when every variant ran, 4 when some could not (:data:`~glassdist.jobs.batch.EXIT_PANE_ERRORS`).
    """
    from ..jobs.batch import EXIT_PANE_ERRORS
    from ..jobs.runner import lock_job_folder, prepare_job_folder

    if method not in ("direct", "comparative"):
        raise InputError(f"unknown method '{method}'; use 'direct' or 'comparative'")
    if spp is not None and spp < 1:
        raise InputError(f"--spp must be at least 1, got {spp}")
    variants = expand_variants(scene_path, vary)
    out = prepare_job_folder(out, command="sweep", folders=("scenes", "variants", "failed"))
    lock = lock_job_folder(out, command="sweep")
    records: dict = {}
    try:
        for stale in (out / "variants").glob(".tmp-*"):
            shutil.rmtree(stale, ignore_errors=True)
        todo = _variants_to_run(variants, out, records, method=method, engine=engine, spp=spp)
        if records:
            echo(f"resuming: {len(records)} variant(s) already done, {len(todo)} to run")
        write_sweep_index(variants, out)
        cwd = None
        if executor is not None and executor.distributed and todo:
            cwd = None if out.is_absolute() else os.getcwd()
            executor.check_paths(files=[out / "scenes" / f"{v.id}.json" for v in todo], folders=[out / "variants"],
                                 cwd=cwd)
            echo(f"running {len(todo)} variant(s) on the {executor.description}")
        from ..jobs.request import ValidateRequest

        jobs = [(ValidateRequest(scene=out / "scenes" / f"{v.id}.json", out=out / "variants" / v.id, method=method,
                                 engine=engine, spp=spp), out / "variants", v.id, cwd) for v in todo]
        _run_variants(variants, todo, jobs, out, records, executor, progress, echo,
                      fingerprint=dict(method=method, engine=engine, spp=spp))
        for stale in (out / "variants").glob(".tmp-*"):  # of attempts lost with their worker
            shutil.rmtree(stale, ignore_errors=True)
    finally:
        lock.close()
    n_err = sum(r["status"] == "error" for r in records.values())
    echo(f"{len(variants)} variants: {len(variants) - n_err} ran, {n_err} could not be run")
    return EXIT_PANE_ERRORS if n_err else 0


def _variants_to_run(variants, out, records: dict, *, method, engine, spp) -> list:
    """The variants not already done with these run options; the done ones' records go into ``records``.

    Every variant's scene file is (re)written where it is missing or differs, so the
    ``scenes`` folder always holds the sweep as it now stands.
    """
    from ..fs import atomic_write_text

    todo = []
    for v in variants:
        fp = v.fingerprint(method=method, engine=engine, spp=spp)
        rec = _read_json(out / "variants" / v.id / "variant.json")
        if rec and rec.get("fingerprint") == fp:
            records[v.id] = rec
        else:
            todo.append(v)
        path = out / "scenes" / f"{v.id}.json"
        if not path.is_file() or path.read_text(encoding="utf-8") != v.scene_text():
            atomic_write_text(path, v.scene_text())
    return todo


def _run_variants(variants, todo, jobs, out, records: dict, executor, progress, echo, *, fingerprint: dict) -> None:
    """Run the ``jobs`` of ``todo`` (here, or as the cluster's futures complete), recording each in ``records``.

    Each finished variant is moved into place (:func:`_finish_variant`), echoed, and the
    index rewritten, so an interrupted sweep leaves an index of what is done.
    ``fingerprint``: the run options (``method``, ``engine``, ``spp``) of :meth:`Variant.fingerprint`.
    """
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ..jobs.runner import PaneOutcome

    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    run_all = executor.as_completed if executor is not None else _serial
    with Progress(*columns, console=Console(stderr=True), disable=not progress, transient=True) as bar:
        task = bar.add_task("sweep", total=len(variants), completed=len(records))
        for done in run_all(_execute_variant, jobs):
            v = todo[done.index]
            if done.error is None:
                tmp, outcome, seconds = done.value
            else:  # the job was lost (its worker died more often than the scheduler allows)
                tmp, seconds = out / "variants" / f".tmp-{v.id}-lost", 0.0
                outcome = PaneOutcome(1, repr(done.error), f"{type(done.error).__name__}: {done.error}")
            fp = v.fingerprint(**fingerprint)
            rec = records[v.id] = _finish_variant(v, out, tmp, outcome, seconds, fp)
            values = ", ".join(f"{k}={x}" for k, x in v.values.items())
            tail = f"  ERROR: {rec['error']}" if rec["status"] == "error" else ""
            echo(f"[{len(records)}/{len(variants)}] {v.id} {values}  ({rec['seconds']:.1f} s){tail}")
            write_sweep_index(variants, out)
            bar.advance(task)


def _serial(fn, jobs):
    from ..distributed import SerialExecutor

    return SerialExecutor().as_completed(fn, jobs)


_CHANNELS = ("phi_eff", "phi_shear", "phi_total")


def _index_rows(variants, out):
    rows = []
    for v in variants:
        row = {"id": v.id, **{k: json.dumps(x) if not isinstance(x, str) else x for k, x in v.values.items()},
               "status": "pending", "method": "", "engine": ""}
        row.update({f"ratio_{c}": "" for c in _CHANNELS})
        row.update({f"correlation_{c}": "" for c in _CHANNELS})
        row.update({"procrustes_rotation_deg": "", "procrustes_scale": "",
                    "analyzer_phi_eff_mean_abs_mD": "", "model_phi_eff_mean_abs_mD": "",
                    "analyzer_phi_shear_mean_abs_mD": "", "model_phi_shear_mean_abs_mD": "",
                    "valid_fraction": "", "warnings": "", "seconds": "", "error": ""})
        done = _read_json(out / "variants" / v.id / "variant.json")
        failed = _read_json(out / "failed" / f"{v.id}.json")
        if done:
            val = _read_json(out / "variants" / v.id / "validation.json") or {}
            stats = val.get("statistics") or {}
            row.update(status="done", method=val.get("method", ""), engine=val.get("engine", ""),
                       seconds=done.get("seconds", ""), valid_fraction=_fmt(val.get("valid_fraction")),
                       warnings=len((val.get("analyzer") or {}).get("warnings") or []))
            for c in _CHANNELS:
                row[f"ratio_{c}"] = _fmt((val.get("ratios") or {}).get(c))
                row[f"correlation_{c}"] = _fmt((val.get("correlations") or {}).get(c))
            pr = val.get("procrustes") or {}
            row.update(procrustes_rotation_deg=_fmt(pr.get("rotation_deg")), procrustes_scale=_fmt(pr.get("scale")))
            for c in ("phi_eff", "phi_shear"):
                row[f"analyzer_{c}_mean_abs_mD"] = _fmt(((stats.get("analyzer") or {}).get(c) or {}).get("mean_abs"))
                row[f"model_{c}_mean_abs_mD"] = _fmt(((stats.get("analytical") or {}).get(c) or {}).get("mean_abs"))
        elif failed:
            row.update(status="error", error=failed.get("error", ""), seconds=failed.get("seconds", ""))
        rows.append(row)
    return rows


def _fmt(v):
    return "" if v is None else f"{float(v):.6g}"


def write_sweep_index(variants, out):
    """Write ``OUT/index.csv`` and ``OUT/index.json``: one row per variant (varied values, status, figures)."""
    from ..fs import atomic_write_text, write_csv

    out = Path(out)
    rows = _index_rows(variants, out)
    write_csv(out / "index.csv", rows)
    atomic_write_text(out / "index.json", json.dumps({"glassdist_version": __version__, "variants": rows}, indent=2) + "\n")
    return out / "index.csv", out / "index.json"
