"""Block A's transfer compensation against the closed form, with and without F5, both methods.

A small sinusoidal displacement ``A sin(2 pi x / Lambda)`` (0.005 carrier periods: the
demodulation is linear) is analysed; the reported (detrended, smoothed) displacement must
be the true one convolved with the Gaussian the result states (``effective_sigma_mm``):
amplitude ``A exp(-2 pi^2 s^2 / Lambda^2)``. The amplitude is read by least squares on
``sin``, ``cos`` and the detrend's own polynomial (total degree N in x, y: what the A2
detrend removed from the bounded sinusoid is a polynomial, and smoothing keeps it one) over
the samples more than 3 sigma inside the region. Judged wherever the smoothed wave keeps at
least 2 % of its amplitude (below it the result claims nothing about the wave).

Known gap, held at its measured size so that a change shows: after F5 the shortest ripple
(2.5 periods) reads 1.5-2.5 % low of the closed form (F5 stops after a few passes on so small
a wave, and the modelled response of those passes, ``(1 - (1 - G B)^n) / B``, is then high there).
"""

import numpy as np
import pytest
from scipy import ndimage

import glassdist
from glassdist.synthetic import synthetic_capture, wave_displacement

PITCH_PX = 8.0
SHAPE = (192, 512)
PERIODS = (2.5, 3.0, 4.0, 6.0, 10.0)
SIGMA_PERIODS = (0.75, 1.0, 1.5, 2.0, 3.0)
AMPLITUDE_PERIODS = 0.005
MIN_GAIN = 0.02
MODES = {"one pass": {"deformation_passes": 0}, "F5": {"deformation_min_deviation": 0.0}}


def _claimed(n: float, sp: float) -> bool:
    return np.exp(-2 * np.pi**2 * sp**2 / n**2) >= MIN_GAIN


def transfer_ratio(method: str, n: float, sp: float, params: dict) -> tuple[float, dict]:
    """Reported amplitude over the closed form's at the stated smoothing, and what the result states."""
    cap = synthetic_capture(SHAPE, pitch_mm=PITCH_PX, mm_per_px=1.0,
                            displacement=wave_displacement(AMPLITUDE_PERIODS * PITCH_PX, n * PITCH_PX, 0.0))
    degree = 0 if method == "comparative" else 2
    res = glassdist.analyze(cap.image, pitch_mm=PITCH_PX, distance_m=10.0,
                            reference=cap.reference if method == "comparative" else None,
                            params={**params, "detrend_degree": degree, "sigma_mm": sp * PITCH_PX})
    s_px = res.effective_sigma_mm / res.mm_per_px
    dist = ndimage.distance_transform_edt(np.pad(res.valid, 1))[1:-1, 1:-1]
    inner = res.valid & (dist > 3 * s_px)
    H, W = SHAPE
    y, x = np.mgrid[0:H, 0:W].astype(float)
    k = 2 * np.pi / (n * PITCH_PX)
    xs, ys = (x - W / 2) / W, (y - H / 2) / H
    cols = [np.sin(k * x), np.cos(k * x)] + [xs**i * ys**j for i in range(degree + 1) for j in range(degree + 1 - i)]
    B = np.stack([c[inner] for c in cols], 1)
    c = np.linalg.lstsq(B, res.displacement_detrended_mm[..., 0][inner], rcond=None)[0]
    truth = AMPLITUDE_PERIODS * PITCH_PX * res.mm_per_px * np.exp(-2 * np.pi**2 * s_px**2 / (n * PITCH_PX) ** 2)
    return float(np.hypot(c[0], c[1]) / truth), {"inner": int(inner.sum()), "demodulations": res.demodulations,
                                                  "effective_sigma_px": s_px}


@pytest.mark.slow
@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_compensated_ripple_is_the_truth_convolved_with_the_stated_gaussian(method, mode):
    off = {}
    for sp in SIGMA_PERIODS:
        for n in PERIODS:
            if not _claimed(n, sp):
                continue
            r, info = transfer_ratio(method, n, sp, MODES[mode])
            assert info["inner"] > 1000
            assert (info["demodulations"] > 1) == (mode == "F5")
            gap = mode == "F5" and n == 2.5
            if not (0.97 <= r <= 0.995 if gap else abs(r - 1) <= 0.01):
                off[(n, sp)] = round(r, 4)
    assert not off, f"{method}, {mode}: compensated / closed form off by more than 1 % at (periods, sigma): {off}"
