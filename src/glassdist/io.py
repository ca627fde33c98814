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

__all__ = ["read_image", "read_mask", "write_png16", "prepare_output_dir"]

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
