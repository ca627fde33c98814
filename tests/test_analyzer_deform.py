"""F5, iterative deformation of the reference: the demodulation follows the local grid.

The truth is the synthetic displacement through the documented linear transfer of the
displacement output (:mod:`~glassdist.analyzer.transfer`): Block F's Gaussian ``G`` per
carrier (:func:`~glassdist.analyzer.demodulate.demodulation_blur_px2`) after one pass, and
``(1 - (1 - G B)^n) / B`` after ``n`` demodulations (``B`` the bilinear interpolation from the
demodulation grid), written out here in the spectrum (a line grid: each carrier's kernel
is axis-aligned and reads one displacement component).
"""

import numpy as np
import pytest
from scipy import ndimage

from glassdist import analyze
from glassdist.analyzer import deform as D
from glassdist.analyzer import fourier as F
from glassdist.analyzer.demodulate import covariances as _covariances
from glassdist.analyzer.demodulate import demodulation_blur_px2 as _demodulation_blur_px2
from glassdist.synthetic import synthetic_capture, wave_displacement

PITCH = 8.0  # mm, 1 mm/px: carrier period 8 px


@pytest.fixture(scope="module")
def strong_wave():
    # Peak strain 2 pi 4 / 80 = 0.31 of the carrier: the one-pass demodulation is no longer linear.
    return synthetic_capture((320, 400), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(4.0, 80.0, 30.0),
                             noise_std=0.01, rng=2)


def _through_transfer(t: np.ndarray, cov: np.ndarray, n: int, step, coarse, photo: int = 0,
                      restart_px: float = 0.0) -> np.ndarray:
    """``t`` (h, w) through the displacement output's transfer, in the spectrum of its odd-reflected extension.

    ``(1 - (1 - G B)^n) / B`` (n = 1: ``G``) on the demodulation grid (``step``), times the
    m x m block means of the analysis grid (``coarse`` = m step) and the cubic B-spline
    interpolation from it to the pixels (Unser 1999: ``sinc^4 / ((2 + cos 2 pi t) / 3)``).
    ``photo`` of the ``n`` are F5's photo passes, from the others' field low-passed by a Gaussian
    of ``restart_px``: the field before them is ``x = (1 - (1 - G B)^(n - photo)) / B``, after the
    low-pass ``L x``, and each photo pass moves it by ``G (1 - B x)``.
    """
    pad = 48
    ext = np.pad(t, pad, mode="reflect", reflect_type="odd")
    fy = np.fft.fftfreq(ext.shape[0])[:, None]
    fx = np.fft.rfftfreq(ext.shape[1])[None, :]
    G = np.exp(-2 * np.pi**2 * (cov[0, 0] * fx**2 + 2 * cov[0, 1] * fx * fy + cov[1, 1] * fy**2))
    B = np.sinc(step[0] * fy) ** 2 * np.sinc(step[1] * fx) ** 2
    gain = G if n == 1 else (1 - (1 - G * B) ** (n - photo)) / B
    if photo:
        gain = gain * np.exp(-2 * np.pi**2 * restart_px**2 * (fx**2 + fy**2))
        for _ in range(photo):
            gain = gain + G * (1 - B * gain)
    for f, s, S in ((fy, step[0], coarse[0]), (fx, step[1], coarse[1])):
        m = int(round(S / s))
        if m > 1:
            gain = gain * np.sinc(S * f) / np.sinc(s * f)  # mean of m samples s apart: sin(pi m s f) / (m sin(pi s f))
        if S > 1:
            gain = gain * np.sinc(S * f) ** 4 / ((2 + np.cos(2 * np.pi * S * f)) / 3)
    return np.fft.irfft2(np.fft.rfft2(ext) * gain, s=ext.shape)[pad:-pad, pad:-pad]


def _error_periods(cap, res) -> np.ndarray:
    """Displacement error (carrier periods) against the truth through Block F's linear transfer, interior only."""
    ks = res.carriers
    blur = _demodulation_blur_px2(ks, _covariances(ks, res.params), res.params)
    kx = 0 if abs(ks.k1.fx) > abs(ks.k1.fy) else 1  # the carrier along x reads the x component
    t = cap.displacement_mm
    step = res.demodulation_step_px  # the grid the phases were measured on (F5 may refine the one pass's)
    extra = (res.photo_passes, res.restart_sigma_px)
    sm = np.stack([_through_transfer(t[..., 0], blur[kx], res.demodulations, step, res.sampling_step_px, *extra),
                   _through_transfer(t[..., 1], blur[1 - kx], res.demodulations, step, res.sampling_step_px, *extra)],
                  axis=-1)
    v = res.valid.copy()
    v[:32] = v[-32:] = False
    v[:, :32] = v[:, -32:] = False
    e = res.displacement_mm - sm
    e -= e[v].mean(axis=0)
    if res.method == "direct":  # relative to the fitted homography: an affine term per component is free
        yy, xx = np.nonzero(v)
        B = np.stack([np.ones_like(xx), xx, yy], axis=1).astype(float)
        for c in range(2):
            coef, *_ = np.linalg.lstsq(B, e[..., c][v], rcond=None)
            e[..., c][v] -= B @ coef
    return e[v] / PITCH


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_deformation_reads_a_strong_wave_through_the_linear_transfer(strong_wave, method):
    ref = strong_wave.reference if method == "comparative" else None
    settings = {"sigma_mm": 16.0, "detrend_degree": 1}
    runs = {n: analyze(strong_wave.image, pitch_mm=PITCH, distance_m=10.0, reference=ref,
                       params={**settings, "deformation_passes": n, "analysis_block": 4}) for n in (0, 3)}
    one, f5 = (_error_periods(strong_wave, runs[n]) for n in (0, 3))
    # On 4 x 4 block means of the demodulation grid. One pass: 0.0066 period RMS, 0.018 at most (the bandpass's
    # non-linear response); deformed: 0.0018, 0.0098 (Comparative) and 0.0018, 0.0101 (Direct), on F5's grid of
    # twice the one pass's samples (0.0019, 0.0109 on the one pass's grid). The deformed output is no longer
    # smoothed by Block F's Gaussian (transfer ~1 at this wave): its peak error is the non-linear remainder and
    # the noise at full bandwidth.
    assert np.sqrt(np.mean(one**2)) > 0.004
    assert np.sqrt(np.mean(f5**2)) < 0.0021
    assert np.abs(f5).max() < 0.011
    assert runs[3].valid.mean() >= runs[0].valid.mean() - 0.005
    # By default Block A keeps F5's resolution (2 x 2 means: analysis_grid.BLOCK_MIN_RESPONSE). Those pass what 4 x 4
    # means removed, the passes' remainder at the carrier frequency (two thirds of the error power lies at
    # 0.09-0.16 cycles/px, the carrier's 0.125; 2 % with 4 x 4 means): 0.0032 period RMS, 0.0165 at most
    # (Comparative), 0.0033, 0.0165 (Direct); without noise 0.0029 and 0.0031.
    auto = analyze(strong_wave.image, pitch_mm=PITCH, distance_m=10.0, reference=ref,
                   params={**settings, "deformation_passes": 3})
    assert auto.sampling_step_px == pytest.approx(tuple(2 * s for s in auto.demodulation_step_px))
    e = _error_periods(strong_wave, auto)
    assert np.sqrt(np.mean(e**2)) < 0.0036
    assert np.abs(e).max() < 0.018


def test_phase_and_displacement_conversions_are_inverse_and_signed():
    pair = F.CarrierPair(F.Carrier(0.1, 0.02), F.Carrier(-0.03, 0.12))
    u = np.random.default_rng(0).normal(size=(5, 7, 2))
    ph = D.displacement_to_phase(u, pair)
    # The photo's carrier phase at r is the reference's at r - u: phi_i = -2 pi f_i . u.
    assert np.allclose(ph[..., 0], -2 * np.pi * (0.1 * u[..., 0] + 0.02 * u[..., 1]))
    assert np.allclose(D.phase_to_displacement_px(ph, pair), u)


def test_to_grid_keeps_sample_positions():
    # A plane a = 2 y - 0.5 x (px) sampled on one grid reads the same plane on another, between
    # the source's outer samples (bilinear); nearest takes the source sample nearest in position.
    src = F.SamplingGrid((256, 384), (64, 96))  # step 4
    dst = F.SamplingGrid((256, 384), (128, 192))  # step 2
    ys, xs = src.coords()
    yd, xd = dst.coords()
    a = (2 * ys - 0.5 * xs).astype(np.float32)
    out = D.to_grid(a, src, dst)
    inner = (yd >= ys.min()) & (yd <= ys.max()) & (xd >= xs.min()) & (xd <= xs.max())
    assert np.allclose(out[inner], (2 * yd - 0.5 * xd)[inner], atol=1e-3)
    near = D.to_grid(a, src, dst, nearest=True)
    iy = np.clip(np.rint((yd - src.offset[0]) / src.step[0]), 0, 63).astype(int)
    ix = np.clip(np.rint((xd - src.offset[1]) / src.step[1]), 0, 95).astype(int)
    assert np.array_equal(near, a[iy, ix])
    assert np.all(np.abs(ys[iy, ix] - yd) <= src.step[0] / 2 + 1e-9)


def test_deformation_grid_halves_the_step_only_where_the_reach_needs_it():
    # A quarter turn per sample at the reach: step <= period / (4 * 0.75) = period / 3.
    g = F.SamplingGrid((1024, 1024), (252, 252))  # step 4.06 px
    fine = D.deformation_grid(g, 0.75, 9.79, "auto")  # 9.79 / 3 = 3.26 < 4.06
    assert fine.shape == (504, 504) and fine.step[0] == pytest.approx(g.step[0] / 2)
    assert D.deformation_grid(g, 0.75, 12.5, "auto") is g  # 12.5 / 3 = 4.17 >= 4.06
    assert D.deformation_grid(g, 0.75, 9.79, 4) is g  # a user-set decimation is kept
    # twice the samples, but never more than the image's own (to a multiple of 4): 104 -> 100
    near_full = F.SamplingGrid((102, 130), (52, 64))
    assert D.deformation_grid(near_full, 0.75, 4.0, "auto").shape == (100, 128)
    assert D.deformation_grid(F.SamplingGrid((130, 102), (64, 52)), 0.75, 4.0, "auto").shape == (128, 100)  # columns


def test_growth_takes_coherent_small_residuals_within_reach_only():
    g = F.SamplingGrid((64, 64), (32, 32))  # step 2 px
    measured = np.zeros((32, 32), bool)
    measured[:, :10] = True
    coherent = np.ones((32, 32), bool)
    coherent[:16, 10:] = False  # upper half: no coherent grid beyond the region
    res = np.zeros((32, 32, 2))
    res[16:24, 11, 0] = 1.5  # a residual over 1 rad on one carrier: its whole period is not safe
    new = D.grow(measured, coherent, res, g, reach_px=4.0)  # two samples of 2 px
    assert set(np.nonzero(new.any(axis=0))[0]) == {10, 11}  # within reach of the region only
    assert not new[:16].any()  # never where the grid is not coherent
    assert new[16:, 10].all() and new[24:, 11].all() and not new[16:24, 11].any()
    assert not (new & measured).any()


def test_growth_never_merges_two_parts_of_the_one_pass():
    # Two measured parts three samples apart, coherent and converged between them: each grows,
    # but no new sample touches the other part's (a seam across an unmeasured band has no residue).
    g = F.SamplingGrid((40, 64), (20, 32))  # step 2 px
    measured = np.zeros((20, 32), bool)
    measured[:, :10] = measured[:, 13:] = True
    parts = np.where(measured, np.where(np.arange(32) < 10, 1, 2)[None, :], 0).astype(np.int32)
    new = D.grow(measured, np.ones((20, 32), bool), np.zeros((20, 32, 2)), g, reach_px=4.0, parts=parts)
    assert new.any()
    lab = np.where(measured | new, parts, 0)
    for a, b in ((1, 2), (2, 1)):
        near_b = ndimage.binary_dilation(lab == b, structure=np.ones((3, 3), bool))
        assert not (near_b & (lab == a)).any()
    # without the parts the same call closes the gap
    assert D.grow(measured, np.ones((20, 32), bool), np.zeros((20, 32, 2)), g, reach_px=4.0)[:, 10:13].all()


# --- F5's opt-in photo passes (deformation_photo_passes): the photo deformed back to the reference's frame ---


def _truth_phase_on(grid: F.SamplingGrid, cap, carriers) -> np.ndarray:
    """The generator's displacement (px, ``img(r) = ref(r - u)``) at ``grid``'s samples, as phases."""
    yy, xx = grid.coords()
    u = -np.stack([ndimage.map_coordinates(np.asarray(cap.displacement_mm)[..., i], [yy, xx], order=1) for i in range(2)],
                  axis=-1)  # 1 mm/px
    return D.displacement_to_phase(u, carriers)


def test_deformed_photo_undoes_the_displacement_and_to_frame_reads_r_minus_u(strong_wave):
    # Deformed by the generator's own displacement, the photo is the reference again (measured 0.9978: both
    # carry their own camera noise); by the opposite displacement it is not (-0.11), nor is the photo itself (0.10).
    ks = F.find_carriers(F.compute_spectrum(strong_wave.reference))
    grid = F.SamplingGrid(strong_wave.image.shape, (160, 200))  # step 2 px
    pred = _truth_phase_on(grid, strong_wave, ks)
    spline = D.photo_spline(strong_wave.image)
    inner = (slice(16, -16), slice(16, -16))

    def corr(a):
        return np.corrcoef(a[inner].ravel(), strong_wave.reference[inner].ravel())[0, 1]

    deformed, outside = D.deformed_photo(spline, pred, grid, ks)
    assert corr(deformed) > 0.997 and corr(strong_wave.image) < 0.5
    assert corr(D.deformed_photo(spline, -pred, grid, ks)[0]) < 0.5
    # the wave moves the grid by up to 4 px: samples within 4 px of the edge may draw from off the photo, none inside
    yy, xx = grid.coords()
    edge = np.minimum(np.minimum(yy, 319 - yy), np.minimum(xx, 399 - xx))
    assert outside.any() and not outside[edge > 4.5].any()
    # to_frame reads a signal of the reference's frame at r - u(r): a plane z = x - 2 y under a uniform
    # displacement u = (1.5, -0.5) px reads x - 1.5 - 2 (y + 0.5)
    u = np.broadcast_to(np.array([1.5, -0.5]), grid.shape + (2,))
    z = (xx - 2 * yy).astype(np.float32)
    out = D.to_frame(z, grid, D.displacement_to_phase(u, ks), grid, ks)
    assert np.allclose(out[4:-4, 4:-4], (xx - 1.5 - 2 * (yy + 0.5))[4:-4, 4:-4], atol=1e-3)


def test_own_shift_is_the_references_phase_across_the_displacement():
    # A reference grid 2 % finer than the carrier along x: own(s) = 2 pi 0.02 f s_x, so across a uniform
    # displacement u the Comparative phase differs from -2 pi f u by own(r - u) - own(r) = -2 pi 0.02 f u_x.
    from types import SimpleNamespace

    from glassdist.analyzer.deform import own_phasors as _own_phasors
    from glassdist.analyzer.deform import own_shift as _own_shift

    ks = F.CarrierPair(F.Carrier(0.125, 0.0), F.Carrier(0.0, 0.125))
    grid = F.SamplingGrid((128, 160), (64, 80))
    yy, xx = grid.coords()
    refm = SimpleNamespace(baseband=(np.exp(2j * np.pi * 0.02 * 0.125 * xx).astype(np.complex64),
                                     np.ones(grid.shape, np.complex64)))
    u = np.broadcast_to(np.array([3.0, -2.0]), grid.shape + (2,))
    shift = _own_shift(_own_phasors(refm, grid, grid, ks), grid, D.displacement_to_phase(u, ks), grid, ks)
    inner = (slice(4, -4), slice(4, -4))
    assert np.allclose(shift[inner][..., 0], -2 * np.pi * 0.02 * 0.125 * 3.0, atol=1e-4)
    assert np.allclose(shift[inner][..., 1], 0.0, atol=1e-6)
    assert _own_phasors(None, grid, grid, ks) is None
    assert _own_shift(None, grid, D.displacement_to_phase(u, ks), grid, ks) == 0.0


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_photo_passes_read_a_strong_wave_through_the_linear_transfer(strong_wave, method):
    # Three photo passes after the warped reference's, from its field low-passed (4 x 4 block means), against the
    # transfer with them (_through_transfer): 0.0011 period RMS, 0.0043 at most (Comparative), 0.0010, 0.0043
    # (Direct), against 0.0018, 0.0098 / 0.0101 without them. Resampling the photo bilinearly, or starting from
    # the warped reference's field itself, read worse (docs/explanation/transfer-function.md, "Photo deformation").
    ref = strong_wave.reference if method == "comparative" else None
    res = analyze(strong_wave.image, pitch_mm=PITCH, distance_m=10.0, reference=ref,
                  params={"sigma_mm": 16.0, "detrend_degree": 1, "deformation_passes": 3, "analysis_block": 4,
                          "deformation_photo_passes": 3})
    e = _error_periods(strong_wave, res)
    assert res.photo_passes == 3 and res.restart_sigma_px == pytest.approx(0.5 * 8.0, rel=0.01)
    assert np.sqrt(np.mean(e**2)) < 0.0013
    assert np.abs(e).max() < 0.005


def test_photo_passes_keep_the_comparative_phase_under_a_perspective_reference():
    # A reference seen in perspective has its own grid frequency varying over the view: the Comparative phase
    # carries own(r - u) - own(r) besides the displacement, which the deformation must not take for one.
    # Measured: 0.0045 period RMS with three photo passes, 0.0072 without them; 0.0219 when the deformation
    # took the Comparative phase for the displacement.
    Hm = np.array([[1.0, 0.02, 0.0], [0.0, 1.0, 0.0], [4e-4, 2e-4, 1.0]])
    cap = synthetic_capture((320, 400), pitch_mm=PITCH, mm_per_px=1.0, displacement=wave_displacement(4.0, 80.0, 30.0),
                            noise_std=0.01, rng=2, homography=Hm)
    res = analyze(cap.image, pitch_mm=PITCH, distance_m=10.0, reference=cap.reference,
                  params={"sigma_mm": 16.0, "detrend_degree": 1, "deformation_passes": 3, "analysis_block": 4,
                          "deformation_photo_passes": 3})
    assert np.sqrt(np.mean(_error_periods(cap, res) ** 2)) < 0.0055


def test_off_frame_marks_where_the_photo_shows_what_the_reference_does_not():
    # A uniform displacement u = (5, -3) px: the photo's samples r with r - u(r) off the image are the columns
    # x < 5 and the rows y > H - 1 - 3, in closed form.
    ks = F.CarrierPair(F.Carrier(0.125, 0.0), F.Carrier(0.0, 0.125))
    grid = F.SamplingGrid((128, 160), (64, 80))  # step 2 px
    yy, xx = grid.coords()
    u = np.broadcast_to(np.array([5.0, -3.0]), grid.shape + (2,))
    off = D.off_frame(D.displacement_to_phase(u, ks), grid, ks)
    assert np.array_equal(off, (xx < 5.0) | (yy > 127 - 3.0))


def test_photo_passes_leave_what_the_reference_never_saw_to_the_warped_reference():
    # The strong wave on top of a uniform 12 px shift: the photo's first 12 columns show the backdrop beyond the
    # reference's view, and no sample of the deformed photo draws from them. Their residual, read at r - u(r)
    # off the image, was the edge's, every pass: after 8 passes their error against the truth through the
    # transfer was 0.049 period RMS (0.031 after 2), where the warped reference alone reads 0.0106. Taking the
    # warped reference's residual there (deform.off_frame): 0.0094 after 8 passes, 0.0105 after 2.
    wave = wave_displacement(4.0, 80.0, 30.0)

    def shifted(X, Y):
        a, b = wave(X, Y)
        return a + 12.0, b

    cap = synthetic_capture((320, 400), pitch_mm=PITCH, mm_per_px=1.0, displacement=shifted, noise_std=0.01, rng=2)
    res = analyze(cap.image, pitch_mm=PITCH, distance_m=10.0, reference=cap.reference,
                  params={"sigma_mm": 16.0, "detrend_degree": 1, "deformation_passes": 3, "analysis_block": 4,
                          "deformation_photo_passes": 8})
    ks = res.carriers
    blur = _demodulation_blur_px2(ks, _covariances(ks, res.params), res.params)
    kx = 0 if abs(ks.k1.fx) > abs(ks.k1.fy) else 1
    sm = _through_transfer(cap.displacement_mm[..., 0], blur[kx], res.demodulations, res.demodulation_step_px,
                           res.sampling_step_px, res.photo_passes, res.restart_sigma_px)
    e = (res.displacement_mm[..., 0] - sm) / PITCH
    inner, band = res.valid.copy(), res.valid.copy()
    inner[:32] = inner[-32:] = band[:32] = band[-32:] = False
    inner[:, :40] = inner[:, -40:] = False
    band[:, 12:] = False
    assert band.sum() > 1000
    e -= e[inner].mean()
    assert np.sqrt(np.mean(e[band] ** 2)) < 0.012


def test_photo_passes_run_by_default_in_the_comparative_method_only(strong_wave):
    # deformation_photo_passes 'auto': 6 with a reference, none without (docs/explanation/transfer-function.md, "Why the
    # Comparative Method only"); an integer applies to both methods, and out-of-range values are refused.
    from glassdist.analyzer.params import AUTO_PHOTO_PASSES, load_params
    from glassdist.errors import InputError

    p = load_params()
    assert p.deformation_photo_passes == "auto"
    assert (p.photo_passes_for(True), p.photo_passes_for(False)) == (AUTO_PHOTO_PASSES, 0) == (6, 0)
    assert load_params({"deformation_photo_passes": 2}).photo_passes_for(False) == 2
    with pytest.raises(InputError):
        load_params({"deformation_photo_passes": 9})
    settings = {"sigma_mm": 16.0, "detrend_degree": 1}
    comparative = analyze(strong_wave.image, pitch_mm=PITCH, distance_m=10.0, reference=strong_wave.reference,
                          params=settings)
    direct = analyze(strong_wave.image, pitch_mm=PITCH, distance_m=10.0, params=settings)
    assert comparative.photo_passes > 0 and direct.photo_passes == 0
