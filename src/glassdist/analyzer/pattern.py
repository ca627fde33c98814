"""Which backdrop a photo shows, a crossed line grid, a checkerboard or a dot lattice, told from its spectrum's harmonics.

The two carriers ``k1``, ``k2`` (F1) are found the same way for both backdrops, but they
mean different lengths: the line spacing for a line grid, the square's diagonal
(pitch·√2) for a checkerboard, so a wrong pattern scales every length in mm by √2
(φ, a ratio of lengths, is unchanged). The harmonics tell them apart:

* a **line grid** is a product of two periodic line profiles, ``t1(k1·x)·t2(k2·x)``: each
  profile's harmonics ``n·k1``, ``n·k2`` sit *along each carrier* (thin lines: the second
  harmonic nearly as strong as the fundamental);
* a **checkerboard** of squares of side p is ``s(x/p)·s(y/p)`` with ``s`` a square wave:
  odd harmonics only, so its spectrum holds frequencies ``(m, n)/(2p)`` with m and n
  *both odd*. Its carriers are the diagonal fundamentals ``k1, k2 = (1, ±1)/(2p)``; a
  frequency ``a·k1 + b·k2`` is ``(a + b, a - b)/(2p)``, so only ``a + b`` odd occurs: the
  mixed terms ``2k1 ± k2``, ``k1 ± 2k2`` (amplitude 1/3 of the fundamental), never
  ``2k1``, ``2k2``, and ``3k1`` only as ``(3, 3)/(2p)``, at 1/9;
* a **dot lattice** of spacing p is one dot profile ``d`` repeated on the square lattice: its
  spectrum holds every ``(m, n)/p`` with the weight ``D(|(m, n)|/p)`` of the dot's (isotropic)
  transform, so the diagonal sums ``k1 ± k2`` (at √2/p) are nearly as strong as the
  fundamentals and stronger than ``2k1`` (at 2/p). The carriers are ``(1, 0)/p`` and
  ``(0, 1)/p``, of period p as for a line grid: the two read the same lengths in mm. In a line
  grid ``k1 ± k2`` comes only from the crossings (the product of the two line profiles' first
  harmonics), weak for thin lines.

:func:`detect_pattern` measures, on a centred square crop (Hann window, one FFT), the
background-corrected spectral energy around ``a·k1 + b·k2`` relative to the fundamentals:
``along`` the largest of ``2k1, 2k2, 3k1, 3k2``, ``mixed`` the largest of ``2k1 ± k2,
k1 ± 2k2``, ``diagonal`` the larger of ``k1 ± k2``. ``diagonal`` above :data:`DOTS_DIAGONAL`
and at least ``along`` reads a dot lattice; else ``along / mixed`` above
:data:`DECISIVE_RATIO` reads a line grid, below its inverse a checkerboard; in between, or
with neither above the noise (a sinusoidal grid, harmonics beyond Nyquist), the spectrum does not tell (``pattern`` None).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from . import fourier as F

if TYPE_CHECKING:
    from .params import AnalyzerParams

__all__ = ["PatternEvidence", "SettledPattern", "detect_pattern", "settle_pattern", "DECISIVE_RATIO", "DOTS_DIAGONAL"]

#: ``along / mixed`` energy ratio (or its inverse) from which the spectrum decides the pattern.
#: Measured: line grids 10-15, checkerboards 0.02-0.06 (synthetic, the bundled photos), up to 0.27
#: on a 400 px crop of a bundled photo.
DECISIVE_RATIO = 3.0

#: Energy of the diagonal sums ``k1 ± k2``, relative to the fundamentals, from which (and at least
#: as strong as the harmonics along the carriers) the spectrum reads a dot lattice. Measured
#: (synthetic, 256 x 320 px): sharp dots of diameter 0.2-0.6 pitch 0.25-0.85, Gaussian dots of FWHM
#: 0.1-0.35 pitch 0.42-0.99; line grids of line width (FWHM) 0.1-0.35 pitch 0.01-0.15; checkerboards 0.
DOTS_DIAGONAL = 0.2

#: Energy above the background, in standard deviations of the background's own sum, that a
#: harmonic needs to count as present ...
_SIGNIFICANCE = 5.0
#: ... and at least this share of the fundamentals' energy (-33 dB: below it, quantisation
#: and compression residue, not the backdrop).
_FLOOR = 5e-4

_ALONG = ((2, 0), (0, 2), (3, 0), (0, 3))
_MIXED = ((2, 1), (2, -1), (1, 2), (1, -2))
_DIAGONAL = ((1, 1), (1, -1))


@dataclass(frozen=True)
class PatternEvidence:
    """What the spectrum says about the backdrop (:func:`detect_pattern`).

    Attributes
    ----------
    pattern : {'lines', 'checkerboard', 'dots'} or None
        None when the harmonics do not decide.
    along, mixed, diagonal : float
        Energy of the strongest harmonic along a carrier (``2k``, ``3k``) and of the
        strongest mixed odd term (``2k1 ± k2``, ``k1 ± 2k2``) and of the stronger diagonal sum
        (``k1 ± k2``), each relative to the mean
        energy of the fundamentals (0 where not above the noise).
    noise : float
        The energy a harmonic needs to count as present, same units: five standard
        deviations of the background's sum over its disk, and at least 5e-4 (-33 dB).
    """

    pattern: str | None
    along: float
    mixed: float
    noise: float
    diagonal: float = 0.0

    def describe(self) -> str:
        """One phrase for messages: what the harmonics show."""
        shown = {"lines": "harmonics along each carrier",
                 "checkerboard": "harmonics only at odd mixed combinations of the carriers",
                 "dots": "strong harmonics at the sums of the carriers"}
        what = shown.get(self.pattern or "", "no decisive harmonics")
        return (f"{what}, energy along/mixed/diagonal {self.along:.3g}/{self.mixed:.3g}/{self.diagonal:.3g} "
                "of the fundamentals")

    def to_dict(self) -> dict[str, object]:
        """The evidence as a JSON-ready mapping."""
        return {"pattern": self.pattern, "along": self.along, "mixed": self.mixed, "diagonal": self.diagonal,
                "noise": self.noise}


def _energy(spectrum: F.Spectrum, f: np.ndarray, radius: float, background: float) -> tuple[float, float]:
    """Power in a disk of ``radius`` bins around frequency ``f`` (cycles/px) less the background, and its noise."""
    n_bins = spectrum.shape[0]  # square crop: the same bin size on both axes
    cy, cx = f[1] * n_bins, f[0] * n_bins
    r = int(math.ceil(radius))
    ky0, kx0 = int(round(cy)) - r, int(round(cx)) - r
    block = spectrum.block(ky0, kx0, 2 * r + 1, 2 * r + 1)
    yy, xx = np.mgrid[0 : 2 * r + 1, 0 : 2 * r + 1]
    inside = np.hypot(ky0 + yy - cy, kx0 + xx - cx) <= radius
    power = np.abs(block[inside]) ** 2
    n = int(inside.sum())
    return float(power.sum() - background * n), float(background * math.sqrt(n))


def detect_pattern(image: np.ndarray, *, max_px: int = 1024, min_period_px: float = 3.0) -> PatternEvidence:
    """Tell a line grid, a checkerboard and a dot lattice apart by the harmonic structure of the photo's spectrum.

    Parameters
    ----------
    image : ndarray (H, W)
        The photo (grey); a centred square crop of at most ``max_px`` px is analysed.
    max_px : int
        Side of the crop, px (enough periods for sharp peaks, one small FFT).
    min_period_px : float
        Shortest carrier period considered (as for F1).

    Returns
    -------
    PatternEvidence

    Raises
    ------
    InputError
        No grid in the photo (as F1).

    Notes
    -----
    Energy ``E(a, b)`` = sum of ``|FFT|²`` over a disk of ``2.5 + 1.5 (|a| + |b|)`` bins
    (distortion spreads a harmonic in proportion to its order) around ``a·k1 + b·k2``,
    less the median background power per bin; relative to ``(E(1,0) + E(0,1))/2``.
    Harmonics beyond Nyquist are not measured.

    Examples
    --------
    >>> from glassdist.synthetic import synthetic_capture
    >>> cap = synthetic_capture((256, 256), pitch_mm=2.0, mm_per_px=0.25, pattern="checkerboard")
    >>> detect_pattern(cap.image).pattern
    'checkerboard'
    >>> detect_pattern(synthetic_capture((256, 256), pitch_mm=2.0, mm_per_px=0.25, pattern="dots").image).pattern
    'dots'
    """
    img = np.asarray(image, dtype=np.float32)
    H, W = img.shape[:2]
    s = min(H, W, max_px)
    y0, x0 = (H - s) // 2, (W - s) // 2
    crop = np.ascontiguousarray(img[y0 : y0 + s, x0 : x0 + s])
    # the command line decides 'auto' from the photo before the analysis, which checks the pattern on the same
    # photo: the evidence of a crop already read is kept (keyed by its bytes, so an edited image is read again)
    key = (hashlib.blake2b(crop.tobytes(), digest_size=16).digest(), crop.shape, float(min_period_px))
    if key not in _EVIDENCE:
        while len(_EVIDENCE) >= 4:  # a run reads two photos at most (the photo, its reference): a few are enough
            del _EVIDENCE[next(iter(_EVIDENCE))]
        _EVIDENCE[key] = _crop_evidence(crop, min_period_px)
    return _EVIDENCE[key]


#: the last crops' evidence (:func:`detect_pattern`), by the crop's digest, oldest first
_EVIDENCE: dict[tuple[bytes, tuple[int, ...], float], PatternEvidence] = {}


def _crop_evidence(crop: np.ndarray, min_period_px: float) -> PatternEvidence:
    """:func:`detect_pattern` on its centred square ``crop`` (float32)."""
    s = crop.shape[0]
    window = np.hanning(s).astype(np.float32)
    spectrum = F.compute_spectrum((crop - crop.mean()) * window[:, None] * window[None, :])
    pair = F.find_carriers(spectrum, min_period_px=min_period_px)
    k1, k2 = pair.k1.f, pair.k2.f
    background = float(np.median(np.abs(spectrum.rfft) ** 2))
    spacing = s * min(pair.k1.norm, pair.k2.norm, float(np.linalg.norm(k1 - k2)), float(np.linalg.norm(k1 + k2)))

    def energy(a: int, b: int) -> tuple[float, float]:
        f = a * k1 + b * k2
        if np.any(np.abs(f) >= 0.5):
            return 0.0, math.inf  # beyond Nyquist: not measured
        return _energy(spectrum, f, min(2.5 + 1.5 * (abs(a) + abs(b)), 0.45 * spacing), background)

    fundamental = 0.5 * (energy(1, 0)[0] + energy(0, 1)[0])
    if not fundamental > 0:
        return PatternEvidence(None, 0.0, 0.0, math.inf)

    def strongest(terms: tuple[tuple[int, int], ...]) -> tuple[float, float]:
        """The strongest present term's energy (0 if none) and the energy a term needs to be present."""
        found = [energy(a, b) for a, b in terms]
        need = max(_SIGNIFICANCE * min(noise for _, noise in found), _FLOOR * fundamental)
        present = [e for e, noise in found if e > max(_SIGNIFICANCE * noise, _FLOOR * fundamental)]
        return (max(present) if present else 0.0), need

    along, noise_a = strongest(_ALONG)
    mixed, noise_m = strongest(_MIXED)
    diagonal, noise_d = strongest(_DIAGONAL)
    noise = min(noise_a, noise_m)
    pattern = None
    if diagonal >= DOTS_DIAGONAL * fundamental and diagonal >= along:
        pattern = "dots"
    elif along > 0 and along >= DECISIVE_RATIO * max(mixed, noise_m):
        pattern = "lines"
    elif mixed > 0 and mixed >= DECISIVE_RATIO * max(along, noise_a):
        pattern = "checkerboard"
    return PatternEvidence(pattern, along / fundamental, mixed / fundamental, noise / fundamental,
                           diagonal / fundamental)


@dataclass(frozen=True)
class SettledPattern:
    """:func:`settle_pattern`'s outcome: the parameters with ``pattern`` decided, the warnings, and whether a grid was seen.

    ``no_grid``: F1's message when the photo's crop shows no grid at all (else None); the
    Comparative Method, which takes its carriers from the reference, raises it.
    """

    params: AnalyzerParams
    warnings: tuple[str, ...] = ()
    no_grid: str | None = None


def settle_pattern(params: AnalyzerParams, image: np.ndarray) -> SettledPattern:
    """The parameters with ``pattern`` decided: ``'auto'`` from the spectrum, a given one checked against it.

    Parameters
    ----------
    params : AnalyzerParams
    image : ndarray (H, W)
        The photo (or the glass-less reference) the pattern is read from.

    Returns
    -------
    SettledPattern
        ``params.pattern`` is ``'lines'``, ``'checkerboard'`` or ``'dots'``; a warning when a given
        pattern is contradicted by the spectrum in a way that changes the scale (a checkerboard's
        carrier period is pitch·√2, the others' the pitch), or when ``'auto'`` cannot decide (then
        ``'lines'`` is used).
    """
    no_grid = None
    try:
        evidence = detect_pattern(image, min_period_px=params.min_period_px)
    except InputError as exc:  # no grid at all: F1 says so on the full photo (or, Comparative, from here)
        evidence, no_grid = PatternEvidence(None, 0.0, 0.0, math.inf), str(exc)
    if params.pattern == "auto":
        warn: tuple[str, ...] = ()
        if evidence.pattern is None:
            warn = (f"the photo's spectrum does not tell a line grid from a checkerboard ({evidence.describe()}); "
                    "assumed 'lines': give the pattern (lengths in mm differ by sqrt(2) between the two)",)
        return SettledPattern(params.model_copy(update={"pattern": evidence.pattern or "lines"}), warn, no_grid)
    same_scale = "checkerboard" not in (evidence.pattern, params.pattern)  # lines and dots: period = pitch
    if evidence.pattern is not None and evidence.pattern != params.pattern and not same_scale:
        return SettledPattern(params, (
            f"the pattern '{params.pattern}' was given but the photo's spectrum shows a {evidence.pattern} "
            f"({evidence.describe()}); lengths in mm (mm_per_px, displacements, sigma) are off by sqrt(2) "
            f"if the backdrop is a {evidence.pattern}: check the pattern, or leave it out to decide from the photo",),
            no_grid)
    return SettledPattern(params, (), no_grid)
