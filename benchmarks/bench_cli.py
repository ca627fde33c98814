"""What ``glassdist analyze`` costs a user: whole command-line processes, in units of one numpy rfft2.

For each image size a synthetic 8-bit PNG of a line grid seen through a roller wave (the
photo of ``bench_analyze.py``) is written once; then, in the same run, each row is one
fresh process under ``/usr/bin/time`` (wall time and peak RSS of that process):

* ``numpy rfft2``: one ``numpy.fft.rfft2`` of the image (float32), best of two calls in its
  process: the unit;
* ``default``: ``glassdist analyze IMG --pitch-mm 8 --distance-m 10 --out DIR`` (Direct Method);
* ``report+export``: the same with ``--report --export``;
* ``fields pixel``: the same with ``--fields pixel`` (sizes up to ``--pixel-max-mpx``);
* the floor under the command, also whole processes: ``import + read`` (``import glassdist``
  and ``read_image``, nothing else) and ``analysis only`` (that, then ``glassdist.analyze``
  with the command's settings, no output written).

Also the output folder's size, and the agreement of the default (analysis-grid) fields with
the pixel-grid ones: each analysis-grid sample of phi_eff / phi_shear against the pixel-grid
field at that sample's pixel (Pearson correlation, mean |phi| ratio), and whether
``glassdist.load_result`` brings the compact file back to the pixel-grid file exactly.

Usage::

    flock /tmp/glassdist-heavy.lock python benchmarks/bench_cli.py --sizes 3000x2000 6000x4000 12000x8400 \
        --out docs/records/performance/cli_results.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ANALYZE = ["--pitch-mm", "8", "--distance-m", "10"]


def make_png(shape, folder: Path) -> Path:
    """An 8-bit PNG of the benchmark's distorted grid (``bench_analyze.make_images``), written in row blocks."""
    import cv2

    sys.path.insert(0, str(HERE))
    from bench_analyze import make_images

    make_images(shape, folder)
    img = np.load(folder / "img.npy", mmap_mode="r")
    out = np.empty(shape, np.uint8)
    for r in range(0, shape[0], 1024):
        out[r : r + 1024] = np.clip(np.round(img[r : r + 1024] * 255.0), 0, 255).astype(np.uint8)
    del img
    for f in ("img.npy", "ref.npy"):
        (folder / f).unlink()
    path = folder / "img.png"
    cv2.imwrite(str(path), out)
    return path


def _timed(cmd) -> dict:
    """Wall time (s) and peak RSS (MB) of one process, by /usr/bin/time."""
    with tempfile.NamedTemporaryFile("r", suffix=".time") as t:
        t0 = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-o", t.name, "-f", "%e %M", *cmd], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        elapsed, kb = t.read().split()[-2:]
    if proc.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} exited {proc.returncode}: {proc.stderr[-2000:]}")
    return {"wall_s": wall, "time_s": float(elapsed), "peak_rss_mb": int(kb) / 1024.0}


def _rfft2(png: Path) -> dict:
    code = ("import sys, time, numpy as np, cv2; x = cv2.imread(sys.argv[1], cv2.IMREAD_GRAYSCALE).astype(np.float32); "
            "ts = []\nfor _ in range(2):\n t = time.perf_counter(); np.fft.rfft2(x); ts.append(time.perf_counter() - t)\n"
            "print(min(ts))")
    out = subprocess.run([sys.executable, "-c", code, str(png)], capture_output=True, text=True, check=True)
    return {"time_s": float(out.stdout.split()[-1])}


_FLOOR = ("import sys, glassdist\nimg = glassdist.read_image(sys.argv[1], dtype='float32')\n"
          "if sys.argv[2] == 'analyze':\n    glassdist.analyze(img, pitch_mm=8, distance_m=10)\n")


def _floor(png: Path, what: str) -> dict:
    """A whole process that imports glassdist and reads the photo (``what='read'``), or also analyses it."""
    return _timed([sys.executable, "-c", _FLOOR, str(png), what])


def _folder_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 1e6


def _agreement(default_dir: Path, pixel_dir: Path) -> dict:
    import glassdist

    stored = glassdist.load_result(default_dir)
    out = {}
    with np.load(pixel_dir / "result.npz") as z:
        rows = np.clip(np.round(stored.grid_rows_px).astype(int), 0, stored.valid.shape[0] - 1)
        cols = np.clip(np.round(stored.grid_cols_px).astype(int), 0, stored.valid.shape[1] - 1)
        for name in ("phi_eff_mD", "phi_shear_mD"):
            grid = stored.fields[name]
            pix = z[name][np.ix_(rows, cols)]
            ok = stored.grid_valid & np.isfinite(grid) & np.isfinite(pix)
            a, b = grid[ok].astype(np.float64), pix[ok].astype(np.float64)
            exact = bool(np.array_equal(stored.pixel_field(name), z[name], equal_nan=True))
            out[name] = {"correlation": float(np.corrcoef(a, b)[0, 1]),
                         "mean_abs_ratio": float(np.mean(np.abs(a)) / np.mean(np.abs(b))),
                         "load_result_exact": exact}
    return out


def bench(sizes, pixel_max_mpx: float, commands: bool = True) -> list[dict]:
    exe = [sys.executable, "-m", "glassdist", "analyze"]
    rows = []
    for W, H in sizes:
        with tempfile.TemporaryDirectory(prefix="bench_cli_") as tmp:
            tmp = Path(tmp)
            png = make_png((H, W), tmp)
            unit = _rfft2(png)["time_s"]
            size = f"{W}x{H}"
            rows.append({"image": size, "run": "numpy rfft2", "time_s": unit, "x_rfft2": 1.0})
            for name, what in (("import + read", "read"), ("analysis only", "analyze")):
                m = _floor(png, what)
                rows.append({"image": size, "run": name, **m, "x_rfft2": m["wall_s"] / unit})
                print(json.dumps(rows[-1]), flush=True)
            runs = [("default", []), ("report+export", ["--report", "--export"])] if commands else []
            if commands and W * H / 1e6 <= pixel_max_mpx:
                runs.append(("fields pixel", ["--fields", "pixel"]))
            for name, extra in runs:
                out = tmp / name.replace(" ", "_").replace("+", "_")
                m = _timed([*exe, str(png), *ANALYZE, "--out", str(out), "-q", *extra])
                rows.append({"image": size, "run": name, **m, "x_rfft2": m["wall_s"] / unit,
                             "folder_mb": _folder_mb(out)})
                print(json.dumps(rows[-1]), flush=True)
            if commands and (tmp / "fields_pixel").exists():
                rows.append({"image": size, "run": "default vs pixel", **_agreement(tmp / "default", tmp / "fields_pixel")})
                print(json.dumps(rows[-1]), flush=True)
            shutil.rmtree(tmp, ignore_errors=True)
    return rows


def table(rows) -> str:
    lines = ["| image | run | wall s | x rfft2 | peak RSS MB | output folder MB |", "|---|---|---|---|---|---|"]
    for r in rows:
        if "x_rfft2" not in r:
            continue
        rss = f"{r['peak_rss_mb']:.0f}" if "peak_rss_mb" in r else ""
        folder = f"{r['folder_mb']:.1f}" if "folder_mb" in r else ""
        wall = r.get("wall_s", r["time_s"])
        lines.append(f"| {r['image']} | {r['run']} | {wall:.2f} | {r['x_rfft2']:.1f} | {rss} | {folder} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    p.add_argument("--sizes", nargs="+", default=["3000x2000", "6000x4000"], help="WxH, px")
    p.add_argument("--pixel-max-mpx", type=float, default=30.0, help="largest image with a --fields pixel row, Mpx")
    p.add_argument("--floor-only", action="store_true", help="only the rfft2 unit and the floor rows")
    p.add_argument("--out", type=Path, help="JSON of the rows")
    args = p.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes]
    rows = bench(sizes, args.pixel_max_mpx, commands=not args.floor_only)
    print(table(rows))
    if args.out:
        record = {"command": " ".join(["python", "benchmarks/bench_cli.py", *(argv or sys.argv[1:])]),
                  "cpus": os.cpu_count(), "rows": rows}
        args.out.write_text(json.dumps(record, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
