"""The Direct Method against the Comparative Method on the bundled photos, with and without the lens model.

Checkerboard, ``--pitch-mm 5 --distance-m 0.5``, detrend degrees 1-3; mean |phi_eff| over
each result's trusted pixels, Direct / Comparative, for ``lens_model`` none, radial (the
default) and radial + tangential + principal point (the table of docs/lens_calibration.md)::

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


if __name__ == "__main__":
    main()
