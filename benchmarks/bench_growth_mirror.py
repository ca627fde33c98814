"""Are the samples F5's growth adds measured like the others? A mirror test on a ray-traced lens.

F5 grows the measured region into samples the one pass left out (``deformation_growth_passes``,
:mod:`glassdist.analyzer.deform`). When a scene's accuracy ratio moves with the growth, either the
grown samples are measured differently, or the compared region now reaches a part of the pane that
the analyzer reads differently anyway. A mirror-symmetric scene separates the two: where the
growth adds samples on one side only, their mirror image across the scene's axis holds the same
truth and is measured with the growth off too.

Per scene and method the accuracy scene is rendered once (exact engine, the accuracy experiment's
settings) and analysed with the growth on (the default) and off; the ratios (mean |φ| Analyzer /
truth over a set of pixels, as docs/validation/accuracy.md, truth detrended on the documented region of the
run with the growth on) are given over

* **all**: that run's compared region;
* **shared**: the pixels both runs compare;
* **added**: the pixels only the run with the growth compares;
* **mirror**: the mirror image of the added pixels across the vertical axis, where that run's
  region has them and the run without growth does too.

The axis is the truth's own: the column reflection that best matches the |φ_eff| map with itself;
``asymmetry`` is the mean |φ_eff| difference of the truth between the added pixels and their mirror,
relative to its mean there (0: the mirror holds the same truth).

Usage::

    python benchmarks/bench_growth_mirror.py [--scenes biconvex_lens_p48] [--out docs/records/growth_mirror.md]
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

CHANNELS = ("phi_eff", "phi_shear")


def mirror_axis(truth: np.ndarray, valid: np.ndarray) -> int:
    """``c`` such that column ``j`` mirrors to ``c - j``: the reflection that best matches ``|truth|`` with itself."""
    t = np.where(valid, np.abs(truth), np.nan)
    W = t.shape[1]
    best, best_err = W - 1, np.inf
    for c in range(W // 2, 3 * W // 2 - 1):
        j = np.arange(max(0, c - W + 1), min(W, c + 1))
        d = t[:, j] - t[:, c - j]
        err = np.nanmean(np.abs(d)) if np.isfinite(d).sum() > t.size // 4 else np.inf
        if err < best_err:
            best, best_err = c, err
    return best


def mirrored(mask: np.ndarray, c: int) -> np.ndarray:
    """``mask`` reflected across the column axis ``c`` (column ``j`` to ``c - j``)."""
    out = np.zeros_like(mask)
    yy, xx = np.nonzero(mask)
    xm = c - xx
    ok = (xm >= 0) & (xm < mask.shape[1])
    out[yy[ok], xm[ok]] = True
    return out


def run(names: list[str]) -> list[dict]:
    from glassdist.experiments._common import RunOptions, evaluate
    from glassdist.experiments.accuracy import SCENES, against_truth
    from glassdist.theory import analysis_params

    def ratios(val, where):  # mean |Analyzer| / mean |truth| per channel, as docs/validation/accuracy.md
        return against_truth(val, where)["ratios_vs_exact"]

    opts = RunOptions()
    prepared = [opts.prepare(SCENES[n][1]()) for n in names]
    rows = []
    for i, inputs in opts.render_each(prepared, reference=True):
        for method in ("comparative", "direct"):
            on = evaluate(inputs, method=method, params=analysis_params(prepared[i]))
            off = evaluate(inputs, method=method, params=analysis_params(prepared[i], deformation_growth_passes=0))
            added = on.valid & ~off.valid
            c = mirror_axis(on.exact.phi_eff_mD, on.valid)
            mirror = mirrored(added, c) & on.valid & off.valid & ~added
            yy, xx = np.nonzero(mirror)  # pixel by pixel: the mirror and the added pixel it reflects
            t = np.abs(on.exact.phi_eff_mD)
            asym = float(np.mean(np.abs(t[yy, xx] - t[yy, c - xx])) / np.mean(t[yy, c - xx])) if yy.size else None
            rows.append({
                "scene": names[i], "method": method, "axis_column": c, "asymmetry": asym,
                "pixels": {"all": int(on.valid.sum()), "growth_off": int(off.valid.sum()),
                           "shared": int((on.valid & off.valid).sum()),
                           "added": int(added.sum()), "mirror": int(mirror.sum())},
                "growth_off": ratios(off, off.valid), "all": ratios(on, on.valid),
                "shared": ratios(on, on.valid & off.valid), "added": ratios(on, added), "mirror": ratios(on, mirror),
                "demodulations": [on.analysis.demodulations, off.analysis.demodulations],
            })
    return rows


def table(rows: list[dict]) -> str:
    cols = ("growth_off", "all", "shared", "added", "mirror")
    head = ["scene", "method", "channel", "growth off (its region)", "growth on: all", "shared", "added", "mirror of added",
            "truth asymmetry"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        for ch in CHANNELS:
            cells = [r["scene"], r["method"], ch.replace("phi", "φ")]
            cells += [f"{r[k][ch]:.4f}" if ch in r[k] else "—" for k in cols]
            cells.append("—" if r["asymmetry"] is None else f"{100 * r['asymmetry']:.2f} %")
            lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "| scene | method | pixels: growth off | growth on | shared | added | mirror |",
              "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['scene']} | {r['method']} | {r['pixels']['growth_off']} | {r['pixels']['all']} | {r['pixels']['shared']} | "
              f"{r['pixels']['added']} | {r['pixels']['mirror']} |" for r in rows]
    return "\n".join(lines)


def main(argv=None) -> int:
    from glassdist.experiments.accuracy import SCENES

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="biconvex_lens_p48", help="comma-separated accuracy scenes (mirror-symmetric)")
    ap.add_argument("--out", type=Path, help="write the table (markdown) and the record (FILE.json beside it)")
    a = ap.parse_args(argv)
    names = a.scenes.split(",")
    unknown = [n for n in names if n not in SCENES]
    if unknown:
        ap.error(f"unknown scene(s) {', '.join(unknown)}; choose from {', '.join(SCENES)}")
    t0 = time.perf_counter()
    rows = run(names)
    text = table(rows)
    print(text)
    print(f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if a.out:
        write_record(a.out, "bench_growth_mirror.py", argv, text, {"rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
