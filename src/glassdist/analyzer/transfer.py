"""The Analyzer's transfer function for a displacement field, and the exact smoothing that undoes it.

For a displacement (phase) field small enough for the demodulation to be linear,
every stage between the photo and the reported fields is a linear, shift-invariant
filter of the displacement component measured by carrier *i*. With ``nu`` a spatial
frequency in cycles/px (x, y order) and ``s`` the step of the grid each stage runs on:

* F1 bandpass, a Gaussian of frequency covariance ``Sigma_f`` centred on the carrier:
  ``B_i(nu) = exp(-nu^T Sigma_f^{-1} nu / 2)``, i.e. a spatial Gaussian of covariance
  ``Sigma_f^{-1} / (4 pi^2)`` px^2;
* F3 complex smoothing, a Gaussian of ``sigma_3 = lambda_i / 3`` px;
* the m x m block means of the analysis grid (fine step ``s``): the Dirichlet kernel
  ``D_m(nu) = sin(pi m s nu) / (m sin(pi s nu))`` per axis;
* the cubic B-spline interpolation of the fields to the image's pixel grid (grid step
  ``S``): ``beta^3(S nu) / b_3(S nu)`` per axis, ``beta^3(t) = sinc(t)^4`` and
  ``b_3(t) = (2 + cos 2 pi t) / 3`` the transform of the sampled spline;
* A3's five-point centred difference on the analysis grid: ``(8 sin w - sin 2w) / (6 w)``,
  ``w = 2 pi S nu``, for the derivative along that axis.

When F5 (iterative deformation, :mod:`~glassdist.analyzer.deform`) ran, the phase is the
prediction plus the residual measured against the reference warped by it; in the linear
regime each pass measures ``G_i (true - B pred)`` (``G_i`` the two Gaussian stages, ``B``
the bilinear interpolation by which the warped reference receives the prediction from the
demodulation grid), so after ``n`` demodulations (the one-pass one included) the Gaussian
stages' response is ``(1 - (1 - G_i B)^n) / B`` instead of ``G_i``: the smoothing no longer
attenuates what the passes have converged on.

The product of the first four is the *instrument transfer* ``H_i(nu)``. The A2 smoothing
then applies ``G_sigma(nu) / H_i(nu)`` (``G_sigma`` the requested Gaussian), so the
reported field is the true one convolved with ``G_sigma``, exactly where the
demodulation is linear. The Gaussian stages are divided out in closed form (a Gaussian
of covariance ``sigma^2 I - Sigma_i``), the others by their transfer on the FFT grid
of the smoothing (:func:`glassdist.analyzer.metrics.masked_filter`). Where
``sigma^2 I - Sigma_i`` is not positive the request is finer than the instrument can
resolve: the smoothing then stops at the instrument's own blur along those directions
(:meth:`InstrumentTransfer.effective_sigma_px`), and the Analyzer says so.

References
----------
Unser (1999), "Splines: a perfect fit for signal and image processing", IEEE Signal
Proc. Mag. 16(6) (B-spline interpolation). Paper §2.2 (F1-F3, metric-anchored smoothing).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "InstrumentTransfer",
    "gaussian_response",
    "dirichlet_response",
    "bspline_response",
    "difference_response",
]

#: Smallest non-Gaussian transfer divided out; below it the correction is capped
#: (the block-mean and interpolation responses stay above 0.6 up to the grid's Nyquist
#: frequency, so the cap only acts on content the smoothing has already removed).
MIN_RESPONSE = 0.25


def gaussian_response(cov_px2: np.ndarray, fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
    """Transfer of a Gaussian of spatial covariance ``cov_px2`` (px^2, (x, y) order) at ``(fy, fx)`` cycles/px."""
    c = np.asarray(cov_px2, float)
    q = c[0, 0] * fx**2 + 2.0 * c[0, 1] * fx * fy + c[1, 1] * fy**2
    return np.exp(-2.0 * np.pi**2 * q)


def dirichlet_response(m: int, step_px: float, f: np.ndarray) -> np.ndarray:
    """Transfer of the mean of ``m`` samples ``step_px`` apart, at frequency ``f`` (cycles/px)."""
    if m <= 1:
        return np.ones_like(np.asarray(f, float))
    a = np.pi * step_px * np.asarray(f, float)
    num = np.sin(m * a)
    den = m * np.sin(a)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.abs(den) > 1e-12, num / np.where(den == 0, 1.0, den), 1.0)


def bspline_response(step_px: float, f: np.ndarray) -> np.ndarray:
    """Mean transfer of cubic B-spline interpolation from samples ``step_px`` apart (baseband term)."""
    t = step_px * np.asarray(f, float)
    return np.sinc(t) ** 4 / ((2.0 + np.cos(2.0 * np.pi * t)) / 3.0)


def difference_response(step_px: float, f: np.ndarray) -> np.ndarray:
    """Transfer of the five-point centred difference relative to the exact derivative ``2 pi i f``."""
    w = 2.0 * np.pi * step_px * np.asarray(f, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (8.0 * np.sin(w) - np.sin(2.0 * w)) / (6.0 * np.where(w == 0, 1.0, w))
    return np.where(np.abs(w) < 1e-9, 1.0, r)


@dataclass(frozen=True)
class InstrumentTransfer:
    """Linear transfer of the Analyzer's stages before and after the A2 smoothing, per component.

    Attributes
    ----------
    gaussian_px2 : ndarray (2, 2, 2)
        Per displacement component, covariance (px^2, (x, y) order) of the Gaussian
        stages (F1 bandpass and F3 complex smoothing of that component's carrier).
    fine_step_px : (float, float)
        ``(sy, sx)``: step of the demodulation grid the block means are taken on, px.
    block : int
        Block factor m of the analysis grid (1: no block means).
    interp_step_px : (float, float) or None
        ``(sy, sx)``: step of the grid the fields are interpolated from (cubic
        B-spline), px; None when the fields are on the pixel grid already.
    passes : int
        Demodulations the displacement sums (F5's; 1: the one-pass demodulation, whose
        Gaussian stages are Gaussian and divided out in closed form). Above 1 their
        response is ``(1 - (1 - G_i B)^passes) / B`` (module notes), divided out with the
        non-Gaussian stages, per component.
    photo_passes : int
        F5's photo passes after those (0: none). They start from the field of the ``passes``
        low-passed by a Gaussian of ``restart_sigma_px``: the response is
        ``(1 - (1 - G_i B)^k (1 - L (1 - (1 - G_i B)^passes))) / B``, ``k`` the photo passes
        and ``L`` that Gaussian's response.
    restart_sigma_px : float
        Sigma of the low-pass the photo passes start from, px.
    """

    gaussian_px2: np.ndarray
    fine_step_px: tuple[float, float] = (1.0, 1.0)
    block: int = 1
    interp_step_px: tuple[float, float] | None = None
    passes: int = 1
    photo_passes: int = 0
    restart_sigma_px: float = 0.0

    def non_gaussian(self, fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        """Transfer of the block means and the interpolation at ``(fy, fx)`` cycles/px."""
        sy, sx = self.fine_step_px
        r = dirichlet_response(self.block, sy, fy) * dirichlet_response(self.block, sx, fx)
        if self.interp_step_px is not None:
            iy, ix = self.interp_step_px
            r = r * bspline_response(iy, fy) * bspline_response(ix, fx)
        return r

    def prediction_interpolation(self, fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        """``B``: the bilinear interpolation by which F5's synthesised reference receives the prediction.

        The prediction comes from the demodulation grid.
        """
        sy, sx = self.fine_step_px
        return np.sinc(sy * fy) ** 2 * np.sinc(sx * fx) ** 2

    def demodulation(self, component: int, fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        """Response of the demodulation's Gaussian stages: ``G_i``, or ``(1 - (1 - G_i B)^n) / B`` after F5."""
        g = gaussian_response(self.gaussian_px2[component], fy, fx)
        if self.total_passes <= 1:
            return g
        b = self.prediction_interpolation(fy, fx)
        left = (1.0 - g * b) ** self.passes
        if self.photo_passes > 0:
            low = gaussian_response(self.restart_sigma_px**2 * np.eye(2), fy, fx)
            left = (1.0 - g * b) ** self.photo_passes * (1.0 - low * (1.0 - left))
        return (1.0 - left) / b

    @property
    def total_passes(self) -> int:
        """All the demodulations the displacement went through: ``passes`` and ``photo_passes``."""
        return int(self.passes) + int(self.photo_passes)

    def response(self, component: int, fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        """``H_i(nu)``: end-to-end transfer of displacement component ``component`` (0 or 1)."""
        return self.demodulation(component, fy, fx) * self.non_gaussian(fy, fx)

    def residual_cov_px2(self, component: int, sigma_px: float) -> np.ndarray:
        """Covariance of the Gaussian still to apply, px^2.

        One pass: ``s^2 I - Sigma_i`` with ``s`` the sigma reached (:meth:`effective_sigma_px`,
        at least the largest blur of either component, so the difference is positive and every
        direction and component carries the same Gaussian of ``s``, the one the result states).
        After F5 the demodulation's response is not Gaussian and :meth:`component_correction`
        divides it out: the whole Gaussian of ``s`` remains to apply.
        """
        s = self.effective_sigma_px(sigma_px)
        if self.total_passes > 1:
            return s**2 * np.eye(2)
        w, V = np.linalg.eigh(s**2 * np.eye(2) - np.asarray(self.gaussian_px2[component], float))
        return (V * np.clip(w, 0.0, None)) @ V.T

    def correction(self, fy: np.ndarray, fx: np.ndarray) -> np.ndarray:
        """``1 / (non-Gaussian transfer)``, capped at ``1 / MIN_RESPONSE``."""
        return 1.0 / np.maximum(self.non_gaussian(fy, fx), MIN_RESPONSE)

    def component_correction(self, component: int):
        """The transfer the smoothing of ``component`` divides out beyond :meth:`residual_cov_px2`'s Gaussian.

        One pass: :meth:`correction`. After F5: ``1 / H_i``, capped at ``1 / MIN_RESPONSE``
        (where ``H_i`` falls below it the Gaussian of at least the instrument's resolution
        has already removed the content).
        """
        if self.total_passes <= 1:
            return self.correction
        return lambda fy, fx: 1.0 / np.maximum(self.response(component, fy, fx), MIN_RESPONSE)

    def resolution_px(self) -> float:
        """Finest Gaussian sigma the smoothing can reach: the instrument's largest Gaussian blur, px."""
        return float(np.sqrt(max(float(np.max(np.linalg.eigvalsh(c))) for c in self.gaussian_px2)))

    def effective_sigma_px(self, sigma_px: float) -> float:
        """The sigma actually reached: the request, or the instrument's resolution when it is finer."""
        return max(float(sigma_px), self.resolution_px())

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping."""
        return {
            "gaussian_px2": np.asarray(self.gaussian_px2).tolist(),
            "fine_step_px": list(self.fine_step_px),
            "block": int(self.block),
            "interp_step_px": None if self.interp_step_px is None else list(self.interp_step_px),
            "resolution_px": self.resolution_px(),
            "passes": int(self.passes),
            "photo_passes": int(self.photo_passes),
            "restart_sigma_px": float(self.restart_sigma_px),
        }
