"""Block F4's valid region and quality map: where the phase is measured, where it is trusted, and why not elsewhere.

Every sample of the demodulation grid gets one integer label (:data:`LABELS`):

===  ==================  ==============================================================
0    analysed            measured and trusted: used in statistics and specifications
1    image edge          within the contamination margin of the image edge (the periodic
                         FFT mixes the opposite edge in)
2    low modulation      occluded or too little grid contrast (either photo), or phase
                         incoherent within the smoothing kernel; and its margin
3    beyond range        the local grid frequency departs from the carrier by more than
                         ``max_frequency_deviation`` (the bandpass cannot follow it); and
                         its margin
4    phase residue       a 2x2 loop of the wrapped phase does not close (noise, occlusion
                         or distortion beyond the sampling condition), or a branch cut
                         between excluded areas the wrapped phase winds around
                         (:func:`~glassdist.analyzer.unwrap.branch_cuts`)
5    user mask           outside the region the user asked for
6    guard band          measured (displacement and channels reported) but within the
                         guard band of an excluded area or the image edge: the metric
                         smoothing there reaches the border and the channels are biased,
                         so it is left out of statistics and specifications
7    fragment            an isolated piece of region too small to unwrap and detrend alone
                         (smaller than ``min_region_fraction`` of the grid, and either
                         smaller than :data:`MIN_REGION_PERIODS` x :data:`MIN_REGION_PERIODS`
                         carrier periods or not continuing its surroundings)
===  ==================  ==============================================================

``valid`` (the reported region) is labels 0 and 6; statistics use label 0. Connected
parts of the measured region are labelled: a frame or mullion splits the pane into regions
unwrapped, detrended and smoothed independently. A part of ``min_region_fraction`` of the
grid is kept; a smaller one that holds :data:`MIN_REGION_PERIODS` x :data:`MIN_REGION_PERIODS`
carrier periods is kept where its whole-period count is fixed by continuity with the flat
glass around it (:func:`_continues_surroundings`): a coherent part the demodulation reads, the
centre of a small strong lens inside the ring its rim makes unmeasurable, is analysed, not
dropped as a fragment.
Every excluded area of that size or larger is named in a warning
(:func:`excluded_area_warning`: its size in periods and mm, where, and why).

Margins (derived, not tuned): Block F's demodulation is a Gaussian low-pass of the
baseband signal with covariance ``C`` (bandpass and complex smoothing, px^2). Behind a
straight boundary an unrelated signal of up to the same amplitude mixes in with weight
``eps(d) = Phi(-d / s_n)`` at distance ``d``, ``s_n`` the kernel's standard deviation
across the boundary (the largest, to be safe), moving the phase by at most
``asin(eps / (1 - eps))``. The margin is the distance where that bound equals
``margin_phase_error_periods`` of a period (:func:`contamination_px`).

Guard band: within ``guard_band_sigmas`` reporting smoothing scales (sigma_px) of an
excluded area (labels 1-4, 7, and the image edge) the first-order normalised
convolution extrapolates over a one-sided window, and any contamination within the
margin is spread by it; measured on synthetic captures with an opaque drop against the
truth through the same stack, the error of phi_eff there decays from ~30% of the map's
p95 at the border to ~10% at 1.5 sigma (docs/accuracy.md). The user mask needs no
guard: the photo beyond it is measured.

References
----------
Paper §2.2 (F3-F4); Goldstein, Zebker & Werner (1988) for residues.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.special import ndtri

from . import fourier as F
from .unwrap import branch_cuts, label_regions, residues, wrap

__all__ = [
    "ANALYSED",
    "IMAGE_EDGE",
    "LOW_MODULATION",
    "BEYOND_RANGE",
    "PHASE_RESIDUE",
    "USER_MASK",
    "GUARD_BAND",
    "FRAGMENT",
    "LABELS",
    "EXCLUDED",
    "Region",
    "valid_region",
    "contamination_px",
    "local_contrast",
    "beyond_range_warning",
    "excluded_area_warning",
    "MIN_REGION_PERIODS",
    "local_frequency_deviation",
    "erode",
    "grid_seen",
    "guard_band",
    "within",
    "pixel_quality",
    "trim_edges",
    "trusted_on",
    "downsample_mask",
]

ANALYSED, IMAGE_EDGE, LOW_MODULATION, BEYOND_RANGE, PHASE_RESIDUE, USER_MASK, GUARD_BAND, FRAGMENT = range(8)

#: Label -> short description (the README and the figures' legends use these).
LABELS = {
    ANALYSED: "analysed",
    IMAGE_EDGE: "image edge",
    LOW_MODULATION: "occluded / low modulation",
    BEYOND_RANGE: "beyond measurable distortion",
    PHASE_RESIDUE: "phase residue",
    USER_MASK: "user mask",
    GUARD_BAND: "guard band (near an excluded area)",
    FRAGMENT: "isolated fragment",
}

#: Labels whose area is not measured and whose neighbourhood gets the guard band.
EXCLUDED = (IMAGE_EDGE, LOW_MODULATION, BEYOND_RANGE, PHASE_RESIDUE, FRAGMENT)

#: Side, in carrier periods, of the smallest square patch a connected part is analysed from on its own
#: (two periods: the demodulation's own support, about a period, fits inside with room to unwrap); an
#: excluded area of that size or larger is named in a warning.
MIN_REGION_PERIODS = 2.0


@dataclass(frozen=True)
class Region:
    """The measured region on the demodulation grid and its quality labels.

    Attributes
    ----------
    valid : ndarray of bool (h, w)
        Measured samples (``labels > 0``).
    labels : ndarray of int (h, w)
        Connected parts, 1..n by decreasing size; 0 outside.
    n : int
        Number of parts kept (see :func:`min_region_samples`).
    quality : ndarray of uint8 (h, w)
        :data:`LABELS` per sample (the guard band is added later, see :func:`guard_band`).
    parts : _PartRule or None
        How its connected parts were kept (:func:`_kept_parts`), for a restriction of it
        (:func:`within`).
    """

    valid: np.ndarray
    labels: np.ndarray
    n: int
    quality: np.ndarray | None = None
    parts: _PartRule | None = None


@dataclass(frozen=True)
class _PartRule:
    """The sizes of :func:`_kept_parts`: parts of ``large`` samples or more are kept; of ``small`` or more, when
    they continue their surroundings (``step``: the grid's step, ``period_px``: the longer carrier period)."""

    small: int
    large: int
    step: tuple[float, float]
    period_px: float


def _part_rule(p, grid: F.SamplingGrid, period_px: float) -> _PartRule:
    large = max(int(p.min_region_fraction * grid.shape[0] * grid.shape[1]), 16)
    return _PartRule(min_region_samples(p, grid, period_px), large, grid.step, float(period_px))


def _continues_surroundings(part: np.ndarray, large: np.ndarray, phases, rule: _PartRule) -> bool:
    """Whether a small part's whole-period count is that of the large parts around it, by continuity.

    The surroundings are the samples of the large parts within two carrier periods beyond the
    nearest of them (across the excluded gap). They must be flat enough to carry their phase
    across the gap (each wrapped phase's mean resultant length over them above 0.9: a spread
    under about a tenth of a period), and the part must continue them: its circular mean phase
    within a quarter period of theirs (and its own resultant above 0.5). The part is then
    unwrapped on its own (its free multiple of 2 pi chosen as every region's) and lands on its
    surroundings' count, as the centre of a small lens in flat glass does; the parts on the
    steep flanks of strong waves, whose count nothing fixes, stay fragments.
    """
    if not large.any():
        return True  # nothing to disagree with: the part is analysed as any region
    dist = ndimage.distance_transform_edt(~part, sampling=rule.step)
    near = dist[large].min()
    collar = large & (dist <= near + 2.0 * rule.period_px)
    for ph in phases[:2]:
        zs = np.exp(1j * ph[part].astype(np.float64)).mean()
        zk = np.exp(1j * ph[collar].astype(np.float64)).mean()
        if abs(zk) < 0.9 or abs(zs) < 0.5 or abs(np.angle(zs * np.conj(zk))) > np.pi / 2:
            return False
    return True


def _kept_parts(valid: np.ndarray, phases, rule: _PartRule) -> tuple[np.ndarray, int]:
    """Connected parts of ``valid`` kept (:func:`~glassdist.analyzer.unwrap.label_regions`, 1..n by size).

    Parts of ``rule.large`` samples (``min_region_fraction`` of the grid) or more are kept;
    smaller ones of ``rule.small`` samples (:func:`min_region_samples`) or more where they
    continue their surroundings (:func:`_continues_surroundings`, with the wrapped ``phases``;
    without phases, where they are at least ``rule.large``).
    """
    regions, n = label_regions(valid, rule.small)
    if n == 0 or rule.small >= rule.large:
        return regions, n
    sizes = np.bincount(regions.ravel(), minlength=n + 1)[1:]
    small = [k + 1 for k in range(n) if sizes[k] < rule.large]
    if not small:
        return regions, n
    large = regions > 0
    large[np.isin(regions, small)] = False
    keep = regions > 0
    for k in small:
        part = regions == k
        if not len(phases) or not _continues_surroundings(part, large, phases, rule):
            keep &= ~part
    return label_regions(keep, rule.small)


def min_region_samples(p, grid: F.SamplingGrid, period_px: float) -> int:
    """The smallest connected part (samples of ``grid``) that can be unwrapped, detrended and smoothed on its own.

    A part of ``min_region_fraction`` of the grid, or one holding a square of
    :data:`MIN_REGION_PERIODS` carrier periods (``period_px``: the longer period) where that is
    smaller; 16 samples at least. The smaller parts are kept where they continue their
    surroundings (:func:`_kept_parts`); the fraction alone made the rule before, and a small
    strong lens's centre, coherent and read by the demodulation but 0.3 % of the view, was dropped.
    """
    h, w = grid.shape
    sy, sx = grid.step
    share = int(p.min_region_fraction * h * w)
    periods = int(np.ceil((MIN_REGION_PERIODS * period_px) ** 2 / (sy * sx)))
    return max(min(share, periods), 16)


def contamination_px(blur_px2: np.ndarray, phase_error_periods: float) -> float:
    """Distance (px) from a boundary beyond which its contamination moves the phase by less than the tolerance.

    Parameters
    ----------
    blur_px2 : ndarray (2, 2, 2)
        Spatial covariance of Block F's low-pass for each carrier, px^2.
    phase_error_periods : float
        Tolerated phase error, carrier periods.

    Notes
    -----
    A signal of up to the same amplitude behind a straight boundary enters with weight
    ``eps = Phi(-d / s_n)``; the phase then errs by at most ``asin(eps / (1 - eps))``.
    Solving ``eps / (1 - eps) = sin(2 pi tol)`` for ``d``:

    .. math:: d = s_n\\,\\Phi^{-1}\\!\\left(1 - \\frac{\\sin 2\\pi t}{1 + \\sin 2\\pi t}\\right).
    """
    s = float(np.sin(2 * np.pi * min(max(phase_error_periods, 0.0), 0.25)))
    if s <= 0:
        return float("inf")
    eps = s / (1.0 + s)
    sd = max(float(np.sqrt(np.max(np.linalg.eigvalsh(c)))) for c in np.asarray(blur_px2))
    return max(0.0, sd * float(ndtri(1.0 - eps)))


def local_frequency_deviation(phase: np.ndarray, carrier: F.Carrier, grid: F.SamplingGrid) -> np.ndarray:
    """``|grad phi| / (2 pi |f|)`` from a wrapped phase: the local frequency's relative offset from the carrier.

    Forward wrapped differences, averaged onto the samples; valid up to an offset of
    ``1 / (2 step |f|)`` (over 0.6 on the default grids).
    """
    sy, sx = grid.step
    gx = np.zeros(phase.shape, np.float32)
    gy = np.zeros(phase.shape, np.float32)
    dx = wrap(np.diff(phase, axis=1)) / sx
    dy = wrap(np.diff(phase, axis=0)) / sy
    gx[:, :-1] += dx
    gx[:, 1:] += dx
    gx[:, 1:-1] *= 0.5
    gy[:-1] += dy
    gy[1:] += dy
    gy[1:-1] *= 0.5
    return np.hypot(gx, gy) / (2 * np.pi * carrier.norm)


def _edge_distance(grid: F.SamplingGrid) -> tuple[np.ndarray, np.ndarray]:
    # Sample j sits at j*s + (s-1)/2 px; its distance to the edge is that plus 1/2 px.
    yv, xv = (np.arange(n) * st + st / 2.0 for n, st in zip(grid.shape, grid.step))
    H, W = grid.full_shape
    return np.minimum(yv, H - yv), np.minimum(xv, W - xv)


def erode(valid: np.ndarray, margin_px: float, grid: F.SamplingGrid, edge_margin_px: float | None = None) -> np.ndarray:
    """Samples farther than ``margin_px`` (image px) from every invalid sample, and than
    ``edge_margin_px`` (default ``margin_px``) from the image edges."""
    import cv2

    sy, sx = grid.step
    edge = margin_px if edge_margin_px is None else edge_margin_px
    dy, dx = _edge_distance(grid)
    out = valid.copy()
    ry, rx = int(margin_px / sy), int(margin_px / sx)
    if margin_px > 0 and (ry or rx):
        # Erosion by the disc of radius margin_px: a sample stays when no excluded sample lies
        # within margin_px of it. Samples excluded within margin_px of the image edge are the
        # edge's own (the periodic transform mixes the opposite edge in there): the edge margin
        # handles them, they are not eroded from.
        band = (dy <= margin_px)[:, None] | (dx <= margin_px)[None, :]
        j, i = np.mgrid[-ry : ry + 1, -rx : rx + 1]
        disc = ((j * sy) ** 2 + (i * sx) ** 2 <= margin_px**2).astype(np.uint8)
        seed = (valid | band).view(np.uint8)
        out &= cv2.erode(seed, disc, borderType=cv2.BORDER_CONSTANT, borderValue=1).view(bool)
    out &= (dy > edge)[:, None]
    out &= (dx > edge)[None, :]
    return out


def valid_region(
    phases, coherences, mods, carriers: F.CarrierPair, grid: F.SamplingGrid, p, user_mask, warn: list[str],
    *, margin_px: float, edge_margin_px: float, deviation_phases=None, beyond=None, contrast=None, cuts: bool = True,
) -> Region:
    """Labels of the demodulation grid from the modulation, coherence, local frequency, residues and the user mask.

    Parameters
    ----------
    phases : sequence of ndarray (h, w)
        Wrapped phases ``angle(z)`` of the F3-smoothed signals, rad.
    coherences, mods : sequences of ndarray (h, w)
        Phase coherence ``|G*z| / G*|z|`` per carrier; local modulations ``G*|b|`` (the
        image's first, then the reference's in the Comparative Method).
    p : AnalyzerParams
    user_mask : ndarray of bool (H, W) or None
    warn : list of str
        Warnings are appended here.
    margin_px, edge_margin_px : float
        Contamination margins at excluded areas and at the image edges, px.
    deviation_phases : sequence of ndarray (h, w), optional
        Wrapped phases whose local frequency the bandpass saw (F5's residual phases after
        image deformation); default ``phases``.
    beyond : ndarray of bool (h, w), optional
        Samples whose local frequency is beyond the bandpass's reach (F5: its gain there,
        read off the warped reference); labelled :data:`BEYOND_RANGE` with the local-frequency test's.
    contrast : callable returning ndarray (h, w), optional
        The photo's local contrast (:func:`local_contrast`, computed only when some carrier lost
        its modulation somewhere): an excluded sample where the photo
        keeps its contrast but its own carriers lost their modulation shows the grid at a
        frequency the bandpass does not pass (:data:`BEYOND_RANGE`), not an occlusion.
    cuts : bool
        Cut the region's charged holes (:func:`~glassdist.analyzer.unwrap.branch_cuts`); False
        where :func:`within` restricts the region first and cuts what is left.
    """
    period = max(carriers.k1.period_px, carriers.k2.period_px)
    dev_phases = phases if deviation_phases is None else deviation_phases
    modulated, half, fast, ok = _signal_tests(dev_phases, coherences, mods, carriers, grid, p, period)
    if beyond is not None:
        fast |= beyond
        ok &= ~beyond
    if contrast is not None:
        fast = fast | _grid_out_of_band(contrast, mods[:2], ok, p, period, grid)
    labels = _excluded_causes(ok, fast, period, grid)
    in_mask = np.ones(grid.shape, bool)
    if user_mask is not None:
        in_mask = downsample_mask(user_mask, grid)
    # The user mask excludes no phase: it is applied after the erosion (no margin around it).
    kept = _kept_beyond_margins(labels, ok, modulated, half, grid, margin_px, edge_margin_px)
    valid = _without_residues(list(phases) + ([] if deviation_phases is None else list(deviation_phases)), kept & in_mask,
                              labels, warn, unwrapped=phases if cuts else ())
    rule = _part_rule(p, grid, period)
    regions, n = _kept_parts(valid, list(phases), rule)
    labels[valid & (regions == 0)] = FRAGMENT
    labels[~in_mask] = USER_MASK
    return Region(regions > 0, regions, n, labels, rule)


def _signal_tests(phases, coherences, mods, carriers: F.CarrierPair, grid: F.SamplingGrid, p,
                  period: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The per-sample tests of the demodulated signals that decide where the phase is measured.

    Parameters
    ----------
    phases, coherences, mods, carriers, grid, p
        As for :func:`valid_region`.
    period : float
        The longer carrier period, px.

    Returns
    -------
    modulated : ndarray of bool (h, w)
        The grid is seen: every modulation clears its global and its local threshold.
    half : ndarray of bool (h, w)
        Some modulation is below half its local level (the dark side of an opaque edge).
    fast : ndarray of bool (h, w)
        Modulated, but the local grid frequency departs from a carrier beyond
        ``max_frequency_deviation``.
    ok : ndarray of bool (h, w)
        Measurable: modulated, coherent and not fast.
    """
    import cv2

    sy, sx = grid.step
    size = (max(3, int(4 * period / sy) | 1), max(3, int(4 * period / sx) | 1))
    box = np.ones(size, np.uint8)
    modulated = np.ones(grid.shape, bool)
    half = np.zeros(grid.shape, bool)
    for m in mods:
        ref = np.percentile(m[::2, ::2], 75)
        modulated &= m > p.modulation_threshold * ref
        # Against the local level (max over a few periods, smoothed): slow lighting changes pass,
        # a narrow opaque band (a frame or mullion blurred by the bandpass) does not.
        local = F.gaussian_blur(cv2.dilate(np.ascontiguousarray(m, np.float32), box, borderType=cv2.BORDER_REPLICATE),
                                (2 * period / sy, 2 * period / sx))
        modulated &= m > p.local_modulation_threshold * local
        # The blurred modulation of a step (an opaque edge) falls to half its level at the
        # edge itself and crosses the thresholds inside the dark side: the margin is taken
        # from the half-level line.
        half |= m < 0.5 * local
    coherent = np.ones(grid.shape, bool)
    for coh in coherences:
        coherent &= coh > p.coherence_threshold
    # Local frequency where the grid is seen: beyond the bandpass's reach the phase is
    # attenuated or wrong even where it stays coherent.
    dev = np.zeros(grid.shape, np.float32)
    for ph, c in zip(phases, (carriers.k1, carriers.k2)):
        dev = np.maximum(dev, local_frequency_deviation(ph, c, grid))
    fast = modulated & (dev > p.max_frequency_deviation)
    ok = modulated & coherent & ~fast
    return modulated, half, fast, ok


def local_contrast(image: np.ndarray, period_px: float, grid: F.SamplingGrid) -> np.ndarray:
    """RMS of the photo's detail finer than a carrier period, over a Gaussian window of half a period, on ``grid``.

    ``sqrt(G * (I - G * I)^2)`` with ``G`` of standard deviation ``period_px / 2``, on ``k x k``
    block means of the photo (``k = period_px // 4``: the grid keeps 4 px per period). Whatever the
    grid's local frequency, a seen grid keeps it; an opaque object, a blank or blurred patch
    does not (their edges do, over about a period).
    """
    import cv2

    img: np.ndarray = np.ascontiguousarray(image, np.float32)
    k = max(1, int(period_px // 4))  # block means keep the grid (at least 4 px per period) at 1/k^2 of the cost
    if k > 1:
        H, W = img.shape
        img = cv2.resize(img[: H // k * k, : W // k * k], (W // k, H // k), interpolation=cv2.INTER_AREA)
    s = 0.5 * period_px / k
    hp = img - F.gaussian_blur(img, (s, s))
    var = F.gaussian_blur(hp * hp, (s, s))
    h, w = grid.shape
    if var.shape != (h, w):
        var = cv2.resize(var, (w, h), interpolation=cv2.INTER_AREA)
    return np.sqrt(np.maximum(var, 0.0))


def _grid_out_of_band(contrast, mods, ok: np.ndarray, p, period: float, grid: F.SamplingGrid) -> np.ndarray:
    """Samples where the photo's own carriers lost their modulation but the photo kept half its typical detail.

    Within a period of a flat patch (a quarter of the typical detail or less: an occluder,
    blank or blurred) the detail is its edge's, not a grid's: not counted.
    """
    if not ok.any():
        return np.zeros(ok.shape, bool)
    weak = np.zeros(ok.shape, bool)
    for m in mods:
        weak |= m < p.modulation_threshold * np.percentile(m[::2, ::2], 75)
    if not weak.any():
        return weak
    return weak & grid_seen(contrast(), ok, period, grid)


def grid_seen(contrast: np.ndarray, ok: np.ndarray, period: float, grid: F.SamplingGrid) -> np.ndarray:
    """Samples where the photo shows a grid at whatever local frequency: half its typical detail or more.

    ``contrast`` from :func:`local_contrast`, the typical level its median over ``ok`` (the
    measured samples); within a period of a flat patch (a quarter of the typical detail or less:
    an occluder, blank or blurred) the detail is its edge's, not a grid's.
    """
    typical = float(np.median(contrast[ok]))
    flat = contrast < 0.25 * typical
    if flat.any():
        flat = ndimage.distance_transform_edt(~flat, sampling=grid.step) <= period
    return (contrast > 0.5 * typical) & ~flat


def _excluded_causes(ok: np.ndarray, fast: np.ndarray, period: float, grid: F.SamplingGrid) -> np.ndarray:
    """Quality labels (uint8): :data:`ANALYSED` where ``ok``, else the cause of the exclusion.

    Parameters
    ----------
    ok, fast : ndarray of bool (h, w)
        As returned by :func:`_signal_tests`.
    period : float
        The longer carrier period, px.
    grid : SamplingGrid
    """
    sy, sx = grid.step
    labels = np.full(grid.shape, ANALYSED, np.uint8)
    bad = ~ok
    if bad.any():
        # Cause of each excluded sample: "beyond range" where the grid is seen nearby with a
        # local frequency past the limit (its signal left the band), else low modulation.
        r = max(1, int(round(period / min(sy, sx))))
        near_fast = ndimage.binary_dilation(fast, iterations=r) if fast.any() else fast
        labels[bad] = np.where(near_fast[bad], BEYOND_RANGE, LOW_MODULATION)
    return labels


def _kept_beyond_margins(labels: np.ndarray, ok, modulated, half, grid: F.SamplingGrid, margin_px: float,
                         edge_margin_px: float) -> np.ndarray:
    """Measurable samples beyond the contamination margins of the excluded areas and the image edges.

    Parameters
    ----------
    labels : ndarray of uint8 (h, w)
        Quality labels; the margin samples take the cause of the nearest excluded sample and
        the edge samples :data:`IMAGE_EDGE` (in place).
    ok, modulated, half : ndarray of bool (h, w)
        As returned by :func:`_signal_tests`.
    grid : SamplingGrid
    margin_px, edge_margin_px : float
        As for :func:`valid_region`.

    Returns
    -------
    ndarray of bool (h, w)
    """
    # At the image edges a sample stays while part of its cell lies beyond the margin; the
    # pixels inside it are trimmed on the pixel grid (:func:`trim_edges`).
    # Excluded areas are located on the sample grid only (to half a step): that is added to
    # their margin.
    edge_s = max(edge_margin_px - 0.5 * max(grid.step), 0.0)
    # Half-level samples count as excluded only where they join an unmodulated sample (the
    # dark side of an edge), not as a stricter threshold of their own.
    dy, dx = _edge_distance(grid)
    at_edge = (dy <= edge_s)[:, None] | (dx <= edge_s)[None, :]
    dark = ~modulated & ~at_edge  # the image edge has its own margin
    edge_side = ~ok | (ndimage.binary_propagation(dark, mask=half | dark) if half.any() and dark.any() else dark)
    kept = erode(ok & ~edge_side, margin_px + 0.5 * max(grid.step), grid, edge_s)
    margin = ok & ~kept
    if margin.any():
        # Margin samples take the cause of the nearest excluded sample (the edge where that is nearer).
        idx = ndimage.distance_transform_edt(ok, sampling=grid.step, return_distances=False, return_indices=True)
        labels[margin] = labels[idx[0][margin], idx[1][margin]]
        if ok.all():
            labels[margin] = IMAGE_EDGE
    labels[at_edge] = IMAGE_EDGE
    return kept


def beyond_range_warning(quality: np.ndarray, p) -> str | None:
    """The warning of a region of which over 1% is :data:`BEYOND_RANGE`, stating every excluded share.

    Parameters
    ----------
    quality : ndarray of uint8 (H, W)
        The quality labels on the image's pixel grid (:func:`pixel_quality`, the result's
        ``quality``): the shares are those of the quality map's legend, one count of the
        same pixels.
    p : AnalyzerParams

    Returns
    -------
    str or None
        Shares are of the pixels inside the user's region (all pixels without a mask).
    """
    counts = {k: int(np.count_nonzero(quality == k)) for k in (*EXCLUDED, USER_MASK)}
    n = max(quality.size - counts[USER_MASK], 1)
    share = {k: counts[k] / n for k in EXCLUDED}
    if share[BEYOND_RANGE] <= 0.01:
        return None
    reach = p.deformation_max_deviation if p.deformation_passes > 0 else p.max_frequency_deviation
    others = ", ".join(f"{100 * share[k]:.1f}% {LABELS[k]}" for k in EXCLUDED if k != BEYOND_RANGE and share[k] > 0.0005)
    return (
        f"strong distortion: {100 * share[BEYOND_RANGE]:.1f}% of the region is beyond measurable distortion (the local "
        f"grid frequency departs from the carrier beyond the bandpass's reach, about {100 * reach:.0f}%; quality label "
        f"{BEYOND_RANGE}); {100 * sum(share.values()):.1f}% of the region is excluded in all"
        + (f" ({others})" if others else "") + "; use a finer grid or a shorter distance L"
    )


#: Excluded areas named one by one in :func:`excluded_area_warning`; the rest are counted.
_NAMED_AREAS = 4


def excluded_area_warning(labels: np.ndarray, user_mask, grid: F.SamplingGrid, period_px: float,
                          mm_per_px: float) -> str | None:
    """The warning naming every excluded area of :data:`MIN_REGION_PERIODS` squared carrier periods or more.

    An excluded area is a connected (8-neighbour) set of samples labelled occluded / low
    modulation, beyond measurable distortion, phase residue or fragment inside the user's
    region; the image edge's margin is expected and not named. Each area large enough to hold
    the smallest part analysed alone (:func:`min_region_samples`) is named, largest first: its
    area and extent in carrier periods and in mm, its centre in image pixels, and its labels'
    shares. A small lens whose rim or whole aperture cannot be measured is then said, however
    small a share of the view it is.

    Parameters
    ----------
    labels : ndarray of uint8 (h, w)
        Final quality labels of the demodulation grid (before the guard band).
    user_mask : ndarray of bool (H, W) or None
    grid : SamplingGrid
    period_px : float
        The longer carrier period, px.
    mm_per_px : float
        Scale on the backdrop (mm per image px).

    Returns
    -------
    str or None
    """
    in_mask = np.ones(grid.shape, bool) if user_mask is None else downsample_mask(user_mask, grid)
    causes = (LOW_MODULATION, BEYOND_RANGE, PHASE_RESIDUE, FRAGMENT)
    excluded = np.isin(labels, causes) & in_mask
    if not excluded.any():
        return None
    sy, sx = grid.step
    parts, n = ndimage.label(excluded, structure=np.ones((3, 3), bool))
    sizes = np.bincount(parts.ravel(), minlength=n + 1)[1:]
    need = (MIN_REGION_PERIODS * period_px) ** 2 / (sy * sx)
    big = [k for k in np.argsort(sizes)[::-1] if sizes[k] >= need]
    if not big:
        return None
    boxes = ndimage.find_objects(parts)
    named = []
    for k in big[:_NAMED_AREAS]:
        box = boxes[k]
        part = parts[box] == k + 1
        rows, cols = np.nonzero(part)
        ext_y, ext_x = (box[0].stop - box[0].start) * sy, (box[1].stop - box[1].start) * sx  # px
        cy, cx = (box[0].start + rows.mean() + 0.5) * sy, (box[1].start + cols.mean() + 0.5) * sx
        lab = labels[box][part]
        share = {c: 100 * np.count_nonzero(lab == c) / lab.size for c in causes if np.any(lab == c)}
        shares = ", ".join(f"{LABELS[c]} (label {c}) {f'{v:.0f}' if v >= 0.5 else '<1'}%" for c, v in share.items())
        named.append(
            f"{sizes[k] * sy * sx / period_px**2:.1f} square periods ({ext_x / period_px:.1f} x {ext_y / period_px:.1f} "
            f"periods, {ext_x * mm_per_px:.0f} x {ext_y * mm_per_px:.0f} mm) around x {cx:.0f}, y {cy:.0f} px: {shares}"
        )
    more = len(big) - len(named)
    return (
        f"{len(big)} area{'s' if len(big) > 1 else ''} of {MIN_REGION_PERIODS:g} x {MIN_REGION_PERIODS:g} carrier "
        f"periods or more {'are' if len(big) > 1 else 'is'} excluded from the analysis (no displacement or power is "
        "reported there): " + "; ".join(named) + (f"; and {more} more" if more else "")
        + "; check the quality map (quality.png) for what the glass does there"
    )


def _without_residues(phases, valid: np.ndarray, labels: np.ndarray, warn: list[str], unwrapped=None) -> np.ndarray:
    """``valid`` less the samples next to a phase residue of either wrapped phase, and the branch cuts.

    Parameters
    ----------
    phases : sequence of ndarray (h, w)
        Wrapped phases, rad.
    valid : ndarray of bool (h, w)
        The region so far (updated in place).
    labels : ndarray of uint8 (h, w)
        Quality labels; the removed samples become :data:`PHASE_RESIDUE` (in place).
    warn : list of str
        Receives a warning when over 1% of the region is removed.
    unwrapped : sequence of ndarray (h, w), optional
        The phases F4 unwraps (default ``phases``; none: no cuts): no hole of the region may hold a
        net residue of theirs (:func:`~glassdist.analyzer.unwrap.branch_cuts`, the cut samples also
        labelled :data:`PHASE_RESIDUE`).

    Returns
    -------
    ndarray of bool (h, w)
    """
    n0 = max(int(valid.sum()), 1)
    res = np.zeros(valid.shape, bool)
    for ph in phases:
        res |= residues(ph)
    if res.any():
        res = ndimage.binary_dilation(res, iterations=1)
        labels[res & valid] = PHASE_RESIDUE
        valid &= ~res
    cut = branch_cuts(phases if unwrapped is None else unwrapped, valid)
    labels[cut] = PHASE_RESIDUE
    valid &= ~cut
    frac = 1.0 - float(valid.sum()) / n0
    if frac > 0.01:
        warn.append(f"{100 * frac:.1f}% of the region has phase residues (noise, occlusion or too strong distortion) "
                    "and was excluded")
    return valid


def within(region: Region, first: Region, p, phases=()) -> Region:
    """``region`` restricted to ``first``'s measured samples (F5's region, within the region its predictor was measured on).

    F5 measures the residual against a reference warped by its prediction; the prediction is
    measured on the one-pass region and on the samples F5 grew it into, a period at a time
    (:func:`~glassdist.analyzer.deform.grow`). Elsewhere (beyond reach, a gap the growth did
    not close) the predictor is a guess whose whole periods nothing can check, so those samples
    stay excluded, with ``first``'s label (the one pass's). The holes of what is left that the
    wrapped ``phases`` (those F4 unwraps) wind around are cut
    (:func:`~glassdist.analyzer.unwrap.branch_cuts`, :data:`PHASE_RESIDUE`), and connected parts
    are labelled anew (:func:`~glassdist.analyzer.unwrap.label_regions`).
    """
    if region.quality is None or first.quality is None:
        raise ValueError("within() needs the quality labels of both regions (Region.quality)")
    valid = region.valid & first.valid
    quality = region.quality.copy()
    dropped = region.valid & ~first.valid
    quality[dropped] = first.quality[dropped]
    if len(phases):
        cut = branch_cuts(phases, valid)
        quality[cut] = PHASE_RESIDUE
        valid &= ~cut
    rule = region.parts or first.parts
    if rule is None:
        regions, n = label_regions(valid, max(int(p.min_region_fraction * valid.size), 16))
    else:
        regions, n = _kept_parts(valid, list(phases), rule)
    quality[valid & (regions == 0)] = FRAGMENT
    return Region(regions > 0, regions, n, quality, rule)


def guard_band(labels: np.ndarray, grid: F.SamplingGrid, guard_px: float) -> np.ndarray:
    """``labels`` with analysed samples within ``guard_px`` (image px) of an excluded sample or the image edge set to 6."""
    out = labels.copy()
    if guard_px <= 0:
        return out
    excluded = np.isin(labels, EXCLUDED)
    dy, dx = _edge_distance(grid)
    near = (dy <= guard_px)[:, None] | (dx <= guard_px)[None, :]
    if excluded.any():
        near |= ndimage.distance_transform_edt(~excluded, sampling=grid.step) <= guard_px
    out[near & (labels == ANALYSED)] = GUARD_BAND
    return out


def _edge_pixels(shape, edge_px: float) -> np.ndarray:
    """Pixels whose centre lies within ``edge_px`` of the image edge."""
    H, W = shape
    y = np.arange(H) + 0.5
    x = np.arange(W) + 0.5
    return (np.minimum(y, H - y) <= edge_px)[:, None] | (np.minimum(x, W - x) <= edge_px)[None, :]


def trim_edges(valid: np.ndarray, edge_px: float) -> np.ndarray:
    """``valid`` (H, W) without the pixels within the image-edge margin (in place; returned)."""
    e = int(np.floor(edge_px - 0.5)) + 1 if edge_px >= 0.5 else 0
    if e > 0:
        valid[:e] = False
        valid[-e:] = False
        valid[:, :e] = False
        valid[:, -e:] = False
    return valid


def trusted_on(quality: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Trusted samples (label 0 throughout each block) of ``quality`` on a grid of ``shape`` (a block grid of it)."""
    t = quality == ANALYSED
    h, w = shape
    if t.shape != (h, w):
        my, mx = t.shape[0] // h, t.shape[1] // w
        t = t[: h * my, : w * mx].reshape(h, my, w, mx).all(axis=(1, 3))
    return t


def pixel_quality(quality: np.ndarray, grid: F.SamplingGrid, valid: np.ndarray, user_mask=None,
                  edge_px: float = 0.0) -> np.ndarray:
    """The quality labels on the image's pixel grid, consistent with the reported region ``valid``.

    Nearest-sample upsampling; unreported pixels within ``edge_px`` of the image edge are
    image edge, pixels the reported region trims elsewhere (partial blocks next to an excluded
    area, non-finite values) take the label of the nearest excluded sample, the cause of the
    trim (low modulation where none is), pixels it adds
    (its border ring) guard band, and pixels outside the user mask user mask.
    """
    from .resample import upsample_labels

    q = upsample_labels(quality, grid)
    reported = (q == ANALYSED) | (q == GUARD_BAND)
    trimmed = ~valid & reported
    excluded = np.isin(quality, EXCLUDED)
    if trimmed.any() and excluded.any():
        iy, ix = ndimage.distance_transform_edt(~excluded, return_distances=False, return_indices=True)
        q[trimmed] = upsample_labels(quality[iy, ix], grid)[trimmed]
    else:
        q[trimmed] = LOW_MODULATION
    if edge_px > 0:
        q[~valid & _edge_pixels(q.shape, edge_px)] = IMAGE_EDGE
    q[valid & ~reported] = GUARD_BAND
    if user_mask is not None:
        q[~np.asarray(user_mask, bool)] = USER_MASK
    return q


def downsample_mask(mask: np.ndarray, grid: F.SamplingGrid) -> np.ndarray:
    """A pixel mask on the sampling grid ``grid``: True where the whole sample's area is (area average > 0.999)."""
    import cv2

    if grid.is_full:
        return mask.astype(bool)
    h, w = grid.shape
    return cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.999
