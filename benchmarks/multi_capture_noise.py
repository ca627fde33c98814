"""Noise of the averaged map against the number of captures (``glassdist.analyze_captures``).

Flat glass (no distortion), synthetic line grid (8 px carrier period, 5 mm pitch, 256 x 320
px), independent Gaussian photo noise per capture (seeded). For n = 1, 2, 4, 8 captures the
table gives std(phi_eff) over the region all n captures cover (mD; the n = 1 value is the RMS
over all eight single captures) and the slope of log std against log n (-0.5 for 1/sqrt(n)). Rows: the
Direct Method; the Comparative Method with a noise-free reference; the Comparative Method
with one noisy reference shared by every capture (its noise does not average down). A last
row registers captures taken after camera moves (0.4-1.8 carrier periods, up to 0.4 deg).

Usage::

    python benchmarks/multi_capture_noise.py            # ~1 min on two cores; prints a markdown table
"""

from __future__ import annotations

import argparse
import logging

import numpy as np

from glassdist import analyze, analyze_captures
from glassdist.synthetic import synthetic_capture

PITCH, MMPX, L = 5.0, 0.625, 2.0
NS = (1, 2, 4, 8)


def _camera(tx: float, ty: float, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, tx], [s, c, ty], [0.0, 0.0, 1.0]])


def row(method: str, noise_std: float, *, reference_noise: bool = False, moved: bool = False, shape=(256, 320)) -> dict:
    params = {"detrend_degree": 2, "sigma_mm": PITCH}
    ref = None
    if method == "comparative":
        ref = synthetic_capture(shape, pitch_mm=PITCH, mm_per_px=MMPX, noise_std=noise_std if reference_noise else 0.0,
                                rng=999).reference
    rng = np.random.default_rng(5)
    moves = [(0.0, 0.0, 0.0)] + [tuple(rng.uniform([-7, -7, -0.4], [7, 7, 0.4])) for _ in range(max(NS) - 1)]
    caps = [synthetic_capture(shape, pitch_mm=PITCH, mm_per_px=MMPX, noise_std=noise_std, rng=100 + i,
                              homography=_camera(*moves[i]) if moved else None).image for i in range(max(NS))]
    singles = [analyze(c, pitch_mm=PITCH, distance_m=L, reference=ref, params=params) for c in caps]
    std = [float(np.sqrt(np.mean([np.var(r.phi_eff_mD[r.valid]) for r in singles])))]
    for n in NS[1:]:
        res = analyze_captures(caps[:n], pitch_mm=PITCH, distance_m=L, reference=ref, params=params)
        every = res.valid & (res.capture_count == n)  # where all n captures overlap
        std.append(float(np.std(res.phi_eff_mD[every])))
    slope = float(np.polyfit(np.log(NS), np.log(std), 1)[0])
    return {"method": method, "noise": noise_std, "reference_noise": reference_noise, "moved": moved, "std": std, "slope": slope}


def main() -> None:
    logging.basicConfig(level=logging.ERROR)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("--moved-only", action="store_true", help="only the row with camera moves")
    args = p.parse_args()
    rows = [row("direct", 0.05, moved=True)]
    if not args.moved_only:
        rows = [row("direct", 0.02), row("direct", 0.05), row("direct", 0.10), row("comparative", 0.05),
                row("comparative", 0.05, reference_noise=True)] + rows
    print("| method | photo noise | reference | camera | " + " | ".join(f"n = {n}" for n in NS) + " | slope |")
    print("|---|---|---|---|" + "---|" * len(NS) + "---|")
    for r in rows:
        ref = "" if r["method"] == "direct" else ("noisy (shared)" if r["reference_noise"] else "noise-free")
        print(f"| {r['method']} | {r['noise']:.2f} | {ref} | {'moved' if r['moved'] else 'fixed'} | "
              + " | ".join(f"{s:.3f}" for s in r["std"]) + f" | {r['slope']:.3f} |")


if __name__ == "__main__":
    main()
