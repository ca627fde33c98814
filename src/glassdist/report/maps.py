"""The maps and histograms of one run, drawn from its analysis grid (rendering only: no file is written).

:func:`run_figures` returns every figure of ``glassdist analyze`` as ``(stem, caption,
PNG bytes)``: the input with the analysed region, the channel heatmaps with the
acceptance overlays (:func:`draw_overlays`: zones, numbered worst regions, named in the
legend by :func:`overlay_legend`) on millimetre axes (:func:`heatmap_axes`), the axis,
quality and uncertainty maps, a threshold mask per specification limit and the
histograms. Figures draw only what the statistics use: the maps' colour scales hold the
trusted pixels alone (:func:`map_samples`), and a mask's title states the statistics'
share, the Results table's number.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..acceptance.stats import format_limit, shared_limit
from ..io import preview
from . import figures as F

__all__ = ["MAP_PX", "MapSamples", "draw_overlays", "describe_clipping", "heatmap_axes", "map_samples", "overlay_legend",
           "run_figures"]

#: one figure of a run: (file stem, caption, PNG bytes)
Figure3 = tuple[str, str, bytes]

#: largest side (samples) of a map drawn: a photo up to this size is drawn pixel for pixel
MAP_PX = 1200


@dataclass(frozen=True)
class MapSamples:
    """The pixels a run's maps draw: every ``step``-th pixel of the photo's pixel grid, in both directions.

    Attributes
    ----------
    step : int
        Pixels between two samples (1: every pixel, for a photo up to :data:`MAP_PX` a side).
    fields : dict
        ``{field name: ndarray (h, w)}``: the pixel-grid fields at the samples, bit-identical
        to the result's (:meth:`~glassdist.analyzer.result.AnalysisResult.pixel_rows`).
    trusted : ndarray of bool, shape (h, w)
        Samples the statistics use (:func:`~glassdist.acceptance.zones.measured_region`): the
        only ones drawn in a colour scale.
    guard : ndarray of bool, shape (h, w)
        Samples measured but not trusted (the guard band), drawn grey.
    extent_px : (float, float, float, float)
        ``(left, right, bottom, top)`` of the samples' cells in pixel coordinates.
    """

    step: int
    fields: dict
    trusted: np.ndarray
    guard: np.ndarray
    extent_px: tuple


def map_samples(result, names, max_px=MAP_PX) -> MapSamples:
    """The fields ``names`` of ``result`` at every ``step``-th pixel (step: the least making each side <= ``max_px``).

    One pass over the pixel grid, by blocks of rows; at ``step`` 1 (a photo up to ``max_px`` a
    side) the maps draw every pixel the statistics are taken over, so a mask's share of red
    among its coloured pixels is the statistics' area share exactly.
    """
    from ..acceptance.zones import measured_region

    H, W = result.valid.shape
    k = max(1, -(-max(H, W) // int(max_px)))
    parts: dict = {n: [] for n in names}
    if names:
        for rows, block in result.pixel_rows(list(names)):
            first = (-(rows.start or 0)) % k
            for n, b in block.items():
                parts[n].append(np.asarray(b)[first::k, ::k])
    fields = {n: np.concatenate(v) for n, v in parts.items()}
    trusted = np.asarray(measured_region(result), bool)[::k, ::k]
    guard = np.asarray(result.valid, bool)[::k, ::k] & ~trusted
    h, w = trusted.shape
    return MapSamples(k, fields, trusted, guard, (-0.5, -0.5 + k * w, -0.5 + k * h, -0.5))


def _extent(samples, to_axes):
    """``imshow`` extent of the samples' cells in the maps' axes."""
    x0, x1, y1, y0 = samples.extent_px
    (ax0, ax1), (ay0, ay1) = (np.asarray(c, float) for c in to_axes(np.array([x0, x1]), np.array([y0, y1])))
    return float(ax0), float(ax1), float(ay1), float(ay0)


def overlay_legend(acceptance, channel) -> list:
    """Legend entries of the overlays :func:`draw_overlays` puts on ``channel``'s heatmap: zones, worst-region numbers."""
    from matplotlib.lines import Line2D

    handles = []
    for i, (name, m) in enumerate(acceptance.masks.items()):
        if m.any():
            handles.append(Line2D([], [], color=_ZONE_COLOURS[i % len(_ZONE_COLOURS)], linestyle="--",
                                  label=f"zone '{name}'"))
    entry = acceptance.regions.get(channel) or {}
    n = len(entry.get("regions", ()))
    if n:
        span = "1" if n == 1 else f"1-{n}"
        handles.append(Line2D([], [], linestyle="none", marker="$1$", color="black", markersize=6,
                              label=f"{span}: worst regions, |{channel}| > {entry['threshold_mD']:.4g} mD "
                                    f"({entry['threshold_source']}), 1 the highest peak (worst_regions.csv)"))
    return handles


def _heatmap(name, samples, v, chosen, axes, acceptance):
    """``(stem, caption, png)`` of one channel's heatmap, with the acceptance overlays (drawn when called)."""
    extent, to_axes, units, px_axis = axes
    _, label, cmap, signed = F.CHANNEL_STYLES[name]
    field = samples.fields[F.CHANNEL_STYLES[name][0]]
    legend = overlay_legend(acceptance, name) if acceptance is not None else []
    fig, ax = F.plot_channel(field, samples.trusted, signed=signed, vmax=v, cmap=cmap, title=f"{label}, mD",
                             extent=_extent(samples, to_axes), axis_units=units, px_axis=px_axis,
                             guard=samples.guard, legend=legend)
    span = f"[-{v:.3g}, {v:.3g}]" if signed else f"[0, {v:.3g}]"
    caption = f"{name} in mD; colour limits {span} mD" + ("." if chosen else " shared by both channels.")
    top = acceptance.stats.get(name, {}).get("max_abs") if acceptance is not None else None
    # the maximum and the clipped share over the trusted pixels, as the statistics
    clip = describe_clipping(field, samples.trusted, v, top)
    F.map_title(ax, f"{label}, mD\n{clip}", fontsize="medium")
    caption += f" {clip} (trusted pixels)."
    if acceptance is not None:
        draw_overlays(ax, acceptance, name, to_axes, extent)
        n = len(acceptance.regions.get(name, {}).get("regions", ()))
        caption += f" Axes in {units}. Dashed: zones; numbers: the {n} worst regions (worst_regions.csv)."
    return name, caption + (" Only the trusted pixels are in the colour scale: dark grey the guard band (measured, "
                            "not trusted), light grey not analysed."), F.figure_png(fig)


def _surface_figures(result, axes):
    """Jobs drawing, in reflection, the front face's height (µm) and slope magnitude (mrad) over the reported
    region, guard band included (the edge lift lies there: :mod:`glassdist.flatness`); none for a result
    without them."""
    if "surface_height_um" not in {f.name for f in result.field_specs()}:
        return []
    _, to_axes, units, px_axis = axes
    samples = map_samples(result, ["surface_height_um", "surface_slope_mrad"])
    shown = samples.trusted | samples.guard
    slope = np.hypot(*np.moveaxis(np.asarray(samples.fields["surface_slope_mrad"], float), -1, 0))

    def draw(stem, field, signed, unit, title, what) -> Figure3:
        v = shared_limit(field, valid=shown)
        fig, ax = F.plot_channel(field, shown, signed=signed, vmax=v, title=f"{title}, {unit}",
                                 extent=_extent(samples, to_axes), axis_units=units, px_axis=px_axis, colorbar=False)
        fig.colorbar(ax.images[0], ax=ax, label=unit, extend="both" if signed else "max")
        span = f"[-{v:.3g}, {v:.3g}]" if signed else f"[0, {v:.3g}]"
        return (stem, f"{what}, {unit} (glassdist.flatness; the measures are summary.json's flatness); colour "
                      f"limits {span} {unit}; over the reported region, guard band included (where the edge "
                      "lift lies).", F.figure_png(fig))

    return [(_COST["map"], functools.partial(draw, *args)) for args in (
        ("surface_height", samples.fields["surface_height_um"], True, "µm", "Surface height Z",
         "Front-face height Z (away from the camera), detrended at degree N"),
        ("surface_slope", slope, False, "mrad", "Surface slope |grad Z|",
         "Front-face slope magnitude |grad Z|, its trend of degree N - 1 removed"))]


def _quality_figures(result, samples, axes, max_px=900):
    """Jobs drawing the quality map (labels, reduced by striding to at most ``max_px`` a side) and the phi_eff
    uncertainty map.

    ``axes``: ``(extent, to_axes, units, px_axis)`` of every map (:func:`_map_axes`).
    """
    extent, to_axes, units, px_axis = axes
    held = {f.name for f in result.field_specs()}
    out = []
    if "quality" in held:
        q = np.asarray(result.quality)
        k = max(1, -(-max(q.shape) // max_px))
        labels, counts = q[::k, ::k], result.quality_counts()

        def quality() -> Figure3:
            fig, _ = F.plot_quality(labels, counts=counts, title="Quality labels", extent=extent, axis_units=units,
                                    px_axis=px_axis)
            return ("quality", "Quality map: every pixel's label (README, quality labels). Statistics, verdicts and "
                               "the maximum use label 0 only; label 6 is reported but not trusted.", F.figure_png(fig))
        out.append((_COST["quality"], quality))
    if "phi_eff_sigma_mD" in samples.fields:
        sig = samples.fields["phi_eff_sigma_mD"]
        floor = result.noise_floor()["phi_eff_sigma_mD"]["median"]

        def uncertainty() -> Figure3:
            fig, _ = F.plot_channel(sig, samples.trusted, signed=False, vmax=shared_limit(sig, valid=samples.trusted),
                                    cmap="magma", guard=samples.guard,
                                    title=f"standard uncertainty of $\\phi_{{eff}}$, mD\nnoise floor {floor:.3g} mD",
                                    extent=_extent(samples, to_axes), axis_units=units, px_axis=px_axis)
            return ("uncertainty", f"Standard uncertainty of phi_eff from the image noise (phi_eff_sigma_mD), mD; "
                                   f"noise floor (median over the trusted pixels) {floor:.3g} mD. Values of |phi_eff| "
                                   "within about 2 of it are not distinguishable from noise. Trusted pixels only.",
                    F.figure_png(fig))
        out.append((_COST["map"], uncertainty))
    return out


def _threshold_masks(samples, limits, stats, axes):
    """Jobs drawing one mask per limit of each power channel, titled with the statistics' share (the Results table's
    number)."""
    extent, to_axes, units, px_axis = axes

    def mask(name: str, field: np.ndarray, lim: float) -> Figure3:
        share = (stats.get(name) or {}).get(format_limit(lim))
        fig, ax = F.plot_threshold_mask(field, samples.trusted, limit_mD=lim, name=name,
                                        extent=_extent(samples, to_axes), axis_units=units, px_axis=px_axis,
                                        guard=samples.guard, share_percent=share)
        ax.set_xlim(extent[0], extent[1])
        ax.set_ylim(extent[2], extent[3])
        shown = ax.get_title().split(": ", 1)[-1]
        return (f"mask_{name}_{lim:g}mD", f"{name}: pixels with |{name}| > {lim:g} mD in red, {shown} "
                                          "(the Results table's share); greys: not judged.", F.figure_png(fig))

    return [(_COST["mask"], functools.partial(mask, name, samples.fields[F.CHANNEL_STYLES[name][0]], lim))
            for name, lims in limits.items() if name in F.CHANNEL_STYLES for lim in lims]


def run_figures(result, image=None, limits=None, *, heatmaps=True, acceptance=None, workers=None):
    """Render the figures of a run.

    Every map draws the pixel-grid fields at the samples of :func:`map_samples` (every pixel
    of a photo up to :data:`MAP_PX` a side), and only the trusted ones, the pixels the
    statistics use, in its colour scale; the guard band and the pixels not analysed are
    drawn in greys named in the legend. The threshold masks' titles state the statistics'
    area shares (the Results table's numbers).

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
        millimetre axes and the colour limits it chose, and the statistics whose
        shares the masks state (:mod:`glassdist.acceptance`).
    workers : int, optional
        Processes drawing the figures (:func:`draw_figures`); default :func:`figure_workers`.

    Returns
    -------
    list of (str, str, bytes)
        ``(file stem, caption, PNG bytes)`` in report order.
    """
    limits = limits or {}
    held = {f.name for f in result.field_specs()}
    names = ["phi_eff_mD", "phi_shear_mD"]
    names += [F.CHANNEL_STYLES[n][0] for n in limits if n in F.CHANNEL_STYLES and F.CHANNEL_STYLES[n][0] not in names]
    names += [n for n in ("axis_deg", "phi_eff_sigma_mD") if n in held and (heatmaps or n != "axis_deg")]
    samples = map_samples(result, [n for n in dict.fromkeys(names) if n in held])
    stats = acceptance.stats if acceptance is not None else {}
    eff, shear = samples.fields["phi_eff_mD"], samples.fields["phi_shear_mD"]
    jobs = []  # (relative cost, draw() -> (stem, caption, png)), in report order
    vmax = shared_limit(eff, shear, valid=samples.trusted)
    vmaxes = dict(acceptance.colour_limits) if acceptance is not None else {}
    axes = _map_axes(result, acceptance)
    extent, to_axes, units, px_axis = axes
    if image is not None:
        import cv2

        small = preview(image)
        region = cv2.resize(np.asarray(result.valid, np.uint8), small.shape[::-1], interpolation=cv2.INTER_NEAREST)

        def input_region() -> Figure3:
            fig, _ = F.plot_input(small, region.astype(bool), extent=extent, axis_units=units, px_axis=px_axis)
            return "input_region", "Input photograph; the analysed region is outlined in orange.", F.figure_png(fig)
        jobs.append((_COST["input"], input_region))
    for name in ("phi_eff", "phi_shear") if heatmaps else ():
        jobs.append((_COST["heatmap"], functools.partial(_heatmap, name, samples, vmaxes.get(name, vmax), bool(vmaxes),
                                                         axes, acceptance)))
    if heatmaps and "axis_deg" in samples.fields:
        def axis() -> Figure3:
            fig, _ = F.plot_axis(samples.fields["axis_deg"], shear, samples.trusted, extent=_extent(samples, to_axes),
                                 axis_units=units, px_axis=px_axis, guard=samples.guard)
            return ("axis", "Astigmatism axis (direction of largest stretch), degrees from +x towards +y (down), "
                            "over the trusted pixels; white where phi_shear is too small for the axis to be "
                            "meaningful.", F.figure_png(fig))
        jobs.append((_COST["axis"], axis))
    jobs += _quality_figures(result, samples, axes)
    jobs += _surface_figures(result, axes)
    jobs += _threshold_masks(samples, limits, stats, axes)

    def histograms() -> Figure3:
        fig = Figure(figsize=(10, 3.8))
        fig.subplots_adjust(left=0.09, right=0.98, bottom=0.14, top=0.9, wspace=0.3)
        for ax, name in zip(fig.subplots(1, 2), ("phi_eff", "phi_shear")):
            _, label, _, signed = F.CHANNEL_STYLES[name]
            F.plot_histogram(samples.fields[F.CHANNEL_STYLES[name][0]], samples.trusted, signed=signed,
                             limits_mD=limits.get(name, ()), ax=ax, title=label, weight=samples.step ** 2,
                             max_abs_mD=stats.get(name, {}).get("max_abs"))
        return ("histograms", "Histograms over the trusted pixels (quality label 0, the statistics' pixels"
                              + ("" if samples.step == 1 else f"; every {samples.step}th pixel, weighted by "
                                 f"{samples.step ** 2}") + "); axis range: the statistics' largest "
                              "|value| (or a specification limit beyond it, dashed red).", F.figure_png(fig))
    jobs.append((_COST["histograms"], histograms))
    return draw_figures(jobs, workers=figure_workers() if workers is None else workers)


#: relative drawing cost of each kind of figure (process time, 1 Mpx example): how jobs are shared between processes
_COST = {"input": 0.8, "heatmap": 1.0, "axis": 1.0, "map": 0.8, "quality": 0.35, "mask": 0.6, "histograms": 0.5}


def figure_workers() -> int:
    """Processes drawing a run's figures: 1, or 2 where ``GLASSDIST_FIGURE_WORKERS=2`` asks for it (Linux only).

    One process by default: a forked child shares the parent's open font files, and a font
    object made before the fork and used by both (matplotlib caches them, mathtext's parses
    among them) reads from one file offset in two processes, which fails at random under load
    ("FT_Load_Glyph failed"). The child drops the caches it knows of (:func:`_child_main`);
    the two-process path stays an explicit choice until no such cache is left.
    """
    import os
    import sys

    env = os.environ.get("GLASSDIST_FIGURE_WORKERS", "").strip()
    if env != "2" or not sys.platform.startswith("linux"):
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return 2 if cores >= 2 else 1


def draw_figures(jobs: list[tuple[float, Callable[[], Figure3]]], *, workers: int = 1) -> list[Figure3]:
    """Run the figure ``jobs`` (``(cost, draw)``, ``draw() -> (stem, caption, png)``); their results in job order.

    With ``workers`` 2, a forked child draws about half of them (by cost, the largest first,
    each to the process with less so far), the caller the rest, at once: the child has the
    caller's memory as it was (nothing is sent to it) and sends back only its PNG bytes.
    Both processes run the same code on the same arrays, so the bytes are those one process
    would draw (``test_report_figures``). Should the child fail or die, the caller draws its
    share itself: a run never loses a figure to the second process.
    """
    if workers < 2 or len(jobs) < 3:
        return [draw() for _, draw in jobs]
    order = sorted(range(len(jobs)), key=lambda i: -jobs[i][0])
    load, share = [0.0, 0.0], ([], [])  # type: tuple[list[float], tuple[list[int], list[int]]]
    for i in order:
        k = 0 if load[0] <= load[1] else 1
        share[k].append(i)
        load[k] += jobs[i][0]
    mine, theirs = sorted(share[0]), sorted(share[1])
    drawn_there, drawn_here = _draw_in_child([jobs[i][1] for i in theirs], lambda: [jobs[i][1]() for i in mine])
    done = {**dict(zip(theirs, drawn_there)), **dict(zip(mine, drawn_here))}
    return [done[i] for i in range(len(jobs))]


def _draw_in_child(draws: list[Callable[[], Figure3]],
                   in_parent: Callable[[], list[Figure3]]) -> tuple[list[Figure3], list[Figure3]]:
    """``draws`` run in a forked child while ``in_parent()`` runs here; the child's results (or, failing, ours)
    in order, followed by ``in_parent()``'s."""
    import multiprocessing
    import pickle

    from .._lazy import wait_background_imports

    wait_background_imports()  # a module lock held by a thread at the fork would be held for ever in the child
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    child: Any = ctx.Process(target=_child_main, args=(draws, send), daemon=True)
    try:
        child.start()
    except Exception:  # noqa: BLE001 - no second process here (none left, or a daemonic one's): drawn here
        child = None
    send.close()
    theirs = None
    try:
        ours = in_parent()
    finally:  # the child is waited for, even when a figure of ours failed
        if child is not None:
            try:
                theirs = pickle.loads(receive.recv_bytes())
            except (EOFError, OSError, pickle.UnpicklingError):
                theirs = None
            child.join()
            if child.exitcode != 0 or not isinstance(theirs, list) or len(theirs) != len(draws):
                theirs = None
        receive.close()
    if theirs is None:  # the child could not draw them: this process does
        theirs = [draw() for draw in draws]
    return theirs, ours


def _child_main(draws: list[Callable[[], Figure3]], send: Any) -> None:
    """The child's work: its figures' PNG bytes (None if one failed: the parent draws them) down ``send``; then it
    ends at once, flushing nothing the parent's streams held at the fork and running no exit handler of the parent's."""
    import os
    import pickle

    try:
        try:
            # font objects made before the fork read the parent's file offsets: this process opens its own
            from matplotlib import font_manager, mathtext

            font_manager._get_font.cache_clear()
            mathtext.MathTextParser._parse_cached.cache_clear()
            payload = pickle.dumps([draw() for draw in draws], protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException:  # noqa: BLE001 - the parent draws them
            payload = pickle.dumps(None)
        send.send_bytes(payload)
        send.close()
    finally:
        os._exit(0)


def _map_axes(result, acceptance):
    """``(extent, to_axes, units, px_axis)`` shared by every map: millimetres, and the photo's px along the top.

    The pane's (or the backdrop's) mm of the acceptance frame when there is one
    (:func:`heatmap_axes`), else backdrop mm from the photo's
    top-left corner (``mm_per_px``). ``px_axis`` = ``(scale, offset)`` with column px =
    scale * x_mm + offset (both frames are axis-aligned scalings of the pixel grid).
    """
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


#: samples (largest side) of the zone masks outlined on a map: about its drawn width (440 px), so an outline
#: is placed to within half a drawn pixel
_CONTOUR_PX = 512

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
    # contours of a decimated mask, at about the figure's own resolution (a map is drawn some 440 px wide)
    step = max(1, int(max(h, w) // _CONTOUR_PX))
    # both frames are axis-aligned scalings of the pixel grid: X depends on x alone, Y on y alone
    xs, ys = np.arange(0, w, step, dtype=float), np.arange(0, h, step, dtype=float)
    X = np.asarray(to_axes(xs, np.zeros_like(xs))[0], float)
    Y = np.asarray(to_axes(np.zeros_like(ys), ys)[1], float)
    for i, (name, m) in enumerate(acc.masks.items()):
        if not m.any():
            continue
        colour = _ZONE_COLOURS[i % len(_ZONE_COLOURS)]
        sub = m[::step, ::step].astype(np.float32)
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
    return f"max |phi| {top:.3g} mD; colours clipped at {vmax:.3g} mD ({share:.2g} % of the trusted region beyond)"
