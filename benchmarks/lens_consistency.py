"""Block I's lens consistency test on synthetic grid points: a radial glass bump with and without a camera lens.

A 512 x 384 view of a regular grid (8 px per period), a radial Gaussian bump of 6 px
(width 50 or 100 px) at several places, seen through no camera lens or a barrel lens
(k1 = -0.02, half-diagonal normalisation). Printed per case: the joint fit's k1, k2, the
share of the bare homography's mean squared residual it removes (the lens is applied from
0.5) and the leave-out refit figures of :func:`glassdist.analyzer.lens.radial_consistency`
(refused above 0.2 for the inner disc, 0.3 for a quadrant); the figures of docs/lens_calibration.md::

    PYTHONPATH=src python benchmarks/lens_consistency.py
"""

from __future__ import annotations

import numpy as np

from glassdist.analyzer.lens import LensModel, fit_lens_homography, radial_consistency
from glassdist.brown import BrownDistortion

CENTRE, SCALE = (255.5, 191.5), 320.0


def main() -> None:
    U, V = np.meshgrid(np.arange(-30, 31, 1.0), np.arange(-22, 23, 1.0))
    src = np.c_[U.ravel(), V.ravel()]
    H = np.array([[8.0, 0.0, CENTRE[0]], [0.0, 8.0, CENTRE[1]], [0, 0, 1.0]])
    q = src @ H[:2, :2].T + H[:2, 2]
    for k1 in (0.0, -0.02):
        for ctr in ((300, 200), (330, 230), (380, 250), (420, 110), (150, 100)):
            for width in (50.0, 100.0):
                v = q - np.asarray(ctr)
                pu = q + 6.0 * np.exp(-np.sum(v**2, 1) / (2 * width**2))[:, None] * v / width
                dst = np.stack(LensModel(BrownDistortion(k1), CENTRE, SCALE).distort_px(pu[:, 0], pu[:, 1]), 1)
                Hf, lf, _, e = fit_lens_homography(src, dst, H, center_px=CENTRE, scale_px=SCALE)
                _, _, _, e0 = fit_lens_homography(src, dst, H, center_px=CENTRE, scale_px=SCALE, fix_distortion=True)
                gain = 1.0 - float(np.mean(e**2) / np.mean(e0**2))
                d = radial_consistency(src, dst, Hf, lf, scale_px=SCALE)
                off = float(np.hypot(ctr[0] - CENTRE[0], ctr[1] - CENTRE[1]))
                print(f"k1 {k1:+.2f} bump {off:5.0f} px off centre, width {width:3.0f} px: fitted k1 {lf.distortion.k1:+.4f} "
                      f"k2 {lf.distortion.k2:+.4f}, gain {gain:.2f}, d inner {d['inner']:.3f}, d quadrant {d['quadrants']:.3f}")


if __name__ == "__main__":
    main()
