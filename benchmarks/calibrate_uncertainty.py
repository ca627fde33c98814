"""Calibration of the per-pixel standard uncertainty against Monte Carlo noise realisations.

For each scene (pattern, carrier period, noise level, reporting sigma, method) the same
synthetic capture (a roller wave) is analysed with ``--n`` independent noise
realisations (the reference gets its own noise too). Per pixel trusted in every
realisation, the empirical standard deviation of ``phi_eff_mD``, ``phi_shear_mD`` and
both components of ``displacement_mm`` over the realisations is divided by the mean of
the predicted ``*_sigma_*`` field; the table gives the median ratio (and the 10th-90th
percentile range over the pixels). A calibrated prediction has median ratios within
0.8-1.25. The noise level the analyzer estimated from each photo is shown against the
true one. Direct Method displacement: Block I's baseline (the homography) moves with the
noise too, an image-wide smooth term the per-pixel uncertainty does not include; it is
removed per realisation (the best-fit change of homography over the trusted pixels: affine
per component plus the two shared projective terms) before the comparison.

Usage::

    python benchmarks/calibrate_uncertainty.py [--n 30] [--size 256] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

FIELDS = {"phi_eff": "phi_eff_mD", "phi_shear": "phi_shear_mD", "disp_x": ("displacement_mm", 0),
          "disp_y": ("displacement_mm", 1)}
SIGMAS = {"phi_eff": "phi_eff_sigma_mD", "phi_shear": "phi_shear_sigma_mD", "disp_x": ("displacement_sigma_mm", 0),
          "disp_y": ("displacement_sigma_mm", 1)}


def _get(res, key):
    if isinstance(key, tuple):
        return getattr(res, key[0])[..., key[1]]
    return getattr(res, key)


def scenes(quick: bool = False):
    """(name, pattern, period_px, noise_std, sigma_periods, method)."""
    grid = itertools.product(("lines", "checkerboard"), (8.0, 12.0), (0.02, 0.05), (2.0, 3.0), ("comparative", "direct"))
    out = [(f"{pat} p{per:g} n{noise:g} s{sig:g} {meth}", pat, per, noise, sig, meth) for pat, per, noise, sig, meth in grid]
    return out[::4] if quick else out


def calibrate(pattern, period_px, noise, sigma_periods, method, *, n=30, size=256, seed=0) -> dict:
    from glassdist import analyze
    from glassdist.experiments.transfer import minus_homography_change
    from glassdist.synthetic import synthetic_capture, wave_displacement

    pitch = period_px / (np.sqrt(2.0) if pattern == "checkerboard" else 1.0)  # mm, at 1 mm/px
    p_c = period_px
    disp = wave_displacement(0.05 * p_c, 12.0 * p_c, 25.0)
    params = {"pattern": pattern, "sigma_mm": sigma_periods * p_c, "detrend_degree": 2}
    stacks = {k: [] for k in FIELDS}
    preds = {k: [] for k in FIELDS}
    trusted = None
    noise_est = []
    rng = np.random.default_rng(seed)
    for _ in range(n):
        cap = synthetic_capture((size, size), pitch_mm=pitch, mm_per_px=1.0, pattern=pattern, displacement=disp,
                                noise_std=noise, rng=rng)
        res = analyze(cap.image, pitch_mm=pitch, distance_m=1.0, reference=cap.reference if method == "comparative" else None,
                      params=params)
        trusted = res.trusted.copy() if trusted is None else trusted & res.trusted
        noise_est.append(res.noise_std[0])
        d_mm = res.displacement_mm.astype(float)
        if method == "direct":
            # Block I's baseline moves with the noise too: an image-wide smooth term outside
            # the per-pixel uncertainty, removed per realisation (best-fit change of homography).
            d_mm = minus_homography_change(d_mm, res.trusted)
        for k in FIELDS:
            val = d_mm[..., FIELDS[k][1]] if isinstance(FIELDS[k], tuple) else _get(res, FIELDS[k]).astype(float)
            stacks[k].append(val)
            preds[k].append(_get(res, SIGMAS[k]).astype(float))
    rec = {"pattern": pattern, "period_px": period_px, "noise_std": noise, "sigma_periods": sigma_periods, "method": method,
           "realisations": n, "size_px": size, "trusted_pixels": int(trusted.sum()),
           "noise_estimated": float(np.median(noise_est))}
    for k in FIELDS:
        emp = np.std(np.stack(stacks[k]), axis=0, ddof=1)[trusted]
        pred = np.mean(np.stack(preds[k]), axis=0)[trusted]
        r = emp / pred
        rec[k] = {"median_ratio": float(np.median(r)), "p10": float(np.percentile(r, 10)), "p90": float(np.percentile(r, 90)),
                  "median_sigma": float(np.median(pred))}
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--n", type=int, default=30, help="noise realisations per scene")
    ap.add_argument("--size", type=int, default=256, help="image size, px")
    ap.add_argument("--quick", action="store_true", help="every fourth scene only")
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    recs = []
    print("| scene | noise est. | φ_eff σ mD | φ_eff ratio | φ_shear ratio | δ_x ratio | δ_y ratio |")
    print("|---|---|---|---|---|---|---|")
    for name, *args in scenes(a.quick):
        r = calibrate(*args, n=a.n, size=a.size)
        recs.append(r)
        cell = lambda k: f"{r[k]['median_ratio']:.2f} ({r[k]['p10']:.2f}-{r[k]['p90']:.2f})"  # noqa: E731
        print(f"| {name} | {r['noise_estimated']:.4f} | {r['phi_eff']['median_sigma']:.3g} | {cell('phi_eff')} | "
              f"{cell('phi_shear')} | {cell('disp_x')} | {cell('disp_y')} |", flush=True)
    if a.out:
        args = shlex.join(argv if argv is not None else sys.argv[1:])
        a.out.write_text(json.dumps({"command": f"python benchmarks/calibrate_uncertainty.py {args}".strip(), "records": recs,
                                     "seconds": time.perf_counter() - t0}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
