"""The output stage of glassdist: every file of a run, written once from its record.

The command line, ``glassdist batch`` and the web app (through their child ``glassdist
analyze`` processes) and the Python API (:func:`write_outputs`) all write a run's folder
through :func:`write_run`: ``result.npz`` (:mod:`~glassdist.storage.fields`),
``statistics.csv``, ``worst_regions.csv``, the figures (rendered by
:mod:`glassdist.report.maps`), ``report.html`` (``report``), ``fields.npz`` and
``tiff/*.tif`` (``export``), then ``summary.json`` once, last, with the size and SHA-256
of every file, hashed while it was written (:func:`glassdist.fs.atomic_write`). Each file is
written atomically (a temporary name, then a rename).

Exit codes (also those of ``glassdist analyze``):

==========  ====================================================================
``0``       analysis done; no specification, or every criterion passed
``2``       bad input (one-line error, e.g. an invalid specification file)
``3``       analysis done, specification FAILED (:data:`EXIT_SPEC_FAIL`)
==========  ====================================================================
"""

from __future__ import annotations

import errno
import itertools
import json
import logging
import shutil
from pathlib import Path

from ..acceptance.spec import as_spec
from ..errors import InputError
from ..fs import atomic_write, atomic_write_bytes, atomic_write_text
from ..io import to_jsonable
from ..report.html import render_report
from ..report.maps import run_figures
from .fields import (
    SUMMARY_NAME,
    grid_members,
    pixel_members,
    write_fields_npz,
    write_fields_tiff,
    write_npz,
    write_statistics_csv,
)
from .folder import OutputFolder, estimate_output_bytes, open_output_folder, plan_outputs, remove_outputs
from .record import EXIT_OK, EXIT_SPEC_FAIL, RunRequest, build_record, read_inputs, result_protocol

__all__ = ["EXIT_OK", "EXIT_SPEC_FAIL", "write_outputs", "write_run"]

logger = logging.getLogger(__name__)


def write_outputs(result, out_dir, *, fields="analysis", report=False, export=False, spec=None, spec_path=None,
                  protocol=None, mask=None, metadata=None, image=None, image_path=None, reference_path=None,
                  mask_path=None, history=None, camera_distance_m=None):
    """Write every file ``glassdist analyze`` writes for an analysis made in Python; prints nothing.

    The same straight line as the command line, from a result in hand: the request from
    the arguments, the inputs read once (the photo for its preview, SHA-256 and EXIF),
    the folder taken, the capture checked and the result assessed
    (:func:`~glassdist.storage.record.build_record`), then :func:`write_run`.

    Parameters
    ----------
    result : AnalysisResult
    out_dir : path
        Created if needed; taken with :func:`~glassdist.storage.folder.open_output_folder`.
    fields : {'analysis', 'pixel'}
        Layout of ``result.npz`` (:mod:`~glassdist.storage.fields`).
    report, export : bool
        Also write ``report.html``; ``fields.npz`` and ``tiff/``.
    spec : LoadedSpec, Spec, dict or path, optional
        Acceptance specification: verdict, masks, exit status 3 on FAIL.
    spec_path : path, optional
        The specification file, when ``spec`` is not given.
    protocol : ResolvedProtocol, optional
        The settings resolved from the options and the specification (recorded). Default,
        for a result of :func:`glassdist.analyze`: the command line's record of the same
        settings (:func:`~glassdist.storage.record.result_protocol`).
    mask : ndarray of bool, optional
        The region the analysis was asked for (coverage is of it).
    metadata : dict, optional
        ``pane_id``, ``lot``, ``site``, ``operator``.
    image : ndarray, optional
        The photograph (any size), drawn with the analysed region outlined when no
        ``image_path`` is given.
    image_path, reference_path, mask_path : path, optional
        The inputs: recorded with their SHA-256, never overwritten; the photo is drawn
        with the analysed region outlined (``input_region.png``). Default: the files
        :func:`glassdist.analyze` read, when it was given paths (``result.sources``).
    history : glassdist.history.Recording or False, optional
        How the run is recorded in the results history once its files are written
        (:func:`glassdist.history.store.record`: a history that cannot be written keeps
        the record in the spool until a later run reaches it, and says so with a
        ``RuntimeWarning``); default ``Recording(source='api')`` (the database of
        ``GLASSDIST_DB``, else the user's data folder); False: not recorded.
    camera_distance_m : float, optional
        Camera to pane, m (transmission, normal incidence): also the pane's intrinsic reading
        (:mod:`glassdist.viewpoint.intrinsic`).

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
    given = spec if spec is not None else spec_path
    loaded = as_spec(given) if given is not None else None
    if protocol is None:
        protocol = result_protocol(result, loaded)
    request = RunRequest(fields=fields, report=report, export=export, spec=loaded, protocol=protocol, mask=mask,
                         metadata=dict(metadata or {}), history=history, camera_distance_m=camera_distance_m)
    inputs = read_inputs(image_path, reference_path, mask_path, image=image, sources=result.sources)
    planned = plan_outputs(result.field_specs(), fields=fields, report=report, export=export, limits=request.limits)
    spec_file = Path(loaded.path) if loaded is not None and loaded.path else None
    with open_output_folder(out_dir, planned=planned, inputs=(*inputs.paths, spec_file)) as folder:
        record = build_record(request, inputs, result)
        write_run(record, folder)
    if folder.recorded is not None and folder.recorded.warning:  # kept in the spool (or lost): said, not printed
        import warnings

        warnings.warn(folder.recorded.line().removeprefix("warning: "), RuntimeWarning, stacklevel=2)
    return record.exit_code


def write_run(record, folder: OutputFolder) -> dict:
    """Write every file of a run into the folder it holds: the one output stage of glassdist.

    ``result.npz``, ``statistics.csv``, ``worst_regions.csv``, the figures, the exports
    (``request.export``), ``report.html`` (``request.report``) and, last and once,
    ``summary.json`` with the size and SHA-256 of every file, hashed from the bytes as
    they were written (nothing is read back). Then the files of an earlier run into the
    folder that this run did not write again are removed (where they still have the
    SHA-256 it recorded) and the run is recorded in the results history (where its record
    went: ``folder.recorded``, a :class:`glassdist.history.store.Recorded`).

    Parameters
    ----------
    record : RunRecord
        :func:`~glassdist.storage.record.build_record`.
    folder : OutputFolder
        :func:`~glassdist.storage.folder.open_output_folder`, held by this run.

    Returns
    -------
    dict
        The ``summary.json`` written.

    Raises
    ------
    InputError
        The disk filled up (with the space the outputs need).
    """
    try:
        return _write_files(record, folder)
    except OSError as exc:
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        out = folder.path
        free = shutil.disk_usage(out).free
        need = estimate_output_bytes(record.result, folder.planned, record.request.fields)
        raise InputError(
            f"no space left on the disk of '{out}' ({free / 1e6:.0f} MB free): this run's outputs need up to "
            f"{need / 1e6:.0f} MB; free some space or choose another --out (without --export and --report a run "
            "needs far less)"
        ) from None


def _write_files(record, folder) -> dict:
    out = folder.path
    digests: dict = {}
    try:
        summary = _write_outputs(record, out, digests)
    except BaseException:
        # A run stopped half-way (an error, a full disk, Ctrl-C) takes back the files it wrote, where
        # they still hold what it wrote: else they, recorded by no summary.json, would stand in the
        # way of the next run into this folder as files glassdist did not write.
        written = {Path(p).relative_to(out).as_posix(): d for p, d in digests.items()}
        remove_outputs(out, written, written, keep=folder.inputs)
        raise
    # The earlier run's files that this one did not write again (its report, masks of another spec).
    names = sorted(set(folder.previous) - set(summary["outputs"]))
    folder.removed, folder.problems = remove_outputs(out, folder.previous, names, keep=folder.inputs)
    # once every file is in place: the history can cost the run nothing (a record it cannot write waits in the spool)
    from ..history.store import record as record_in_history

    folder.recorded = record_in_history(summary, exit_code=record.exit_code, out_dir=out,
                                        recording=record.request.history)
    logger.info("outputs written to %s: %s", out, ", ".join(summary["outputs"]))
    return summary


def _write_outputs(record, out, digests) -> dict:
    """Every file of the run into ``out``, ``summary.json`` last; ``digests`` collects what was written."""
    result, request, acc = record.result, record.request, record.acceptance
    members = grid_members(result) if request.fields == "analysis" else pixel_members(result)
    if request.camera_distance_m is not None and result.optics is None:  # the pane's intrinsic maps
        from ..viewpoint.intrinsic import intrinsic_members

        pose = request.capture_pose
        members = itertools.chain(members, intrinsic_members(result, request.camera_distance_m, request.fields,
                                                             None if pose is None else pose.geometry))
    atomic_write(out / "result.npz", lambda fh: write_npz(fh, members), digests=digests)
    files = [write_statistics_csv(acc.stats, out / "statistics.csv", digests=digests),
             atomic_write_text(out / "worst_regions.csv", acc.regions_csv(), digests=digests)]
    figs = run_figures(result, record.inputs.preview, request.limits, heatmaps=True, acceptance=acc)
    files += [atomic_write_bytes(out / f"{stem}.png", png, digests=digests) for stem, _, png in figs]
    if request.export:
        files += [write_fields_npz(result, out / "fields.npz", digests=digests),
                  *write_fields_tiff(result, out / "tiff", digests=digests)]
    if request.report:
        html = render_report(result, stats=acc.stats, figures=figs, inputs=record.described_inputs(),
                             verdict=acc.verdict, acceptance=acc, mask_given=request.mask is not None,
                             measures=record.measures)
        files.append(atomic_write_text(out / "report.html", html, digests=digests))
    summary = to_jsonable(record.summary(files=[str(p.relative_to(out)) for p in files]))
    summary["outputs"] = dict(sorted((Path(p).relative_to(out).as_posix(), d) for p, d in digests.items()))
    atomic_write_text(out / SUMMARY_NAME, json.dumps(summary, indent=2, allow_nan=False) + "\n")
    return summary
