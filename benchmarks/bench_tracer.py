"""Speed of the exact ray tracer.

Measures, in one run on this machine:
* rays per second of the core tracer (heightfield Newton intersections + vector Snell at
  both faces + backdrop landing), on the shipped wavy-slab scene;
* wall time of a full render (jittered stratified supersampling, box-filtered backdrop)
  of the wavy slab at SIZE x SIZE px and SPP samples per pixel, with and without glass.

Usage::

    python benchmarks/bench_tracer.py [--size 1024] [--spp 16] [--repeat 1]

Prints one JSON record. Thread count follows the NumPy build (set OMP_NUM_THREADS to pin it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from glassdist.render import render_scene, trace_rays
from glassdist.scene import load_scene, pixel_directions

SCENE = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "wavy_slab.yaml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()

    scene = load_scene(SCENE).with_changes(
        camera={"pixels": [args.size, args.size]}, render={"samples_per_pixel": args.spp, "seed": 0}
    )
    rng = np.random.default_rng(0)
    n_rays = 1 << 20
    cols = rng.uniform(0, args.size, n_rays)
    rows = rng.uniform(0, args.size, n_rays)
    dirs = pixel_directions(scene.camera, cols, rows)
    t0 = time.perf_counter()
    trace_rays(scene, dirs)
    t_trace = time.perf_counter() - t0

    renders, refs = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        render_scene(scene)
        renders.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        render_scene(scene, reference=True)
        refs.append(time.perf_counter() - t0)
    total_rays = args.size * args.size * args.spp
    print(json.dumps({
        "machine": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "trace_rays_per_s": n_rays / t_trace,
        "render_size_px": args.size,
        "samples_per_pixel": args.spp,
        "render_s": min(renders),
        "render_rays_per_s": total_rays / min(renders),
        "reference_render_s": min(refs),
    }, indent=2))


if __name__ == "__main__":
    main()
