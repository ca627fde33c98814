"""Image and mask input/output.

Images are returned as ``float64`` arrays indexed ``(row, col)``, scaled so that
the largest value the file's integer type can hold maps to 1.0 (8-bit: /255,
16-bit: /65535); colour images are reduced to luminance (ITU-R BT.601 weights).
Nothing here ever normalises to the image's own range: intensities keep their
meaning for saturation and contrast checks.
"""

from __future__ import annotations

import json
import os
from pathlib import Path, PurePosixPath

import numpy as np

from .errors import InputError

__all__ = [
    "read_image", "read_mask", "write_png16", "prepare_output_dir", "output_record", "recorded_outputs",
    "remove_outputs",
]

_READABLE = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg"}


def _imread_any(path: Path) -> np.ndarray:
    import cv2

    if path.suffix.lower() in {".tif", ".tiff"}:
        import tifffile

        try:
            return np.asarray(tifffile.imread(path))
        except Exception as exc:  # noqa: BLE001 - any decoder failure is a user file problem
            raise InputError(f"cannot read TIFF image '{path}': {exc}; check the file is a valid TIFF") from None
    data = np.fromfile(str(path), dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(
            f"cannot decode image '{path}'; supported formats are PNG, TIFF, BMP and JPEG (8 or 16 bit)"
        )
    if img.ndim == 3:
        img = img[..., ::-1] if img.shape[2] in (3, 4) else img  # BGR(A) -> RGB(A)
    return img


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as a grey ``float64`` array in [0, 1], indexed (row, col).

    Parameters
    ----------
    path : str or path-like
        PNG, TIFF, BMP or JPEG file; 8- or 16-bit integer or floating point;
        grey, RGB or RGBA (alpha is ignored).

    Returns
    -------
    image : ndarray, shape (H, W), float64
        Luminance scaled by the integer type's maximum (floats are kept as is).

    Raises
    ------
    InputError
        If the file is missing, unreadable, or not a 2-D image.

    Examples
    --------
    A 16-bit PNG reads back as floats in [0, 1]:

    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from glassdist.io import read_image, write_png16
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = Path(folder.name) / "ramp.png"
    >>> write_png16(path, np.linspace(0.0, 1.0, 64)[None, :].repeat(48, axis=0))
    >>> image = read_image(path)
    >>> image.shape, image.dtype, float(image[0, 0]), float(image[0, -1])
    ((48, 64), dtype('float64'), 0.0, 1.0)
    >>> folder.cleanup()
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"image file '{p}' does not exist; check the path")
    if p.is_dir():
        raise InputError(f"'{p}' is a folder, not an image file; give the path of a PNG/TIFF/BMP/JPEG file")
    if p.suffix.lower() not in _READABLE:
        raise InputError(f"'{p}' has an unsupported extension '{p.suffix}'; use PNG, TIFF, BMP or JPEG")
    raw = _imread_any(p)
    if raw.ndim == 3 and raw.shape[2] >= 3:
        rgb = raw[..., :3].astype(np.float64)
        grey = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    elif raw.ndim == 3 and raw.shape[2] in (1, 2):
        grey = raw[..., 0].astype(np.float64)
    elif raw.ndim == 2:
        grey = raw.astype(np.float64)
    else:
        raise InputError(f"'{p}' is not a 2-D image (array shape {raw.shape}); give a single grey or colour frame")
    if np.issubdtype(raw.dtype, np.integer):
        grey /= float(np.iinfo(raw.dtype).max)
    if not np.all(np.isfinite(grey)):
        raise InputError(f"'{p}' contains NaN or infinite pixel values; export it again as an integer image")
    return grey


def read_mask(path: str | os.PathLike, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a region mask: non-zero pixels are analysed, zero pixels are excluded.

    Parameters
    ----------
    path : str or path-like
        Any image :func:`read_image` accepts (or a ``.npy`` boolean array).
    shape : (int, int), optional
        Expected (H, W); a mask of another size is an error.

    Returns
    -------
    mask : ndarray of bool, shape (H, W)
    """
    p = Path(path)
    if p.suffix.lower() == ".npy":
        if not p.exists():
            raise InputError(f"mask file '{p}' does not exist; check the path")
        mask = np.load(p).astype(bool)
    else:
        mask = read_image(p) > 0.5 / 255.0
    if mask.ndim != 2:
        raise InputError(f"mask '{p}' must be a 2-D image, got shape {mask.shape}")
    if shape is not None and mask.shape != tuple(shape):
        raise InputError(
            f"mask '{p}' is {mask.shape[1]}x{mask.shape[0]} px but the image is {shape[1]}x{shape[0]} px; "
            "make the mask the same size as the image"
        )
    if not mask.any():
        raise InputError(f"mask '{p}' excludes every pixel; white (non-zero) pixels mark the region to analyse")
    return mask


def write_png16(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write a grey image in [0, 1] as a 16-bit PNG (values are clipped to [0, 1])."""
    import cv2

    arr = np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0)
    ok = cv2.imwrite(str(path), np.round(arr * 65535.0).astype(np.uint16))
    if not ok:
        raise InputError(f"cannot write '{path}'; check the folder exists and is writable")


def prepare_output_dir(path: str | os.PathLike) -> Path:
    """Create the output folder (and parents) if needed.

    Raises
    ------
    InputError
        If ``path`` exists and is not a folder: glassdist never replaces a user's file by a folder.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"output path '{p}' is an existing file; give --out a folder path (new or existing)")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create output folder '{p}': {exc.strerror}; choose a writable location") from None
    return p


# ---------------------------------------------------------------- files written by a run
#
# ``glassdist analyze`` lists the files it wrote in ``summary.json`` ("outputs": relative
# path -> size in bytes, summary.json itself excepted). When it runs again into the same
# folder it removes the files of that list that the new run did not write again, so that
# no result of the earlier run (a FAIL report, threshold masks of another specification)
# is left beside the new one. Nothing that is not on the list is ever removed.

SUMMARY_NAME = "summary.json"


def output_record(out_dir: str | os.PathLike, paths) -> dict[str, int]:
    """``{path relative to out_dir (with '/'): size in bytes}`` of files written into ``out_dir``.

    ``summary.json``, which holds the record, is left out of it.
    """
    out_dir = Path(out_dir)
    record = {Path(p).relative_to(out_dir).as_posix(): Path(p).stat().st_size for p in paths
              if Path(p).name != SUMMARY_NAME or Path(p).parent != out_dir}
    return dict(sorted(record.items()))


def _own_file(out_dir: Path, name) -> Path | None:
    """``out_dir / name`` if ``name`` is a plain relative path to a regular file inside ``out_dir``, else None."""
    if not isinstance(name, str) or not name or "\\" in name:
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


def recorded_outputs(out_dir: str | os.PathLike) -> dict[str, int]:
    """The files the last glassdist run into ``out_dir`` recorded as written, still as it left them.

    Reads ``out_dir/summary.json`` ("outputs"); keeps only the entries that name a regular
    file inside ``out_dir`` (no link, no '..') whose size is still the recorded one, so that
    a file replaced by the user since then is not taken for glassdist's.

    Returns
    -------
    dict
        ``{relative path: size in bytes}``; empty when there is no readable glassdist summary.
    """
    out_dir = Path(out_dir)
    try:
        summary = json.loads((out_dir / SUMMARY_NAME).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return {}
    if not isinstance(summary, dict) or "glassdist_version" not in summary:
        return {}
    outputs = summary.get("outputs")
    if not isinstance(outputs, dict):
        return {}
    kept = {}
    for name, size in outputs.items():
        path = _own_file(out_dir, name)
        if path is not None and isinstance(size, int) and path.stat().st_size == size:
            kept[name] = size
    return kept


def remove_outputs(out_dir: str | os.PathLike, names) -> tuple[list[str], list[str]]:
    """Remove files of ``out_dir`` named by :func:`recorded_outputs`, and folders they leave empty.

    Returns
    -------
    removed : list of str
        The names removed.
    problems : list of str
        One line per file that could not be removed (the run goes on).
    """
    out_dir = Path(out_dir)
    removed, problems = [], []
    for name in names:
        path = _own_file(out_dir, name)
        if path is None:
            continue
        try:
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
