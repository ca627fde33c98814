"""Brown-Conrady lens distortion: the one model shared by the scene camera and the analyzer.

Normalised image coordinates ``x = (col - c_x) / s``, ``y = (row - c_y) / s`` (``s`` a
length in px: the focal length in px for OpenCV's convention) are distorted as

.. math::

   x_d = x\\,(1 + k_1 r^2 + k_2 r^4) + 2 p_1 x y + p_2 (r^2 + 2 x^2), \\qquad
   y_d = y\\,(1 + k_1 r^2 + k_2 r^4) + p_1 (r^2 + 2 y^2) + 2 p_2 x y, \\qquad r^2 = x^2 + y^2,

so ``k1 < 0`` is barrel (points pulled towards the centre), ``k1 > 0`` pincushion, and
``k1 < 0 < k2`` the moustache of wide-angle lenses. The coefficients are OpenCV's
(``cv2.calibrateCamera``'s ``k1, k2, p1, p2``) when ``s`` is the focal length in px.
Coefficients normalised by another length ``s'`` relate by ``k1' = k1 (s'/s)^2``,
``k2' = k2 (s'/s)^4``, ``p' = p (s'/s)`` (:meth:`BrownDistortion.rescaled`).

References
----------
D. C. Brown (1966), Photogramm. Eng. 32, 444 ("Decentering distortion of lenses");
OpenCV camera calibration documentation (the same model, its sign conventions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BrownDistortion"]


@dataclass(frozen=True)
class BrownDistortion:
    """Radial (``k1``, ``k2``) and tangential (``p1``, ``p2``) Brown distortion of normalised coordinates."""

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    @property
    def is_identity(self) -> bool:
        """True when every coefficient is zero (the ideal pinhole)."""
        return self.k1 == 0 and self.k2 == 0 and self.p1 == 0 and self.p2 == 0

    def distort(self, x, y):
        """Distorted normalised coordinates ``(x_d, y_d)`` of undistorted ``(x, y)`` (module equation)."""
        r2 = x * x + y * y
        g = 1.0 + r2 * (self.k1 + self.k2 * r2)
        return (x * g + 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x),
                y * g + self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y)

    def undistort(self, xd, yd, iterations: int = 40):
        """Undistorted ``(x, y)`` whose :meth:`distort` is ``(xd, yd)``.

        Fixed-point iteration ``x <- (x_d - t(x)) / g(x)`` (OpenCV's ``undistortPoints``),
        at most ``iterations`` steps and stopped once a step moves no point by more than
        1e-15 (checked every fourth step), followed by two Newton steps on the exact
        Jacobian, to rounding for the distortions of real lenses (``|k1| r^2`` well below 1).
        """
        xd = np.asarray(xd, float)
        yd = np.asarray(yd, float)
        if self.is_identity:
            return xd.copy(), yd.copy()
        x, y = xd.copy(), yd.copy()
        for i in range(iterations):
            r2 = x * x + y * y
            g = 1.0 + r2 * (self.k1 + self.k2 * r2)
            tx = 2 * self.p1 * x * y + self.p2 * (r2 + 2 * x * x)
            ty = self.p1 * (r2 + 2 * y * y) + 2 * self.p2 * x * y
            xn, yn = (xd - tx) / g, (yd - ty) / g
            # a real lens converges in 10-20 steps; the check costs a step's tenth, so not every step
            done = i % 4 == 3 and max(float(np.max(np.abs(xn - x), initial=0.0)),
                                      float(np.max(np.abs(yn - y), initial=0.0))) <= 1e-15
            x, y = xn, yn
            if done:
                break
        for _ in range(2):
            fx, fy = self.distort(x, y)
            a, b, c, d = self.jacobian(x, y)
            ex, ey = fx - xd, fy - yd
            det = a * d - b * c
            x, y = x - (d * ex - b * ey) / det, y - (a * ey - c * ex) / det
        return x, y

    def jacobian(self, x, y):
        """``(dxd/dx, dxd/dy, dyd/dx, dyd/dy)`` of :meth:`distort` at undistorted ``(x, y)``."""
        r2 = x * x + y * y
        g = 1.0 + r2 * (self.k1 + self.k2 * r2)
        dg = self.k1 + 2 * self.k2 * r2  # dg/d(r^2)
        a = g + 2 * x * x * dg + 2 * self.p1 * y + 6 * self.p2 * x
        b = 2 * x * y * dg + 2 * self.p1 * x + 2 * self.p2 * y
        c = 2 * x * y * dg + 2 * self.p1 * x + 2 * self.p2 * y
        d = g + 2 * y * y * dg + 6 * self.p1 * y + 2 * self.p2 * x
        return a, b, c, d

    def rescaled(self, factor: float) -> BrownDistortion:
        """The same distortion for coordinates normalised by ``factor`` times the length (``s' = factor s``)."""
        f = float(factor)
        return BrownDistortion(self.k1 * f**2, self.k2 * f**4, self.p1 * f, self.p2 * f)

    def to_dict(self) -> dict:
        """The coefficients as a JSON-ready mapping (``k1``, ``k2``, ``p1``, ``p2``)."""
        return {"k1": self.k1, "k2": self.k2, "p1": self.p1, "p2": self.p2}
