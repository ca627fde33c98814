"""Optical-flow peers (OpenCV), written as the displacement glassdist and FCD report.

Every peer field is ``u`` (px) with ``img(r) = ref(r - u(r))``: defined at the photo's
pixels, as FCD's phase difference and glassdist's displacement are. The flow is therefore
computed from the photo to the reference: OpenCV's ``flow`` then satisfies
``img(r) = ref(r + flow(r))`` at the photo's pixels, and ``u = -flow`` exactly.

The flow the other way (reference to photo) is defined at the reference's pixels:
``ref(r) = img(r + f(r))``, so ``u(r) = f(r - u(r))``. Taking ``u = f`` is a first-order
approximation that errs by about ``(grad u) u``: on the waves photo's steep flanks
(displacement gradient about 0.3, displacement a few px) that is about 0.1 carrier period,
the agreement tolerance itself. Measured on the real ``distorted_waves.bmp`` (``benchmarks/_data.py``) with no-pyramid
Farneback (window 21 px, 30 iterations): FCD and the flow agree within 0.1 period on 84.3 % of
the photo with the first-order flow, on 94.1 % computed from the photo.
"""

from __future__ import annotations

import numpy as np

__all__ = ["farneback_displacement", "dis_displacement"]


def _u8(a: np.ndarray) -> np.ndarray:
    return np.clip(a * 255, 0, 255).astype(np.uint8)


def farneback_displacement(ref: np.ndarray, img: np.ndarray, winsize: int, iterations: int = 10, poly_n: int = 7,
                           poly_sigma: float = 1.5, levels: int = 1, gaussian: bool = True) -> np.ndarray:
    """Farneback flow as ``u`` (px, (H, W, 2): x, y) with ``img(r) = ref(r - u(r))``.

    ``levels`` = 1: no pyramid (the photo's own scale only; a pyramid locks onto the wrong
    period of a checkerboard).
    """
    import cv2

    flags = cv2.OPTFLOW_FARNEBACK_GAUSSIAN if gaussian else 0
    flow = cv2.calcOpticalFlowFarneback(_u8(img), _u8(ref), None, 0.5, levels, winsize, iterations, poly_n,
                                        poly_sigma, flags)
    return -flow.astype(float)


def dis_displacement(ref: np.ndarray, img: np.ndarray) -> np.ndarray:
    """DIS flow (finest scale, 12 px patches, stride 4) as ``u`` (px) with ``img(r) = ref(r - u(r))``.

    Finest pyramid level and long descents: the presets lock onto the wrong period of the grid.
    """
    import cv2

    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    dis.setFinestScale(0)
    dis.setPatchSize(12)
    dis.setPatchStride(4)
    dis.setGradientDescentIterations(25)
    return -dis.calc(_u8(img), _u8(ref), None).astype(float)
