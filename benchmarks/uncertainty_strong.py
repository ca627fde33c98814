"""Per-pixel uncertainty against repeated single captures of a strong roller wave (F5 runs).

The scene of ``tests/test_analyzer_deform.py``: a roller wave of strain 0.31 (amplitude
4 mm, wavelength 80 mm, 30 deg) on an 8 px line grid, 320 x 400 px at 1 mm/px, analysed at
``sigma_mm`` = 16, ``detrend_degree`` = 1 (``--degree``), L = 10 m. ``--n`` independent noise
realisations of the same scene (seeded generators; the reference gets its own noise too)
are analysed by both methods. Per pixel trusted in every realisation, the empirical
standard deviation of ``phi_eff_mD``, ``phi_shear_mD`` and both components of
``displacement_mm`` over the realisations is divided by the mean predicted ``*_sigma_*``
field, nothing removed between realisations; the table gives the median ratio (and the
10th-90th percentile range over the pixels). A calibrated prediction reads 0.8-1.25.

``--minus-projective`` also gives, for the Direct Method, the ratios after removing per
realisation what a change of Block I's homography puts in the maps: from the displacement
its best fit by a change of homography (``calibrate_uncertainty.py``'s correction), from
phi_eff its best-fit plane (a change of homography moves the displacement by an affine term
plus two quadratic ones; the degree-1 detrend takes the affine, the strain of the rest is a
plane to first order). phi_shear is left as it is (a magnitude). What the removal takes
out is the part of the scatter that is Block I's baseline.

Usage::

    python benchmarks/uncertainty_strong.py [--n 16] [--noise 0.03] [--amplitude 4] [--size 320 400]
        [--seed 0] [--degree 1] [--methods comparative direct] [--minus-projective] [--out FILE.json]

``docs/records/uncertainty_strong.json`` holds the run with ``--minus-projective`` (figures and
discussion: ``docs/explanation/transfer-function.md``, "With image deformation (F5)").
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

FIELDS = ("phi_eff", "phi_shear", "disp_x", "disp_y")


def _value(res, k: str) -> np.ndarray:
    if k.startswith("disp"):
        return res.displacement_mm[..., "xy".index(k[-1])].astype(float)
    return getattr(res, f"{k}_mD").astype(float)


def _sigma(res, k: str) -> np.ndarray:
    if k.startswith("disp"):
        return res.displacement_sigma_mm[..., "xy".index(k[-1])].astype(float)
    return getattr(res, f"{k}_sigma_mD").astype(float)


def _minus_plane(f: np.ndarray, region: np.ndarray) -> np.ndarray:
    """``f`` less its least-squares plane over ``region``."""
    yy, xx = np.mgrid[0 : f.shape[0], 0 : f.shape[1]]
    A = np.stack([np.ones(int(region.sum())), xx[region], yy[region]], axis=1)
    coef, *_ = np.linalg.lstsq(A, f[region], rcond=None)
    return f - (coef[0] + coef[1] * xx + coef[2] * yy)


def realisations(method: str, *, n: int = 16, noise: float = 0.03, shape=(320, 400), seed: int = 0,
                 amplitude_mm: float = 4.0, degree: int = 1):
    """Analyse ``n`` noise realisations of the strong wave; yields each result."""
    from glassdist import analyze
    from glassdist.synthetic import synthetic_capture, wave_displacement

    disp = wave_displacement(amplitude_mm, 80.0, 30.0)
    params = {"pattern": "lines", "sigma_mm": 16.0, "detrend_degree": degree}
    for i in range(n):
        cap = synthetic_capture(tuple(shape), pitch_mm=8.0, mm_per_px=1.0, displacement=disp, noise_std=noise,
                                rng=np.random.default_rng([seed, i]))
        yield analyze(cap.image, pitch_mm=8.0, distance_m=10.0,
                      reference=cap.reference if method == "comparative" else None, params=params)


def ratios(results, *, minus_projective: bool = False) -> dict:
    """Median (p10, p90) over the pixels trusted in every result of empirical std / mean predicted sigma."""
    results = list(results)
    trusted = np.logical_and.reduce([r.trusted for r in results])
    out = {"realisations": len(results), "trusted_pixels": int(trusted.sum()),
           "demodulations": sorted({int(r.demodulations) for r in results}),
           "noise_estimated": float(np.median([r.noise_std[0] for r in results]))}
    vals = {k: [_value(r, k) for r in results] for k in FIELDS}
    if minus_projective:
        from glassdist.experiments.transfer import minus_homography_change

        disp = [minus_homography_change(r.displacement_mm, r.trusted) for r in results]
        vals["disp_x"], vals["disp_y"] = [d[..., 0] for d in disp], [d[..., 1] for d in disp]
        vals["phi_eff"] = [_minus_plane(v, r.trusted) for v, r in zip(vals["phi_eff"], results)]
    for k in FIELDS:
        emp = np.std(np.stack(vals[k]), axis=0, ddof=1)[trusted]
        pred = np.mean(np.stack([_sigma(r, k) for r in results]), axis=0)[trusted]
        q = emp / pred
        out[k] = {"median_ratio": float(np.median(q)), "p10": float(np.percentile(q, 10)),
                  "p90": float(np.percentile(q, 90)), "median_sigma": float(np.median(pred))}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--n", type=int, default=16, help="noise realisations per method")
    ap.add_argument("--noise", type=float, default=0.03, help="noise std, full scale 1")
    ap.add_argument("--size", type=int, nargs=2, default=(320, 400), metavar=("H", "W"), help="image size, px")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--amplitude", type=float, default=4.0, help="wave amplitude, mm (4: strain 0.31)")
    ap.add_argument("--degree", type=int, default=1, help="detrend degree N (the Direct Method's default is 2)")
    ap.add_argument("--methods", nargs="+", default=("comparative", "direct"), choices=("comparative", "direct"))
    ap.add_argument("--minus-projective", action="store_true",
                    help="Direct: also the ratios with Block I's baseline removed per realisation (module docstring)")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    recs = {}
    print("| method | trusted px | φ_eff σ mD | φ_eff | φ_shear | δ_x | δ_y |")
    print("|---|---|---|---|---|---|---|")
    for method in a.methods:
        res = list(realisations(method, n=a.n, noise=a.noise, shape=a.size, seed=a.seed, amplitude_mm=a.amplitude,
                               degree=a.degree))
        rows = [("", ratios(res))]
        if a.minus_projective and method == "direct":
            rows.append((" (projective removed)", ratios(res, minus_projective=True)))
        for tag, r in rows:
            recs[method + tag.replace(" (projective removed)", "_minus_projective")] = r
            cell = lambda k: f"{r[k]['median_ratio']:.2f} ({r[k]['p10']:.2f}-{r[k]['p90']:.2f})"  # noqa: E731
            print(f"| {method}{tag} | {r['trusted_pixels']} | {r['phi_eff']['median_sigma']:.3g} | {cell('phi_eff')} | "
                  f"{cell('phi_shear')} | {cell('disp_x')} | {cell('disp_y')} |", flush=True)
    secs = time.perf_counter() - t0
    print(f"{secs:.0f} s")
    if a.out:
        args = shlex.join(argv if argv is not None else sys.argv[1:])
        a.out.write_text(json.dumps({"command": f"python benchmarks/uncertainty_strong.py {args}".strip(), "records": recs,
                                     "seconds": secs}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
