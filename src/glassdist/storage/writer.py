"""The output stage of ``glassdist analyze``: every file of a run, planned, written and recorded here.

The command line, ``glassdist batch`` (through its child ``glassdist analyze`` processes)
and the Python API (:func:`write_outputs`) all write a run's folder through this module:

1. :func:`plan_outputs` names the files a run can write, before any work;
2. :func:`open_output_folder` takes the folder before the analysis: created, refused when
   a planned output would overwrite an input, checked writable, locked against a second
   run into it (exit status 2), and cleaned of the temporary files a killed run left;
3. :func:`write_outputs` writes ``result.npz`` and ``summary.json``, then
   :func:`finish_analysis` the statistics, verdict, figures, report and exports; each file
   is written atomically (a temporary name, then a rename) and recorded with its size and
   SHA-256 in ``summary.json`` (``outputs``); files of an earlier run into the folder that
   this run did not write again are removed only where they still have the SHA-256 that
   run recorded (a crafted summary.json cannot make glassdist delete another file).

Exit codes (also those of ``glassdist analyze``):

==========  ====================================================================
``0``       analysis done; no specification, or every criterion passed
``2``       bad input (one-line error, e.g. an invalid specification file)
``3``       analysis done, specification FAILED (:data:`EXIT_SPEC_FAIL`)
==========  ====================================================================

Files besides ``result.npz`` and ``summary.json``: ``statistics.csv``,
``worst_regions.csv``, the heatmaps ``phi_eff.png``, ``phi_shear.png``, ``axis.png``,
``input_region.png``, ``histograms.png``, ``mask_<channel>_<T>mD.png`` per limit of the
specification, ``report.html`` (``report=True``), ``fields.npz`` and ``tiff/*.tif``
(``exports=True``, pixel grid; :mod:`glassdist.storage.fields`).
"""

from __future__ import annotations

import errno
import json
import logging
import shutil
from pathlib import Path

import numpy as np

from ..acceptance.spec import load_spec, spec_limits
from ..acceptance.stats import STATISTIC_FIELDS, valid_percent
from ..errors import InputError
from ..fs import atomic_write, atomic_write_bytes, atomic_write_text, file_sha256
from ..io import camera_metadata, to_jsonable
from ..report.console import echo_acceptance
from ..report.maps import run_figures
from .fields import GRID_KEYS, SUMMARY_NAME, grid_members, pixel_members, write_fields_npz, write_fields_tiff, write_npz
from .fields import write_statistics_csv
from .folder import OutputFolder, estimate_output_bytes, open_output_folder, plan_outputs, recorded_outputs, remove_outputs

__all__ = ["EXIT_OK", "EXIT_SPEC_FAIL", "finish_analysis", "output_record", "write_outputs"]

logger = logging.getLogger(__name__)

EXIT_OK = 0
#: exit status of ``glassdist analyze --spec`` when the analysis ran but the specification failed
EXIT_SPEC_FAIL = 3


def output_record(out_dir, paths) -> dict[str, dict]:
    """``{path relative to out_dir (with '/'): {"size": bytes, "sha256": hex}}`` of files written into ``out_dir``.

    ``summary.json``, which holds the record, is left out of it.
    """
    out_dir = Path(out_dir)
    record = {Path(p).relative_to(out_dir).as_posix(): {"size": Path(p).stat().st_size, "sha256": file_sha256(p)}
              for p in paths if Path(p).name != SUMMARY_NAME or Path(p).parent != out_dir}
    return dict(sorted(record.items()))


def write_outputs(result, out_dir, *, fields="analysis", report=False, export=False, spec_path=None, spec=None,
                  protocol=None, mask=None, metadata=None, image=None, image_path=None, reference_path=None,
                  mask_path=None, captures=(), echo=print, history=None):
    """Write every output of an analysis into ``out_dir``: the one output stage of glassdist.

    Parameters
    ----------
    result : AnalysisResult
    out_dir : path or OutputFolder
        A path is taken with :func:`open_output_folder` (and released on return); an
        :class:`OutputFolder` (the command line takes it before the analysis) is used as is.
    fields : {'analysis', 'pixel'}
        Layout of ``result.npz`` (see the module documentation).
    report, export : bool
        Also write ``report.html``; ``fields.npz`` and ``tiff/``.
    spec_path : path, optional
        Acceptance specification: verdict, masks, exit status 3 on FAIL.
    spec : (Spec, str), optional
        The specification already loaded from ``spec_path`` and its SHA-256.
    protocol, mask, metadata
        As for :func:`finish_analysis`.
    image : ndarray, optional
        The photograph (any size; reduced for the figure), else read from ``image_path``.
    image_path, reference_path, mask_path : path, optional
        The inputs: recorded with their SHA-256, never overwritten.
    captures : sequence of path
        Every photo when several captures were averaged.
    echo : callable
        Receives the user-facing lines (verdict, zones, report).
    history : glassdist.history.Recording or False, optional
        How the run is recorded in the results history once its files are written
        (:func:`glassdist.history.record_run`: a history that cannot be written is a
        warning on stderr, nothing more); default ``Recording(source='api')`` (the
        database of ``GLASSDIST_DB``, else the user's data folder); False: not recorded.

    Returns
    -------
    int
        :data:`EXIT_OK` or :data:`EXIT_SPEC_FAIL`.

    Examples
    --------
    >>> res = glassdist.analyze("pane.png", pitch_mm=5, distance_m=1)   # doctest: +SKIP
    >>> glassdist.write_outputs(res, "out/pane", report=True)           # doctest: +SKIP
    0
    """
    if not isinstance(out_dir, OutputFolder):
        limits = spec_limits((spec or load_spec(spec_path))[0]) if spec_path is not None or spec else {}
        planned = plan_outputs(result.field_specs(), fields=fields, report=report, export=export, limits=limits)
        with open_output_folder(out_dir, planned=planned, inputs=(image_path, reference_path, mask_path, spec_path,
                                                                  *captures)) as folder:
            return write_outputs(result, folder, fields=fields, report=report, export=export, spec_path=spec_path,
                                 spec=spec, protocol=protocol, mask=mask, metadata=metadata, image=image,
                                 image_path=image_path, reference_path=reference_path, mask_path=mask_path,
                                 captures=captures, echo=echo, history=history)
    folder, out = out_dir, out_dir.path
    try:
        return _write_all(result, folder, fields=fields, report=report, export=export, spec_path=spec_path, spec=spec,
                          protocol=protocol, mask=mask, metadata=metadata, image=image, image_path=image_path,
                          reference_path=reference_path, mask_path=mask_path, captures=captures, echo=echo,
                          history=history)
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        free = shutil.disk_usage(out).free
        raise InputError(
            f"no space left on the disk of '{out}' ({free / 1e6:.0f} MB free): this run's outputs need up to "
            f"{estimate_output_bytes(result, folder.planned, fields) / 1e6:.0f} MB; free some space or choose "
            "another --out (without --export and --report a run needs far less)"
        ) from None


def _write_all(result, folder, *, fields, report, export, spec_path, spec, protocol, mask, metadata, image,
               image_path, reference_path, mask_path, captures, echo, history):
    """The writing of :func:`write_outputs` into the folder it holds."""
    out = folder.path
    spec = spec or (load_spec(spec_path) if spec_path is not None else None)
    members = grid_members(result) if fields == "analysis" else pixel_members(result)
    npz = atomic_write(out / "result.npz", lambda fh: write_npz(fh, members))
    acc = _assess(result, spec, spec_path, protocol=protocol, mask=mask, metadata=metadata, image_path=image_path)
    # the acceptance statistics are over the same trusted pixels: one pass over them for both files
    summary = result.summary(statistics={STATISTIC_FIELDS[ch]: s for ch, s in acc.stats.items()})
    summary["inputs"] = {
        "image": None if image_path is None else str(image_path),
        "image_sha256": None if image_path is None else file_sha256(image_path),
        "reference": None if reference_path is None else str(reference_path),
        "reference_sha256": None if reference_path is None else file_sha256(reference_path),
        "mask": None if mask_path is None else str(mask_path),
    }
    if len(captures) > 1:
        summary["inputs"]["captures"] = [{"image": str(c), "sha256": file_sha256(c)} for c in captures]
    summary["fields"] = {"layout": fields, "file": "result.npz", "keys": [f.name for f in result.field_specs()]
                         + (list(GRID_KEYS) if fields == "analysis" else ["valid"])}
    atomic_write_text(out / SUMMARY_NAME, json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n")
    code = finish_analysis(result, out_dir=out, image_path=image_path, reference_path=reference_path,
                           spec_path=spec_path, report=report, exports=export, written=[npz], echo=echo,
                           protocol=protocol, mask=mask, metadata=metadata, spec=spec, image=image, acceptance=acc,
                           summary=summary)
    # The earlier run's files that this one did not write again (its report, masks of another spec).
    names = sorted(set(folder.previous) - set(recorded_outputs(out)))
    folder.removed, folder.problems = remove_outputs(out, folder.previous, names, keep=folder.inputs)
    if history is not False:  # once every file is in place: the history can cost the run nothing
        from ..history import Recording, record_run

        record_run(to_jsonable(summary), exit_code=code, out_dir=out, recording=history or Recording())
    return code


def _assess(result, spec, spec_path, **kw):
    """:func:`~glassdist.acceptance.assess.assess` with the specification ``(Spec, sha256)`` or its path."""
    from ..acceptance.assess import assess

    spec, sha = spec or (load_spec(spec_path) if spec_path is not None else (None, ""))
    image_path = kw.pop("image_path", None)
    if image_path is not None:
        kw["camera"] = camera_metadata(image_path)
    return assess(result, spec, spec_path=spec_path or "", spec_sha256=sha, **kw)


def _describe_input(path, shape):
    if path is None:
        return None
    path = Path(path)
    return {"name": path.name, "path": str(path), "sha256": file_sha256(path), "size": f"{shape[1]} x {shape[0]} px"}


def _update_summary(path, additions, summary=None):
    """Add ``additions`` to ``summary.json``: to ``summary`` (what the caller wrote, updated in place) or the file's."""
    if summary is not None:
        summary.update(additions)
        atomic_write_text(path, json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n")
        return summary
    summary = {}
    if path.is_file():
        try:
            summary = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            logger.warning("could not read %s; writing a new one", path)
            summary = {}
    summary.update(additions)
    atomic_write_text(path, json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n")
    return summary


def finish_analysis(result, *, out_dir, image_path, reference_path=None, spec_path=None, report=False,
                    exports=False, written=(), echo=print, protocol=None, mask=None, metadata=None, spec=None,
                    image=None, acceptance=None, summary=None):
    """Statistics, verdict, zones, worst regions, A4 figures, report and exports of an analysis.

    Parameters
    ----------
    result : AnalysisResult
    out_dir : path
        Existing output folder (holds ``summary.json`` if the caller wrote one).
    image_path : path
        The analysed photograph (hashed, and drawn with the region outline).
    reference_path : path, optional
        The glass-less reference (Comparative method), hashed.
    spec_path : path, optional
        Acceptance specification JSON (:mod:`glassdist.acceptance.spec`).
    report : bool
        Write ``report.html``.
    exports : bool
        Write ``fields.npz`` and ``tiff/``.
    written : sequence of path
        Files the caller already wrote into ``out_dir`` for this analysis (``result.npz``);
        listed with this function's own in ``summary.json`` ``"outputs"``.
    echo : callable
        Receives the user-facing lines (verdict, files); default ``print``.
    protocol : ResolvedProtocol, optional
        The settings resolved from the options and the specification (recorded).
    mask : ndarray of bool, optional
        The user's region to analyse (coverage is of it).
    metadata : dict, optional
        ``pane_id``, ``lot``, ``site``, ``operator`` for the report (and the history).
    spec : (Spec, str), optional
        The specification already loaded from ``spec_path`` and its SHA-256.
    image : ndarray, optional
        The photograph (any size), instead of reading ``image_path`` again.
    acceptance : Acceptance, optional
        The assessment already made (:func:`glassdist.acceptance.assess.assess`).
    summary : dict, optional
        What the caller wrote to ``summary.json``: completed in place (and written) rather
        than read back from the file.

    Returns
    -------
    int
        :data:`EXIT_OK` or :data:`EXIT_SPEC_FAIL`.

    Raises
    ------
    InputError
        Invalid specification file, or a capture outside its protocol's limits.
    """
    from ..io import read_image

    out_dir = Path(out_dir)
    spec, spec_sha = spec or (load_spec(spec_path) if spec_path is not None else (None, ""))
    limits = spec_limits(spec) if spec is not None else {}
    acc = acceptance or _assess(result, (spec, spec_sha), spec_path, protocol=protocol, mask=mask, metadata=metadata,
                                image_path=image_path)
    stats, verdict = acc.stats, acc.verdict
    inputs = {k: _describe_input(v, result.valid.shape) for k, v in (("image", image_path), ("reference", reference_path))}
    cover = valid_percent(result.valid)
    files = [write_statistics_csv(stats, out_dir / "statistics.csv"),
             atomic_write_text(out_dir / "worst_regions.csv", acc.regions_csv())]
    figs = run_figures(result, read_image(image_path, dtype=np.float32) if image is None and image_path is not None else image, limits,
                      heatmaps=True, acceptance=acc)
    files += [atomic_write_bytes(out_dir / f"{stem}.png", png) for stem, _, png in figs]
    if exports:
        files += [write_fields_npz(result, out_dir / "fields.npz"), *write_fields_tiff(result, out_dir / "tiff")]
    measures, html = _measures_and_report(result, acc, figs, inputs, cover, report)
    if html is not None:
        files.append(atomic_write_text(out_dir / "report.html", html))
    names = [str(p.relative_to(out_dir)) for p in files]
    _update_summary(out_dir / "summary.json", {
        "verdict": verdict.to_dict() if verdict else None,
        "a4": {"statistics": stats, "valid_percent": cover, "files": names, "inputs": inputs},
        **acc.summary(), "measures": measures, "outputs": output_record(out_dir, [*written, *files]),
    }, summary)
    echo_acceptance(acc, out_dir / "report.html" if report else None, echo)
    logger.info("A4 outputs written to %s: %s", out_dir, ", ".join(names))
    return EXIT_SPEC_FAIL if verdict is not None and not verdict.passed else EXIT_OK


def _measures_and_report(result, acc, figs, inputs, cover, report):
    """The standard measures (as a dict) and, when ``report``, the HTML report's text (else None)."""
    from ..measures import standard_measures
    from ..report.html import render_report

    measures = standard_measures(result).to_dict()
    if not report:
        return measures, None
    return measures, render_report(result, stats=acc.stats, figures=figs, inputs=inputs, verdict=acc.verdict,
                                   valid_percent=cover, acceptance=acc, measures=measures)


