"""Speed, memory and accuracy of `glassdist.analyze`, as ratios measured in one run.

For each image size a synthetic line-grid photo with a known smooth distortion (a roller
wave) and its glass-less reference are made once; then each measurement runs in a fresh
process (so its peak RSS is its own):

* one ``numpy.fft.rfft2`` of the same image (the floor of any Fourier method),
* ``analyze`` Direct and Comparative (the Comparative reference prepared inside the timing),
* peers a user might pick: OpenCV Farneback optical flow (Comparative) and, if an
  interpreter with OpenLSA is available (``GLASSDIST_OPENLSA_PYTHON`` or
  ``~/.cache/glassdist/openlsa-venv``; see ``benchmarks/setup_openlsa.sh``), OpenLSA.

Timing: every timed call runs twice in its process and the table shows the better run (the
JSON keeps the first, cold call too: page faults of fresh arrays and FFT plans), the same
for the rfft2 floor, glassdist and the peers. ``analyze`` returns its fields on the analysis
grid and brings them to the image's pixel grid on first access: that step is timed apart
("+ pixel-grid fields": displacement and the three channels, about 0.5 GB at 24 Mpx).

Accuracy: phi_eff against the truth put through the same evaluation stack (same N, sigma,
region), and the displacement error against the known field (Comparative and peers), so
a speed-up that costs accuracy shows. ``--full-res-check`` compares the default path with
the full-resolution path (no decimation) on one size.

``--before-src DIR`` times the analysis alone against another version of the package (``DIR``:
its ``src`` folder, e.g. ``git archive main src | tar -x -C /tmp/before``), in the same run: for each
case and repeat, one process that loads the image and runs one ``numpy.fft.rfft2`` (the unit,
timed whole from outside: interpreter start, load, transform), then the two versions in fresh
processes, their order alternating. Each analysis process reports its wall and CPU seconds
(``prepare_reference`` and ``analyze``; the pixel-grid fields apart) and its peak RSS (after the
analysis, then with the pixel-grid fields), and leaves
its fields for the largest difference between the versions. Cases: ``waves`` (the real
Comparative pair in ``../shared/data/real-checkerboard-water``, 1024 px, F5 with its photo passes;
skipped where absent) and ``lines8`` / ``lines16`` (a 6000 x 4000 synthetic line grid of 8 or 16 px
period under the roller wave, Direct). Medians over the repeats; ``--record`` merges the cases
into a JSON record (a case run again replaces its entry).

Usage::

    python benchmarks/bench_analyze.py --sizes 2000x1500 6000x4000 --out docs/records/performance/results.json
    python benchmarks/bench_analyze.py --before-src /tmp/before/src --cases waves --repeats 3 \
        --record docs/records/performance/analysis_results.json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PITCH_PX = 8.0  # carrier period, px (mm_per_px = 1)
L_M = 10.0
WAVE = dict(amplitude_mm=0.8, wavelength_mm=300.0, direction_deg=20.0)
PARAMS = {"detrend_degree": 2, "sigma_mm": 40.0}
REPEATS = 2  # every timed call runs this often in its process; the table shows the best, the JSON the first too


def _wave(X, Y):
    t = np.radians(WAVE["direction_deg"])
    e = np.array([np.cos(t), np.sin(t)])
    a = WAVE["amplitude_mm"] * np.sin(2 * np.pi * (e[0] * X + e[1] * Y) / WAVE["wavelength_mm"])
    return a * e[0], a * e[1]


def make_images(shape, folder: Path, pitch_px: float = PITCH_PX) -> None:
    """Write img.npy, ref.npy (float32) for a wave seen through a line grid, in row blocks (low memory)."""
    from glassdist.synthetic import backdrop_pattern

    H, W = shape
    img = np.lib.format.open_memmap(folder / "img.npy", mode="w+", dtype=np.float32, shape=(H, W))
    ref = np.lib.format.open_memmap(folder / "ref.npy", mode="w+", dtype=np.float32, shape=(H, W))
    x = np.arange(W) - (W - 1) / 2.0
    for r0 in range(0, H, 256):
        y = np.arange(r0, min(H, r0 + 256)) - (H - 1) / 2.0
        X, Y = np.meshgrid(x, y)
        dX, dY = _wave(X, Y)
        ref[r0 : r0 + len(y)] = backdrop_pattern(X, Y, pitch_mm=pitch_px)
        img[r0 : r0 + len(y)] = backdrop_pattern(X + dX, Y + dY, pitch_mm=pitch_px)
    img.flush()
    ref.flush()


def _truth_on(shape, step):
    H, W = shape
    y = np.arange(step // 2, H, step) - (H - 1) / 2.0
    x = np.arange(step // 2, W, step) - (W - 1) / 2.0
    X, Y = np.meshgrid(x, y)
    dX, dY = _wave(X, Y)
    return np.stack([dX, dY], -1)


def _phi_error(phi_eff_full, valid_full, mm_per_px, sigma_mm, degree, step):
    """phi_eff against the truth through the same stack, on every step-th pixel."""
    from glassdist.analyzer.metrics import evaluate_displacement

    sl = (slice(step // 2, None, step), slice(step // 2, None, step))
    v = valid_full[sl]
    truth = evaluate_displacement(_truth_on(valid_full.shape, step), v, distance_m=L_M, mm_per_px=mm_per_px,
                                  detrend_degree=degree, sigma_mm=sigma_mm, step_px=(step, step))
    a = phi_eff_full[sl][v]
    b = truth.phi_eff_mD[v]
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    return {
        "phi_eff_ratio": float(np.mean(np.abs(a)) / np.mean(np.abs(b))),
        "phi_eff_corr": float(np.corrcoef(a, b)[0, 1]),
        "phi_eff_rel_rms_error": float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b**2))),
    }


def _disp_error(disp, valid, step):
    sl = (slice(step // 2, None, step), slice(step // 2, None, step))
    t = _truth_on(valid.shape, step)
    v = valid[sl] & np.all(np.isfinite(disp[sl]), axis=-1)
    e = disp[sl][v] - t[v]
    return {"displacement_rms_error_mm": float(np.sqrt(np.mean(e**2))),
            "displacement_rel_rms_error": float(np.sqrt(np.mean(e**2) / np.mean(t[v] ** 2)))}


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def worker(task: dict) -> dict:
    """One measurement in this (fresh) process."""
    folder = Path(task["folder"])
    img = np.load(folder / "img.npy")
    kind = task["kind"]
    out = {"kind": kind, "shape": list(img.shape)}
    step = max(1, int(np.sqrt(img.size / 1e6)))
    if kind == "rfft2":
        ts = []
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            np.fft.rfft2(img)
            ts.append(time.perf_counter() - t0)
        out["seconds"], out["first_call_s"] = min(ts), ts[0]
    elif kind in ("direct", "comparative"):
        from glassdist import analyze, prepare_reference

        params = dict(PARAMS, **task.get("params", {}))
        ref = np.load(folder / "ref.npy") if kind == "comparative" else None
        ts = []
        for _ in range(REPEATS):  # the same treatment as the rfft2 row: best of REPEATS, first call kept
            res = None
            t0 = time.perf_counter()
            r = prepare_reference(ref, params=params) if ref is not None else None
            res = analyze(img, pitch_mm=PITCH_PX, distance_m=L_M, reference=r, params=params)
            ts.append(time.perf_counter() - t0)
        out["seconds"], out["first_call_s"] = min(ts), ts[0]
        # The result's fields live on the analysis grid and are brought to the pixel grid on
        # first access; that cost is timed on its own (a CLI run pays it when writing result.npz).
        t0 = time.perf_counter()
        for name in ("displacement_mm", "phi_eff_mD", "phi_shear_mD", "phi_total_mD"):
            getattr(res, name)
        out["pixel_grid_fields_s"] = time.perf_counter() - t0
        out["peak_rss_mb"] = _peak_rss_mb()
        out["valid_fraction"] = res.valid_fraction
        out.update(_phi_error(res.phi_eff_mD, res.valid, res.mm_per_px, res.sigma_mm, res.detrend_degree, step))
        if kind == "comparative":
            out.update(_disp_error(res.displacement_mm, res.valid, step))
    elif kind == "farneback":
        from _flow import farneback_displacement

        ref = np.load(folder / "ref.npy")
        ts = []
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            # computed from the photo to the reference: defined at the photo's pixels (benchmarks/_flow.py)
            u = farneback_displacement(ref, img, 15, 3, 5, 1.2, levels=3, gaussian=False)
            ts.append(time.perf_counter() - t0)
        out["seconds"], out["first_call_s"] = min(ts), ts[0]
        out["peak_rss_mb"] = _peak_rss_mb()
        disp = -u  # img(r) = ref(r - u): delta = -u (mm_per_px = 1)
        valid = np.ones(img.shape, bool)
        m = int(4 * PITCH_PX)
        valid[:m], valid[-m:], valid[:, :m], valid[:, -m:] = False, False, False, False
        out.update(_disp_error(disp, valid, step))
        from glassdist.analyzer.metrics import evaluate_displacement

        sl = (slice(step // 2, None, step), slice(step // 2, None, step))
        ch = evaluate_displacement(disp[sl], valid[sl], distance_m=L_M, mm_per_px=1.0, detrend_degree=PARAMS["detrend_degree"],
                                   sigma_mm=PARAMS["sigma_mm"], step_px=(step, step))
        full = np.full(img.shape, np.nan)
        full[sl] = ch.phi_eff_mD
        vv = np.zeros(img.shape, bool)
        vv[sl] = valid[sl]
        out.update(_phi_error(full, vv, 1.0, PARAMS["sigma_mm"], PARAMS["detrend_degree"], step))
    return out


def analysis_worker(task: dict) -> dict:
    """One timed analysis (``--before-src`` mode) in this fresh process: wall and CPU seconds, peak RSS, fields kept."""
    from glassdist import analyze, prepare_reference

    folder = Path(task["folder"])
    img = np.load(folder / "img.npy")
    ref = np.load(folder / "ref.npy") if task["comparative"] else None
    c = task["case"]
    t0, c0 = time.perf_counter(), time.process_time()
    r = prepare_reference(ref, pattern=c["pattern"], params=c["params"]) if ref is not None else None
    res = analyze(img, pitch_mm=c["pitch_mm"], distance_m=c["distance_m"], reference=r, pattern=c["pattern"],
                  params=c["params"])
    out = {"seconds": time.perf_counter() - t0, "cpu_s": time.process_time() - c0, "peak_rss_mb": _peak_rss_mb()}
    t0 = time.perf_counter()
    fields = {name: np.asarray(getattr(res, name)) for name in ("displacement_mm", "phi_eff_mD", "phi_shear_mD")}
    out["pixel_grid_fields_s"] = time.perf_counter() - t0
    out["peak_rss_with_fields_mb"] = _peak_rss_mb()  # the analysis's peak, or the pixel-grid fields' on top of it
    out["valid_fraction"] = float(res.valid_fraction)
    out["phi_eff_p95_abs_mD"] = float(np.nanpercentile(np.abs(fields["phi_eff_mD"]), 95))
    np.savez(task["fields"], **fields)
    return out


#: ``--before-src`` cases: the image (``waves``: the real pair; else a 6000 x 4000 line grid of that period) and the call
CASES = {
    "waves": {"photo": "distorted_waves.bmp", "reference": "reference.png", "comparative": True, "pitch_mm": 5.0,
              "distance_m": 1.0, "pattern": "checkerboard", "params": {}},
    "lines8": {"shape": (4000, 6000), "period_px": 8.0, "comparative": False, "pitch_mm": 8.0, "distance_m": L_M,
               "pattern": "lines", "params": PARAMS},
    "lines16": {"shape": (4000, 6000), "period_px": 16.0, "comparative": False, "pitch_mm": 16.0, "distance_m": L_M,
                "pattern": "lines", "params": PARAMS},
}
REAL = HERE.parent.parent / "shared" / "data" / "real-checkerboard-water"


def _case_images(name: str, folder: Path) -> bool:
    """Write the case's img.npy (and ref.npy) as float32; False where its photos are absent."""
    c = CASES[name]
    if "photo" not in c:
        make_images(c["shape"], folder, c["period_px"])
        return True
    if not (REAL / c["photo"]).exists():
        print(f"{name}: skipped, {REAL / c['photo']} is absent", file=sys.stderr)
        return False
    from glassdist.io import read_image

    np.save(folder / "img.npy", read_image(REAL / c["photo"], dtype=np.float32))
    np.save(folder / "ref.npy", read_image(REAL / c["reference"], dtype=np.float32))
    return True


def _unit_process(folder: Path) -> float:
    """Wall seconds of a fresh process that loads the photo and runs one numpy rfft2 (the unit)."""
    code = f"import numpy as np; np.fft.rfft2(np.load({str(folder / 'img.npy')!r}))"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


def _largest_difference(a: Path, b: Path) -> dict:
    """Per field: the largest |after - before| over the largest |before| (NaN patterns must agree)."""
    out = {}
    with np.load(a) as za, np.load(b) as zb:
        for k in za.files:
            x, y = za[k], zb[k]
            same_nan = bool(np.array_equal(np.isnan(x), np.isnan(y)))
            ok = np.isfinite(x) & np.isfinite(y)
            scale = float(np.max(np.abs(x[ok]))) if ok.any() else 0.0
            diff = float(np.max(np.abs(x[ok] - y[ok]))) if ok.any() else 0.0
            out[k] = {"nan_pattern_equal": same_nan, "max_abs_diff": diff, "max_abs_diff_rel": diff / scale if scale else 0.0,
                      "bit_identical": bool(same_nan and np.array_equal(x[ok], y[ok]))}
    return out


def compare_versions(cases, before_src: Path, repeats: int) -> dict:
    """Each case: the unit, the two versions alternating, ``repeats`` times; medians and the fields' differences."""
    after_src = HERE.parent / "src"
    rows = {}
    for name in cases:
        with tempfile.TemporaryDirectory() as d:
            folder = Path(d)
            if not _case_images(name, folder):
                continue
            c = CASES[name]
            runs: dict[str, list] = {"unit": [], "before": [], "after": []}
            for r in range(repeats):
                runs["unit"].append(_unit_process(folder))
                for version in (("before", "after") if r % 2 == 0 else ("after", "before")):
                    src = before_src if version == "before" else after_src
                    task = {"folder": d, "comparative": c["comparative"], "case": {k: v for k, v in c.items() if k in (
                        "pitch_mm", "distance_m", "pattern", "params")}, "fields": str(folder / f"{version}.npz")}
                    res = _run_worker(dict(task, kind="analysis"), env_src=src)
                    if "error" in res:
                        raise RuntimeError(f"{name} {version}: {res['error']}")
                    runs[version].append(res)
            unit = float(np.median(runs["unit"]))
            row: dict = {"image": list(np.load(folder / "img.npy", mmap_mode="r").shape), "unit_process_s": unit,
                         "unit_process_runs_s": runs["unit"]}
            for version in ("before", "after"):
                rs = runs[version]
                med = {k: float(np.median([x[k] for x in rs])) for k in ("seconds", "cpu_s", "pixel_grid_fields_s",
                                                                          "peak_rss_mb", "peak_rss_with_fields_mb")}
                row[version] = dict(med, x_unit=med["seconds"] / unit, runs_s=[x["seconds"] for x in rs],
                                    valid_fraction=rs[0]["valid_fraction"], phi_eff_p95_abs_mD=rs[0]["phi_eff_p95_abs_mD"])
            row["speed_up_wall"] = row["before"]["seconds"] / row["after"]["seconds"]
            row["speed_up_cpu"] = row["before"]["cpu_s"] / row["after"]["cpu_s"]
            row["fields_after_vs_before"] = _largest_difference(folder / "before.npz", folder / "after.npz")
            rows[name] = row
            print(f"{name}: unit {unit:.2f} s; before {row['before']['seconds']:.2f} s wall "
                  f"{row['before']['cpu_s']:.2f} s CPU {row['before']['peak_rss_mb']:.0f} MB; after "
                  f"{row['after']['seconds']:.2f} s wall {row['after']['cpu_s']:.2f} s CPU {row['after']['peak_rss_mb']:.0f} MB",
                  flush=True)
    return rows


def _run_worker(task: dict, python: str | None = None, script: Path | None = None, env_src: Path | None = None) -> dict:
    cmd = [python or sys.executable, str(script or Path(__file__)), "--worker", json.dumps(task)]
    env = dict(os.environ)
    if env_src is not None:
        env["PYTHONPATH"] = str(env_src)
    env.setdefault("PYTHONPATH", str(HERE.parent / "src"))
    p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        return {"kind": task["kind"], "error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else "failed"}
    return json.loads(p.stdout.strip().splitlines()[-1])


def _openlsa_python() -> str | None:
    cand = os.environ.get("GLASSDIST_OPENLSA_PYTHON") or str(Path.home() / ".cache/glassdist/openlsa-venv/bin/python")
    return cand if Path(cand).exists() else None


def bench(sizes, peers=True, full_res_check=None):
    rows = []
    for shape in sizes:
        with tempfile.TemporaryDirectory() as d:
            make_images(shape, Path(d))
            base = {"folder": d}
            fft = _run_worker(dict(base, kind="rfft2"))
            row = {"shape": list(shape), "megapixels": shape[0] * shape[1] / 1e6, "rfft2_s": fft.get("seconds"),
                   "rfft2_first_call_s": fft.get("first_call_s")}
            kinds = ["direct", "comparative"] + (["farneback"] if peers else [])
            for k in kinds:
                r = _run_worker(dict(base, kind=k))
                if "seconds" in r and row["rfft2_s"]:
                    r["x_rfft2"] = r["seconds"] / row["rfft2_s"]
                    r["mpx_per_s"] = row["megapixels"] / r["seconds"]
                row[k] = r
            py = _openlsa_python() if peers else None
            if py:
                r = _run_worker(dict(base, kind="openlsa", pitch_px=PITCH_PX), python=py, script=HERE / "_openlsa_worker.py")
                if "displacement" in r:
                    disp = np.load(r.pop("displacement"))
                    valid = np.all(np.isfinite(disp), axis=-1)
                    r.update(_disp_error(disp, valid, max(1, int(np.sqrt(valid.size / 1e6)))))
                if "seconds" in r and row["rfft2_s"]:
                    r["x_rfft2"] = r["seconds"] / row["rfft2_s"]
                    r["mpx_per_s"] = row["megapixels"] / r["seconds"]
                row["openlsa"] = r
            if full_res_check and tuple(full_res_check) == tuple(shape):
                row["direct_full_resolution"] = _run_worker(
                    dict(base, kind="direct", params={"decimation": 1, "analysis_block": 1}))
                row["comparative_full_resolution"] = _run_worker(
                    dict(base, kind="comparative", params={"decimation": 1, "analysis_block": 1}))
        rows.append(row)
    return rows


def _fmt(rows) -> str:
    lines = ["| image | method | time s | x rfft2 | Mpx/s | first call s | + pixel-grid fields s | peak RSS MB | "
             "phi_eff ratio | phi_eff corr | disp. RMS err mm |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        size = f"{row['shape'][1]}x{row['shape'][0]}"
        lines.append(f"| {size} | numpy rfft2 | {row['rfft2_s']:.3f} | 1 | {row['megapixels'] / row['rfft2_s']:.1f} | "
                     f"{row.get('rfft2_first_call_s', float('nan')):.3f} | | | | | |")
        for k in ("direct", "comparative", "direct_full_resolution", "comparative_full_resolution", "farneback", "openlsa"):
            r = row.get(k)
            if not r:
                continue
            if "error" in r:
                lines.append(f"| {size} | {k} | failed: {r['error']} | | | | | | | | |")
                continue
            x = r.get("x_rfft2", r["seconds"] / row["rfft2_s"])
            lines.append(
                f"| {size} | {k} | {r['seconds']:.2f} | {x:.1f} | {row['megapixels'] / r['seconds']:.1f} | "
                f"{r.get('first_call_s', float('nan')):.2f} | {r.get('pixel_grid_fields_s', float('nan')):.2f} | "
                f"{r.get('peak_rss_mb', float('nan')):.0f} | {r.get('phi_eff_ratio', float('nan')):.4f} | "
                f"{r.get('phi_eff_corr', float('nan')):.4f} | {r.get('displacement_rms_error_mm', float('nan')):.4f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("--sizes", nargs="+", default=["2000x1500", "6000x4000"], help="WxH sizes")
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--full-res-check", default=None, help="WxH size on which to also run the full-resolution path")
    ap.add_argument("--out", type=Path, default=None, help="write the JSON results here")
    ap.add_argument("--before-src", type=Path, default=None,
                    help="time the analysis alone against the package in this src folder (module docstring)")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES), help="--before-src cases")
    ap.add_argument("--repeats", type=int, default=3, help="--before-src: runs of each version per case")
    ap.add_argument("--record", type=Path, default=None, help="--before-src: JSON record to merge the cases into")
    ap.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        task = json.loads(a.worker)
        print(json.dumps(analysis_worker(task) if task["kind"] == "analysis" else worker(task)))
        return 0
    if a.before_src:
        rows = compare_versions(a.cases, a.before_src.resolve(), a.repeats)
        command = "python benchmarks/bench_analyze.py " + " ".join(sys.argv[1:] if argv is None else argv)
        for row in rows.values():  # each case keeps the command that measured it, and the machine's load then
            row.update(command=command, cpu_count=os.cpu_count(), load_average_at_end=list(os.getloadavg()))
        if a.record:
            old = json.loads(a.record.read_text()) if a.record.exists() else {}
            a.record.write_text(json.dumps({
                "what": "analysis alone (prepare_reference + analyze), two versions alternating in fresh processes, "
                        "against one process that loads the image and runs one numpy rfft2 (unit); medians",
                "cases": dict(old.get("cases", {}), **rows)}, indent=1) + "\n")
        return 0
    parse = lambda s: tuple(int(v) for v in s.lower().split("x"))[::-1]  # noqa: E731 - WxH -> (H, W)
    sizes = [parse(s) for s in a.sizes]
    rows = bench(sizes, peers=not a.no_peers, full_res_check=parse(a.full_res_check) if a.full_res_check else None)
    table = _fmt(rows)
    print(table)
    if a.out:
        a.out.write_text(json.dumps({"rows": rows, "table": table, "wave": WAVE, "pitch_px": PITCH_PX, "params": PARAMS,
                                     "cpu_count": os.cpu_count()}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
