"""The Analyzer's transfer function for a displacement field, measured, and ray-traced ripples and a large lens.

Three parts (docs/explanation/transfer-function.md):

* **Measured transfer function** (synthetic captures, :mod:`glassdist.synthetic`): a small
  sinusoidal displacement of wavelength ``n`` carrier periods is pushed through the
  Analyzer (Comparative Method) and the amplitude of the smoothed displacement it
  reports is divided by the displacement's own amplitude; the target is the Gaussian of
  ``sigma_mm``, ``exp(-2 pi^2 sigma^2 / Lambda^2)``. Also shown: the instrument's own
  transfer before Block A's correction (:class:`glassdist.analyzer.transfer.InstrumentTransfer`).
* **Ray-traced ripples** (``examples/scenes/ripple_slab.yaml``, exact tracer): ripples of
  2.5 to 10 carrier periods, the displacement amplitude kept at ~0.005 periods, both
  methods, sigma 1 to 3 periods. Each ripple is rendered at +A and at -A with the same
  render seed, and every map is the half difference of the two readings: the render's
  sampling noise (the same sub-pixel samples) and the even-order terms of the
  demodulation (the harmonic resonance at 3 periods) cancel, the odd third-order term
  (relative error ~ A^2, < 1e-4 at 0.005 periods) stays. The amplitude (least-squares
  slope of the Analyzer's phi_eff on the truth's over the interior: at least 3 sigma
  inside the valid region) is compared with the exact landing-point truth
  (a) through the Analyzer's own evaluation stack and (b) through an independent
  evaluation written here (polynomial detrend by least squares, mask-normalised Gaussian
  of ``scipy.ndimage``, ``numpy.gradient``). Cases where the smoothed truth keeps less
  than 2% of the ripple (``G_sigma(Lambda) < 0.02``) are listed but not judged.
* **Large lenses** (N = 1, both methods, ratio and correlation against the truth through
  the stack and, over the interior, through the independent evaluation):
  ``examples/scenes/large_lens.yaml``, a lens of compact support over 47% of a 512 x 384
  view with flat glass around it (the Direct Method's bound), and
  ``examples/scenes/wide_gaussian_lens.yaml``, a Gaussian lens wider than the view (no
  flat glass in view: reported, not bounded).

    glassdist experiment transfer --out docs/records/experiments
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..scene import load_scene
from ..theory import analysis_params, read_params_file
from ._common import ExperimentResult, RunOptions, evaluate, render_inputs, share_fig_ax

__all__ = ["measured_transfer", "independent_phi_eff", "minus_homography_change", "run_transfer", "RIPPLE_PERIODS",
           "SIGMA_PERIODS"]

_SCENES = __import__("pathlib").Path(__file__).resolve().parents[3] / "examples" / "scenes"
RIPPLE_PERIODS = (2.5, 3.0, 4.0, 6.0, 10.0)
SIGMA_PERIODS = (1.0, 1.5, 2.0, 3.0)
#: Displacement amplitude of the ray-traced ripples, carrier periods (linear demodulation).
RIPPLE_AMPLITUDE_PERIODS = 0.005
#: Smallest share of the ripple the smoothed truth must keep for a case to be judged.
MIN_GAIN = 0.02
BOUND = 0.01


def measured_transfer(periods, sigma_periods, *, pitch_mm: float = 12.0, shape=(256, 512), method: str = "comparative",
                      params: dict | None = None):
    """Amplitude of the Analyzer's smoothed displacement / the true amplitude, synthetic sinusoids.

    ``params``: analyzer parameters under the sweep's own detrend degree and sigma.

    Returns
    -------
    dict
        ``{sigma_periods: [ratio for each wavelength]}`` and the instrument's transfer
        ``'instrument'`` at those wavelengths (carrier 1, along the wave).
    """
    import glassdist
    from glassdist.synthetic import synthetic_capture, wave_displacement

    out: dict = {}
    H, W = shape
    x = (np.arange(W) - (W - 1) / 2)[None, :] * np.ones((H, 1))
    for sp in sigma_periods:
        row = []
        for n in periods:
            cap = synthetic_capture(shape, pitch_mm=pitch_mm, mm_per_px=1.0,
                                    displacement=wave_displacement(0.005 * pitch_mm, n * pitch_mm, 0.0))
            res = glassdist.analyze(cap.image, pitch_mm=pitch_mm, distance_m=10.0,
                                    reference=cap.reference if method == "comparative" else None,
                                    params={**(params or {}), "detrend_degree": 0 if method == "comparative" else 2,
                                            "sigma_mm": sp * pitch_mm})
            s = sp * pitch_mm / res.mm_per_px
            d = res.displacement_detrended_mm[..., 0]
            dist = ndimage.distance_transform_edt(np.pad(res.valid, 1))[1:-1, 1:-1]
            inner = res.valid & (dist > max(3 * s, 2 * pitch_mm))
            k = 2 * np.pi / (n * pitch_mm)
            B = np.stack([np.sin(k * x), np.cos(k * x), np.ones_like(x)], -1)[inner]
            c = np.linalg.lstsq(B, d[inner], rcond=None)[0]
            row.append(float(np.hypot(c[0], c[1]) / (0.005 * pitch_mm)))
        out[sp] = row
    return out


def _instrument(periods, pitch_px: float = 12.0):
    """The Block F transfer (bandpass along the wave + F3) at default parameters, carrier along x."""
    from ..analyzer.params import load_params

    p = load_params()
    f = 1.0 / (np.asarray(periods, float) * pitch_px)
    sd_f = p.bandpass_sigma_along / pitch_px
    var = 1.0 / (4 * np.pi**2 * sd_f**2) + (p.smoothing_periods * pitch_px) ** 2
    return np.exp(-2 * np.pi**2 * var * f**2)


def minus_homography_change(displacement_mm, region):
    """``displacement_mm`` less its best fit over ``region`` by a small change of homography (8 parameters).

    To first order a change of homography moves a pixel by an affine term per component
    plus the two projective terms shared by both, ``g1 x^2 + g2 x y`` along x and
    ``g1 x y + g2 y^2`` along y (one least-squares fit of both components, in pixel
    coordinates normalised by the image size). The Direct Method's baseline (Block I,
    one homography for the whole view) takes that family from the glass's displacement,
    or moves by it between captures.

    Parameters
    ----------
    displacement_mm : ndarray, shape (H, W, 2)
        (x, y) displacement; finite on ``region``.
    region : ndarray of bool, shape (H, W)
        Pixels the fit is made on.

    Returns
    -------
    ndarray, shape (H, W, 2)
        A new array; the input is not changed.
    """
    d = np.asarray(displacement_mm, dtype=float)
    region = np.asarray(region, bool)
    h, w = d.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    x, y = (xx - w / 2) / w, (yy - h / 2) / h
    xr, yr, one, zero = x[region], y[region], np.ones(int(region.sum())), np.zeros(int(region.sum()))
    A = np.concatenate([np.stack([one, xr, yr, zero, zero, zero, xr * xr, xr * yr], 1),
                        np.stack([zero, zero, zero, one, xr, yr, xr * yr, yr * yr], 1)])
    coef, *_ = np.linalg.lstsq(A, np.concatenate([d[..., 0][region], d[..., 1][region]]), rcond=None)
    out = d.copy()
    out[..., 0] -= coef[0] + coef[1] * x + coef[2] * y + coef[6] * x * x + coef[7] * x * y
    out[..., 1] -= coef[3] + coef[4] * x + coef[5] * y + coef[6] * x * y + coef[7] * y * y
    return out


def independent_phi_eff(displacement_mm, region, *, jacobian, sigma_px: float, degree: int, distance_m: float,
                        minus_homography: bool = False):
    """phi_eff (mD) of a displacement field by a plain evaluation, independent of the Analyzer's code.

    Each 4-connected part of ``region`` on its own, as the Analyzer treats its regions:
    least-squares polynomial detrend of total degree ``degree`` over the part, Gaussian
    smoothing normalised by the smoothed part (``scipy.ndimage.gaussian_filter``); then
    centred differences (``numpy.gradient``) and the chain rule through the glass-less
    pixel -> backdrop Jacobian ``jacobian`` (mm per px). One fit over several parts would
    remove a polynomial the result never removed: on a Direct capture whose region falls
    into three parts it read 0.8 % off.

    ``minus_homography``: first remove the best change of homography over the whole region
    (:func:`minus_homography_change`), what the Direct Method's one baseline takes from the
    glass. At ``degree`` >= 2 the detrend spans it anyway (to first order); at 1 it keeps
    the two projective terms, which the Direct Method does not report.
    """
    if minus_homography:
        displacement_mm = minus_homography_change(displacement_mm, region)
    h, w = region.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    xs, ys = (xx - w / 2) / w, (yy - h / 2) / h
    cols = [xs**i * ys**j for i in range(degree + 1) for j in range(degree + 1 - i)]
    parts, n = ndimage.label(region)
    sm = np.full((h, w, 2), np.nan)
    for k in range(1, n + 1):
        part = parts == k
        A = np.stack([c[part] for c in cols], 1)
        wgt = ndimage.gaussian_filter(part.astype(float), sigma_px, mode="constant")
        for c in range(2):
            f = displacement_mm[..., c]
            coef = np.linalg.lstsq(A, f[part], rcond=None)[0]
            det = np.zeros((h, w))
            det[part] = f[part] - A @ coef
            with np.errstate(invalid="ignore", divide="ignore"):
                sm[part, c] = (ndimage.gaussian_filter(det, sigma_px, mode="constant") / wgt)[part]
    grads = [np.gradient(sm[..., c]) for c in range(2)]
    G = np.stack([np.stack((gx, gy), -1) for gy, gx in grads], -2)  # (h, w, comp, d/d(x, y))
    Jinv = np.linalg.inv(jacobian)
    grad = G @ Jinv
    return (grad[..., 0, 0] + grad[..., 1, 1]) / distance_m * 1000.0


def _interior(region, sigma_px):
    return region & (ndimage.distance_transform_edt(np.pad(region, 1))[1:-1, 1:-1] > 3 * sigma_px)


def _rms_ratio(a, b, m):
    """Amplitude of ``a`` relative to ``b``: the least-squares slope of ``a`` on ``b``.

    Render noise, uncorrelated with ``b``, does not bias it.
    """
    x, y = b[m] - b[m].mean(), a[m] - a[m].mean()
    return float(np.sum(x * y) / np.sum(x * x))


def _ripple_scene(base, n: float, amplitude_mm: float):
    dm = base.model_dump()["pane"]["deformation"]
    dm["both"] = [{**dm["both"][0], "wavelength_mm": n * base.backdrop.pitch_mm, "amplitude_mm": amplitude_mm}]
    return base.with_changes(name=f"ripple_{n:g}p", pane={"deformation": dm})


def _amplitude_for(base, n: float) -> float:
    """Ripple height (mm) giving a displacement amplitude of RIPPLE_AMPLITUDE_PERIODS (linear in the height)."""
    from ..render import landing_points

    probe = _ripple_scene(base, n, 0.01).with_changes(camera={"pixels": [256, 192]})
    d = landing_points(probe).displacement_mm
    amp = np.sqrt(2.0) * float(np.nanstd(d[..., 0] - np.nanmean(d[..., 0])))
    return 0.01 * RIPPLE_AMPLITUDE_PERIODS * base.backdrop.pitch_mm / max(amp, 1e-12)


def _ripple_pair(base, n: float, opts: RunOptions):
    """Renders of the ripple at +A and -A (same render seed: the same sub-pixel samples), one reference."""
    from dataclasses import replace

    amp = _amplitude_for(base, n)
    plus = render_inputs(_ripple_scene(base, n, amp), engine=opts.engine, reference=True, progress=opts.progress)
    minus = render_inputs(_ripple_scene(base, n, -amp), engine=opts.engine, reference=False, progress=opts.progress)
    return plus, replace(minus, reference=plus.reference)


def _ripple_rows(pair, n: float, sigma_periods, file_params=None) -> list[dict]:
    """Both methods, each sigma: the half difference of the +A and -A readings against the truth's."""
    from ..scene import landing_jacobian

    plus, minus = pair
    scene, p_c = plus.scene, plus.scene.backdrop.pitch_mm
    J = landing_jacobian(scene)
    half = (np.nan_to_num(plus.truth.displacement_mm) - np.nan_to_num(minus.truth.displacement_mm)) / 2
    fin = np.isfinite(plus.truth.displacement_mm).all(-1) & np.isfinite(minus.truth.displacement_mm).all(-1)
    rows = []
    for method in ("comparative", "direct"):
        for sp in sigma_periods:
            vals = [evaluate(i, method=method, params=analysis_params(i.scene, file_params, detrend_degree=2,
                                                                     sigma_mm=sp * p_c))
                    for i in pair]
            res = vals[0].analysis
            s_px = sp * p_c / res.mm_per_px
            region = vals[0].valid & vals[1].valid & fin  # compared: the trusted pixels
            # detrended and smoothed over the region the Analyzer detrends over (its detrend region)
            fit = vals[0].analysis.detrend_region & vals[1].analysis.detrend_region & fin
            ind = independent_phi_eff(half, fit, jacobian=J,
                                      sigma_px=s_px, degree=2, distance_m=scene.backdrop.distance_m)
            an = (vals[0].analysis.phi_eff_mD - vals[1].analysis.phi_eff_mD) / 2
            ex = (vals[0].exact.phi_eff_mD - vals[1].exact.phi_eff_mD) / 2
            ok = _interior(region, s_px) & np.isfinite(an) & np.isfinite(ex) & np.isfinite(ind)
            gain = float(np.exp(-2 * np.pi**2 * sp**2 / n**2))
            nan = float("nan")
            rows.append({
                "periods": n, "sigma_periods": sp, "method": method, "gain": gain, "judged": gain >= MIN_GAIN,
                "interior_fraction": float(ok.mean()),
                "ratio_stack": _rms_ratio(an, ex, ok) if ok.any() else nan,
                "ratio_independent": _rms_ratio(an, ind, ok) if ok.any() else nan,
                "stack_vs_independent": _rms_ratio(ex, ind, ok) if ok.any() else nan,
                "ratio_single_render": _rms_ratio(res.phi_eff_mD, vals[0].exact.phi_eff_mD, ok) if ok.any() else nan,
                "effective_sigma_mm": res.effective_sigma_mm, "warnings": list(res.warnings),
            })
    return rows


def _lens_rows(scene, opts: RunOptions, file_params=None) -> list[dict]:
    """Both methods on a lens scene: ratio and r against the truth through the stack (valid region, and
    the interior more than 3 sigma inside it) and through the independent evaluation (interior)."""
    from ..scene import landing_jacobian

    inputs = render_inputs(scene, engine=opts.engine, reference=True, progress=opts.progress)
    params = analysis_params(scene, file_params)
    fin = np.isfinite(inputs.truth.displacement_mm).all(-1)
    rows = []
    for method in ("comparative", "direct"):
        val = evaluate(inputs, method=method, params=params)
        res = val.analysis
        ex, an = val.exact.phi_eff_mD, res.phi_eff_mD
        s_px = params.sigma_mm / res.mm_per_px
        region = val.valid & fin  # compared: the trusted pixels
        # detrended over the region the Analyzer detrends over (its detrend region): with N = 1 on a lens
        # the fitted plane, hence a uniform power, depends on the region (the trusted one reads 2.7 % apart)
        ind = independent_phi_eff(np.nan_to_num(inputs.truth.displacement_mm), res.detrend_region & fin,
                                  jacobian=landing_jacobian(scene), sigma_px=s_px, degree=params.detrend_degree,
                                  distance_m=scene.backdrop.distance_m)
        m = val.valid & np.isfinite(ex) & np.isfinite(an)
        inner = _interior(region, s_px) & m & np.isfinite(ind)
        rows.append({
            "scene": scene.name, "method": method, "ratio": val.metrics["analyzer_vs_exact"]["phi_eff"],
            "corr": float(np.corrcoef(ex[m], an[m])[0, 1]), "interior_fraction": float(inner.mean()),
            "ratio_interior_stack": float(np.mean(np.abs(an[inner])) / np.mean(np.abs(ex[inner]))),
            "ratio_interior_independent": float(np.mean(np.abs(an[inner])) / np.mean(np.abs(ind[inner]))),
            "corr_interior_independent": float(np.corrcoef(ind[inner], an[inner])[0, 1]),
            "homography_excluded_fraction": getattr(res.homography_fit, "excluded_fraction", None),
            "warnings": list(res.warnings),
        })
    return rows


def _bound(what: str, values, limit: float) -> dict:
    v = max(abs(x - 1) for x in values)
    return {"what": what, "limit": limit, "value": v, "met": v <= limit}


def run_transfer(*, periods=RIPPLE_PERIODS, sigma_periods=SIGMA_PERIODS, sigma_mm=None, params_file=None,
                 **options) -> ExperimentResult:
    """Measured transfer function, ray-traced ripple sweep and large lenses (see the module notes).

    ``sigma_mm`` is refused: the sweep sets sigma in carrier periods (``sigma_periods``).
    ``params_file``: analyzer parameters (JSON) under each run's own detrend degree and sigma, over
    the scenes' analysis settings; a bad file is bad input before anything renders.
    """
    if sigma_mm is not None:
        from ..errors import InputError

        raise InputError("the transfer experiment sweeps sigma in carrier periods; leave out --sigma-mm")
    file_params = {}
    if params_file is not None:  # read once; a bad file is bad input before anything renders
        from ..analyzer.params import load_params

        file_params = read_params_file(params_file)
        load_params(file_params)
    opts = RunOptions(**options)
    tf_periods = np.array([2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 14.0])
    tf = measured_transfer(tf_periods, sigma_periods, params=file_params)
    record: dict = {"transfer_function": {"periods": tf_periods.tolist(), "measured": {str(k): v for k, v in tf.items()},
                                          "instrument": _instrument(tf_periods).tolist()}}
    base = opts.prepare(load_scene(_SCENES / "ripple_slab.yaml"))
    rows = [r for n in periods for r in _ripple_rows(_ripple_pair(base, n, opts), n, sigma_periods, file_params)]
    record["ripples"] = rows
    lens_rows = []
    for name in ("large_lens", "wide_gaussian_lens"):
        lens = load_scene(_SCENES / f"{name}.yaml")
        lens_rows += _lens_rows(opts.prepare(lens) if opts.scale == 1.0 else lens, opts, file_params)
    record["large_lens"] = lens_rows
    judged = [r for r in rows if r["judged"]]
    direct = next(r for r in lens_rows if r["scene"] == "large_lens" and r["method"] == "direct")
    record["bounds"] = {
        "ripples_stack": _bound("ripples, judged cases: abs(ratio - 1) via the stack", [r["ratio_stack"] for r in judged], BOUND),
        "ripples_independent": _bound("ripples, judged cases: abs(ratio - 1) via the independent evaluation",
                                      [r["ratio_independent"] for r in judged], BOUND),
        "lens_direct": _bound("large lens, Direct: abs(ratio - 1), valid region (stack) and interior (stack, independent)",
                              [direct["ratio"], direct["ratio_interior_stack"], direct["ratio_interior_independent"]], 0.02),
        "lens_direct_corr": {"what": "large lens, Direct: r (stack) and r (independent, interior), at least", "limit": 0.99,
                             "value": min(direct["corr"], direct["corr_interior_independent"]),
                             "met": min(direct["corr"], direct["corr_interior_independent"]) >= 0.99},
    }
    figures = {"transfer_function.png": lambda: transfer_figure(record)}
    return ExperimentResult("transfer", record, transfer_table(record), figures)


def transfer_table(record: dict) -> str:
    """Markdown tables of the ripple sweep and the large lenses."""
    lines = [
        "Ray-traced ripples (`examples/scenes/ripple_slab.yaml`, displacement amplitude "
        f"{RIPPLE_AMPLITUDE_PERIODS} carrier periods), N = 2, each rendered at +A and at -A with the same render seed "
        "(the same sub-pixel samples); every map below is the half difference of the two readings, which cancels "
        "the render's sampling noise and the demodulation's even-order terms. Ratio: amplitude of phi_eff over the "
        "interior (more than 3 sigma inside the valid region), least-squares slope of the Analyzer's map on the "
        "exact truth's through the Analyzer's stack (*stack*) and through the independent evaluation (*indep.*); "
        "*single*: the +A render alone, through the stack. *G*: the share of the ripple the Gaussian of sigma keeps; "
        f"cases with G < {MIN_GAIN} keep too little of the ripple to be judged (listed).",
        "",
        "| ripple, periods | sigma, periods | G | method | ratio (stack) | ratio (indep.) | truth stack / indep. "
        "| single | interior | judged |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in record["ripples"]:
        lines.append(
            f"| {r['periods']:g} | {r['sigma_periods']:g} | {r['gain']:.3g} | {r['method']} | {r['ratio_stack']:.4f} | "
            f"{r['ratio_independent']:.4f} | {r['stack_vs_independent']:.4f} | {r['ratio_single_render']:.4f} | "
            f"{100 * r['interior_fraction']:.0f}% | {'yes' if r['judged'] else 'no'} |"
        )
    lines += ["", "Large lenses (N = 1): `large_lens` (compact support, flat glass around it, 47% of the view) and "
              "`wide_gaussian_lens` (wider than the view, no flat glass). Ratio: mean |phi_eff| Analyzer / truth over "
              "the valid region (stack) and over the interior (stack, independent evaluation); r: correlation.", "",
              "| scene | method | ratio (stack) | r (stack) | ratio interior (stack) | ratio interior (indep.) | "
              "r interior (indep.) | interior | strained share (Block I) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in record["large_lens"]:
        ex = r["homography_excluded_fraction"]
        lines.append(f"| {r['scene']} | {r['method']} | {r['ratio']:.4f} | {r['corr']:.4f} | {r['ratio_interior_stack']:.4f} | "
                     f"{r['ratio_interior_independent']:.4f} | {r['corr_interior_independent']:.4f} | "
                     f"{100 * r['interior_fraction']:.0f}% | {'-' if ex is None else f'{100 * ex:.0f}%'} |")
    lines += ["", "| check | value | limit | met |", "|---|---|---|---|"]
    for b in record["bounds"].values():
        lines.append(f"| {b['what']} | {b['value']:.4f} | {b['limit']:g} | {'yes' if b['met'] else '**no**'} |")
    return "\n".join(lines)


def transfer_figure(record: dict, *, fig=None, ax=None):
    """Measured amplitude transfer vs wavelength (carrier periods) for each sigma, with the target Gaussians."""
    fig, axes = share_fig_ax(fig, ax, figsize=(7.5, 4.8))
    a = np.ravel(axes)[0]
    tf = record["transfer_function"]
    n = np.asarray(tf["periods"])
    nn = np.linspace(n.min(), n.max(), 200)
    for i, (sp, vals) in enumerate(tf["measured"].items()):
        c = f"C{i}"
        a.plot(nn, np.exp(-2 * np.pi**2 * float(sp) ** 2 / nn**2), "-", color=c, lw=1,
               label=f"target G, sigma {float(sp):g} periods")
        a.plot(n, vals, "o", color=c, ms=4, label=f"measured, sigma {float(sp):g}")
    a.plot(n, tf["instrument"], "k--", lw=1, label="Block F alone (bandpass + F3)")
    a.set_yscale("log")
    a.set_ylim(1e-3, 1.2)
    a.set_xlabel("ripple wavelength, carrier periods")
    a.set_ylabel("amplitude transfer")
    a.set_title("Analyzer transfer for a displacement field (Comparative, synthetic)", fontsize=10)
    a.legend(fontsize=7, ncol=2)
    a.grid(True, which="both", alpha=0.3)
    return fig, axes
