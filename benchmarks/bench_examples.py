"""Analysed area and channel statistics on the real photos (``benchmarks/_data.py``), as recorded before/after.

The factory example's settings (checkerboard, pitch 5 mm, L = 1 m, N = 2, default sigma),
both methods, both distorted photos. Per run: the reported share of the image (``valid``),
the trusted share (quality label 0; the reported one where the version has no quality
map), mean / p95 / max |phi_eff| and p95 |phi_shear| as ``statistics()`` gives them, and
the largest |phi_eff| anywhere in the reported region. ``--before FILE`` embeds the
records of an earlier version (made by running this script with that version first on
``PYTHONPATH``)::

    PYTHONPATH=/path/to/old/src python benchmarks/bench_examples.py --out old.json
    python benchmarks/bench_examples.py --before old.json --before-command "..." --out docs/records/examples_before_after.json
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def measure() -> dict:
    from _data import real_photos

    import glassdist
    from glassdist import analyze
    from glassdist.io import read_image

    data = real_photos()
    ref = read_image(data / "reference.png")
    out = {"glassdist_version": glassdist.__version__, "records": []}
    for name in ("distorted_waves", "distorted_floating_ring"):
        img = read_image(data / f"{name}.bmp")
        for method in ("comparative", "direct"):
            r = analyze(img, pitch_mm=5.0, distance_m=1.0, reference=ref if method == "comparative" else None,
                        pattern="checkerboard", params={"detrend_degree": 2})
            s = r.statistics()
            trusted = getattr(r, "trusted", r.valid)
            out["records"].append({
                "photo": name, "method": method, "valid": float(r.valid.mean()), "trusted": float(trusted.mean()),
                "mean_eff": s["phi_eff_mD"]["mean_abs"], "p95_eff": s["phi_eff_mD"]["p95_abs"],
                "max_eff": s["phi_eff_mD"]["max_abs"], "p95_shear": s["phi_shear_mD"]["p95_abs"],
                "max_eff_reported": float(np.nanmax(np.abs(r.phi_eff_mD[r.valid]))), "warnings": list(r.warnings),
            })
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--before", type=Path)
    ap.add_argument("--before-command", default="")
    a = ap.parse_args(argv)
    rec = measure()
    args = shlex.join(argv if argv is not None else sys.argv[1:])
    rec["command"] = f"python benchmarks/bench_examples.py {args}".strip()
    if a.before:
        prev = json.loads(a.before.read_text())
        rec["before"] = {"command": a.before_command or prev.get("command", ""), "records": prev["records"],
                         "glassdist_version": prev.get("glassdist_version")}
    a.out.write_text(json.dumps(rec, indent=1))
    for r in rec["records"]:
        print(f"{r['photo']} {r['method']}: valid {100 * r['valid']:.1f} %, trusted {100 * r['trusted']:.1f} %, "
              f"p95 |phi_eff| {r['p95_eff']:.1f} mD, max {r['max_eff']:.1f} mD")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
