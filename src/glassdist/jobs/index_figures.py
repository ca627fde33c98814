"""Figures of a batch index: heatmap thumbnails on one shared colour scale, and the per-lot trend.

* Thumbnails (``OUT/thumbs/<id>.png``): each pane's ``phi_eff`` without axes, at most
  :data:`THUMB_PX` px wide, all on the same diverging scale ``[-V, V]`` mD so that their
  colours compare across panes; ``V`` is the largest of the panes' 99th percentiles of
  ``|phi_eff|`` over their trusted samples (quality label 0: the guard band next to excluded
  areas, biased by the smoothing, does not set the scale; ``OUT/thumbs/colourbar.png`` shows it).
* Trend (``OUT/trend.png``): p95 ``|phi_eff|`` and p95 ``phi_shear`` of each analysed pane
  in batch order, grouped by lot (the manifest's ``lot`` column), PASS / FAIL / no
  verdict marked, with each lot's median.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

__all__ = ["THUMB_PX", "load_phi_eff", "write_thumbnails", "write_trend"]

logger = logging.getLogger(__name__)

#: largest side of a thumbnail, px
THUMB_PX = 160


def load_phi_eff(pane_dir):
    """``phi_eff`` (mD, NaN outside the analysed region) and its trusted samples from a pane's ``result.npz``.

    Reads either layout of ``result.npz`` (pixel grid with ``valid``, or analysis grid
    with ``grid_valid`` and pixel coordinates), subsampled to about :data:`THUMB_PX` px
    on its longer side. Trusted samples are those of quality label 0 (the pixel under an
    analysis-grid sample); a file without ``quality`` trusts its analysed region.

    Returns
    -------
    (ndarray, ndarray of bool) or None
    """
    path = Path(pane_dir) / "result.npz"
    try:
        with np.load(path, allow_pickle=False) as z:
            if "phi_eff_mD" not in z.files or z["phi_eff_mD"].ndim != 2:
                return None
            f = z["phi_eff_mD"]
            step = max(1, int(np.ceil(max(f.shape) / THUMB_PX)))
            sub = (slice(None, None, step), slice(None, None, step))
            f = np.asarray(f[sub], dtype=np.float64)
            for key in ("valid", "grid_valid"):
                if key in z.files and z[key].shape == z["phi_eff_mD"].shape:
                    f = np.where(z[key][sub], f, np.nan)
                    break
            return f, np.isfinite(f) & _trusted(z, sub, z["phi_eff_mD"].shape)
    except (OSError, ValueError, KeyError, IndexError):
        logger.warning("could not read %s for its thumbnail", path)
        return None


def _trusted(z, sub, shape):
    """Quality label 0 at the samples ``sub`` of a field of ``shape`` (all True without a quality map)."""
    if "quality" not in z.files:
        return True
    q = z["quality"]
    if q.shape == shape:
        return q[sub] == 0
    if "grid_rows_px" in z.files and "grid_cols_px" in z.files:
        rows = np.clip(np.rint(z["grid_rows_px"][sub[0]]).astype(int), 0, q.shape[0] - 1)
        cols = np.clip(np.rint(z["grid_cols_px"][sub[1]]).astype(int), 0, q.shape[1] - 1)
        return q[np.ix_(rows, cols)] == 0
    return True


def write_thumbnails(out, ids):
    """Write the thumbnails of the panes ``ids`` (those with a ``result.npz``) on one colour scale.

    Parameters
    ----------
    out : path
        The batch folder (``panes/<id>/result.npz`` are read).
    ids : sequence of str

    Returns
    -------
    thumbs : dict
        ``{id: path relative to out}`` of the thumbnails written.
    vmax : float or None
        The shared colour limit ``V``, mD (None without any thumbnail).
    """
    import matplotlib
    import matplotlib.image  # the submodule is not loaded by "import matplotlib" alone
    from matplotlib.colors import Normalize

    out = Path(out)
    loaded = {i: f for i in ids if (f := load_phi_eff(out / "panes" / i)) is not None}
    fields = {i: f for i, (f, _) in loaded.items()}
    if not fields:
        return {}, None
    # the scale from trusted samples only: the guard band next to excluded areas is biased
    trusted = [a for f, t in loaded.values() if (a := np.abs(f[t])).size]
    vmax = max((float(np.percentile(a, 99)) for a in trusted), default=0.0) or 1.0
    folder = out / "thumbs"
    folder.mkdir(exist_ok=True)
    cmap = matplotlib.colormaps["RdBu_r"].with_extremes(bad=(0.85, 0.85, 0.85, 1.0))
    norm = Normalize(-vmax, vmax)
    written = {}
    for i, f in fields.items():
        rgba = cmap(norm(np.ma.masked_invalid(f)))
        matplotlib.image.imsave(folder / f"{i}.png", rgba)
        written[i] = f"thumbs/{i}.png"
    _colourbar(folder / "colourbar.png", cmap, norm)
    return written, vmax


def _colourbar(path, cmap, norm):
    from matplotlib.cm import ScalarMappable
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.0, 0.9), layout="constrained")
    ax = fig.add_subplot()
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=ax, orientation="horizontal",
                 label="phi_eff, mD (every thumbnail)", extend="both")
    fig.savefig(path, dpi=100)


def write_trend(out, rows):
    """Write ``OUT/trend.png``: p95 of both channels per pane, grouped by lot.

    Parameters
    ----------
    out : path
    rows : list of dict
        Index rows (``id``, ``lot``, ``status``, ``verdict``, ``phi_eff_p95_abs_mD``,
        ``phi_shear_p95_abs_mD``).

    Returns
    -------
    str or None
        ``"trend.png"``, or None when no pane has statistics yet.
    """
    from matplotlib.figure import Figure

    done = [r for r in rows if r["status"] == "done" and r.get("phi_eff_p95_abs_mD") not in ("", None)]
    if not done:
        return None
    lots = list(dict.fromkeys(r.get("lot") or "" for r in done))
    order = sorted(done, key=lambda r: lots.index(r.get("lot") or ""))
    fig = Figure(figsize=(max(6.0, 0.35 * len(order) + 2), 3.8), layout="constrained")
    ax = fig.add_subplot()
    x = np.arange(len(order))
    colours = {"PASS": "tab:green", "FAIL": "tab:red"}
    for key, marker, label in (("phi_eff_p95_abs_mD", "o", "p95 |phi_eff|"),
                               ("phi_shear_p95_abs_mD", "s", "p95 phi_shear")):
        y = np.array([float(r[key]) if r.get(key) not in ("", None) else np.nan for r in order])
        c = [colours.get(r["verdict"], "tab:gray") for r in order]
        ax.scatter(x, y, marker=marker, c=c, zorder=3)
    start = 0
    for lot in lots:
        n = sum((r.get("lot") or "") == lot for r in order)
        y = [float(r["phi_eff_p95_abs_mD"]) for r in order[start:start + n]]
        ax.hlines(np.median(y), start - 0.4, start + n - 0.6, colors="tab:blue", linewidth=1.5, zorder=2)
        if len(lots) > 1:
            ax.axvline(start - 0.5, color="0.6", linewidth=0.8)
            ax.text(start + (n - 1) / 2, 1.01, lot or "(no lot)", transform=ax.get_xaxis_transform(), ha="center",
                    va="bottom", fontsize="small")
        start += n
    ax.set_xticks(x, [r["id"] for r in order], rotation=60, ha="right", fontsize="x-small")
    ax.set_ylabel("mD")
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.3", marker=m, linestyle="", label=t)
               for m, t in (("o", "p95 |phi_eff|"), ("s", "p95 phi_shear"))]
    handles += [Line2D([], [], color=c, marker="o", linestyle="", label=t)
                for c, t in (("tab:green", "PASS"), ("tab:red", "FAIL"), ("tab:gray", "no verdict"))]
    handles.append(Line2D([], [], color="tab:blue", label="lot median p95 |phi_eff|"))
    ax.legend(handles=handles, fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.savefig(Path(out) / "trend.png", dpi=100)
    return "trend.png"
