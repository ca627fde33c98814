"""A4 visual metrics: heatmaps, threshold masks and histograms of the power channels.

Every plot function takes arrays (or an analysis result), draws on ``ax`` (a new
figure when ``ax`` is None) and returns ``(fig, ax)``; nothing is shown on
screen (figures use the non-interactive Agg canvas). Images are drawn in pixel
coordinates, ``(row, col)`` with ``x`` along columns and ``y`` down the rows, as
the photograph was taken. Values are in millidiopters (mD). A map draws in its colour
scale only the pixels the statistics use (``valid``: the trusted ones); the others never
enter a colour limit and are drawn in greys named in the figure's legend: the guard band
(``guard``, measured but not trusted) in :data:`GUARD_RGBA`, every other pixel (excluded,
not analysed) in :data:`EXCLUDED_RGBA`.

Colour conventions
------------------
* ``phi_eff`` (signed): diverging map ``RdBu_r`` with symmetric limits ``[-V, V]``
  (blue: ``phi_eff < 0``, converging; red: diverging).
* ``phi_shear`` (non-negative): sequential map ``viridis`` on ``[0, V]``.
* astigmatism axis: cyclic map ``twilight`` on ``(-90, 90]`` degrees, drawn only
  where ``phi_shear`` is large enough for the axis to mean something.

The two channels share the same ``V`` (see :func:`glassdist.acceptance.stats.shared_limit`) so that their
colours compare directly.

References
----------
Paper §2.2, A4 (standardised heatmaps, threshold masks, statistical summaries).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from ..acceptance.stats import shared_limit

__all__ = [
    "CHANNEL_STYLES",
    "histogram_range",
    "plot_channel",
    "plot_axis",
    "plot_input",
    "plot_threshold_mask",
    "plot_histogram",
    "plot_quality",
    "save_channel_heatmaps",
    "save_figure",
    "figure_png",
    "add_legend",
    "EXCLUDED_RGBA",
    "GUARD_RGBA",
    "LOW_SHEAR_RGBA",
    "MASK_COLOURS",
]

logger = logging.getLogger(__name__)

#: channel name -> (result attribute, label, colour map, signed)
CHANNEL_STYLES = {
    "phi_eff": ("phi_eff_mD", r"$\phi_{eff}$ (sphere-equivalent power)", "RdBu_r", True),
    "phi_shear": ("phi_shear_mD", r"$\phi_{shear}$ (cylinder-equivalent astigmatism)", "viridis", False),
    "phi_total": ("phi_total_mD", r"$\phi_{total}$ (Frobenius norm)", "magma", False),
}

#: colour of the pixels not analysed (excluded, or outside the region); in no colour map used here
EXCLUDED_RGBA = (0.85, 0.85, 0.85, 1.0)
#: colour of the guard band: measured, not trusted, so outside every statistic and colour scale
GUARD_RGBA = (0.55, 0.55, 0.55, 1.0)
_INVALID_RGBA = EXCLUDED_RGBA

#: how the maps are drawn: each drawn pixel takes its nearest sample's value, colour-mapped once drawn (a map has
#: more samples than drawn pixels: colour-mapping every sample first cost twice as much, for the same picture)
_NEAREST = {"interpolation": "nearest", "interpolation_stage": "data"}

_GUARD_TEXT = "guard band (measured, not trusted)"
_EXCLUDED_TEXT = "excluded / not analysed"


def _untrusted_patches(valid, guard):
    """Legend patches of the greys a map shows: the guard band (where ``guard`` has a pixel) and the excluded pixels."""
    from matplotlib.patches import Patch

    handles = []
    if guard is not None and np.any(guard):
        handles.append(Patch(facecolor=GUARD_RGBA, edgecolor="0.3", label=_GUARD_TEXT))
    shown = np.ones(np.shape(valid), bool) if valid is None else np.asarray(valid, bool)
    if guard is not None:
        shown = shown | np.asarray(guard, bool)
    if not shown.all():
        handles.append(Patch(facecolor=EXCLUDED_RGBA, edgecolor="0.3", label=_EXCLUDED_TEXT))
    return handles


def _draw_guard(ax, guard, valid, extent):
    """Overlay the guard band (``guard & ~valid``) in :data:`GUARD_RGBA` on a map (a second image, transparent elsewhere)."""
    if guard is None:
        return
    g = np.asarray(guard, bool)
    if valid is not None:
        g = g & ~np.asarray(valid, bool)
    if not g.any():
        return
    rgba = np.zeros((*g.shape, 4), np.float32)
    rgba[g] = GUARD_RGBA
    ax.imshow(rgba, interpolation="nearest", extent=extent)


def add_legend(ax, handles, *, below=False):
    """Legend of a map: under the axes in a figure :func:`_map_ax` made room for, else inside the axes, lower right.

    Returns the legend (None without handles).
    """
    if not handles:
        return None
    if below:
        return ax.figure.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.01, 0.005),
                                fontsize="x-small", frameon=False, ncol=_legend_columns(handles), handlelength=1.2,
                                columnspacing=1.0)
    return ax.legend(handles=handles, loc="lower right", fontsize="x-small", framealpha=0.85)


def _legend_columns(handles) -> int:
    """Two columns of short legend entries, one of long ones."""
    return 2 if all(len(h.get_label()) <= 36 for h in handles) else 1


def count_legend_rows(handles) -> int:
    """Rows the legend of ``handles`` takes under a map (:func:`add_legend`)."""
    return -(-len(handles) // _legend_columns(handles)) if handles else 0


def _new_ax(ax, figsize=(6.4, 3.6)):
    """Return ``(fig, ax)``: ``ax``'s figure, or a new Agg figure with one axes (plots that are not maps)."""
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=figsize)
    fig.subplots_adjust(left=0.12, right=0.97, bottom=0.15, top=0.88)
    return fig, fig.add_subplot()


def _map_ax(ax, shape, extent=None, colorbar=True, px_axis=None, legend_rows=0):
    """``(fig, ax, cax)`` for a map of ``shape`` (h, w): ``ax``'s figure, or a new one sized to the map.

    The axes are placed by hand: a layout solver cost more than drawing the map. ``cax``
    is the colour bar's axes (None with ``ax`` given: matplotlib takes room from ``ax``).
    With ``px_axis`` the top margin holds the secondary pixel axis too; ``legend_rows`` rows
    of legend fit under the x axis label.
    """
    if ax is not None:
        return ax.figure, ax, None
    if extent is not None:
        aspect = abs(extent[2] - extent[3]) / max(abs(extent[1] - extent[0]), 1e-9)
    else:
        aspect = shape[0] / max(shape[1], 1)
    w_in = 4.4
    h_in = w_in * aspect
    if h_in > 5.0 or h_in < 1.2:  # very tall or very flat maps keep a readable size
        h_in = min(max(h_in, 1.2), 5.0)
        w_in = min(h_in / aspect, 7.0)
    left, bottom, top, right = 0.9, 0.6 + 0.2 * legend_rows, (1.25 if px_axis else 0.75), (1.4 if colorbar else 0.3)
    W, H = left + w_in + right, bottom + h_in + top
    fig = Figure(figsize=(W, H))
    ax = fig.add_axes((left / W, bottom / H, w_in / W, h_in / H))
    cax = fig.add_axes(((left + w_in + 0.2) / W, bottom / H, 0.18 / W, h_in / H)) if colorbar else None
    return fig, ax, cax


def _centres(shape, extent):
    """``(x, y)`` coordinates of the sample centres of an (h, w) map drawn with ``extent`` (default: indices)."""
    h, w = shape
    if extent is None:
        return np.arange(w), np.arange(h)
    return (extent[0] + (np.arange(w) + 0.5) * (extent[1] - extent[0]) / w,
            extent[3] + (np.arange(h) + 0.5) * (extent[2] - extent[3]) / h)


def _label_image_axes(ax, title, units="px", px_axis=None):
    """Axis labels in ``units``; with ``px_axis = (scale, offset)`` (column px = scale * x + offset) a
    secondary axis along the top in the photo's pixels."""
    ax.set_xlabel(f"x ({units}, columns)" if units == "px" else f"x ({units})")
    ax.set_ylabel(f"y ({units}, rows)" if units == "px" else f"y ({units})")
    if px_axis is not None:
        scale, offset = (float(v) for v in px_axis)
        sec = ax.secondary_xaxis("top", functions=(lambda x: scale * x + offset, lambda c: (c - offset) / scale))
        sec.set_xlabel("x (px, columns)", fontsize="small")
        sec.tick_params(labelsize="small")
        ax.glassdist_px_axis = True
    if title:
        map_title(ax, title)


def map_title(ax, text, **kwargs):
    """Set a map's title, above its secondary pixel axis when it has one.

    The position is given (``y`` = the axes' top, then ``pad`` points: 36 clear the secondary
    axis's small tick labels and label), so matplotlib does not search every artist's extent
    for it at each draw (over a second of a 24 Mpx run's figures).
    """
    ax.set_title(text, pad=36 if getattr(ax, "glassdist_px_axis", False) else 6, y=1.0, **kwargs)


def _masked(field, valid):
    field = np.asarray(field, dtype=np.float64)
    ok = np.isfinite(field)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool)
    return np.ma.masked_where(~ok, field), ok


def plot_channel(field, valid=None, *, signed=True, vmax=None, cmap=None, title=None, ax=None, colorbar=True,
                 extent=None, axis_units="px", px_axis=None, guard=None, legend=()):
    """Heatmap of one power channel, in mD, over the pixels the statistics use.

    Parameters
    ----------
    field : ndarray, shape (H, W)
        Channel in mD; NaN where invalid.
    valid : ndarray of bool, shape (H, W), optional
        Pixels drawn in the colour scale (the trusted ones); the others are grey.
    signed : bool
        True: diverging map, limits ``[-vmax, vmax]``; False: sequential, ``[0, vmax]``.
    vmax : float, optional
        Colour limit in mD; default :func:`shared_limit` of this field over ``valid``.
    cmap : str, optional
        Matplotlib colour-map name; default ``RdBu_r`` (signed) or ``viridis``.
    title : str, optional
    ax : matplotlib Axes, optional
    colorbar : bool
        Draw a colour bar labelled in mD.
    extent : (float, float, float, float), optional
        ``imshow`` extent (left, right, bottom, top) in ``axis_units`` (e.g. mm); default pixels.
    axis_units : str
        Label of the axes' unit.
    px_axis : (float, float), optional
        ``(scale, offset)``: column px = scale * x + offset; a secondary axis in the
        photo's pixels along the top (every map: mm below, px above).
    guard : ndarray of bool, shape (H, W), optional
        The guard band: drawn in :data:`GUARD_RGBA` (not in the colour scale), the other
        pixels outside ``valid`` in :data:`EXCLUDED_RGBA`; both named in the legend.
    legend : sequence of matplotlib artists
        More legend entries (e.g. the zones, what the numbers on the map are).

    Returns
    -------
    fig, ax
        ``ax.images[0]`` holds the values drawn (masked outside ``valid``), ``ax.images[1]``
        the guard band where there is one.
    """
    import matplotlib

    handles = [*_untrusted_patches(valid, guard), *legend]
    own = ax is None
    fig, ax, cax = _map_ax(ax, np.shape(field), extent, colorbar, px_axis, legend_rows=count_legend_rows(handles))
    data, _ = _masked(field, valid)
    if vmax is None:
        vmax = shared_limit(field, valid=valid)
    cmap_obj = matplotlib.colormaps[cmap or ("RdBu_r" if signed else "viridis")].with_extremes(bad=EXCLUDED_RGBA)
    norm = Normalize(-vmax, vmax) if signed else Normalize(0.0, vmax)
    im = ax.imshow(data, cmap=cmap_obj, norm=norm, **_NEAREST, extent=extent)
    _draw_guard(ax, guard, valid, extent)
    _label_image_axes(ax, title, axis_units, px_axis)
    if colorbar:
        fig.colorbar(im, ax=ax, cax=cax, label="mD", extend="both" if signed else "max", shrink=1.0 if cax else 0.9)
    add_legend(ax, handles, below=own)
    return fig, ax


#: Colours of the quality labels (``glassdist.analyzer.QUALITY_LABELS``), in label order:
#: analysed green; guard band a paler green (reported, not trusted); the exclusions in distinct hues.
QUALITY_COLOURS = ("#1b9e77", "#7f7f7f", "#e7298a", "#d95f02", "#7570b3", "#d9d9d9", "#b8e0c8", "#e6ab02")


def plot_quality(labels, *, counts=None, title=None, ax=None, extent=None, axis_units="px", px_axis=None):
    """Quality map: each pixel's label, in categorical colours with a legend naming each label.

    Parameters
    ----------
    labels : ndarray of uint8, shape (H, W)
        Quality labels 0-7 (:data:`glassdist.analyzer.QUALITY_LABELS`); any size (a
        reduced map is drawn as it is).
    counts : dict, optional
        ``{label name: pixels}`` of the whole map (the result's ``quality_counts``): each
        legend entry then gives its share; labels with no pixel are left out of the legend.
    title : str, optional
    ax : matplotlib Axes, optional
    extent : (float, float, float, float), optional
        ``imshow`` extent in ``axis_units``; default pixels.
    axis_units : str

    Returns
    -------
    fig, ax
    """
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    from ..analyzer import QUALITY_LABELS

    own = ax is None
    fig, ax, _ = _map_ax(ax, np.shape(labels), extent, colorbar=False, px_axis=px_axis)
    if own:  # room on the right for the legend: widen the figure, keep the map's size in inches
        W, H = fig.get_size_inches()
        extra = 2.8
        pos = ax.get_position()
        fig.set_size_inches(W + extra, H)
        ax.set_position((pos.x0 * W / (W + extra), pos.y0, pos.width * W / (W + extra), pos.height))
    n = len(QUALITY_LABELS)
    cmap = ListedColormap(QUALITY_COLOURS[:n])
    ax.imshow(np.asarray(labels), cmap=cmap, norm=BoundaryNorm(np.arange(n + 1) - 0.5, n), **_NEAREST,
              extent=extent)
    _label_image_axes(ax, title, axis_units, px_axis)
    total = sum(counts.values()) if counts else 0
    handles = []
    for k, name in QUALITY_LABELS.items():
        c = counts.get(name, 0) if counts else None
        if counts and not c:
            continue
        text = f"{k}: {name}" + (f" ({100.0 * c / total:.1f} %)" if counts else "")
        handles.append(Patch(facecolor=QUALITY_COLOURS[k], edgecolor="0.3", label=text))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="x-small", frameon=False)
    return fig, ax


#: colour of the trusted pixels whose astigmatism is too small for an axis (twilight never reaches white)
LOW_SHEAR_RGBA = (1.0, 1.0, 1.0, 1.0)


def plot_axis(axis_deg, phi_shear, valid=None, *, min_shear_mD=None, title=None, ax=None, colorbar=True, extent=None,
              axis_units="px", px_axis=None, guard=None):
    """Principal axis of the astigmatism (direction of largest stretch), degrees.

    Parameters
    ----------
    axis_deg : ndarray, shape (H, W)
        Axis in degrees in (-90, 90], from +x (columns) towards +y (rows, down).
    phi_shear : ndarray, shape (H, W)
        Astigmatism in mD; the axis is drawn only where ``phi_shear >= min_shear_mD``.
    valid : ndarray of bool, shape (H, W), optional
        Pixels drawn (the trusted ones); the others grey, as :func:`plot_channel`.
    min_shear_mD : float, optional
        Below this the axis is undefined in practice and is drawn white; default
        10 % of the 95th percentile of ``phi_shear`` over ``valid``.
    title : str, optional
    ax : matplotlib Axes, optional
    colorbar : bool
    guard : ndarray of bool, shape (H, W), optional
        The guard band (see :func:`plot_channel`).

    Returns
    -------
    fig, ax
    """
    import matplotlib
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=LOW_SHEAR_RGBA, edgecolor="0.3", label="phi_shear too small for an axis"),
               *_untrusted_patches(valid, guard)]
    own = ax is None
    fig, ax, cax = _map_ax(ax, np.shape(axis_deg), extent, colorbar, px_axis, legend_rows=count_legend_rows(handles))
    _, ok = _masked(phi_shear, valid)
    if min_shear_mD is None:
        min_shear_mD = 0.1 * float(np.percentile(np.asarray(phi_shear)[ok], 95)) if ok.any() else 0.0
    ok &= np.isfinite(axis_deg)
    show = ok & (np.nan_to_num(np.asarray(phi_shear), nan=-1.0) >= min_shear_mD)
    # under the axis colours: 0 excluded (grey), 1 too little shear (white), 2 drawn over by the axis image
    low = np.where(ok, np.where(show, 2, 1), 0).astype(np.uint8)
    ax.imshow(low, cmap=ListedColormap([EXCLUDED_RGBA, LOW_SHEAR_RGBA, LOW_SHEAR_RGBA]), norm=Normalize(-0.5, 2.5),
              **_NEAREST, extent=extent)
    data = np.ma.masked_where(~show, np.asarray(axis_deg, dtype=np.float64))
    cmap_obj = matplotlib.colormaps["twilight"].with_extremes(bad=(0, 0, 0, 0))
    im = ax.imshow(data, cmap=cmap_obj, norm=Normalize(-90.0, 90.0), **_NEAREST, extent=extent)
    _draw_guard(ax, guard, valid, extent)
    _label_image_axes(ax, title or f"astigmatism axis (where $\\phi_{{shear}}$ ≥ {min_shear_mD:.3g} mD)", axis_units,
                      px_axis)
    if colorbar:
        cb = fig.colorbar(im, ax=ax, cax=cax, label="axis (deg from +x towards +y, down)", shrink=1.0 if cax else 0.9)
        cb.set_ticks([-90, -45, 0, 45, 90])
    add_legend(ax, handles, below=own)
    return fig, ax


def plot_input(image, valid=None, *, title=None, ax=None, extent=None, axis_units="px", px_axis=None):
    """The input photograph (grey, its own intensities) with the analysed region outlined.

    Parameters
    ----------
    image : ndarray, shape (H, W)
        Grey image in [0, 1].
    valid : ndarray of bool, shape (H, W), optional
        Analysed region; its boundary is drawn in orange.
    title : str, optional
    ax : matplotlib Axes, optional

    Returns
    -------
    fig, ax
    """
    fig, ax, _ = _map_ax(ax, np.shape(image), extent, colorbar=False, px_axis=px_axis)
    ax.imshow(np.asarray(image, dtype=np.float64), cmap="gray", vmin=0.0, vmax=1.0, **_NEAREST,
              extent=extent)
    if valid is not None and np.any(valid):
        v = np.asarray(valid, dtype=float)
        ax.contour(*_centres(v.shape, extent), v, levels=[0.5], colors=["tab:orange"], linewidths=1.5)
    _label_image_axes(ax, title or "input with analysed region (orange)", axis_units, px_axis)
    return fig, ax


#: colours of a threshold mask: under the limit, over it
MASK_COLOURS = ("white", "tab:red")


def plot_threshold_mask(field, valid=None, *, limit_mD, absolute=True, name="φ", title=None, ax=None, extent=None,
                        axis_units="px", px_axis=None, guard=None, share_percent=None):
    """Pixels over a limit: red over the limit, white under it, greys outside the trusted region (named in the legend).

    Parameters
    ----------
    field : ndarray, shape (H, W)
        Channel in mD.
    valid : ndarray of bool, shape (H, W), optional
        The pixels judged (the trusted ones, those of the statistics).
    limit_mD : float
        Threshold in mD; a pixel is over when ``|field| > limit_mD`` (``absolute``)
        or ``field > limit_mD``.
    absolute : bool
    name : str
        Channel name used in the default title.
    title : str, optional
    ax : matplotlib Axes, optional
    guard : ndarray of bool, shape (H, W), optional
        The guard band (see :func:`plot_channel`).
    share_percent : float, optional
        The share over the limit the title states: the statistics' ``area_over`` (the
        Results table's number, computed over every trusted pixel); default the share of
        the pixels drawn, the same number when they are all of them.

    Returns
    -------
    fig, ax
        ``ax.images[0]`` holds the mask drawn (1 over, 0 under, masked outside ``valid``).
    """
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    op = f"|{name}|" if absolute else name
    handles = [Patch(facecolor=MASK_COLOURS[1], edgecolor="0.3", label=f"{op} > {limit_mD:g} mD"),
               Patch(facecolor=MASK_COLOURS[0], edgecolor="0.3", label=f"{op} ≤ {limit_mD:g} mD"),
               *_untrusted_patches(valid, guard)]
    own = ax is None
    fig, ax, _ = _map_ax(ax, np.shape(field), extent, colorbar=False, px_axis=px_axis,
                         legend_rows=count_legend_rows(handles))
    _, ok = _masked(field, valid)
    values = np.abs(np.asarray(field)) if absolute else np.asarray(field)
    over = ok & (np.nan_to_num(values, nan=-np.inf) > limit_mD)
    img = np.ma.masked_where(~ok, over.astype(float))
    cmap_obj = ListedColormap(list(MASK_COLOURS)).with_extremes(bad=EXCLUDED_RGBA)
    ax.imshow(img, cmap=cmap_obj, vmin=0, vmax=1, **_NEAREST, extent=extent)
    _draw_guard(ax, guard, valid, extent)
    frac = 100.0 * over.sum() / max(int(ok.sum()), 1) if share_percent is None else float(share_percent)
    _label_image_axes(ax, title or f"{op} > {limit_mD:g} mD: {frac:.4g} % of the trusted region", axis_units, px_axis)
    add_legend(ax, handles, below=own)
    return fig, ax


def histogram_range(max_abs_mD, *, signed=True, limits_mD=()) -> tuple[float, float]:
    """The histogram's axis range: the statistics' range of the channel, widened to show every limit.

    ``[-M, M]`` for a signed channel, ``[0, M]`` otherwise, with ``M`` the maximum |φ| over
    the trusted pixels (the statistics' ``max_abs``), or 1.1 times the largest limit when
    that is larger (so that its line is drawn); 1 mD when nothing is known.
    """
    known = max_abs_mD is not None and np.isfinite(max_abs_mD)  # NaN / None: no pixel is trusted
    top = max([float(max_abs_mD) if known else 0.0] + [1.1 * float(x) for x in limits_mD]) or 1.0
    return (-top if signed else 0.0), top


def plot_histogram(field, valid=None, *, signed=True, limits_mD=(), bins=80, title=None, ax=None, weight=1.0,
                   max_abs_mD=None):
    """Histogram of a channel over the trusted region, on the statistics' range, with optional limit lines.

    Parameters
    ----------
    field : ndarray, shape (H, W)
        Channel in mD.
    valid : ndarray of bool, shape (H, W), optional
        The pixels the statistics are over (the trusted ones): the same pixels, so that the
        histogram and the statistics describe one set of values.
    signed : bool
        Signed channels get mirror lines at ``±limit``.
    limits_mD : sequence of float
        Limits drawn as dashed red vertical lines, mD.
    bins : int
    title : str, optional
    ax : matplotlib Axes, optional
    weight : float
        Pixels each value stands for (an analysis-grid sample: its cell area, px), so that
        the counts read in pixels.
    max_abs_mD : float, optional
        The statistics' maximum |φ| over those pixels (:func:`histogram_range`); default
        the largest |value| drawn.

    Returns
    -------
    fig, ax
    """
    fig, ax = _new_ax(ax, figsize=(6.4, 3.6))
    _, ok = _masked(field, valid)
    values = np.asarray(field, dtype=np.float64)[ok]
    if max_abs_mD is None and values.size:
        max_abs_mD = float(np.max(np.abs(values)))
    lo, top = histogram_range(max_abs_mD, signed=signed, limits_mD=limits_mD)
    if values.size:
        # one filled outline, not a patch per bin: the same pixels, 0.014 s instead of 0.10 s per histogram
        counts, edges = np.histogram(np.clip(values, lo, top), bins=bins, range=(lo, top))
        ax.stairs(counts * float(weight), edges, fill=True, color="tab:blue" if signed else "tab:green", alpha=0.85)
    for lim in limits_mD:
        for v in ((-lim, lim) if signed else (lim,)):
            ax.axvline(v, color="tab:red", linestyle="--", linewidth=1.2)
    ax.set_xlim(lo, top)
    ax.set_xlabel("mD")
    ax.set_ylabel("pixels")
    if title:
        ax.set_title(title, y=1.0)  # given: no search of the artists' extents at each draw
    return fig, ax


#: zlib level of the PNGs written: 3 encodes the maps in about 60 % of the default level's (6) time, files 1 % larger
PNG_COMPRESS_LEVEL = 3


def save_figure(fig, path):
    """Write ``fig`` as a PNG (100 dpi) and return the path."""
    path = Path(path)
    fig.savefig(path, dpi=100, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return path


def figure_png(fig, *, dpi=100):
    """``fig`` encoded as PNG bytes (for embedding or writing)."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buf.getvalue()


def save_channel_heatmaps(result, out_dir, *, vmax=None):
    """Write the standard heatmaps of an analysis result as PNG files.

    Parameters
    ----------
    result : AnalysisResult
        Needs ``phi_eff_mD``, ``phi_shear_mD``, ``valid``; ``axis_deg`` and
        ``method`` are used when present.
    out_dir : path
        Existing folder; files ``phi_eff.png``, ``phi_shear.png`` and
        ``axis.png`` are written there.
    vmax : float, optional
        Shared colour limit in mD (e.g. fixed across a batch); default
        :func:`shared_limit` of the two channels.

    Returns
    -------
    list of Path
        The files written.
    """
    from ..acceptance.zones import measured_region

    out_dir = Path(out_dir)
    valid = measured_region(result)  # the statistics' pixels: the guard band is grey, not in the colour scale
    guard = np.asarray(result.valid, dtype=bool) & ~valid
    if vmax is None:
        vmax = shared_limit(result.phi_eff_mD, result.phi_shear_mD, valid=valid)
    method = result.method
    written = []
    for name in ("phi_eff", "phi_shear"):
        attr, label, cmap, signed = CHANNEL_STYLES[name]
        fig, _ = plot_channel(
            getattr(result, attr), valid, signed=signed, vmax=vmax, cmap=cmap, guard=guard,
            title=f"{label}\n{method} method, mD" if method else f"{label}, mD",
        )
        written.append(save_figure(fig, out_dir / f"{name}.png"))
    if any(f.name == "axis_deg" for f in result.field_specs()):
        fig, _ = plot_axis(result.axis_deg, result.phi_shear_mD, valid, guard=guard)
        written.append(save_figure(fig, out_dir / "axis.png"))
    logger.debug("heatmaps written: %s", ", ".join(p.name for p in written))
    return written
