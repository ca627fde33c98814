"""Batch and sweep on a local Dask cluster vs one after the other in one process.

Runs the same commands a user types, as child processes, and times them end to end
(cluster start-up included):

* ``glassdist batch`` of 8 panes (the bundled 1024 x 1024 photos, Comparative and
  Direct, with reports): serial, then ``--workers 2``;
* ``glassdist sweep`` of the wavy slab over 3 grid pitches x 2 smoothing scales
  (6 variants; image size and samples per pixel set by ``--pixels`` / ``--spp``):
  serial, then ``--workers 2``.

Each parallel run's outputs are checked against the serial run's (every file but
logs and timings byte-identical). Usage::

    python benchmarks/bench_distributed.py --out docs/records/performance/distributed_results.json
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _data import REAL_PHOTOS as DATA  # noqa: E402 (the benchmarks' own helpers, after sys.path)
from _data import real_photos  # noqa: E402


def _glassdist(*args):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), MPLBACKEND="Agg")
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "glassdist", *map(str, args)], capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    if r.returncode not in (0, 3):
        raise SystemExit(f"glassdist {' '.join(map(str, args))} failed ({r.returncode}): {r.stderr[-2000:]}")
    return seconds, r.returncode


_STAMP = re.compile(rb"\d{4}-\d\d-\d\d[T ]\d\d:\d\d:\d\d(\+00:00)?")


def _same(serial: Path, parallel: Path) -> list[str]:
    """Files that differ between the two runs, other than logs, records with timings and the HTML index.

    A report's time of generation is left out of its comparison (it differs between any two runs).
    """
    skip = ("analyze.log", "validate.log", "pane.json", "variant.json", "index.html", "index.csv", "index.json",
            "validation.json")
    differ = []
    for p in sorted(serial.rglob("*")):
        rel = p.relative_to(serial)
        if not p.is_file() or p.name in skip:
            continue
        if p.name == "report.html":
            same = _STAMP.sub(b"", p.read_bytes()) == _STAMP.sub(b"", (parallel / rel).read_bytes())
        else:
            same = filecmp.cmp(p, parallel / rel, shallow=False)
        if not same:
            differ.append(str(rel))
    return differ


def _manifest(folder: Path) -> Path:
    real_photos()
    rows = ["id,image,reference,pitch_mm,distance_m,pattern,detrend_degree"]
    photos = [("waves", "distorted_waves.bmp"), ("ring", "distorted_floating_ring.bmp")]
    for k in range(2):
        for name, image in photos:
            rows.append(f"factory_{name}_{k},{DATA / image},{DATA / 'reference.png'},5,{0.5 + k},checkerboard,3")
            rows.append(f"insitu_{name}_{k},{DATA / image},,5,{0.5 + k},checkerboard,3")
    path = folder / "manifest.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


def _scene(folder: Path, pixels, spp) -> Path:
    data = yaml.safe_load((ROOT / "examples" / "scenes" / "wavy_slab.yaml").read_text())
    data["camera"]["pixels"] = list(pixels)
    data["render"]["samples_per_pixel"] = spp
    path = folder / "wavy_slab.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("--out", type=Path, help="write the timings as JSON here")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--pixels", type=int, nargs=2, default=(512, 384), metavar=("W", "H"), help="sweep image size")
    ap.add_argument("--spp", type=int, default=4, help="sweep samples per pixel")
    ap.add_argument("--runs", nargs="+", choices=["batch", "sweep"], default=["batch", "sweep"])
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="bench-distributed-"))
    try:
        manifest = _manifest(work)
        scene = _scene(work, args.pixels, args.spp)
        vary = ["--vary", "backdrop.pitch_mm=24.2,36.3,48.4", "--vary", "analysis.sigma_mm=40,80"]
        runs = {}
        commands = {"batch": ("batch_8_panes", ["batch", manifest, "--report", "--no-progress"]),
                    "sweep": ("sweep_6_variants", ["sweep", scene, *vary, "--no-progress"])}
        for what, cmd in (commands[r] for r in args.runs):
            serial_s, code_s = _glassdist(*cmd, "--out", work / f"{what}_serial")
            dask_s, code_d = _glassdist(*cmd, "--out", work / f"{what}_dask", "--workers", args.workers)
            runs[what] = {
                "serial_s": round(serial_s, 2), "dask_s": round(dask_s, 2), "speed_up": round(serial_s / dask_s, 2),
                "exit_codes": [code_s, code_d],
                "files_differing": _same(work / f"{what}_serial", work / f"{what}_dask"),
            }
            print(f"{what}: serial {serial_s:.1f} s, {args.workers} Dask workers {dask_s:.1f} s "
                  f"(x{serial_s / dask_s:.2f}), exit {code_s}/{code_d}, "
                  f"{len(runs[what]['files_differing'])} output files differ")
        record = {"workers": args.workers, "sweep_pixels": list(args.pixels), "sweep_spp": args.spp,
                  "cpu_count": os.cpu_count(), "python": platform.python_version(),
                  "load_average_1min_after": round(os.getloadavg()[0], 2), "runs": runs}
        if args.out:
            args.out.write_text(json.dumps(record, indent=2) + "\n")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
