"""How much of a Direct Method reading is its homography's.

The accuracy scenes read with Block I's own A1 Jacobian and with the glass-less grid's.

The Direct Method takes its gradients with respect to backdrop mm through the Jacobian of the
homography Block I fits on the photo itself, through the glass. Where the glass stretches the
grid over the part of the view that fit relies on, the homography takes some of that stretch
(a uniform power is a magnification), and every gradient is scaled with it. For each scene of
the accuracy experiment (``glassdist.experiments.accuracy``) this prints φ_eff / φ_shear over the
trusted region and 1 σ inside it, against the exact truth, for the Comparative Method, the Direct
Method, and the Direct Method's own phases with the Comparative Method's A1 Jacobian (the
homography of the glass-less reference) in place of its own; and the ratio of the two
homographies' area scales at the view's centre. ``--also`` adds Direct runs with one of Block I's
inputs replaced: ``reference-carriers`` (F1's carriers of the glass-less reference instead of the
photo's own) and ``zero-offsets`` (every part of the region joins the baseline at the integer
offset its unwrapping gave it, instead of Block I's choice: the offsets read from the largest part's
homography, or, where those are ambiguous, the largest part alone); ``a+b`` replaces both.
``--ripple PERIODS SIGMA`` does the same for one
cell of ``benchmarks/bench_strong_ripples.py`` (its ratios over the interior, through the stack and
through the independent evaluation). A diagnostic, not a method: a user of the Direct Method has
no reference::

    python benchmarks/direct_baseline_share.py [--scenes wavy_slab_A0.5,biconvex_lens_p48,biconvex_lens_p64]
    python benchmarks/direct_baseline_share.py --scenes "" --ripple 4 3
    python benchmarks/direct_baseline_share.py --scenes wavy_slab_A0.75 \
        --also reference-carriers,zero-offsets,reference-carriers+zero-offsets
"""

from __future__ import annotations

import argparse
import sys
from contextlib import ExitStack, contextmanager
from dataclasses import replace
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    from glassdist.analyzer import fourier, homography, pipeline
    from glassdist.analyzer.homography import logical_jacobian
    from glassdist.experiments import accuracy
    from glassdist.experiments._common import RunOptions

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="wavy_slab_A0.5,biconvex_lens_p48,biconvex_lens_p64")
    ap.add_argument("--ripple", type=float, nargs=2, metavar=("PERIODS", "SIGMA"),
                    help="also one cell of bench_strong_ripples.py (peak 0.35 period, scale 0.5, N = 2)")
    ap.add_argument("--also", default="", help="comma-separated: reference-carriers, zero-offsets, or both joined by +")
    a = ap.parse_args(argv)
    names = [n for n in a.scenes.split(",") if n]
    also = [x for x in a.also.split(",") if x]
    opts = RunOptions()
    measure = pipeline.measure
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
                pipeline.measure = keep
                runs[method] = accuracy.measure(inputs, method, params, kind)
                baselines[method] = held["m"].baseline
            pipeline.measure = lambda *a, **k: replace(measure(*a, **k), baseline=baselines["comparative"])
            runs["direct, the reference's A1 Jacobian"] = accuracy.measure(inputs, "direct", params, kind)
        finally:
            pipeline.measure = measure
        for what in also:  # "a+b": both replaced at once
            with ExitStack() as stack:
                for part in what.split("+"):
                    stack.enter_context(_replaced(part, inputs, fourier, homography))
                runs[f"direct, {what}"] = accuracy.measure(inputs, "direct", params, kind)
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
            pipeline.measure = one
            try:
                rows = ripples.run_case(scene, [sp], 2, None)
            finally:
                pipeline.measure = measure
            for r in rows if not swap else rows[1:]:
                what = r["method"] + (", the reference's A1 Jacobian" if swap else "")
                print(f"| {n:g} | {sp:g} | {what} | {r['ratio_stack']:.4f} | {r['ratio_independent']:.4f} |")
    return 0


@contextmanager
def _replaced(what, inputs, fourier, homography):
    """One of Block I's inputs replaced for the length of a Direct run (see the module's docstring)."""
    if what == "reference-carriers":
        ref = fourier.find_carriers(fourier.compute_spectrum(np.asarray(inputs.reference, float)))
        find = fourier.find_carriers

        def carriers(spectrum, **kwargs):  # the photo's own pair, each carrier moved to the reference's nearest
            own = find(spectrum, **kwargs)
            cands = (ref.k1, ref.k2, ref.k1.negated(), ref.k2.negated())
            near = [min(cands, key=lambda r, c=c: np.hypot(r.fx - c.fx, r.fy - c.fy)) for c in (own.k1, own.k2)]
            return fourier.CarrierPair(*(replace(r, strength=c.strength) for r, c in zip(near, (own.k1, own.k2))))

        fourier.find_carriers = carriers
        try:
            yield
        finally:
            fourier.find_carriers = find
    elif what == "zero-offsets":
        fit_grid, inverse = homography.fit_grid_homography, homography.apply_inverse

        def fit(UV, yy, xx, *args, **kwargs):  # the offsets are read against apply_inverse(H, xx, yy): make it U, V
            homography.apply_inverse = lambda H, x, y: (UV[0], UV[1]) if (x is xx and y is yy) else inverse(H, x, y)
            try:
                return fit_grid(UV, yy, xx, *args, **kwargs)
            finally:
                homography.apply_inverse = inverse

        from glassdist.analyzer import pipeline

        pipeline.fit_grid_homography = fit
        try:
            yield
        finally:
            pipeline.fit_grid_homography = fit_grid
    else:
        raise SystemExit(f"--also: unknown {what!r}; choose reference-carriers or zero-offsets")


if __name__ == "__main__":
    raise SystemExit(main())
