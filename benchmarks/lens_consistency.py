"""Block I's lens consistency test on synthetic grid points: a radial glass bump with and without a camera lens.

A 512 x 384 view of a regular grid (8 px per period), a radial Gaussian bump of 6 px
(width 50 or 100 px) at several places, seen through no camera lens or a barrel lens
(k1 = -0.02, half-diagonal normalisation). Printed per case: the joint fit's k1, k2, the
share of the bare homography's mean squared residual it removes (the lens is applied from
0.5) and the leave-out refit figures of :func:`glassdist.analyzer.lens.radial_consistency`
(refused above 0.2 for the inner disc, 0.3 for a quadrant); the figures of docs/user-guide/lens-calibration.md::

    PYTHONPATH=src python benchmarks/lens_consistency.py

``--through-block-i`` instead runs Block I's own decision (``refit_with_lens``: the strain masks,
the gain test, the leave-out checks) on grid samples seen through a real camera lens (k1 from
-0.06 to -0.10) with an off-axis glass bump growing until the gain test refuses the lens: where
the lens is refused, and by which check.
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


def through_block_i() -> None:
    """Block I's decision on a lens plus an off-axis bump of growing amplitude (384 x 512 px, 8 px period)."""
    import itertools

    from glassdist.analyzer import homography as hm

    h, w, step = 384, 512, 8.0
    H = np.array([[8.0, 0.3, 255.5 - 8 * 30], [-0.2, 8.2, 191.5 - 8.2 * 22], [1e-5, -2e-5, 1.0]])
    y, x = np.meshgrid(np.arange(step / 2, h, step), np.arange(step / 2, w, step), indexing="ij")
    for k1, amp, width in itertools.product((-0.06, -0.08, -0.10), (9.0, 11.0, 13.0), (80.0, 120.0)):
        lens = LensModel(BrownDistortion(k1), ((w - 1) / 2, (h - 1) / 2), float(np.hypot(w, h) / 2))
        xu, yu = lens.undistort_px(x, y)
        vx, vy = xu - 400.0, yu - 100.0  # the bump 174 px off the centre, towards a corner
        g = amp * np.exp(-(vx**2 + vy**2) / (2 * width**2)) / width
        U, V = hm.apply_inverse(H, xu - g * vx, yu - g * vy)
        fit = hm.refit_with_lens(hm.HomographyFit(H, 1.0, U.size, 0.0),
                                 hm.LogicalGrid(U, V, y, x, np.ones(U.shape, bool), 1, 8.0, (step, step)),
                                 hm.LensFitOptions(0.8, (h, w))).fit
        cal = fit.lens
        d = cal.consistency or {}
        verdict = "applied" if cal.identifiable else "refused: " + cal.note.split(" (")[0]
        print(f"k1 {k1:+.2f} bump {amp:4.1f} px x width {width:3.0f} px: d inner {d.get('inner', float('nan')):.3f}, "
              f"d quadrant {d.get('quadrants', float('nan')):.3f}; {verdict}")


if __name__ == "__main__":
    import sys

    through_block_i() if "--through-block-i" in sys.argv[1:] else main()
