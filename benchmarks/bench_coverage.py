"""Coverage and precision of glassdist's analysed region against independent peers.

Peers: a compact fast checkerboard demodulation (``benchmarks/_fcd.py``, Wildeman
2018) and OpenCV's DIS and Farneback optical flow, all given the reference and the
distorted photo. The *agreement area* is where FCD agrees within 0.1 carrier period
(max over the two displacement components) with at least one of the two flows (each
flow alone fails in places on a periodic pattern: it locks onto the wrong period);
glassdist (Comparative Method) is then scored by

* coverage: share of the agreement area inside glassdist's analysed region (``valid``),
* precision: share of the analysed region inside the agreement area,
* accuracy: share of the analysed region where glassdist agrees with FCD within 0.1 period.

Cases: the real photos (``benchmarks/_data.py``) (1024 px), 320 px centre crops and 320 px
downscales of them, each also with an opaque drop (a dark disc, 120 px across at
1024 px) painted into the distorted photo; synthetic renders (line grid and
checkerboard, 512 and 320 px, a roller wave, with and without a drop).

Usage::

    python benchmarks/bench_coverage.py [--params JSON] [--out FILE.json] [--cases SUBSTR,...] [--before FILE.json]

``--out docs/records/coverage.json`` is the record docs/validation/accuracy.md shows; ``--before`` embeds an
earlier run's records (e.g. of an earlier version) as the "before" columns.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from _fcd import fcd_carriers, fcd_displacement  # noqa: E402 (the benchmarks' own helpers, after sys.path)
from _flow import dis_displacement, farneback_displacement  # noqa: E402

TOL_PERIODS = 0.1


def _paint_drop(img: np.ndarray, diameter_px: float, centre=(0.42, 0.58)) -> np.ndarray:
    H, W = img.shape
    yy, xx = np.mgrid[0:H, 0:W]
    r = np.hypot(yy - centre[0] * H, xx - centre[1] * W)
    edge = np.clip((r - diameter_px / 2 + 2.0) / 4.0, 0.0, 1.0)  # 4 px soft rim
    return img * edge + 0.08 * (1.0 - edge)


def cases(names: list[str] | None):
    import cv2
    from _data import real_photos

    from glassdist.io import read_image
    from glassdist.synthetic import synthetic_capture, wave_displacement

    data = real_photos()
    ref = read_image(data / "reference.png")
    out = []
    for stem in ("distorted_waves", "distorted_floating_ring"):
        img = read_image(data / f"{stem}.bmp")
        c0 = (ref.shape[0] - 320) // 2
        crop = (slice(c0, c0 + 320), slice(c0, c0 + 320))
        variants = {
            "1024": (ref, img, 120.0),
            "crop320": (ref[crop], img[crop], 120.0),
            "down320": (cv2.resize(ref, (320, 320), interpolation=cv2.INTER_AREA),
                        cv2.resize(img, (320, 320), interpolation=cv2.INTER_AREA), 120.0 * 320 / 1024),
        }
        for v, (r_, i_, d) in variants.items():
            out.append((f"{stem}/{v}", r_, i_, "checkerboard"))
            out.append((f"{stem}/{v}+drop", r_, _paint_drop(i_, d), "checkerboard"))
    for pattern in ("lines", "checkerboard"):
        for n in (512, 320):
            cap = synthetic_capture((n, n), pitch_mm=5.0, mm_per_px=0.5, pattern=pattern, noise_std=0.02, rng=1,
                                    displacement=wave_displacement(0.4, 80.0, 30.0))
            out.append((f"synthetic_{pattern}/{n}", cap.reference, cap.image, pattern))
            out.append((f"synthetic_{pattern}/{n}+drop", cap.reference, _paint_drop(cap.image, 120.0), pattern))
    if names:
        out = [c for c in out if any(s in c[0] for s in names)]
    return out


def score(name, ref, img, pattern, params) -> dict:
    from glassdist import analyze

    t0 = time.perf_counter()
    res = analyze(img, pitch_mm=5.0, distance_m=1.0, reference=ref, pattern=pattern, params=params)
    t_gd = time.perf_counter() - t0
    period = max(res.carriers.k1.period_px, res.carriers.k2.period_px)
    gd = -res.displacement_mm / res.mm_per_px  # u = -delta (px)
    fcd = fcd_displacement(ref, img)
    k = fcd_carriers(ref)
    period_fcd = float(2 * np.pi / min(np.hypot(*k[0]), np.hypot(*k[1])))
    dis = dis_displacement(ref, img)
    farn = farneback_displacement(ref, img, 15, 5, 5, 1.2, levels=3, gaussian=False)

    def close(a, b):
        with np.errstate(invalid="ignore"):
            return np.nanmax(np.abs(a - b), axis=-1) < TOL_PERIODS * period

    agree = close(fcd, dis) | close(fcd, farn)
    valid = res.valid
    inside = valid & agree
    q = getattr(res, "quality", None)
    rec = {
        "case": name,
        "shape": list(img.shape),
        "period_px": period,
        "period_px_fcd": period_fcd,
        "agree_area": float(agree.mean()),
        "agree_fcd_dis": float(close(fcd, dis).mean()),
        "agree_fcd_farneback": float(close(fcd, farn).mean()),
        "analysed": float(valid.mean()),
        "coverage": float(inside.sum() / max(agree.sum(), 1)),
        "precision": float(inside.sum() / max(valid.sum(), 1)),
        "accuracy": float((valid & close(gd, fcd)).sum() / max(valid.sum(), 1)),
        "glassdist_s": t_gd,
        "warnings": list(res.warnings),
    }
    if q is not None:
        rec["quality_counts"] = {int(v): int(c) for v, c in zip(*np.unique(np.asarray(q), return_counts=True))}
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    ap.add_argument("--params", default="{}", help="analyzer parameter overrides, JSON")
    ap.add_argument("--out", type=Path, help="write the records as JSON")
    ap.add_argument("--cases", help="comma-separated substrings of the case names to run")
    ap.add_argument("--before", type=Path, help="an earlier run's JSON, embedded as the 'before' records")
    ap.add_argument("--before-command", default="", help="how the --before record was made (shown with it)")
    a = ap.parse_args(argv)
    params = json.loads(a.params)
    recs = []
    print("| case | px | agree area | analysed | coverage | precision | accuracy |")
    print("|---|---|---|---|---|---|---|")
    for name, ref, img, pattern in cases(a.cases.split(",") if a.cases else None):
        r = score(name, ref, img, pattern, params)
        recs.append(r)
        print(f"| {name} | {r['shape'][0]} | {100 * r['agree_area']:.1f} % | {100 * r['analysed']:.1f} % | "
              f"{100 * r['coverage']:.1f} % | {100 * r['precision']:.1f} % | {100 * r['accuracy']:.1f} % |", flush=True)
    if a.out:
        import glassdist

        args = shlex.join(argv if argv is not None else sys.argv[1:])
        out = {"command": f"python benchmarks/bench_coverage.py {args}".strip(), "glassdist_version": glassdist.__version__,
               "params": params, "tolerance_periods": TOL_PERIODS, "records": recs}
        if a.before:
            prev = json.loads(a.before.read_text())
            out["before"] = {"command": a.before_command or prev.get("command", ""), "records": prev["records"]}
        a.out.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
