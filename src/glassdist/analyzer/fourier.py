"""Block F, stages F1-F3: carriers, bandpass, heterodyne and complex smoothing.

Conventions
-----------
* Images are indexed ``(row, col)``; a spatial frequency is written
  ``f = (fx, fy)`` in cycles/px with ``fx`` along columns and ``fy`` along rows,
  so the carrier phase at pixel ``r = (x, y)`` is ``2 pi f . r``.
* The analytic signal of carrier *i* is brought to baseband,
  ``b_i(r) = a_i(r) exp(-2 pi i f_i . r)``; this *is* the heterodyne against a
  synthetic flat carrier (Direct Method, pass 1). The Comparative Method then
  forms ``b_i^dist conj(b_i^ref)``.
* Because the bandpassed signal is band-limited, it is computed directly on a
  coarser *sampling grid* (:class:`SamplingGrid`) by inverse-transforming only a
  patch of the spectrum around the carrier (FFT-domain decimation). Sample
  ``(j, i)`` of that grid sits at full-resolution pixel
  ``(j sy + (sy - 1)/2, i sx + (sx - 1)/2)``, the convention of area resampling,
  so that ``cv2.resize(..., INTER_LINEAR)`` maps it back exactly.

References
----------
Takeda, Ina & Kobayashi (1982), JOSA 72, 156: Fourier-transform fringe analysis.
Jacobsen & Kootsookos (2007), IEEE Signal Proc. Mag. 24(3): fast accurate
frequency estimators. Paper §2.2, F1-F3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft
from scipy import ndimage

from ..errors import InputError

__all__ = [
    "Carrier",
    "CarrierPair",
    "SamplingGrid",
    "Spectrum",
    "compute_spectrum",
    "find_carriers",
    "sampling_grid",
    "bandpass_covariance",
    "baseband",
    "block_grid",
    "block_mean",
    "smooth_complex",
    "gaussian_blur",
    "check_image_size",
]

_WORKERS = -1  # scipy.fft: use every core


@dataclass(frozen=True)
class Carrier:
    """One grid carrier.

    Attributes
    ----------
    fx, fy : float
        Spatial frequency, cycles/px (x along columns, y along rows).
    strength : float
        Peak magnitude over the median spectral background (dimensionless).
    """

    fx: float
    fy: float
    strength: float = float("nan")

    @property
    def f(self) -> np.ndarray:
        """Frequency vector ``(fx, fy)``, cycles/px."""
        return np.array([self.fx, self.fy])

    @property
    def norm(self) -> float:
        """``|f|``, cycles/px."""
        return float(np.hypot(self.fx, self.fy))

    @property
    def period_px(self) -> float:
        """Carrier wavelength ``lambda = 1/|f|``, px."""
        return 1.0 / self.norm

    @property
    def angle_deg(self) -> float:
        """Direction of ``f`` from +x towards +y (rows, down), degrees."""
        return float(np.degrees(np.arctan2(self.fy, self.fx)))

    def negated(self) -> "Carrier":
        """The same carrier of opposite sign (frequency and phase negated)."""
        return Carrier(-self.fx, -self.fy, self.strength)

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping."""
        return {
            "fx_cycles_per_px": self.fx,
            "fy_cycles_per_px": self.fy,
            "period_px": self.period_px,
            "angle_deg": self.angle_deg,
            "strength": self.strength,
        }


@dataclass(frozen=True)
class CarrierPair:
    """The two grid carriers, oriented so that ``det([f1; f2]) > 0``.

    With that orientation the logical grid frame (U along carrier 1, V along
    carrier 2) has the handedness of the image frame (x right, y down), so the
    pixel -> backdrop map is a proper rotation times a stretch.
    """

    k1: Carrier
    k2: Carrier

    @property
    def matrix(self) -> np.ndarray:
        """Rows ``f1, f2`` (cycles/px): ``(U, V) = F @ (x, y)`` for a flat grid."""
        return np.array([self.k1.f, self.k2.f])

    def to_dict(self) -> dict:
        """The record as a JSON-ready mapping."""
        a = abs(self.k1.angle_deg - self.k2.angle_deg) % 180.0
        return {"k1": self.k1.to_dict(), "k2": self.k2.to_dict(), "angle_between_deg": min(a, 180.0 - a)}


@dataclass(frozen=True)
class SamplingGrid:
    """A coarse grid on which the band-limited demodulated signals are carried.

    Attributes
    ----------
    full_shape : (int, int)
        ``(H, W)`` of the image, px.
    shape : (int, int)
        ``(h, w)`` of the coarse grid.
    """

    full_shape: tuple[int, int]
    shape: tuple[int, int]

    @property
    def step(self) -> tuple[float, float]:
        """``(sy, sx)``: pixel spacing of the coarse samples along rows and columns."""
        return (self.full_shape[0] / self.shape[0], self.full_shape[1] / self.shape[1])

    @property
    def offset(self) -> tuple[float, float]:
        """Full-resolution position of sample (0, 0), px."""
        sy, sx = self.step
        return ((sy - 1.0) / 2.0, (sx - 1.0) / 2.0)

    def coords(self) -> tuple[np.ndarray, np.ndarray]:
        """Full-resolution pixel coordinates ``(y, x)`` of the samples, each (h, w)."""
        sy, sx = self.step
        oy, ox = self.offset
        y = np.arange(self.shape[0]) * sy + oy
        x = np.arange(self.shape[1]) * sx + ox
        return np.meshgrid(y, x, indexing="ij")

    @property
    def is_full(self) -> bool:
        """Whether the grid samples every pixel (no decimation)."""
        return self.shape == self.full_shape


@dataclass(frozen=True)
class Spectrum:
    """The real FFT of a mean-subtracted image (computed once, reused).

    Attributes
    ----------
    rfft : ndarray, complex, shape (H, W//2 + 1)
    shape : (int, int)
        ``(H, W)`` of the image.
    """

    rfft: np.ndarray
    shape: tuple[int, int]

    def block(self, ky0: int, kx0: int, h: int, w: int) -> np.ndarray:
        """Full complex spectrum on the ``h x w`` block of bins starting at ``(ky0, kx0)`` (any sign).

        Rows wrap around; columns are read from the stored half-plane, the
        negative ones through Hermitian symmetry (:meth:`full`) only when the block
        reaches them.
        """
        H, W = self.shape
        if 0 <= kx0 and kx0 + w - 1 <= self.rfft.shape[1] - 1 - (W % 2 == 0):
            rows = np.mod(np.arange(ky0, ky0 + h), H)
            return self.rfft[:, kx0 : kx0 + w][rows]
        return self.full(np.arange(ky0, ky0 + h)[:, None], np.arange(kx0, kx0 + w)[None, :])

    def full(self, ky: np.ndarray | float, kx: np.ndarray | float) -> np.ndarray:
        """Full complex spectrum at integer bins ``(ky, kx)`` (any sign), via Hermitian symmetry."""
        H, W = self.shape
        ky = np.asarray(ky).astype(np.int64)
        kx = np.asarray(kx).astype(np.int64)
        kx_w = np.mod(kx + W // 2, W) - W // 2  # signed, in [-W/2, W/2)
        neg = kx_w < 0
        row = np.where(neg, np.mod(-ky, H), np.mod(ky, H))
        col = np.abs(kx_w)
        col = np.minimum(col, self.rfft.shape[1] - 1)
        vals = self.rfft[row, col]
        return np.where(neg, np.conj(vals), vals)


def compute_spectrum(image: np.ndarray) -> Spectrum:
    """Real 2-D FFT of the mean-subtracted image (the DC term carries no phase).

    Subtracting the mean changes the DC bin alone, so it is zeroed after the
    transform instead of copying the image.
    """
    img = np.asarray(image, dtype=np.float32)
    rfft = sfft.rfft2(img, workers=_WORKERS)
    rfft[0, 0] = 0
    return Spectrum(rfft, img.shape)


def _jacobsen(xm: complex | np.ndarray, x0: complex | np.ndarray, xp: complex | np.ndarray) -> float:
    """Fractional bin offset of a spectral peak from three complex bins (Jacobsen 2007)."""
    den = 2.0 * x0 - xm - xp
    if abs(den) == 0:
        return 0.0
    d = float(np.real((xm - xp) / den))
    return float(np.clip(d, -0.5, 0.5))


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two lines (directions taken mod 180 deg), degrees in [0, 90]."""
    c = abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(c, 0.0, 1.0))))


def _spectral_peaks(work: np.ndarray, n: int) -> np.ndarray:
    """Flat indices of up to ``n`` local maxima (5x5) of ``work``, found on a 4x4 max-pooled copy first."""
    h, w = work.shape
    b = 4
    if min(h, w) < 64:
        lm = (work == ndimage.maximum_filter(work, size=5, mode="wrap")) & (work > 0)
        return np.flatnonzero(lm)
    hh, ww = h // b * b, w // b * b
    # Rows first (contiguous blocks), then columns: several times faster than one 4-D reduction.
    pooled = work[:hh, :ww].reshape(hh // b, b, ww).max(axis=1).reshape(hh // b, ww // b, b).max(axis=2)
    lm = (pooled == ndimage.maximum_filter(pooled, size=3, mode="wrap")) & (pooled > 0)
    cand = np.flatnonzero(lm)
    cand = cand[np.argsort(pooled.ravel()[cand])[::-1][:n]]
    out = []
    for c in cand:  # refine each pooled peak to its bin, then check it is a 5x5 local maximum
        r, q = divmod(int(c), pooled.shape[1])
        r0, q0 = r * b, q * b
        blk = work[r0 : r0 + b, q0 : q0 + b]
        i, j = np.unravel_index(int(np.argmax(blk)), blk.shape)
        rr, cc = r0 + i, q0 + j
        rows = np.arange(rr - 2, rr + 3) % h
        cols = np.clip(np.arange(cc - 2, cc + 3), 0, w - 1)
        if work[rr, cc] >= work[np.ix_(rows, cols)].max():
            out.append(rr * w + cc)
    return np.unique(np.array(out, dtype=np.int64))


def _check_no_finer_grid(spectrum: Spectrum, min_period_px: float, carrier_magnitude: float, *, rows: int = 512) -> None:
    """Refuse a photo whose grid is finer than ``min_period_px``: its own peak lies beyond the carrier band.

    The carriers are searched below ``1 / min_period_px`` cycles/px only; a grid of a
    shorter period would be read from the aliases of its harmonics at the wrong scale.
    Bins with ``|fx|`` or ``|fy|`` beyond the band's edge are scanned (in blocks of
    ``rows`` rows) for a peak 1.2 times as strong as the carrier (the fundamental of a
    2.5 px line grid is 1.5 times the alias of its second harmonic; the third harmonic of a
    thin-line 8 px grid, the strongest legitimate peak there, 0.65 times its fundamental).
    """
    H, W = spectrum.shape
    ky_max = int(np.ceil(H / min_period_px))
    kx_max = min(W // 2, int(np.ceil(W / min_period_px)))
    rf = spectrum.rfft
    best, at = 1.2 * float(carrier_magnitude), None
    for r0 in range(0, H, rows):
        r1 = min(H, r0 + rows)
        ky = np.rint(sfft.fftfreq(H)[r0:r1] * H)
        block = np.abs(rf[r0:r1])
        block[np.abs(ky) <= ky_max, : kx_max + 1] = 0.0  # the carrier band (and DC)
        i = int(np.argmax(block))
        if block.flat[i] > best:
            r, c = divmod(i, block.shape[1])
            best, at = float(block.flat[i]), (ky[r] / H, c / W)
    if at is not None:
        period = 1.0 / float(np.hypot(*at))
        raise InputError(
            f"the grid's period in the photo is about {period:.2f} px, below the {min_period_px:g} px the analysis "
            "needs (it would be read at the wrong scale); move the camera closer, zoom in or use a coarser grid"
        )


def _carrier_band(spectrum: Spectrum, min_period_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened magnitude of the band that can hold a carrier, the signed row frequencies (bins), and the band.

    Only bins below 1/min_period_px can hold a carrier: that block is cut out first (rows
    fftshifted when cut, so that row r holds the signed frequency ky[r]); DC/illumination
    (fewer than 4 periods across the image) and finer frequencies are zeroed.
    """
    H, W = spectrum.shape
    ky_max = int(np.ceil(H / min_period_px))
    kx_max = min(W // 2, int(np.ceil(W / min_period_px)))
    rf = spectrum.rfft
    if 2 * ky_max + 1 < H:
        mag = np.empty((2 * ky_max + 1, kx_max + 1), np.float32)
        np.abs(rf[H - ky_max :, : kx_max + 1], out=mag[:ky_max])
        np.abs(rf[: ky_max + 1, : kx_max + 1], out=mag[ky_max:])
        ky = np.arange(-ky_max, ky_max + 1)
    else:
        mag = np.abs(rf[:, : kx_max + 1]).astype(np.float32, copy=False)
        ky = np.rint(sfft.fftfreq(H) * H).astype(int)
    fy = (ky / H).astype(np.float32)[:, None]
    fx = (np.arange(kx_max + 1) / W).astype(np.float32)[None, :]
    fr = np.sqrt(fx * fx + fy * fy)
    low = 4.0 / min(H, W)
    band = (fr > low) & (fr < 1.0 / min_period_px)
    # Column kx = 0 holds both +f and -f; keep one half-line so a peak is seen once.
    band[:, 0] &= fy[:, 0] > 0
    if W % 2 == 0 and kx_max == W // 2:
        band[:, -1] &= fy[:, 0] > 0
    # Soft whitening below ~16 periods across the image: edges of frames and opaque objects
    # have spectra falling as 1/|f| that would otherwise outshine the grid at low frequencies;
    # above it the weight is ~1, so harmonics gain little on their fundamental.
    f0 = np.float32(16.0 / min(H, W))
    fr += f0
    np.divide(fr - f0, fr, out=fr)
    work = mag
    work *= fr
    del fr
    work[~band] = 0.0
    if not band.any():
        raise InputError("the image has no periodic pattern (flat spectrum); photograph the grid through the glass")
    return work, ky, band


#: Share of the frame the grid must fill for the carrier search to read the photo's own spectrum;
#: below it the search reads the grid-filled part, apodised (:func:`_grid_filled_spectrum`).
GRID_FILL_MIN = 0.8


def _grid_filled_spectrum(spectrum: Spectrum, image: np.ndarray | None = None) -> Spectrum | None:
    """The spectrum of the grid-filled part of the photo, apodised, where the grid fills under :data:`GRID_FILL_MIN`.

    A grid filling only part of the frame (a mirror in dark surroundings, a screen with its
    edges in view) leaves the outline of its region in the spectrum: a step, whose 1/|f|
    spectrum along the directions normal to the outline outshines a weak grid's carriers at
    low frequencies. On a copy of ~256 px on the short side, the local mean ``mu`` (Gaussian,
    standard deviation ``s`` = 1/24 of the short side: it averages out a period of the
    coarsest carrier searched, 6 periods across) is split in two by Otsu's threshold. The
    split is an outline, not a brightness gradient, when it explains most of ``mu``'s
    variance (between-class share above 0.9; a linear ramp gives 0.75) and the step between
    the classes exceeds twice the texture (the median local standard deviation about a mean 4
    times finer than ``mu``) of the class holding the grid, the more textured one. Where that
    class is under :data:`GRID_FILL_MIN` of the frame, the image less its mean over the class
    is multiplied by the class eroded by ``2 s`` and blurred by ``s`` (at the outline the taper
    is near 2 %): the outline's content is left within a few bins of DC, and the carriers,
    broadened by the taper's narrow spectrum, stay where they were.

    ``image``: the photo ``spectrum`` was computed from, if at hand (else it is transformed back
    from ``spectrum``, less its mean: every test above and the apodised image's spectrum are the same
    for any offset).

    Returns None (search the photo's own spectrum) where no such outline is found.
    """
    import cv2
    from skimage.filters import threshold_otsu

    H, W = spectrum.shape
    if image is not None and np.shape(image) == (H, W):
        img = np.asarray(image, dtype=np.float32)
    else:
        img = sfft.irfft2(spectrum.rfft, s=(H, W), workers=_WORKERS).astype(np.float32, copy=False)
    b = max(1, min(H, W) // 256)
    size = (max(1, W // b), max(1, H // b))
    crop = img[: size[1] * b, : size[0] * b]  # whole blocks: OpenCV's fast integer-factor area resize
    m1 = cv2.resize(crop, size, interpolation=cv2.INTER_AREA)
    sq = np.square(crop)
    m2 = cv2.resize(sq, size, interpolation=cv2.INTER_AREA)
    del sq
    s = min(size) / 24.0
    mu = ndimage.gaussian_filter(m1, s, mode="nearest")
    # Texture: the local variance about a 4 times finer mean, so that the outline's own step
    # counts only in a thin band along it.
    fine = ndimage.gaussian_filter(m1, s / 4, mode="nearest")
    var = np.maximum(ndimage.gaussian_filter(m2, s / 4, mode="nearest") - fine * fine, 0.0)
    if not np.ptp(mu) > 0:
        return None
    t = threshold_otsu(mu)
    hi = mu > t
    n_hi = float(hi.mean())
    if not 0.0 < n_hi < 1.0:
        return None
    m_hi, m_lo = float(mu[hi].mean()), float(mu[~hi].mean())
    between = n_hi * (1.0 - n_hi) * (m_hi - m_lo) ** 2
    if between < 0.9 * float(mu.var()):
        return None
    grid = hi if np.median(var[hi]) >= np.median(var[~hi]) else ~hi
    texture = float(np.sqrt(np.median(var[grid])))
    if grid.mean() >= GRID_FILL_MIN or abs(m_hi - m_lo) < 2.0 * texture:
        return None
    r = max(1, int(round(2 * s)))
    core = ndimage.binary_erosion(grid, structure=np.ones((3, 3), bool), iterations=r, border_value=1)
    if not core.any():
        return None
    taper = ndimage.gaussian_filter(core.astype(np.float32), s, mode="nearest")
    w = cv2.resize(taper, (W, H), interpolation=cv2.INTER_LINEAR)  # stretched over the < b px the blocks leave
    level = float(np.sum(img * w) / np.sum(w))
    return compute_spectrum((img - level) * w)


def _strongest_peaks(work: np.ndarray, band: np.ndarray, max_peaks: int):
    """Up to ``max_peaks`` local maxima of ``work``, strongest first, with their strength over the background.

    Returns ``(rows, cols, strengths)``.
    """
    sub = work[::3, ::3][band[::3, ::3]]
    background = float(np.median(sub)) if sub.size else 0.0
    peak = float(work.max())
    background = max(background, 1e-9 * peak)  # a noise-free synthetic grid has an exactly empty background
    if background <= 0 or not np.isfinite(background):
        raise InputError("the image has no periodic pattern (flat spectrum); photograph the grid through the glass")
    idx = _spectral_peaks(work, 4 * max_peaks)
    if idx.size == 0:
        raise InputError("no grid pattern found in the image; check the photo shows the printed grid in focus")
    idx = idx[np.argsort(work.ravel()[idx])[::-1][:max_peaks]]
    rows, cols = np.unravel_index(idx, work.shape)
    strengths = work.ravel()[idx] / background
    if strengths[0] < 8.0:
        raise InputError(
            f"no grid pattern found in the image (strongest spectral peak only {strengths[0]:.1f}x the background); "
            "check the photo shows the printed grid in focus, and that at least 6 grid periods fit across it"
        )
    return rows, cols, strengths


def _fundamental(i: int, vecs: np.ndarray, strengths: np.ndarray, size: int) -> int:
    """A harmonic q = n p (n = 2, 3, 4) of a peak p of comparable strength is replaced by p."""
    for j in range(len(vecs)):
        if j != i and strengths[j] > 0.3 * strengths[i]:
            for n in (2, 3, 4):
                for sign in (1.0, -1.0):
                    if np.linalg.norm(n * sign * vecs[j] - vecs[i]) < (n + 1.5) / size:
                        return _fundamental(j, vecs, strengths, size)
    return i


def _one_family(f1: np.ndarray, size: int, found: str) -> InputError:
    """The error for a spectrum with one peak family: a line grid, or no grid at all.

    A peak within 2 periods of the band's low cut (4 periods across the image) is the tail
    of the illumination's spectrum (a brightness gradient, a few large shapes), not a grid.
    """
    if np.linalg.norm(f1) * size < 6.0:
        return InputError("no grid pattern found in the image (its only periodic content is a brightness gradient or "
                          "a few large shapes); check the photo shows the printed grid in focus, and that at least "
                          "6 grid periods fit across it")
    return InputError(f"{found}; glassdist needs a crossed line grid or a checkerboard")


def _pick_pair(vecs: np.ndarray, strengths: np.ndarray, size: int) -> tuple[int, int]:
    """Indices of k1 (strongest fundamental) and k2 (> 45 deg from it, not a cross term k_a +- k1)."""
    i1 = _fundamental(0, vecs, strengths, size)
    cand = [j for j in range(len(vecs)) if j != i1 and _angle_between(vecs[j], vecs[i1]) > 45.0]
    if not cand:
        raise _one_family(vecs[i1], size, "only one family of grid lines found")
    i2 = _fundamental(max(cand, key=lambda j: strengths[j]), vecs, strengths, size)
    # Reject cross terms q = p +- k1: prefer the lower-frequency peak p if it exists and is >45 deg from k1.
    for _ in range(2):
        q = vecs[i2]
        better = None
        for s in (+1.0, -1.0):
            p = q - s * vecs[i1]
            for j in cand:
                if j == i2:
                    continue
                for sign in (1.0, -1.0):
                    if np.linalg.norm(sign * vecs[j] - p) < 2.5 / size and np.linalg.norm(p) < np.linalg.norm(q):
                        if strengths[j] > 0.25 * strengths[i2] and (better is None or strengths[j] > strengths[better]):
                            better = j
        if better is None:
            break
        i2 = better
    if strengths[i2] < 4.0:
        raise _one_family(vecs[i1], size, "only one family of grid lines is visible")
    return i1, i2


def _refine_carrier(spectrum: Spectrum, ky: float, kx: float, strength: float) -> Carrier:
    """Sub-bin frequency of the peak at bin (ky, kx): Jacobsen, or the power centroid for a spread carrier."""
    H, W = spectrum.shape
    cy, cx = _spectral_centroid(spectrum, ky, kx)
    if np.hypot(cy - ky, cx - kx) > 1.5:
        # Strong distortion spreads the carrier into sidebands (frequency modulation) and
        # the tallest bin can be one of them: the power centroid is the mean local frequency.
        return Carrier(cx / W, cy / H, strength)
    s = spectrum.full
    dx = _jacobsen(s(ky, kx - 1), s(ky, kx), s(ky, kx + 1))
    dy = _jacobsen(s(ky - 1, kx), s(ky, kx), s(ky + 1, kx))
    return Carrier((kx + dx) / W, (ky + dy) / H, strength)


def find_carriers(spectrum: Spectrum, *, min_period_px: float = 3.0, max_peaks: int = 40,
                  image: np.ndarray | None = None) -> CarrierPair:
    """F1: locate the two grid carriers in the 2-D spectrum, refined to sub-bin precision.

    ``k1`` is the strongest peak away from DC; ``k2`` the strongest peak more than
    45 deg from ``k1`` that is not a cross-modulation term ``k_a +- k1`` of a
    lower-frequency peak (paper §2.2 F1).

    Parameters
    ----------
    spectrum : Spectrum
        From :func:`compute_spectrum`.
    min_period_px : float
        Shortest carrier period accepted, px (finer peaks are ignored).
    max_peaks : int
        Number of spectral peaks considered.
    image : ndarray (H, W), optional
        The image ``spectrum`` was computed from: the test for a grid filling only part of the
        frame reads it instead of transforming the spectrum back (one inverse FFT of the photo less).

    Returns
    -------
    CarrierPair
        Oriented so that ``det([f1; f2]) > 0``.

    Raises
    ------
    InputError
        If no periodic pattern stands out of the spectral background.

    Examples
    --------
    A crossed line grid of period 8 px along x and 10 px along y:

    >>> import numpy as np
    >>> from glassdist.analyzer.fourier import compute_spectrum, find_carriers
    >>> y, x = np.mgrid[0:160, 0:200]
    >>> img = 0.5 + 0.2 * np.cos(2 * np.pi * x / 8) + 0.2 * np.cos(2 * np.pi * y / 10)
    >>> pair = find_carriers(compute_spectrum(img))
    >>> sorted(round(c.period_px, 3) for c in (pair.k1, pair.k2))
    [8.0, 10.0]
    """
    H, W = spectrum.shape
    filled = _grid_filled_spectrum(spectrum, image)
    if filled is not None:  # the grid fills part of the frame: its outline must not pass for a carrier
        spectrum = filled
    work, ky, band = _carrier_band(spectrum, min_period_px)
    rows, cols, strengths = _strongest_peaks(work, band, max_peaks)
    kys = ky[rows].astype(float)
    kxs = cols.astype(float)
    vecs = np.stack([kxs / W, kys / H], axis=1)  # (fx, fy) at integer bins
    i1, i2 = _pick_pair(vecs, strengths, min(H, W))
    _check_no_finer_grid(spectrum, min_period_px, abs(spectrum.rfft[int(kys[i1]) % H, int(kxs[i1])]))
    c1 = _refine_carrier(spectrum, kys[i1], kxs[i1], float(strengths[i1]))
    c2 = _refine_carrier(spectrum, kys[i2], kxs[i2], float(strengths[i2]))
    if min(c1.norm, c2.norm) * min(H, W) < 4.0:  # refined below the band's low cut: the illumination's tail
        raise _one_family(np.zeros(2), 1, "")
    if np.linalg.det(np.array([c1.f, c2.f])) < 0:
        c2 = c2.negated()
    return CarrierPair(c1, c2)


def _spectral_centroid(spectrum: Spectrum, ky: float, kx: float, *, width: float = 0.2, iterations: int = 50):
    """Power centroid (bins) of the spectrum around a peak, by Gaussian-weighted mean shift.

    The weight has a standard deviation of ``width`` |f| (the scale of the carrier
    bandpass), so the other carrier, the cross terms and DC (all at least ~0.7 |f| away)
    weigh little. For a clean tone it stays on the peak; for a frequency-modulated one it
    converges to the mean local frequency (the power centroid of an FM spectrum).
    """
    H, W = spectrum.shape
    f = np.hypot(kx / W, ky / H)
    sd_y, sd_x = width * f * H, width * f * W  # bins along ky and kx
    ry, rx = int(np.ceil(3 * sd_y)) + 1, int(np.ceil(3 * sd_x)) + 1
    y0, x0 = int(round(ky)), int(round(kx))
    yy = np.arange(y0 - ry, y0 + ry + 1)
    xx = np.arange(x0 - rx, x0 + rx + 1)
    pw = np.abs(spectrum.block(y0 - ry, x0 - rx, yy.size, xx.size)) ** 2
    # Sidebands of a modulated carrier stand well above the background; broadband content
    # (edges of frames and objects, noise) does not and must not pull the centroid.
    pw[pw < 0.05 * pw[ry, rx]] = 0.0
    cy, cx = float(ky), float(kx)
    for _ in range(iterations):
        wgt = pw * np.exp(-0.5 * ((yy[:, None] - cy) / sd_y) ** 2 - 0.5 * ((xx[None, :] - cx) / sd_x) ** 2)
        tot = wgt.sum()
        if not tot > 0:
            break
        ny_, nx_ = float((wgt.sum(axis=1) @ yy) / tot), float((wgt.sum(axis=0) @ xx) / tot)
        done = abs(ny_ - cy) + abs(nx_ - cx) < 1e-3
        cy, cx = ny_, nx_
        if done:
            break
    return cy, cx


def bandpass_covariance(
    carrier: Carrier, other: Carrier, *, sigma_along: float, sigma_cross: float, isotropic: bool = False
) -> np.ndarray:
    """Frequency-domain covariance (cycles/px)^2 of the Gaussian bandpass around ``carrier``.

    The narrow axis points along the other carrier, i.e. towards the cross terms
    ``f_i +- f_other`` whose leakage would rotate the recovered frame (paper
    §3.1); the wide axis, perpendicular to it, keeps the distortion sidebands.

    Returns
    -------
    ndarray, shape (2, 2)
        Covariance ``Sigma_f`` in (x, y) order: the bandpass is
        ``exp(-nu^T Sigma_f^{-1} nu / 2)`` for an offset ``nu`` from the carrier.
    """
    wide = sigma_along * carrier.norm
    if isotropic:
        return np.eye(2) * wide**2
    u = other.f / other.norm
    n = np.array([-u[1], u[0]])
    narrow = sigma_cross * other.norm
    return narrow**2 * np.outer(u, u) + wide**2 * np.outer(n, n)


def sampling_grid(
    shape: tuple[int, int], covariances: list[np.ndarray], decimation: int | str = "auto", *, support: float = 4.0,
    multiple: int = 4,
) -> SamplingGrid:
    """Choose the coarse grid that carries the bandpassed signals without aliasing.

    ``auto``: the spectral patch spans ``+- support`` standard deviations of the
    widest bandpass, so the Gaussian tails outside it are below ``exp(-support^2/2)``.
    The grid shape is a multiple of ``multiple`` so that it can be block-averaged
    by 2 or 4 exactly (:func:`block_grid`).
    """
    H, W = shape
    if decimation == "auto":
        sd = max(float(np.sqrt(np.max(np.linalg.eigvalsh(c)))) for c in covariances)
        half = support * sd  # cycles/px
        h = min(H, int(2 * np.ceil(half * H)))
        w = min(W, int(2 * np.ceil(half * W)))
    else:
        d = int(decimation)
        h, w = int(np.ceil(H / d)), int(np.ceil(W / d))
    if (h, w) == (H, W) and H % multiple == 0 and W % multiple == 0:
        return SamplingGrid((H, W), (H, W))

    def fit(n, N):
        up = int(np.ceil(max(n, 8) / multiple)) * multiple
        return up if up <= N else (N // multiple) * multiple

    return SamplingGrid((H, W), (fit(h, H), fit(w, W)))


def block_grid(grid: SamplingGrid, m: int) -> SamplingGrid:
    """The grid of ``m x m`` block averages of ``grid`` (same position convention)."""
    h, w = grid.shape
    if h % m or w % m:
        raise ValueError(f"grid {grid.shape} is not divisible by {m}")
    return SamplingGrid(grid.full_shape, (h // m, w // m))


def block_mean(a: np.ndarray, weight: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted ``m x m`` block means of ``a`` (h, w[, c]) and the block fill fraction of ``weight``.

    NaN samples of ``a`` must have zero weight. Computed in single precision
    (OpenCV's area resampling, which is the exact block mean for an integer factor).
    """
    if m == 1:
        return a, weight.astype(float)
    import cv2

    h, w = weight.shape
    size = (w // m, h // m)
    wt = np.ascontiguousarray(weight, np.float32)
    fill = cv2.resize(wt, size, interpolation=cv2.INTER_AREA)
    aw = np.nan_to_num(np.asarray(a, np.float32))
    aw *= wt if aw.ndim == 2 else wt[..., None]
    s = cv2.resize(aw, size, interpolation=cv2.INTER_AREA)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s / (fill if s.ndim == 2 else fill[..., None])
    return mean, fill.astype(float)


def baseband(
    spectrum: Spectrum, carrier: Carrier, cov_f: np.ndarray, grid: SamplingGrid, *, smooth_sigma_px: float | None = None
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """F1+F2 (flat reference): bandpassed analytic signal of ``carrier`` at baseband on ``grid``.

    Returns ``b(r) = a(r) exp(-2 pi i f . r)`` sampled on ``grid``, where ``a`` is
    the inverse FFT of the spectrum times the Gaussian bandpass centred on the
    (sub-bin) carrier frequency.

    With ``smooth_sigma_px``, also returns ``G * b`` (F3, a Gaussian of that sigma in
    image px), applied as a product in the spectral patch at no extra pass.

    Returns
    -------
    ndarray, complex64, shape ``grid.shape`` (or the pair ``(b, G * b)``)
    """
    H, W = spectrum.shape
    h, w = grid.shape
    ky_c, kx_c = carrier.fy * H, carrier.fx * W
    ky0, kx0 = int(np.round(ky_c)), int(np.round(kx_c))
    my = np.arange(-(h // 2), h - h // 2)
    mx = np.arange(-(w // 2), w - w // 2)
    patch = spectrum.block(ky0 + my[0], kx0 + mx[0], h, w).astype(np.complex64, copy=False)
    # Gaussian bandpass exp(-q/2), q = nu^T Sigma^-1 nu, as separable factors times the cross term.
    ny = (ky0 + my - ky_c) / H
    nx = (kx0 + mx - kx_c) / W
    inv = np.linalg.inv(cov_f)
    gx = np.exp(-0.5 * inv[0, 0] * nx**2)
    gy = np.exp(-0.5 * inv[1, 1] * ny**2)
    # Sample positions j*sy + oy: shift by the offset, relative to the integer bin.
    oy, ox = grid.offset
    ey = (gy * np.exp(2j * np.pi * my / H * oy)).astype(np.complex64)
    ex = (gx * np.exp(2j * np.pi * mx / W * ox)).astype(np.complex64)
    patch *= ey[:, None]
    patch *= ex[None, :]
    if inv[0, 1] != 0:
        patch *= np.exp(np.float32(-inv[0, 1]) * np.outer(ny.astype(np.float32), nx.astype(np.float32)))
    sy, sx = grid.step
    yv = np.arange(h) * sy + oy
    xv = np.arange(w) * sx + ox
    frac_y, frac_x = (ky_c - ky0) / H, (kx_c - kx0) / W
    # Remove the fractional-bin remainder of the carrier: b = a * exp(-2 pi i f.r) (separable).
    ry = (np.exp(-2j * np.pi * frac_y * yv) * (h * w / (H * W))).astype(np.complex64)[:, None]
    rx = np.exp(-2j * np.pi * frac_x * xv).astype(np.complex64)[None, :]

    def to_space(pt):
        b = sfft.ifft2(sfft.ifftshift(pt), workers=_WORKERS, overwrite_x=True)
        b *= ry
        b *= rx
        return b

    if smooth_sigma_px is None:
        return to_space(patch)
    g = 2 * np.pi**2 * smooth_sigma_px**2
    sm = patch * np.exp(-g * ny**2).astype(np.float32)[:, None]
    sm *= np.exp(-g * nx**2).astype(np.float32)[None, :]
    return to_space(patch), to_space(sm)


def gaussian_blur(a: np.ndarray, sigma: tuple[float, float], *, truncate: float = 4.0) -> np.ndarray:
    """Separable Gaussian filter of a real or complex 2-D array, edge samples replicated.

    Same kernel as ``scipy.ndimage.gaussian_filter(a, sigma, mode="nearest",
    truncate=truncate)`` (radius ``int(truncate * sigma + 0.5)`` samples), computed in
    single precision by OpenCV, several times faster on large grids.

    Parameters
    ----------
    a : ndarray (h, w), float or complex
    sigma : (float, float)
        Standard deviation along rows and along columns, samples.
    """
    import cv2

    sy, sx = (float(v) for v in sigma)
    cplx = np.iscomplexobj(a)
    src = np.ascontiguousarray(a, np.complex64 if cplx else np.float32)
    if cplx:
        src = src.view(np.float32).reshape(a.shape + (2,))
    ky = cv2.getGaussianKernel(2 * int(truncate * sy + 0.5) + 1, sy, cv2.CV_32F) if sy > 0 else np.ones((1, 1), np.float32)
    kx = cv2.getGaussianKernel(2 * int(truncate * sx + 0.5) + 1, sx, cv2.CV_32F) if sx > 0 else np.ones((1, 1), np.float32)
    out = cv2.sepFilter2D(src, -1, kx, ky, borderType=cv2.BORDER_REPLICATE)
    return out.reshape(out.shape[:2] + (-1,)).view(np.complex64)[..., 0] if cplx else out


def smooth_complex(z: np.ndarray, sigma_px: float, grid: SamplingGrid) -> np.ndarray:
    """F3: Gaussian smoothing of the complex signal (real and imaginary parts), sigma in full-res px.

    Smoothing the complex signal rather than the wrapped phase lets weak regions
    inherit phase from the well-modulated grid lines around them (paper F3).
    """
    sy, sx = grid.step
    return gaussian_blur(z, (sigma_px / sy, sigma_px / sx), truncate=3.5)


def check_image_size(shape, period_px: float) -> None:
    """Raise :class:`InputError` unless at least 6 carrier periods fit across the image."""
    if min(shape) < 6.0 * period_px:
        raise InputError(
            f"the image ({shape[1]}x{shape[0]} px) is too small for the grid period ({period_px:.1f} px): "
            "at least 6 periods must fit across; use a finer grid or a larger crop"
        )
