"""Block F for one photo (paper §2.2, F1-F4): the photo checked, its carriers, the heterodyne, F3 and the valid region.

The Comparative Method demodulates the photo against the analytic signal of a glass-less
reference (:class:`ReferenceModel`, derived once per reference); the Direct Method against
a synthetic flat carrier found in the photo itself. The result is a frozen
:class:`Demodulation` record on the demodulation grid; F4's valid region
(:func:`region`) and unwrapped phases (:func:`unwrapped_phases`) follow from it. Each
stage returns the warnings it raises with its value; nothing is appended to a caller's list.

References
----------
Paper §2.2 (F1-F4); Takeda, Ina & Kobayashi (1982); Herraez et al. (2002).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Callable, cast

import numpy as np

from ..errors import AnalysisError, InputError
from . import fourier as F
from .homography import HomographyFit
from .params import AnalyzerParams, load_params
from .region import Region, contamination_px, local_contrast, valid_region, within
from .uncertainty import noise_std
from .unwrap import unwrap

__all__ = [
    "DEVIATION_WARN", "Demodulation", "LocalContrast", "Margins", "ReferenceModel", "bandpass_px2", "basebands",
    "carrier_period_mm", "checked_image", "covariances", "demodulate", "demodulation_blur_px2", "deviation_warnings",
    "frequency_deviation", "margins", "modulation", "read_inputs", "region", "region_warnings", "sampling_warnings",
    "smooth_with_coherence", "unwrapped_phases",
]


@dataclass(frozen=True)
class ReferenceModel:
    """State derived once from a glass-less reference photo and reused for every frame.

    Holds its spectrum-derived carriers, baseband signals and the homography of its
    (undistorted) grid, so each distorted frame then costs one FFT.
    """

    shape: tuple[int, int]
    carriers: F.CarrierPair
    covariances: tuple[np.ndarray, np.ndarray]
    grid: F.SamplingGrid
    baseband: tuple[np.ndarray, ...]
    modulation: tuple[np.ndarray, ...]
    homography: HomographyFit
    params: AnalyzerParams = field(repr=False)
    warnings: tuple[str, ...] = ()
    noise_std: float = float("nan")
    grid_spread: float = float("nan")  # glassdist.analyzer.plausibility.grid_spread: the swapped-pair check


@dataclass(frozen=True)
class Demodulation:
    """F1-F3: carriers, the F3-smoothed heterodyned signals, their coherence and the modulations.

    ``mods`` holds G*|b| of the distorted photo's two carriers, then (Comparative) the reference's.
    ``spectrum``: the photo's full spectrum, kept for F5 (its basebands on a finer grid) and
    dropped once F5 has read it (None after F5, and on F5's own demodulation).
    """

    method: str
    carriers: F.CarrierPair
    covariances: tuple[np.ndarray, np.ndarray]
    grid: F.SamplingGrid
    signals: tuple[np.ndarray, ...]
    coherences: tuple[np.ndarray, ...]
    mods: tuple[np.ndarray, ...]
    noise_std: float = float("nan")
    passes: int = 1  # demodulations the phase sums (F5's iterative deformation; 1: one pass)
    photo_passes: int = 0  # F5's photo passes after those, from their field low-passed by restart_sigma_px
    restart_sigma_px: float = 0.0
    spectrum: F.Spectrum | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class Margins:
    """Contamination margins (px): at excluded areas (``border_px``) and at the image edges (``edge_px``)."""

    border_px: float
    edge_px: float

    def as_tuple(self) -> tuple[float, float]:
        """``(border_px, edge_px)``, as the result states them."""
        return (self.border_px, self.edge_px)


# --------------------------------------------------------------------------- the photo


def checked_image(img: np.ndarray, what: str) -> tuple[np.ndarray, tuple[str, ...]]:
    """The photo as float32 and its exposure warnings; an :class:`InputError` for what cannot be analysed.

    Raises on a non-2-D array, under 32 x 32 px, NaN or infinite values, no contrast, and
    over 70 % of the pixels saturated or black; warns over 2 % saturated and below an
    intensity range of 0.08.
    """
    a = np.asarray(img)
    if a.ndim != 2:
        raise InputError(f"the {what} must be a 2-D grey image, got an array of shape {a.shape}")
    a = a.astype(np.float32, copy=False)
    if min(a.shape) < 32:
        raise InputError(f"the {what} is only {a.shape[1]}x{a.shape[0]} px; at least 32x32 px are needed")
    lo, hi = float(a.min()), float(a.max())  # also NaN-detecting: NaN propagates through min/max
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise InputError(f"the {what} contains NaN or infinite values")
    # Exposure statistics need no more than a regular subsample of a large photo.
    k = max(1, int(np.sqrt(a.size / 2_000_000)))
    a_s = a[::k, ::k]
    if hi - lo < 1e-3 or float(a_s.std()) < 2e-3:
        raise InputError(f"the {what} is blank (no contrast); check the exposure and that the grid is in view")
    sat = float(np.mean(a_s >= 0.999 * max(hi, 1e-12))) if hi >= 0.98 else 0.0
    dark = float(np.mean(a_s <= 1e-3))
    if sat > 0.7 or dark > 0.7:
        raise InputError(
            f"the {what} is {'saturated' if sat > 0.7 else 'black'} over {100 * max(sat, dark):.0f}% of its pixels; "
            "re-expose the photo so the grid lines and the background are both visible"
        )
    warn: list[str] = []
    if sat > 0.02:
        warn.append(f"{what}: {100 * sat:.1f}% of pixels are saturated; phase near them is less reliable")
    if hi - lo < 0.08:
        warn.append(f"{what}: low contrast (intensity range {hi - lo:.3f}); expect a noisier result")
    return a, tuple(warn)


def carrier_period_mm(pitch_mm: float, pattern: str) -> float:
    """The carrier period on the backdrop, mm: the pitch (line grid, dot lattice), or ``pitch * sqrt(2)`` for a checkerboard.

    Checkerboard fundamentals are the diagonal products of the two square waves. The checkerboard's is a
    ``numpy.float64``, and float32 phases scaled by it are computed in float64 (NumPy's promotion rules).
    """
    return pitch_mm * np.sqrt(2.0) if pattern == "checkerboard" else pitch_mm


def read_inputs(image: Any, reference: Any, params: Any, mask: Any, detrend_degree: int | None,
                sigma_mm: float | None) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
    """Photos and mask given as paths read; ``detrend_degree`` / ``sigma_mm`` merged into the parameters.

    Also returns the files read (:attr:`~glassdist.analyzer.result.AnalysisResult.sources`): each
    path with the SHA-256 of the bytes decoded, and the photo's EXIF camera. What
    :func:`~glassdist.analyzer.pipeline.analyze` reads before its inputs are checked
    (:func:`~glassdist.analyzer.pipeline.checked_inputs`).
    """
    from ..io import read_sources

    image, reference, mask, sources = read_sources(image, reference, mask)
    settings = {k: v for k, v in (("detrend_degree", detrend_degree), ("sigma_mm", sigma_mm)) if v is not None}
    if settings:
        if params is None and isinstance(reference, ReferenceModel):
            params = reference.params
        if isinstance(params, AnalyzerParams):
            params = {**params.model_dump(exclude_unset=True), **settings}
        else:
            params = load_params(params, **settings)
    return image, reference, params, mask, sources


# --------------------------------------------------------------------------- Block F's filters


def covariances(carriers: F.CarrierPair, p: AnalyzerParams) -> tuple[np.ndarray, np.ndarray]:
    """F2: the frequency covariance (cycles/px)^2 of each carrier's Gaussian bandpass."""
    along, cross, iso = p.bandpass_sigma_along, p.bandpass_sigma_cross, p.isotropic_bandpass
    return (
        F.bandpass_covariance(carriers.k1, carriers.k2, sigma_along=along, sigma_cross=cross, isotropic=iso),
        F.bandpass_covariance(carriers.k2, carriers.k1, sigma_along=along, sigma_cross=cross, isotropic=iso),
    )


def bandpass_px2(covs: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Spatial covariance (px^2) of each carrier's Gaussian bandpass of frequency covariance ``cov``: ``cov^-1 / (4 pi^2)``."""
    return np.array([np.linalg.inv(cov) / (4 * np.pi**2) for cov in covs])


def demodulation_blur_px2(carriers: F.CarrierPair, covs: tuple[np.ndarray, np.ndarray], p: AnalyzerParams) -> np.ndarray:
    """Spatial covariance (px^2) of the low-pass Block F applies to each phase map: the bandpass, then the complex smoothing."""
    s3 = [p.smoothing_periods * c.period_px for c in (carriers.k1, carriers.k2)]
    return bandpass_px2(covs) + np.array([s**2 * np.eye(2) for s in s3])


_EDGE_PERIODS = 0.5
_DIRECT_EDGE_PERIODS = 0.75


def margins(carriers: F.CarrierPair, covs: tuple[np.ndarray, np.ndarray], p: AnalyzerParams, direct: bool) -> Margins:
    """Contamination margins (px) at excluded areas and at the image edges.

    Given in carrier periods by ``border_periods``/``edge_margin_periods``, else derived
    from Block F's kernel for ``margin_phase_error_periods``
    (:func:`~glassdist.analyzer.region.contamination_px`). At the image edges the derived
    margin has a floor (0.5 carrier period, 0.75 in the Direct Method): the wrap-around of
    the periodic FFT is an unrelated signal of full amplitude that the reference cancels
    only where both photos see the same pattern there (not after a camera move, not where
    the glass distorts the edge), and edge samples enter the A2 fit of the whole region.
    """
    period = max(carriers.k1.period_px, carriers.k2.period_px)
    derived = contamination_px(demodulation_blur_px2(carriers, covs, p), p.margin_phase_error_periods)
    derived_edge = max(derived, (_DIRECT_EDGE_PERIODS if direct else _EDGE_PERIODS) * period)
    border = derived if p.border_periods is None else p.border_periods * period
    edge = derived_edge if p.edge_margin_periods is None else p.edge_margin_periods * period
    return Margins(float(border), float(edge))


def basebands(spec: F.Spectrum, carriers: F.CarrierPair, covs: tuple[np.ndarray, np.ndarray],
              grid: F.SamplingGrid) -> tuple[np.ndarray, ...]:
    """F2: each carrier's bandpassed, heterodyned signal on ``grid`` (complex64)."""
    return tuple(cast(np.ndarray, F.baseband(spec, c, cov, grid)) for c, cov in zip((carriers.k1, carriers.k2), covs))


def modulation(b: np.ndarray, period_px: float, grid: F.SamplingGrid, p: AnalyzerParams) -> np.ndarray:
    """Local modulation G*|b| (same kernel as F3)."""
    sy, sx = grid.step
    s = p.smoothing_periods * period_px
    return F.gaussian_blur(np.abs(b), (s / sy, s / sx), truncate=3.5)


def smooth_with_coherence(zs: tuple[np.ndarray, ...] | list[np.ndarray], ks: tuple[F.Carrier, F.Carrier],
                          grid: F.SamplingGrid, p: AnalyzerParams,
                          smoothed_abs: tuple[np.ndarray, ...] | None = None,
                          ) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """F3 smoothing of each complex signal and its phase coherence |G*z| / G*|z| in [0, 1].

    ``smoothed_abs``: the G*|z| maps when already known (Direct Method: the modulation).
    """
    out, coh = [], []
    for i, (z, c) in enumerate(zip(zs, ks)):
        s = p.smoothing_periods * c.period_px
        zs_ = F.smooth_complex(z, s, grid)
        a = smoothed_abs[i] if smoothed_abs is not None else modulation(z, c.period_px, grid, p)
        out.append(zs_)
        coh.append(np.abs(zs_) / np.maximum(a, 1e-30))
    return tuple(out), tuple(coh)


# Relative local-frequency deviation above which results degrade (ray-traced roller waves:
# right at 0.31, wrong from 0.41; docs/accuracy.md).
DEVIATION_WARN = 0.35


def frequency_deviation(phases: np.ndarray, valid: np.ndarray, carriers: tuple[F.Carrier, F.Carrier],
                        step: tuple[float, float]) -> float:
    """99th percentile over ``valid`` of |grad phi_i| / (2 pi |f_i|), the larger of the two carriers.

    The distortion phase's gradient is the local shift of the grid frequency; the
    bandpass passes a limited band around the carrier, so large shifts are attenuated
    (and beyond it the unwrap and the homography fail).
    """
    if valid.sum() < 16:
        return 0.0
    out = 0.0
    for i, c in enumerate(carriers):
        gy, gx = np.gradient(phases[..., i], step[0], step[1])
        g = np.hypot(gx, gy)[valid]
        g = g[np.isfinite(g)]
        if g.size:
            out = max(out, float(np.percentile(g, 99)) / (2 * np.pi * c.norm))
    return out


def deviation_warnings(phases: np.ndarray, valid: np.ndarray, step: tuple[float, float], ks: tuple[F.Carrier, F.Carrier],
                       method: str, p: AnalyzerParams, prior: Sequence[str]) -> tuple[str, ...]:
    """A strong-distortion warning when the local grid frequency departs far from the carrier (unless one was given)."""
    deviation = frequency_deviation(phases, valid, ks, step)
    limit = p.deformation_max_deviation if p.deformation_passes > 0 else DEVIATION_WARN
    if deviation > limit and not any(w.startswith("strong distortion") for w in prior):
        advice = "use a finer grid or a shorter distance L" + (" or the Comparative Method" if method == "direct" else "")
        return (
            f"strong distortion: the local grid frequency departs from the carrier by up to {100 * deviation:.0f}% "
            f"(results were reliable up to about {100 * limit:.0f}% in tests); the result may be attenuated or wrong - "
            f"{advice}",
        )
    return ()


# --------------------------------------------------------------------------- F1-F3


def demodulate(img: np.ndarray, refm: ReferenceModel | None, p: AnalyzerParams) -> Demodulation:
    """F1-F3: one FFT of the photo, the carriers (its own, or the reference's), heterodyne, F3.

    The photo's spectrum goes with the record (``spectrum``) for F5, which needs its basebands
    on another grid: the photo is transformed once per analysis. In the Comparative Method the
    photo's own carriers are not searched: the reference's are used, and a photo that shows
    no grid leaves no region (:func:`region_warnings`).
    """
    spec = F.compute_spectrum(img)
    if refm is None:
        carriers = F.find_carriers(spec, min_period_px=p.min_period_px, image=img)
        F.check_image_size(img.shape, max(carriers.k1.period_px, carriers.k2.period_px))
        covs = covariances(carriers, p)
        grid = F.sampling_grid(img.shape, list(covs), p.decimation)
    else:
        carriers, covs, grid = refm.carriers, refm.covariances, refm.grid
    ks = (carriers.k1, carriers.k2)
    noise = noise_std(spec, carriers)
    if refm is None:
        # Direct: F3 applied in the spectral patch; coherence against the modulation G*|b|.
        pairs = [cast("tuple[np.ndarray, np.ndarray]",
                      F.baseband(spec, c, cov, grid, smooth_sigma_px=p.smoothing_periods * c.period_px))
                 for c, cov in zip(ks, covs)]
        mods = tuple(modulation(b, c.period_px, grid, p) for (b, _), c in zip(pairs, ks))
        zs = tuple(gb for _, gb in pairs)
        cohs = tuple(np.abs(z) / np.maximum(m_, 1e-30) for z, m_ in zip(zs, mods))
        return Demodulation("direct", carriers, covs, grid, zs, cohs, mods, noise, spectrum=spec)
    bb = basebands(spec, carriers, covs, grid)
    mods = tuple(modulation(b, c.period_px, grid, p) for b, c in zip(bb, ks)) + tuple(refm.modulation)
    zs = tuple(b * np.conj(r) for b, r in zip(bb, refm.baseband))
    zs, cohs = smooth_with_coherence(zs, ks, grid, p)  # F3
    return Demodulation("comparative", carriers, covs, grid, zs, cohs, mods, noise, spectrum=spec)


def sampling_warnings(carriers: F.CarrierPair) -> tuple[str, ...]:
    """A carrier period under 3.5 px may be the alias of a grid finer than 2 px per period.

    A grid of frequency f > 0.5 cycles/px shows at 1 - f; for 1 - f < 1/3 (the carrier band)
    that is a period of 3 to 3.5 px for true periods of 1.4 to 1.5 px, read at the wrong scale.
    """
    short = min(carriers.k1.period_px, carriers.k2.period_px)
    if short < 3.5:
        return (
            f"the grid's carrier period is only {short:.2f} px, near the sampling limit: a grid finer than 2 px per "
            "period would show at this period and give a wrong mm_per_px; check the scale, or photograph the grid larger",
        )
    return ()


# --------------------------------------------------------------------------- F4


def region(demod: Demodulation, p: AnalyzerParams, mask: np.ndarray | None, margins: Margins,
           residual: list[np.ndarray] | None = None, mods: list[np.ndarray] | None = None,
           beyond: np.ndarray | None = None, contrast: Callable[[], np.ndarray] | None = None,
           first: Region | None = None) -> tuple[Region, tuple[str, ...]]:
    """F4's valid region of a demodulation, and the warnings its labelling raised.

    After F5: ``residual`` (its residual phases, for the local-frequency test), ``mods`` (the
    modulations over the bandpass's gain at the local frequency), ``beyond`` (where that
    gain is out of reach) and ``first``, the region its predictor was measured on: the region is
    restricted to it and its branch cuts drawn on what is left
    (:func:`~glassdist.analyzer.region.within`). ``contrast``: the photo's local contrast, for the
    cause of an exclusion.
    """
    wrapped = [np.angle(z) for z in demod.signals]
    warn: list[str] = []
    out = valid_region(wrapped, demod.coherences, demod.mods if mods is None else mods, demod.carriers, demod.grid,
                       p, mask, warn, margin_px=margins.border_px, edge_margin_px=margins.edge_px,
                       deviation_phases=residual, beyond=beyond, contrast=contrast, cuts=first is None)
    return (out if first is None else within(out, first, p, wrapped)), tuple(warn)


def region_warnings(region: Region, mods: tuple[np.ndarray, ...]) -> tuple[str, ...]:
    """No analysable region is an error (:class:`AnalysisError`); a faint grid a warning."""
    if region.n == 0:
        raise AnalysisError(
            "no region of the photo carries a reliable grid signal; check focus, exposure and that the grid fills the view"
        )
    # Grid modulation: amplitude of the fundamental (|b| is half of it), intensity units.
    amp = 2.0 * min(float(np.median(m_[region.valid])) for m_ in mods[:2])
    if amp < 0.03:
        return (f"low grid contrast (carrier amplitude {amp:.3f} of full scale); expect a noisier result",)
    return ()


def unwrapped_phases(demod: Demodulation, region: Region, p: AnalyzerParams) -> np.ndarray:
    """F4: the wrapped phases of the F3 signals unwrapped per region, (h, w, 2) float32 rad."""
    psi = [unwrap(np.angle(z), region.valid, region.labels, region.n, seed=p.ransac_seed) for z in demod.signals]
    return np.stack(psi, axis=-1).astype(np.float32)


class LocalContrast:
    """The photo's local contrast (:func:`~glassdist.analyzer.region.local_contrast`), computed once per grid, on demand.

    Only an exclusion's cause needs it, so it is computed only when asked for.
    """

    def __init__(self, image: np.ndarray, period_px: float) -> None:
        self._image, self._period_px = image, period_px
        self._held: dict[tuple[int, int], np.ndarray] = {}

    def __call__(self, grid: F.SamplingGrid) -> np.ndarray:
        """The contrast on ``grid`` (computed on the first call for its shape)."""
        if grid.shape not in self._held:
            self._held[grid.shape] = local_contrast(self._image, self._period_px, grid)
        return self._held[grid.shape]
