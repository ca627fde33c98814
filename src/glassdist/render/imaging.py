"""Optional imaging effects applied to a rendered radiance image.

Order: uneven lighting, vignetting, optical blur, sensor noise, clipping to [0, 1].
All effects are deterministic given the generator.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.ndimage import gaussian_filter

from ..scene import Imaging

__all__ = ["apply_imaging"]


def apply_imaging(image: np.ndarray, imaging: Imaging, rng: np.random.Generator) -> np.ndarray:
    """Apply lighting, vignetting, blur and noise to a linear image in [0, 1].

    Parameters
    ----------
    image : ndarray (H, W)
        Linear radiance in [0, 1].
    imaging : Imaging
    rng : numpy.random.Generator
        Source of the noise.

    Returns
    -------
    ndarray (H, W), float64 in [0, 1]

    Notes
    -----
    Lighting gain :math:`1 + g\\,t` with :math:`t \\in [-1, 1]` the position along
    ``direction_deg``; vignetting gain :math:`1 - v (r / r_{corner})^2`; Gaussian
    blur of ``blur_px``; shot noise :math:`\\mathrm{Poisson}(I N_{fw}) / N_{fw}`
    and Gaussian read noise of standard deviation ``read_noise``.
    """
    img = np.asarray(image, float)
    H, W = img.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    xc, yc = xx - (W - 1) / 2, yy - (H - 1) / 2
    if imaging.lighting is not None and imaging.lighting.gradient > 0:
        t = math.radians(imaging.lighting.direction_deg)
        proj = xc * math.cos(t) + yc * math.sin(t)
        img = img * (1.0 + imaging.lighting.gradient * proj / max(np.abs(proj).max(), 1e-12))
    if imaging.vignetting > 0:
        r2 = (xc**2 + yc**2) / (xc[0, 0] ** 2 + yc[0, 0] ** 2)
        img = img * (1.0 - imaging.vignetting * r2)
    if imaging.blur_px > 0:
        img = gaussian_filter(img, imaging.blur_px, mode="nearest")
    if imaging.noise is not None:
        if imaging.noise.full_well_e is not None:
            fw = imaging.noise.full_well_e
            img = rng.poisson(np.clip(img, 0, None) * fw) / fw
        if imaging.noise.read_noise > 0:
            img = img + rng.normal(0.0, imaging.noise.read_noise, img.shape)
    return np.clip(img, 0.0, 1.0)
