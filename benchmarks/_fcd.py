"""A compact fast checkerboard demodulation (FCD), a peer for comparison only.

Wildeman (2018), "Real-time quantitative Schlieren imaging by fast Fourier
demodulation of a checkered backdrop", Exp. Fluids 59, 97: the two carriers of the
reference are located in its spectrum; each is isolated in both photos by a disc of
radius ``min |k_i| / 2`` around it in the 2-D FFT; the phase difference of the two
analytic signals, unwrapped, gives the displacement ``u = -K^{-1} phi`` with the
rows of ``K`` the carrier wave vectors (rad/px).

Convention: ``I_def(r) = I_ref(r - u(r))`` (u in px, ``[..., 0]`` along columns,
``[..., 1]`` along rows). Independent of glassdist (own carrier search, filter and
unwrapping call) so that the two can be compared.
"""

from __future__ import annotations

import numpy as np
from skimage.restoration import unwrap_phase

__all__ = ["fcd_carriers", "fcd_displacement"]


def fcd_carriers(ref: np.ndarray) -> np.ndarray:
    """The two strongest spectral peaks of ``ref`` more than 45 deg apart, as wave vectors (rad/px), rows ``(kx, ky)``."""
    H, W = ref.shape
    win = np.outer(np.hanning(H), np.hanning(W))
    S = np.abs(np.fft.fft2((ref - ref.mean()) * win))
    fy = np.fft.fftfreq(H)[:, None]
    fx = np.fft.fftfreq(W)[None, :]
    fr = np.hypot(fx, fy)
    S[fr < 4.0 / min(H, W)] = 0.0  # DC and illumination
    S[(fy < 0) | ((fy == 0) & (fx < 0))] = 0.0  # one half-plane: each carrier once
    ks = []
    for _ in range(2):
        i = np.unravel_index(int(np.argmax(S)), S.shape)
        f = np.array([fx[0, i[1]], fy[i[0], 0]])
        ks.append(2 * np.pi * f)
        # Remove this peak and everything within 45 deg of its direction (its harmonics).
        cosang = np.abs(fx * f[0] + fy * f[1]) / np.maximum(fr * np.hypot(*f), 1e-12)
        S[cosang > np.cos(np.radians(45.0))] = 0.0
    return np.array(ks)


def _analytic(F: np.ndarray, k: np.ndarray, radius: float) -> np.ndarray:
    H, W = F.shape
    ky = 2 * np.pi * np.fft.fftfreq(H)[:, None]
    kx = 2 * np.pi * np.fft.fftfreq(W)[None, :]
    mask = (kx - k[0]) ** 2 + (ky - k[1]) ** 2 < radius**2
    return np.fft.ifft2(F * mask)


def fcd_displacement(ref: np.ndarray, img: np.ndarray) -> np.ndarray:
    """Displacement u (H, W, 2), px, with ``img(r) = ref(r - u(r))`` (see module notes)."""
    ref = np.asarray(ref, float)
    img = np.asarray(img, float)
    K = fcd_carriers(ref)
    radius = 0.5 * min(np.hypot(*K[0]), np.hypot(*K[1]))
    Fr, Fi = np.fft.fft2(ref), np.fft.fft2(img)
    phis = []
    for k in K:
        dphi = np.angle(_analytic(Fi, k, radius) * np.conj(_analytic(Fr, k, radius)))
        un = unwrap_phase(dphi, rng=0)
        un -= 2 * np.pi * np.round(np.median(un) / (2 * np.pi))
        phis.append(un)
    phi = np.stack(phis, axis=-1)  # phi_i = -k_i . u
    return -phi @ np.linalg.inv(K).T
