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

``--processes`` measures instead what a user waits for, against the unit a user feels: one
process that starts Python, loads the same image and runs one ``numpy.fft.rfft2`` of it
(``load + rfft2``). Each case runs its commands and that process in turn, ``--repeat`` times
(alternating, so that a change in the machine's load falls on both), and states medians; each
command records its run in a history database of the benchmark's own (``GLASSDIST_DB``):

* ``quick start``: the README's Quick start on ``examples/images`` (Comparative, 1024 x 768);
* ``WxH lines P px, direct|comparative``: the default command on a synthetic line grid of
  period P px seen through a roller wave (``bench_analyze.py``'s wave), without or with the
  grid's reference photo;
* ``WxH ... report+export``: the first such command with ``--report --export``.

Each row: the median wall (s), the median CPU time (user + system, the process and its
children), the median ``load + rfft2`` wall of the same case, their ratio, the largest peak RSS
(MB) and the output folder's size (MB). ``--baseline-src DIR`` runs each
command a second time, alternating, with ``PYTHONPATH=DIR`` (another checkout's ``src``): a
before/after in one sitting::

    python benchmarks/bench_cli.py --processes --quick-start --sizes 6000x4000 --periods 16 8 --repeat 3 \
        --out docs/records/performance/cli_processes.json
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


def _timed(cmd, env=None) -> dict:
    """Wall time (s) and peak RSS (MB) of one process (the largest of it and its children), by /usr/bin/time."""
    with tempfile.NamedTemporaryFile("r", suffix=".time") as t:
        t0 = time.perf_counter()
        proc = subprocess.run(["/usr/bin/time", "-o", t.name, "-f", "%e %M %U %S", *cmd], capture_output=True,
                              text=True, env=env)
        wall = time.perf_counter() - t0
        elapsed, kb, user, system = t.read().split()[-4:]
    if proc.returncode not in (0, 3):
        raise RuntimeError(f"{' '.join(cmd)} exited {proc.returncode}: {proc.stderr[-2000:]}")
    return {"wall_s": wall, "time_s": float(elapsed), "peak_rss_mb": int(kb) / 1024.0,
            "cpu_s": float(user) + float(system)}


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


def make_line_grid(shape, period_px: float, folder: Path) -> tuple[Path, Path]:
    """8-bit PNGs ``img.png`` (the grid of period ``period_px`` seen through the wave) and ``ref.png`` (without it)."""
    import cv2

    sys.path.insert(0, str(HERE))
    from bench_analyze import _wave

    from glassdist.synthetic import backdrop_pattern

    H, W = shape
    img, ref = np.empty(shape, np.uint8), np.empty(shape, np.uint8)
    x = np.arange(W) - (W - 1) / 2.0
    for r0 in range(0, H, 256):
        y = np.arange(r0, min(H, r0 + 256)) - (H - 1) / 2.0
        X, Y = np.meshgrid(x, y)
        dX, dY = _wave(X, Y)
        for out, (u, v) in ((ref, (X, Y)), (img, (X + dX, Y + dY))):
            out[r0 : r0 + len(y)] = np.clip(np.round(backdrop_pattern(u, v, pitch_mm=period_px) * 255.0), 0, 255)
    paths = folder / "img.png", folder / "ref.png"
    for path, a in zip(paths, (img, ref)):
        cv2.imwrite(str(path), a)
    return paths


#: with --baseline-src: the cases (words of their names) run with it too; empty: every case
BASELINE_CASES: list[str] = []
#: with --only: the cases (words of their names) run; empty: every case
ONLY_CASES: list[str] = []

_LOAD_RFFT2 = ("import sys, numpy as np, cv2\n"
               "x = cv2.imread(sys.argv[1], cv2.IMREAD_GRAYSCALE).astype(np.float32)\nnp.fft.rfft2(x)\n")


def _process_case(name, image, command, out: Path, repeat: int, baseline_src) -> list[dict]:
    """``repeat`` rounds of (load + rfft2, the command, the command with ``baseline_src``): the case's rows."""
    if ONLY_CASES and not any(w in name for w in ONLY_CASES):
        return []
    if baseline_src and BASELINE_CASES and not any(w in name for w in BASELINE_CASES):
        baseline_src = None
    variants = [("", os.environ.get("PYTHONPATH"))] + ([(" (baseline)", str(baseline_src))] if baseline_src else [])
    unit, walls, cpu = [], {v: [] for v, _ in variants}, {v: [] for v, _ in variants}
    rss, folder = {v: 0.0 for v, _ in variants}, {}
    for _ in range(repeat):
        unit.append(_timed([sys.executable, "-c", _LOAD_RFFT2, str(image)])["wall_s"])
        for v, src in variants:
            shutil.rmtree(out, ignore_errors=True)
            # the run is recorded in a history of the benchmark's own, as a user's run is in theirs
            env = {**os.environ, "GLASSDIST_DB": str(out.parent / f"history{v.strip(' ()')}.sqlite")}
            if src is not None:
                env["PYTHONPATH"] = src
            m = _timed([sys.executable, "-m", "glassdist", *command, "--out", str(out)], env=env)
            walls[v].append(m["wall_s"])
            cpu[v].append(m["cpu_s"])
            rss[v] = max(rss[v], m["peak_rss_mb"])
            folder[v] = _folder_mb(out)
    shutil.rmtree(out, ignore_errors=True)
    u = float(np.median(unit))
    rows = []
    for v, _ in variants:
        w = float(np.median(walls[v]))
        rows.append({"case": name + v, "wall_s": w, "walls_s": walls[v], "cpu_s": float(np.median(cpu[v])),
                     "cpus_s": cpu[v], "unit_wall_s": u, "unit_walls_s": unit,
                     "x_load_rfft2": w / u, "peak_rss_mb": rss[v], "folder_mb": folder[v]})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def bench_processes(sizes, periods, repeat: int, quick_start: bool, baseline_src=None) -> list[dict]:
    """The ``--processes`` cases (module docstring)."""
    rows = []
    if quick_start:
        ex = HERE.parent / "examples" / "images"
        cmd = ["analyze", str(ex / "factory_pane.png"), "--reference", str(ex / "factory_reference.png"),
               "--pattern", "checkerboard", "--pitch-mm", "10", "--distance-m", "1", "-q"]
        with tempfile.TemporaryDirectory(prefix="bench_cli_") as tmp:
            rows += _process_case("quick start", ex / "factory_pane.png", cmd, Path(tmp) / "out", repeat,
                                  baseline_src)
    for W, H in sizes:
        for i, period in enumerate(periods):
            with tempfile.TemporaryDirectory(prefix="bench_cli_") as tmp:
                tmp = Path(tmp)
                img, ref = make_line_grid((H, W), float(period), tmp)
                base = ["analyze", str(img), "--pitch-mm", f"{period:g}", "--distance-m", "10", "-q"]
                label = f"{W}x{H} lines {period:g} px"
                rows += _process_case(f"{label}, direct", img, base, tmp / "out", repeat, baseline_src)
                rows += _process_case(f"{label}, comparative", img, [*base, "--reference", str(ref)], tmp / "out",
                                      repeat, baseline_src)
                if i == 0:
                    rows += _process_case(f"{label}, direct, report+export", img, [*base, "--report", "--export"],
                                          tmp / "out", repeat, baseline_src)
    return rows


def process_table(rows) -> str:
    """The ``--processes`` rows as a table (medians; the unit: one process loading the image and running one rfft2)."""
    lines = ["| case | wall s (median) | CPU s (median) | load + rfft2 s (median) | x load + rfft2 | peak RSS MB | "
             "output folder MB |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} | {r['unit_wall_s']:.2f} | "
                     f"{r['x_load_rfft2']:.1f} | {r['peak_rss_mb']:.0f} | {r['folder_mb']:.1f} |")
    return "\n".join(lines)


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
    p.add_argument("--sizes", nargs="*", default=["3000x2000", "6000x4000"], help="WxH, px (none: the Quick start alone)")
    p.add_argument("--pixel-max-mpx", type=float, default=30.0, help="largest image with a --fields pixel row, Mpx")
    p.add_argument("--floor-only", action="store_true", help="only the rfft2 unit and the floor rows")
    p.add_argument("--out", type=Path, help="JSON of the rows")
    p.add_argument("--processes", action="store_true", help="the whole-process cases against a load + rfft2 process")
    p.add_argument("--quick-start", action="store_true", help="with --processes: the README's Quick start too")
    p.add_argument("--periods", nargs="+", type=float, default=[16.0, 8.0], help="with --processes: grid periods, px")
    p.add_argument("--repeat", type=int, default=3, help="with --processes: rounds per case (medians)")
    p.add_argument("--baseline-src", type=Path, help="with --processes: also each command with PYTHONPATH=this")
    p.add_argument("--baseline-cases", nargs="*", default=[],
                   help="with --baseline-src: only the cases whose name holds one of these words")
    p.add_argument("--only", nargs="*", default=[], help="with --processes: only the cases whose name holds one of these")
    p.add_argument("--note", default="", help="with --processes: the record's note (the machine, its load)")
    args = p.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes]
    if args.processes:
        BASELINE_CASES[:] = args.baseline_cases
        ONLY_CASES[:] = args.only
        load = os.getloadavg()
        rows = bench_processes(sizes, args.periods, args.repeat, args.quick_start, args.baseline_src)
        print(process_table(rows))
        if args.out:
            record = {"command": " ".join(["python", "benchmarks/bench_cli.py", *(argv or sys.argv[1:])]),
                      "cpus": os.cpu_count(), "load_average_before": [round(x, 2) for x in load],
                      "load_average_after": [round(x, 2) for x in os.getloadavg()], "note": args.note, "rows": rows}
            args.out.write_text(json.dumps(record, indent=1) + "\n")
        return 0
    rows = bench(sizes, args.pixel_max_mpx, commands=not args.floor_only)
    print(table(rows))
    if args.out:
        record = {"command": " ".join(["python", "benchmarks/bench_cli.py", *(argv or sys.argv[1:])]),
                  "cpus": os.cpu_count(), "rows": rows}
        args.out.write_text(json.dumps(record, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
