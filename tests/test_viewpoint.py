"""The pane's intrinsic reading, the view from another point and the comparison of two captures (normal incidence).

Scenes are generated here: a 6 mm pane (n = 1.52) larger than the view, the camera on the
pane normal through its centre, aimed at it, its field covering +-500 mm of the pane at
every distance (same pane point per pixel), the backdrop's lines 12 px a period, the
smoothing 40 mm on the pane (sigma_b = 40 (Dc + L) / Dc). The truths are the exact
tracer's landing points through ``tests/_truth.py`` (never the analyzer's stack) on the
region the result documents.
"""

import json

import numpy as np
import pytest

import _truth
from glassdist.analyzer.metrics import channel_statistics
from glassdist.cli import main
from glassdist.render import landing_points, render_scene
from glassdist.scene import landing_jacobian, scene_from_dict

N_GLASS = 1.52
PANE_SIGMA_MM = 40.0
HALF_VIEW_MM = 500.0
PIXELS = (320, 240)
WAVE = {"front": [{"kind": "roller_wave", "amplitude_mm": 0.6, "wavelength_mm": 400, "direction_deg": 0}]}
OTHER_WAVE = {"front": [{"kind": "roller_wave", "amplitude_mm": 0.75, "wavelength_mm": 400, "direction_deg": 0}]}
# a converging lens of P = (n - 1) 2 A / s^2 = 36 mD at its centre (thickening 2 A, Gaussian of s)
LENS_A_MM, LENS_S_MM = 1.0, 170.0
LENS = {"front": [{"kind": "gaussian", "amplitude_mm": -LENS_A_MM, "sigma_mm": LENS_S_MM, "center_mm": [0, 0]}],
        "back": [{"kind": "gaussian", "amplitude_mm": LENS_A_MM, "sigma_mm": LENS_S_MM, "center_mm": [0, 0]}]}


def pane_scene(deformation, Dc_m, L_m, *, pixels=PIXELS, pane_sigma_mm=PANE_SIGMA_MM, detrend=2, spp=16, seed=1):
    W, H = pixels
    mpp = 2 * HALF_VIEW_MM * (Dc_m + L_m) / Dc_m / W
    pitch = round(12 * mpp, 1)
    return scene_from_dict({
        "pane": {"size_mm": [2400, 1800], "thickness_mm": 6, "refractive_index": N_GLASS, "deformation": deformation},
        "backdrop": {"pattern": "lines", "pitch_mm": pitch, "line_width_mm": pitch / 4, "distance_m": L_m},
        "camera": {"focal_length_mm": 18 * Dc_m * 1000 / HALF_VIEW_MM, "sensor_width_mm": 36, "pixels": [W, H],
                   "position_mm": [0, 0, -Dc_m * 1000]},
        "render": {"samples_per_pixel": spp, "seed": seed},
        "analysis": {"detrend_degree": detrend, "sigma_mm": pane_sigma_mm * (Dc_m + L_m) / Dc_m}})


def _capture(tmp, name, scene, Dc_m):
    """``glassdist analyze`` of the scene's render pair (Comparative) with --camera-distance-m; its folder."""
    from glassdist.io import write_png16

    img, ref = tmp / f"{name}.png", tmp / f"{name}_ref.png"
    write_png16(img, render_scene(scene))
    write_png16(ref, render_scene(scene, reference=True))
    out = tmp / name
    code = main(["analyze", str(img), "--reference", str(ref), "--pitch-mm", str(scene.backdrop.pitch_mm),
                 "--distance-m", str(scene.backdrop.distance_m), "--pattern", "lines", "--sigma-mm",
                 str(scene.analysis["sigma_mm"]), "--detrend-degree", str(scene.analysis["detrend_degree"]),
                 "--camera-distance-m", str(Dc_m), "--fields", "pixel", "--out", str(out), "-q"])
    assert code == 0
    return out


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """Renders analysed: the wave at Dc 3 m / L 1 m and Dc 6 m / L 0.5 m, the lens likewise, another wave at 6 / 0.5."""
    tmp = tmp_path_factory.mktemp("viewpoint")
    out = {}
    for key, deform in (("wave", WAVE), ("lens", LENS)):
        for Dc, L in ((3.0, 1.0), (6.0, 0.5)):
            out[key, Dc] = _capture(tmp, f"{key}_{Dc:g}", pane_scene(deform, Dc, L, detrend=2 if key == "wave" else 1),
                                    Dc)
    out["other", 6.0] = _capture(tmp, "other_6", pane_scene(OTHER_WAVE, 6.0, 0.5), 6.0)
    return out


def _summary(folder):
    return json.loads((folder / "summary.json").read_text())


# --- the normal-incidence factor in closed form --------------------------------------------------------------------


def _pane_radius_mm(scene):
    W, H = scene.camera.pixels
    r, c = np.indices((H, W))
    return np.hypot(c - (W - 1) / 2, r - (H - 1) / 2) * (2 * HALF_VIEW_MM / W)


def _central(field, scene, radius_mm=25.0):
    """Mean of a map over the pixels whose pane point lies within ``radius_mm`` of the centre."""
    return float(np.nanmean(field[_pane_radius_mm(scene) < radius_mm]))


@pytest.mark.parametrize("Dc, L", [(3.0, 1.0), (6.0, 0.5), (10.0, 3.0)])
def test_normal_incidence_factor_of_a_thin_lens(Dc, L):
    """A thin lens of power P reads phi_eff = -2 P Dc / (Dc + L) through a pinhole at Dc, and -2 P intrinsically.

    Closed form: the Gaussian thickening 2A exp(-rho^2 / 2 s^2) smoothed by a Gaussian of sigma_p (on the pane) is
    2A' exp(-rho^2 / 2 s'^2), s'^2 = s^2 + sigma_p^2, A' = A s^2 / s'^2, of Laplacian
    2A' (rho^2 / s'^2 - 2) / s'^2 exp(-rho^2 / 2 s'^2) = -2 P(rho): P(0) = (n - 1) 2A' / s'^2, averaged over the
    pixels within 25 mm of the centre. The exact tracer's
    landing points through the independent evaluation (tests/_truth.py), and glassdist.theory's model through the
    shared stack, both read it at the centre (measured: exact 0.9994-1.0040, model 1.0002-1.0052 of the closed
    form, intrinsic 0.9993-1.0040); the slab's lateral shift and the thickened slab's own shift add 0.2-0.9 %. No detrend
    here (it would take the lens's own linear part): the flat slab's shift, -s(alpha) (exact, the model's term
    ``slab``; a linear field that any detrend of degree >= 1 removes, 1 mD of apparent power at Dc 3 m / L 1 m),
    is taken out of both.
    """
    from glassdist.theory import predict_channels, predict_displacement
    from glassdist.viewpoint import CaptureGeometry, capture_factor, intrinsic_reading

    sigma_p = 10.0
    sc = pane_scene(LENS, Dc, L, pixels=(160, 120), pane_sigma_mm=sigma_p, detrend=0)
    W, H = sc.camera.pixels
    mpp = 2 * HALF_VIEW_MM * (Dc + L) / Dc / W
    s2 = LENS_S_MM**2 + sigma_p**2
    rho2 = _pane_radius_mm(sc) ** 2
    laplacian = 2 * LENS_A_MM * LENS_S_MM**2 / s2 * (rho2 / s2 - 2) / s2 * np.exp(-rho2 / (2 * s2))  # 1/mm
    P_mD = -0.5 * _central((N_GLASS - 1) * laplacian * 1e6, sc)  # 1/mm -> mD
    expect = -2 * P_mD * capture_factor(Dc, L)
    pred = predict_displacement(sc)
    slab = pred.terms_mm["slab"]
    exact = np.nan_to_num(landing_points(sc).displacement_mm) - slab
    region = np.ones((H, W), bool)
    truth = _truth.evaluate(exact, region, distance_m=L, mm_per_px=mpp, detrend_degree=0,
                            sigma_mm=sc.analysis["sigma_mm"], jacobian=landing_jacobian(sc))
    from dataclasses import replace

    pred = replace(pred, displacement_mm=pred.displacement_mm - slab)
    _, model, _ = predict_channels(sc, sigma_mm=sc.analysis["sigma_mm"], detrend_degree=0, mm_per_px=mpp,
                                   prediction=pred)
    for ch in (truth, model):
        print("capture / closed form", Dc, L, _central(ch.phi_eff_mD, sc) / expect)
        assert _central(ch.phi_eff_mD, sc) == pytest.approx(expect, rel=0.01)
    reading = intrinsic_reading(truth.phi_eff_mD, truth.phi_shear_mD, truth.axis_deg,
                                rows_px=np.arange(H)[:, None], cols_px=np.arange(W)[None], image_shape=(H, W),
                                mm_per_px=mpp, sigma_mm=sc.analysis["sigma_mm"], geometry=CaptureGeometry(Dc, L))
    print("intrinsic / closed form", Dc, L, _central(reading.phi_eff_mD, sc) / (-2 * P_mD))
    assert _central(reading.phi_eff_mD, sc) == pytest.approx(-2 * P_mD, rel=0.01)
    assert reading.pane_sigma_mm == pytest.approx(sigma_p)
    assert expect < 0  # a converging lens reads phi_eff < 0


def test_projection_factors_are_one_on_the_axis_and_grow_off_it():
    """m_t = sec^2(a) kappa_t / (n - 1) and m_s = sec(a) K0 / (n - 1): 1 at normal incidence, above 1 off it."""
    from glassdist.viewpoint import projection_factors

    mt, ms = projection_factors(np.radians([0.0, 10.0, 20.0]))
    assert mt[0] == pytest.approx(1.0) and ms[0] == pytest.approx(1.0)
    assert np.all(np.diff(mt) > 0) and np.all(np.diff(ms) > 0) and np.all(mt[1:] > ms[1:])


@pytest.mark.parametrize("deformation", ["wave", "lens"])
def test_intrinsic_model_is_geometry_free_on_exact_landing_points(deformation):
    """The chain alone (no analyzer): exact landing points at Dc 3 / L 1, Dc 6 / L 0.5 and near-orthographic Dc 200 m,
    evaluated independently, read the same intrinsic mean |phi_eff| and mean phi_shear within 1 % (the capture
    readings differ by 17-25 %). Measured (mean |phi_eff|, mean phi_shear, 160 x 120 px): wave 40.18, 40.12 / 40.33, 40.26 /
    40.25, 40.25 mD; lens (detrend 1) 14.52, 14.14 / 14.64, 14.26 / 14.61, 14.24 mD."""
    from glassdist.viewpoint import CaptureGeometry, intrinsic_reading

    deform = WAVE if deformation == "wave" else LENS
    detrend = 2 if deformation == "wave" else 1
    means = []
    for Dc, L in ((3.0, 1.0), (6.0, 0.5), (200.0, 1.0)):
        sc = pane_scene(deform, Dc, L, pixels=(160, 120), detrend=detrend)
        W, H = sc.camera.pixels
        mpp = 2 * HALF_VIEW_MM * (Dc + L) / Dc / W
        exact = np.nan_to_num(landing_points(sc).displacement_mm)
        region = np.ones((H, W), bool)
        t = _truth.evaluate(exact, region, distance_m=L, mm_per_px=mpp, detrend_degree=detrend,
                            sigma_mm=sc.analysis["sigma_mm"], jacobian=landing_jacobian(sc))
        r = intrinsic_reading(t.phi_eff_mD, t.phi_shear_mD, t.axis_deg, rows_px=np.arange(H)[:, None],
                              cols_px=np.arange(W)[None], image_shape=(H, W), mm_per_px=mpp,
                              sigma_mm=sc.analysis["sigma_mm"], geometry=CaptureGeometry(Dc, L))
        means.append([channel_statistics(getattr(r, n), region)["mean_abs"] for n in ("phi_eff_mD", "phi_shear_mD")])
    means = np.array(means)
    print(deformation, means)
    assert np.all(np.abs(means[:2] / means[2] - 1) < 0.01), means


@pytest.mark.parametrize("deformation", ["wave", "lens"])
def test_intrinsic_reading_of_oblique_captures(deformation):
    """The chain off the normal (no analyzer): captures at Dc 3 m (along the line of sight) / L 1 m, normal and 30 and
    45 deg from the side, their exact landing points evaluated independently (smoothing 10 mm on the pane), read the
    same intrinsic mean |phi_eff| and mean phi_shear over the pane's central 800 x 700 mm within 2 % (the capture
    readings differ by up to a factor 3), the wave also the near-orthographic Dc 200 m's. Measured (phi_eff, phi_shear):
    wave (detrend 1) normal 48.54, 48.41; 30 deg 48.18, 48.02; 45 deg 48.40, 48.22; orthographic 48.40, 48.40 mD;
    lens (no detrend) normal 13.06, 18.24; 30 deg 13.04, 18.28; 45 deg 13.10, 18.34 mD (the orthographic 13.49 mD of
    phi_eff differs by the flat slab's shift, which no detrend takes out here). The detrend acts in the capture's
    pixels, projective on the pane off the normal: with detrend 1 the lens's phi_eff (its linear part is its power)
    reads -3.3 % at 30 deg and -6.4 % at 45 deg (not tested)."""
    from glassdist.viewpoint import CaptureGeometry, intrinsic_reading
    from glassdist.viewpoint.view import observer_camera

    deform, detrend = (WAVE, 1) if deformation == "wave" else (LENS, 0)
    W, H = 160, 120
    means = {}
    for Dc, th in ((200.0, 0.0), (3.0, 0.0), (3.0, 30.0), (3.0, 45.0)):
        cam = observer_camera(Dc, th, 0.0, (H, W), 2 * HALF_VIEW_MM / W)
        sc = _camera_scene(deform, {"focal_length_px": cam.focal_length_px, "pixels": [W, H],
                                    "position_mm": cam.position_mm, "yaw_deg": cam.yaw_deg,
                                    "pitch_deg": cam.pitch_deg}, 1.0)
        J = landing_jacobian(sc)
        mpp = float(np.median(np.sqrt(np.abs(np.linalg.det(J)))))
        g = CaptureGeometry(Dc, 1.0, viewing_angle_deg=th, focal_length_px=cam.focal_length_px)
        sigma_b = 10.0 / g.factor
        t = _truth.evaluate(np.nan_to_num(landing_points(sc).displacement_mm), np.ones((H, W), bool), distance_m=1.0,
                            mm_per_px=mpp, detrend_degree=detrend, sigma_mm=sigma_b, jacobian=J)
        r = intrinsic_reading(t.phi_eff_mD, t.phi_shear_mD, t.axis_deg, rows_px=np.arange(H)[:, None],
                              cols_px=np.arange(W)[None], image_shape=(H, W), mm_per_px=mpp, sigma_mm=sigma_b,
                              geometry=g)
        inner = (np.abs(r.x_mm) < 400) & (np.abs(r.y_mm) < 350)
        means[Dc, th] = np.array([channel_statistics(getattr(r, c), inner)["mean_abs"]
                                  for c in ("phi_eff_mD", "phi_shear_mD")])
    print(deformation, means)
    for th in (30.0, 45.0):
        assert np.all(np.abs(means[3.0, th] / means[3.0, 0.0] - 1) < 0.02), means
    if deformation == "wave":
        assert np.all(np.abs(means[3.0, 45.0] / means[200.0, 0.0] - 1) < 0.02), means


# --- analysed captures ------------------------------------------------------------------------------------------------


def test_capture_summary_and_fields_carry_the_intrinsic_reading(captures):
    """``analyze --camera-distance-m`` writes ``intrinsic`` (the statistics keys of ``statistics``, the factor, the
    smoothing carried onto the pane) and the intrinsic maps in result.npz; the capture's own figures unchanged."""
    folder = captures["wave", 3.0]
    s = _summary(folder)
    intr = s["intrinsic"]
    assert set(s["statistics"]["phi_eff_mD"]) <= set(intr["phi_eff_mD"])
    assert intr["capture_factor"] == pytest.approx(0.75) and intr["pane_sigma_mm"] == pytest.approx(PANE_SIGMA_MM)
    with np.load(folder / "result.npz") as z:
        assert {"intrinsic_phi_eff_mD", "intrinsic_phi_shear_mD", "intrinsic_axis_deg"} <= set(z.files)
        eff = z["intrinsic_phi_eff_mD"]
        trusted = z["quality"] == 0
    assert channel_statistics(eff, trusted)["mean_abs"] == pytest.approx(intr["phi_eff_mD"]["mean_abs"], rel=1e-5)
    # off-axis pixels read more than Dc/(Dc+L) alone says (sec^2 alpha): the intrinsic mean is below capture / k
    assert intr["phi_eff_mD"]["mean_abs"] < s["statistics"]["phi_eff_mD"]["mean_abs"] / 0.75


@pytest.mark.parametrize("pane", ["wave", "lens"])
def test_two_capture_geometries_read_the_same_intrinsic_pane(captures, pane):
    """Dc 3 m / L 1 m and Dc 6 m / L 0.5 m (Comparative, one render each, analysed by ``glassdist analyze``): the
    capture readings differ by 20-25 %, the intrinsic mean |phi_eff| and mean phi_shear agree, and match the
    near-orthographic reading (exact landing points at Dc 200 m / L 1 m, independent evaluation, same pane region).

    Measured (mean |phi_eff|, mean phi_shear; intrinsic A / B - 1): wave 36.35 / 36.26 mD (+0.25 %), 36.35 / 36.25 mD
    (+0.27 %), near-orthographic 36.09, 36.09 mD; lens 15.76 / 16.14 mD (-2.4 %), 16.65 / 17.12 mD (-2.7 %),
    near-orthographic 15.98, 16.72 mD, of which the two captures' own analysis errors (analyzer / truth 0.990 and
    1.007 on phi_eff, 1.001 and 1.022 on phi_shear) make about 2 %: the chain alone, on each capture's exact landing
    points, agrees within 1 %. Tolerances: 2 % (wave), 3 % (lens: the 2 % asked for is not met end to end with these
    captures; why, and where it is, in the next test).
    """
    from glassdist.storage import load_result
    from glassdist.viewpoint import CaptureGeometry, intrinsic_reading

    deform = WAVE if pane == "wave" else LENS
    chans = ("phi_eff_mD", "phi_shear_mD")
    a, b = (_summary(captures[pane, Dc]) for Dc in (3.0, 6.0))
    trusted_a = load_result(captures[pane, 3.0]).pixel_field("quality") == 0
    exact_intrinsic = []
    for Dc, L in ((3.0, 1.0), (6.0, 0.5), (200.0, 1.0)):
        stored = load_result(captures[pane, min(Dc, 6.0) if Dc < 200 else 3.0])
        sc = pane_scene(deform, Dc, L)
        sigma = PANE_SIGMA_MM * (Dc + L) / Dc
        t = _view_truth(sc, stored, sigma_mm=sigma, detrend=stored.summary["detrend_degree"])
        W, H = sc.camera.pixels
        r = intrinsic_reading(t.phi_eff_mD, t.phi_shear_mD, t.axis_deg, rows_px=np.arange(H)[:, None],
                              cols_px=np.arange(W)[None], image_shape=(H, W), mm_per_px=2 * HALF_VIEW_MM * (Dc + L) / Dc / W,
                              sigma_mm=sigma, geometry=CaptureGeometry(Dc, L))
        exact_intrinsic.append([channel_statistics(getattr(r, ch), trusted_a)["mean_abs"] for ch in chans])
    ortho = exact_intrinsic[2]
    tol = 0.02 if pane == "wave" else 0.03
    for i, ch in enumerate(chans):
        ia, ib = a["intrinsic"][ch]["mean_abs"], b["intrinsic"][ch]["mean_abs"]
        ca, cb = a["statistics"][ch]["mean_abs"], b["statistics"][ch]["mean_abs"]
        print(pane, ch, "capture", ca, cb, "intrinsic", ia, ib, ia / ib - 1, "exact chain", [e[i] for e in exact_intrinsic])
        assert abs(ca / cb - 1) > 0.1
        assert ia == pytest.approx(ib, rel=tol)
        assert exact_intrinsic[0][i] == pytest.approx(exact_intrinsic[1][i], rel=0.01)
        for v in (ia, ib):  # the near-orthographic render's reading
            assert v == pytest.approx(ortho[i], rel=0.03)


def test_lens_intrinsic_agreement_where_neither_capture_is_strained_or_noise_limited(tmp_path):
    """Where the 2 % is missed (the lens above: -2.4 %, -2.7 %) and why, measured on the same pane area (both
    captures' trusted pixels; same pane point per pixel): the chain alone, on each capture's exact landing points,
    agrees within 0.7 % (-0.64 %, -0.72 %; with the variation of the projection factors across the pane kept,
    -0.71 %, -0.51 %: neither the field angle per pixel nor the smoothing carried onto the pane is the cause). The
    rest is each capture's own analysis error: at Dc 3 m / L 1 m, -1.0 % on phi_eff, the first-order reading of a
    capture strained to 5.4 % at the lens centre (-2 P k L = 0.054; +0.3 % at half the lens's power); at Dc 6 m /
    L 0.5 m, +0.7 % and +2.2 %, the noise's bias on a mean of magnitudes (the render's sampling noise, 0.68 mD, on
    a displacement halved by L; 16 samples per pixel). The same pane at half the power rendered with 64 samples per
    pixel (noise 0.14 and 0.25 mD): the two geometries agree within 2 % (measured -1.49 %, -1.39 %)."""
    tmp = tmp_path
    A = LENS_A_MM / 2
    lens = {"front": [{"kind": "gaussian", "amplitude_mm": -A, "sigma_mm": LENS_S_MM, "center_mm": [0, 0]}],
            "back": [{"kind": "gaussian", "amplitude_mm": A, "sigma_mm": LENS_S_MM, "center_mm": [0, 0]}]}
    folders = [_capture(tmp, f"lens_{Dc:g}", pane_scene(lens, Dc, L, detrend=1, spp=64), Dc)
               for Dc, L in ((3.0, 1.0), (6.0, 0.5))]
    maps = [np.load(f / "result.npz") for f in folders]
    common = (maps[0]["quality"] == 0) & (maps[1]["quality"] == 0)
    for ch in ("intrinsic_phi_eff_mD", "intrinsic_phi_shear_mD"):
        a, b = (channel_statistics(m[ch], common)["mean_abs"] for m in maps)
        print(ch, a, b, a / b - 1)
        assert a == pytest.approx(b, rel=0.02)


def _view_truth(scene, stored, *, sigma_mm, detrend):
    """The independent evaluation of the exact landing points of ``scene`` on the capture's region (same pane points)."""
    exact = np.nan_to_num(landing_points(scene).displacement_mm)
    W, _ = scene.camera.pixels
    Dc, L = -scene.camera.position_mm[2] / 1000, scene.backdrop.distance_m
    mpp = 2 * HALF_VIEW_MM * (Dc + L) / Dc / W
    return _truth.evaluate(exact, stored.valid, distance_m=L, mm_per_px=mpp, detrend_degree=detrend,
                           sigma_mm=sigma_mm, jacobian=landing_jacobian(scene))


@pytest.mark.parametrize("pane", ["wave", "lens"])
def test_view_predicts_a_render_from_ten_metres(captures, pane, tmp_path):
    """``glassdist view`` of the Dc 3 m / L 1 m capture at Do 10 m / Lo 3 m predicts the exact render's reading there
    (independent evaluation of its landing points, same pane region, S and N) within 3 % on mean |phi_eff| and
    mean phi_shear; the smoothing is the capture's carried to that backdrop, 52 mm. Measured (view / render truth - 1):
    wave +1.08 %, +0.90 %; lens -0.14 %, +0.27 %; the axis where phi_shear > half its largest value, 95th percentile
    of the difference 0.43 deg (wave), 2.56 deg (lens)."""
    from glassdist.storage import load_result

    src = captures[pane, 3.0]
    out = tmp_path / "view"
    assert main(["view", str(src), "--observer-distance-m", "10", "--background-distance-m", "3", "--out", str(out)]) == 0
    s = _summary(out)
    assert s["sigma_mm"] == pytest.approx(PANE_SIGMA_MM * 13 / 10)
    stored = load_result(src)
    detrend = s["detrend_degree"]
    truth = _view_truth(pane_scene(WAVE if pane == "wave" else LENS, 10.0, 3.0), stored, sigma_mm=s["sigma_mm"],
                        detrend=detrend)
    trusted = stored.pixel_field("quality") == 0
    for ch in ("phi_eff_mD", "phi_shear_mD"):
        want = channel_statistics(getattr(truth, ch), trusted)["mean_abs"]
        got = s["statistics"][ch]["mean_abs"]
        print(pane, ch, "view", got, "render truth", want, got / want - 1)
        assert got == pytest.approx(want, rel=0.03)
    # the axis, where phi_shear is well above its noise (half its largest value): within 3 deg
    with np.load(out / "result.npz") as z:
        axis = z["axis_deg"]
    strong = trusted & (truth.phi_shear_mD > 0.5 * np.nanmax(truth.phi_shear_mD[trusted]))
    diff = _truth.axis_difference_deg(axis[strong], truth.axis_deg[strong])
    print(pane, "axis: median, p95 difference", np.median(diff), np.percentile(diff, 95))
    assert np.percentile(diff, 95) < 3.0


OBLIQUE_DO_M, OBLIQUE_LO_M = 5.0, 1.0


def _camera_scene(deformation, camera, Lo_m):
    """The pane seen by the camera ``glassdist view`` records (its summary's ``view.camera``), the backdrop Lo behind."""
    W, _ = camera["pixels"]
    return scene_from_dict({
        "pane": {"size_mm": [2400, 1800], "thickness_mm": 6, "refractive_index": N_GLASS, "deformation": deformation},
        "backdrop": {"pattern": "lines", "pitch_mm": 20, "line_width_mm": 5, "distance_m": Lo_m},
        "camera": {"focal_length_mm": camera["focal_length_px"] * 36 / W, "sensor_width_mm": 36,
                   "pixels": camera["pixels"], "position_mm": camera["position_mm"], "yaw_deg": camera["yaw_deg"],
                   "pitch_deg": camera["pitch_deg"]}})


@pytest.mark.parametrize("th", [0.0, 15.0, 30.0, 45.0, 60.0])
def test_oblique_factors_in_closed_form_against_the_exact_tracer(th):
    """Seen at incidence theta (Do 5 m along the line of sight, L 1 m, from the side), a thin lens of power P reads
    E_tt = -k P m_t and E_ss = -k P m_s at the pane centre (t in the plane of incidence), k = h / (h + L) with
    h = Do cos(theta), (m_t, m_s) of :func:`projection_factors`; a cylinder reads the one of them along its power.
    The exact tracer's landing points (flat slab's shift taken out, exact), differentiated on their own (centred
    differences, the exact Jacobian), over the central 4 x 4 px (8 x 8 mm across the plane of incidence), against the
    same at normal incidence. Measured (tracer / closed form - 1) at 15, 30, 45, 60 deg: spherical lens t +0.02,
    -0.07, -0.58, -1.6 %; s +0.05, +0.17, +0.39, +0.73 %; cylinder along t +0.02, -0.03, -0.32, -0.88 %; along s
    +0.02, +0.07, +0.16, +0.25 %."""
    from glassdist.theory import predict_displacement
    from glassdist.viewpoint import projection_factors
    from glassdist.viewpoint.view import observer_camera

    lens = {"back": [{"kind": "spherical_cap", "radius_mm": 20000, "aperture_mm": 600}]}
    cyl_t = {"back": [{"kind": "roller_wave", "amplitude_mm": 1.0, "wavelength_mm": 2000, "phase_deg": 90}]}
    cyl_s = {"back": [{"kind": "roller_wave", "amplitude_mm": 1.0, "wavelength_mm": 2000, "direction_deg": 90,
                       "phase_deg": 90}]}

    def central_tensor(deformation, theta):
        cam = observer_camera(OBLIQUE_DO_M, theta, 0.0, (32, 32), 2.0)
        sc = _camera_scene(deformation, {"focal_length_px": cam.focal_length_px, "pixels": [32, 32],
                                         "position_mm": cam.position_mm, "yaw_deg": cam.yaw_deg,
                                         "pitch_deg": cam.pitch_deg}, OBLIQUE_LO_M)
        exact = np.nan_to_num(landing_points(sc).displacement_mm) - predict_displacement(sc).terms_mm["slab"]
        G = _truth.gradient_mm(exact, jacobian=landing_jacobian(sc))
        return 1000 * 0.5 * (G + np.swapaxes(G, -1, -2))[14:18, 14:18].mean(axis=(0, 1)) / OBLIQUE_LO_M

    h = OBLIQUE_DO_M * np.cos(np.radians(th))
    k = h / (h + OBLIQUE_LO_M) / (OBLIQUE_DO_M / (OBLIQUE_DO_M + OBLIQUE_LO_M))
    mt, ms = projection_factors(np.radians(th))
    E_lens, E0_lens = central_tensor(lens, th), central_tensor(lens, 0.0)
    E_t, E0_t = central_tensor(cyl_t, th)[0, 0], central_tensor(cyl_t, 0.0)[0, 0]
    E_s, E0_s = central_tensor(cyl_s, th)[1, 1], central_tensor(cyl_s, 0.0)[1, 1]
    got = {"lens t": E_lens[0, 0] / E0_lens[0, 0], "lens s": E_lens[1, 1] / E0_lens[1, 1], "cylinder t": E_t / E0_t,
           "cylinder s": E_s / E0_s}
    want = {"lens t": k * mt, "lens s": k * ms, "cylinder t": k * mt, "cylinder s": k * ms}
    print(th, {key: round(got[key] / want[key] - 1, 5) for key in got})
    assert E0_lens[0, 0] < 0 and abs(E_lens[0, 1]) < 1e-3 * abs(E_lens[0, 0])  # converging; the axis stays on t
    for key in got:
        assert got[key] == pytest.approx(want[key], rel=0.02)


@pytest.fixture(scope="module")
def direct_wave(captures, tmp_path_factory):
    """The Dc 3 m / L 1 m wave's render analysed by the Direct Method (no reference), with --camera-distance-m."""
    img = captures["wave", 3.0].parent / "wave_3.png"
    sc = pane_scene(WAVE, 3.0, 1.0)
    out = tmp_path_factory.mktemp("direct") / "direct"
    assert main(["analyze", str(img), "--pitch-mm", str(sc.backdrop.pitch_mm), "--distance-m", "1", "--pattern",
                 "lines", "--sigma-mm", str(sc.analysis["sigma_mm"]), "--detrend-degree", "2",
                 "--camera-distance-m", "3", "--out", str(out), "-q"]) == 0
    return out


@pytest.mark.parametrize("theta, azimuth", [(30.0, 0.0), (45.0, 0.0), (45.0, 90.0)])
@pytest.mark.parametrize("pane", ["wave", "lens", "wave, Direct"])
def test_view_predicts_oblique_renders(captures, direct_wave, pane, theta, azimuth, tmp_path):
    """``glassdist view`` of the Dc 3 m / L 1 m capture at Do 5 m / Lo 1 m, 30 and 45 deg from the side (and 45 deg
    from above) predicts the exact render's reading from the camera it records (the independent evaluation of the
    render's landing points over the region it documents, with its S, N and scale) within 3 % (30 deg) and 5 % (45
    deg) on mean |phi_eff| and mean phi_shear; the axis within 3 deg (95th percentile) where phi_shear exceeds half
    its largest value. Measured (view / render truth - 1, phi_eff, phi_shear; axis p95): wave 30 deg +1.22, +1.19 %,
    0.37 deg; 45 deg -0.39, -0.29 %, 0.53 deg; lens 30 deg -1.19, -0.67 %, 1.60 deg; 45 deg -1.52, -1.10 %, 1.49 deg;
    lens 45 deg from above +0.09, +0.98 %, 2.64 deg."""
    src = direct_wave if pane == "wave, Direct" else captures[pane, 3.0]
    out = tmp_path / "view"
    assert main(["view", str(src), "--observer-distance-m", str(OBLIQUE_DO_M), "--background-distance-m",
                 str(OBLIQUE_LO_M), "--viewing-angle-deg", str(theta), "--viewing-azimuth-deg", str(azimuth),
                 "--out", str(out)]) == 0
    s = _summary(out)
    v = s["view"]
    assert v["viewing_angle_deg"] == theta and v["median_incidence_deg"] == pytest.approx(theta, abs=2.0)
    with np.load(out / "result.npz") as z:
        valid, trusted, axis = z["valid"], z["trusted"], z["axis_deg"]
    sc = _camera_scene(LENS if pane == "lens" else WAVE, v["camera"], OBLIQUE_LO_M)
    truth = _truth.evaluate(np.nan_to_num(landing_points(sc).displacement_mm), valid, distance_m=OBLIQUE_LO_M,
                            mm_per_px=s["mm_per_px"], detrend_degree=s["detrend_degree"], sigma_mm=s["sigma_mm"],
                            jacobian=landing_jacobian(sc))
    tol = 0.03 if theta <= 30 else 0.05
    for ch in ("phi_eff_mD", "phi_shear_mD"):
        want = channel_statistics(getattr(truth, ch), trusted)["mean_abs"]
        got = s["statistics"][ch]["mean_abs"]
        print(pane, theta, azimuth, ch, "view", got, "render truth", want, got / want - 1)
        assert got == pytest.approx(want, rel=tol)
    strong = trusted & (truth.phi_shear_mD > 0.5 * np.nanmax(truth.phi_shear_mD[trusted]))
    diff = _truth.axis_difference_deg(axis[strong], truth.axis_deg[strong])
    print(pane, theta, azimuth, "axis: median, p95 difference", np.median(diff), np.percentile(diff, 95))
    assert np.percentile(diff, 95) < 3.0


def test_view_warns_where_the_small_angle_model_stops_holding(captures):
    """Beyond 60 deg incidence (the range validated against exact refraction) the prediction says so."""
    from glassdist.storage import load_result
    from glassdist.viewpoint import predict_view

    stored = load_result(captures["lens", 3.0])
    assert not any("incidence" in w for w in predict_view(stored, observer_distance_m=5.0, background_distance_m=1.0,
                                                           viewing_angle_deg=30.0).warnings)
    far = predict_view(stored, observer_distance_m=5.0, background_distance_m=1.0, viewing_angle_deg=60.0)
    assert any("not validated against exact refraction" in w for w in far.warnings), far.warnings


def test_view_at_the_capture_geometry_gives_back_the_capture(captures):
    """Predicting the capture's own point (Do = Dc, Lo = L, its S and N) returns its statistics within 1 %."""
    from glassdist.storage import load_result
    from glassdist.viewpoint import predict_view

    stored = load_result(captures["wave", 6.0])
    pred = predict_view(stored, observer_distance_m=6.0, background_distance_m=0.5)
    for ch in ("phi_eff_mD", "phi_shear_mD"):
        assert pred.statistics[ch]["mean_abs"] == pytest.approx(stored.summary["statistics"][ch]["mean_abs"], rel=0.01)


def test_view_refuses_finer_smoothing_no_geometry_and_oblique_views(captures, tmp_path, capsys):
    """Exit 2 with one line: S finer than the capture resolved, a result without --camera-distance-m, a view at 70 deg
    or more (the pane nearly edge-on); the output folder is not written."""
    src = captures["wave", 3.0]
    base = ["view", str(src), "--observer-distance-m", "10", "--background-distance-m", "3"]
    for extra, needle in ((["--sigma-mm", "40"], "finer than the capture resolved"),
                          (["--viewing-angle-deg", "75"], "outside [0, 70)")):
        capsys.readouterr()
        assert main([*base, *extra, "--out", str(tmp_path / "v")]) == 2
        err = capsys.readouterr().err.strip()
        assert needle in err and len(err.splitlines()) == 1, err
        assert not (tmp_path / "v").exists()
    bare = tmp_path / "bare"
    bare.mkdir()
    s = _summary(src)
    del s["intrinsic"]
    (bare / "summary.json").write_text(json.dumps(s))
    (bare / "result.npz").write_bytes((src / "result.npz").read_bytes())
    assert main(["view", str(bare), "--observer-distance-m", "10", "--background-distance-m", "3",
                 "--out", str(tmp_path / "v")]) == 2
    assert "--camera-distance-m" in capsys.readouterr().err


def test_compare_one_pane_two_geometries_and_two_panes(captures, tmp_path, capsys):
    """``glassdist compare``: the wave at Dc 3 / L 1 against Dc 6 / L 0.5 is consistent with zero; against a wave
    25 % deeper at Dc 6 / L 0.5 a difference is detected (both channels)."""
    from glassdist.storage import load_result
    from glassdist.viewpoint import compare_results

    same = compare_results(load_result(captures["wave", 3.0]), load_result(captures["wave", 6.0]))
    other = compare_results(load_result(captures["wave", 3.0]), load_result(captures["other", 6.0]))
    print("same", same.to_dict(), "other", other.to_dict())
    assert same.consistent and not same.warnings
    assert not other.phi_eff_mean_abs.consistent and not other.phi_shear_mean.consistent
    assert other.phi_eff_mean_abs.difference < 0  # the deeper wave reads more
    out = tmp_path / "cmp.json"
    assert main(["compare", str(captures["wave", 3.0]), str(captures["wave", 6.0]), "--json", str(out)]) == 0
    assert json.loads(out.read_text())["consistent_with_zero"] is True
    assert "consistent with zero" in capsys.readouterr().out


def test_direct_method_accepts_the_camera_distance_and_reads_the_same_pane(captures, tmp_path):
    """``--camera-distance-m`` without a reference or a camera file (Direct Method): accepted, and its intrinsic
    reading of the Dc 3 m / L 1 m wave within 2 % of the Comparative one. Measured: 36.27 / 36.35 mD (phi_eff),
    36.20 / 36.35 mD (phi_shear)."""
    comp = captures["wave", 3.0]
    img = comp.parent / "wave_3.png"
    sc = pane_scene(WAVE, 3.0, 1.0)
    out = tmp_path / "direct"
    assert main(["analyze", str(img), "--pitch-mm", str(sc.backdrop.pitch_mm), "--distance-m", "1", "--pattern",
                 "lines", "--sigma-mm", str(sc.analysis["sigma_mm"]), "--detrend-degree", "2",
                 "--camera-distance-m", "3", "--out", str(out), "-q"]) == 0
    d, c = _summary(out)["intrinsic"], _summary(comp)["intrinsic"]
    for ch in ("phi_eff_mD", "phi_shear_mD"):
        print("direct / comparative", ch, d[ch]["mean_abs"], c[ch]["mean_abs"])
        assert d[ch]["mean_abs"] == pytest.approx(c[ch]["mean_abs"], rel=0.02)


def test_spec_reference_geometry_converts_the_capture_and_states_the_factor(captures, tmp_path, capsys):
    """A specification whose limits hold at another geometry: the verdict judges the capture converted there, states
    the factor and the sentence; the wave at Dc 3 m / L 1 m passes 32 mD as captured (about 27 mD) and fails it
    intrinsically (factor 4/3, about 36 mD); without --camera-distance-m the geometry check fails (never a silent
    PASS); an area_over criterion cannot be converted and is refused (exit 2)."""
    import glassdist
    from glassdist.viewpoint import CaptureGeometry, reference_factor

    comp = captures["wave", 3.0]
    sc = pane_scene(WAVE, 3.0, 1.0)
    base = ["analyze", str(comp.parent / "wave_3.png"), "--reference", str(comp.parent / "wave_3_ref.png"),
            "--pitch-mm", str(sc.backdrop.pitch_mm), "--distance-m", "1", "--pattern", "lines", "--sigma-mm",
            str(sc.analysis["sigma_mm"]), "--detrend-degree", "2", "-q"]
    crit = [{"channel": "phi_eff", "statistic": "mean_abs", "max_mD": 32}]

    def spec(name, geometry, criteria=crit):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"name": name, "criteria": criteria, "reference_geometry": geometry}))
        return str(path)

    captured = _summary(comp)["statistics"]["phi_eff_mD"]["mean_abs"]
    assert captured < 32
    plain = spec("plain", {"observer_distance_m": 3, "background_distance_m": 1})  # the capture's own: k = 1
    assert main([*base, "--camera-distance-m", "3", "--spec", plain, "--out", str(tmp_path / "a")]) == 0
    intr = spec("intrinsic", {"intrinsic": True})
    assert main([*base, "--camera-distance-m", "3", "--spec", intr, "--out", str(tmp_path / "b")]) == 3
    v = _summary(tmp_path / "b")["verdict"]
    geo = next(c for c in v["checks"] if c["criterion"].startswith("reference geometry"))
    k = reference_factor(CaptureGeometry(3.0, 1.0), glassdist.acceptance.geometry.ReferenceGeometry(intrinsic=True))
    assert geo["value"] == pytest.approx(4 / 3) == pytest.approx(k)
    assert "the difference is geometry (factor 1.333), not glass" in geo["note"]
    mean = next(c for c in v["checks"] if c["criterion"].startswith("mean"))
    assert mean["value"] == pytest.approx(captured * 4 / 3, rel=1e-6) and not mean["passed"]
    assert geo["note"].startswith("at the specification's geometry this pane reads")
    assert main([*base, "--spec", intr, "--out", str(tmp_path / "c")]) == 3
    v = _summary(tmp_path / "c")["verdict"]
    assert "--camera-distance-m" in next(c for c in v["checks"] if c["criterion"].startswith("reference"))["note"]
    area = spec("area", {"intrinsic": True}, [{"channel": "phi_eff", "statistic": "area_over", "threshold_mD": 50,
                                               "max_percent": 1}])
    capsys.readouterr()
    assert main([*base, "--camera-distance-m", "3", "--spec", area, "--out", str(tmp_path / "d")]) == 2
    assert "reference_geometry" in capsys.readouterr().err


# --- oblique captures through the command line -----------------------------------------------------------------------

OBLIQUE_WAVE = {"front": [{"kind": "roller_wave", "amplitude_mm": 0.6, "wavelength_mm": 500, "direction_deg": 0}]}


def _oblique_capture_scene(theta_deg, *, Dc_m=3.0, L_m=1.0, pixels=(320, 240)):
    """The wave (crests across the plane of incidence) seen from Dc along a line of sight at theta from the side, the
    camera ``glassdist view`` would place (pane mm per px at the centre across the plane as the normal capture's), 4
    samples per pixel; the lines 12 px a period (geometric mean); ``--sigma-mm`` giving 40 mm on the pane along the
    plane of incidence (the capture's smoothing, isotropic in its pixels, is shorter across it by cos theta)."""
    from glassdist.viewpoint.view import observer_camera

    W, H = pixels
    cam = observer_camera(Dc_m, theta_deg, 0.0, (H, W), 2 * HALF_VIEW_MM / W)
    c = np.cos(np.radians(theta_deg))
    R_mm = 1000.0 * (Dc_m + L_m / c)  # camera to the backdrop along the line of sight
    mpp = R_mm / (cam.focal_length_px * np.sqrt(c))  # backdrop mm per px, geometric mean at the centre
    pitch = round(12 * mpp, 1)
    sigma_b = PANE_SIGMA_MM * R_mm * np.sqrt(c) / (1000.0 * Dc_m)
    sc = scene_from_dict({
        "pane": {"size_mm": [2400, 1800], "thickness_mm": 6, "refractive_index": N_GLASS, "deformation": OBLIQUE_WAVE},
        "backdrop": {"pattern": "lines", "pitch_mm": pitch, "line_width_mm": pitch / 4, "distance_m": L_m},
        "camera": {"focal_length_mm": cam.focal_length_px * 36 / W, "sensor_width_mm": 36, "pixels": [W, H],
                   "position_mm": cam.position_mm, "yaw_deg": cam.yaw_deg, "pitch_deg": cam.pitch_deg},
        "render": {"samples_per_pixel": 4, "seed": 1}})
    return sc, round(float(sigma_b), 3), cam.focal_length_px


@pytest.fixture(scope="module")
def oblique_pair(tmp_path_factory):
    """The wave at Dc 3 m / L 1 m, normal and 30 deg from the side (Comparative, detrend 1), and the 30 deg render by
    the Direct Method without the angle: ``{0: folder, 30: folder, ('direct', 0 or 30): folder, 'focal_px': f}``."""
    from glassdist.io import write_png16

    tmp = tmp_path_factory.mktemp("oblique")
    out = {}
    for th in (0.0, 30.0):
        sc, sigma_b, out["focal_px"] = _oblique_capture_scene(th)
        img, ref = tmp / f"w{th:g}.png", tmp / f"w{th:g}_ref.png"
        write_png16(img, render_scene(sc))
        write_png16(ref, render_scene(sc, reference=True))
        common = ["--pitch-mm", str(sc.backdrop.pitch_mm), "--distance-m", "1", "--pattern", "lines", "--sigma-mm",
                  str(sigma_b), "--detrend-degree", "1", "--camera-distance-m", "3", "-q"]
        angle = ["--camera-angle-deg", str(th)] if th else []
        out[th] = tmp / f"o{th:g}"
        assert main(["analyze", str(img), "--reference", str(ref), *common, *angle, "--fields", "pixel",
                     "--out", str(out[th])]) == 0
        out["direct", th] = tmp / f"direct{th:g}"
        assert main(["analyze", str(img), *common, "--out", str(out["direct", th])]) == 0
    return out


def test_oblique_capture_through_analyze_reads_the_normal_capture_intrinsic_pane(oblique_pair, tmp_path, capsys):
    """``glassdist analyze --camera-angle-deg 30`` of a capture 30 deg from the side (the focal length from the capture's
    scale, within 3 % of the render's) reads the same intrinsic mean |phi_eff| and mean phi_shear as the normal capture
    of the pane within 2 % over the pane area both trust (``glassdist compare``, which takes the oblique capture), the
    difference consistent with zero; the capture readings differ by half. Measured: capture 34.43 / 22.58 mD; intrinsic
    A (30 deg) / B (normal) phi_eff 29.58 / 29.54, phi_shear 29.48 / 29.55 mD (+0.14 %, -0.22 %); f 971.2 px for
    960 px. Over each capture's own trusted pixels (``summary.json`` ``intrinsic``, different pane areas of a 500 mm
    wave) 27.91 / 29.58 mD."""
    s0, s30 = _summary(oblique_pair[0.0]), _summary(oblique_pair[30.0])
    i30 = s30["intrinsic"]
    assert (i30["angle_source"], i30["incidence"], i30["viewing_angle_deg"]) == ("stated", "oblique", 30.0)
    assert i30["focal_length_source"] == "capture scale"
    assert i30["focal_length_px"] == pytest.approx(oblique_pair["focal_px"], rel=0.03)
    assert s0["intrinsic"]["angle_source"] == "assumed normal"
    ratio = s30["statistics"]["phi_eff_mD"]["mean_abs"] / s0["statistics"]["phi_eff_mD"]["mean_abs"]
    assert ratio > 1.3, ratio  # the oblique capture reads the pane amplified
    capsys.readouterr()
    js = tmp_path / "cmp.json"
    assert main(["compare", str(oblique_pair[30.0]), str(oblique_pair[0.0]), "--json", str(js)]) == 0
    cmp = json.loads(js.read_text())
    print(capsys.readouterr().out, cmp)
    for ch in ("phi_eff_mD_mean_abs", "phi_shear_mD_mean_abs"):
        assert cmp[ch]["a"] == pytest.approx(cmp[ch]["b"], rel=0.02)
        assert cmp[ch]["consistent_with_zero"]
    with np.load(oblique_pair[30.0] / "result.npz") as z:
        assert {"intrinsic_phi_eff_mD", "intrinsic_phi_shear_mD"} <= set(z.files)


def test_direct_homography_estimates_the_capture_angle(oblique_pair):
    """By the Direct Method without --camera-angle-deg or a camera file, the 30 deg capture's angle is read from the
    homography's projective terms (the focal length calibrated from the same homography) within 2 deg, the azimuth
    within 5 deg; the normal capture's homography reads normal incidence, without a warning. Measured: 29.20 deg,
    azimuth 2.84 deg, f 956.2 px for 960 px."""
    s0 = _summary(oblique_pair["direct", 0.0])
    assert (s0["intrinsic"]["angle_source"], s0["intrinsic"]["viewing_angle_deg"]) == ("homography", 0.0)
    assert not any("normal" in w for w in s0["warnings"]), s0["warnings"]
    i = _summary(oblique_pair["direct", 30.0])["intrinsic"]
    print(i["viewing_angle_deg"], i["viewing_azimuth_deg"], i["focal_length_px"])
    assert (i["angle_source"], i["focal_length_source"]) == ("homography", "homography")
    assert i["viewing_angle_deg"] == pytest.approx(30.0, abs=2.0)
    assert min(i["viewing_azimuth_deg"], 360.0 - i["viewing_azimuth_deg"]) < 5.0
    assert i["focal_length_px"] == pytest.approx(oblique_pair["focal_px"], rel=0.05)


@pytest.mark.parametrize("Do, theta", [(3.0, 0.0), (5.0, 30.0)])
def test_view_from_an_oblique_capture_predicts_renders(oblique_pair, Do, theta):
    """``view`` of the 30 deg capture predicts renders (Do 3 m normal, Do 5 m at 30 deg from the side, Lo 1 m) within
    3 % on mean |phi_eff| and mean phi_shear against the independent evaluation of the render's exact landing points
    over the region the prediction documents. Measured: -2.15, -2.00 % (3 m normal); -1.52, -1.43 % (5 m, 30 deg)."""
    from glassdist.storage import load_result
    from glassdist.viewpoint import predict_view

    p = predict_view(load_result(oblique_pair[30.0]), observer_distance_m=Do, background_distance_m=1.0,
                     viewing_angle_deg=theta)
    cam = p.summary()["view"]["camera"]
    sc = _camera_scene(OBLIQUE_WAVE, cam, 1.0)
    t = _truth.evaluate(np.nan_to_num(landing_points(sc).displacement_mm), p.valid, distance_m=1.0,
                        mm_per_px=p.mm_per_px, detrend_degree=p.detrend_degree, sigma_mm=p.sigma_mm,
                        jacobian=landing_jacobian(sc))
    for ch in ("phi_eff_mD", "phi_shear_mD"):
        want = channel_statistics(getattr(t, ch), p.trusted)["mean_abs"]
        got = p.statistics[ch]["mean_abs"]
        print(Do, theta, ch, got, want, got / want - 1)
        assert got == pytest.approx(want, rel=0.03)


@pytest.mark.parametrize("extra, needle", [
    (["--camera-angle-deg", "30"], "add --camera-distance-m"),
    (["--camera-distance-m", "3", "--camera-angle-deg", "75"], "outside [0, 70)"),
    (["--camera-distance-m", "3", "--camera-azimuth-deg", "90"], "needs --camera-angle-deg"),
    (["--camera-distance-m", "3", "--camera-angle-deg", "nan"], "outside [0, 70)"),
])
def test_analyze_refuses_inconsistent_capture_pose_options(tmp_path, capsys, extra, needle):
    """Exit 2 with one line naming the fix; nothing written."""
    from glassdist.io import write_png16

    img = tmp_path / "p.png"
    x = np.arange(64)
    write_png16(img, np.tile(0.5 + 0.4 * np.cos(2 * np.pi * x / 8), (48, 1)))
    capsys.readouterr()
    code = main(["analyze", str(img), "--pitch-mm", "5", "--distance-m", "1", *extra, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and needle in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("psi", [0.0, 45.0, 90.0, 200.0])
@pytest.mark.parametrize("swapped", [False, True])
def test_pose_from_an_exact_plane_homography(psi, swapped):
    """Closed form: the homography of the pane plane through a pinhole 35 deg off the normal (the camera of
    ``pane_coordinates``) gives back the angle, the azimuth and the focal length (grid axes in either order); a
    capture facing the pane has no projective terms."""
    import cv2

    from glassdist.viewpoint import CaptureGeometry
    from glassdist.viewpoint.intrinsic import pane_coordinates
    from glassdist.viewpoint.pose import angle_from_homography, focal_from_homography, homography_is_normal

    shape = (240, 320)
    r, c = np.meshgrid(np.linspace(0, 239, 7), np.linspace(0, 319, 7), indexing="ij")

    def homography(theta):
        g = CaptureGeometry(3.0, 1.0, viewing_angle_deg=theta, viewing_azimuth_deg=psi, focal_length_px=900.0)
        x, y = pane_coordinates(r, c, shape, mm_per_px=1.0, geometry=g)
        src = np.stack([-y.ravel(), x.ravel()], -1) if swapped else np.stack([x.ravel(), y.ravel()], -1)
        return cv2.findHomography(src, np.stack([c.ravel(), r.ravel()], -1), 0)[0]

    H = homography(35.0)
    theta, azimuth = angle_from_homography(H, shape, 900.0)
    assert theta == pytest.approx(35.0, abs=1e-4)
    assert (azimuth - psi + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-4)
    assert focal_from_homography(H, shape) == pytest.approx(900.0, rel=1e-5)
    assert not homography_is_normal(H, shape)
    if psi == 0.0 and not swapped:
        scale = CaptureGeometry(3.0, 1.0).factor
        facing = np.array([[1 / scale, 0, 159.5], [0, 1 / scale, 119.5], [0, 0, 1.0]])
        assert homography_is_normal(facing, shape) and focal_from_homography(facing, shape) is None
