"""Where an oblique capture was taken from: the camera's angle to the pane normal and its focal length.

The intrinsic reading of a capture off the normal (:mod:`glassdist.viewpoint.intrinsic`)
needs the angle ``theta`` between the line of sight to the pane centre (the optical axis,
the camera aimed at the centre) and the pane normal, its azimuth ``psi`` (``glassdist
view``'s convention), and the focal length ``f`` in px that places each pixel on the pane.

The angle is stated (``--camera-angle-deg``, ``--camera-azimuth-deg``) or, by the Direct
Method, read from the homography ``H`` from the backdrop's logical grid to the pixels
(Zhang 2000, §3.1): with ``K = [[f, 0, c_x], [0, f, c_y], [0, 0, 1]]`` (principal point at the
image centre, square pixels), ``K^-1 H = lambda [r_1 r_2 t]``, the backdrop's normal in the
camera frame is ``n = r_1 x r_2`` and ``cos theta = |n_z|``, the optical axis in the pane
frame ``(r_1 . z, r_2 . z, n . z)`` gives ``psi`` (backdrop and pane parallel, the grid along
the pane's edges). Projective terms that put the camera within 2 deg of the normal for any
focal length up to 4 image widths (:func:`homography_is_normal`) read as normal incidence.
A Comparative capture states no pose of its own (its reference is glass-less, the analysis
is relative to it): the angle is stated, or normal incidence is assumed.

The focal length, in this order: the lens calibration's (``--camera-file``, ``--lens-photo``);
the photo's EXIF 35 mm-equivalent focal length (``f = f_35 W / 36``); the homography's own
(the orthogonality and equal length of ``r_1``, ``r_2``, well posed off the normal: trusted from
:data:`MIN_SELF_CALIBRATED_ANGLE_DEG`); the capture's scale (``mm_per_px`` the
geometric-mean backdrop mm per px at the centre: ``f = 1000 (Dc + L / cos theta) /
(mm_per_px sqrt(cos theta))``). Only the field angles of off-axis pixels depend on ``f``.

References
----------
Zhang, Z. (2000). A flexible new technique for camera calibration. *IEEE TPAMI* 22(11), 1330-1334.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .intrinsic import DEFAULT_REFRACTIVE_INDEX, CaptureGeometry

if TYPE_CHECKING:
    from ..analyzer.result import AnalysisResult

__all__ = ["CapturePose", "angle_from_homography", "capture_pose", "focal_from_homography",
           "homography_is_normal"]


#: The oblique reading's range (:class:`~glassdist.viewpoint.intrinsic.CaptureGeometry`), deg.
MAX_ANGLE_DEG = 70.0

#: Below this angle a focal length calibrated from the homography itself is not trusted (ill-posed at the normal).
MIN_SELF_CALIBRATED_ANGLE_DEG = 10.0


@dataclass(frozen=True)
class CapturePose:
    """The capture's geometry with where its angle and focal length came from, and what could not be had.

    Attributes
    ----------
    geometry : CaptureGeometry
    angle_source : str
        ``"stated"``, ``"homography"`` or ``"assumed normal"``.
    focal_length_source : str or None
        ``"lens calibration"`` (``--camera-file``, ``--lens-photo``), ``"EXIF"``, ``"homography"``,
        ``"capture scale"`` (None at normal incidence).
    warnings : tuple of str
    """

    geometry: CaptureGeometry
    angle_source: str
    focal_length_source: str | None = None
    warnings: tuple[str, ...] = ()

    def sources(self) -> dict:
        """``angle_source`` and ``focal_length_source``, for ``summary.json`` ``intrinsic``."""
        return {"angle_source": self.angle_source, "focal_length_source": self.focal_length_source}


def _centred(H, image_shape):
    h, w = image_shape
    T = np.array([[1.0, 0.0, -(w - 1) / 2.0], [0.0, 1.0, -(h - 1) / 2.0], [0.0, 0.0, 1.0]])
    return T @ np.asarray(H, float)


def focal_from_homography(H, image_shape) -> float | None:
    """``f`` (px) from a plane's homography (``r_1 . r_2 = 0``, ``|r_1| = |r_2|``); None where not well posed."""
    G = _centred(H, image_shape)
    h1, h2 = G[:, 0], G[:, 1]
    a = np.array([h1[0] * h2[0] + h1[1] * h2[1], h1[0] ** 2 + h1[1] ** 2 - h2[0] ** 2 - h2[1] ** 2])
    b = np.array([h1[2] * h2[2], h1[2] ** 2 - h2[2] ** 2])
    # a / f^2 + b = 0 in least squares; b ~ 0 at normal incidence (no projective terms)
    scale = np.linalg.norm(a)
    if scale == 0 or np.linalg.norm(b) * max(image_shape) ** 2 < 1e-3 * scale:
        return None
    inv_f2 = -float(a @ b) / float(a @ a)
    return 1.0 / math.sqrt(inv_f2) if inv_f2 > 0 else None


def angle_from_homography(H, image_shape, focal_length_px: float) -> tuple[float, float]:
    """``(theta, psi)`` (deg) of the camera's line of sight to the backdrop's normal from its homography.

    The grid's axes ``r_1``, ``r_2`` (unit, in the camera frame, turned to run along the image's
    columns and rows) give the normal ``n = r_1 x r_2`` and the optical axis in the pane frame,
    ``a = (r_1 . z, r_2 . z, n . z)``: ``cos theta = a_z``, ``psi = atan2(a_y, a_x)``.
    """
    G = _centred(H, image_shape)
    B = np.diag([1.0 / focal_length_px, 1.0 / focal_length_px, 1.0]) @ G
    r1, r2 = B[:, 0] / np.linalg.norm(B[:, 0]), B[:, 1] / np.linalg.norm(B[:, 1])
    if abs(r1[0]) < abs(r2[0]):  # the grid's first axis along the image rows
        r1, r2 = r2, r1
    r1, r2 = (r1 if r1[0] > 0 else -r1), (r2 if r2[1] > 0 else -r2)
    n = np.cross(r1, r2)
    n = n / np.linalg.norm(n)
    theta = math.degrees(math.acos(min(1.0, abs(float(n[2])))))
    psi = math.degrees(math.atan2(r2[2], r1[2])) if theta > 1e-6 else 0.0
    return theta, psi % 360.0


def homography_is_normal(H, image_shape, longest_focal_widths: float = 4.0, angle_deg: float = 2.0) -> bool:
    """Whether ``H``'s projective terms put the camera within ``angle_deg`` of the normal for any focal length
    up to ``longest_focal_widths`` image widths (``tan theta ~ f q``, ``q`` the perspective per px)."""
    G = _centred(H, image_shape)
    q = math.hypot(G[2, 0] / np.hypot(G[0, 0], G[1, 0]), G[2, 1] / np.hypot(G[0, 1], G[1, 1]))
    return longest_focal_widths * image_shape[1] * q < math.tan(math.radians(angle_deg))


def _exif_focal_px(camera, width_px: int) -> float | None:
    f35 = (camera or {}).get("focal_length_35mm_mm") if isinstance(camera, dict) else None
    return float(f35) * width_px / 36.0 if f35 else None


def capture_pose(result: AnalysisResult, camera_distance_m: float, *, angle_deg: float | None = None, azimuth_deg: float = 0.0,
                 focal_length_px: float | None = None, camera=None,
                 refractive_index: float = DEFAULT_REFRACTIVE_INDEX) -> CapturePose:
    """The capture's :class:`CapturePose`: the angle stated, else the Direct homography's, else normal (module notes).

    Parameters
    ----------
    result : AnalysisResult
        Transmission; its ``homography`` (Direct) and ``mm_per_px``.
    camera_distance_m : float
        ``Dc``, camera to the pane centre along the line of sight, m.
    angle_deg, azimuth_deg : float, optional
        The stated ``theta`` and ``psi``; ``angle_deg`` None: estimated where the data allow.
    focal_length_px : float, optional
        The lens calibration's focal length, px.
    camera : dict, optional
        The photo's EXIF facts (:func:`glassdist.io.read_photo`).
    """
    shape = result.valid.shape
    warnings = []
    focal, fsource = focal_length_px, "lens calibration"
    if focal is None:
        focal, fsource = _exif_focal_px(camera, shape[1]), "EXIF"
    H = result.homography  # None in the Comparative Method
    if focal is None and H is not None:
        focal, fsource = focal_from_homography(H, shape), "homography"
    source = "stated"
    if angle_deg is None:
        if H is None:
            angle_deg, source = 0.0, "assumed normal"
        elif homography_is_normal(H, shape):
            angle_deg, source = 0.0, "homography"
        elif focal is None:
            angle_deg, source = 0.0, "assumed normal"
            warnings.append("the camera's angle to the pane normal could not be read from the Direct homography: "
                            "it needs the focal length (a --camera-file, the photo's EXIF 35 mm-equivalent focal "
                            "length, or a view oblique enough to calibrate itself); read as normal incidence, give "
                            "--camera-angle-deg if the camera was not facing the pane")
        else:
            angle_deg, azimuth_deg = angle_from_homography(H, shape, focal)
            source = "homography"
            if fsource == "homography" and angle_deg < MIN_SELF_CALIBRATED_ANGLE_DEG:
                warnings.append(f"the Direct homography puts the camera within {MIN_SELF_CALIBRATED_ANGLE_DEG:g} deg "
                                "of the pane normal, too close to calibrate its focal length from the view itself; "
                                "read as normal incidence: give --camera-file (or --camera-angle-deg) to read the "
                                "angle")
                angle_deg, azimuth_deg, source = 0.0, 0.0, "assumed normal"
            elif angle_deg >= MAX_ANGLE_DEG:
                warnings.append(f"the Direct homography puts the camera {angle_deg:.3g} deg off the pane normal, beyond "
                                f"the {MAX_ANGLE_DEG:g} deg the oblique reading covers; read as normal incidence: give "
                                "--camera-angle-deg if that is the capture's pose")
                angle_deg, azimuth_deg, source = 0.0, 0.0, "assumed normal"
    if angle_deg == 0.0:
        return CapturePose(CaptureGeometry(float(camera_distance_m), float(result.distance_m), refractive_index),
                           source, None, tuple(warnings))
    if focal is None:
        c = math.cos(math.radians(angle_deg))
        focal = 1000.0 * (camera_distance_m + result.distance_m / c) / (float(result.mm_per_px) * math.sqrt(c))
        fsource = "capture scale"
    g = CaptureGeometry(float(camera_distance_m), float(result.distance_m), refractive_index,
                        viewing_angle_deg=float(angle_deg), viewing_azimuth_deg=float(azimuth_deg),
                        focal_length_px=float(focal))
    return CapturePose(g, source, fsource, tuple(warnings))
