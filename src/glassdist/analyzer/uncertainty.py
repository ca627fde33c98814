"""Per-pixel standard uncertainty from the image noise, propagated in closed form.

The image noise is taken as white with standard deviation ``s`` (intensity units),
estimated from the photo itself: the median power of its spectrum away from the
grid's lattice of carriers, harmonics and cross terms (:func:`noise_std`).

Propagation (all operators linear, Gaussian kernels, so every step is closed form):

* **Demodulation** (F1-F3): the baseband signal ``b = A/2 exp(i phi)`` picks up
  complex circular noise of power ``s^2 int |H|^2``, ``H`` the transfer function of the
  bandpass and the complex smoothing; its component across ``b`` moves the phase,

  .. math:: \\operatorname{var}\\varphi = \\frac{s^2}{2|b|^2}\\int |H(\\nu)|^2 d\\nu
            = \\frac{s^2}{2|b|^2}\\,\\frac{1}{4\\pi\\sqrt{\\det C}},

  for a Gaussian of spatial covariance ``C`` (px^2): ``4 pi sqrt(det C)`` is the
  effective number of samples of the filter. The Comparative Method adds the
  reference's term (its own noise and modulation).
* **Unwrapping** (F4) adds multiples of 2 pi only: no change where it is consistent.
* **Block A**: block means, the metric smoothing and the differentiation are further
  linear filters; the phase noise's spectrum times the squared transfer function of
  the whole chain (total covariance ``C_t``) integrates to

  .. math:: \\operatorname{cov}(\\nabla\\varphi) = \\frac{s^2}{2|b|^2}\\,
            \\frac{C_t^{-1}}{8\\pi\\sqrt{\\det C_t}} \\quad (\\mathrm{rad^2/px^2}),

  then the map from phases to displacement (``T``, mm per rad) and from image px to
  backdrop mm (``W = J^{-1}``) give the strain's covariance, and the channels follow:
  phi_eff (linear) exactly; phi_shear linearised along the measured shear direction
  (for a shear smaller than about twice its uncertainty it is Rice-distributed, biased
  upwards, and the value given is the linearised one).

* **F5** (iterative deformation): each pass demodulates the photo against a reference
  synthesised from the prediction, so the same noise re-enters every pass. In the linear
  regime of the transfer module (:mod:`~glassdist.analyzer.transfer`), after ``n``
  demodulations the photo's phase noise has gone through ``k_n`` and the reference's
  through ``r_n``:

  .. math:: k_1 = r_1 = C, \\quad k_{j+1} = k_j + C\\,(1 - B k_j), \\quad
            r_{j+1} = r_j + C B\\,(B_1 - r_j),

  ``C`` the Gaussian stages, ``B`` the bilinear interpolation of the prediction and of the
  reference's baseband into the synthesised reference, ``B_1`` the bandpass alone (the
  reference enters through its baseband, :func:`deformation_noise_gains`). ``k_n`` tends to
  ``1 / B``: the converged displacement keeps the photo's noise that one pass smoothed away
  (1.7 times the one-pass sigma after 5 demodulations on a strong wave); the reference's
  stays near ``B_1``. The displacement's variance is the one-pass closed form times these
  gains. Block A divides out the signal's response (``k_n``) and applies ``G_sigma``, so
  the photo's term reaches the channels through ``G_sigma`` as in one pass, and the
  reference's through ``(r_n / k_n) G_sigma``, a little less (:func:`deformation_channel_gain`).
  After F5's photo passes the photo's phase noise level ``s^2 / (2 |b|^2)`` takes the deformed
  photo's modulation, at the carrier, for ``|b|``: the one the last pass measured at.

* **A2 detrend** (:func:`detrended_gradient_covariance`): the noise's own polynomial of
  degree N is removed with the glass's, and Block A's first-order normalised smoothing fits a
  plane at every sample, whose slope is noisier near the region's border. For a white phase
  noise of level ``w`` both are linear least squares and their gradient covariance is exact:
  ``w (E(x) - (S b)^T G^-1 (S b))``, ``E`` the plane fit's own (``I / (8 pi sigma^4)`` inside),
  ``b`` the detrend's monomials, ``G`` their Gram matrix over the region and ``S b`` their
  slope through the same plane fit. Where sigma is a fair part of the region that takes most
  of the smoothed noise (at sigma = 3 carrier periods, N = 4, on a view of 18 x 14 periods
  the prediction without it was three times the scatter of repeated captures).

The carriers' noises are independent (disjoint bands of a white spectrum), and so are
the image's and the reference's. Near region borders the first-order normalised
convolution averages fewer samples than the formula assumes (the uncertainty there is
larger; those pixels are in the guard band of the quality map).

Not included: the Direct Method's baseline (Block I's homography) moves with the noise
too. Its change is affine plus two projective terms; the detrend removes the affine part,
and at degree 1 the projective terms' strain remains, a plane in phi_eff. On a strongly
distorted view that motion is set by Block I's discrete choices (RANSAC's consensus, the
samples called undistorted, the winning candidate), not by a linear propagation of the
phase noise, and it is not predicted here: at strain 0.31 and degree 1 the scatter of
phi_eff over repeated captures reads 1.3-2.3 times the predicted sigma on 320 x 400 px
(noise 0.06-0.01; 2.9-3.8 on 256 x 320 px; ``benchmarks/uncertainty_strong.py``,
``docs/transfer_function.md``).

References
----------
Paper §2.2 (F1-F3, A2-A3). Takeda et al. (1982) for the demodulation; the noise of a
phase estimate: Rife & Boorstyn (1974), IEEE Trans. Inf. Theory 20, 591.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import fourier as F
from .metrics import inverse_2x2

__all__ = [
    "PhaseNoise",
    "phase_noise",
    "field_uncertainty",
    "noise_std",
    "phase_variance",
    "gradient_covariance",
    "ChannelUncertainty",
    "channel_uncertainty",
    "displacement_sigma",
    "deformation_noise_gains",
    "deformation_channel_gain",
    "detrended_gradient_covariance",
]


def noise_std(spectrum: F.Spectrum, carriers: F.CarrierPair, *, exclusion: float = 0.3, max_bins: int = 100_000) -> float:
    """Standard deviation of the image's white noise, intensity units, from its spectrum.

    The grid's power sits on the lattice ``n1 f1 + n2 f2`` (carriers, harmonics, cross
    terms and DC); bins farther than ``exclusion * min |f_i|`` from every lattice point
    hold the noise (and little else). For white noise of variance ``s^2`` the
    unnormalised FFT power ``|F|^2`` is exponential with mean ``H W s^2``; its lower
    quartile, ``ln(4/3)`` times the mean, is used (the sidebands of a strongly modulated
    grid and aliased harmonics sit in the upper tail). On noise-free synthetic grids the
    estimate is not zero but ~0.002-0.006 of full scale (aliasing, sidebands): an upper
    bound at very low noise.

    Parameters
    ----------
    spectrum : Spectrum
        Real FFT of the image (:func:`~glassdist.analyzer.fourier.compute_spectrum`).
    carriers : CarrierPair
    exclusion : float
        Radius excluded around each lattice point, in units of the shorter carrier's |f|.
    max_bins : int
        At most about this many bins are used (a regular subsample of large spectra).

    Returns
    -------
    float
        ``s`` in the image's intensity units (0 for a noise-free image).
    """
    H, W = spectrum.shape
    rf = spectrum.rfft
    k = max(1, int(np.ceil(np.sqrt(rf.size / max_bins))))
    fy = (np.fft.fftfreq(H)[::k, None]).astype(np.float32)
    fx = (np.arange(rf.shape[1])[None, ::k] / W).astype(np.float32)
    M = carriers.matrix.T  # columns f1, f2 (x, y)
    Minv = np.linalg.inv(M)
    a1 = Minv[0, 0] * fx + Minv[0, 1] * fy
    a2 = Minv[1, 0] * fx + Minv[1, 1] * fy
    n1, n2 = np.rint(a1), np.rint(a2)
    dx = fx - (M[0, 0] * n1 + M[0, 1] * n2)
    dy = fy - (M[1, 0] * n1 + M[1, 1] * n2)
    fmin = min(carriers.k1.norm, carriers.k2.norm)
    keep = np.hypot(dx, dy) > exclusion * fmin
    # Bins on the stored half-plane's first column carry both +f and -f: fine, same statistics.
    p = np.abs(rf[::k, ::k][keep]) ** 2
    if p.size < 64:
        return float("nan")
    q = float(np.partition(p, p.size // 4)[p.size // 4])
    return float(np.sqrt(q / (np.log(4.0 / 3.0) * H * W)))


def _det_inv(C: np.ndarray):
    return C[..., 0, 0] * C[..., 1, 1] - C[..., 0, 1] * C[..., 1, 0], inverse_2x2(C)


def phase_variance(white: np.ndarray, cov_px2: np.ndarray) -> np.ndarray:
    """Variance (rad^2) of a phase after a Gaussian low-pass of covariance ``cov_px2``.

    Parameters
    ----------
    white : ndarray
        Phase noise level ``s^2 / (2 |b|^2)`` (summed over the photos), rad^2 px^2.
    cov_px2 : ndarray (2, 2)
        Spatial covariance of the whole filter chain applied to the baseband noise, px^2.
    """
    det = float(np.linalg.det(cov_px2))
    return white / (4 * np.pi * np.sqrt(det))


def gradient_covariance(white: np.ndarray, cov_px2: np.ndarray) -> np.ndarray:
    """Covariance (rad^2/px^2) of the phase gradient ``(d/dx, d/dy)`` after the low-pass; shape ``white.shape + (2, 2)``."""
    det, inv = _det_inv(np.asarray(cov_px2, float))
    return np.asarray(white)[..., None, None] * (inv / (8 * np.pi * np.sqrt(det)))


@dataclass(frozen=True)
class ChannelUncertainty:
    """Standard uncertainties of the A3 channels (mD), arrays on the analysis grid."""

    phi_eff_sigma_mD: np.ndarray
    phi_shear_sigma_mD: np.ndarray


def _bilinear(Q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a^T Q b`` for stacks of 2-vectors ``(..., 2)`` and of 2 x 2 matrices ``(..., 2, 2)``."""
    return (a[..., 0] * (Q[..., 0, 0] * b[..., 0] + Q[..., 0, 1] * b[..., 1])
            + a[..., 1] * (Q[..., 1, 0] * b[..., 0] + Q[..., 1, 1] * b[..., 1]))


def channel_uncertainty(
    grad_cov: tuple[np.ndarray, np.ndarray],
    T: np.ndarray,
    W: np.ndarray,
    strain: np.ndarray,
    distance_m: float,
) -> ChannelUncertainty:
    """Propagate the phase-gradient covariances of the two carriers to phi_eff and phi_shear.

    Parameters
    ----------
    grad_cov : (ndarray (h, w, 2, 2), ndarray (h, w, 2, 2))
        Covariance of ``grad phi_i`` (rad^2/px^2, (x, y) order) for carriers 1 and 2.
    T : ndarray (2, 2)
        ``delta_c = sum_i T[c, i] phi_i``: mm of displacement per rad, in the frame of the
        displacement components.
    W : ndarray (2, 2) or (h, w, 2, 2)
        ``d/dX_a = sum_b W[b, a] d/dr_b``: the inverse Jacobian (px per mm) in that frame.
    strain : ndarray (h, w, 2, 2)
        The measured strain in that frame (sets the direction of the shear).
    distance_m : float
        L, m.
    """
    W = np.asarray(W, float)
    var_tr: np.ndarray | float = 0.0
    c_aa: np.ndarray | float = 0.0
    c_bb: np.ndarray | float = 0.0
    c_ab: np.ndarray | float = 0.0
    for i, Q in enumerate(grad_cov):
        # x^T Cg y with Cg = W^T Q W the covariance of g_i = W^T grad phi_i (rad^2/mm^2): (W x)^T Q (W y),
        # elementwise (a stack of 2 x 2 matrix products costs several times more)
        t = T[:, i]
        Wt_, Wu, Wv = (W[..., :, 0] * x[0] + W[..., :, 1] * x[1]
                       for x in (t, np.array([t[0], -t[1]]) / 2.0, np.array([t[1], t[0]]) / 2.0))
        var_tr = var_tr + _bilinear(Q, Wt_, Wt_)
        c_aa = c_aa + _bilinear(Q, Wu, Wu)
        c_bb = c_bb + _bilinear(Q, Wv, Wv)
        c_ab = c_ab + _bilinear(Q, Wu, Wv)
    scale = 1000.0 / distance_m
    a = 0.5 * (strain[..., 0, 0] - strain[..., 1, 1])
    b = 0.5 * (strain[..., 0, 1] + strain[..., 1, 0])
    r = np.hypot(a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        na, nb = np.where(r > 0, a / r, 1.0), np.where(r > 0, b / r, 0.0)
    var_sh = 4.0 * (na * na * c_aa + 2 * na * nb * c_ab + nb * nb * c_bb)
    return ChannelUncertainty(
        (scale * np.sqrt(var_tr)).astype(np.float32), (scale * np.sqrt(np.maximum(var_sh, 0.0))).astype(np.float32)
    )


def displacement_sigma(phase_var: tuple[np.ndarray, np.ndarray], T: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
    """Standard uncertainty (mm) of the camera-frame displacement components, (h, w, 2).

    ``delta_cam = (T phi) @ R`` (row-vector form, ``R`` the frame rotation; identity when None).
    """
    A = T if R is None else R.T @ T  # delta_cam = A phi
    var = A[:, 0] ** 2 * phase_var[0][..., None] + A[:, 1] ** 2 * phase_var[1][..., None]
    return np.sqrt(var).astype(np.float32)


def deformation_noise_gains(transfer, component: int, bandpass_px2: np.ndarray, *, samples: int = 128) -> tuple[float, float]:
    """Variance gains of a displacement component's phase noise after F5's passes: ``(photo, reference)``.

    Relative to one pass (module notes, **F5**): ``int |k_n N|^2 / int |C N|^2`` and
    ``int |r_n N|^2 / int |C N|^2``, ``N`` the block means and the interpolation to the
    pixel grid, summed on a frequency grid that resolves ``C``.

    Parameters
    ----------
    transfer : InstrumentTransfer
        The Analyzer's transfer (:mod:`~glassdist.analyzer.transfer`): the Gaussian stages'
        covariance ``C`` per carrier, the demodulation grid's step (``B``), the block means,
        the interpolation step and ``passes`` (``n``).
    component : int
        Carrier 0 or 1.
    bandpass_px2 : ndarray (2, 2)
        Spatial covariance (px^2) of that carrier's bandpass alone (``B_1``).
    samples : int
        Frequency samples per axis (the sums of Gaussians converge fast: 128 and 1024 agree to 5 digits
        on the strong wave's transfer, a 1 px kernel and a 30 px one).

    Returns
    -------
    (float, float)
        ``(1.0, 1.0)`` for one pass.
    """
    if transfer.total_passes <= 1:
        return 1.0, 1.0
    cov = np.asarray(transfer.gaussian_px2[component], float)
    # C is negligible beyond 5 of its frequency sigmas (1 / (2 pi sigma_px)) along its narrowest spatial axis
    fy, fx = _frequencies(5.0 / (2 * np.pi * np.sqrt(float(np.linalg.eigvalsh(cov)[0]))), samples)
    C, k, r = _pass_responses(transfer, component, bandpass_px2, fy, fx)
    N2 = np.abs(transfer.non_gaussian(fy, fx)) ** 2
    one = float(np.sum(C**2 * N2))
    return float(np.sum(k**2 * N2)) / one, float(np.sum(r**2 * N2)) / one


def deformation_channel_gain(transfer, component: int, bandpass_px2: np.ndarray, sigma_px: float, *,
                             samples: int = 128) -> float:
    """Variance gain of the reference's term in the channels' gradient noise after F5's passes.

    Block A divides out the signal's response ``k_n`` (the photo's noise goes through it too)
    and applies ``G_sigma``: the photo's term reaches the channels through ``G_sigma`` alone,
    the reference's through ``(r_n / k_n) G_sigma`` (module notes, **F5**). Returned:
    ``int |nu|^2 |r_n / k_n|^2 G_sigma^2 / int |nu|^2 G_sigma^2`` (1.0 for one pass).

    Parameters
    ----------
    transfer, component, bandpass_px2, samples
        As :func:`deformation_noise_gains`.
    sigma_px : float
        The reporting smoothing's sigma reached, px.
    """
    if transfer.total_passes <= 1:
        return 1.0
    fy, fx = _frequencies(5.0 / (2 * np.pi * float(sigma_px)), samples)
    _, k, r = _pass_responses(transfer, component, bandpass_px2, fy, fx)
    w = (fx**2 + fy**2) * np.exp(-4.0 * np.pi**2 * float(sigma_px) ** 2 * (fx**2 + fy**2))
    return float(np.sum(w * (r / k) ** 2) / np.sum(w))


def _frequencies(f_max: float, samples: int):
    f = np.linspace(-min(0.5, f_max), min(0.5, f_max), samples, endpoint=False)
    return f[:, None], f[None, :]


def _pass_responses(transfer, component: int, bandpass_px2, fy, fx):
    """``(C, k_n, r_n)`` at ``(fy, fx)`` cycles/px: the Gaussian stages and the photo's and the reference's noise transfer.

    The recursions of the module notes in closed form: ``k_n`` is the signal's own response
    (:meth:`~glassdist.analyzer.transfer.InstrumentTransfer.demodulation`), and
    ``r_n = B_1 + (C - B_1) (1 - C B)^(n - 1)``. F5's photo passes heterodyne the deformed photo
    against the reference's baseband itself, ``r_(j+1) = r_j + C (B_1 - B r_j)``, from the low-pass
    ``L r_n`` of the warped reference's: ``r = B_1 / B + (L r_n - B_1 / B) (1 - C B)^k``.
    """
    from .transfer import gaussian_response

    C = gaussian_response(np.asarray(transfer.gaussian_px2[component], float), fy, fx)
    B1 = gaussian_response(np.asarray(bandpass_px2, float), fy, fx)
    B = transfer.prediction_interpolation(fy, fx)
    r = B1 + (C - B1) * (1.0 - C * B) ** (int(transfer.passes) - 1)
    if transfer.photo_passes > 0:
        L = gaussian_response(float(transfer.restart_sigma_px) ** 2 * np.eye(2), fy, fx)
        r = B1 / B + (L * r - B1 / B) * (1.0 - C * B) ** int(transfer.photo_passes)
    return C, transfer.demodulation(component, fy, fx), r


def detrended_gradient_covariance(labels: np.ndarray, degree: int, sigma_px: float,
                                  step_px: tuple[float, float]) -> np.ndarray:
    """Covariance (h, w, 2, 2), px^-4 per unit white level, of the detrended, smoothed field's gradient.

    Module notes (**A2 detrend**). Per region of ``labels`` (0 excluded; each detrended and
    smoothed on its own, as :func:`~glassdist.analyzer.detrend.polynomial_detrend` and Block A's
    smoothing treat them), the smoothing is the first-order normalised Gaussian of ``sigma_px``:
    at every sample a Gaussian-weighted plane fit, of weights ``g`` and regressors
    ``Phi = (1, x' - x, y' - y)``, whose slope is the gradient. For a white noise of level 1
    that slope's covariance is the gradient block of ``M^-1 N M^-1``, ``M = sum g Phi Phi^T dA``,
    ``N = sum g^2 Phi Phi^T dA`` (``g^2`` is the Gaussian of ``sigma / sqrt 2`` over
    ``4 pi sigma^2``): ``I / (8 pi sigma^4)`` inside (:func:`gradient_covariance`), larger near
    the border. The detrend first removes the noise's least-squares polynomial of total degree
    ``degree`` (monomials ``b``, Gram matrix ``G = sum b b^T dA``, coefficients of covariance
    ``G^-1``): less ``(S b)^T G^-1 (S b)``, ``S b`` the same slope of each monomial. Sums over the
    samples of a grid of ``step_px`` = ``(sy, sx)`` px, ``dA = sy sx``.
    """
    from scipy import ndimage

    from .detrend import _monomials

    h, w = labels.shape
    sy, sx = float(step_px[0]), float(step_px[1])
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    yy, xx = yy * sy, xx * sx
    out = np.zeros((h, w, 2, 2))
    n_terms = (degree + 1) * (degree + 2) // 2
    for r in range(1, int(labels.max(initial=0)) + 1):
        region = labels == r
        iy, ix = np.nonzero(region)
        if iy.size < 2 * n_terms:
            continue
        box = (slice(iy.min(), iy.max() + 1), slice(ix.min(), ix.max() + 1))
        reg, X, Y = region[box], xx[box], yy[box]
        cx, cy = X[reg].mean(), Y[reg].mean()
        X, Y = X - cx, Y - cy
        m = reg.astype(np.float64)

        def g(a, s_px):
            return ndimage.gaussian_filter(a, (s_px / sy, s_px / sx), mode="constant", truncate=4.0)

        def about(s_px):  # sum g Phi Phi^T over the region, about each sample
            m0, mx, my = g(m, s_px), g(m * X, s_px), g(m * Y, s_px)
            mxx, mxy, myy = g(m * X * X, s_px), g(m * X * Y, s_px), g(m * Y * Y, s_px)
            ax, ay = mx - X * m0, my - Y * m0
            axx = mxx - 2 * X * mx + X * X * m0
            ayy = myy - 2 * Y * my + Y * Y * m0
            axy = mxy - X * my - Y * mx + X * Y * m0
            return np.stack([np.stack([m0, ax, ay], -1), np.stack([ax, axx, axy], -1), np.stack([ay, axy, ayy], -1)], -2)

        M = about(sigma_px)
        N = about(sigma_px / np.sqrt(2.0)) / (4 * np.pi * sigma_px**2)
        ok = reg & (M[..., 0, 0] > 1e-6)
        Mi = np.linalg.inv(M[ok])
        E = (Mi @ N[ok] @ Mi)[:, 1:, 1:]
        sc = max(float(np.ptp(X[reg])), float(np.ptp(Y[reg])), 1.0) / 2.0
        B = _monomials(X / sc, Y / sc, degree)  # the detrend's monomials (its own scaling)
        Gi = np.linalg.pinv(np.einsum("nk,nl->kl", B[reg], B[reg]) * (sy * sx))
        # S b: the plane fit's slope of each monomial, from sum g Phi b about each sample
        Sb = np.empty((int(ok.sum()), 2, n_terms))
        for k in range(n_terms):
            bk = m * B[..., k]
            v0, vx, vy = g(bk, sigma_px), g(bk * X, sigma_px), g(bk * Y, sigma_px)
            rhs = np.stack([v0, vx - X * v0, vy - Y * v0], -1)[ok]
            Sb[:, :, k] = np.einsum("nij,nj->ni", Mi, rhs)[:, 1:]
        Q = np.einsum("nak,kl,nbl->nab", Sb, Gi, Sb)
        sub = out[box]
        sub[ok] = E - Q
    return out


# --------------------------------------------------------------------------- the analysis's fields
# --------------------------------------------------------------------------- the analysis's fields


@dataclass(frozen=True)
class PhaseNoise:
    """Phase noise levels ``s^2 / (2 |b|^2)`` per carrier on the Block A grid (rad^2 px^2), and the filters they went through."""

    photo: tuple[np.ndarray, ...]
    reference: tuple[np.ndarray, ...] | None  # independent of the photo's; None: Direct Method
    blur: np.ndarray  # (2, 2, 2): per carrier, spatial covariance (px^2) of the low-pass up to that grid
    bandpass: np.ndarray  # (2, 2, 2): that of the bandpass alone (F5's reference term)


def phase_noise(mods: tuple[np.ndarray, ...], noise: tuple[float, float | None], fine: F.SamplingGrid,
                agrid: F.SamplingGrid, blur_px2: np.ndarray, bandpass_px2: np.ndarray) -> PhaseNoise:
    """The photo's and the reference's phase noise levels on the Block A grid and Block F's filters.

    ``mods``: the modulations on the demodulation grid ``fine`` (the photo's two, then the
    reference's in the Comparative Method); ``noise``: the photo's and the reference's
    white-noise standard deviations (None: Direct Method); ``blur_px2`` and ``bandpass_px2``:
    Block F's low-pass and its bandpass alone, per carrier (px^2). The block means of the
    Block A grid ``agrid`` add their own variance (a box of ``m`` samples: ``(m step)^2 / 12``).
    """
    m = fine.shape[0] // agrid.shape[0]
    ones = np.ones(fine.shape, np.float32)

    def level(s: float, ms: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        out = []
        for mod in ms:
            w_ = (s**2 / (2 * np.maximum(mod.astype(np.float64), 1e-12) ** 2)).astype(np.float32)
            out.append(F.block_mean(w_, ones, m)[0] if m > 1 else w_)
        return tuple(out)

    blur = blur_px2
    if m > 1:
        blur = blur + (m * max(fine.step)) ** 2 / 12.0 * np.eye(2)
    ref_noise = noise[1]
    return PhaseNoise(level(noise[0], mods[:2]), None if ref_noise is None else level(ref_noise, mods[2:4]),
                      blur, bandpass_px2)


def field_uncertainty(report: np.ndarray, transfer, noise: PhaseNoise, strain: np.ndarray, a1,
                      sigma_px: float, distance_m: float, detrend: tuple | None = None) -> dict[str, np.ndarray]:
    """Standard uncertainties of the displacement and the channels from the image noise (registered fields).

    The phase noise (:func:`phase_noise`) through Block F's kernel (and the block means),
    times F5's gains when its passes ran (``transfer``, an
    :class:`~glassdist.analyzer.transfer.InstrumentTransfer` or None), gives the displacement's;
    through the whole chain, the metric smoothing included, and the differentiation, the
    channels'. ``a1``: the :class:`~glassdist.analyzer.components.A1Map` (mm per rad, px per mm,
    frame rotation, compensated blur); ``strain``: the channels' strain (camera frame). NaN
    outside ``report``. ``detrend``: ``(labels, degree, step_px)`` of the A2 detrend on this
    grid, whose removal of the noise's own polynomial the channels' uncertainty takes off
    (:func:`detrended_gradient_covariance`); None: not taken off. Returns ``phi_eff_sigma_mD``,
    ``phi_shear_sigma_mD`` and ``displacement_sigma_mm`` (the displacement is not detrended).
    """
    blur, photo, ref, bandpass = noise.blur, noise.photo, noise.reference, noise.bandpass
    tr = transfer
    var, grad_cov = [], []
    for i in range(2):
        g_photo, g_ref = (1.0, 1.0) if tr is None else deformation_noise_gains(tr, i, bandpass[i])
        g_chan = 1.0 if tr is None or ref is None else deformation_channel_gain(tr, i, bandpass[i],
                                                                                tr.effective_sigma_px(sigma_px))
        var.append(phase_variance(photo[i] * np.float32(g_photo) + (0.0 if ref is None else ref[i] * np.float32(g_ref)),
                                  blur[i]))
        s_eff = sigma_px if tr is None else tr.effective_sigma_px(sigma_px)
        metric = s_eff**2 * np.eye(2)
        if a1.blur is not None:  # the metric smoothing tops the demodulation blur up to the sigma reached
            ev, V = np.linalg.eigh(metric - a1.blur[i])
            metric = (V * np.clip(ev, 0.0, None)) @ V.T
        white = photo[i] if ref is None else photo[i] + ref[i] * np.float32(g_chan)
        if detrend is None:
            grad_cov.append(gradient_covariance(white, blur[i] + metric))
        else:  # the plane fit's own border term, less what the detrend takes
            labels, degree, step = detrend
            s_tot = float(np.sqrt(np.mean(np.linalg.eigvalsh(blur[i] + metric))))
            grad_cov.append(np.asarray(white, np.float64)[..., None, None]
                            * detrended_gradient_covariance(labels, degree, s_tot, step))
    disp = displacement_sigma((var[0], var[1]), a1.T, a1.R)
    strain = strain if a1.R is None else a1.R @ strain @ a1.R.T  # back to the component frame
    unc = channel_uncertainty((grad_cov[0], grad_cov[1]), a1.T, a1.W, strain, distance_m)
    out = {"phi_eff_sigma_mD": unc.phi_eff_sigma_mD, "phi_shear_sigma_mD": unc.phi_shear_sigma_mD,
           "displacement_sigma_mm": disp}
    for f_ in out.values():
        f_[~report] = np.nan
    return out
