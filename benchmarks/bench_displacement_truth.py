"""The displacement output against a known displacement, beside two peers and the truth itself.

A synthetic checkerboard (``glassdist.synthetic.synthetic_capture``: 768 px, 10 px squares, a
carrier period of 14.1 px, camera noise 0.02) seen through a roller wave 80 px long (5.7 carrier
periods) of increasing strength, and its glass-less reference. The truth is the generator's own
displacement, ``u = -delta / mm_per_px`` at the photo's pixels (``img(r) = ref(r - u(r))``). Each field
is scored over glassdist's valid region:

* **error**: RMS over the pixels of the larger of the two components' error, carrier periods;
* **correlation**: the reference warped by the field, correlated with the photo (the waves photo's
  score, ``bench_waves_peers.py``), next to the truth's own, which bounds what a displacement can
  explain (camera noise, the pattern's blur);
* **amplitude**: regression slope of the field on the truth, both smoothed by one carrier period over
  glassdist's region (the waves benchmark's amplitude measure, ``bench_waves_peers.slope``), so that
  a peer's amplitude error is known where the waves photo compares glassdist with it.

glassdist runs with its defaults (Comparative Method) and with F5 forced on
(``{"deformation_min_deviation": 0}``): by default F5 runs only where the one-pass local grid
frequency departs from the carrier by more than 0.2 of it (p99), and it reads that on the one-pass
field, which Block F's transfer has already attenuated. "through its transfer" is the truth passed
through glassdist's documented transfer (``bench_waves_peers.matched``), against glassdist's field.

Usage::

    python benchmarks/bench_displacement_truth.py [--params JSON] [--out docs/records/displacement_truth.md]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _fcd import fcd_displacement  # noqa: E402
from _flow import farneback_displacement  # noqa: E402
from _record import write_record  # noqa: E402
from bench_waves_peers import FARNEBACK, correlation, field_px, matched, slope, smooth_nan, warp_reference  # noqa: E402

SHAPE = (768, 768)
MM_PER_PX = 0.5
PITCH_MM = 5.0
WAVELENGTH_MM = 40.0
AMPLITUDES_MM = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0)


def _error_periods(u: np.ndarray, truth: np.ndarray, where: np.ndarray, period: float) -> float:
    e = np.max(np.abs(u - truth), axis=-1)[where]
    return float(np.sqrt(np.nanmean(e**2)) / period)


def run_case(amplitude_mm: float, overrides: dict | None = None) -> dict:
    from glassdist import analyze
    from glassdist.synthetic import synthetic_capture, wave_displacement

    cap = synthetic_capture(SHAPE, pitch_mm=PITCH_MM, mm_per_px=MM_PER_PX, pattern="checkerboard", noise_std=0.02, rng=1,
                            displacement=wave_displacement(amplitude_mm, WAVELENGTH_MM, 30.0))
    ref, img = cap.reference, cap.image
    truth = -np.asarray(cap.displacement_mm) / MM_PER_PX
    runs = {"glassdist": dict(overrides or {}), "glassdist, F5 forced": {**(overrides or {}), "deformation_min_deviation": 0.0}}
    results = {k: analyze(img, reference=ref, pattern="checkerboard", pitch_mm=PITCH_MM, distance_m=1.0, params=p)
               for k, p in runs.items()}
    base = results["glassdist"]
    valid = base.valid
    period = max(base.carriers.k1.period_px, base.carriers.k2.period_px)
    fields = {"truth": truth}
    for k, res in results.items():
        fields[k] = field_px(res)
    fields["FCD"] = fcd_displacement(ref, img)
    fields["Farneback"] = farneback_displacement(ref, img, **FARNEBACK)  # the waves benchmark's peer
    # amplitude: the waves benchmark's measure (one carrier period of smoothing over glassdist's region), against the truth
    sm = {k: smooth_nan(np.where(valid[..., None], u, np.nan), period) for k, u in fields.items()}
    rows = {k: {"error_periods": _error_periods(u, truth, valid, period),
                "correlation": correlation(warp_reference(ref, u), img, valid),
                "amplitude_vs_truth": slope(sm[k], sm["truth"], valid)} for k, u in fields.items()}
    for k, res in results.items():
        through = matched(truth, res)
        rows[k]["demodulations"] = int(res.demodulations)
        rows[k]["vs_truth_through_transfer_periods"] = _error_periods(fields[k], through, valid & res.valid, period)
        rows[k]["amplitude_vs_truth_through_transfer"] = slope(
            sm[k], smooth_nan(np.where(valid[..., None], through, np.nan), period), valid)
    return {"amplitude_mm": amplitude_mm, "gradient": 2 * np.pi * amplitude_mm / WAVELENGTH_MM,
            "wavelength_periods": WAVELENGTH_MM / MM_PER_PX / period, "period_px": period,
            "analysed": float(valid.mean()), "rows": rows}


def table(recs: list[dict]) -> str:
    names = list(recs[0]["rows"])
    lines = ["| wave gradient | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for r in recs:
        cells = []
        for k in names:
            x = r["rows"][k]
            cell = f"{x['error_periods']:.4f} / {x['correlation']:.4f} / {x['amplitude_vs_truth']:.3f}"
            if "demodulations" in x:
                cell += (f" (n = {x['demodulations']}; {x['vs_truth_through_transfer_periods']:.4f} / "
                         f"{x['amplitude_vs_truth_through_transfer']:.3f})")
            cells.append(cell)
        lines.append(f"| {r['gradient']:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", default="{}", help="analyzer parameter overrides for both glassdist runs, JSON")
    ap.add_argument("--out", type=Path, help="write the table (markdown) and the record (FILE.json beside it)")
    a = ap.parse_args(argv)
    recs = [run_case(A, json.loads(a.params)) for A in AMPLITUDES_MM]
    text = ("Each cell: error against the truth (carrier periods, RMS) / correlation of the reference warped by "
            "the field with the photo / amplitude against the truth (slope after one carrier period of smoothing, "
            "the waves benchmark's measure); for glassdist also the demodulations, and the error and amplitude "
            f"against the truth through its documented transfer. Carrier period {recs[0]['period_px']:.2f} px, wave "
            f"{recs[0]['wavelength_periods']:.1f} periods long, {100 * recs[0]['analysed']:.1f} % of the image "
            "analysed.\n\n" + table(recs))
    print(text)
    if a.out:
        write_record(a.out, "bench_displacement_truth.py", argv, text, {"records": recs})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
