"""Plausibility of a run's inputs: the slips a valid input can still carry, each a warning.

An input can pass every check of :mod:`glassdist.validation` (a number in range, a
readable photo) and still be a slip that changes the verdict: millimetres typed as
metres, the photo and the reference given the other way round, a grid pitch that does
not match the camera. Each check here is a pure function of figures the run already
has (or of the raw photos, at the cost of one FFT each) that returns a warning, or
None; the analysis adds the warnings to its result, so that the command line, a batch
pane and the Python API report the same ones.

Lengths in mm, the glass-to-grid distance ``L`` in m, angles in degrees.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .fourier import CarrierPair, Spectrum

__all__ = [
    "EXIF_SCALE_FACTOR",
    "MIN_VIEW_ANGLE_DEG",
    "SWAP_FLOOR",
    "SWAP_RATIO",
    "distance_warning",
    "exif_scale_mm_per_px",
    "exif_scale_warning",
    "grid_spread",
    "review_measurement",
    "swap_warning",
    "view_angle_deg",
]

#: Narrowest full angle of view, degrees, of any camera set-up glassdist expects: about a
#: 2000 mm lens on a full-frame sensor (36 mm / 2000 mm = 1.03 deg); a super-telephoto of
#: 800 mm already sees 2.6 deg.
MIN_VIEW_ANGLE_DEG = 1.0

#: A reference whose grid spread is more than this many times the photo's reads as the
#: more distorted of the two: the two are likely swapped.
SWAP_RATIO = 1.5

#: Grid spreads (relative local-frequency deviation) below this are the noise floor of a
#: regular grid and never call for a swap warning.
SWAP_FLOOR = 0.02

#: The measured scale and the one the EXIF focal length and subject distance imply may
#: differ by this factor (either way) before a warning: the subject distance EXIF records is
#: the focus distance, coarse, and to the grid or the pane.
EXIF_SCALE_FACTOR = 2.0

#: Diagonal of the 24 x 36 mm frame that 35 mm-equivalent focal lengths refer to, mm.
_FULL_FRAME_DIAGONAL_MM = math.hypot(24.0, 36.0)


def view_angle_deg(mm_per_px: float, image_shape: tuple[int, int], distance_m: float) -> float:
    """Largest full angle of view, degrees, a camera can have that sees the photo's backdrop extent at ``distance_m``.

    The camera lies in front of the glass, which lies ``L`` in front of the grid: the
    camera is at least ``L`` from the backdrop, so its angle of view across the backdrop
    extent ``w = mm_per_px * max(H, W)`` seen is at most

    .. math:: \\theta_{max} = 2 \\arctan\\frac{w}{2 L} .

    Parameters
    ----------
    mm_per_px : float
        Measured backdrop scale, mm per px.
    image_shape : (int, int)
        ``(H, W)`` of the photo, px.
    distance_m : float
        Glass-to-grid distance ``L``, m.
    """
    width_mm = float(mm_per_px) * max(image_shape)
    return math.degrees(2.0 * math.atan2(width_mm, 2000.0 * float(distance_m)))


def distance_warning(distance_m: float, mm_per_px: float, image_shape: tuple[int, int]) -> str | None:
    """A warning when the glass-to-grid distance needs a narrower angle of view than any camera has, else None.

    The bound is :func:`view_angle_deg` against :data:`MIN_VIEW_ANGLE_DEG`. The likely slip
    is millimetres typed as metres; the warning names ``L / 1000`` m where that distance is
    itself plausible.

    Examples
    --------
    The real photos (about 0.72 mm/px over 1024 px) with ``distance_m = 500``:

    >>> print(distance_warning(500.0, 0.722, (768, 1024)))  # doctest: +ELLIPSIS
    implausible distance: 500 m for distance_m (the glass-to-grid distance L) ... did you mean 0.5 m ...?
    >>> distance_warning(0.5, 0.722, (768, 1024)) is None
    True
    """
    if not (np.isfinite(mm_per_px) and mm_per_px > 0 and np.isfinite(distance_m) and distance_m > 0):
        return None
    angle = view_angle_deg(mm_per_px, image_shape, distance_m)
    if angle >= MIN_VIEW_ANGLE_DEG:
        return None
    width_m = mm_per_px * max(image_shape) / 1000.0
    text = (f"implausible distance: {distance_m:g} m for distance_m (the glass-to-grid distance L) puts "
            f"the camera at least {distance_m:g} m from a backdrop it sees {width_m:.3g} m of: an angle of view of "
            f"{angle:.2g} deg, narrower than any camera lens ({MIN_VIEW_ANGLE_DEG:g} deg); every power in mD scales "
            "as 1/L")
    guess = distance_m / 1000.0
    if view_angle_deg(mm_per_px, image_shape, guess) >= MIN_VIEW_ANGLE_DEG:
        text += f"; did you mean {guess:g} m (millimetres typed as metres)?"
    else:
        text += "; check the distance is in metres"
    return text


def _baseband(spectrum: Spectrum, f: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
    """The complex baseband of carrier ``f`` (cycles/px), from the bins within ``|f| / 2`` of it; and its sample step, px."""
    H, W = spectrum.shape
    half = 0.5 * float(np.hypot(*f))
    ry, rx = max(2, int(half * H)), max(2, int(half * W))
    cy, cx = round(float(f[1]) * H), round(float(f[0]) * W)
    patch = spectrum.block(cy - ry, cx - rx, 2 * ry + 1, 2 * rx + 1)
    # a raised-cosine window on the patch: the baseband's ringing stays off the statistic
    patch = patch * np.outer(np.hanning(2 * ry + 3)[1:-1], np.hanning(2 * rx + 3)[1:-1]).astype(np.float32)
    z = np.fft.ifft2(np.fft.ifftshift(patch))
    return z, (H / z.shape[0], W / z.shape[1])


def grid_spread(image: np.ndarray | None, carriers: CarrierPair, *, spectrum: Spectrum | None = None) -> float:
    """Spread of the grid's local carrier frequency over the photo, relative to the carrier frequency.

    A glass-less photo of a printed grid has one frequency everywhere but for the camera's
    perspective (a frequency varying linearly across the image) and its lens; glass bends
    the lines and spreads it. Per carrier the baseband is taken from the spectrum's bins
    within ``|f| / 2`` of it, its local frequency is the wrapped phase difference between
    neighbouring samples, a plane (the perspective) is fitted to it and removed, and the
    spread is the 90th percentile of ``|f_local - plane| / |f|`` over the samples where the
    grid's modulation is at least a quarter of its 90th percentile (occluded parts
    carry no frequency). The figure is the larger of the two carriers'.

    Parameters
    ----------
    image : ndarray (H, W)
        Grey photo.
    carriers : CarrierPair
        The carriers both photos of a pair are measured at (the reference's).
    spectrum : Spectrum, optional
        :func:`glassdist.analyzer.fourier.compute_spectrum` of ``image``, when already
        computed (``image`` may then be None).

    Returns
    -------
    float
        Dimensionless; NaN where the grid is nowhere visible.
    """
    from .fourier import compute_spectrum

    if spectrum is None:
        if image is None:
            raise ValueError("grid_spread needs the image or its spectrum")
        spectrum = compute_spectrum(image)
    out = []
    for c in (carriers.k1, carriers.k2):
        f = np.array([c.fx, c.fy], float)
        z, (sy, sx) = _baseband(spectrum, f)
        z = z[1:-1, 1:-1]  # the periodic transform's seam at the borders
        if min(z.shape) < 4:
            continue
        dx = np.angle(z[:-1, 1:] * np.conj(z[:-1, :-1])) / (2 * np.pi * sx)
        dy = np.angle(z[1:, :-1] * np.conj(z[:-1, :-1])) / (2 * np.pi * sy)
        mod = np.minimum(np.abs(z[:-1, :-1]), np.minimum(np.abs(z[:-1, 1:]), np.abs(z[1:, :-1])))
        keep = mod >= 0.25 * np.percentile(mod, 90)
        if np.count_nonzero(keep) < 8:
            continue
        yy, xx = np.nonzero(keep)
        A = np.column_stack([np.ones(yy.size), xx, yy]).astype(float)
        dev = []
        for d in (dx, dy):
            v = d[keep]
            coef = np.linalg.lstsq(A, v, rcond=None)[0]
            dev.append(v - A @ coef)
        rel = np.hypot(*dev) / float(np.hypot(*f))
        out.append(float(np.percentile(rel, 90)))
    return max(out) if out else float("nan")


def swap_warning(photo_spread: float, reference_spread: float) -> str | None:
    """A warning when the reference reads as more distorted than the photo (:func:`grid_spread`), else None.

    Fires when the reference's spread exceeds :data:`SWAP_RATIO` times the photo's and the
    noise floor :data:`SWAP_FLOOR`.

    Examples
    --------
    >>> print(swap_warning(0.02, 0.10))  # doctest: +ELLIPSIS
    the reference looks more distorted than the photo ...: the two may be swapped; ...
    >>> swap_warning(0.10, 0.02) is None
    True
    """
    if not (np.isfinite(photo_spread) and np.isfinite(reference_spread)):
        return None
    if reference_spread <= SWAP_FLOOR or reference_spread <= SWAP_RATIO * photo_spread:
        return None
    return (f"the reference looks more distorted than the photo (spread of the grid's local frequency "
            f"{100 * reference_spread:.1f}% against {100 * photo_spread:.1f}%): the two may be swapped; "
            "give the photo through the glass as the image and the glass-less one as the reference")


def exif_scale_mm_per_px(camera: dict[str, Any] | None, image_shape: tuple[int, int]) -> float | None:
    """The backdrop scale, mm per px, that the photo's EXIF focal length and subject distance imply, or None.

    With the camera's pixel pitch ``p`` (from the focal-plane resolution, else from the
    35 mm-equivalent focal length over the 43.3 mm full-frame diagonal), focal length
    ``f`` and subject distance ``s`` (thin lens),

    .. math:: \\frac{mm}{px} = p \\, \\frac{s - f}{f} .

    A photo resized since it was taken is allowed for through the EXIF pixel width.
    """
    if not camera:
        return None
    s_mm = 1000.0 * float(camera.get("subject_distance_m") or 0.0)
    f_mm = float(camera.get("focal_length_mm") or 0.0)
    f35 = float(camera.get("focal_length_35mm_mm") or 0.0)
    H, W = image_shape
    # EXIF records 0 for unknown and 0xFFFFFFFF for infinity
    if not (0 < s_mm < 1e7):
        return None
    px_per_mm = float(camera.get("focal_plane_px_per_mm") or 0.0)
    native = max(float(camera.get("pixel_width") or 0.0), float(camera.get("pixel_height") or 0.0))
    resized = native / max(W, H) if native > 0 else 1.0  # the sensor's pixels per pixel of the photo
    if f_mm > 0 and px_per_mm > 0:
        pitch_mm, focal = resized / px_per_mm, f_mm
    elif f35 > 0:
        pitch_mm, focal = _FULL_FRAME_DIAGONAL_MM / math.hypot(H, W), f35
    else:
        return None
    if s_mm <= focal:
        return None
    return pitch_mm * (s_mm - focal) / focal


def exif_scale_warning(camera: dict[str, Any] | None, mm_per_px: float, image_shape: tuple[int, int],
                       pitch_mm: float) -> str | None:
    """A warning when the measured scale and the EXIF's differ by more than :data:`EXIF_SCALE_FACTOR`.

    The measured scale is the stated pitch over the carrier period in px: a pitch typed in
    the wrong unit moves it by a factor of 10 or more.
    """
    expected = exif_scale_mm_per_px(camera, image_shape)
    if camera is None or expected is None or not (np.isfinite(mm_per_px) and mm_per_px > 0):
        return None
    ratio = mm_per_px / expected
    if 1.0 / EXIF_SCALE_FACTOR <= ratio <= EXIF_SCALE_FACTOR:
        return None
    return (f"scale mismatch: with a grid pitch of {pitch_mm:g} mm (pitch_mm) the grid measures {mm_per_px:.3g} "
            f"mm/px, but the photo's EXIF (focal length, subject distance {camera['subject_distance_m']:g} m) implies "
            f"about {expected:.3g} mm/px ({ratio:.2g} times as much); check the pitch is the printed grid's, in mm")


def review_measurement(image_shape: tuple[int, ...], reference_spread: float | None, photo_spread: float, *, mm_per_px: float,
                       distance_m: float, pitch_mm: float, camera: dict[str, Any] | None = None) -> list[str]:
    """Every plausibility warning of one measured photo: distance, swapped pair, EXIF scale.

    Parameters
    ----------
    image_shape : tuple
        The shape of the photo through the glass, (H, W).
    reference_spread : float or None
        :func:`grid_spread` of the reference photo (Comparative Method), None without one.
    photo_spread : float
        :func:`grid_spread` of the photo at the carriers it was demodulated at, from its F1
        spectrum (NaN where not computed: the Direct Method).
    mm_per_px, distance_m, pitch_mm : float
        The measured backdrop scale, the glass-to-grid distance L (m) and the stated pitch (mm).
    camera : dict, optional
        The photo's EXIF facts (:func:`glassdist.io.camera_metadata`).
    """
    shape = (int(image_shape[0]), int(image_shape[1]))
    found = [distance_warning(distance_m, mm_per_px, shape),
             exif_scale_warning(camera, mm_per_px, shape, pitch_mm)]
    if reference_spread is not None and np.isfinite(reference_spread) and reference_spread > SWAP_FLOOR:
        found.append(swap_warning(photo_spread, reference_spread))
    return [w for w in found if w is not None]
