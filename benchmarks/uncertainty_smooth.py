"""Per-pixel uncertainty of phi_eff against repeated single captures of a smooth ray-traced pane.

A pillowed pane (1.5 mm dome, 10 mm glass) with two mild local thickness defects (Gaussian, 10
and -8 um) on its front face, seen through a 96.9 mm line grid at L = 10 m from 5 m (f 300 mm,
18 x 14 carrier periods in view, 16 px per period); ``--strong``: a 6 mm dome and a 200 mm
roller wave (30 um) on the front face too. One exact render (``--spp`` samples per pixel: its
sampling noise is the same in every capture, so it is kept small), then ``--n`` captures,
each with its own white noise of ``--noise`` (full scale 1; the reference gets its own in the
Comparative Method). Both methods, sigma 1-3 carrier periods, detrend degree N 1-4. Per pixel
trusted in every capture: the median over the pixels of the predicted ``phi_eff_sigma_mD``
(mean over the captures) over the empirical standard deviation of ``phi_eff_mD``, nothing
removed between captures. A calibrated prediction reads 0.8-1.25. The noise the Analyzer
estimated from the photo is shown against the true one: the prediction scales with it.

Usage::

    python benchmarks/uncertainty_smooth.py [--strong] [--n 12] [--noise 0.01] [--spp 64]
        [--sigma 1 2 3] [--degree 1 2 4] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _record import write_record  # noqa: E402

PITCH_MM = 96.9


def scene(strong: bool, spp: int, px_per_period: int = 16):
    from glassdist.scene.model import Scene

    size = [900, 750]
    front = [{"kind": "gaussian", "amplitude_mm": 0.01, "sigma_mm": 40, "center_mm": [-90, 40]},
             {"kind": "gaussian", "amplitude_mm": -0.008, "sigma_mm": 55, "center_mm": [110, -60]}]
    if strong:
        front.append({"kind": "roller_wave", "amplitude_mm": 0.03, "wavelength_mm": 200, "direction_deg": 25})
    return Scene.model_validate({
        "name": "smooth_pane_strong" if strong else "smooth_pane",
        "pane": {"size_mm": size, "thickness_mm": 10, "refractive_index": 1.52, "center_mm": [0, 0, 0],
                 "deformation": {"both": [{"kind": "pillow", "amplitude_mm": 6.0 if strong else 1.5, "size_mm": size}],
                                 "front": front}},
        "backdrop": {"pattern": "lines", "pitch_mm": PITCH_MM, "line_width_mm": 24, "distance_m": 10},
        "camera": {"focal_length_mm": 300, "sensor_width_mm": 18 * PITCH_MM * 300 / 15000,
                   "pixels": [18 * px_per_period, 14 * px_per_period], "position_mm": [0, 0, -5000]},
        "render": {"samples_per_pixel": spp, "seed": 3},
    })


def run_case(inputs, method: str, sigma_periods: float, degree: int, *, n: int, noise: float, seed: int = 1) -> dict:
    from glassdist import analyze
    from glassdist.theory import analysis_params

    rng = np.random.default_rng(seed)
    params = analysis_params(inputs.scene, detrend_degree=degree, sigma_mm=sigma_periods * PITCH_MM)
    vals, preds, est, trusted = [], [], [], None
    t0 = time.perf_counter()
    for _ in range(n):
        img = inputs.distorted + rng.normal(0.0, noise, inputs.distorted.shape)
        ref = inputs.reference + rng.normal(0.0, noise, inputs.reference.shape) if method == "comparative" else None
        res = analyze(img, pitch_mm=PITCH_MM, distance_m=inputs.scene.backdrop.distance_m, reference=ref, params=params)
        trusted = res.trusted.copy() if trusted is None else trusted & res.trusted
        vals.append(res.phi_eff_mD.astype(float))
        preds.append(res.phi_eff_sigma_mD.astype(float))
        est.append(res.noise_std[0])
    emp = np.std(np.stack(vals), axis=0, ddof=1)[trusted]
    pred = np.mean(np.stack(preds), axis=0)[trusted]
    r = pred / emp
    return {"method": method, "sigma_periods": sigma_periods, "degree": degree, "captures": n,
            "trusted": float(trusted.mean()), "median_pred_over_emp": float(np.median(r)),
            "p10": float(np.percentile(r, 10)), "p90": float(np.percentile(r, 90)),
            "noise": noise, "noise_estimated": float(np.median(est)), "seconds": time.perf_counter() - t0}


HEADER = ("| method | sigma, periods | N | pred / emp (p10-p90) | noise est. (true) | trusted |", "|---|---|---|---|---|---|")


def row(r: dict) -> str:
    return (f"| {r['method']} | {r['sigma_periods']:g} | {r['degree']} | {r['median_pred_over_emp']:.2f} "
            f"({r['p10']:.2f}-{r['p90']:.2f}) | {r['noise_estimated']:.4f} ({r['noise']:g}) | {100 * r['trusted']:.0f}% |")


def main(argv=None) -> int:
    from glassdist.experiments._common import render_inputs

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--strong", action="store_true")
    ap.add_argument("--n", type=int, default=12)
    ap.add_argument("--noise", type=float, default=0.01)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--sigma", type=float, nargs="+", default=[1, 2, 3])
    ap.add_argument("--degree", type=int, nargs="+", default=[1, 2, 4])
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    inputs = render_inputs(scene(a.strong, a.spp), engine="exact", reference=True)
    lines, recs = list(HEADER), []
    print("\n".join(lines), flush=True)
    for method in ("comparative", "direct"):
        for s in a.sigma:
            for d in a.degree:
                r = run_case(inputs, method, s, d, n=a.n, noise=a.noise)
                recs.append(r)
                lines.append(row(r))
                print(lines[-1], flush=True)
    if a.out:
        write_record(a.out, "uncertainty_smooth.py", argv, "\n".join(lines), {"records": recs})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
