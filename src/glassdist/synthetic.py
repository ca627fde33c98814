"""Synthetic grid photos with a known displacement field (tests, benchmarks, examples).

A pixel ``r = (x, y)`` of the camera sees the backdrop point ``X0(r)`` (mm) without
glass -- an affine or projective map -- and ``X0(r) + delta(X0(r))`` with glass.
The photo is the backdrop pattern evaluated there. This is a 2-D warp, not a ray
trace: it is the ground truth for the Analyzer's own round trips (the ray-traced
Virtual Pipeline lives in :mod:`glassdist.render`).

The pattern is band-limited (Gaussian line profiles, smoothed checker edges) so
that point sampling does not alias.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["SyntheticCapture", "backdrop_pattern", "synthetic_capture", "wave_displacement", "lens_displacement"]

DisplacementFn = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class SyntheticCapture:
    """A synthetic distorted photo, its glass-less reference and the truth.

    Attributes
    ----------
    image, reference : ndarray (H, W) float64 in [0, 1]
    displacement_mm : ndarray (H, W, 2)
        True delta (x, y) at each pixel, mm.
    jacobian : ndarray (H, W, 2, 2)
        ``dX0/dr`` (backdrop mm per px) of the glass-less view.
    mm_per_px : float
        ``sqrt(|det J|)`` at the image centre.
    """

    image: np.ndarray
    reference: np.ndarray
    displacement_mm: np.ndarray
    jacobian: np.ndarray
    mm_per_px: float


def backdrop_pattern(X: np.ndarray, Y: np.ndarray, *, pitch_mm: float, pattern: str = "lines",
                     rotation_deg: float = 0.0, line_width: float = 0.25, contrast: float = 0.8) -> np.ndarray:
    """Intensity of the printed backdrop at backdrop points (X, Y) mm.

    ``lines``: dark lines (Gaussian profile, FWHM ``line_width * pitch``) every
    ``pitch_mm`` along both grid axes; ``checkerboard``: squares of side
    ``pitch_mm`` with softened edges; ``dots``: a square lattice of dark round dots
    (Gaussian profile, FWHM ``line_width * pitch``, as the lines: band-limited, so that a
    few pixels per period sample it without aliasing) every ``pitch_mm`` along both grid
    axes. The grid axes are rotated by ``rotation_deg`` (from +X towards +Y).
    """
    t = np.radians(rotation_deg)
    u = (np.cos(t) * X + np.sin(t) * Y) / pitch_mm
    v = (-np.sin(t) * X + np.cos(t) * Y) / pitch_mm
    if pattern == "lines":
        s = line_width / 2.3548
        du = u - np.round(u)
        dv = v - np.round(v)
        lu = np.exp(-0.5 * (du / s) ** 2)
        lv = np.exp(-0.5 * (dv / s) ** 2)
        ink = 1.0 - (1.0 - lu) * (1.0 - lv)
        return 0.9 - contrast * 0.9 * ink
    if pattern == "checkerboard":
        k = 3.0
        c = np.tanh(k * np.sin(np.pi * u)) * np.tanh(k * np.sin(np.pi * v)) / np.tanh(k) ** 2
        return 0.5 + 0.5 * contrast * c
    if pattern == "dots":
        s = line_width / 2.3548
        ink = np.exp(-0.5 * ((u - np.round(u)) ** 2 + (v - np.round(v)) ** 2) / s**2)
        return 0.9 - contrast * 0.9 * ink
    raise ValueError(f"unknown pattern {pattern!r}; use 'lines', 'checkerboard' or 'dots'")


def wave_displacement(amplitude_mm: float, wavelength_mm: float, direction_deg: float = 0.0,
                      polarization: str = "longitudinal") -> DisplacementFn:
    """delta(X) of a roller wave: ``A sin(2 pi s / Lambda)`` with ``s`` along ``direction_deg``.

    ``longitudinal``: delta along the wave vector (phi_eff = phi_shear magnitude);
    ``transverse``: delta perpendicular to it (pure shear, phi_eff = 0).
    """
    t = np.radians(direction_deg)
    e = np.array([np.cos(t), np.sin(t)])
    d = e if polarization == "longitudinal" else np.array([-e[1], e[0]])

    def fn(X, Y):
        a = amplitude_mm * np.sin(2 * np.pi * (e[0] * X + e[1] * Y) / wavelength_mm)
        return a * d[0], a * d[1]

    return fn


def lens_displacement(power_D: float, distance_m: float, center_mm=(0.0, 0.0), radius_mm: float = np.inf) -> DisplacementFn:
    """delta(X) of a thin lens of power P (D) at distance L from the backdrop, far-background limit.

    ``delta = L * dtheta = -P L r`` inside ``radius_mm`` (a converging lens pulls
    the landing points towards its axis); smooth Gaussian roll-off outside. The
    divergence is ``-2 P L`` so ``phi_eff = -2P`` (D), i.e. negative for P > 0.
    """
    cx, cy = center_mm
    k = -power_D * distance_m  # mm of delta per mm of radius (delta_m = L_m * dtheta, r in mm -> delta in mm)

    def fn(X, Y):
        dx, dy = X - cx, Y - cy
        if np.isinf(radius_mm):
            w = 1.0
        else:
            w = np.exp(-0.5 * (dx**2 + dy**2) / radius_mm**2)
        return k * dx * w, k * dy * w

    return fn


def synthetic_capture(
    shape: tuple[int, int],
    *,
    pitch_mm: float,
    mm_per_px: float,
    displacement: DisplacementFn | None = None,
    pattern: str = "lines",
    rotation_deg: float = 0.0,
    homography: np.ndarray | None = None,
    noise_std: float = 0.0,
    rng: np.random.Generator | int | None = 0,
    dtype=np.float64,
) -> SyntheticCapture:
    """Render a synthetic distorted photo and its reference with a known displacement.

    Parameters
    ----------
    shape : (H, W)
    pitch_mm : float
        Backdrop pitch (line spacing, dot spacing, or square side for a checkerboard), mm.
    mm_per_px : float
        Backdrop mm per image pixel at the image centre.
    displacement : callable (X, Y) -> (dX, dY), optional
        delta as a function of the glass-less landing point, mm.
    pattern, rotation_deg
        See :func:`backdrop_pattern`.
    homography : ndarray (3, 3), optional
        Extra projective map applied to centred pixel coordinates before scaling
        (perspective); identity by default.
    noise_std : float
        Gaussian noise added to both photos (intensity units).
    rng : Generator or int
        Seed or generator for the noise.
    """
    H, W = shape
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    xc, yc = x - (W - 1) / 2.0, y - (H - 1) / 2.0
    if homography is not None:
        Hm = np.asarray(homography, float)
        w = Hm[2, 0] * xc + Hm[2, 1] * yc + Hm[2, 2]
        px = (Hm[0, 0] * xc + Hm[0, 1] * yc + Hm[0, 2]) / w
        py = (Hm[1, 0] * xc + Hm[1, 1] * yc + Hm[1, 2]) / w
    else:
        px, py = xc, yc
    X0, Y0 = px * mm_per_px, py * mm_per_px
    J = np.empty((H, W, 2, 2))
    J[..., 0, 1], J[..., 0, 0] = np.gradient(X0)
    J[..., 1, 1], J[..., 1, 0] = np.gradient(Y0)
    if displacement is None:
        dX, dY = np.zeros_like(X0), np.zeros_like(Y0)
    else:
        dX, dY = displacement(X0, Y0)
        dX = np.broadcast_to(dX, X0.shape).astype(float)
        dY = np.broadcast_to(dY, Y0.shape).astype(float)
    kw = dict(pitch_mm=pitch_mm, pattern=pattern, rotation_deg=rotation_deg)
    ref = backdrop_pattern(X0, Y0, **kw)
    img = backdrop_pattern(X0 + dX, Y0 + dY, **kw)
    if noise_std > 0:
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        img = img + g.normal(0.0, noise_std, img.shape)
        ref = ref + g.normal(0.0, noise_std, ref.shape)
    img = np.clip(img, 0.0, 1.0).astype(dtype)
    ref = np.clip(ref, 0.0, 1.0).astype(dtype)
    Jc = J[H // 2, W // 2]
    return SyntheticCapture(img, ref, np.stack([dX, dY], -1), J, float(np.sqrt(abs(np.linalg.det(Jc)))))
