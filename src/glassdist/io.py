"""Input/output of images, masks, EXIF and JSON documents.

Images are returned as ``float64`` arrays indexed ``(row, col)``, scaled so that
the largest value of the file's bit depth maps to 1.0 (8-bit: /255, 16-bit: /65535,
a 10/12/14-bit camera TIFF: /1023, /4095, /16383 from its BitsPerSample); colour
images are reduced to luminance (ITU-R BT.601 weights). Every file is checked by
:mod:`glassdist.validation` first, and its size read from the header before decoding.
Nothing here ever normalises to the image's own range: intensities keep their
meaning for saturation and contrast checks.
"""

from __future__ import annotations

import contextlib
import hashlib
import io as _io
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError
from .validation import check_input_file, limits, safe_text

__all__ = ["Photo", "read_photo", "read_sources", "read_image", "preview", "image_shape", "read_mask", "write_png16",
           "prepare_output_dir", "open_with_pillow", "camera_metadata", "to_jsonable"]

_READABLE = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg"}


def _read_bytes(path: Path) -> bytes:
    """The file's bytes, read once (decoded, hashed and searched for EXIF from memory)."""
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as exc:
        raise InputError(f"cannot read image '{safe_text(path)}': {exc.strerror}; check the file") from None


def _imread_any(path: Path, data: bytes, max_pixels: float) -> tuple[np.ndarray, int | None]:
    """Decode an image file's bytes ``data`` (RGB(A) channel order); returns the array and its bits per sample (TIFF)."""
    import cv2

    if path.suffix.lower() in {".tif", ".tiff"}:
        return _tiff_frame(path, max_pixels, data)
    _check_pixels(path, *_header_size(path, data), max_pixels)
    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(
            f"cannot decode image '{safe_text(path)}'; supported formats are PNG, TIFF, BMP and JPEG (8 or 16 bit)"
        )
    if img.ndim == 3:
        if img.shape[2] in (3, 4):  # BGR(A) -> RGB(A): the alpha channel stays last
            img = img[..., [2, 1, 0, *range(3, img.shape[2])]]
    return img, None


def _tiff_page(tif, p: Path, max_pixels: float):
    """The one frame of an open TIFF, its size and sample type checked (nothing decoded)."""
    shown = safe_text(p)
    # reduced-resolution pages (thumbnails, previews) are not frames
    frames = [pg for pg in tif.pages if not (getattr(pg, "subfiletype", 0) & 1)]
    if not frames:
        raise InputError(f"TIFF image '{shown}' holds no image page; export it again")
    if len(frames) > 1:
        raise InputError(
            f"TIFF image '{shown}' holds {len(frames)} pages (a stack); glassdist analyses one photo: "
            "save the frame to analyse as a single-page TIFF"
        )
    page = frames[0]
    _check_pixels(p, int(page.imagewidth), int(page.imagelength), max_pixels)
    if np.dtype(page.dtype).kind == "c":
        raise InputError(f"TIFF image '{shown}' holds complex numbers; give a real-valued (intensity) image")
    planes = _tiff_planes(page)
    if planes > 1:
        raise InputError(
            f"TIFF image '{shown}' holds {planes} image planes in one page (a stack, not colour channels); glassdist "
            "analyses one photo: save the frame to analyse as a single grey or colour image"
        )
    return page


def _tiff_planes(page) -> int:
    """Image planes of a TIFF page that are neither colour channels nor alpha: depth slices or unnamed samples."""
    import tifffile

    depth = int(getattr(page, "imagedepth", 1) or 1)
    samples = int(page.samplesperpixel)
    colour = 3 if page.photometric in (tifffile.PHOTOMETRIC.RGB, tifffile.PHOTOMETRIC.YCBCR) else 1
    # ExtraSamples 1 and 2 are (associated, unassociated) alpha; 0 is unspecified data
    alpha = sum(1 for e in (page.extrasamples or ()) if int(e) in (1, 2))
    return depth * max(samples - colour - alpha + 1, 1)


def _open_tiff(p: Path, use, data: bytes | None = None):
    """``use(TiffFile)`` of the file ``p`` (or of its bytes ``data``), any decoder failure reported as a one-line InputError."""
    import tifffile

    try:
        with tifffile.TiffFile(p if data is None else _io.BytesIO(data)) as tif:
            return use(tif)
    except (InputError, MemoryError):
        raise
    except Exception as exc:  # noqa: BLE001 - any decoder failure is a user file problem
        raise InputError(
            f"cannot read TIFF image '{safe_text(p)}': {safe_text(exc, 200)}; check the file is a valid TIFF"
        ) from None


def _tiff_frame(p: Path, max_pixels: float, data: bytes) -> tuple[np.ndarray, int | None]:
    """Page 0 of a single-frame TIFF as (H, W) or (H, W, S) and its BitsPerSample, size checked first."""
    def decode(tif):
        page = _tiff_page(tif, p, max_pixels)
        return page.asarray(), page.axes, page.bitspersample

    data, axes, bits = _open_tiff(p, decode, data)
    # drop length-1 axes; planar (separate) colour planes come first ('SYX'): samples go last
    dims = [(n, a) for n, a in zip(data.shape, axes) if a in "SYX" or n != 1]
    data = data.reshape([n for n, _ in dims])
    if "".join(a for _, a in dims) == "SYX":
        data = np.moveaxis(data, 0, -1)
    return data, (bits if np.issubdtype(data.dtype, np.integer) else None)


def _check_pixels(p: Path, width: int, height: int, max_pixels: float) -> None:
    if width * height > max_pixels:
        raise InputError(
            f"image '{safe_text(p)}' is {width}x{height} px ({width * height / 1e6:.0f} megapixels), more than the "
            f"{max_pixels / 1e6:g} megapixels accepted; crop or bin it, or raise the limit (GLASSDIST_MAX_MEGAPIXELS)"
        )


@contextlib.contextmanager
def open_with_pillow(path):
    """``PIL.Image.open(path)`` for its header (size, EXIF) only, without Pillow's pixel-count check.

    glassdist applies its own, configurable limit (``GLASSDIST_MAX_MEGAPIXELS``) from the
    same header, so Pillow's ``DecompressionBombWarning`` (over 89 Mpx) or error (over
    179 Mpx) would only print a raw warning about a photo glassdist accepts or refuses
    anyway. The pixels are never decoded here.
    """
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        bomb, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            im = Image.open(path)
        finally:
            Image.MAX_IMAGE_PIXELS = bomb
    with im:
        yield im


def _header_size(p: Path, data: bytes | None = None) -> tuple[int, int]:
    """(width, height) from a PNG/BMP/JPEG header (of the file, or of its bytes ``data``), without decoding the pixels."""
    from PIL import UnidentifiedImageError

    try:
        with open_with_pillow(p if data is None else _io.BytesIO(data)) as im:
            return im.size
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError):
        raise InputError(
            f"cannot decode image '{safe_text(p)}'; supported formats are PNG, TIFF, BMP and JPEG (8 or 16 bit)"
        ) from None


def image_shape(path: str | os.PathLike, *, max_megapixels: float | None = None) -> tuple[int, int]:
    """``(H, W)`` of an image file from its header, with every check of :func:`read_image` that needs no decoding.

    For checking many inputs before any work (``glassdist batch``): the file is a
    readable regular file of a supported format, a single frame (TIFF), real-valued
    and within the size limit.
    """
    p = _checked_image_path(path)
    max_pixels = _max_pixels(max_megapixels)
    if p.suffix.lower() in {".tif", ".tiff"}:
        def size(tif):
            page = _tiff_page(tif, p, max_pixels)
            return int(page.imagelength), int(page.imagewidth)

        return _open_tiff(p, size)
    width, height = _header_size(p)
    _check_pixels(p, width, height, max_pixels)
    return height, width


def _checked_image_path(path) -> Path:
    p = check_input_file(path, "image file")
    if p.suffix.lower() not in _READABLE:
        raise InputError(f"'{safe_text(p)}' has an unsupported extension '{safe_text(p.suffix, 20)}'; use PNG, TIFF, BMP or JPEG")
    return p


def _max_pixels(max_megapixels: float | None) -> float:
    return 1e6 * (limits().megapixels if max_megapixels is None else float(max_megapixels))


def read_image(path: str | os.PathLike, *, max_megapixels: float | None = None, dtype=np.float64) -> np.ndarray:
    """Read an image file as a grey floating-point array in [0, 1], indexed (row, col).

    Parameters
    ----------
    path : str or path-like
        PNG, TIFF, BMP or JPEG file; 8- to 16-bit integer or floating point;
        grey, RGB or RGBA (fully opaque: alpha is not used), colour planes contiguous or
        separate (planar TIFF). A TIFF must hold one frame (reduced-resolution previews
        aside). Floats are intensities in [0, 1].
    max_megapixels : float, optional
        Largest image accepted, megapixels, checked from the file's header before the
        pixels are decoded; default :attr:`glassdist.validation.Limits.megapixels`
        (250, or the ``GLASSDIST_MAX_MEGAPIXELS`` environment variable).
    dtype : {numpy.float64, numpy.float32}
        Type of the result. ``float32`` holds exactly the ``float64`` values rounded to
        single precision (what the analyzer works in) at half the memory, without a
        double-precision copy of a grey image ever being made.

    Returns
    -------
    image : ndarray, shape (H, W), ``dtype``
        Luminance scaled by the largest value of the file's bit depth: ``2**b - 1``
        for a TIFF of ``b`` bits per sample (a 10-, 12- or 14-bit camera image reaches
        1.0 at its own full scale), else the integer type's maximum (8-bit: 255, 16-bit:
        65535). Floats are kept as they are.

    Raises
    ------
    InputError
        If the file is missing, not a regular file, unreadable, empty, larger than the
        limit, not decodable, not a single 2-D frame (a stack of pages, or of planes in
        one page), complex-valued, black and white only (1 bit), has transparent pixels,
        holds floats outside [0, 1] or NaN or infinite values.

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

    A 12-bit camera TIFF reaches 1.0 at its own full scale (4095):

    >>> import tifffile
    >>> path = Path(folder.name) / "camera12bit.tif"
    >>> tifffile.imwrite(path, np.full((8, 8), 4095, np.uint16), bitspersample=12)
    >>> float(read_image(path).max())
    1.0
    >>> folder.cleanup()
    """
    p = _checked_image_path(path)
    return _decoded(p, _read_bytes(p), max_megapixels, dtype)


def _check_samples(p: Path, raw: np.ndarray, *, binary: bool = False) -> None:
    """What a decoded photo may not hold: transparency, only black and white, or floats that are not intensities in [0, 1].

    ``binary``: a black-and-white image is accepted (a mask).
    """
    shown = safe_text(p)
    if raw.ndim == 3 and raw.shape[2] in (2, 4):
        alpha = raw[..., -1]
        opaque = np.iinfo(alpha.dtype).max if np.issubdtype(alpha.dtype, np.integer) else 1.0
        clear = float(np.count_nonzero(alpha < opaque)) / alpha.size
        if clear > 0:
            raise InputError(
                f"image '{shown}' has transparent pixels ({100 * clear:.3g}% of its alpha channel below opaque); the "
                "colour under them is not the photo's: save it without transparency (flattened), and give any part "
                "to leave out as a mask (--mask)"
            )
    if raw.dtype == bool and not binary:
        raise InputError(
            f"image '{shown}' is black and white only (1 bit per pixel): the grey levels the grid's phase is measured "
            "from are lost; give the camera's grey or colour image"
        )
    if raw.dtype.kind == "f" and raw.size:
        with warnings.catch_warnings():  # an all-NaN image: no range, refused by the checks that follow
            warnings.simplefilter("ignore", RuntimeWarning)
            lo, hi = float(np.nanmin(raw)), float(np.nanmax(raw))
        if np.isfinite(lo) and np.isfinite(hi) and (lo < -_FLOAT_SLACK or hi > 1.0 + _FLOAT_SLACK):
            raise InputError(
                f"image '{shown}' holds floating-point values from {lo:.4g} to {hi:.4g}; glassdist reads a float image "
                "as intensities in [0, 1] (1 = full scale, which saturation and contrast checks rely on): scale it to "
                "[0, 1] or save it as an 8- or 16-bit integer image"
            )


#: How far a float image may stray outside [0, 1] (noise around a dark-frame subtraction, a
#: white slightly above full scale) and still be read as intensities.
_FLOAT_SLACK = 0.05


def _decoded(p: Path, data: bytes, max_megapixels, dtype, *, binary: bool = False) -> np.ndarray:
    """:func:`read_image` of the file ``p`` whose bytes are ``data`` (``binary``: black and white accepted)."""
    raw, bits = _imread_any(p, data, _max_pixels(max_megapixels))
    _check_samples(p, raw, binary=binary)
    if raw.ndim == 3 and raw.shape[2] >= 3 and np.issubdtype(raw.dtype, np.integer):
        return _colour_grey(raw, _full_scale(raw.dtype, bits), dtype)
    if raw.ndim == 3 and raw.shape[2] >= 3:
        rgb = raw[..., :3].astype(np.float64)
        grey = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    elif raw.ndim == 3 and raw.shape[2] in (1, 2):
        grey = raw[..., 0].astype(np.float64)
    elif raw.ndim == 2:
        if np.issubdtype(raw.dtype, np.integer) and raw.dtype.itemsize <= 2:
            return _scaled_grey(raw, bits, dtype)
        grey = raw.astype(np.float64)
    else:
        raise InputError(f"'{safe_text(p)}' is not a 2-D image (array shape {raw.shape}); give a single grey or colour frame")
    if np.issubdtype(raw.dtype, np.integer):
        grey /= _full_scale(raw.dtype, bits)  # a 10/12/14-bit camera image: 2**bits - 1
    elif raw.dtype == bool:
        grey = grey.astype(np.float64)
    if not np.all(np.isfinite(grey)):
        raise InputError(f"'{safe_text(p)}' contains NaN or infinite pixel values; export it again as an integer image")
    return grey.astype(dtype, copy=False)


def _full_scale(dtype, bits) -> float:
    """Value that reads 1.0: ``2**bits - 1`` for a 10/12/14-bit camera image in a 16-bit container, else the type's maximum."""
    full = float(np.iinfo(dtype).max)
    if bits is not None and 1 <= bits < np.iinfo(dtype).bits:
        full = float(2**bits - 1)
    return full


def _scaled_grey(raw: np.ndarray, bits, dtype) -> np.ndarray:
    """An 8/16-bit grey image scaled to [0, 1] through a table of ``k / full`` (float64, then ``dtype``).

    The same values as ``raw.astype(float64) / full`` cast to ``dtype``, by one gather
    instead of a double-precision copy of the image and a division over it.
    """
    table = (np.arange(np.iinfo(raw.dtype).max + 1, dtype=np.float64) / _full_scale(raw.dtype, bits)).astype(dtype)
    return table[raw]


#: Rows of a colour photo converted to grey at a time (:func:`_colour_grey`): bounds the double-precision work.
_GREY_ROWS = 256


def _colour_grey(raw: np.ndarray, full: float, dtype) -> np.ndarray:
    """Rec. 601 luma ``(0.299 R + 0.587 G + 0.114 B) / full`` of an integer colour image, as ``dtype``.

    Computed in double precision a block of :data:`_GREY_ROWS` rows at a time, so the only
    full-size array is the result (a whole-image ``float64`` copy of the three channels is
    eight times the photo's bytes per channel); the values are those of the whole-image formula.
    """
    out = np.empty(raw.shape[:2], dtype)
    for r0 in range(0, raw.shape[0], _GREY_ROWS):
        rgb = raw[r0 : r0 + _GREY_ROWS, :, :3].astype(np.float64)
        grey = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
        grey /= full
        out[r0 : r0 + _GREY_ROWS] = grey
    return out


def read_mask(path: str | os.PathLike, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a region mask: non-zero pixels are analysed, zero pixels are excluded.

    Parameters
    ----------
    path : str or path-like
        Any image :func:`read_image` accepts (or a ``.npy`` array of booleans or
        finite numbers).
    shape : (int, int), optional
        Expected (H, W); a mask of another size is an error.

    Returns
    -------
    mask : ndarray of bool, shape (H, W)
    """
    p = Path(path)
    if p.suffix.lower() == ".npy":
        mask = _read_npy_mask(check_input_file(p, "mask file", option="--mask"))
    else:
        q = _checked_image_path(p)
        mask = _decoded(q, _read_bytes(q), None, np.float32, binary=True) > 0.5 / 255.0
    shown = safe_text(p)
    if mask.ndim != 2:
        raise InputError(f"mask '{shown}' must be a 2-D image, got shape {mask.shape}")
    if shape is not None and mask.shape != tuple(shape):
        raise InputError(
            f"mask '{shown}' is {mask.shape[1]}x{mask.shape[0]} px but the image is {shape[1]}x{shape[0]} px; "
            "make the mask the same size as the image"
        )
    if not mask.any():
        raise InputError(f"mask '{shown}' excludes every pixel; white (non-zero) pixels mark the region to analyse")
    return mask


def _read_npy_mask(p: Path) -> np.ndarray:
    """A ``.npy`` mask: header (shape, dtype) checked before the data is read; NaN refused."""
    shown = safe_text(p)
    try:
        head = np.load(p, mmap_mode="r", allow_pickle=False)  # the header only; data mapped, not read
        if not isinstance(head, np.ndarray) or head.dtype.kind not in "biuf" or head.ndim != 2:
            raise InputError(f"mask '{shown}' must be a 2-D array of booleans or numbers, "
                             f"got {getattr(head, 'dtype', '?')} {getattr(head, 'shape', '')}")
        _check_pixels(p, int(head.shape[1]), int(head.shape[0]), limits().megapixels * 1e6)
        arr = np.array(head)
        del head
    except InputError:
        raise
    except (OSError, ValueError, EOFError) as exc:
        raise InputError(f"cannot read mask '{shown}': {safe_text(exc, 200)}; save it with numpy.save") from None
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise InputError(f"mask '{shown}' holds NaN or infinite values; give 0 (excluded) or 1 (analysed)")
    return arr.astype(bool)


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
    if not os.fspath(path):
        raise InputError("the output folder is empty (''); give --out a folder path (new or existing)")
    p = Path(path)
    try:
        if p.exists() and not p.is_dir():
            raise InputError(f"output path '{p}' is an existing file; give --out a folder path (new or existing)")
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # no permission, a name too long for the file system, ...
        raise InputError(f"cannot create output folder '{safe_text(p, 200)}': {exc.strerror}; "
                         "choose a writable location with a shorter name") from None
    return p


_EXIF_TAGS = {  # EXIF tag id -> name recorded
    0x010F: "make", 0x0110: "model", 0x0132: "datetime", 0x9003: "datetime_original", 0x829A: "exposure_time_s",
    0x829D: "f_number", 0x920A: "focal_length_mm", 0x8827: "iso", 0xA434: "lens_model", 0xA431: "serial_number",
    # the capture geometry (glassdist.analyzer.plausibility): focus distance, 35 mm-equivalent focal length, native width
    0x9206: "subject_distance_m", 0xA405: "focal_length_35mm_mm", 0xA002: "pixel_width",
    0xA003: "pixel_height",
}
#: EXIF FocalPlaneResolutionUnit -> mm per unit (2 inch, 3 cm, 4 mm, 5 um)
_FOCAL_PLANE_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}


def camera_metadata(path):
    """Camera facts from a photo's EXIF block (Pillow), or ``None`` when it has none.

    Parameters
    ----------
    path : path or binary file
        The photograph (or its bytes, ``io.BytesIO``).

    Returns
    -------
    dict or None
        Any of ``make``, ``model``, ``lens_model``, ``serial_number``, ``datetime``,
        ``datetime_original``, ``exposure_time_s``, ``f_number``, ``focal_length_mm``,
        ``iso``, ``subject_distance_m``, ``focal_length_35mm_mm``, ``pixel_width``, ``pixel_height`` (px, as taken),
        ``focal_plane_px_per_mm`` (the sensor's pixels per mm) that the file records.
    """
    try:
        with open_with_pillow(path) as im:
            exif = im.getexif()
            tags = dict(exif)
            tags.update(exif.get_ifd(0x8769))  # the Exif sub-IFD: exposure, lens, original time
    except (OSError, ValueError, SyntaxError):
        return None
    out = {}
    for tag, name in _EXIF_TAGS.items():
        value = tags.get(tag)
        if value is None:
            continue
        if isinstance(value, bytes):
            value = value.decode("ascii", "replace")
        if isinstance(value, str):
            value = value.strip("\x00 ").strip()
            if not value:
                continue
        elif isinstance(value, tuple):
            value = value[0]
        else:
            try:
                value = float(value)
            except (TypeError, ValueError):
                value = str(value)
        out[name] = value
    res, unit = tags.get(0xA20E), _FOCAL_PLANE_UNIT_MM.get(tags.get(0xA210, 2))
    try:
        if res is not None and unit is not None and float(res) > 0:
            out["focal_plane_px_per_mm"] = float(res) / unit
    except (TypeError, ValueError, ZeroDivisionError):
        pass
    return out or None


def to_jsonable(obj):
    """``obj`` with numpy values turned into Python ones and NaN / inf into ``None`` (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.generic,)):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    return str(obj)


@dataclass(frozen=True)
class Photo:
    """A photograph as a run reads it (:func:`read_photo`): pixels, digest and camera, from one read of the file.

    Attributes
    ----------
    image : ndarray (H, W)
        As :func:`read_image` returns it.
    sha256 : str
        SHA-256 of the file's bytes, the bytes decoded.
    camera : dict or None
        :func:`camera_metadata` of the same bytes.
    """

    image: np.ndarray
    sha256: str
    camera: dict | None


def read_photo(path: str | os.PathLike, *, max_megapixels: float | None = None, dtype=np.float64) -> Photo:
    """Read a photograph once: its pixels (:func:`read_image`), the SHA-256 of the bytes read and its EXIF camera.

    The file is opened once; the hash, the header, the pixels and the EXIF block all come
    from the bytes read, so the digest is of exactly what was analysed.

    Raises
    ------
    InputError
        As :func:`read_image`.
    """
    p = _checked_image_path(path)
    data = _read_bytes(p)
    image = _decoded(p, data, max_megapixels, dtype)
    return Photo(image, hashlib.sha256(data).hexdigest(), camera_metadata(_io.BytesIO(data)))


def preview(image, max_px: int = 1200) -> np.ndarray:
    """``image`` reduced by area averaging so that its longer side is at most ``max_px`` (float32)."""
    import cv2

    img = np.asarray(image, dtype=np.float32)
    k = max(img.shape) / max_px
    if k <= 1:
        return img
    size = (max(1, round(img.shape[1] / k)), max(1, round(img.shape[0] / k)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def read_sources(image, reference=None, mask=None) -> tuple:
    """The photo, reference and mask of an analysis, each read where it is given as a path, and the files read.

    Parameters
    ----------
    image, reference : ndarray or path
        Read with :func:`read_photo` (single precision, what the analyzer works in) when paths.
    mask : ndarray or path, optional
        Read with :func:`read_mask` (the photo's size) when a path.

    Returns
    -------
    image, reference, mask
        Arrays (or as given).
    sources : dict
        What was read from files: ``image`` (path), ``image_sha256`` and ``camera``
        (:func:`camera_metadata`), ``reference`` and ``reference_sha256``, ``mask``; empty
        when nothing was given as a path.
    """
    sources: dict = {}
    if isinstance(image, (str, os.PathLike)):
        photo = read_photo(image, dtype=np.float32)
        sources.update(image=os.fspath(image), image_sha256=photo.sha256, camera=photo.camera)
        image = photo.image
    if isinstance(reference, (str, os.PathLike)):
        ref = read_photo(reference, dtype=np.float32)
        sources.update(reference=os.fspath(reference), reference_sha256=ref.sha256)
        reference = ref.image
    if isinstance(mask, (str, os.PathLike)):
        sources["mask"] = os.fspath(mask)
        mask = read_mask(mask, np.shape(image))
    return image, reference, mask, sources
