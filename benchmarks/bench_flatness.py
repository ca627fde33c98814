"""Speed of the height integrator (glassdist.flatness.integrate): conjugate gradients with the DCT preconditioner
against the sparse direct factorisation, on masked grids the size of analysis grids.

Each grid: a rectangle less a rectangular hole, cut by a disc, its top eighth removed, and a separate island;
smooth random slopes. Both solvers on the same equations; their largest difference is recorded.

Usage::

    python benchmarks/bench_flatness.py [--sizes 150x200 300x400 600x800]

Writes benchmarks/flatness_results.json (the command, the machine's CPU count, one row per grid).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

import glassdist.flatness.integrate as integ

OUT = Path(__file__).resolve().with_name("flatness_results.json")


def _grid(h: int, w: int):
    m = np.ones((h, w), bool)
    m[h // 3:h // 2, w // 3:w // 2] = False
    r, c = np.indices((h, w))
    m &= np.hypot(r - h / 2, c - w / 2) < 0.55 * max(h, w)
    m[: h // 8, :] = False
    m[5:15, 5:25] = True
    g = np.random.default_rng(0).normal(size=(h, w))
    return m, ndimage.gaussian_filter(g, 3), ndimage.gaussian_filter(np.roll(g, 7, 0), 3)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", default=["150x200", "300x400", "600x800"])
    args = ap.parse_args(argv)
    rows = []
    for size in args.sizes:
        h, w = (int(v) for v in size.split("x"))
        mask, gx, gy = _grid(h, w)
        limit, integ.DIRECT_MAX_SAMPLES = integ.DIRECT_MAX_SAMPLES, 0  # the conjugate gradients at every size
        try:
            t = time.perf_counter()
            z_cg = integ.integrate_slope(gx, gy, mask, (1.0, 1.2))
            t_cg = time.perf_counter() - t
        finally:
            integ.DIRECT_MAX_SAMPLES = limit
        real = integ._solve_cg
        integ._solve_cg = lambda *a, **k: None  # the direct fallback
        try:
            t = time.perf_counter()
            z_direct = integ.integrate_slope(gx, gy, mask, (1.0, 1.2))
            t_direct = time.perf_counter() - t
        finally:
            integ._solve_cg = real
        rows.append({"grid": [h, w], "samples": int(mask.sum()), "cg_s": round(t_cg, 3), "direct_s": round(t_direct, 3),
                     "max_difference_rel": float(np.nanmax(np.abs(z_cg - z_direct)) / np.nanstd(z_direct))})
        print(rows[-1])
    cmd = "python benchmarks/bench_flatness.py " + " ".join(argv if argv is not None else os.sys.argv[1:])
    OUT.write_text(json.dumps({"command": cmd.strip(), "cpus": os.cpu_count(), "runs": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
