"""The run folder: what a run writes there, taken before the analysis, and what an earlier run left.

1. :func:`plan_outputs` names the files a run can write, before any work;
2. :func:`open_output_folder` takes the folder before the analysis: created, refused when
   a planned output would overwrite an input, checked writable, locked against a second
   run into it (exit status 2), and cleaned of the temporary files a killed run left;
3. once the run's files are written, files of an earlier run into the folder that this
   run did not write again are removed (:func:`remove_outputs`) only where they still
   have the SHA-256 that run recorded in its ``summary.json`` (:func:`recorded_outputs`):
   a crafted summary.json cannot make glassdist delete another file.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from ..acceptance.stats import CHANNEL_FIELDS
from ..errors import InputError
from ..fs import TEMP_NAME, check_writable, file_sha256, first_missing, lock_folder, pid_alive, remove_empty_tree, same_file
from ..io import prepare_output_dir
from .fields import FIELD_LAYOUTS, SUMMARY_NAME, tiff_names

__all__ = [
    "SUMMARY_NAME", "OutputFolder", "estimate_output_bytes", "open_output_folder", "plan_outputs", "recorded_outputs",
    "remove_outputs",
]



_FIGURES = ("phi_eff", "phi_shear", "axis", "input_region", "quality", "uncertainty", "histograms")


def plan_outputs(specs, *, fields="analysis", report=False, export=False, limits=None) -> tuple[str, ...]:
    """Every file (path relative to the output folder) a run writes, ``summary.json`` last.

    ``specs``: the result's fields (``result.field_specs()``, or
    :data:`glassdist.analyzer.FIELDS` before the analysis: a superset); ``limits``:
    ``{channel: [limit_mD, ...]}`` of the specification (one mask figure each).
    """
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
        if path is None or any(same_file(path, k) for k in keep):
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
            m = TEMP_NAME.match(entry.name)
            if not m or not entry.is_file(follow_symlinks=False):
                continue
            rel = Path(entry.path).relative_to(out_dir).parent / m["name"]
            name = rel.as_posix()
            ours = name in planned or re.fullmatch(r"mask_[a-z_]+_[^/]+mD\.png|tiff/[a-z_]+\.tif", name)
            if ours and not pid_alive(int(m["pid"])):
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
    recorded: object = None  # where the run's record went (glassdist.history.store.Recorded), once written
    _lock_fd: int | None = None

    def close(self, failed: bool = False) -> None:
        """Release the folder; after a failed run, remove the folders it created if they are still empty."""
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # releases the flock
            self._lock_fd = None
        if failed and self.created is not None:
            remove_empty_tree(self.path, self.created)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        self.close(failed=exc_type is not None)


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
    created = first_missing(Path(out_dir).absolute())
    path = prepare_output_dir(out_dir)
    try:
        return _take_folder(path, planned, inputs, created)
    except BaseException:
        if created is not None:
            remove_empty_tree(path, created)
        raise


def _take_folder(path: Path, planned, inputs, created) -> OutputFolder:
    """The checks and the lock of :func:`open_output_folder` on the existing folder ``path``."""
    inputs = tuple(Path(p) for p in inputs if p is not None)
    for name in planned:
        target = path / name
        for p in inputs:
            if same_file(target, p):
                raise InputError(
                    f"the input '{p}' would be overwritten by the output '{name}' in '{path}'; "
                    "choose another --out folder (or rename the input)"
                )
    check_writable(path)
    fd = lock_folder(path)
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
