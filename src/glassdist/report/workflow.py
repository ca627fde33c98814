"""The industrial workflow after an analysis: statistics, verdict, A4 figures, report, exports.

:func:`finish_analysis` is what ``glassdist analyze`` runs once ``result.npz`` and
``summary.json`` are written. Exit codes (also those of ``glassdist analyze``):

==========  ====================================================================
``0``       analysis done; no specification, or every criterion passed
``2``       bad input (one-line error, e.g. an invalid specification file)
``3``       analysis done, specification FAILED (:data:`EXIT_SPEC_FAIL`)
==========  ====================================================================

Files added to the output folder:

* ``statistics.csv``: per-channel statistics (always);
* ``input_region.png``: the input with the analysed region outlined;
  ``histograms.png``; ``mask_<channel>_<T>mD.png`` for each limit of the
  specification (pixels over the limit);
* ``report.html`` with ``report=True``: self-contained report (:mod:`glassdist.report.html`);
* ``fields.npz`` and ``tiff/*.tif`` with ``exports=True`` (:mod:`glassdist.report.exports`);
* ``summary.json`` gains ``verdict`` (``null`` without a specification), ``a4``
  (statistics with the area-over values, analysed-area percentage, files
  written, input file names and SHA-256) and ``outputs`` (every file of the run,
  the caller's included, with its size; see :func:`glassdist.io.recorded_outputs`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import sys
from pathlib import Path

from .exports import atomic_write_bytes, atomic_write_text, to_jsonable, write_fields_npz, write_fields_tiff
from .exports import write_statistics_csv
from .spec import load_spec, spec_limits
from .stats import valid_percent

__all__ = ["EXIT_OK", "EXIT_SPEC_FAIL", "finish_analysis", "file_sha256", "a4_figures"]

logger = logging.getLogger(__name__)

EXIT_OK = 0
#: exit status of ``glassdist analyze --spec`` when the analysis ran but the specification failed
EXIT_SPEC_FAIL = 3


def file_sha256(path):
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _describe_input(path, shape):
    if path is None:
        return None
    path = Path(path)
    return {"name": path.name, "path": str(path), "sha256": file_sha256(path), "size": f"{shape[1]} x {shape[0]} px"}


def a4_figures(result, image=None, limits=None, *, heatmaps=True, acceptance=None):
    """Render the A4 figures of a result.

    Parameters
    ----------
    result : AnalysisResult
    image : ndarray, shape (H, W), optional
        The analysed photograph (grey, [0, 1]) for the region outline.
    limits : dict, optional
        ``{channel: [limit_mD, ...]}``: a threshold mask per limit, and limit lines
        on the histograms.
    heatmaps : bool
        Include the channel and axis heatmaps (ids ``phi_eff``, ``phi_shear``, ``axis``).
    acceptance : Acceptance, optional
        Zones and numbered worst regions drawn on the heatmaps, which then have
        millimetre axes and the colour limits it chose
        (:mod:`glassdist.report.acceptance`).

    Returns
    -------
    list of (str, str, bytes)
        ``(file stem, caption, PNG bytes)`` in report order.
    """
    from matplotlib.figure import Figure

    from . import figures as F
    from .acceptance import describe_clipping, draw_overlays, heatmap_axes

    limits = limits or {}
    valid = result.valid
    out = []
    vmax = F.shared_limit(result.phi_eff_mD, result.phi_shear_mD, valid=valid)
    vmaxes = dict(acceptance.colour_limits) if acceptance is not None else {}
    extent, to_axes, units = (None, None, "px")
    if acceptance is not None:
        extent, to_axes, units = heatmap_axes(acceptance.frame, result.mm_per_px, valid.shape)
    if image is not None:
        fig, _ = F.plot_input(image, valid)
        out.append(("input_region", "Input photograph; the analysed region is outlined in orange.", F.figure_png(fig)))
    for name in ("phi_eff", "phi_shear") if heatmaps else ():
        attr, label, cmap, signed = F.CHANNELS[name]
        v = vmaxes.get(name, vmax)
        field = getattr(result, attr)
        fig, ax = F.plot_channel(field, valid, signed=signed, vmax=v, cmap=cmap, title=f"{label}, mD",
                                 extent=extent, axis_units=units)
        span = f"[-{v:.3g}, {v:.3g}]" if signed else f"[0, {v:.3g}]"
        caption = f"{name} in mD; colour limits {span} mD"
        caption += "." if vmaxes else " shared by both channels."
        if acceptance is not None:
            draw_overlays(ax, acceptance, name, to_axes, extent)
            ax.set_title(f"{label}, mD\n{describe_clipping(field, valid, v)}", fontsize="medium")
            n = len(acceptance.regions.get(name, {}).get("regions", ()))
            caption += (f" Axes in {units}. {describe_clipping(field, valid, v)}. Dashed: zones; numbers: the "
                        f"{n} worst regions (worst_regions.csv).")
        out.append((name, caption + " Grey: not analysed.", F.figure_png(fig)))
    if heatmaps and getattr(result, "axis_deg", None) is not None:
        fig, _ = F.plot_axis(result.axis_deg, result.phi_shear_mD, valid)
        out.append(("axis", "Astigmatism axis (direction of largest stretch), degrees from +x towards +y (down); "
                            "grey where phi_shear is too small for the axis to be meaningful.", F.figure_png(fig)))
    for name, lims in limits.items():
        attr = F.CHANNELS[name][0]
        for lim in lims:
            fig, _ = F.plot_threshold_mask(getattr(result, attr), valid, limit_mD=lim, name=name)
            out.append((f"mask_{name}_{lim:g}mD", f"{name}: pixels with |{name}| > {lim:g} mD in red.",
                        F.figure_png(fig)))
    fig = Figure(figsize=(10, 3.6), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, name in zip(axes, ("phi_eff", "phi_shear")):
        attr, label, _, signed = F.CHANNELS[name]
        F.plot_histogram(getattr(result, attr), valid, signed=signed, limits_mD=limits.get(name, ()), ax=ax,
                         title=label)
    out.append(("histograms", "Histograms over the analysed region; dashed red: specification limits.",
                F.figure_png(fig)))
    return out


def _update_summary(path, additions):
    summary = {}
    if path.is_file():
        try:
            summary = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            logger.warning("could not read %s; writing a new one", path)
            summary = {}
    summary.update(additions)
    atomic_write_text(path, json.dumps(to_jsonable(summary), indent=2, allow_nan=False) + "\n")


def finish_analysis(result, *, out_dir, image_path, reference_path=None, spec_path=None, report=False,
                    exports=False, written=(), echo=print, protocol=None, mask=None, metadata=None, spec=None):
    """Statistics, verdict, zones, worst regions, A4 figures, report and exports of an analysis.

    Parameters
    ----------
    result : AnalysisResult
    out_dir : path
        Existing output folder (holds ``summary.json`` if the caller wrote one).
    image_path : path
        The analysed photograph (hashed, and drawn with the region outline).
    reference_path : path, optional
        The glass-less reference (Comparative method), hashed.
    spec_path : path, optional
        Acceptance specification JSON (:mod:`glassdist.report.spec`).
    report : bool
        Write ``report.html``.
    exports : bool
        Write ``fields.npz`` and ``tiff/``.
    written : sequence of path
        Files the caller already wrote into ``out_dir`` for this analysis (``result.npz``);
        listed with this function's own in ``summary.json`` ``"outputs"``.
    echo : callable
        Receives the user-facing lines (verdict, files); default ``print``.
    protocol : ResolvedProtocol, optional
        The settings resolved from the options and the specification (recorded).
    mask : ndarray of bool, optional
        The user's region to analyse (coverage is of it).
    metadata : dict, optional
        ``pane_id``, ``site``, ``operator`` for the report.
    spec : (Spec, str), optional
        The specification already loaded from ``spec_path`` and its SHA-256.

    Returns
    -------
    int
        :data:`EXIT_OK` or :data:`EXIT_SPEC_FAIL`.

    Raises
    ------
    InputError
        Invalid specification file, or a capture outside its protocol's limits.
    """
    from ..io import output_record, read_image
    from .acceptance import assess
    from .html import render_report

    out_dir = Path(out_dir)
    if spec is None:
        spec = load_spec(spec_path) if spec_path is not None else (None, "")
    spec, spec_sha = spec
    limits = spec_limits(spec) if spec is not None else {}
    acc = assess(result, spec, spec_path=spec_path or "", spec_sha256=spec_sha, protocol=protocol, mask=mask,
                 metadata=metadata, image_path=image_path)
    stats, verdict = acc.stats, acc.verdict
    shape = result.valid.shape
    inputs = {"image": _describe_input(image_path, shape), "reference": _describe_input(reference_path, shape)}
    cover = valid_percent(result.valid)

    caller_written = list(written)
    written = [write_statistics_csv(stats, out_dir / "statistics.csv"),
               atomic_write_text(out_dir / "worst_regions.csv", acc.regions_csv())]
    figs = a4_figures(result, read_image(image_path), limits, heatmaps=True, acceptance=acc)
    for stem, _, png in figs:
        written.append(atomic_write_bytes(out_dir / f"{stem}.png", png))
    if exports:
        written.append(write_fields_npz(result, out_dir / "fields.npz"))
        written.extend(write_fields_tiff(result, out_dir / "tiff"))
    if report:
        html = render_report(result, stats=stats, figures=figs, inputs=inputs, verdict=verdict, valid_percent=cover,
                             acceptance=acc)
        written.append(atomic_write_text(out_dir / "report.html", html))
    names = [str(p.relative_to(out_dir)) for p in written]
    _update_summary(out_dir / "summary.json", {
        "verdict": verdict.to_dict() if verdict else None,
        "a4": {"statistics": stats, "valid_percent": cover, "files": names, "inputs": inputs},
        **acc.summary(),
        "outputs": output_record(out_dir, caller_written + written),
    })
    for w in acc.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if verdict is not None:
        for line in verdict.lines():
            echo(line)
    for name, z in acc.zones.items():
        s = z["statistics"].get("phi_eff", {})
        echo(f"zone {name}: {z['coverage_percent']:.1f} % analysed, p95 |phi_eff| {s.get('p95_abs', float('nan')):.4g} mD, "
             f"p95 |phi_shear| {z['statistics'].get('phi_shear', {}).get('p95_abs', float('nan')):.4g} mD")
    if report:
        echo(f"report: {out_dir / 'report.html'}")
    logger.info("A4 outputs written to %s: %s", out_dir, ", ".join(names))
    return EXIT_SPEC_FAIL if verdict is not None and not verdict.passed else EXIT_OK
