"""Worst regions: connected areas of a channel over a threshold, located in pane (or backdrop) millimetres.

A worst region is a connected set (8-neighbourhood) of analysed pixels where
``|phi| > T`` mD. For each region, with ``a(x, y)`` the pixel's area in the frame
(mm^2, see :class:`glassdist.acceptance.zones.PaneFrame`) and ``(u, v)`` its frame
coordinates (mm):

* ``area_mm2 = sum a``;
* centroid ``(sum a u / sum a, sum a v / sum a)``, mm;
* extent: the bounding box ``[u_min, u_max] x [v_min, v_max]`` of its pixel centres, mm;
* ``peak_mD``: the signed value of largest ``|phi|``; ``mean_abs_mD = sum a |phi| / sum a``.

Regions are numbered 1, 2, ... by decreasing ``|peak|`` (ties: larger area first).
The threshold ``T`` is the specification's limit for the channel (the smallest
``threshold_mD`` of its ``area_over`` criteria and ``max_mD`` of its ``p95_abs`` /
``max_abs`` criteria), a value given in the specification's ``"worst_regions"``, or by
default the 95th percentile of ``|phi|`` over the analysed region (the worst 5 %).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

from .stats import CHANNEL_FIELDS, pixel_blocks

if TYPE_CHECKING:
    from ..analyzer.result import Result
    from .spec import Spec
    from .zones import PaneFrame

__all__ = ["WorstRegion", "worst_regions", "region_thresholds", "all_worst_regions", "regions_csv"]

#: channels worst regions are listed for by default
REGION_CHANNELS = ("phi_eff", "phi_shear")


@dataclass(frozen=True)
class WorstRegion:
    """One connected region over the threshold (lengths mm in the frame's units, power mD)."""

    number: int
    channel: str
    threshold_mD: float
    centroid_mm: tuple[float, float]
    extent_mm: tuple[float, float, float, float]
    area_mm2: float
    peak_mD: float
    mean_abs_mD: float
    n_pixels: int
    centroid_px: tuple[float, float]
    units: str = "pane_mm"

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``extent_mm`` as ``[u_min, u_max, v_min, v_max]``)."""
        d = asdict(self)
        for k in ("centroid_mm", "extent_mm", "centroid_px"):
            d[k] = [float(v) for v in d[k]]
        return d


def _per_label(ufunc: np.ufunc, values: np.ndarray, labels: np.ndarray, n: int) -> np.ndarray:
    """``ufunc`` (np.minimum or np.maximum) of ``values`` over each label 1..n (unbuffered ``ufunc.at``)."""
    out = np.full(n, np.inf if ufunc is np.minimum else -np.inf)
    ufunc.at(out, labels - 1, values)
    return out


def worst_regions(field: ArrayLike, valid: ArrayLike, frame: PaneFrame, threshold_mD: float, *, channel: str = "phi_eff",
                  max_count: int = 10, min_area_mm2: float = 0.0) -> tuple[WorstRegion, ...]:
    """Connected regions where ``|field| > threshold_mD``, worst first.

    Parameters
    ----------
    field : ndarray, shape (H, W)
        Channel, mD (NaN where invalid).
    valid : ndarray of bool, shape (H, W)
        Region the search is restricted to (analysed pixels, or those of a zone).
    frame : PaneFrame
        Pixel-to-millimetre map (:mod:`glassdist.acceptance.zones`).
    threshold_mD : float
        Threshold on ``|field|``, mD.
    channel : str
        Name recorded in each region.
    max_count : int
        Most regions returned.
    min_area_mm2 : float
        Regions smaller than this are left out.

    Returns
    -------
    tuple of WorstRegion
        Numbered 1.. by decreasing ``|peak|``.

    Examples
    --------
    >>> from glassdist.acceptance.zones import pane_frame_from_region
    >>> f = np.zeros((40, 60)); f[10:20, 30:50] = 7.0
    >>> frame = pane_frame_from_region(np.ones(f.shape, bool), 0.5)
    >>> (r,) = worst_regions(f, np.ones(f.shape, bool), frame, 5.0)
    >>> r.area_mm2, r.centroid_mm, r.peak_mD
    (50.0, (20.0, 7.5), 7.0)
    """
    f = np.asarray(field)
    over = np.asarray(valid, dtype=bool) & (np.abs(f) > threshold_mD)  # NaN compares False
    return _regions_of(over, f[over], frame, threshold_mD, channel=channel, max_count=max_count,
                       min_area_mm2=min_area_mm2)


def _over_threshold(result: Result, attr: str, valid: np.ndarray, threshold_mD: float, max_pixels: int = 1 << 21
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``(over, values)``: the pixels of ``valid`` where ``|result.attr| > threshold_mD`` and their signed values
    (raster order), taken block by block of image rows (no full-size copy of the field)."""
    over = np.zeros(valid.shape, bool)
    values = []
    for rows, block in pixel_blocks(result, [attr], max_pixels):
        f = block[attr]
        o = over[rows]
        np.greater(np.abs(f), threshold_mD, out=o)  # NaN compares False
        o &= valid[rows]
        values.append(f[o])
    return over, np.concatenate(values) if values else np.empty(0, np.float32)


def _regions_of(over: np.ndarray, signed: np.ndarray, frame: PaneFrame, threshold_mD: float, *, channel: str,
                max_count: int, min_area_mm2: float) -> tuple[WorstRegion, ...]:
    """:func:`worst_regions` of the pixels ``over`` (bool (H, W)) with their signed values ``signed`` (raster order)."""
    labels, n = ndimage.label(over, structure=np.ones((3, 3), bool))
    if n == 0:
        return ()
    yy, xx = np.nonzero(over)
    lab = labels[yy, xx]
    del labels
    u, v = frame.to_mm(xx, yy)
    w = frame.pixel_area_mm2(xx, yy)
    vals = np.abs(signed).astype(np.float64)
    area = np.bincount(lab, weights=w, minlength=n + 1)[1:]
    count = np.bincount(lab, minlength=n + 1)[1:]
    cu = np.bincount(lab, weights=w * u, minlength=n + 1)[1:] / area
    cv = np.bincount(lab, weights=w * v, minlength=n + 1)[1:] / area
    cx = np.bincount(lab, weights=xx, minlength=n + 1)[1:] / count
    cy = np.bincount(lab, weights=yy, minlength=n + 1)[1:] / count
    mean = np.bincount(lab, weights=w * vals, minlength=n + 1)[1:] / area
    umin, umax = _per_label(np.minimum, u, lab, n), _per_label(np.maximum, u, lab, n)
    vmin, vmax = _per_label(np.minimum, v, lab, n), _per_label(np.maximum, v, lab, n)
    # signed peak: the value at each region's largest |phi| (the first such pixel in raster order)
    top = vals == _per_label(np.maximum, vals, lab, n)[lab - 1]
    _, first = np.unique(lab[top], return_index=True)
    peak = signed[top][first].astype(np.float64)
    order = sorted((i for i in range(n) if area[i] >= min_area_mm2), key=lambda i: (-abs(peak[i]), -area[i]))
    out = []
    for k, i in enumerate(order[:max_count], start=1):
        out.append(WorstRegion(
            k, channel, float(threshold_mD), (float(cu[i]), float(cv[i])),
            (float(umin[i]), float(umax[i]), float(vmin[i]), float(vmax[i])), float(area[i]), float(peak[i]),
            float(mean[i]), int(count[i]), (float(cx[i]), float(cy[i])), frame.units,
        ))
    return tuple(out)


def region_thresholds(result: Result, spec: Spec | None = None, channels: Sequence[str] = REGION_CHANNELS, *,
                      statistics: Mapping[str, Mapping[str, Any]] | None = None,
                      limits: Mapping[str, Sequence[float]] | None = None) -> dict[str, tuple[float, str]]:
    """Threshold (mD) per channel: the specification's, else the 95th percentile of ``|phi|``.

    ``statistics``, the channels' statistics over the analysed region already computed
    (``{channel: {"p95_abs": ...}}``), saves taking the percentile again; ``limits``,
    :func:`~glassdist.acceptance.spec.spec_limits` of ``spec`` already computed.

    Returns
    -------
    dict
        ``{channel: (threshold_mD, source)}`` with source ``"worst_regions"`` (set in
        the spec), ``"spec limit"`` or ``"p95"``.
    """
    from .spec import spec_limits
    from .zones import measured_region

    if limits is None:
        limits = spec_limits(spec) if spec is not None else {}
    given = {str(k): float(v) for k, v in spec.worst_regions.threshold_mD.items()} if spec is not None else {}
    valid = measured_region(result)
    out: dict[str, tuple[float, str]] = {}
    for ch in channels:
        if ch in given:
            out[ch] = (float(given[ch]), "worst_regions")
        elif limits.get(ch):
            out[ch] = (float(min(limits[ch])), "spec limit")
        elif statistics is not None and ch in statistics:
            out[ch] = (float(statistics[ch]["p95_abs"]), "p95")
        else:
            f = np.abs(np.asarray(result.pixel_field(CHANNEL_FIELDS[ch]), dtype=np.float64))
            ok = valid & np.isfinite(f)
            out[ch] = (float(np.percentile(f[ok], 95)) if ok.any() else float("nan"), "p95")
    return out


def all_worst_regions(result: Result, frame: PaneFrame, spec: Spec | None = None, *, channels: Sequence[str] = REGION_CHANNELS,
                      statistics: Mapping[str, Mapping[str, Any]] | None = None,
                      limits: Mapping[str, Sequence[float]] | None = None) -> dict[str, dict[str, Any]]:
    """Worst regions of each channel over the analysed region, with the thresholds used.

    ``statistics``, ``limits`` as for :func:`region_thresholds`.

    Returns
    -------
    dict
        ``{channel: {"threshold_mD", "threshold_source", "regions": tuple of WorstRegion}}``.
    """
    from .zones import measured_region

    settings = spec.worst_regions if spec is not None else None
    valid = measured_region(result)
    out = {}
    max_count = settings.max_count if settings else 10
    min_area_mm2 = settings.min_area_mm2 if settings else 0.0
    for ch, (t, source) in region_thresholds(result, spec, channels, statistics=statistics, limits=limits).items():
        regions = () if not np.isfinite(t) else _regions_of(*_over_threshold(result, CHANNEL_FIELDS[ch], valid, t),
                                                             frame, t, channel=ch, max_count=max_count,
                                                             min_area_mm2=min_area_mm2)
        out[ch] = {"threshold_mD": t, "threshold_source": source, "regions": regions}
    return out


_CSV_FIELDS = ("channel", "number", "threshold_mD", "centroid_x_mm", "centroid_y_mm", "x_min_mm", "x_max_mm",
               "y_min_mm", "y_max_mm", "area_mm2", "peak_mD", "mean_abs_mD", "n_pixels", "centroid_x_px",
               "centroid_y_px", "units")


def regions_csv(found: Mapping[str, Mapping[str, Any]]) -> str:
    """CSV text of :func:`all_worst_regions`' output, one row per region."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(_CSV_FIELDS)
    for entry in found.values():
        for r in entry["regions"]:
            w.writerow([r.channel, r.number, f"{r.threshold_mD:.6g}", *(f"{c:.6g}" for c in r.centroid_mm),
                        *(f"{c:.6g}" for c in r.extent_mm), f"{r.area_mm2:.6g}", f"{r.peak_mD:.6g}",
                        f"{r.mean_abs_mD:.6g}", r.n_pixels, *(f"{c:.2f}" for c in r.centroid_px), r.units])
    return buf.getvalue()
