"""Two captures, one pane: both on the intrinsic axis, their difference and its uncertainty.

Each capture's channels are brought to the pane's intrinsic reading
(:func:`glassdist.viewpoint.intrinsic.intrinsic_reading`, its stored geometry), over the
pane area both captures trust: every trusted pixel of one whose pane point falls on a
trusted pixel of the other (nearest pixel). What it needs: the camera aimed at the pane
centre (the image centre), the image axes along the pane's edges, ``--camera-distance-m``
given at analysis and, for an oblique capture, its angle (``--camera-angle-deg`` or the
Direct homography's).

The uncertainty of a capture's mean is the noise part, the median standard
uncertainty over ``sqrt(n_eff)`` (``n_eff`` the trusted area over the smoothing's
``4 pi sigma^2``), and the model part, :data:`MODEL_RELATIVE_UNCERTAINTY` of the reading
(the first-order chain and one capture's own analysis error: two ray-traced captures of
one pane at Dc 3 m / L 1 m and Dc 6 m / L 0.5 m differ by 0.25 % (a roller wave) to
2.7 % (a lens), tests/test_viewpoint.py). The difference is
consistent with zero when within the expanded uncertainty ``U = 2 u`` (coverage k = 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..analyzer.metrics import channel_statistics
from .intrinsic import IntrinsicReading, intrinsic_reading, pane_to_pixels
from .view import capture_sigma_mm, stored_geometry, trusted_pixels

__all__ = [
    "COVERAGE_FACTOR",
    "MODEL_RELATIVE_UNCERTAINTY",
    "ChannelDifference",
    "Comparison",
    "compare_results",
    "stored_reading",
]

#: Relative standard uncertainty of one capture's intrinsic mean from the model and the analysis.
MODEL_RELATIVE_UNCERTAINTY = 0.015
#: Coverage factor of the expanded uncertainty.
COVERAGE_FACTOR = 2.0


@dataclass(frozen=True)
class ChannelDifference:
    """One statistic of both captures and their difference (mD).

    Attributes
    ----------
    a, b : float
        The statistic of each capture's intrinsic reading over the common pane area.
    difference : float
        ``a - b``.
    uncertainty : float
        Combined standard uncertainty ``u`` of the difference.
    expanded_uncertainty : float
        ``U = k u``.
    consistent : bool
        ``|a - b| <= U``.
    """

    a: float
    b: float
    difference: float
    uncertainty: float
    expanded_uncertainty: float
    consistent: bool

    def to_dict(self) -> dict:
        """JSON-serialisable form (``consistent`` as ``consistent_with_zero``)."""
        return {"a": self.a, "b": self.b, "difference": self.difference, "uncertainty": self.uncertainty,
                "expanded_uncertainty": self.expanded_uncertainty, "consistent_with_zero": self.consistent}


@dataclass(frozen=True)
class Comparison:
    """The two captures on the intrinsic axis.

    Attributes
    ----------
    phi_eff_mean_abs, phi_shear_mean : ChannelDifference
        Mean |phi_eff| and mean phi_shear, mD.
    common_pane_percent : (float, float)
        Share of each capture's trusted pixels inside the common area.
    pane_sigma_mm : (float, float)
        Each reading's smoothing on the pane, mm.
    warnings : tuple of str
    """

    phi_eff_mean_abs: ChannelDifference
    phi_shear_mean: ChannelDifference
    common_pane_percent: tuple
    pane_sigma_mm: tuple
    warnings: tuple

    @property
    def consistent(self) -> bool:
        """Both differences within their expanded uncertainties."""
        return self.phi_eff_mean_abs.consistent and self.phi_shear_mean.consistent

    def to_dict(self) -> dict:
        """JSON-serialisable form (``glassdist compare --json``)."""
        return {"phi_eff_mD_mean_abs": self.phi_eff_mean_abs.to_dict(),
                "phi_shear_mD_mean_abs": self.phi_shear_mean.to_dict(),
                "consistent_with_zero": self.consistent, "common_pane_percent": list(self.common_pane_percent),
                "pane_sigma_mm": list(self.pane_sigma_mm), "coverage_factor": COVERAGE_FACTOR,
                "model_relative_uncertainty": MODEL_RELATIVE_UNCERTAINTY, "warnings": list(self.warnings)}


def stored_reading(stored) -> IntrinsicReading:
    """The intrinsic reading of a stored result on its pixel grid (from its channels and recorded geometry)."""
    g = stored_geometry(stored)
    H, W = stored.valid.shape
    fields = stored.fields

    def get(name):
        return np.asarray(stored.pixel_field(name), float) if name in fields else None

    return intrinsic_reading(get("phi_eff_mD"), get("phi_shear_mD"), get("axis_deg"),
                             rows_px=np.arange(H, dtype=float)[:, None], cols_px=np.arange(W, dtype=float)[None, :],
                             image_shape=(H, W), mm_per_px=float(stored.summary["mm_per_px"]),
                             sigma_mm=capture_sigma_mm(stored), geometry=g,
                             phi_eff_sigma_mD=get("phi_eff_sigma_mD"), phi_shear_sigma_mD=get("phi_shear_sigma_mD"))


def _covered(reading: IntrinsicReading, x_mm, y_mm, trusted) -> np.ndarray:
    """Whether pane points fall on a trusted pixel of ``reading`` (nearest pixel)."""
    H, W = trusted.shape
    g = reading.geometry
    rows, cols = pane_to_pixels(x_mm, y_mm, (H, W), mm_per_px=reading.pane_mm_per_px / g.factor, geometry=g)
    c, r = np.rint(cols).astype(np.int64), np.rint(rows).astype(np.int64)
    inside = (c >= 0) & (c < W) & (r >= 0) & (r < H)
    out = np.zeros(np.shape(x_mm), bool)
    out[inside] = trusted[r[inside], c[inside]]
    return out


def _noise_u(reading: IntrinsicReading, name: str, region: np.ndarray) -> float:
    u = getattr(reading, name)
    if u is None:
        return 0.0
    v = u[region & np.isfinite(u)]
    if not v.size:
        return 0.0
    sigma_px = reading.pane_sigma_mm / reading.pane_mm_per_px
    n_eff = max(1.0, region.sum() / (4.0 * math.pi * sigma_px * sigma_px))
    return float(np.median(v)) / math.sqrt(n_eff)


def _difference(a, b, ua, ub) -> ChannelDifference:
    u = math.sqrt(ua * ua + ub * ub + (MODEL_RELATIVE_UNCERTAINTY * a) ** 2 + (MODEL_RELATIVE_UNCERTAINTY * b) ** 2)
    U = COVERAGE_FACTOR * u
    return ChannelDifference(a, b, a - b, u, U, abs(a - b) <= U)


def compare_results(stored_a, stored_b) -> Comparison:
    """Put two stored captures of one pane on the intrinsic axis and difference them (module notes).

    Parameters
    ----------
    stored_a, stored_b : glassdist.storage.StoredResult
        :func:`glassdist.load_result` of two runs with ``--camera-distance-m``.

    Returns
    -------
    Comparison

    Raises
    ------
    InputError
        A result without its geometry, or in reflection; no common pane area.
    """
    from ..errors import InputError

    ra, rb = stored_reading(stored_a), stored_reading(stored_b)
    ta, tb = trusted_pixels(stored_a) & stored_a.valid, trusted_pixels(stored_b) & stored_b.valid
    ca = ta & _covered(rb, ra.x_mm, ra.y_mm, tb)
    cb = tb & _covered(ra, rb.x_mm, rb.y_mm, ta)
    if not ca.any() or not cb.any():
        raise InputError("the two captures share no trusted pane area (pane coordinates from the image centres at "
                         "their geometries); compare captures of the same pane, aimed at its centre")
    warnings = []
    sa, sb = ra.pane_sigma_mm, rb.pane_sigma_mm
    if abs(sa - sb) > 0.05 * max(sa, sb):
        warnings.append(f"the readings carry different smoothing on the pane ({sa:.3g} mm and {sb:.3g} mm): the finer "
                        "one reads higher where the distortion is fine; analyse with --sigma-mm so that "
                        "sigma Dc / (Dc + L) agrees")
    diffs = []
    for name, noise in (("phi_eff_mD", "phi_eff_sigma_mD"), ("phi_shear_mD", "phi_shear_sigma_mD")):
        a = channel_statistics(getattr(ra, name), ca)["mean_abs"]
        b = channel_statistics(getattr(rb, name), cb)["mean_abs"]
        diffs.append(_difference(a, b, _noise_u(ra, noise, ca), _noise_u(rb, noise, cb)))
    pct = (100.0 * ca.sum() / max(ta.sum(), 1), 100.0 * cb.sum() / max(tb.sum(), 1))
    return Comparison(diffs[0], diffs[1], pct, (sa, sb), tuple(warnings))
