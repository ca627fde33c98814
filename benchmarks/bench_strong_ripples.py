"""Single captures of strong ray-traced ripples, with and without a pillow dome under them.

The scene is ``examples/scenes/ripple_slab.yaml`` with its ripple height scaled so that the
displacement's peak is ``--peak-pitch`` carrier periods (0.35: strong, the local grid
frequency moves by up to 2 pi 0.35 / n of the carrier); with ``--dome`` the pane also
carries a pillow of ``--dome-pitch`` periods of peak displacement. One render, one capture
(no +-A average). Both methods, detrend degree N (4 with the dome). Ratios of phi_eff over
the interior (more than 3 sigma inside the trusted region): least-squares slope of the
Analyzer's map on the exact truth's through the Analyzer's stack (*stack*) and through the
independent evaluation (*indep.*, the truth detrended on the Analyzer's detrend region).
``--dome-only``: the dome alone, p95 |phi_eff| over the interior (the truth after the N = 4
detrend is ~0).

Usage::

    python benchmarks/bench_strong_ripples.py [--scale 0.5] [--periods 2.5 3 4 6 10] [--sigma 1 2 3] \
        [--peak-pitch 0.35] [--dome] [--dome-only] [--passes N] [--params JSON] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _record import write_record  # noqa: E402

ROOT = HERE.parent


def _scene(n: float | None, peak_pitch: float, dome_pitch: float | None, scale: float):
    from glassdist.experiments.transfer import RIPPLE_AMPLITUDE_PERIODS, _amplitude_for, _ripple_scene
    from glassdist.render import landing_points
    from glassdist.scene import load_scene

    base = load_scene(ROOT / "examples" / "scenes" / "ripple_slab.yaml")
    px = [int(round(1024 * scale)), int(round(768 * scale))]
    if n is None:
        scene = _ripple_scene(base, 3.0, 0.0)
    else:
        amp = _amplitude_for(base, n) * peak_pitch / RIPPLE_AMPLITUDE_PERIODS
        scene = _ripple_scene(base, n, amp)
    if dome_pitch:
        dm = scene.model_dump()["pane"]["deformation"]
        size = list(scene.pane.size_mm)
        probe = {"kind": "pillow", "amplitude_mm": 1.0, "size_mm": size}
        d = landing_points(base.with_changes(pane={"deformation": {"both": [probe]}}, camera={"pixels": [256, 192]}))
        peak = float(np.nanmax(np.hypot(*(d.displacement_mm - np.nanmean(d.displacement_mm, (0, 1))).transpose(2, 0, 1))))
        dm["both"] = list(dm["both"]) + [{**probe, "amplitude_mm": dome_pitch * base.backdrop.pitch_mm / max(peak, 1e-12)}]
        scene = scene.with_changes(pane={"deformation": dm})
    return scene.with_changes(camera={"pixels": px})


def run_case(scene, sigma_periods, degree: int, overrides: dict | None = None) -> list[dict]:
    from glassdist.experiments._common import evaluate, render_inputs
    from glassdist.experiments.transfer import _interior, _rms_ratio, independent_phi_eff
    from glassdist.scene import landing_jacobian
    from glassdist.theory import analysis_params

    inputs = render_inputs(scene, engine="exact", reference=True)
    p_c = scene.backdrop.pitch_mm
    J = landing_jacobian(scene)
    fin = np.isfinite(inputs.truth.displacement_mm).all(-1)
    rows = []
    for method in ("comparative", "direct"):
        for sp in sigma_periods:
            params = analysis_params(scene, detrend_degree=degree, sigma_mm=sp * p_c)
            if overrides:
                params = params.model_copy(update=overrides)
            t0 = time.perf_counter()
            val = evaluate(inputs, method=method, params=params)
            res = val.analysis
            s_px = sp * p_c / res.mm_per_px
            ind = independent_phi_eff(np.nan_to_num(inputs.truth.displacement_mm), res.detrend_region & fin, jacobian=J,
                                      sigma_px=s_px, degree=degree, distance_m=scene.backdrop.distance_m)
            an, ex = res.phi_eff_mD, val.exact.phi_eff_mD
            ok = _interior(val.valid & fin, s_px) & np.isfinite(an) & np.isfinite(ex) & np.isfinite(ind)
            nan = float("nan")
            rows.append({
                "method": method, "sigma_periods": sp, "interior": float(ok.mean()), "valid": float(res.valid.mean()),
                "ratio_stack": _rms_ratio(an, ex, ok) if ok.any() else nan,
                "ratio_independent": _rms_ratio(an, ind, ok) if ok.any() else nan,
                "p95_abs_mD": float(np.percentile(np.abs(an[ok]), 95)) if ok.any() else nan,
                "truth_p95_abs_mD": float(np.percentile(np.abs(ex[ok]), 95)) if ok.any() else nan,
                "analyze_s": time.perf_counter() - t0, "warnings": list(res.warnings),
            })
    return rows


HEADER = (("| ripple, periods | sigma, periods | method | ratio (stack) | ratio (indep.) | p95 abs phi_eff, mD "
           "(truth) | interior | valid |"), "|---|---|---|---|---|---|---|---|")


def row(r: dict) -> str:
    """One record's line of the table (``r["periods"]`` None: the dome alone)."""
    n = r["periods"]
    return (f"| {'dome alone' if n is None else f'{n:g}'} | {r['sigma_periods']:g} | {r['method']} | "
            f"{r['ratio_stack']:.4f} | {r['ratio_independent']:.4f} | {r['p95_abs_mD']:.4f} "
            f"({r['truth_p95_abs_mD']:.4f}) | {100 * r['interior']:.0f}% | {100 * r['valid']:.0f}% |")


def table(recs: list[dict]) -> str:
    """The markdown table of a run's records (what ``--out`` writes)."""
    return "\n".join([*HEADER, *(row(r) for r in recs)])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scale", type=float, default=0.5)
    ap.add_argument("--periods", type=float, nargs="+", default=[2.5, 3, 4, 6, 10])
    ap.add_argument("--sigma", type=float, nargs="+", default=[1, 2, 3])
    ap.add_argument("--peak-pitch", type=float, default=0.35)
    ap.add_argument("--dome", action="store_true", help="a pillow dome under the ripple")
    ap.add_argument("--dome-only", action="store_true", help="the pillow dome alone (N = 4)")
    ap.add_argument("--dome-pitch", type=float, default=0.35)
    ap.add_argument("--degree", type=int)
    ap.add_argument("--passes", type=int, help="deformation_passes (default: the analyzer's)")
    ap.add_argument("--params", default="{}", help="analyzer parameter overrides, JSON")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    dome = a.dome_pitch if (a.dome or a.dome_only) else None
    degree = a.degree if a.degree is not None else (4 if dome else 2)
    cases = [None] if a.dome_only else a.periods
    overrides = {**json.loads(a.params), **({} if a.passes is None else {"deformation_passes": a.passes})}
    lines = list(HEADER)
    print("\n".join(lines), flush=True)
    recs = []
    for n in cases:
        scene = _scene(n, a.peak_pitch, dome, a.scale)
        for r in run_case(scene, a.sigma, degree, overrides):
            r["periods"] = n
            recs.append(r)
            line = row(r)
            lines.append(line)
            print(line, flush=True)
    if a.out:
        write_record(a.out, "bench_strong_ripples.py", argv, "\n".join(lines), {"records": recs})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
