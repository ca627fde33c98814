"""Zones of a pane: its outline in the photograph, a millimetre frame on it, named zones and their statistics.

A specification's ``"zones"`` name parts of the pane in millimetres (see
:class:`glassdist.acceptance.spec.Zone`): a band along the pane outline
(``edge_band_mm``), the pane minus a border (``inset_mm``) or a polygon
(``polygon_mm``). They are drawn on the image through a :class:`PaneFrame`, the map
between image pixels ``(x, y)`` (x along columns, y down the rows, pixel centres
at integer coordinates) and frame millimetres ``(u, v)``:

* **pane given in the specification** (``"pane": {"corners_frac" or "corners_px", "size_mm"}``): the
  homography taking the four corners to the rectangle ``[0, w] x [0, h]`` mm; the
  frame is the pane's own (``units = "pane_mm"``), exact for any perspective, and a
  pixel's distance to the outline is ``min(u, w - u, v, h - v)``;
* **outline found in the image**: the region where the grid is visible (the
  analysed region with its holes filled, grown back by the margin the analyzer
  eroded around excluded areas) when it lies inside the photo, i.e. a frame or
  edge of the pane is seen all round; distances are measured in the image and
  converted with the result's ``mm_per_px`` (backdrop millimetres, ``units =
  "backdrop_mm"``: exact for a frontal view, and on the backdrop's scale, not the
  pane's); the frame's origin is the top-left corner of the region's bounding box;
* **no outline visible** (the grid reaches the photo's edges): the analysed region
  (holes filled) stands in for the pane, with a warning.

The area of a pixel in the frame is ``|det J|`` with ``J`` the Jacobian of the
pixel-to-millimetre map; for a homography ``H`` (last row ``h3``),
``det J = det(H) / (h3 . (x, y, 1))^3``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property, partial
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .stats import CHANNEL_FIELDS, regions_statistics

if TYPE_CHECKING:
    from ..analyzer.result import Result
    from .spec import Pane, Zone

__all__ = ["PaneFrame", "check_pane", "PANE_SCALE_RANGE", "distance_to_outside", "fill_holes", "grow_region", "pane_frame",
           "pane_frame_from_corners", "pane_frame_from_region", "zone_masks", "zone_statistics", "measured_region",
           "region_statistics"]


def _apply(H: np.ndarray, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """``H`` applied to points ``(x, y)`` (arrays), returns ``(u, v)``."""
    xa = np.asarray(x, dtype=np.float64)
    ya = np.asarray(y, dtype=np.float64)
    w = H[2, 0] * xa + H[2, 1] * ya + H[2, 2]
    return (H[0, 0] * xa + H[0, 1] * ya + H[0, 2]) / w, (H[1, 0] * xa + H[1, 1] * ya + H[1, 2]) / w


@dataclass(frozen=True)
class PaneFrame:
    """The pane in the photograph and a millimetre frame on it.

    Attributes
    ----------
    px_to_mm : ndarray, shape (3, 3)
        Homography from image pixels ``(x, y, 1)`` to frame millimetres ``(u, v, 1)``.
    inside : ndarray of bool, shape (H, W)
        Pixels on the pane.
    edge_distance_mm : ndarray of float32, shape (H, W)
        Distance from each pixel to the pane outline, mm (NaN outside the pane);
        computed on first access when given as a function (only zones need it).
    source : {'spec', 'image', 'analysed_region'}
        Where the outline came from.
    units : {'pane_mm', 'backdrop_mm'}
        The frame's millimetres: on the pane (corners given) or on the backdrop
        (through ``mm_per_px``).
    outline_px : tuple of ndarray (N, 2)
        The outline as polygons of ``(x, y)`` pixel vertices, for drawing.
    size_mm : (float, float) or None
        Width and height of the pane, mm (given, or the region's bounding box).
    warning : str
        Said when the outline is a stand-in.
    """

    px_to_mm: np.ndarray
    inside: np.ndarray
    edge_distance: np.ndarray | Callable[[], np.ndarray]  # or a function returning it
    source: str
    units: str
    outline_px: tuple[np.ndarray, ...] = ()
    size_mm: tuple[float, float] | None = None
    warning: str = ""
    _mm_to_px: np.ndarray | None = field(default=None, repr=False, compare=False)

    @cached_property
    def edge_distance_mm(self) -> np.ndarray:
        """Distance from each pixel to the pane outline, mm (float32, NaN outside the pane)."""
        return self.edge_distance() if callable(self.edge_distance) else self.edge_distance

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the image."""
        return (int(self.inside.shape[0]), int(self.inside.shape[1]))

    def to_mm(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Frame millimetres ``(u, v)`` of image points ``(x, y)`` (px)."""
        return _apply(self.px_to_mm, x, y)

    def to_px(self, u: ArrayLike, v: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Image points ``(x, y)`` (px) of frame millimetres ``(u, v)``."""
        return _apply(np.linalg.inv(self.px_to_mm), u, v)

    def pixel_area_mm2(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Area (mm^2) of the pixels at ``(x, y)``: ``|det H| / |h3 . (x, y, 1)|^3``."""
        H = self.px_to_mm
        w = H[2, 0] * np.asarray(x, dtype=np.float64) + H[2, 1] * np.asarray(y, dtype=np.float64) + H[2, 2]
        return np.abs(np.linalg.det(H) / w**3)

    def area_mm2(self, mask: np.ndarray) -> float:
        """Area (mm^2) of the pixels of ``mask`` (bool, shape (H, W))."""
        H = self.px_to_mm
        if H[2, 0] == 0 and H[2, 1] == 0:  # affine: one area for every pixel
            return float(np.count_nonzero(mask) * abs(np.linalg.det(H) / H[2, 2] ** 3))
        yy, xx = np.nonzero(mask)
        return float(self.pixel_area_mm2(xx, yy).sum()) if yy.size else 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON form for ``summary.json`` (``"pane"``); ``outline_px``: one ``"x,y x,y ..."`` string per polygon."""
        return {
            "source": self.source, "units": self.units,
            "size_mm": None if self.size_mm is None else [float(v) for v in self.size_mm],
            "px_to_mm": self.px_to_mm.tolist(), "area_mm2": self.area_mm2(self.inside),
            "outline_px": [_compact_polygon(p) for p in self.outline_px], "warning": self.warning or None,
        }


def _compact_polygon(points: ArrayLike, tolerance_px: float = 1.5) -> str:
    """A polygon's vertices for ``summary.json``: ``"x,y x,y ..."`` (SVG ``points``), whole px.

    Douglas-Peucker (``cv2.approxPolyDP``) keeps the vertices within ``tolerance_px`` of the
    outline, which is found on the analysis grid (a few px step) and drawn at that precision;
    one string per polygon keeps ``summary.json`` short (it was a third of the file).
    """
    import cv2

    pts: np.ndarray = np.asarray(points, dtype=np.float32).reshape(-1, 1, 2)
    if len(pts) > 3:
        pts = cv2.approxPolyDP(pts, tolerance_px, closed=True)
    return " ".join(f"{x:.0f},{y:.0f}" for x, y in pts.reshape(-1, 2))


def pane_frame_from_corners(corners_px: ArrayLike, size_mm: Sequence[float], shape: tuple[int, int]) -> PaneFrame:
    """The frame of a pane given by its four corners in the photograph.

    Parameters
    ----------
    corners_px : array_like, shape (4, 2)
        ``(x, y)`` of the top-left, top-right, bottom-right, bottom-left corners, px.
    size_mm : (float, float)
        Width (top edge) and height (left edge) of the pane, mm.
    shape : (int, int)
        ``(H, W)`` of the image.

    Returns
    -------
    PaneFrame
        ``units = "pane_mm"``; the edge distance is ``min(u, w - u, v, h - v)``.

    Examples
    --------
    >>> f = pane_frame_from_corners([[9.5, 19.5], [109.5, 19.5], [109.5, 69.5], [9.5, 69.5]], (200, 100), (100, 150))
    >>> [round(float(c), 6) for c in f.to_mm(59.5, 44.5)], round(f.area_mm2(f.inside), 6)
    ([100.0, 50.0], 20000.0)
    """
    from skimage.transform import ProjectiveTransform

    w_mm, h_mm = (float(v) for v in size_mm)
    src = np.asarray(corners_px, dtype=np.float64).reshape(4, 2)
    dst = np.array([[0, 0], [w_mm, 0], [w_mm, h_mm], [0, h_mm]], dtype=np.float64)
    if hasattr(ProjectiveTransform, "from_estimate"):
        H = ProjectiveTransform.from_estimate(src, dst).params
    else:  # scikit-image < 0.26
        t = ProjectiveTransform()
        t.estimate(src, dst)
        H = t.params
    H = H / H[2, 2]
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    u, v = _apply(H, xx, yy)
    dist = np.minimum(np.minimum(u, w_mm - u), np.minimum(v, h_mm - v))
    inside = dist >= 0
    dist = np.where(inside, dist, np.nan).astype(np.float32)
    return PaneFrame(H, inside, dist, "spec", "pane_mm", (src,), (w_mm, h_mm))


def _outline_polygons(region: np.ndarray) -> tuple[np.ndarray, ...]:
    import cv2

    contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return tuple(cv2.approxPolyDP(c, 1.0, True).reshape(-1, 2).astype(np.float64)
                 for c in sorted(contours, key=cv2.contourArea, reverse=True) if len(c) >= 3)


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """``mask`` with its holes filled: the pixels not reached from outside the image through the background.

    Same as :func:`scipy.ndimage.binary_fill_holes` (the background connected through
    edge neighbours, 4-connectivity), by one flood fill of OpenCV (at 24 Mpx about 20x
    faster than the iterated dilation).

    Examples
    --------
    >>> m = np.zeros((5, 5), bool); m[1:4, 1:4] = True; m[2, 2] = False
    >>> bool(fill_holes(m)[2, 2]), int(fill_holes(m).sum())
    (True, 9)
    """
    import cv2

    mask = np.asarray(mask, dtype=bool)
    background = np.pad(~mask, 1, constant_values=True).view(np.uint8).copy()
    cv2.floodFill(background, None, (0, 0), 2, flags=4)
    return background[1:-1, 1:-1] != 2


def distance_to_outside(mask: np.ndarray) -> np.ndarray:
    """Euclidean distance (px, float32) from each pixel of ``mask`` to the nearest pixel outside it (0 outside).

    Exact Euclidean distance transform (OpenCV's ``DIST_MASK_PRECISE``, the algorithm of
    Felzenszwalb & Huttenlocher, 2012), as :func:`scipy.ndimage.distance_transform_edt`
    but about 10x faster at camera resolution. The image border is not an outside pixel;
    where ``mask`` has no outside pixel at all, the distance is ``inf``.
    """
    import cv2

    mask = np.asarray(mask, dtype=bool)
    if mask.all():
        return np.full(mask.shape, np.inf, np.float32)
    return cv2.distanceTransform(np.ascontiguousarray(mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def grow_region(mask: np.ndarray, radius_px: float) -> np.ndarray:
    """``mask`` grown by ``radius_px``: the pixels whose centre lies within ``radius_px`` of a pixel of ``mask``.

    The same pixels as ``distance_to_outside(~mask) <= radius_px``, by one dilation with
    the exact disk of offsets ``i^2 + j^2 <= radius_px^2`` (at 24 Mpx about 10x faster
    than the distance transform).

    Examples
    --------
    >>> m = np.zeros((7, 7), bool); m[3, 3] = True
    >>> int(grow_region(m, 1.0).sum()), int(grow_region(m, 1.5).sum()), int(grow_region(m, 2.0).sum())
    (5, 9, 13)
    """
    import cv2

    mask = np.asarray(mask, dtype=bool)
    r = int(np.floor(radius_px))
    if r < 1 or not mask.any():
        return mask.copy()
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    disk = (yy**2 + xx**2 <= float(radius_px) ** 2).astype(np.uint8)
    return cv2.dilate(np.ascontiguousarray(mask).view(np.uint8), disk).view(bool)


def pane_frame_from_region(valid: np.ndarray, mm_per_px: float, *, grow_px: float = 0.0) -> PaneFrame:
    """The pane's outline found in the image: the region where the grid is visible.

    Parameters
    ----------
    valid : ndarray of bool, shape (H, W)
        The analysed region.
    mm_per_px : float
        Backdrop mm per px (the result's).
    grow_px : float
        Margin (px) the analyzer eroded around excluded areas; the analysed region
        is grown back by it to reach the edge of the visible grid.

    Returns
    -------
    PaneFrame
        ``source = "image"`` when the visible grid ends inside the photo all round (a
        frame is seen), else ``"analysed_region"`` (holes filled) with a warning;
        ``units = "backdrop_mm"``.
    """
    valid = np.asarray(valid, dtype=bool)
    filled = fill_holes(valid)
    region = filled
    if grow_px > 0 and filled.any():
        region = fill_holes(grow_region(filled, grow_px))
    border = np.concatenate([region[0], region[-1], region[:, 0], region[:, -1]])
    warning = ""
    if not filled.any() or border.any():
        region = filled
        source = "analysed_region"
        warning = ("no pane outline visible all round (the grid reaches the photo's edges): the analysed region "
                   "stands in for the pane in the zones; give 'pane': {'corners_frac', 'size_mm'} in the specification "
                   "for zones on the pane itself")
    else:
        source = "image"
    rows, cols = np.flatnonzero(region.any(axis=1)), np.flatnonzero(region.any(axis=0))
    if rows.size:
        x0, y0 = cols.min() - 0.5, rows.min() - 0.5
        size = ((cols.max() + 0.5 - x0) * mm_per_px, (rows.max() + 0.5 - y0) * mm_per_px)
    else:
        x0 = y0 = 0.0
        size = None
    s = float(mm_per_px)
    H = np.array([[s, 0.0, -s * x0], [0.0, s, -s * y0], [0.0, 0.0, 1.0]])
    return PaneFrame(H, region, partial(_edge_distance_mm, region, float(mm_per_px)), source, "backdrop_mm",
                     _outline_polygons(region), size, warning)


def _edge_distance_mm(region: np.ndarray, mm_per_px: float) -> np.ndarray:
    """Distance (mm, float32) from each pixel centre of ``region`` to its edge; NaN outside.

    The edge lies half a pixel beyond the last centre inside.
    """
    dist = distance_to_outside(region)
    dist -= 0.5
    dist *= mm_per_px
    dist[~region] = np.nan
    return dist


#: accepted ratio of the pane's span on the backdrop (its corners' px times ``mm_per_px``) to its stated size,
#: transmission: a pane at distance C from the camera, L in front of the grid, spans ``(C + L) / C`` times its size
#: there (1 for a far camera, 3 for one at L / 2 from the pane); down to 0.75 for a pane seen up to 40 deg
#: obliquely (its foreshortened side). Reflection: the scale is on the pane (ratio 1, oblique view as above).
PANE_SCALE_RANGE = {"transmission": (0.75, 3.0), "reflection": (0.75, 1.0 / 0.75)}

#: largest ratio between the two sides' scale ratios (one camera distance for both; a pane seen obliquely)
_PANE_ASPECT_RATIO = 1.0 / 0.75

#: corners this far (px) beyond the photo's outer edge are still inside it (rounding of a corner picked by hand)
_CORNER_SLACK_PX = 1.0


def check_pane(pane: Pane | None, zones: Sequence[Zone], result: Result, *, spec_label: str = "the specification") -> None:
    """Refuse a pane or zone that the photo cannot show: outside it, or at odds with its measured scale.

    Parameters
    ----------
    pane : glassdist.acceptance.spec.Pane or None
    zones : sequence of glassdist.acceptance.spec.Zone
    result : AnalysisResult
        ``valid`` (the photo's shape), ``mm_per_px`` (backdrop mm per px, or pane mm in
        reflection) and ``optics``.
    spec_label : str
        How the message names the specification.

    Checks, in order: every corner lies inside the photo (within 1 px of its outer edge);
    the corners' span in backdrop millimetres (mean of the two opposite sides' lengths, px,
    times ``mm_per_px``) divided by ``size_mm`` lies in :data:`PANE_SCALE_RANGE` for each
    side, and the two sides' ratios agree within 4:3 (one camera distance for both); a
    polygon zone lies on the pane; an ``inset_mm`` zone leaves some of the pane.

    Raises
    ------
    InputError
        One line naming the mismatch and the fix (exit 2): the specification cannot judge
        what the photo did not measure.
    """
    from ..errors import InputError

    if pane is not None:
        H, W = np.asarray(result.valid).shape
        c = pane.corners_in((H, W))
        key = pane.corners_key
        lo, hi = -0.5 - _CORNER_SLACK_PX, np.array([W, H]) - 0.5 + _CORNER_SLACK_PX
        out = np.flatnonzero(np.any((c < lo) | (c > hi), axis=1))
        if out.size:
            x, y = c[out[0]]
            raise InputError(
                f"the pane of {spec_label} has a corner at ({x:.6g}, {y:.6g}) px, outside the {W} x {H} px photo: "
                f"its '{key}' were written for another photo; give the corners of the pane in this photo, or as "
                "fractions of the image ('corners_frac') to serve every resolution")
        s = float(result.mm_per_px)
        d = np.hypot(*(c[[1, 2, 3, 2]] - c[[0, 3, 0, 1]]).T)  # top, bottom, left, right edges, px
        span = ((d[0] + d[1]) / 2 * s, (d[2] + d[3]) / 2 * s)
        size = tuple(float(v) for v in pane.size_mm)
        ratio = (span[0] / size[0], span[1] / size[1])
        optics = "reflection" if result.optics is not None else "transmission"
        r_lo, r_hi = PANE_SCALE_RANGE[optics]
        aspect = max(ratio) / max(min(ratio), 1e-300)
        if math.isfinite(s) and (not all(r_lo <= r <= r_hi for r in ratio) or aspect > _PANE_ASPECT_RATIO):
            where = "on the backdrop" if optics == "transmission" else "on the pane"
            r_text = f"{ratio[0]:.2g}" if f"{ratio[0]:.2g}" == f"{ratio[1]:.2g}" else f"{ratio[0]:.2g} x {ratio[1]:.2g}"
            raise InputError(
                f"the pane of {spec_label} spans {span[0]:.4g} x {span[1]:.4g} mm {where} by the measured scale "
                f"({s:.4g} mm per px) but its size_mm is {size[0]:.4g} x {size[1]:.4g} mm (ratio {r_text}; the capture "
                f"geometry allows {r_lo:g} to {r_hi:.3g}, alike on both sides): its '{key}' were written for another "
                "resolution or set-up, or its size_mm or the pitch is wrong; give the pane's corners in this photo, or "
                "as fractions of the image ('corners_frac') to serve every resolution")
    w_h = None if pane is None else tuple(float(v) for v in pane.size_mm)
    for i, z in enumerate(zones, 1):
        if w_h is None:
            continue
        if z.polygon_mm is not None:
            p = np.asarray(z.polygon_mm, dtype=np.float64)
            if np.any(p < -1e-9) or np.any(p > np.array(w_h) + 1e-9):
                raise InputError(
                    f"zone {i} ('{z.name}') of {spec_label} reaches beyond the {w_h[0]:g} x {w_h[1]:g} mm pane "
                    "('polygon_mm' is in pane mm from its top-left corner); keep its vertices on the pane")
        if z.inset_mm is not None and 2 * z.inset_mm >= min(w_h):
            raise InputError(
                f"zone {i} ('{z.name}') of {spec_label} is empty: an inset of {z.inset_mm:g} mm leaves nothing of the "
                f"{w_h[0]:g} x {w_h[1]:g} mm pane; give an inset_mm under {min(w_h) / 2:g}")


def pane_frame(result: Result, pane: Pane | None = None) -> PaneFrame:
    """The :class:`PaneFrame` of an analysis: from the specification's ``pane``, else found in the image.

    Parameters
    ----------
    result : AnalysisResult
        Needs ``valid`` and ``mm_per_px``; ``margin_px`` (the margin at excluded areas) is
        grown back onto the analysed region.
    pane : glassdist.acceptance.spec.Pane, optional
    """
    valid = np.asarray(result.valid, dtype=bool)
    if pane is not None:
        return pane_frame_from_corners(pane.corners_in(valid.shape), pane.size_mm, valid.shape)
    grow = float(result.margin_px[0])
    return pane_frame_from_region(valid, float(result.mm_per_px), grow_px=grow)


def zone_masks(frame: PaneFrame, zones: Sequence[Zone]) -> dict[str, np.ndarray]:
    """Pixels of each zone.

    Parameters
    ----------
    frame : PaneFrame
    zones : sequence of glassdist.acceptance.spec.Zone

    Returns
    -------
    dict
        ``{name: ndarray of bool (H, W)}``: ``edge_band_mm`` b keeps the pane pixels
        less than b from the outline, ``inset_mm`` d those at least d from it (the two
        split the pane when b = d), ``polygon_mm`` the pane pixels inside the polygon.
    """
    from skimage.draw import polygon as polygon_pixels

    out = {}
    # the distance map only where a zone is defined by it
    if any(z.edge_band_mm is not None or z.inset_mm is not None for z in zones):
        d = np.nan_to_num(frame.edge_distance_mm, nan=-1.0)
    for z in zones:
        if z.edge_band_mm is not None:
            m = frame.inside & (d < z.edge_band_mm)
        elif z.inset_mm is not None:
            m = frame.inside & (d >= z.inset_mm)
        else:
            poly = np.asarray(z.polygon_mm, dtype=np.float64)
            # a homography keeps straight edges straight: the polygon's vertices suffice, and a
            # pixel belongs to the zone when its centre is inside
            x, y = frame.to_px(poly[:, 0], poly[:, 1])
            m = np.zeros(frame.shape, bool)
            m[polygon_pixels(y, x, frame.shape)] = True
            m &= frame.inside
        out[z.name] = m
    return out


def measured_region(result: Result) -> np.ndarray:
    """The pixels statistics and verdicts use: the result's trusted pixels (quality label 0), else its valid region."""
    return np.asarray(result.trusted, dtype=bool)


def region_statistics(result: Result, region: np.ndarray, *, over_limits_mD: Mapping[str, Sequence[float]] | None = None,
                      channels: Sequence[str] = tuple(CHANNEL_FIELDS)) -> dict[str, dict[str, Any]]:
    """``{channel: statistics}`` of ``channels`` of ``result`` (those it holds) over the pixels of ``region`` (bool, (H, W)).

    ``channels``: names of :data:`glassdist.acceptance.stats.STATISTIC_FIELDS` (default the power
    channels; a specification may add the uncertainty channels). See
    :func:`~glassdist.acceptance.stats.regions_statistics`, which takes several regions in one pass.
    """
    return regions_statistics(result, {"region": region}, over_limits_mD=over_limits_mD, channels=channels)["region"]


def zone_statistics(result: Result, frame: PaneFrame, zones: Sequence[Zone], *,
                    over_limits_mD: Mapping[str, Sequence[float]] | None = None,
                    masks: Mapping[str, np.ndarray] | None = None, channels: Sequence[str] = tuple(CHANNEL_FIELDS),
                    statistics: Mapping[str, dict[str, dict[str, Any]]] | None = None) -> dict[str, dict[str, Any]]:
    """Statistics and coverage of every zone.

    Parameters
    ----------
    result : AnalysisResult
        The channels and ``valid``.
    frame : PaneFrame
    zones : sequence of glassdist.acceptance.spec.Zone
    over_limits_mD : dict, optional
        ``{channel: [T, ...]}`` thresholds for the area-over statistics.
    masks : dict, optional
        :func:`zone_masks` already computed.
    channels : sequence of str
        As for :func:`region_statistics`.
    statistics : dict, optional
        ``{zone name: {channel: statistics}}`` already taken over each zone's analysed pixels.

    Returns
    -------
    dict
        ``{name: {"definition", "area_mm2", "analysed_area_mm2", "trusted_percent",
        "statistics": {channel: statistics}}}``; ``trusted_percent`` is the trusted (analysed)
        share of the zone's area (NaN for a zone outside the photo), the statistics are
        over the analysed pixels of the zone (see :mod:`glassdist.acceptance.stats`); analysed
        pixels are those of :func:`measured_region`.
    """
    masks = zone_masks(frame, zones) if masks is None else masks
    measured = measured_region(result)
    if statistics is None:
        statistics = regions_statistics(result, {z.name: measured & masks[z.name] for z in zones},
                                        over_limits_mD=over_limits_mD, channels=channels)
    out = {}
    for z in zones:
        m = masks[z.name]
        area = frame.area_mm2(m)
        analysed = frame.area_mm2(m & measured)
        stats = statistics[z.name]
        out[z.name] = {
            "definition": z.describe(), "area_mm2": area, "analysed_area_mm2": analysed,
            "trusted_percent": 100.0 * analysed / area if area > 0 else math.nan, "statistics": stats,
        }
    return out
