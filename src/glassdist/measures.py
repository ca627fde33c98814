"""A4: standard measures of see-through distortion, from the displacement field.

The industry reads glass distortion with scalar measures of its own; a grid photo serves
them all once the displacement field is known (formulas and references in
``docs/user-guide/standard-measures.md``):

* :func:`roll_wave` -- roll-wave period, direction and amplitude (ASTM C1651 quantities),
  from the spectrum of the field's divergence;
* :func:`line_profile` -- a field sampled along a chosen line (:func:`result_profile`: a
  result's field along a line in pane or backdrop millimetres);
* :func:`angular_deviation` -- the ray deviation angle and its change over a gauge length,
  arc minutes (ECE R43 / ISO 3538 "optical deviation" and "optical distortion");
* :func:`grid_line_slope` -- the largest slope of a distorted grid line, "1 in N" (ASTM F2156);
* :func:`equivalent_power` -- the optometric sphere-equivalent power ``P = -phi_eff / 2``;
* :func:`standard_measures` -- all of them for an :class:`~glassdist.analyzer.AnalysisResult`.

Conventions
-----------
* ``displacement_mm[..., 0]`` = delta_x (along columns), ``[..., 1]`` = delta_y (along
  rows, down), backdrop mm; delta = landing point with glass minus without.
* Fields are sampled on a regular grid: ``step_mm = (sy, sx)`` is the spacing of rows and
  columns in backdrop mm; sample ``(i, j)`` sits at ``x = x0 + j sx``, ``y = y0 + i sy``
  with ``origin_mm = (x0, y0)`` (default 0: the first sample).
* ``distance_m`` is the glass-to-backdrop distance L in m; power in mD.
* Directions in degrees from +x towards +y.
* NaN marks invalid samples; every statistic is over the finite samples only.

The angle a ray is turned by the glass follows from delta in the far-background limit,
``delta = L tan(alpha)`` (paper §2.2.3, ``delta_m = L_m dtheta``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from .analyzer.captures import sample_field
from .analyzer.metrics import derivative

if TYPE_CHECKING:
    from .analyzer.result import Optics

__all__ = [
    "RollWave",
    "LineProfile",
    "AngularDeviation",
    "GridLineSlope",
    "EquivalentPower",
    "StandardMeasures",
    "displacement_gradient",
    "roll_wave",
    "line_profile",
    "result_profile",
    "angular_deviation",
    "grid_line_slope",
    "equivalent_power",
    "standard_measures",
    "reflected_roll_wave",
    "REFLECTION_MEANING",
    "ARCMIN_PER_RAD",
    "EQUIVALENT_POWER_CONVENTION",
]

#: arc minutes per radian
ARCMIN_PER_RAD = 60.0 * 180.0 / np.pi

#: the optometric convention, as stated in reports
EQUIVALENT_POWER_CONVENTION = (
    "P_sph,eq = -phi_eff/2 (far-background limit): the optometric sphere-equivalent power of a thin lens "
    "that would give the same local area change; a converging lens reads P > 0 (phi_eff < 0)"
)


def _step(step_mm) -> tuple[float, float]:
    if np.isscalar(step_mm):
        s = float(step_mm)
        sy, sx = s, s
    else:
        sy, sx = (float(v) for v in step_mm)
    if not (np.isfinite(sy) and np.isfinite(sx) and sy > 0 and sx > 0):
        raise ValueError(f"step_mm must be positive sample spacings (sy, sx) in mm, got {step_mm!r}")
    return sy, sx


def _check_field(displacement_mm) -> np.ndarray:
    d = np.asarray(displacement_mm, dtype=float)
    if d.ndim != 3 or d.shape[-1] != 2:
        raise ValueError(f"displacement_mm must have shape (h, w, 2), got {d.shape}")
    return d


def _check_distance(distance_m: float) -> float:
    L = float(distance_m)
    if not (np.isfinite(L) and L > 0):
        raise ValueError(f"distance_m must be a positive length in m, got {distance_m!r}")
    return L


def _finite(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    return a[np.isfinite(a)]


def _max_abs(a: np.ndarray) -> float:
    v = _finite(a)
    return float(np.abs(v).max()) if v.size else float("nan")


def _p95_abs(a: np.ndarray) -> float:
    v = _finite(a)
    return float(np.percentile(np.abs(v), 95)) if v.size else float("nan")


def _robust_pv(a: np.ndarray) -> float:
    """Peak-to-valley between the 0.5th and 99.5th percentiles (a single noisy sample does not set it)."""
    v = _finite(a)
    if not v.size:
        return float("nan")
    lo, hi = np.percentile(v, [0.5, 99.5])
    return float(hi - lo)


def displacement_gradient(displacement_mm: np.ndarray, step_mm) -> np.ndarray:
    """Full displacement gradient ``G[..., a, b] = d delta_a / d X_b`` (dimensionless).

    Fourth-order centred differences (the stencil of Block A3), X in backdrop mm:
    ``b = 0`` along x (columns), ``b = 1`` along y (rows). Unlike the strain, ``G`` keeps
    the antisymmetric part (local rotation), which bends grid lines. NaN within two samples
    of invalid samples and of the array's edges: only the five-point stencil is kept (the
    less accurate three-point and one-sided differences there would set the maxima the
    measures report).

    Parameters
    ----------
    displacement_mm : ndarray (h, w, 2)
    step_mm : float or (float, float)
        Sample spacing (sy, sx), mm.

    Returns
    -------
    ndarray (h, w, 2, 2)
    """
    d = _check_field(displacement_mm)
    sy, sx = _step(step_mm)
    G = np.empty(d.shape[:2] + (2, 2))
    for c in range(2):
        G[..., c, 0] = derivative(d[..., c], 1, sx)
        G[..., c, 1] = derivative(d[..., c], 0, sy)
    ok = np.all(np.isfinite(d), axis=-1)
    for axis, b in ((1, 0), (0, 1)):  # the five samples of the stencil along that axis
        full = ok.copy()
        for sh in (-2, -1, 1, 2):
            full &= ndimage.shift(ok, [sh if a == axis else 0 for a in range(2)], order=0, mode="constant", cval=False)
        G[~full, :, b] = np.nan
    return G


# --------------------------------------------------------------------------- roll waves


@dataclass(frozen=True)
class RollWave:
    """The dominant roll wave of a displacement field (see :func:`roll_wave`).

    Attributes
    ----------
    period_mm : float
        Wavelength Lambda on the backdrop, mm.
    direction_deg : float
        Roll direction (the wave vector: the direction along which the field varies),
        degrees from +x towards +y in (-90, 90].
    amplitude_mm : float
        Fitted amplitude A of the displacement along the roll direction, mm.
    power_amplitude_mD : float
        Fitted amplitude of the power along the roll direction,
        ``2 pi A / (Lambda L)`` (x 1000), mD.
    displacement_pv_mm : float
        Observed peak-to-valley of the displacement along the roll direction (0.5th to
        99.5th percentile), mm; ``2 A`` for a pure wave.
    power_pv_mD : float
        Observed peak-to-valley of the directional power ``d delta_s / ds / L``, mD;
        ``2 power_amplitude_mD`` for a pure wave.
    explained_fraction : float
        Fraction of the variance of the displacement along the roll direction that the
        fitted sinusoid explains (1: a pure roll wave; near 0: no wave).
    distance_m : float
    """

    period_mm: float
    direction_deg: float
    amplitude_mm: float
    power_amplitude_mD: float
    displacement_pv_mm: float
    power_pv_mD: float
    explained_fraction: float
    distance_m: float

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping (its fields, by name)."""
        return asdict(self)


def _sinusoid_fit(d: np.ndarray, x: np.ndarray, y: np.ndarray, k: np.ndarray):
    """Least squares ``e.d = c + a cos(2 pi k.r) + b sin(2 pi k.r)``, e = k/|k|; returns (rss, (c, a, b), tss)."""
    e = k / np.hypot(*k)
    s = d[:, 0] * e[0] + d[:, 1] * e[1]
    ph = 2 * np.pi * (k[0] * x + k[1] * y)
    A = np.stack([np.ones_like(ph), np.cos(ph), np.sin(ph)], axis=-1)
    coef, *_ = np.linalg.lstsq(A, s, rcond=None)
    r = s - A @ coef
    return float(r @ r), coef, float(((s - s.mean()) ** 2).sum())


def _refine_wave_vector(d: np.ndarray, x: np.ndarray, y: np.ndarray, k0: np.ndarray, *, iterations: int = 20) -> np.ndarray:
    """Gauss-Newton on (c, a, b, kx, ky) of the sinusoid fit, a step accepted only when it lowers the residual."""
    k = np.asarray(k0, float)
    rss, coef, _ = _sinusoid_fit(d, x, y, k)
    for _ in range(iterations):
        e = k / np.hypot(*k)
        s = d[:, 0] * e[0] + d[:, 1] * e[1]
        ph = 2 * np.pi * (k[0] * x + k[1] * y)
        c_, s_ = np.cos(ph), np.sin(ph)
        _, a, b = coef
        dph = -a * s_ + b * c_  # d(model)/d(phase)
        J = np.stack([np.ones_like(ph), c_, s_, 2 * np.pi * x * dph, 2 * np.pi * y * dph], axis=-1)
        r = s - (coef[0] + a * c_ + b * s_)
        step, *_ = np.linalg.lstsq(J, r, rcond=None)
        dk = step[3:]
        for _ in range(8):
            rss1, coef1, _ = _sinusoid_fit(d, x, y, k + dk)
            if rss1 <= rss:
                break
            dk = dk / 2
        else:
            break
        k = k + dk
        done = np.hypot(*dk) <= 1e-9 * np.hypot(*k) or rss - rss1 <= 1e-12 * rss
        rss, coef = rss1, coef1
        if done:
            break
    return k


def _parabolic_peak(S: np.ndarray, iy: int, ix: int) -> tuple[float, float]:
    """Sub-bin offsets (rows, cols) of a spectral peak from a parabola through log S on each axis."""
    out = []
    for axis, i in ((0, iy), (1, ix)):
        n = S.shape[axis]
        if axis == 0:
            v = [S[(iy - 1) % n, ix], S[iy, ix], S[(iy + 1) % n, ix]]
        else:
            if not 0 < ix < n - 1:
                out.append(0.0)
                continue
            v = [S[iy, ix - 1], S[iy, ix], S[iy, ix + 1]]
        lv = np.log(np.maximum(v, 1e-300))
        den = lv[0] - 2 * lv[1] + lv[2]
        out.append(float(np.clip(0.5 * (lv[0] - lv[2]) / den, -0.5, 0.5)) if den < 0 else 0.0)
    return out[0], out[1]


def roll_wave(
    displacement_mm: np.ndarray,
    *,
    step_mm,
    distance_m: float,
    min_period_mm: float | None = None,
    max_period_mm: float | None = None,
) -> RollWave:
    """Dominant roll wave: period and direction from the spectrum, amplitude by least squares.

    A roll wave of the surface, ``z(s)`` along the roll direction ``e``, turns rays along
    ``e`` only, so its displacement is longitudinal: ``delta = A sin(2 pi s / Lambda) e``.
    Its power along ``e`` is ``phi_ss = d delta_s / ds / L``.

    Parameters
    ----------
    displacement_mm : ndarray (h, w, 2)
        Detrended displacement, mm (NaN = invalid).
    step_mm : float or (float, float)
        Sample spacing (sy, sx), mm.
    distance_m : float
        L, m.
    min_period_mm, max_period_mm : float, optional
        Band searched (default: four samples to the field's larger extent).

    Returns
    -------
    RollWave

    Notes
    -----
    The wave vector ``k`` (cycles/mm) is the peak of the spectrum of the divergence,

    .. math:: S(\\mathbf{k}) = \\left|\\mathbf{k}\\cdot\\hat{\\boldsymbol\\delta}(\\mathbf{k})\\right|^2

    (the spectrum of phi_eff's longitudinal part: the wave that carries the most power,
    not the most displacement), refined by minimising the residual of the least-squares
    fit ``e.delta = c + a cos(2 pi k.r) + b sin(2 pi k.r)`` over the valid samples (the
    maximum-likelihood frequency of one sinusoid in white noise). Then

    .. math:: \\Lambda = 1/|\\mathbf{k}|, \\quad A = \\sqrt{a^2 + b^2}, \\quad
              \\hat\\phi_{ss} = \\frac{2\\pi A}{\\Lambda L}.

    References
    ----------
    ASTM C1651, Standard Test Method for Measurement of Roll Wave Optical Distortion in
    Heat-Treated Flat Glass (roll-wave period and peak-to-valley, optical power in mD).
    """
    d = _check_field(displacement_mm)
    L = _check_distance(distance_m)
    sy, sx = _step(step_mm)
    ok = np.all(np.isfinite(d), axis=-1)
    nan = float("nan")
    if ok.sum() < 16:
        return RollWave(nan, nan, nan, nan, nan, nan, nan, L)
    f = np.where(ok[..., None], d - d[ok].mean(axis=0), 0.0)
    k0 = _spectral_peak(f, (sy, sx), min_period_mm, max_period_mm)
    if k0 is None:
        return RollWave(nan, nan, nan, nan, nan, nan, 0.0, L)
    # Refinement: least-squares sinusoid over the valid samples only (masks make the FFT peak leak).
    yy, xx = np.nonzero(ok)
    x, y, dv = xx * sx, yy * sy, d[ok]
    # A regular subset of at most ~40k samples pins five parameters as well as all of them.
    sub = slice(None, None, max(1, x.size // 40_000))
    k = _refine_wave_vector(dv[sub], x[sub], y[sub], k0)
    rss, (_, a, b), tss = _sinusoid_fit(dv, x, y, k)
    return _fitted_roll_wave(d, (sy, sx), L, k, (a, b), rss, tss)


def _spectral_peak(f: np.ndarray, step_mm: tuple[float, float], min_period_mm: float | None,
                   max_period_mm: float | None) -> np.ndarray | None:
    """Wave vector ``(kx, ky)`` (cycles/mm) of the peak of the divergence spectrum within the band.

    Parameters
    ----------
    f : ndarray (h, w, 2)
        Displacement less its mean, zero at invalid samples, mm.
    step_mm : (float, float)
        Sample spacing (sy, sx), mm.
    min_period_mm, max_period_mm : float or None
        As for :func:`roll_wave`.

    Returns
    -------
    ndarray (2,) or None
        The coarse peak, to a fraction of a bin; None when the band holds no power.
    """
    sy, sx = step_mm
    h, w = f.shape[:2]
    # Coarse peak on a zero-padded spectrum (2x: the peak is sampled finely enough for the refinement).
    ny, nx = 2 * h, 2 * w
    D = [np.fft.rfft2(f[..., c], s=(ny, nx)) for c in range(2)]
    fy = np.fft.fftfreq(ny, sy)[:, None]
    fx = np.fft.rfftfreq(nx, sx)[None, :]
    S = np.abs(fx * D[0] + fy * D[1]) ** 2
    kn = np.hypot(fx, fy)
    lo = 1.0 / (max_period_mm if max_period_mm is not None else max(h * sy, w * sx))
    hi = 1.0 / (min_period_mm if min_period_mm is not None else 4.0 * max(sy, sx))
    S[(kn < lo) | (kn > hi)] = 0.0
    if not np.any(S > 0):
        return None
    iy, ix = np.unravel_index(int(np.argmax(S)), S.shape)
    oy, ox = _parabolic_peak(S, iy, ix)
    return np.array([fx[0, ix] + ox / (nx * sx), fy[iy, 0] + oy / (ny * sy)])


def _fitted_roll_wave(d: np.ndarray, step_mm: tuple[float, float], L: float, k: np.ndarray, ab, rss: float,
                      tss: float) -> RollWave:
    """The :class:`RollWave` of the sinusoid fitted with wave vector ``k``.

    Parameters
    ----------
    d : ndarray (h, w, 2)
        Displacement, mm (NaN = invalid).
    step_mm : (float, float)
        Sample spacing (sy, sx), mm.
    L : float
        Glass-to-backdrop distance, m.
    k : ndarray (2,)
        Refined wave vector, cycles/mm.
    ab : (float, float)
        Cosine and sine amplitudes of the fit, mm.
    rss, tss : float
        Residual and total sums of squares of the fit.

    Returns
    -------
    RollWave
        Direction folded into (-90, 90] deg; peak-to-valley values over the whole field.
    """
    sy, sx = step_mm
    a, b = ab
    kn1 = float(np.hypot(*k))
    e = k / kn1
    period = 1.0 / kn1
    direction = float(np.degrees(np.arctan2(e[1], e[0])))
    if direction <= -90.0:
        direction += 180.0
    elif direction > 90.0:
        direction -= 180.0
    amp = float(np.hypot(a, b))
    G = displacement_gradient(d, (sy, sx))
    phi_ss = np.einsum("...ab,a,b->...", G, e, e) * (1000.0 / L)
    s_disp = d[..., 0] * e[0] + d[..., 1] * e[1]
    return RollWave(
        period_mm=float(period),
        direction_deg=direction,
        amplitude_mm=amp,
        power_amplitude_mD=float(2 * np.pi * amp / period * 1000.0 / L),
        displacement_pv_mm=_robust_pv(s_disp),
        power_pv_mD=_robust_pv(phi_ss),
        explained_fraction=float(max(0.0, 1.0 - rss / tss)) if tss > 0 else 0.0,
        distance_m=L,
    )


@dataclass(frozen=True)
class LineProfile:
    """A field sampled along a line segment.

    Attributes
    ----------
    s_mm : ndarray (n,)
        Arc length from the start, mm.
    x_mm, y_mm : ndarray (n,)
        Sample positions, mm (frame of ``origin_mm``).
    values : ndarray (n,) or (n, c)
        Cubic-spline samples of the field (:func:`~glassdist.analyzer.captures.sample_field`);
        NaN where any of the four nearest samples is invalid or the point lies outside the field.
    """

    s_mm: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    values: np.ndarray


def _segment(start_mm, end_mm, spacing_mm: float):
    """Arc length and positions (mm) of points every ``spacing_mm`` from ``start_mm`` to ``end_mm``."""
    p0, p1 = np.asarray(start_mm, float), np.asarray(end_mm, float)
    length = float(np.hypot(*(p1 - p0)))
    ds = float(spacing_mm)
    if not (np.isfinite(ds) and ds > 0):
        raise ValueError(f"spacing_mm must be positive, got {spacing_mm!r}")
    n = max(2, int(np.floor(length / ds)) + 1)
    s = np.linspace(0.0, length, n) if length > 0 else np.zeros(1)
    t = s / length if length > 0 else s
    return s, p0[0] + t * (p1[0] - p0[0]), p0[1] + t * (p1[1] - p0[1])


def line_profile(field: np.ndarray, *, step_mm, start_mm, end_mm, spacing_mm: float | None = None,
                 origin_mm=(0.0, 0.0)) -> LineProfile:
    """Sample a field (a channel or the displacement) along the segment ``start_mm -> end_mm``.

    Parameters
    ----------
    field : ndarray (h, w) or (h, w, c)
    step_mm : float or (float, float)
        Sample spacing (sy, sx), mm.
    start_mm, end_mm : (float, float)
        End points ``(x, y)``, mm, in the frame where the sample ``(0, 0)`` sits at
        ``origin_mm``.
    spacing_mm : float, optional
        Spacing of the profile's samples (default: the smaller grid step).
    origin_mm : (float, float)
        ``(x, y)`` of the field's sample ``(0, 0)``, mm.
    """
    sy, sx = _step(step_mm)
    f = np.asarray(field, dtype=float)
    if f.ndim not in (2, 3):
        raise ValueError(f"field must have shape (h, w) or (h, w, c), got {f.shape}")
    s, x, y = _segment(start_mm, end_mm, spacing_mm if spacing_mm is not None else min(sx, sy))
    return LineProfile(s, x, y, _sample_planes(f, (y - origin_mm[1]) / sy, (x - origin_mm[0]) / sx))


def _sample_planes(f: np.ndarray, rows, cols) -> np.ndarray:
    """:func:`~glassdist.analyzer.captures.sample_field` of each plane of an (h, w) or (h, w, c) field."""
    if f.ndim == 2:
        return sample_field(f, rows, cols)
    return np.stack([sample_field(f[..., c], rows, cols) for c in range(f.shape[2])], axis=-1)


def result_profile(result, name: str, *, start_mm, end_mm, frame=None, spacing_mm: float | None = None) -> LineProfile:
    """Field ``name`` of an analysis along a segment in pane or backdrop millimetres.

    Parameters
    ----------
    result : AnalysisResult
    name : str
        A registered field (``phi_eff_mD``, ``displacement_detrended_mm``, ...), sampled on
        the analysis grid.
    start_mm, end_mm : (float, float)
        End points ``(u, v)``, mm: in the pane frame ``frame``, or without one on the backdrop
        with the image's top-left pixel centre at (0, 0) (``x = column * mm_per_px``).
    frame : glassdist.acceptance.zones.PaneFrame, optional
        Its ``px_to_mm`` homography maps pixels to the frame's millimetres.
    spacing_mm : float, optional
        Default: the analysis grid step in mm.
    """
    g = result.analysis_grid
    f = np.asarray(result.grid_field(name), dtype=float)
    s, u, v = _segment(start_mm, end_mm, spacing_mm if spacing_mm is not None else min(g.step) * result.mm_per_px)
    if frame is None:
        x_px, y_px = u / result.mm_per_px, v / result.mm_per_px
    else:
        Hinv = np.linalg.inv(np.asarray(frame.px_to_mm, dtype=float))
        w = Hinv[2, 0] * u + Hinv[2, 1] * v + Hinv[2, 2]
        x_px, y_px = (Hinv[0, 0] * u + Hinv[0, 1] * v + Hinv[0, 2]) / w, (Hinv[1, 0] * u + Hinv[1, 1] * v + Hinv[1, 2]) / w
    return LineProfile(s, u, v, _sample_planes(f, (y_px - g.offset[0]) / g.step[0], (x_px - g.offset[1]) / g.step[1]))


# --------------------------------------------------------------------------- angular deviation


@dataclass(frozen=True)
class AngularDeviation:
    """Ray deviation angle implied by the displacement, and its change over a gauge length.

    Attributes
    ----------
    angle_arcmin : ndarray (h, w)
        ``alpha = atan(|delta| / L)``, arc minutes.
    angle_x_arcmin, angle_y_arcmin : ndarray (h, w)
        Components ``atan(delta_x / L)``, ``atan(delta_y / L)``, arc minutes.
    rate_x_arcmin, rate_y_arcmin : ndarray (h, w)
        Change of the deviation component along x (y) between the two ends of a gauge of
        ``gauge_mm`` along x (y) centred on each sample, arc minutes per gauge; NaN where
        an end falls outside the valid field.
    gauge_mm : float
    """

    angle_arcmin: np.ndarray
    angle_x_arcmin: np.ndarray
    angle_y_arcmin: np.ndarray
    rate_x_arcmin: np.ndarray
    rate_y_arcmin: np.ndarray
    gauge_mm: float

    def statistics(self) -> dict:
        """Max and p95 of |alpha| and of |rate| (both directions together), arc minutes."""
        both = np.concatenate([_finite(self.rate_x_arcmin), _finite(self.rate_y_arcmin)])
        return {
            "angle_max_arcmin": _max_abs(self.angle_arcmin),
            "angle_p95_arcmin": _p95_abs(self.angle_arcmin),
            "gauge_mm": self.gauge_mm,
            "rate_max_arcmin": _max_abs(both),
            "rate_p95_arcmin": _p95_abs(both),
            "rate_x_max_arcmin": _max_abs(self.rate_x_arcmin),
            "rate_y_max_arcmin": _max_abs(self.rate_y_arcmin),
        }


def _shifted(f: np.ndarray, axis: int, shift: float) -> np.ndarray:
    """``f`` at sample ``i + shift`` along ``axis`` (linear interpolation; NaN beyond the edges)."""
    n = f.shape[axis]
    i0 = int(np.floor(shift))
    t = shift - i0
    idx = np.arange(n) + i0
    a = np.take(f, np.clip(idx, 0, n - 1), axis=axis)
    b = np.take(f, np.clip(idx + 1, 0, n - 1), axis=axis)
    out = (1 - t) * a + t * b if t > 0 else a
    inside = (idx >= 0) & (idx + (1 if t > 0 else 0) <= n - 1)
    shape = [1] * f.ndim
    shape[axis] = n
    return np.where(inside.reshape(shape), out, np.nan)


def angular_deviation(displacement_mm: np.ndarray, *, step_mm, distance_m: float, gauge_mm: float) -> AngularDeviation:
    """Angular deviation map (arc minutes) and its rate over a gauge length (R43-style).

    Parameters
    ----------
    displacement_mm : ndarray (h, w, 2)
        delta, mm. Which displacement decides what the angle is relative to: the
        detrended field gives the deviation relative to the degree-N trend (a uniform
        prism and a pane-wide lens are part of the trend).
    step_mm : float or (float, float)
        Sample spacing (sy, sx), mm.
    distance_m : float
        L, m.
    gauge_mm : float
        Gauge length g, mm (the distance between the two points whose deviations are
        compared).

    Returns
    -------
    AngularDeviation

    Notes
    -----
    In the far-background limit a ray turned by ``alpha`` lands ``delta = L tan(alpha)``
    from where it would land without the glass, so

    .. math:: \\alpha = \\arctan\\frac{|\\boldsymbol\\delta|}{L}, \\qquad
              \\Delta\\alpha_x(\\mathbf{r}) = \\arctan\\frac{\\delta_x(\\mathbf{r} + \\tfrac{g}{2}\\hat{x})}{L}
              - \\arctan\\frac{\\delta_x(\\mathbf{r} - \\tfrac{g}{2}\\hat{x})}{L}

    (delta in mm, L in mm here; likewise along y). For small angles
    ``Delta alpha_x ~ g phi_xx`` with ``phi_xx = d delta_x / dx / L``: 1 mD over 4 mm is
    4e-6 rad = 0.0138 arcmin. delta is interpolated linearly between samples, so a
    linear displacement (a thin lens or prism) gives the closed form exactly.

    References
    ----------
    UN ECE Regulation No. 43, Annex 3 (optical deviation; optical distortion as the
    difference of angular deviation between two points a given distance apart);
    ISO 3538, Road vehicles -- Safety glazing materials -- Test methods for optical properties.
    """
    d = _check_field(displacement_mm)
    L_mm = 1000.0 * _check_distance(distance_m)
    sy, sx = _step(step_mm)
    g = float(gauge_mm)
    if not (np.isfinite(g) and g > 0):
        raise ValueError(f"gauge_mm must be a positive length in mm, got {gauge_mm!r}")
    k = ARCMIN_PER_RAD
    ang = np.arctan(np.hypot(d[..., 0], d[..., 1]) / L_mm) * k
    ax = np.arctan(d[..., 0] / L_mm) * k
    ay = np.arctan(d[..., 1] / L_mm) * k
    hx, hy = 0.5 * g / sx, 0.5 * g / sy
    rate_x = (np.arctan(_shifted(d[..., 0], 1, hx) / L_mm) - np.arctan(_shifted(d[..., 0], 1, -hx) / L_mm)) * k
    rate_y = (np.arctan(_shifted(d[..., 1], 0, hy) / L_mm) - np.arctan(_shifted(d[..., 1], 0, -hy) / L_mm)) * k
    return AngularDeviation(ang, ax, ay, rate_x, rate_y, g)


# --------------------------------------------------------------------------- grid-line slope


@dataclass(frozen=True)
class GridLineSlope:
    """Slope of distorted grid lines relative to their undistorted direction (ASTM F2156).

    Attributes
    ----------
    directions_deg : tuple of float
        Directions of the grid-line families, degrees from +x towards +y.
    slopes : tuple of ndarray (h, w)
        Signed slope of each family's lines at every sample (dimensionless).
    max_slopes : tuple of float
        max |slope| of each family.
    one_in_n : tuple of float
        ``N = 1 / max|slope|`` of each family ("1 in N"; inf for straight lines).
    """

    directions_deg: tuple[float, ...]
    slopes: tuple[np.ndarray, ...]
    max_slopes: tuple[float, ...]
    one_in_n: tuple[float, ...]

    @property
    def worst_one_in_n(self) -> float:
        """The smallest N over the families (the steepest line)."""
        return float(min(self.one_in_n))

    def statistics(self) -> dict:
        """The measure's figures as a JSON-ready mapping (directions, maximum slopes, one-in-N)."""
        return {
            "directions_deg": list(self.directions_deg),
            "max_slope": list(self.max_slopes),
            "one_in_n": list(self.one_in_n),
            "worst_one_in_n": self.worst_one_in_n,
        }


def grid_line_slope(displacement_mm: np.ndarray, *, step_mm, directions_deg=(0.0, 90.0)) -> GridLineSlope:
    """Largest slope of grid lines seen through the glass, reported as "1 in N".

    Parameters
    ----------
    displacement_mm : ndarray (h, w, 2)
        delta, mm.
    step_mm : float or (float, float)
        Sample spacing (sy, sx), mm.
    directions_deg : sequence of float
        Directions ``t`` of the printed grid lines (default horizontal and vertical lines).

    Returns
    -------
    GridLineSlope

    Notes
    -----
    A straight line ``{u : n.u = c}`` of the backdrop (unit normal ``n``, direction ``t``)
    is seen at the glass-less points ``u`` with ``n.(u + delta(u)) = c``. Differentiating
    along the seen line gives its slope against the original direction

    .. math:: m = \\frac{d(\\mathbf{n}\\cdot\\mathbf{u})}{d(\\mathbf{t}\\cdot\\mathbf{u})}
              = -\\frac{\\partial_t \\delta_n}{1 + \\partial_n \\delta_n}
              \\approx -\\frac{\\partial \\delta_\\perp}{\\partial s},
              \\qquad N = \\frac{1}{\\max|m|}.

    Unlike the strain channels it includes local rotation (a line tilts when the field
    rotates it), which is what bends grid lines.

    References
    ----------
    ASTM F2156, Standard Test Method for Measuring Optical Distortion in Transparent
    Parts Using Grid Line Slope (distortion as the slope of localized grid line bending,
    e.g. "1 in 5").
    """
    G = displacement_gradient(displacement_mm, step_mm)
    dirs, slopes, maxs, ns = [], [], [], []
    for deg in directions_deg:
        th = np.radians(float(deg))
        t = np.array([np.cos(th), np.sin(th)])
        n = np.array([-t[1], t[0]])
        with np.errstate(invalid="ignore", divide="ignore"):
            m = -np.einsum("...ab,a,b->...", G, n, t) / (1.0 + np.einsum("...ab,a,b->...", G, n, n))
        mx = _max_abs(m)
        dirs.append(float(deg))
        slopes.append(m)
        maxs.append(mx)
        ns.append(float(np.inf) if mx == 0 else (1.0 / mx if np.isfinite(mx) else float("nan")))
    return GridLineSlope(tuple(dirs), tuple(slopes), tuple(maxs), tuple(ns))


# --------------------------------------------------------------------------- optometric power


@dataclass(frozen=True)
class EquivalentPower:
    """Optometric sphere-equivalent power ``P = -phi_eff / 2`` over the valid region, mD.

    Attributes
    ----------
    mean_mD, min_mD, max_mD, p95_abs_mD : float
    convention : str
    """

    mean_mD: float
    min_mD: float
    max_mD: float
    p95_abs_mD: float
    convention: str = EQUIVALENT_POWER_CONVENTION

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping (its fields, by name)."""
        return asdict(self)


def equivalent_power(phi_eff_mD: np.ndarray) -> EquivalentPower:
    """Sphere-equivalent power in the optometric convention from phi_eff (mD).

    Notes
    -----
    A thin lens of power P turns a ray at height r by ``dtheta = -P r``, so
    ``delta = L dtheta``, ``div delta = -2 P L`` and (paper §2.2.3)

    .. math:: P_{sph,eq} = -\\phi_{eff} / 2 .

    phi_eff is the full trace (the local area change); the ophthalmic spherical
    equivalent is half of it, with the opposite sign.
    """
    P = -0.5 * _finite(phi_eff_mD)
    if not P.size:
        nan = float("nan")
        return EquivalentPower(nan, nan, nan, nan)
    return EquivalentPower(float(P.mean()), float(P.min()), float(P.max()), float(np.percentile(np.abs(P), 95)))


# --------------------------------------------------------------------------- all of them for a result


@dataclass(frozen=True)
class StandardMeasures:
    """The standard measures of one analysis (see :func:`standard_measures`)."""

    roll_wave: RollWave
    angular_deviation: AngularDeviation
    grid_line_slope: GridLineSlope
    equivalent_power: EquivalentPower
    step_mm: tuple[float, float]
    field: str
    reflection: dict | None = None

    def to_dict(self) -> dict:
        """JSON-serialisable summary (``summary.json["measures"]``)."""
        return {
            "field": self.field,
            "step_mm": list(self.step_mm),
            "roll_wave": self.roll_wave.to_dict(),
            "angular_deviation": self.angular_deviation.statistics(),
            "grid_line_slope": self.grid_line_slope.statistics(),
            "equivalent_power": self.equivalent_power.to_dict(),
            **({"reflected_roll_wave": self.reflection, "reflection_meaning": REFLECTION_MEANING}
               if self.reflection is not None else {}),
        }


#: What the standard measures mean in reflection (``summary.json["measures"]["reflection_meaning"]``).
REFLECTION_MEANING = {
    "roll_wave": "the board displacement's wave (amplitude_mm and displacement_pv_mm are board mm, not the "
                 "surface's height): read reflected_roll_wave for the pane",
    "angular_deviation": "deviation of the reflected ray (twice the change of the surface slope, L = D / cos "
                         "theta), its change over the gauge length on the pane",
    "grid_line_slope": "slope of the board's grid lines seen in the pane (derivatives along board mm)",
    "equivalent_power": "-phi_eff / 2 of the reflective power: the pane's mean principal power as a mirror "
                        "(a concave, converging pane reads P > 0)",
}


def reflected_roll_wave(rw: RollWave, optics: Optics) -> dict:
    """The roll wave in reflection: period on the pane, reflective power amplitude, implied surface height.

    ``rw`` is :func:`roll_wave` of the board displacement on pane mm with
    ``L = D / cos(theta)``: then ``power_amplitude_mD`` is the reflective power amplitude
    along the wave, ``2 A k^2 F`` with ``F = cos^2(b) / cos(theta) + sin^2(b) cos(theta)``
    (``b`` the angle between the wave and the plane of incidence; ``F = 1`` at normal
    incidence: ``2 A (2 pi / Lambda)^2``), and the surface amplitude is
    ``A = P / (2 k^2 F)``, peak-to-valley ``2 A``. The pane mm along the image axes: with the
    plane of incidence along an image axis, the camera (aimed at the view's centre) sees the
    pane foreshortened by ``cos(theta)`` along it (:func:`standard_measures`).
    """
    theta = np.radians(optics.incidence_deg)
    b = np.radians(rw.direction_deg - optics.plane_of_incidence_deg)
    F = float(np.cos(b) ** 2 / np.cos(theta) + np.sin(b) ** 2 * np.cos(theta))
    k = 2 * np.pi / rw.period_mm
    A = rw.power_amplitude_mD * 1e-6 / (2 * k * k * F)
    return {
        "period_mm": rw.period_mm, "direction_deg": rw.direction_deg,
        "power_amplitude_mD": rw.power_amplitude_mD, "power_pv_mD": rw.power_pv_mD,
        "surface_pv_mm": 2 * A, "explained_fraction": rw.explained_fraction,
        "assumptions": "period and direction on the pane; power: reflective power along the wave "
                       "(2 A (2 pi / period)^2 at normal incidence); surface_pv_mm = 2 A from a one-dimensional, "
                       "near-sinusoidal wave (explained_fraction near 1) at the stated incidence, constant over the view; "
                       "oblique views: camera aimed at the view's centre, plane of incidence along an image axis",
    }


def standard_measures(result, *, gauge_mm: float = 4.0, directions_deg=(0.0, 90.0)) -> StandardMeasures:
    """All standard measures of an :class:`~glassdist.analyzer.AnalysisResult`.

    They are computed from the field ``displacement_detrended_mm`` on the result's analysis
    grid (the field the power channels differentiate: after the degree-N detrend and the sigma
    smoothing, so relative to the Direct Method's homography baseline or the Comparative
    reference and to the degree-N trend), at the trusted samples whose centre pixel is in the
    reported region (the region the statistics use), with the isotropic ``mm_per_px``.

    Parameters
    ----------
    result : AnalysisResult
    gauge_mm : float
        Gauge length of the angular-deviation rate, mm.
    directions_deg : sequence of float
        Grid-line directions for the grid-line slope.
    """
    g = result.analysis_grid
    # The samples whose centre pixel is in the reported region (the grid fields also hold a
    # smooth extension one block beyond it), and of those the trusted ones (quality label 0:
    # the guard band's channels are biased).
    yy, xx = g.coords()
    H, W = result.valid.shape
    inside = result.valid[np.clip(np.rint(yy).astype(int), 0, H - 1), np.clip(np.rint(xx).astype(int), 0, W - 1)]
    inside &= result.grid_trusted
    d = np.where(inside[..., None], np.asarray(result.grid_field("displacement_detrended_mm"), dtype=float), np.nan)
    phi = np.where(inside, np.asarray(result.grid_field("phi_eff_mD"), dtype=float), np.nan)
    sy, sx = g.step
    step = (sy * result.mm_per_px, sx * result.mm_per_px)
    L = result.distance_m
    optics = result.optics
    rw_step = gl_step = step
    if optics is not None:
        # board mm per sample; in reflection D / cos(theta) turns the board displacement into reflective power
        gl_step = (step[0] * optics.magnification, step[1] * optics.magnification)
        cos_t = float(np.cos(np.radians(optics.incidence_deg)))
        L = optics.board_distance_m / cos_t
        # a camera aimed at the view's centre sees the pane foreshortened by cos(theta) along the plane of
        # incidence: pane mm per px mm_per_px / sqrt(cos) along it, x sqrt(cos) across (image axes only)
        psi = np.radians(optics.plane_of_incidence_deg)
        f = np.sqrt(cos_t)
        if abs(np.sin(psi)) < 1e-9:
            rw_step = (step[0] * f, step[1] / f)
        elif abs(np.cos(psi)) < 1e-9:
            rw_step = (step[0] / f, step[1] * f)
    rw = roll_wave(d, step_mm=rw_step, distance_m=L)
    return StandardMeasures(
        roll_wave=rw,
        angular_deviation=angular_deviation(d, step_mm=step, distance_m=L, gauge_mm=gauge_mm),
        grid_line_slope=grid_line_slope(d, step_mm=gl_step, directions_deg=directions_deg),
        equivalent_power=equivalent_power(phi),
        step_mm=step,
        field=(
            f"displacement_detrended_mm (degree-{result.detrend_degree} detrend, sigma_mm = {result.sigma_mm:.4g}) "
            "on the analysis grid"
        ),
        reflection=None if optics is None else reflected_roll_wave(rw, optics),
    )
