"""The Direct Method against the Comparative Method on the bundled photos, with and without the lens model.

Checkerboard, ``--pitch-mm 5 --distance-m 0.5``, detrend degrees 1-3; mean |phi_eff| over
each result's trusted pixels, Direct / Comparative, for ``lens_model`` none, radial (the
default) and radial + tangential + principal point (the table of docs/lens_calibration.md), after
the Direct Method's floor on this camera and board (the glass-less reference read by it)::

    PYTHONPATH=src python benchmarks/lens_photos.py
"""

from __future__ import annotations

import numpy as np

import glassdist
from glassdist.io import read_image

MODELS = ("none", "radial", "radial+tangential+center")


def main() -> None:
    ref = read_image("examples/data/reference.png")
    for name in ("distorted_waves.bmp", "distorted_floating_ring.bmp"):
        img = read_image(f"examples/data/{name}")
        for n in (1, 2, 3):
            common = dict(pitch_mm=5.0, distance_m=0.5)
            comp = glassdist.analyze(img, reference=ref, params={"detrend_degree": n, "pattern": "checkerboard"}, **common)
            c = float(np.mean(np.abs(comp.phi_eff_mD[comp.trusted])))
            row = []
            for lm in MODELS:
                res = glassdist.analyze(img, params={"detrend_degree": n, "pattern": "checkerboard", "lens_model": lm},
                                        **common)
                row.append(float(np.mean(np.abs(res.phi_eff_mD[res.trusted]))) / c)
            print(f"{name} N={n} comparative {c:.3f} mD; direct/comparative " +
                  ", ".join(f"{lm}: {r:.3f}" for lm, r in zip(MODELS, row)))


def floor() -> None:
    """The Direct Method's floor on this camera and board: the glass-less reference read by the Direct Method."""
    ref = read_image("examples/data/reference.png")
    H, W = ref.shape[:2]
    yy, xx = np.mgrid[0:H, 0:W]
    radius = np.hypot(xx - (W - 1) / 2, yy - (H - 1) / 2) / np.hypot(W / 2, H / 2)
    for lm in MODELS[1:]:
        for n in (1, 2, 3):
            res = glassdist.analyze(ref, pitch_mm=5.0, distance_m=0.5,
                                    params={"detrend_degree": n, "pattern": "checkerboard", "lens_model": lm})
            a = np.abs(res.phi_eff_mD)
            t = res.trusted
            rings = [float(np.mean(a[t & (radius >= r0) & (radius < r0 + 0.2)])) for r0 in (0.0, 0.2, 0.4, 0.6, 0.8)]
            print(f"reference.png alone (no glass), Direct N={n} {lm}: mean |phi_eff| {np.mean(a[t]):.2f} mD, "
                  f"p95 {np.percentile(a[t], 95):.2f} mD; by radius (centre to corner, 0.2 of the half diagonal each) "
                  + " ".join(f"{v:.2f}" for v in rings))


if __name__ == "__main__":
    floor()
    main()
