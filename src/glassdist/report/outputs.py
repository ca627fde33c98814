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

``result.npz`` layouts (``fields=``):

* ``'analysis'`` (default, compact): every registered field
  (:data:`glassdist.analyzer.FIELDS`) on the analysis grid, float32, NaN outside the
  analysed region, with :data:`GRID_KEYS`: the samples' pixel coordinates, the grid's
  valid samples and the pixel-grid region as bits. :func:`load_result` reads it back and
  brings any field to the pixel grid exactly as the analysis does. An NPZ with coordinate
  vectors, rather than NetCDF or Zarr: it is what the pixel-grid file already is
  (``numpy.load``, nothing to install), the grid is regular (two vectors place every
  sample) and the units are in the key names, as everywhere in glassdist.
* ``'pixel'``: the documented pixel-grid file, ``displacement_mm`` (H, W, 2; x, y),
  ``displacement_detrended_mm``, ``phi_eff_mD``, ``phi_shear_mD``, ``phi_total_mD``,
  ``axis_deg`` (NaN where invalid), the other registered fields, and ``valid``; written
  member by member, one field on the pixel grid at a time.

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
(``exports=True``, pixel grid; :mod:`glassdist.report.exports`).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import logging
import os
import re
import secrets
import shutil
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from ..errors import InputError

from .exports import atomic_write_bytes, atomic_write_text, to_jsonable, write_fields_npz, write_fields_tiff
from .exports import write_statistics_csv
from .spec import load_spec, spec_limits
from .stats import CHANNEL_FIELDS, STATISTIC_FIELDS, valid_percent

__all__ = [
    "EXIT_OK", "EXIT_SPEC_FAIL", "FIELD_LAYOUTS", "GRID_KEYS", "OutputFolder", "StoredResult", "a4_figures", "estimate_output_bytes",
    "file_sha256", "finish_analysis", "load_result", "open_output_folder", "output_record", "plan_outputs", "preview",
    "recorded_outputs", "remove_outputs", "write_npz", "write_outputs",
]

logger = logging.getLogger(__name__)

EXIT_OK = 0
#: exit status of ``glassdist analyze --spec`` when the analysis ran but the specification failed
EXIT_SPEC_FAIL = 3


#: ``fields=`` choices: the analysis grid (compact, default) or the input's pixel grid
FIELD_LAYOUTS = ("analysis", "pixel")

#: keys of the compact ``result.npz`` besides the fields
GRID_KEYS = {
    "layout": "'analysis' (this layout)",
    "image_shape": "(H, W) of the input image, px",
    "grid_rows_px": "(h,) row coordinate of each analysis-grid row in image pixels (pixel centres at integers)",
    "grid_cols_px": "(w,) column coordinate of each analysis-grid column, px",
    "grid_valid": "(h, w) bool: analysis-grid samples inside the analysed region",
    "valid_bits": "numpy.packbits of the (H, W) pixel-grid valid region, row-major",
    "mm_per_px": "backdrop mm per image px (mean scale)",
}

SUMMARY_NAME = "summary.json"
# atomic_write's temporary names: .NAME.PID.TOKEN.tmp
_DEBRIS = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.tmp$")
_FIGURES = ("phi_eff", "phi_shear", "axis", "input_region", "quality", "uncertainty", "histograms")


def plan_outputs(specs, *, fields="analysis", report=False, export=False, limits=None) -> tuple[str, ...]:
    """Every file (path relative to the output folder) a run writes, ``summary.json`` last.

    ``specs``: the result's fields (``result.field_specs()``, or
    :data:`glassdist.analyzer.FIELDS` before the analysis: a superset); ``limits``:
    ``{channel: [limit_mD, ...]}`` of the specification (one mask figure each).
    """
    from .exports import tiff_names

    if fields not in FIELD_LAYOUTS:
        raise InputError(f"fields must be one of {', '.join(FIELD_LAYOUTS)}, got '{fields}'")
    names = ["result.npz", "statistics.csv", "worst_regions.csv"] + [f"{s}.png" for s in _FIGURES]
    names += [f"mask_{ch}_{float(lim):g}mD.png" for ch, lims in (limits or {}).items() if ch in CHANNEL_FIELDS
              for lim in lims]
    if report:
        names.append("report.html")
    if export:
        names += ["fields.npz"] + [f"tiff/{n}" for n in tiff_names(specs)]
    return tuple(dict.fromkeys(names + [SUMMARY_NAME]))


def file_sha256(path) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _own_file(out_dir: Path, name) -> Path | None:
    """``out_dir / name`` if ``name`` is a plain relative path to a regular file inside ``out_dir``, else None."""
    if not isinstance(name, str) or not name or "\\" in name or "\x00" in name:
        return None
    rel = PurePosixPath(name)
    if rel.is_absolute() or any(part in ("", ".", "..") for part in rel.parts) or rel.name == SUMMARY_NAME:
        return None
    path = out_dir.joinpath(*rel.parts)
    try:
        if path.is_symlink() or not path.is_file():
            return None
        path.resolve().relative_to(out_dir.resolve())  # no linked folder on the way out
    except (OSError, ValueError):
        return None
    return path


def recorded_outputs(out_dir) -> dict[str, dict]:
    """The files the last glassdist run into ``out_dir`` recorded as written (well-formed entries only).

    Reads ``out_dir/summary.json`` (``outputs``: ``{relative path: {"size": bytes,
    "sha256": hex}}``); keeps the entries that name a regular file inside ``out_dir`` (no
    link, no '..') of the recorded size. Whether the file still has the recorded SHA-256
    is checked by :func:`remove_outputs`, just before it would remove it.

    Returns
    -------
    dict
        ``{relative path: {"size", "sha256"}}``; empty without a readable glassdist summary.
    """
    out_dir = Path(out_dir)
    try:
        with open(out_dir / SUMMARY_NAME, "rb") as fh:
            summary = json.loads(fh.read(16 << 20).decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return {}
    outputs = summary.get("outputs") if isinstance(summary, dict) and "glassdist_version" in summary else None
    if not isinstance(outputs, dict):
        return {}
    kept = {}
    for name, rec in outputs.items():
        if not (isinstance(rec, dict) and isinstance(rec.get("size"), int) and isinstance(rec.get("sha256"), str)
                and re.fullmatch(r"[0-9a-f]{64}", rec["sha256"])):
            continue
        path = _own_file(out_dir, name)
        if path is not None and path.stat().st_size == rec["size"]:
            kept[name] = {"size": rec["size"], "sha256": rec["sha256"]}
    return kept


def remove_outputs(out_dir, record: dict, names, *, keep=()) -> tuple[list[str], list[str]]:
    """Remove the files ``names`` of an earlier run's ``record`` that still have the recorded SHA-256.

    Parameters
    ----------
    out_dir : path
    record : dict
        :func:`recorded_outputs` of the earlier run.
    names : iterable of str
        Candidates; a name not in ``record``, or whose file changed since, is left alone.
    keep : iterable of path
        Files never removed (the run's inputs).

    Returns
    -------
    removed : list of str
    problems : list of str
        One line per file that could not be removed (the run goes on).
    """
    out_dir = Path(out_dir)
    keep = [Path(k) for k in keep]
    removed, problems = [], []
    for name in names:
        path = _own_file(out_dir, name) if name in record else None
        if path is None or any(_same_file(path, k) for k in keep):
            continue
        try:
            if path.stat().st_size != record[name]["size"] or file_sha256(path) != record[name]["sha256"]:
                continue  # changed since that run wrote it: not glassdist's any more
            path.unlink()
        except OSError as exc:
            problems.append(f"could not remove '{path}' of the previous run: {exc.strerror}")
            continue
        removed.append(name)
        parent = path.parent
        while parent != out_dir and out_dir in parent.parents:
            try:
                parent.rmdir()  # only if empty
            except OSError:
                break
            parent = parent.parent
    return removed, problems


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # someone else's live process (or not a pid): not provably ours
    return True


def _remove_debris(out_dir: Path, planned) -> list[str]:
    """Remove temporary files a killed run into ``out_dir`` left: ``.NAME.PID.TOKEN.tmp`` of a dead PID.

    Only names this stage writes (``planned``, and any threshold mask) qualify, and the
    caller holds the folder's lock, so no live run of ours is writing them.
    """
    removed = []
    folders = {out_dir} | {out_dir / PurePosixPath(n).parent for n in planned if "/" in n}
    for folder in folders:
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for entry in entries:
            m = _DEBRIS.match(entry.name)
            if not m or not entry.is_file(follow_symlinks=False):
                continue
            rel = Path(entry.path).relative_to(out_dir).parent / m["name"]
            name = rel.as_posix()
            ours = name in planned or re.fullmatch(r"mask_[a-z_]+_[^/]+mD\.png|tiff/[a-z_]+\.tif", name)
            if ours and not _pid_alive(int(m["pid"])):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed.append(entry.name)
    return removed


@dataclass
class OutputFolder:
    """An output folder held by one run (see :func:`open_output_folder`); release with :meth:`close`."""

    path: Path
    planned: tuple[str, ...]
    inputs: tuple[Path, ...]
    previous: dict
    debris_removed: list[str] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)  # an earlier run's files this run removed
    problems: list[str] = field(default_factory=list)  # those it could not remove
    created: Path | None = None  # the topmost folder this run created, if any
    _lock_fd: int | None = None

    def close(self, failed: bool = False) -> None:
        """Release the folder; after a failed run, remove the folders it created if they are still empty."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None
        if failed and self.created is not None:
            _remove_empty_tree(self.path, self.created)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(failed=exc_type is not None)


def _first_missing(path: Path) -> Path | None:
    """The topmost folder of ``path`` that does not exist yet (None if ``path`` exists)."""
    missing = None
    for p in (path, *path.parents):
        try:
            if p.exists():
                break
        except OSError:  # e.g. a name too long: prepare_output_dir says so
            return None
        missing = p
    return missing


def _remove_empty_tree(path: Path, top: Path) -> None:
    """Remove ``path`` and its parents up to ``top`` while they are empty (a refused run leaves no folder)."""
    path, top = Path(path).absolute(), Path(top).absolute()
    if top != path and top not in path.parents:
        return
    for p in (path, *path.parents):
        try:
            p.rmdir()
        except OSError:  # not empty (or gone): keep it and what is above
            return
        if p == top:
            return


def _lock(path: Path) -> int | None:
    """Exclusive, non-blocking lock on the folder itself (no lock file left behind)."""
    try:
        import fcntl
    except ImportError:  # no advisory locks on this platform
        return None
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise InputError(f"another glassdist run is writing to '{path}'; wait for it to finish or choose another --out") from None
    return fd


def _check_writable(path: Path) -> None:
    probe = path / f".glassdist-probe.{os.getpid()}.{secrets.token_hex(4)}.tmp"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"cannot write into output folder '{path}': {exc.strerror}; choose a writable --out") from None


def open_output_folder(out_dir, *, planned=(), inputs=()) -> OutputFolder:
    """Take ``out_dir`` for one run, before any work: every check that can refuse the run is here.

    Parameters
    ----------
    out_dir : path
        Created (with parents) if needed.
    planned : sequence of str
        :func:`plan_outputs` of the run.
    inputs : sequence of path or None
        The run's input files (image, reference, mask, specification, parameters).

    Returns
    -------
    OutputFolder
        Holding an exclusive lock on the folder until closed (a second run into the same
        folder is refused, exit status 2, rather than mixing two runs' files).

    Raises
    ------
    InputError
        ``out_dir`` is a file, cannot be created or written, is locked by another run, or a
        planned output would overwrite an input (e.g. ``--out`` is the input's folder and
        the image is called ``phi_eff.png``).
    """
    from ..io import prepare_output_dir

    created = _first_missing(Path(out_dir).absolute())
    path = prepare_output_dir(out_dir)
    try:
        return _take_folder(path, planned, inputs, created)
    except BaseException:
        if created is not None:
            _remove_empty_tree(path, created)
        raise


def _take_folder(path: Path, planned, inputs, created) -> OutputFolder:
    """The checks and the lock of :func:`open_output_folder` on the existing folder ``path``."""
    inputs = tuple(Path(p) for p in inputs if p is not None)
    for name in planned:
        target = path / name
        for p in inputs:
            if _same_file(target, p):
                raise InputError(
                    f"the input '{p}' would be overwritten by the output '{name}' in '{path}'; "
                    "choose another --out folder (or rename the input)"
                )
    _check_writable(path)
    fd = _lock(path)
    folder = OutputFolder(path, tuple(planned), inputs, {}, created=created, _lock_fd=fd)
    try:
        folder.debris_removed = _remove_debris(path, set(planned))
        folder.previous = recorded_outputs(path)
        _refuse_foreign(path, planned, folder.previous)
    except BaseException:
        folder.close()
        raise
    return folder


def _is_summary(path: Path) -> bool:
    """Whether ``path`` is a summary a glassdist run wrote (it names the version and the outputs)."""
    try:
        with open(path, "rb") as fh:
            summary = json.loads(fh.read(16 << 20).decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return False
    return isinstance(summary, dict) and "glassdist_version" in summary and isinstance(summary.get("outputs"), dict)


def _refuse_foreign(path: Path, planned, previous: dict) -> None:
    """Refuse the run when a planned output's name is taken by a file glassdist did not write.

    A file is the tool's own when the previous run's ``summary.json`` records it with its
    present size and SHA-256 (``summary.json`` itself when it is a glassdist summary);
    anything else in the way (the user's own ``summary.json``, a ``phi_eff.png`` edited
    or made by hand, a folder) would be overwritten, so the run stops before any work.

    Raises
    ------
    InputError
        Naming the first such file.
    """
    for name in planned:
        target = path.joinpath(*PurePosixPath(name).parts)
        if not os.path.lexists(target):
            continue
        if name == SUMMARY_NAME:
            own = target.is_file() and not target.is_symlink() and _is_summary(target)
        else:
            rec = previous.get(name)
            own = rec is not None and _own_file(path, name) is not None and file_sha256(target) == rec["sha256"]
        if not own:
            raise InputError(
                f"'{target}' is in the way of the output '{name}' and was not written by glassdist (no previous "
                "run's summary.json records it); move it away or choose another --out folder"
            )


def write_npz(fh, members) -> None:
    """Write an NPZ member by member: ``members`` yields ``(key, array, compress)``, one array at a time.

    Only the array being written is held (a generator can produce each plane when asked);
    ``numpy.load`` reads the file like any ``numpy.savez`` output.
    """
    with zipfile.ZipFile(fh, "w", allowZip64=True) as zf:
        for key, arr, compress in members:
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
            if compress:
                info._compresslevel = 1  # fast: the members compressed are masks
            with zf.open(info, "w", force_zip64=True) as m:
                np.lib.format.write_array(m, np.asanyarray(arr), allow_pickle=False)


def _grid_members(result):
    """``result.npz`` members of the analysis-grid layout (:data:`GRID_KEYS` and the fields)."""
    grid = result.analysis_grid
    rows, cols = grid.coords()
    gv = np.asarray(result.grid_valid, dtype=bool)
    yield "layout", np.str_("analysis"), False
    yield "image_shape", np.asarray(grid.full_shape, dtype=np.int64), False
    yield "grid_rows_px", rows[:, 0].astype(np.float64), False
    yield "grid_cols_px", cols[0].astype(np.float64), False
    yield "grid_valid", gv, True
    yield "valid_bits", np.packbits(np.asarray(result.valid, dtype=bool), axis=None), True
    yield "mm_per_px", np.float64(result.mm_per_px), False
    for spec in result.field_specs():
        if spec.kind == "float":
            f = np.array(result.grid_field(spec.name), dtype=np.float32)
            f[~gv] = np.nan
            yield spec.name, f, False
        else:  # label maps: on the pixel grid (their own rules there), compressed to a few hundred kB
            yield spec.name, result.pixel_field(spec.name), True


def _pixel_members(result, on_plane=None):
    """``result.npz`` members of the pixel-grid layout: each field brought to the pixel grid, one at a time."""
    for spec in result.field_specs():
        plane = result.pixel_field(spec.name)
        if on_plane is not None:
            on_plane(spec.name, plane)
        yield spec.name, plane, False
        del plane
    yield "valid", np.asarray(result.valid, dtype=bool), False


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


def estimate_output_bytes(result, planned, fields="analysis") -> int:
    """Upper bound (bytes) of what a run's outputs ``planned`` take on disk, before compression.

    Each full-resolution file (``result.npz`` with ``fields='pixel'``, ``fields.npz``, one
    TIFF per plane) holds the fields on the pixel grid, 4 bytes a value (1 for labels);
    the compact ``result.npz`` about a 49th of that (a ~7 px analysis step); 2 MB for each
    figure, table and the report.
    """
    h, w = result.valid.shape
    sizes = {s.name: h * w * s.components * (4 if s.kind == "float" else 1) for s in result.field_specs()}
    full = sum(sizes.values()) + h * w
    total = 0
    for name in planned:
        if name == "result.npz":
            total += full if fields == "pixel" else full // 49
        elif name == "fields.npz":
            total += full
        elif name.startswith("tiff/"):
            total += 4 * h * w  # one float32 plane
        else:
            total += 2 << 20
    return total


def _write_all(result, folder, *, fields, report, export, spec_path, spec, protocol, mask, metadata, image,
               image_path, reference_path, mask_path, captures, echo, history):
    """The writing of :func:`write_outputs` into the folder it holds."""
    from .exports import atomic_write

    out = folder.path
    spec = spec or (load_spec(spec_path) if spec_path is not None else None)
    members = _grid_members(result) if fields == "analysis" else _pixel_members(result)
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
    """:func:`~glassdist.report.acceptance.assess` with the specification ``(Spec, sha256)`` or its path."""
    from .acceptance import assess

    spec, sha = spec or (load_spec(spec_path) if spec_path is not None else (None, ""))
    return assess(result, spec, spec_path=spec_path or "", spec_sha256=sha, **kw)


def _describe_input(path, shape):
    if path is None:
        return None
    path = Path(path)
    return {"name": path.name, "path": str(path), "sha256": file_sha256(path), "size": f"{shape[1]} x {shape[0]} px"}


def preview(image, max_px: int = 1200) -> np.ndarray:
    """``image`` reduced by area averaging so that its longer side is at most ``max_px`` (float32)."""
    import cv2

    img = np.asarray(image, dtype=np.float32)
    k = max(img.shape) / max_px
    if k <= 1:
        return img
    size = (max(1, round(img.shape[1] / k)), max(1, round(img.shape[0] / k)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def _map_of(result, attr):
    """Field ``attr`` on the result's analysis grid (what every figure draws), NaN outside the region."""
    f = np.array(result.grid_field(attr), dtype=np.float64)
    f[~result.grid_valid] = np.nan
    return f


def _heatmap(result, name, field, gv, v, chosen, axes, acceptance):
    """``(stem, caption, png)`` of one channel's heatmap (analysis grid), with the acceptance overlays."""
    from . import figures as F
    from .acceptance import describe_clipping, draw_overlays

    extent, to_axes, units, px_axis = axes
    _, label, cmap, signed = F.CHANNELS[name]
    fig, ax = F.plot_channel(field, gv, signed=signed, vmax=v, cmap=cmap, title=f"{label}, mD", extent=extent,
                             axis_units=units, px_axis=px_axis)
    span = f"[-{v:.3g}, {v:.3g}]" if signed else f"[0, {v:.3g}]"
    caption = f"{name} in mD; colour limits {span} mD" + ("." if chosen else " shared by both channels.")
    if acceptance is not None:
        draw_overlays(ax, acceptance, name, to_axes, extent)
        # the maximum and the clipped share over the trusted samples, as the statistics
        clip = describe_clipping(field, gv & np.asarray(result.grid_trusted, bool), v,
                                 acceptance.stats.get(name, {}).get("max_abs"))
        F.map_title(ax, f"{label}, mD\n{clip}", fontsize="medium")
        n = len(acceptance.regions.get(name, {}).get("regions", ()))
        caption += (f" Axes in {units}. {clip} (trusted pixels). Dashed: zones; numbers: the "
                    f"{n} worst regions (worst_regions.csv).")
    return name, caption + " Grey: not analysed.", F.figure_png(fig)


def _quality_figures(result, gv, axes, max_px=900):
    """The quality map (labels, reduced by striding to at most ``max_px`` a side) and the phi_eff uncertainty map.

    ``axes``: ``(extent, units, px_axis)`` of every map (:func:`_map_axes`).
    """
    extent, units, px_axis = axes
    from . import figures as F

    held = {f.name for f in result.field_specs()}
    out = []
    if "quality" in held:
        q = np.asarray(result.quality)
        k = max(1, -(-max(q.shape) // max_px))
        fig, _ = F.plot_quality(q[::k, ::k], counts=result.quality_counts(), title="Quality labels", extent=extent,
                                axis_units=units, px_axis=px_axis)
        out.append(("quality", "Quality map: every pixel's label (README, quality labels). Statistics, verdicts and "
                               "the maximum use label 0 only; label 6 is reported but not trusted.", F.figure_png(fig)))
    if "phi_eff_sigma_mD" in held:
        sig = _map_of(result, "phi_eff_sigma_mD")
        trusted = gv & np.asarray(result.grid_trusted, bool)
        floor = result.noise_floor()["phi_eff_sigma_mD"]["median"]
        fig, _ = F.plot_channel(sig, gv, signed=False, vmax=F.shared_limit(sig, valid=trusted), cmap="magma",
                                title=f"standard uncertainty of $\\phi_{{eff}}$, mD\nnoise floor {floor:.3g} mD",
                                extent=extent, axis_units=units, px_axis=px_axis)
        out.append(("uncertainty", f"Standard uncertainty of phi_eff from the image noise (phi_eff_sigma_mD), mD; "
                                   f"noise floor (median over the trusted pixels) {floor:.3g} mD. Values of |phi_eff| "
                                   "within about 2 of it are not distinguishable from noise.", F.figure_png(fig)))
    return out


def a4_figures(result, image=None, limits=None, *, heatmaps=True, acceptance=None):
    """Render the A4 figures of a result, from its analysis grid.

    Every map is drawn from the fields on the analysis grid (``result.grid_field``), placed
    over the photo's pixels (or millimetres) by its extent: at camera resolution,
    resampling the pixel-grid fields for a 600 px figure cost more than the analysis.

    Parameters
    ----------
    result : AnalysisResult
    image : ndarray, shape (h, w), optional
        The analysed photograph (grey, [0, 1]), any size (reduced by :func:`preview`), for
        the region outline.
    limits : dict, optional
        ``{channel: [limit_mD, ...]}``: a threshold mask per limit, and limit lines
        on the histograms.
    heatmaps : bool
        Include the channel and axis heatmaps (ids ``phi_eff``, ``phi_shear``, ``axis``).
    acceptance : Acceptance, optional
        Zones and numbered worst regions drawn on the heatmaps, which then have
        millimetre axes and the colour limits it chose
        (:mod:`glassdist.report.acceptance`).

    Returns
    -------
    list of (str, str, bytes)
        ``(file stem, caption, PNG bytes)`` in report order.
    """
    from matplotlib.figure import Figure

    from . import figures as F

    limits = limits or {}
    H, W = result.valid.shape
    gv = np.asarray(result.grid_valid, dtype=bool)
    trusted = gv & np.asarray(result.grid_trusted, dtype=bool)  # the statistics' pixels
    sy, sx = result.analysis_grid.step
    maps = {name: _map_of(result, F.CHANNELS[name][0]) for name in ("phi_eff", "phi_shear")}
    out = []
    vmax = F.shared_limit(*maps.values(), valid=trusted)
    vmaxes = dict(acceptance.colour_limits) if acceptance is not None else {}
    extent, to_axes, units, px_axis = _map_axes(result, acceptance)
    if image is not None:
        import cv2

        small = preview(image)
        region = cv2.resize(np.asarray(result.valid, np.uint8), small.shape[::-1], interpolation=cv2.INTER_NEAREST)
        fig, _ = F.plot_input(small, region.astype(bool), extent=extent, axis_units=units, px_axis=px_axis)
        out.append(("input_region", "Input photograph; the analysed region is outlined in orange.", F.figure_png(fig)))
    for name in ("phi_eff", "phi_shear") if heatmaps else ():
        out.append(_heatmap(result, name, maps[name], gv, vmaxes.get(name, vmax), bool(vmaxes),
                            (extent, to_axes, units, px_axis), acceptance))
    if heatmaps and any(f.name == "axis_deg" for f in result.field_specs()):
        fig, _ = F.plot_axis(_map_of(result, "axis_deg"), maps["phi_shear"], gv, extent=extent, axis_units=units,
                             px_axis=px_axis)
        out.append(("axis", "Astigmatism axis (direction of largest stretch), degrees from +x towards +y (down); "
                            "grey where phi_shear is too small for the axis to be meaningful.", F.figure_png(fig)))
    out += _quality_figures(result, gv, (extent, units, px_axis))
    for name, lims in ((n, v) for n, v in limits.items() if n in F.CHANNELS):  # masks of the power channels
        field = maps[name] if name in maps else _map_of(result, F.CHANNELS[name][0])
        for lim in lims:
            fig, _ = F.plot_threshold_mask(field, gv, limit_mD=lim, name=name, extent=extent, axis_units=units,
                                           px_axis=px_axis)
            out.append((f"mask_{name}_{lim:g}mD", f"{name}: pixels with |{name}| > {lim:g} mD in red.",
                        F.figure_png(fig)))
    stats = acceptance.stats if acceptance is not None else {}
    fig = Figure(figsize=(10, 3.8))
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.14, top=0.9, wspace=0.3)
    for ax, name in zip(fig.subplots(1, 2), ("phi_eff", "phi_shear")):
        _, label, _, signed = F.CHANNELS[name]
        F.plot_histogram(maps[name], trusted, signed=signed, limits_mD=limits.get(name, ()), ax=ax, title=label,
                         weight=sy * sx, max_abs_mD=stats.get(name, {}).get("max_abs"))
    out.append(("histograms", "Histograms over the trusted pixels (quality label 0, the statistics' pixels; "
                              "analysis-grid samples weighted by their cells); axis range: the statistics' largest "
                              "|value| (or a specification limit beyond it, dashed red).", F.figure_png(fig)))
    return out


def _map_axes(result, acceptance):
    """``(extent, to_axes, units, px_axis)`` shared by every map: millimetres, and the photo's px along the top.

    The pane's (or the backdrop's) mm of the acceptance frame when there is one
    (:func:`~glassdist.report.acceptance.heatmap_axes`), else backdrop mm from the photo's
    top-left corner (``mm_per_px``). ``px_axis`` = ``(scale, offset)`` with column px =
    scale * x_mm + offset (both frames are axis-aligned scalings of the pixel grid).
    """
    from .acceptance import heatmap_axes

    H, W = result.valid.shape
    s = float(result.mm_per_px)
    if acceptance is not None:
        extent, to_axes, units = heatmap_axes(acceptance.frame, s, (H, W))
    else:
        def to_axes(x, y):
            return (np.asarray(x, dtype=float) + 0.5) * s, (np.asarray(y, dtype=float) + 0.5) * s
        extent, units = (0.0, W * s, H * s, 0.0), "backdrop mm from the photo's top-left"
    (x0, x1), _ = to_axes(np.array([0.0, 1.0]), np.array([0.0, 0.0]))
    scale = 1.0 / float(x1 - x0)
    return extent, to_axes, units, (scale, -float(x0) * scale)


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


def _echo_acceptance(acc, report_path, echo):
    """The user-facing lines of the A4 stage: warnings (stderr), verdict, zones, the report's path."""
    for w in acc.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if acc.verdict is not None:
        for line in acc.verdict.lines():
            echo(line)
    for name, z in acc.zones.items():
        eff, shear = z["statistics"].get("phi_eff", {}), z["statistics"].get("phi_shear", {})
        echo(f"zone {name}: {z['coverage_percent']:.1f} % analysed, p95 |phi_eff| {eff.get('p95_abs', float('nan')):.4g} mD, "
             f"p95 |phi_shear| {shear.get('p95_abs', float('nan')):.4g} mD")
    if report_path is not None:
        echo(f"report: {report_path}")


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
        Acceptance specification JSON (:mod:`glassdist.report.spec`).
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
        The assessment already made (:func:`glassdist.report.acceptance.assess`).
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
    figs = a4_figures(result, read_image(image_path, dtype=np.float32) if image is None and image_path is not None else image, limits,
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
    _echo_acceptance(acc, out_dir / "report.html" if report else None, echo)
    logger.info("A4 outputs written to %s: %s", out_dir, ", ".join(names))
    return EXIT_SPEC_FAIL if verdict is not None and not verdict.passed else EXIT_OK


def _measures_and_report(result, acc, figs, inputs, cover, report):
    """The standard measures (as a dict) and, when ``report``, the HTML report's text (else None)."""
    from .html import render_report
    from .measures import standard_measures

    measures = standard_measures(result).to_dict()
    if not report:
        return measures, None
    return measures, render_report(result, stats=acc.stats, figures=figs, inputs=inputs, verdict=acc.verdict,
                                   valid_percent=cover, acceptance=acc, measures=measures)


@dataclass(frozen=True)
class StoredResult:
    """A run's fields read back from its folder (:func:`load_result`).

    Attributes
    ----------
    layout : {'analysis', 'pixel'}
        How ``result.npz`` stores the fields.
    fields : dict of str -> ndarray
        As stored: on the analysis grid (h, w[, 2]) or on the pixel grid (H, W[, 2]);
        float32, NaN outside the analysed region.
    valid : ndarray (H, W) bool
        The analysed region on the pixel grid.
    grid_valid : ndarray (h, w) bool
        The analysed samples of the analysis grid (``valid`` for the pixel layout).
    grid_rows_px, grid_cols_px : ndarray
        Pixel coordinates of the stored rows and columns (integers 0..H-1, 0..W-1 for the
        pixel layout).
    summary : dict
        ``summary.json``.
    """

    layout: str
    fields: dict
    valid: np.ndarray
    grid_valid: np.ndarray
    grid_rows_px: np.ndarray
    grid_cols_px: np.ndarray
    summary: dict

    def pixel_field(self, name: str) -> np.ndarray:
        """Field ``name`` on the input's pixel grid, brought there exactly as the analysis does."""
        if name not in self.fields:
            raise KeyError(f"'{name}' is not a field of this result; it holds {', '.join(self.fields)}")
        f = self.fields[name]
        if self.layout == "pixel" or f.shape[:2] == self.valid.shape:  # label maps are stored on the pixel grid
            return f
        from ..analyzer.fourier import SamplingGrid
        from ..analyzer.resample import grid_fill_indices, upsample_field, upsample_labels

        grid = SamplingGrid(tuple(self.valid.shape), tuple(self.grid_valid.shape))
        if f.dtype.kind != "f":
            return upsample_labels(f, grid)
        return upsample_field(f, grid_fill_indices(self.grid_valid), grid, ~self.valid)

    def to_pixel_grid(self) -> dict:
        """Every field on the pixel grid, plus ``valid``: the keys of ``analyze --fields pixel``'s result.npz."""
        return {**{name: self.pixel_field(name) for name in self.fields}, "valid": self.valid}


def load_result(out_dir) -> StoredResult:
    """Read the fields of a ``glassdist analyze`` run from its output folder.

    Parameters
    ----------
    out_dir : path
        Folder holding ``result.npz`` and ``summary.json`` (either layout).

    Returns
    -------
    StoredResult
        ``.fields`` as stored, ``.pixel_field(name)`` / ``.to_pixel_grid()`` on the pixel grid.

    Raises
    ------
    InputError
        No readable glassdist result in ``out_dir``.

    Examples
    --------
    >>> res = glassdist.load_result("out/waves")                    # doctest: +SKIP
    >>> res.fields["phi_eff_mD"].shape, res.pixel_field("phi_eff_mD").shape  # doctest: +SKIP
    ((150, 150), (1024, 1024))
    """
    from ..analyzer.result import FIELDS

    out_dir = Path(out_dir)
    try:
        summary = json.loads((out_dir / SUMMARY_NAME).read_text(encoding="utf-8"))
        z = np.load(out_dir / "result.npz", allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"'{out_dir}' holds no readable glassdist result ({exc}); give the --out folder of a "
                         "'glassdist analyze' run") from None
    with z:
        names = [f.name for f in FIELDS if f.name in z.files]
        fields = {n: z[n] for n in names}
        if "layout" in z.files and str(z["layout"]) == "analysis":
            H, W = (int(v) for v in z["image_shape"])
            valid = np.unpackbits(z["valid_bits"], count=H * W).reshape(H, W).astype(bool)
            return StoredResult("analysis", fields, valid, z["grid_valid"], z["grid_rows_px"], z["grid_cols_px"], summary)
        valid = z["valid"]
    H, W = valid.shape
    return StoredResult("pixel", fields, valid, valid, np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64),
                        summary)
