"""Self-contained HTML report of one analysis (images embedded, no external resource).

The report is meant to be attached to an acceptance record or a dispute file: it
states what was measured (input file and its SHA-256, capture geometry, method,
parameters, glassdist version), what came out (statistics, heatmaps, threshold
masks, histograms) and, when a specification was given, the verdict per criterion.
A machine-readable copy of the key facts is embedded as JSON in
``<script type="application/json" id="glassdist-report-data">``.

References
----------
Paper §2.2 (A4), §4.1-4.3.
"""

from __future__ import annotations

import base64
import json
import math
from datetime import datetime, timezone
from html import escape

import numpy as np

from ..acceptance.stats import STATISTICS
from ..io import to_jsonable

__all__ = ["render_report", "METHOD_TEXT", "measures_rows", "metadata_rows", "resolved_parameters"]

METHOD_TEXT = {
    "comparative": (
        "Comparative method: a photograph of the same printed grid without the glass (the reference) "
        "supplies the carrier phase; the displacement of the grid seen through the pane is measured against "
        "it by Fourier demodulation and phase unwrapping (paper §2.2, blocks F and A). This is the factory-line "
        "configuration (§4.1)."
    ),
    "direct": (
        "Direct method: no glass-less reference exists, so the projective view of the grid (homography) is "
        "inferred from the photograph itself by a robust fit, and a synthetic reference is built from it "
        "(paper §2.2, block I). This is the in-situ configuration (§4.3); the fit can absorb a small part of "
        "slow distortion, so values can differ from a Comparative measurement of the same pane by a few "
        "per cent."
    ),
}

_CONVENTIONS = (
    "Displacement δ: landing point of a line of sight on the grid with the glass minus without it, mm on the grid "
    "plane; x along image columns, y down the rows. Slow trends are removed by a polynomial of the stated degree "
    "before differentiation, so the channels describe local distortion (ripples, localised defects), not bulk "
    "curvature. φ_eff = tr(ε)/L (area change; negative for a converging lens), φ_shear = 2·max shear/L (shape "
    "change, ≥ 0), with ε = sym(∇δ) and L the glass-to-grid distance; values in millidiopters (mD). The "
    "astigmatism axis is the direction of largest stretch, degrees from +x towards +y. Statistics are taken over "
    "the trusted pixels only (quality label 0: analysed, outside the guard band); area percentages are of them, "
    "and the maps draw them alone in their colour scales."
)

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,Arial,sans-serif;margin:2em auto;max-width:1100px;
color:#1d1d1f;line-height:1.4;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}
th{background:#f2f2f2}td.num{text-align:right;font-variant-numeric:tabular-nums}
.verdict{font-size:1.5em;font-weight:bold;padding:.5em 1em;border-radius:6px;display:inline-block;margin:.5em 0}
.PASS{background:#d8f3dc;color:#1b5e20}.FAIL{background:#ffd7d5;color:#b71c1c}.NONE{background:#eee;color:#444}
tr.FAIL td{background:#fff0ef}tr.PASS td{background:#f3fbf4}
.figs{display:grid;grid-template-columns:repeat(auto-fill,minmax(460px,1fr));gap:1em;align-items:start}
figure{margin:0}figure img{width:100%}figure.wide{grid-column:1/-1}figure.wide img{max-width:1000px}
figcaption{font-size:.9em;color:#555}code,.mono{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.92em}
.warn{background:#fff8e1;border-left:4px solid #f9a825;padding:.3em .8em}
.small{font-size:.9em;color:#555}
"""


def _num(v, digits=4):
    if v is None:
        return "—"
    if isinstance(v, (float, np.floating)):
        return "—" if math.isnan(v) else f"{float(v):.{digits}g}"
    return escape(str(v))


def _kv_table(rows):
    body = "".join(f"<tr><th>{escape(k)}</th><td>{v}</td></tr>" for k, v in rows)
    return f"<table>{body}</table>"


def _img(png, alt, caption):
    data = base64.b64encode(png).decode("ascii")
    cls = ' class="wide"' if alt == "histograms" else ""
    return (f'<figure{cls}><img alt="{escape(alt)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def _stats_table(stats):
    area_keys = sorted({k for s in stats.values() for k in s if k.startswith("area_over_")},
                       key=lambda k: float(k.removeprefix("area_over_")))
    head = "".join(f"<th>{escape(k)} (mD)</th>" for k in STATISTICS)
    head += "".join(f"<th>|φ| &gt; {escape(k.removeprefix('area_over_'))} mD (% of the trusted region)</th>" for k in area_keys)
    rows = ""
    for ch, s in stats.items():
        cells = "".join(f'<td class="num">{_num(s.get(k))}</td>' for k in STATISTICS + tuple(area_keys))
        rows += f"<tr><th>{escape(ch)}</th>{cells}</tr>"
    return f'<table id="statistics"><tr><th>channel</th>{head}</tr>{rows}</table>'


def _verdict_section(verdict):
    if verdict is None:
        return ('<div class="verdict NONE" id="verdict">NO SPECIFICATION</div>'
                "<p>No acceptance specification was given (<code>--spec</code>); the results are reported without a "
                "verdict.</p>")
    rows = ""
    for c in verdict.checks:
        label = "PASS" if c.passed else "FAIL"
        value = _num(c.value) + (f" {escape(c.unit)}" if c.unit and isinstance(c.value, (int, float)) else "")
        note = f"<br><span class='small'>{escape(c.note)}</span>" if c.note else ""
        covers = "—" if c.covers_percent is None else f"{_num(c.covers_percent)} % of {escape(c.covers)}"
        rows += (f'<tr class="{label}"><td>{escape(c.criterion)}</td><td class="num">{value}</td>'
                 f"<td>{escape(c.comparison)} {_num(c.limit)} {escape(c.unit)}</td><td class='covers'>{covers}</td>"
                 f"<td><b>{label}</b>{note}</td></tr>")
    n_ok = sum(c.passed for c in verdict.checks)
    return (f'<div class="verdict {verdict.label}" id="verdict">{verdict.label}</div>'
            f"<p>Specification <b>{escape(verdict.spec_name)}</b>: {n_ok} of {len(verdict.checks)} criteria passed. "
            f"Specification file <code>{escape(verdict.spec_path)}</code>, SHA-256 "
            f"<code>{escape(verdict.spec_sha256)}</code>.</p>"
            '<table id="criteria"><tr><th>criterion</th><th>value</th><th>limit</th><th>judged over (trusted share)</th>'
            f'<th>result</th></tr>{rows}</table>')


def _input_rows(label, info):
    if info is None:
        return [(label, "none")]
    return [
        (label, f"<code>{escape(info['name'])}</code>"),
        (f"{label} SHA-256", f'<code class="sha256">{escape(info["sha256"])}</code>'),
        (f"{label} size", escape(info.get("size", ""))),
    ]


def _acceptance_sections(acc):
    """Pane metadata, protocol, zones and worst-region tables (HTML) of an Acceptance."""
    meta = _kv_table([(k, escape(v)) for k, v in metadata_rows(acc.metadata)])
    proto = ""
    if acc.protocol:
        used = acc.protocol.get("used", {})
        pinned = acc.protocol.get("pinned", {})
        sources = acc.protocol.get("sources", {})
        rows = "".join(f"<tr><th>{escape(k)}</th><td>{_num(v)}</td><td>{_num(pinned.get(k))}</td>"
                       f"<td>{escape(str(sources.get(k, '')))}</td></tr>" for k, v in used.items())
        extra = "".join(f"<tr><th>{escape(k)}</th><td>{_num(used.get('px_per_period')) if k == 'min_px_per_period' else '—'}"
                        f"</td><td>{_num(v)}</td><td>{'capture limit (px per period)' if k == 'min_px_per_period' else 'pinned'}"
                        "</td></tr>" for k, v in pinned.items() if k not in used)
        proto = ('<table id="protocol"><tr><th>setting</th><th>used</th><th>pinned by the specification</th>'
                 f"<th>from</th></tr>{rows}{extra}</table>")
    f = acc.frame
    pane = (f"<p>Pane outline: <b>{escape(f.source.replace('_', ' '))}</b>; millimetres "
            f"{'on the pane' if f.units == 'pane_mm' else 'on the backdrop (through mm per px)'}"
            + (f"; size {f.size_mm[0]:.4g} × {f.size_mm[1]:.4g} mm" if f.size_mm else "") + ".</p>"
            + (f'<p class="warn">{escape(f.warning)}</p>' if f.warning and acc.zones else ""))
    zrows = ""
    for name, z in acc.zones.items():
        e, s_ = z["statistics"].get("phi_eff", {}), z["statistics"].get("phi_shear", {})
        zrows += (f"<tr><th>{escape(name)}</th><td>{escape(z['definition'])}</td><td class='num'>{_num(z['area_mm2'])}</td>"
                  f"<td class='num'>{_num(z['trusted_percent'])}</td><td class='num'>{_num(e.get('mean_abs'))}</td>"
                  f"<td class='num'>{_num(e.get('p95_abs'))}</td><td class='num'>{_num(s_.get('p95_abs'))}</td></tr>")
    zones = ('<table id="zones"><tr><th>zone</th><th>definition</th><th>area (mm²)</th><th>trusted (% of zone)</th>'
             f"<th>mean |φ_eff| (mD)</th><th>p95 |φ_eff| (mD)</th><th>p95 φ_shear (mD)</th></tr>{zrows}</table>"
             if zrows else "<p>No zones in the specification: statistics are over the whole analysed region.</p>")
    rrows = ""
    for ch, e in acc.regions.items():
        for r in e["regions"]:
            rrows += (f"<tr><td>{escape(ch)}</td><td class='num'>{r.number}</td>"
                      f"<td class='num'>{_num(r.centroid_mm[0])}, {_num(r.centroid_mm[1])}</td>"
                      f"<td class='num'>{_num(r.extent_mm[0])}–{_num(r.extent_mm[1])} × "
                      f"{_num(r.extent_mm[2])}–{_num(r.extent_mm[3])}</td><td class='num'>{_num(r.area_mm2)}</td>"
                      f"<td class='num'>{_num(r.peak_mD)}</td><td class='num'>{_num(r.mean_abs_mD)}</td></tr>")
    thresholds = "; ".join(f"{escape(ch)} over {_num(e['threshold_mD'])} mD ({escape(e['threshold_source'])})"
                           for ch, e in acc.regions.items())
    regions = (f"<p>Connected regions {thresholds}; numbered on the heatmaps, worst peak first; coordinates in "
               f"{'pane' if f.units == 'pane_mm' else 'backdrop'} mm from the pane frame's origin.</p>"
               '<table id="worst-regions"><tr><th>channel</th><th>#</th><th>centroid x, y (mm)</th>'
               "<th>extent x × y (mm)</th><th>area (mm²)</th><th>peak (mD)</th><th>mean |φ| (mD)</th></tr>"
               f"{rrows}</table>")
    return meta, f"<h2>Protocol</h2>{proto or '<p>No protocol pinned.</p>'}", \
        f"<h2>Pane and zones</h2>{pane}{zones}<h2>Worst regions</h2>{regions}"


def _measures_section(measures):
    """The standard measures (:func:`glassdist.measures.standard_measures`) as a table."""
    rows = _kv_table([(k, escape(v)) for k, v in measures_rows(measures)])
    return f'<h3>Standard measures</h3><div id="standard-measures">{rows}</div>'


def _fit_facts(result):
    fit = result.homography_fit
    if fit is None:
        return None
    return {"inlier_fraction": fit.inlier_fraction, "n_points": fit.n_points, "rms_inlier_px": fit.rms_inlier_px}


def _geometry_rows(result, params, shares, fit_facts):
    """Rows of the capture-geometry table (the homography and its fit for the Direct method)."""
    optics = result.optics
    where = "the grid plane" if optics is None else "the pane"
    geometry = [
        ("grid pitch", f"{_num(result.pitch_mm)} mm"),
        ("glass-to-grid distance L" if optics is None else "board-to-pane distance D", f"{_num(result.distance_m)} m"),
        ("grid pattern", escape(str(params.get("pattern", "—")))),
        (f"scale on {where}", f"{_num(result.mm_per_px)} mm per px"),
        (f"smoothing scale σ (on {where})", f"{_num(result.sigma_mm)} mm"),
        ("detrend degree N", _num(result.detrend_degree)),
    ]
    if shares is not None:  # the two shares of the region asked for, as summary.json states them
        of = escape(shares["of"])
        geometry += [("measured area", f'<span id="measured-percent">{_num(shares["measured_percent"])}</span> % of {of}'),
                     ("trusted area (statistics cover it)",
                      f'<span id="trusted-percent">{_num(shares["trusted_percent"])}</span> % of {of}')]
    if optics is not None:
        geometry.insert(2, ("optics", escape(
            f"reflection: φ in reflective power on the pane (Coddington); camera at {_num(optics.camera_distance_m)} m, "
            f"incidence {_num(optics.incidence_deg)}°, board mm per pane mm {_num(optics.magnification)}")))
    if result.homography is not None:
        rows = "<br>".join(" ".join(f"{x: .6g}" for x in r) for r in np.asarray(result.homography, dtype=float))
        geometry.append(("homography (grid → image)", f'<span class="mono">{rows}</span>'))
    if fit_facts is not None:
        share = fit_facts["inlier_fraction"]
        geometry.append(("homography fit (Direct method)",
                         f'<span id="homography-fit">inliers {_num(None if share is None else 100 * share)} % of '
                         f'{_num(fit_facts["n_points"])} grid points, RMS inlier reprojection error '
                         f'{_num(fit_facts["rms_inlier_px"])} px</span>'))
    return geometry


def _report_data(result, generated, inputs, shares, verdict, stats, params, acceptance, measures):
    """The report's key facts, embedded as JSON (``glassdist-report-data``)."""
    data = {
        "glassdist_version": str(result.version), "method": str(result.method),
        "generated_utc": generated.isoformat(timespec="seconds"), "inputs": inputs, "pitch_mm": result.pitch_mm,
        "distance_m": result.distance_m, "mm_per_px": result.mm_per_px, "sigma_mm": result.sigma_mm,
        "detrend_degree": result.detrend_degree,
        **({} if shares is None else {k: shares[k] for k in ("measured_percent", "trusted_percent")}),
        "verdict": verdict.to_dict() if verdict is not None else None, "statistics": stats, "parameters": params,
        "homography_fit": _fit_facts(result), "warnings": list(result.warnings),
    }
    if acceptance is not None:
        data.update({k: v for k, v in acceptance.summary().items() if k in ("metadata", "protocol", "zones", "worst_regions")})
    if measures is not None:
        data["measures"] = measures
    return data


def render_report(result, *, stats, figures, inputs, verdict=None, generated=None, acceptance=None, measures=None,
                  mask_given=False):
    """HTML text of the report.

    Parameters
    ----------
    result : AnalysisResult
    stats : dict
        ``{channel: statistics}`` (mD, percent), see :mod:`glassdist.acceptance.stats`.
    figures : list of (str, str, bytes)
        ``(id, caption, png bytes)`` in display order.
    inputs : dict
        ``{"image": {"name", "sha256", "size"}, "reference": {...} or None}``.
    verdict : Verdict, optional
    generated : datetime, optional
        Time stamp written in the report (default: now, UTC).
    acceptance : Acceptance, optional
        Pane metadata, protocol, zones, worst regions and the measured and trusted shares
        (:func:`glassdist.acceptance.assess.assess`).
    measures : dict, optional
        :meth:`glassdist.measures.StandardMeasures.to_dict` (roll wave, angular
        deviation, grid-line slope, P = -phi_eff/2), shown under the results.
    mask_given : bool
        Whether the shares are of a user mask (else of the image).

    Returns
    -------
    str
        A complete HTML document with every image embedded as a data URI.
    """
    generated = generated or datetime.now(timezone.utc)
    version, method = str(result.version), str(result.method)
    params = resolved_parameters(result)
    carriers = result.carriers.to_dict()
    fit_facts = _fit_facts(result)
    warnings = tuple(result.warnings)
    image_name = inputs["image"]["name"] if inputs.get("image") else "image given as an array"
    title = f"Glass distortion report: {image_name}"
    pane_id = (acceptance.metadata.get("pane_id") if acceptance is not None else None)
    if pane_id:
        title = f"Glass distortion report: pane {pane_id} ({image_name})"
    shares = None if acceptance is None else {"measured_percent": acceptance.measured_percent,
                                              "trusted_percent": acceptance.trusted_percent,
                                              "of": "the mask" if mask_given else "the image"}
    geometry = _geometry_rows(result, params, shares, fit_facts)
    data = _report_data(result, generated, inputs, shares, verdict, stats, params, acceptance, measures)
    meta_html, proto_html, zones_html = _acceptance_sections(acceptance) if acceptance is not None else ("", "", "")
    measures_html = "" if measures is None else _measures_section(measures)
    data_json = json.dumps(to_jsonable(data), allow_nan=False).replace("</", "<\\/")
    warn_html = "".join(f'<p class="warn">{escape(w)}</p>' for w in warnings) or "<p>None.</p>"
    fig_html = "".join(_img(png, fid, cap) for fid, cap, png in figures)
    body = f"""
<h1>{escape(title)}</h1>
<p class="small">glassdist {escape(version)} · {escape(method)} method ·
generated {escape(generated.strftime('%Y-%m-%d %H:%M:%S'))} UTC</p>
{_verdict_section(verdict)}
<h2>1. Identification</h2>
{_kv_table(_input_rows('input image', inputs['image']) + _input_rows('reference image', inputs.get('reference'))
           + [('glassdist version', f'<code id="version">{escape(version)}</code>'), ('method', escape(method))])}
<div id="pane-metadata">{meta_html}</div>
<h2>2. Capture geometry</h2>
{_kv_table(geometry)}
{proto_html}
<details><summary>carriers detected in the photograph</summary>
<pre>{escape(json.dumps(to_jsonable(carriers), indent=1))}</pre></details>
<h2>3. Method</h2>
<p>{escape(METHOD_TEXT.get(method, method))}</p>
<p class="small">{escape(_CONVENTIONS)}</p>
<details><summary>all analysis parameters (resolved)</summary>
<pre>{escape(json.dumps(to_jsonable(params), indent=1))}</pre></details>
<h2>4. Results</h2>
{_stats_table(stats)}
{measures_html}
{zones_html}
<div class="figs">{fig_html}</div>
<h2>5. Warnings</h2>
{warn_html}
<h2>6. Scope</h2>
<p class="small">φ_eff and φ_shear are candidate industrial metrics (paper §1.3, §4): limits in a specification are
only meaningful for the capture geometry, smoothing scale and detrend degree they were written for, all recorded
above.</p>
<script type="application/json" id="glassdist-report-data">{data_json}</script>
"""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{escape(title)}</title>'
            f"<style>{_CSS}</style></head><body>{body}</body></html>\n")


def resolved_parameters(result):
    """The analyzer parameters a result was computed with, as recorded in summary.json and the report.

    ``result.params.resolved()`` with ``sigma_mm`` replaced by the smoothing scale actually
    used (the parameter's default, ``None``, stands for 2 carrier periods).
    """
    return {**result.params.resolved(), "sigma_mm": result.sigma_mm}


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


def _g(v, unit: str = "", digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—" if not (isinstance(v, float) and np.isinf(v)) else "∞"
    return f"{float(v):.{digits}g}{unit}"


def _direction(v) -> str:
    """A direction modulo 180 degrees, one decimal, in (-90, 90] after rounding."""
    if v is None or not np.isfinite(v):
        return "—"
    r = round(float(v), 1)
    return f"{90.0 if r <= -90.0 else r:g}°"


def measures_rows(measures: dict) -> list[tuple[str, str]]:
    """``(label, text)`` rows of a :meth:`StandardMeasures.to_dict` for a report (plain text, units stated)."""
    rw, ad = measures["roll_wave"], measures["angular_deviation"]
    gl, ep = measures["grid_line_slope"], measures["equivalent_power"]
    slopes = ", ".join(f"1 in {_g(n)} (lines at {_g(d, '°')})" for d, n in zip(gl["directions_deg"], gl["one_in_n"]))
    if "reflected_roll_wave" in measures:  # reflection: the pane's roll wave, and what the others mean there
        r, mean = measures["reflected_roll_wave"], measures["reflection_meaning"]
        return [
            ("reflected roll wave", f"period {_g(r['period_mm'], ' mm', 4)} along {_direction(r['direction_deg'])}; "
             f"reflective power amplitude {_g(r['power_amplitude_mD'], ' mD')} (peak-to-valley {_g(r['power_pv_mD'], ' mD')}); "
             f"surface peak-to-valley {_g(r['surface_pv_mm'], ' mm')} ({r['assumptions']})"),
            ("deviation of the reflected ray",
             f"max {_g(ad['angle_max_arcmin'], ' arcmin')}, p95 {_g(ad['angle_p95_arcmin'], ' arcmin')}; "
             f"change over {_g(ad['gauge_mm'], ' mm')}: p95 {_g(ad['rate_p95_arcmin'], ' arcmin')} "
             f"({mean['angular_deviation']})"),
            ("grid-line slope of the reflected board", slopes),
            ("sphere-equivalent power of the pane as a mirror P = −φ_eff/2",
             f"mean {_g(ep['mean_mD'], ' mD')}, p95 |P| {_g(ep['p95_abs_mD'], ' mD')} ({mean['equivalent_power']})"),
            ("field measured", str(measures["field"])),
        ]
    return [
        ("roll wave (ASTM C1651 quantities)",
         f"period {_g(rw['period_mm'], ' mm', 4)} along {_direction(rw['direction_deg'])}; "
         f"amplitude {_g(rw['amplitude_mm'], ' mm')} "
         f"= {_g(rw['power_amplitude_mD'], ' mD')} along the roll direction "
         f"(peak-to-valley {_g(rw['displacement_pv_mm'], ' mm')}, "
         f"{_g(rw['power_pv_mD'], ' mD')}); the wave explains {_g(100 * rw['explained_fraction'], ' %', 2)} of the "
         "displacement along it"),
        ("angular deviation (ECE R43 / ISO 3538)",
         f"max {_g(ad['angle_max_arcmin'], ' arcmin')}, p95 {_g(ad['angle_p95_arcmin'], ' arcmin')}; change over "
         f"{_g(ad['gauge_mm'], ' mm')}: max {_g(ad['rate_max_arcmin'], ' arcmin')}, p95 {_g(ad['rate_p95_arcmin'], ' arcmin')}"),
        ("grid-line slope (ASTM F2156)", slopes),
        ("sphere-equivalent power P = −φ_eff/2",
         f"mean {_g(ep['mean_mD'], ' mD')}, min {_g(ep['min_mD'], ' mD')}, max {_g(ep['max_mD'], ' mD')}, "
         f"p95 |P| {_g(ep['p95_abs_mD'], ' mD')}. {ep['convention']}"),
        ("field measured", str(measures["field"])),
    ]
