"""The Direct Method against the Comparative Method on the real photos (``benchmarks/_data.py``), with and without the lens model.

Checkerboard, ``--pitch-mm 5 --distance-m 0.5``, detrend degrees 1-3; mean |phi_eff| over
each result's trusted pixels, Direct / Comparative, for ``lens_model`` none, radial (the
default) and radial + tangential + principal point (the table of docs/user-guide/lens-calibration.md), after
the Direct Method's floor on this camera and board (the glass-less reference read by it)::

    PYTHONPATH=src python benchmarks/lens_photos.py

``--variants`` instead reads each photo and its reference through changes that leave the pane's
distortion as it is (intensities inverted, mirrored, seeded noise, 5 % exposure, half and 1.7×
size, a 3 px blur) and tabulates the radial self-calibration's leave-out figures, whether the
lens was applied and Direct / Comparative at N = 2 and 3 (docs/user-guide/lens-calibration.md, "How stable
the decision is")::

    PYTHONPATH=src python benchmarks/lens_photos.py --variants
"""

from __future__ import annotations

import numpy as np
from _data import real_photos

import glassdist
from glassdist.io import read_image

MODELS = ("none", "radial", "radial+tangential+center")


def main() -> None:
    ref = read_image(real_photos() / "reference.png")
    for name in ("distorted_waves.bmp", "distorted_floating_ring.bmp"):
        img = read_image(real_photos() / name)
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
    ref = read_image(real_photos() / "reference.png")
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


def variants() -> None:
    """The lens decision and Direct / Comparative on variants of each photo that keep the pane's distortion."""
    import logging

    import cv2

    logging.disable(logging.WARNING)  # the table says what matters here; each run's warnings are logged
    ref = read_image(real_photos() / "reference.png")

    def scaled(a, f):
        return cv2.resize(a.astype(np.float32), None, fx=f, fy=f, interpolation=cv2.INTER_AREA if f < 1 else cv2.INTER_CUBIC)

    changes = {
        "as bundled": lambda a: a,
        "inverted": lambda a: 1.0 - a,
        "mirrored": lambda a: a[:, ::-1].copy(),
        "noise 0.08": lambda a: np.clip(a + np.random.default_rng(0).normal(0, 0.08, a.shape), 0, 1),
        "exposure 5 %": lambda a: 0.05 * a,
        "half size": lambda a: scaled(a, 0.5),
        "1.7x size": lambda a: scaled(a, 1.7),
        "blur 3 px": lambda a: cv2.GaussianBlur(a.astype(np.float32), (0, 0), 3),
    }
    print("| photo | change | d inner | d quadrant | lens applied | Direct / Comparative, N = 2 | N = 3 |")
    print("|---|---|---|---|---|---|---|")
    for name in ("distorted_waves.bmp", "distorted_floating_ring.bmp"):
        img = read_image(real_photos() / name)
        for label, f in changes.items():
            # noise (seeded) and blur touch the photo alone, as a second capture of the pane would; the
            # other changes apply to the photo and its reference alike
            im, rf = f(img), (ref if label.startswith(("noise", "blur")) else f(ref))
            ratios = []
            for n in (2, 3):
                common = dict(pitch_mm=5.0, distance_m=0.5, params={"detrend_degree": n, "pattern": "checkerboard"})
                comp = glassdist.analyze(im, reference=rf, **common)
                res = glassdist.analyze(im, **common)
                ratios.append(float(np.mean(np.abs(res.phi_eff_mD[res.trusted])) /
                                    np.mean(np.abs(comp.phi_eff_mD[comp.trusted]))))
            cal = res.homography_fit.lens
            cons = cal.consistency if cal is not None else {}
            print(f"| {name} | {label} | {cons.get('inner', float('nan')):.3f} | {cons.get('quadrants', float('nan')):.3f} | "
                  f"{'yes' if res.homography_fit.lens_model is not None else 'no'} | {ratios[0]:.3f} | {ratios[1]:.3f} |",
                  flush=True)


if __name__ == "__main__":
    import sys

    if "--variants" in sys.argv[1:]:
        variants()
    else:
        floor()
        main()
