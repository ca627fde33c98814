"""Acceptance record of one analysis: protocol, pane and zones, worst regions, verdict, pane metadata.

:func:`assess` gathers what a specification asks of an analysis into one
:class:`Acceptance` (no file written); the output stage writes its
:meth:`~Acceptance.summary` into ``summary.json``, :meth:`~Acceptance.regions_csv`
as ``worst_regions.csv`` and draws :func:`draw_overlays` (zones, numbered worst
regions) on the heatmaps, whose axes are in millimetres (:func:`heatmap_axes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .regions import REGION_CHANNELS, all_worst_regions, regions_csv
from .spec import spec_channels, spec_limits, spec_verdict
from .stats import CHANNEL_FIELDS, regions_statistics, valid_percent
from .zones import measured_region, pane_frame, zone_masks, zone_statistics

__all__ = ["Acceptance", "assess", "camera_metadata", "heatmap_axes", "draw_overlays", "colour_limits", "describe_clipping", "metadata_rows",
           "METADATA_KEYS"]

#: pane facts a report states (given on the command line, in a batch manifest or to the API)
METADATA_KEYS = ("pane_id", "site", "operator")

_EXIF_TAGS = {  # EXIF tag id -> name recorded
    0x010F: "make", 0x0110: "model", 0x0132: "datetime", 0x9003: "datetime_original", 0x829A: "exposure_time_s",
    0x829D: "f_number", 0x920A: "focal_length_mm", 0x8827: "iso", 0xA434: "lens_model", 0xA431: "serial_number",
}


def camera_metadata(path):
    """Camera facts from a photo's EXIF block (Pillow), or ``None`` when it has none.

    Parameters
    ----------
    path : path
        The photograph.

    Returns
    -------
    dict or None
        Any of ``make``, ``model``, ``lens_model``, ``serial_number``, ``datetime``,
        ``datetime_original``, ``exposure_time_s``, ``f_number``, ``focal_length_mm``,
        ``iso`` that the file records.
    """
    from ..io import open_with_pillow

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
    return out or None


@dataclass(frozen=True)
class Acceptance:
    """What a specification asks of one analysis (see :func:`assess`).

    Attributes
    ----------
    stats : dict
        ``{channel: statistics}`` over the analysed region (the result's trusted pixels,
        :func:`~glassdist.report.zones.measured_region`; with the spec's area-over values).
    frame : PaneFrame
        The pane and its millimetre frame.
    zones : dict
        ``{name: {"definition", "area_mm2", "analysed_area_mm2", "coverage_percent", "statistics"}}``.
    masks : dict
        ``{name: bool (H, W)}`` of each zone.
    regions : dict
        ``{channel: {"threshold_mD", "threshold_source", "regions"}}``.
    verdict : Verdict or None
    coverage_percent : float
        Analysed share (percent) of the region to analyse (the mask's, else the image).
    protocol : dict or None
        :meth:`ResolvedProtocol.to_dict` with the values the analysis used.
    metadata : dict
        Pane ID, site, operator (given) and camera (EXIF).
    colour_limits : dict
        ``{channel: mD}`` of the heatmaps.
    warnings : tuple of str
    """

    stats: dict
    frame: object
    zones: dict
    masks: dict
    regions: dict
    verdict: object
    coverage_percent: float
    protocol: dict | None
    metadata: dict
    colour_limits: dict
    warnings: tuple = field(default=())

    def summary(self):
        """Additions to ``summary.json``: ``protocol``, ``pane``, ``zones``, ``worst_regions``, ``metadata``."""
        return {
            "protocol": self.protocol,
            "pane": self.frame.to_dict(),
            "zones": self.zones,
            "worst_regions": {ch: {"threshold_mD": e["threshold_mD"], "threshold_source": e["threshold_source"],
                                   "units": self.frame.units, "regions": [r.to_dict() for r in e["regions"]]}
                              for ch, e in self.regions.items()},
            "metadata": self.metadata,
            "coverage_percent": self.coverage_percent,
            "colour_limits_mD": self.colour_limits,
        }

    def regions_csv(self):
        """``worst_regions.csv`` text."""
        return regions_csv(self.regions)


def colour_limits(result, spec=None, channels=("phi_eff", "phi_shear")):
    """Colour limit (mD) of each heatmap: the spec's choice (``figures.colour_limit``), else a shared p99.

    The shared p99 is taken where the heatmaps are drawn from: the trusted samples of the
    analysis grid.

    Returns
    -------
    dict
        ``{channel: vmax_mD}``.
    """
    from .figures import CHANNELS, shared_limit

    maps = [result.grid_field(CHANNELS[c][0]) for c in channels]
    valid = np.asarray(result.grid_valid, bool) & np.asarray(result.grid_trusted, bool)
    shared = shared_limit(*maps, valid=valid)
    choice = spec.figures.colour_limit if spec is not None else "auto"
    if choice == "auto":
        return {c: shared for c in channels}
    if choice != "spec":
        return {c: float(choice) for c in channels}
    limits = spec_limits(spec)
    return {c: float(min(limits[c])) if limits.get(c) else shared for c in channels}


def assess(result, spec=None, *, spec_path="", spec_sha256="", protocol=None, mask=None, metadata=None,
           image_path=None):
    """Statistics, pane frame, zones, worst regions and verdict of one analysis.

    Parameters
    ----------
    result : AnalysisResult
    spec : Spec, optional
        Without one: whole-region statistics, the pane found in the image, worst
        regions over the default threshold, no verdict.
    spec_path, spec_sha256 : str
        Recorded in the verdict.
    protocol : ResolvedProtocol, optional
        The settings resolved from the options and the spec (recorded).
    mask : ndarray of bool, shape (H, W), optional
        The user's region to analyse: coverage is the analysed share of it.
    metadata : dict, optional
        ``pane_id``, ``site``, ``operator`` (None values left out).
    image_path : path, optional
        The photograph, for its camera EXIF.

    Returns
    -------
    Acceptance

    Raises
    ------
    InputError
        The capture violates the protocol's capture limits.
    """
    limits = spec_limits(spec) if spec is not None else {}
    # the power channels always; the uncertainty channels where a criterion judges them
    channels = tuple(dict.fromkeys((*CHANNEL_FIELDS, *(spec_channels(spec) if spec is not None else ()))))
    measured = measured_region(result)
    frame = pane_frame(result, spec.pane if spec is not None else None)
    zones_def = spec.zones if spec is not None else ()
    masks = zone_masks(frame, zones_def)
    # the whole region and every zone in one pass over the pixel grid
    regions = {None: measured, **{z.name: measured & masks[z.name] for z in zones_def}}
    per_region = regions_statistics(result, regions, over_limits_mD=limits, channels=channels)
    stats = per_region.pop(None)
    zones = zone_statistics(result, frame, zones_def, over_limits_mD=limits, masks=masks, channels=channels,
                            statistics=per_region)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        coverage = 100.0 * np.count_nonzero(measured & m) / max(np.count_nonzero(m), 1)
    else:
        coverage = valid_percent(measured)
    verdict = None
    if spec is not None:
        verdict = spec_verdict(spec, stats, result, spec_path=spec_path, spec_sha256=spec_sha256, zones=zones,
                                coverage_percent=None if mask is None else coverage)
    regions = all_worst_regions(result, frame, spec, channels=REGION_CHANNELS, statistics=stats)
    meta = {k: v for k, v in (metadata or {}).items() if v is not None}
    if image_path is not None:
        meta["camera"] = camera_metadata(image_path)
    proto = None
    if protocol is not None:
        proto = protocol.to_dict()
    if proto is not None or spec is not None:
        proto = proto or {"pinned": spec.protocol.model_dump(exclude_none=True)}
        from .spec import px_per_period

        proto["used"] = {"method": result.method, "pitch_mm": result.pitch_mm, "distance_m": result.distance_m,
                         "pattern": getattr(getattr(result, "params", None), "pattern", None),
                         "sigma_mm": result.sigma_mm, "detrend_degree": result.detrend_degree,
                         "px_per_period": px_per_period(result)}
    warnings = (frame.warning,) if frame.warning and zones_def else ()
    return Acceptance(stats, frame, zones, masks, regions, verdict, float(coverage), proto, meta,
                      colour_limits(result, spec), warnings)


def heatmap_axes(frame, mm_per_px, shape):
    """Millimetre axes of the heatmaps.

    In the pane frame when it is axis-aligned with the photo (the outline found in the
    image: frame mm = image px scaled, shifted); otherwise (a pane given by corners
    seen in perspective) in backdrop mm from the photo's top-left corner.

    Returns
    -------
    extent : (float, float, float, float)
        ``imshow`` extent ``(left, right, bottom, top)``, mm.
    to_axes : callable
        ``(x_px, y_px) -> (X_mm, Y_mm)``.
    label : str
        What the axes measure.
    """
    H = frame.px_to_mm
    h, w = shape
    if abs(H[0, 1]) < 1e-12 and abs(H[1, 0]) < 1e-12 and abs(H[2, 0]) < 1e-12 and abs(H[2, 1]) < 1e-12:
        def to_axes(x, y):
            return frame.to_mm(x, y)
        where = "pane" if frame.units == "pane_mm" else "backdrop"
        label = f"{where} mm"
    else:
        s = float(mm_per_px)

        def to_axes(x, y):
            return (np.asarray(x, dtype=float) + 0.5) * s, (np.asarray(y, dtype=float) + 0.5) * s
        label = "backdrop mm from the photo's top-left"
    (x0, x1), (y0, y1) = (np.asarray(c) for c in to_axes(np.array([-0.5, w - 0.5]), np.array([-0.5, h - 0.5])))
    return (float(x0), float(x1), float(y1), float(y0)), to_axes, label


_ZONE_COLOURS = ("black", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive")


def draw_overlays(ax, acc, channel, to_axes, extent):
    """Draw the zones (outlined, named) and the channel's numbered worst regions on a heatmap.

    Parameters
    ----------
    ax : matplotlib Axes
    acc : Acceptance
    channel : str
        Whose worst regions are numbered.
    to_axes, extent
        From :func:`heatmap_axes`.
    """
    import matplotlib.patheffects as pe

    halo = [pe.withStroke(linewidth=2.5, foreground="white")]
    h, w = acc.frame.shape
    step = max(1, int(max(h, w) // 1000))  # contours of a decimated mask: enough for a figure
    for i, (name, m) in enumerate(acc.masks.items()):
        if not m.any():
            continue
        colour = _ZONE_COLOURS[i % len(_ZONE_COLOURS)]
        sub = m[::step, ::step].astype(float)
        X, Y = to_axes(*np.meshgrid(np.arange(0, w, step), np.arange(0, h, step)))
        ax.contour(X, Y, sub, levels=[0.5], colors=[colour], linewidths=1.2, linestyles="--")
        yy, xx = np.nonzero(m[::step, ::step])
        k = np.argmin(yy * w + xx)  # label at the zone's top-left-most pixel
        tx, ty = to_axes(xx[k] * step, yy[k] * step)
        ax.text(float(tx), float(ty), f" {name}", color=colour, fontsize="small", va="top", ha="left",
                path_effects=halo)
    entry = acc.regions.get(channel)
    for r in entry["regions"] if entry else ():
        tx, ty = to_axes(*r.centroid_px)
        ax.text(float(tx), float(ty), str(r.number), color="black", fontsize="small", fontweight="bold",
                ha="center", va="center", path_effects=halo)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])


def describe_clipping(field, valid, vmax, top=None):
    """Caption text: the largest ``|phi|`` and whether the colour scale clips it.

    ``valid``: the samples the caption speaks of (the trusted ones); ``top``: their largest
    ``|phi|`` when known (the statistics' ``max_abs``, over the trusted pixels), else taken
    from ``field``.
    """
    f = np.asarray(field, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool) & np.isfinite(f)
    if not ok.any():
        return ""
    top = float(np.abs(f[ok]).max()) if top is None or not math.isfinite(top) else float(top)
    share = 100.0 * np.count_nonzero(np.abs(f[ok]) > vmax) / np.count_nonzero(ok)
    if top <= vmax or math.isclose(top, vmax):
        return f"max |phi| {top:.3g} mD"
    return f"max |phi| {top:.3g} mD; colours clipped at {vmax:.3g} mD ({share:.2g} % of the region beyond)"


def metadata_rows(metadata):
    """``(label, text)`` rows of the pane metadata for a report."""
    rows = []
    for key, label in (("pane_id", "pane ID"), ("lot", "lot"), ("site", "site"), ("operator", "operator")):
        if metadata.get(key):
            rows.append((label, str(metadata[key])))
    cam = metadata.get("camera")
    if cam:
        parts = [" ".join(str(cam[k]) for k in ("make", "model") if cam.get(k))]
        if cam.get("lens_model"):
            parts.append(f"lens {cam['lens_model']}")
        if cam.get("focal_length_mm"):
            parts.append(f"f = {cam['focal_length_mm']:g} mm")
        if cam.get("f_number"):
            parts.append(f"f/{cam['f_number']:g}")
        if cam.get("exposure_time_s"):
            parts.append(f"{cam['exposure_time_s']:.3g} s")
        if cam.get("iso"):
            parts.append(f"ISO {cam['iso']:g}")
        if cam.get("datetime_original") or cam.get("datetime"):
            parts.append(str(cam.get("datetime_original") or cam.get("datetime")))
        rows.append(("camera (EXIF)", ", ".join(p for p in parts if p)))
    else:
        rows.append(("camera (EXIF)", "not recorded in the photo"))
    return rows


