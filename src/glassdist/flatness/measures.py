"""Flatness measures of the front face in mm and µm: roller wave, height peak-to-valley, bow.

Written to ``summary.json["flatness"]`` for reflection runs (:func:`flatness_measures`), from
the field ``surface_height_um`` (:mod:`glassdist.flatness.slope`) on the analysis grid, over
its trusted samples.

Roller wave. The height over the region is modelled as the degree-N polynomial its detrend
leaves free plus one sinusoid,

.. math:: Z(\\mathbf r) = \\sum_{i+j \\le N} c_{ij} x^i y^j + a \\cos(2\\pi\\,\\mathbf k\\cdot\\mathbf r)
          + b \\sin(2\\pi\\,\\mathbf k\\cdot\\mathbf r),

the wave vector ``k`` (cycles per pane mm) started at the peak of the 2-D spectrum of the
masked height (zero-padded twice, parabolic sub-bin peak) and refined by least squares
(variable projection: the linear coefficients solved at each ``k``,
``scipy.optimize.least_squares`` on ``k``), the maximum-likelihood frequency of a sinusoid in
white noise. Then the wavelength is ``1 / |k|``, the peak-to-valley ``2 sqrt(a^2 + b^2)``, and
``direction_deg`` the direction of ``k`` (across the rollers: the direction along which the
height varies), deg from +x towards +y in (-90, 90]. Fitting the polynomial with the wave
makes the result independent of the detrend.

ASTM C1651 millidioptres. The optical power of a sinusoidal roll wave of depth (peak to
valley) ``PV`` and wavelength ``lambda`` seen in reflection at normal incidence is the peak
curvature ``(PV / 2)(2 pi / lambda)^2`` times 2 (a mirror):

.. math:: P = \\frac{4 \\pi^2\\, PV}{\\lambda^2}

(x 1e6: mD for ``PV`` and ``lambda`` in mm; 43.9 mD for 0.1 mm at 300 mm): the peak
reflective power of the sinusoid, the quantity in which ASTM C1651 reports roll wave (mD),
written here from the wave's curvature; equal, at normal incidence, to the
``power_amplitude_mD`` that ``measures.reflected_roll_wave`` reads from the board strain. A
gauge that reports a different convention (e.g. the power's peak-to-valley, twice this)
differs by its stated factor.

Bow. A uniform curvature of the face is a degree-2 term of the height. The Direct Method's
homography absorbs it (a change of scale of the board's image), and a detrend of degree
N >= 2 removes it; the Comparative Method with N <= 1 keeps it, and the mean curvature of the
height's fitted quadratic gives the radius.

References
----------
ASTM C1651-11, *Standard Test Method for Measurement of Roll Wave Optical Distortion in
Heat-Treated Flat Glass*.
EN 12150-1:2015, *Glass in building - Thermally toughened soda lime silicate safety glass*,
§ 6 (roller wave and edge lift, measured with a straight edge).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

__all__ = [
    "EdgeLift",
    "FlatnessMeasures",
    "RollerWaveHeight",
    "astm_c1651_mD",
    "bow_of",
    "edge_lift",
    "edge_lifts",
    "flatness_measures",
    "roller_wave_height",
]


#: the pane edges a view can hold (``top``: the image's first rows)
EDGE_NAMES = ("top", "bottom", "left", "right")
EDGE_LIFT_NOTE = ("height at the edge above the straight line fitted to the profile between 100 and 300 mm in "
                  "(EN 12150-1 practice), mm, > 0 away from the camera; the edge (edge_px, image px, pixel j "
                  "centred on j) is where the reported region meets the frame or the dark surroundings; the "
                  "profile is the height averaged along the edge over span_px, carried from its first sample "
                  "(first_mm) to the edge by the quadratic of its first 40 mm")


#: quality labels of what lies beyond a pane edge seen (:data:`glassdist.analyzer.region.LABELS`): occluded / low
#: modulation (the frame, the dark surroundings) and beyond range (the strongly bent glass next to them); pinned
#: to the analyzer's by tests/test_flatness.py
BEYOND_EDGE_LABELS = (2, 3)


def astm_c1651_mD(peak_to_valley_mm: float, wavelength_mm: float) -> float:
    """Reflected optical power of a roll wave, ``4 pi^2 PV / lambda^2`` (module notes), mD."""
    return float(4.0 * math.pi**2 * peak_to_valley_mm / wavelength_mm**2 * 1e6)


@dataclass(frozen=True)
class RollerWaveHeight:
    """The dominant periodic component of the height (module notes, "Roller wave").

    Attributes
    ----------
    peak_to_valley_mm : float
        ``2 sqrt(a^2 + b^2)``, mm.
    wavelength_mm : float
        ``1 / |k|``, pane mm.
    direction_deg : float
        Direction of the wave vector (across the rollers), deg from +x towards +y, (-90, 90].
    astm_c1651_mD : float
        ``4 pi^2 PV / lambda^2``, mD.
    explained_fraction : float
        Share of the height's variance (less the polynomial) the sinusoid explains.
    """

    peak_to_valley_mm: float
    wavelength_mm: float
    direction_deg: float
    astm_c1651_mD: float
    explained_fraction: float

    def to_dict(self) -> dict:
        """The roller wave as ``summary.json["flatness"]["roller_wave"]`` writes it."""
        return asdict(self)


def _basis(x, y, degree):
    return np.column_stack([x**i * y**(n - i) for n in range(degree + 1) for i in range(n + 1)])


def _spectral_peak(z, mask, step_mm):
    """Wave vector (kx, ky), cycles/mm, of the masked height's spectral peak, or None."""
    sy, sx = step_mm
    h, w = z.shape
    f = np.where(mask, z - z[mask].mean(), 0.0)
    ny, nx = 2 * h, 2 * w
    S = np.abs(np.fft.rfft2(f, s=(ny, nx))) ** 2
    fy = np.fft.fftfreq(ny, sy)[:, None]
    fx = np.fft.rfftfreq(nx, sx)[None, :]
    kn = np.hypot(fx, fy)
    S[(kn < 1.0 / max(h * sy, w * sx)) | (kn > 1.0 / (4.0 * max(sy, sx)))] = 0.0
    if not np.any(S > 0):
        return None
    iy, ix = np.unravel_index(int(np.argmax(S)), S.shape)
    lv = np.log(np.maximum([S[(iy - 1) % ny, ix], S[iy, ix], S[(iy + 1) % ny, ix]], 1e-300))
    oy = 0.5 * (lv[0] - lv[2]) / (lv[0] - 2 * lv[1] + lv[2]) if lv[0] - 2 * lv[1] + lv[2] < 0 else 0.0
    ox = 0.0
    if 0 < ix < S.shape[1] - 1:
        lv = np.log(np.maximum([S[iy, ix - 1], S[iy, ix], S[iy, ix + 1]], 1e-300))
        den = lv[0] - 2 * lv[1] + lv[2]
        ox = 0.5 * (lv[0] - lv[2]) / den if den < 0 else 0.0
    return np.array([fx[0, ix] + np.clip(ox, -0.5, 0.5) / (nx * sx), fy[iy, 0] + np.clip(oy, -0.5, 0.5) / (ny * sy)])


def roller_wave_height(height_um: np.ndarray, mask: np.ndarray, step_mm, *, degree: int = 0) -> RollerWaveHeight | None:
    """The dominant roller wave of a height map (module notes).

    Parameters
    ----------
    height_um : ndarray (h, w)
        Height, µm (read where ``mask``).
    mask : ndarray (h, w) bool
        Samples to fit.
    step_mm : (float, float)
        Pane mm per sample along rows and columns.
    degree : int
        Degree of the polynomial fitted with the wave (the height's detrend degree N).

    Returns
    -------
    RollerWaveHeight or None
        None when fewer than 16 samples, no spectral peak in the band (four samples to the
        region's extent), or the refined wave vector leaves that band (no periodic component the
        region holds: the least squares ran to a wavelength longer than the region, where it is a
        polynomial's, or shorter than four samples).
    """
    mask = np.asarray(mask, bool) & np.isfinite(height_um)
    if mask.sum() < 16:
        return None
    z = np.asarray(height_um, float)
    k0 = _spectral_peak(z, mask, step_mm)
    if k0 is None:
        return None
    r, c = np.nonzero(mask)
    y, x, zv = r * step_mm[0], c * step_mm[1], z[mask]
    xc, yc, sc = x.mean(), y.mean(), max(np.ptp(x), np.ptp(y), 1e-12) / 2
    P = _basis((x - xc) / sc, (y - yc) / sc, max(int(degree), 0))
    sub = slice(None, None, max(1, x.size // 40_000))

    def design(k, s=slice(None)):
        ph = 2 * np.pi * (k[0] * (x[s] - xc) + k[1] * (y[s] - yc))
        return np.column_stack([P[s], np.cos(ph), np.sin(ph)])

    def resid(k, s=sub):
        A = design(k, s)
        return zv[s] - A @ np.linalg.lstsq(A, zv[s], rcond=None)[0]

    k = least_squares(resid, k0, x_scale=np.full(2, np.hypot(*k0)), xtol=1e-12, ftol=1e-12).x
    A = design(k)
    coef = np.linalg.lstsq(A, zv, rcond=None)[0]
    rest = zv - P @ np.linalg.lstsq(P, zv, rcond=None)[0]
    rss, tss = float(np.sum((zv - A @ coef) ** 2)), float(np.sum(rest**2))
    kn = float(np.hypot(*k))
    extent = max(np.ptp(x) + step_mm[1], np.ptp(y) + step_mm[0])
    if not (1.0 / extent <= kn <= 1.0 / (4.0 * max(step_mm))):
        return None
    direction = math.degrees(math.atan2(k[1], k[0]))
    direction = direction + 180.0 if direction <= -90.0 else direction - 180.0 if direction > 90.0 else direction
    pv_mm = 2e-3 * float(np.hypot(coef[-2], coef[-1]))
    return RollerWaveHeight(pv_mm, 1.0 / kn, direction, astm_c1651_mD(pv_mm, 1.0 / kn),
                            max(0.0, 1.0 - rss / tss) if tss > 0 else 0.0)


def bow_of(height_um: np.ndarray, mask: np.ndarray, step_mm, *, method: str, degree: int, bulk=None) -> dict:
    """The bow the result leaves identifiable (module notes, "Bow"): radius of the mean curvature, or why none.

    Returns
    -------
    dict
        ``identifiable``, ``radius_m`` (of ``Z = -r^2 / 2R``: positive for a face concave towards
        the camera; None when not identifiable or flat), ``note``.
    """
    pinned = getattr(bulk, "pinned", None) if bulk is not None else None
    if method == "direct" and pinned and bulk.phi_eff_mD is not None and bulk.phi_eff_mD != 0:
        sig = bulk.phi_eff_sigma_mD
        R = -4000.0 / bulk.phi_eff_mD
        return {"identifiable": True, "radius_m": float(R),
                "radius_sigma_m": None if sig is None else float(abs(R) * sig / abs(bulk.phi_eff_mD)),
                "note": "Direct Method, magnification pinned (camera file and camera-to-pane distance): the bulk "
                        "channel's sphere, R = -4000 / phi_eff (mD, reflective power 4 / R at normal incidence; "
                        "R > 0 concave towards the camera); radius_sigma_m from its noise only, the distance's and "
                        "focal length's own tolerances as the bulk channel's pinned sensitivities say"}
    if method == "direct":
        return {"identifiable": False, "radius_m": None,
                "note": "Direct Method: a uniform curvature is a change of scale of the board's image, absorbed by "
                        "the homography; read the bow with the Comparative Method (a flat reference surface), or pin "
                        "the camera (a camera file and the camera-to-pane distance: --camera-file, "
                        "--camera-distance-m)"}
    if degree >= 2:
        return {"identifiable": False, "radius_m": None,
                "note": f"the height is detrended at degree {degree} (>= 2), which removes a uniform curvature; "
                        "run with --detrend-degree 1 or 0 to keep it"}
    mask = np.asarray(mask, bool) & np.isfinite(height_um)
    r, c = np.nonzero(mask)
    if r.size < 16:
        return {"identifiable": False, "radius_m": None, "note": "too few samples"}
    y, x = r * step_mm[0], c * step_mm[1]
    x, y = x - x.mean(), y - y.mean()
    A = np.column_stack([np.ones_like(x), x, y, x * x, x * y, y * y])
    cf = np.linalg.lstsq(A, np.asarray(height_um, float)[mask] * 1e-3, rcond=None)[0]  # mm
    mean_curv = cf[3] + cf[5]  # (Z_xx + Z_yy) / 2, 1/mm
    return {"identifiable": True, "radius_m": None if mean_curv == 0 else float(-1.0 / mean_curv / 1000.0),
            "note": "Comparative Method: radius of the mean curvature of the height's least-squares quadratic "
                    "(Z = -r^2 / 2R, R > 0 concave towards the camera), relative to the reference surface"}


@dataclass(frozen=True)
class FlatnessMeasures:
    """``summary.json["flatness"]`` of a reflection run.

    Attributes
    ----------
    roller_wave : RollerWaveHeight or None
    height_peak_to_valley_um : float
        Maximum less minimum of the detrended height over the trusted samples, µm.
    bow : dict
        :func:`bow_of`.
    detrend_degree : int
    step_mm : (float, float)
        Pane mm per sample of the height map.
    height_sigma_um : float or None
        RMS over the trusted samples of ``surface_height_sigma_um`` (the height's standard uncertainty
        from the image noise), µm; None when the result has none.
    edge_lifts : dict
        :func:`edge_lifts`: per edge (``top``, ``bottom``, ``left``, ``right``) None where the edge is
        not in view, else its lift (mm), where the edge lies and the profile used.
    """

    roller_wave: RollerWaveHeight | None
    height_peak_to_valley_um: float
    bow: dict
    detrend_degree: int
    step_mm: tuple[float, float]
    edge_lifts: dict = field(default_factory=dict)
    height_sigma_um: float | None = None

    @property
    def edge_lift_mm(self) -> dict:
        """``{edge: lift_mm or None}`` for the four edges."""
        return {e: None if self.edge_lifts.get(e) is None else self.edge_lifts[e]["lift_mm"] for e in EDGE_NAMES}

    def to_dict(self) -> dict:
        """The measures as ``summary.json["flatness"]`` writes them."""
        return {
            "roller_wave": None if self.roller_wave is None else self.roller_wave.to_dict(),
            "height_peak_to_valley_um": self.height_peak_to_valley_um,
            "height_sigma_um": self.height_sigma_um,
            "edge_lift_mm": self.edge_lift_mm,
            "edge_lift": {**{e: self.edge_lifts.get(e) for e in EDGE_NAMES}, "definition": EDGE_LIFT_NOTE},
            "bow": self.bow,
            "detrend_degree": self.detrend_degree,
            "step_mm": list(self.step_mm),
            "field": "surface_height_um (pane frame, detrended at detrend_degree) on the analysis grid, trusted "
                     "samples (glassdist.flatness); the reflective-power amplitude of the wave read from the board "
                     "strain is measures.reflected_roll_wave.power_amplitude_mD",
        }


def flatness_measures(result, *, beyond_edge_labels=BEYOND_EDGE_LABELS) -> FlatnessMeasures | None:
    """The flatness measures of a reflection result holding ``surface_height_um``, else None.

    ``beyond_edge_labels``: the quality labels that may lie beyond a pane edge seen (:func:`edge_lifts`).
    """
    from .slope import pane_step_mm

    if "surface_height_um" not in {f.name for f in result.field_specs()}:
        return None
    z = np.asarray(result.grid_field("surface_height_um"), float)
    mask = np.asarray(result.grid_valid, bool) & np.asarray(result.grid_trusted, bool) & np.isfinite(z)
    step = pane_step_mm(result)
    N = int(result.detrend_degree)
    pv = float(np.ptp(z[mask])) if mask.any() else float("nan")
    region = np.asarray(result.grid_valid, bool) & np.isfinite(z)  # the edges: the reported region, to its border
    lifts = edge_lifts(z, region, result.analysis_grid.coords(), step, np.asarray(result.valid, bool),
                       np.asarray(result.quality), grid_step_px=result.analysis_grid.step,
                       beyond_edge_labels=beyond_edge_labels)
    sig = None
    if "surface_height_sigma_um" in {f.name for f in result.field_specs()} and mask.any():
        sig = float(np.sqrt(np.nanmean(np.asarray(result.grid_field("surface_height_sigma_um"), float)[mask] ** 2)))
    return FlatnessMeasures(roller_wave_height(z, mask, step, degree=N), pv,
                            bow_of(z, mask, step, method=result.method, degree=N, bulk=result.bulk), N, step, lifts,
                            sig)


@dataclass(frozen=True)
class EdgeLift:
    """The edge lift of one height profile taken in from a pane edge (:func:`edge_lift`).

    Attributes
    ----------
    lift_mm : float
        Height at the edge (``d = 0``) above the straight line fitted between ``flat_mm``, mm;
        NaN when the profile does not reach the flat part or the edge's neighbourhood.
    edge_height_um : float
        The profile's height at the edge, µm: measured there, or extrapolated by the quadratic
        fitted over the first ``extrapolate_mm`` of the measured profile when it starts further in.
    first_mm : float
        Distance from the edge of the first measured sample, mm.
    line : (float, float)
        ``(a, b)`` of the straight edge's line ``a + b d`` (µm, µm per mm).
    """

    lift_mm: float
    edge_height_um: float
    first_mm: float
    line: tuple[float, float]


def edge_lift(d_mm, height_um, *, flat_mm=(100.0, 300.0), extrapolate_mm: float = 40.0) -> EdgeLift:
    """Edge lift of a height profile: the height at the edge above the line fitted to its flat part.

    EN 12150-1 practice: a straight edge rests on the flat part of the pane, between 100 mm and
    300 mm in from the edge, and the lift is the gap at the edge. Here the straight edge is the
    least-squares line over the samples with ``flat_mm[0] <= d <= flat_mm[1]``, and the height at
    the edge is the quadratic fitted over ``first_mm <= d <= first_mm + extrapolate_mm``,
    evaluated at ``d = 0`` (exact for a lift ``h (1 - d / w)^2`` reaching ``w >= first_mm +
    extrapolate_mm`` in; the measured region usually stops a guard band short of the edge).

    Parameters
    ----------
    d_mm : array_like (n,)
        Distance of each sample from the edge, inwards, pane mm.
    height_um : array_like (n,)
        Height ``Z`` (away from the camera), µm; NaN samples are skipped.
    flat_mm : (float, float)
        The straight edge's span, mm from the edge.
    extrapolate_mm : float
        Span of the quadratic that carries the profile to the edge, mm.

    Returns
    -------
    EdgeLift
        ``lift_mm`` > 0: the edge stands above the straight edge, away from the camera (for a lift towards the
        camera, < 0).
    """
    d, z = np.asarray(d_mm, float), np.asarray(height_um, float)
    ok = np.isfinite(d) & np.isfinite(z) & (d >= 0)
    d, z = d[ok], z[ok]
    nan = float("nan")
    flat = (d >= flat_mm[0]) & (d <= flat_mm[1])
    if flat.sum() < 2 or d.size == 0:
        return EdgeLift(nan, nan, float(d.min()) if d.size else nan, (nan, nan))
    b, a = np.polyfit(d[flat], z[flat], 1)
    first = float(d.min())
    near = d <= first + extrapolate_mm
    if first > flat_mm[0] or near.sum() < 3:
        return EdgeLift(nan, nan, first, (float(a), float(b)))
    z0 = float(np.polyval(np.polyfit(d[near], z[near], 2), 0.0))
    return EdgeLift((z0 - a) / 1000.0, z0, first, (float(a), float(b)))


def _edge_of(valid_px: np.ndarray, quality_px: np.ndarray, name: str, tolerance_px: float = 2.0,
             beyond=BEYOND_EDGE_LABELS):
    """Where the reported region meets a pane edge seen in the photo, px, and the span along it, or None.

    The edge is the outer side of the region's first pixel on each line across the edge, over the middle
    half of the region's extent along the edge (away from the corners and the other edges' lifts), the
    mean over them (the border steps by the demodulation's sampling; the mean of the steps follows the
    edge to a fraction of one). None unless the pixels just beyond are occluded / low modulation or beyond
    range (``beyond``, :data:`BEYOND_EDGE_LABELS`) on nine lines in ten: the frame, the dark
    surroundings, or the strongly bent glass next to them (an image edge or a user mask is not a pane
    edge); and None where the border is not straight (interquartile range above ``tolerance_px``).
    """
    v, q = (valid_px, quality_px) if name in ("left", "right") else (valid_px.T, quality_px.T)
    if name in ("right", "bottom"):
        v, q = v[:, ::-1], q[:, ::-1]
    lines = np.flatnonzero(v.any(axis=1))
    if lines.size < 8:
        return None
    a, b = lines[0] + 0.25 * (lines[-1] - lines[0]), lines[0] + 0.75 * (lines[-1] - lines[0])
    mid = lines[(lines >= a) & (lines <= b)]
    first = np.argmax(v[mid], axis=1)
    outside = q[mid, np.maximum(first - 1, 0)]
    if np.mean((first > 0) & np.isin(outside, beyond)) < 0.9:
        return None
    q1, q3 = np.percentile(first, [25, 75])
    if q3 - q1 > tolerance_px:
        return None
    inner = float(np.mean(first)) - 0.5  # the outer side of the first pixel, counted from this edge
    edge = inner if name in ("left", "top") else v.shape[1] - 1 - inner
    return float(edge), (float(a), float(b))


def edge_lifts(height_um: np.ndarray, mask: np.ndarray, coords_px, step_mm, valid_px: np.ndarray,
               quality_px: np.ndarray, *,
               grid_step_px, flat_mm=(100.0, 300.0), beyond_edge_labels=BEYOND_EDGE_LABELS) -> dict[str, Any]:
    """Edge lift at each pane edge in view (EN 12150-1 practice; :func:`edge_lift` on each edge's profile).

    The profile of an edge is the height averaged along the edge over the middle half of the region's
    extent (away from the corners, where two edges' lifts add), as a function of the distance ``d`` in
    from the edge; the edge is where the reported region meets the frame or the dark surroundings
    (:func:`_edge_of`): the lift is that of the glass the region reaches. Where the lift bends the grid's
    image beyond the demodulation's range next to the frame, the region, and so the edge, stops short of
    the glass's edge (``edge_px`` says where).

    Parameters
    ----------
    height_um : ndarray (h, w)
        Height on the analysis grid, µm.
    mask : ndarray (h, w) bool
        Samples of the profile (the reported region).
    coords_px : (ndarray, ndarray)
        Pixel coordinates ``(y, x)`` of the grid samples (pixel ``j`` centred on ``j``).
    step_mm : (float, float)
        Pane mm per grid sample along rows and columns.
    valid_px, quality_px : ndarray (H, W)
        The result's reported region and quality labels on the photo's pixels (what lies beyond the
        region's border).
    grid_step_px : (float, float)
        Pixels per grid sample.
    flat_mm : (float, float)
        The straight edge's span (:func:`edge_lift`).
    beyond_edge_labels : tuple of int
        The quality labels that may lie beyond a pane edge (:data:`BEYOND_EDGE_LABELS`).

    Returns
    -------
    dict
        ``{edge: None or {"lift_mm", "edge_px", "span_px", "first_mm", "line_um", "profile": {"d_mm",
        "height_um"}}}`` for ``top``, ``bottom``, ``left``, ``right`` (``top``: the image's first rows).
    """
    yy, xx = coords_px
    out: dict[str, Any] = {}
    for name in EDGE_NAMES:
        found = _edge_of(np.asarray(valid_px, bool), np.asarray(quality_px), name,
                         tolerance_px=1.0 + float(max(grid_step_px)), beyond=beyond_edge_labels)
        if found is None:
            out[name] = None
            continue
        edge, (a, b) = found
        across_cols = name in ("left", "right")
        along, pos = (yy[:, 0], xx[0, :]) if across_cols else (xx[0, :], yy[:, 0])
        mm_per_px = step_mm[1] / grid_step_px[1] if across_cols else step_mm[0] / grid_step_px[0]
        sel = (along >= a) & (along <= b)
        z = np.where(mask, height_um, np.nan)
        band = z[sel, :] if across_cols else z[:, sel].T
        counts = np.isfinite(band).sum(axis=0)
        full = counts > 0.5 * band.shape[0]  # a sample of the profile: most of the band measured there
        prof = np.where(full, np.nansum(band, axis=0) / np.maximum(counts, 1), np.nan)
        d = (pos - edge if name in ("left", "top") else edge - pos) * mm_per_px
        keep = np.isfinite(prof) & (d >= 0)
        order = np.argsort(d[keep])
        d, prof = d[keep][order], prof[keep][order]
        el = edge_lift(d, prof, flat_mm=flat_mm)
        if not np.isfinite(el.lift_mm):
            out[name] = None
            continue
        out[name] = {"lift_mm": el.lift_mm, "edge_px": edge, "span_px": [a, b], "first_mm": el.first_mm,
                     "line_um": list(el.line),
                     "profile": {"d_mm": [round(float(x), 3) for x in d],
                                 "height_um": [round(float(x), 4) for x in prof]}}
    return out
