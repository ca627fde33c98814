"""How much of a Direct Method reading is its homography's: the accuracy scenes read with Block I's own A1 Jacobian and with the glass-less grid's.

The Direct Method takes its gradients with respect to backdrop mm through the Jacobian of the
homography Block I fits on the photo itself, through the glass. Where the glass stretches the
grid over the part of the view that fit relies on, the homography takes some of that stretch
(a uniform power is a magnification), and every gradient is scaled with it. For each scene of
the accuracy experiment (``glassdist.experiments.accuracy``) this prints φ_eff / φ_shear over the
trusted region and 1 σ inside it, against the exact truth, for the Comparative Method, the Direct
Method, and the Direct Method's own phases with the Comparative Method's A1 Jacobian (the
homography of the glass-less reference) in place of its own; and the ratio of the two
homographies' area scales at the view's centre. ``--ripple PERIODS SIGMA`` does the same for one
cell of ``benchmarks/bench_strong_ripples.py`` (its ratios over the interior, through the stack and
through the independent evaluation). A diagnostic, not a method: a user of the Direct Method has
no reference::

    python benchmarks/direct_baseline_share.py [--scenes wavy_slab_A0.5,biconvex_lens_p48,biconvex_lens_p64]
    python benchmarks/direct_baseline_share.py --scenes "" --ripple 4 3
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    from glassdist.analyzer import pipeline
    from glassdist.analyzer.homography import logical_jacobian
    from glassdist.experiments import accuracy
    from glassdist.experiments._common import RunOptions

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="wavy_slab_A0.5,biconvex_lens_p48,biconvex_lens_p64")
    ap.add_argument("--ripple", type=float, nargs=2, metavar=("PERIODS", "SIGMA"),
                    help="also one cell of bench_strong_ripples.py (peak 0.35 period, scale 0.5, N = 2)")
    a = ap.parse_args(argv)
    names = [n for n in a.scenes.split(",") if n]
    opts = RunOptions()
    measure = pipeline._measure
    held = {}

    def keep(*args, **kwargs):  # the Comparative Method's measurement: its reference's homography
        held["m"] = measure(*args, **kwargs)
        return held["m"]

    if names:
        print("| scene | run | φ_eff | φ_shear | φ_eff 1 σ inside | φ_shear 1 σ inside |\n|---|---|---|---|---|---|")
    for name in names:
        kind, build, _ = accuracy.SCENES[name]
        scene = opts.prepare(build())
        (_, inputs), = list(opts.render_each([scene], reference=True))
        params = accuracy.analysis_params(scene)
        runs, baselines = {}, {}
        try:
            for method in ("comparative", "direct"):
                pipeline._measure = keep
                runs[method] = accuracy.measure(inputs, method, params, kind)
                baselines[method] = held["m"].baseline
            pipeline._measure = lambda *a, **k: replace(measure(*a, **k), baseline=baselines["comparative"])
            runs["direct, the reference's A1 Jacobian"] = accuracy.measure(inputs, "direct", params, kind)
        finally:
            pipeline._measure = measure
        for run_name, run in runs.items():
            r, i = run["ratios_vs_exact"], run["interior"]["ratios_vs_exact"]
            print(f"| {name} | {run_name} | {r['phi_eff']:.4f} | {r['phi_shear']:.4f} | {i['phi_eff']:.4f} | "
                  f"{i['phi_shear']:.4f} |")
        h, w = inputs.distorted.shape[:2]
        area = {m: abs(np.linalg.det(logical_jacobian(H, None, np.array([(w - 1) / 2]), np.array([(h - 1) / 2]))
                                     .reshape(2, 2))) for m, H in baselines.items()}
        print(f"| {name} | area scale of the grid at the centre, Direct / reference | "
              f"{area['direct'] / area['comparative']:.4f} | | | |")
    if a.ripple:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import bench_strong_ripples as ripples

        n, sp = a.ripple
        scene = ripples._scene(n, 0.35, None, 0.5)
        print("\n| ripple, periods | sigma, periods | run | ratio (stack) | ratio (indep.) |\n|---|---|---|---|---|")
        for swap in (False, True):
            def one(*args, swap=swap, **kwargs):
                m = measure(*args, **kwargs)
                if m.fit is None:
                    held["comparative"] = m.baseline
                return replace(m, baseline=held["comparative"]) if swap and m.fit is not None else m
            pipeline._measure = one
            try:
                rows = ripples.run_case(scene, [sp], 2, None)
            finally:
                pipeline._measure = measure
            for r in rows if not swap else rows[1:]:
                what = r["method"] + (", the reference's A1 Jacobian" if swap else "")
                print(f"| {n:g} | {sp:g} | {what} | {r['ratio_stack']:.4f} | {r['ratio_independent']:.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
