"""The accuracy experiment's ratios on two yardsticks, beside an earlier record of them.

``glassdist experiment accuracy`` detrends the truth on the region the result documents as the
A2 fit's (``result.detrend_region``, the whole analysis-grid blocks). Records made before that
region was stated detrended it on ``result.valid``, which adds the ring of partial blocks along
every border that the analyzer's fit never sees. A change of a ratio between such a record and
today's can therefore come from the analyzer or from the yardstick. This benchmark renders the
accuracy scenes once (exact engine, the experiment's settings), analyses each with both methods,
and gives per run the φ_eff and φ_shear ratios (mean |φ| Analyzer / truth over the compared
region, as in docs/validation/accuracy.md; the flat-glass controls have none):

* **record**: the earlier record (``git show COMMIT:docs/accuracy.json``; blank when git or the
  commit is not available);
* **on ``valid``**: today's analyzer, the truth detrended on ``valid`` (the record's yardstick);
* **documented**: today's analyzer on today's yardstick (docs/validation/accuracy.md's figures).

The first two columns differ only by the analyzer; the last two only by the yardstick.

Usage::

    python benchmarks/bench_yardstick.py [--record-commit 8c60441] [--scenes a,b] [--out docs/records/yardstick.md]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _record import write_record  # noqa: E402

CHANNELS = ("phi_eff", "phi_shear")


def record_ratios(commit: str) -> dict:
    """``{(scene, method): {channel: ratio}}`` of ``docs/accuracy.json`` at ``commit`` ({} when unavailable)."""
    try:
        text = subprocess.run(["git", "show", f"{commit}:docs/accuracy.json"], cwd=ROOT, capture_output=True,
                              text=True, check=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return {}
    out = {}
    for s in json.loads(text)["scenes"]:
        for method, run in s["runs"].items():
            out[(s["name"], method)] = run.get("ratios_vs_exact", {})
    return out


def run(names: list[str]) -> list[dict]:
    from glassdist.analyzer import analyze
    from glassdist.experiments._common import RunOptions
    from glassdist.experiments.accuracy import SCENES, against_truth
    from glassdist.theory import analysis_params
    from glassdist.virtual import compare_with_scene

    opts = RunOptions()
    prepared = [opts.prepare(SCENES[n][1]()) for n in names]
    rows = []
    for i, inputs in opts.render_each(prepared, reference=True):
        scene = inputs.scene
        params = analysis_params(prepared[i])
        for method in ("comparative", "direct"):
            result = analyze(inputs.distorted, pitch_mm=scene.backdrop.pitch_mm, distance_m=scene.backdrop.distance_m,
                             reference=inputs.reference if method == "comparative" else None, params=params)
            row = {"scene": names[i], "method": method, "kind": SCENES[names[i]][0]}
            for key, region in (("documented", None), ("on_valid", result.valid)):
                val = compare_with_scene(result, scene, model=inputs.model, truth=inputs.truth, truth_region=region)
                row[key] = against_truth(val, val.valid)["ratios_vs_exact"]
            rows.append(row)
    return rows


def table(rows: list[dict], record: dict, commit: str) -> str:
    head = ["scene", "method"] + [f"{ch} {k}" for ch in ("φ_eff", "φ_shear") for k in (f"record ({commit})", "on `valid`",
                                                                                      "documented")]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cell(d, ch):
        return f"{d[ch]:.3f}" if d and ch in d else "—"

    for r in rows:
        if r["kind"] == "flat":  # no distortion to read: a ratio to a truth of ~0 says nothing (docs/validation/accuracy.md)
            continue
        rec = record.get((r["scene"], r["method"]), {})
        cells = [r["scene"], r["method"]]
        for ch in CHANNELS:
            cells += [cell(rec, ch), cell(r["on_valid"], ch), cell(r["documented"], ch)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from glassdist.experiments.accuracy import SCENES

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--record-commit", default="8c60441", help="commit whose docs/accuracy.json is the earlier record")
    ap.add_argument("--scenes", help="comma-separated subset of the accuracy scenes (default: all)")
    ap.add_argument("--out", type=Path, help="write the table (markdown) and the record (FILE.json beside it)")
    a = ap.parse_args(argv)
    names = a.scenes.split(",") if a.scenes else list(SCENES)
    unknown = [n for n in names if n not in SCENES]
    if unknown:
        ap.error(f"unknown scene(s) {', '.join(unknown)}; choose from {', '.join(SCENES)}")
    t0 = time.perf_counter()
    rows = run(names)
    record = record_ratios(a.record_commit)
    text = table(rows, record, a.record_commit)
    print(text)
    print(f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if a.out:
        write_record(a.out, "bench_yardstick.py", argv, text, {
            "record_commit": a.record_commit, "rows": rows,
            "record": [{"scene": k[0], "method": k[1], **v} for k, v in record.items()]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
