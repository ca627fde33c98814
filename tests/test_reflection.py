"""Reflected distortion: the geometry's closed forms, the tracer's reflection branch and the analyzer on ray-traced renders.

Truths are closed forms of the surface (Coddington's mirror powers of a sphere, the roll
wave's 2 A k^2), evaluated at each pixel's hit point on the pane's nominal front plane
(the camera's line of sight, from the scene alone), smoothed like the result documents
(a sinusoid's Gaussian factor at the result's effective sigma), over the interior of the
trusted region (3 sigma inside it). Single captures, seeded renders.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import ndimage

from glassdist.analyzer.reflection import (
    ReflectionGeometry,
    analyze_reflection,
    coddington_power,
    power_channels,
    power_from_strain,
)
from glassdist.cli import main
from glassdist.io import write_png16
from glassdist.render import landing_points, render_scene
from glassdist.render.tracer import fresnel_reflectance
from glassdist.measures import standard_measures
from glassdist.scene import pixel_directions, pixel_grid, scene_from_dict
from glassdist.theory import predict_displacement

D_MM = 2000.0
THICK = 6.0


def _scene(deformation, *, incidence_deg=0.0, pixels=(384, 288), focal_mm=240.0, pitch_mm=12.0, back_face=False,
           spp=16):
    """Board at D = 2 m, camera in the board plane, turned so its axis meets the pane centre at ``incidence_deg``."""
    cx = -D_MM * math.tan(math.radians(incidence_deg))
    return scene_from_dict({
        "pane": {"size_mm": [2400, 1600], "thickness_mm": THICK, "refractive_index": 1.52,
                 "deformation": {"both": deformation}},
        "backdrop": {"pattern": "lines", "pitch_mm": pitch_mm, "line_width_mm": pitch_mm / 4, "distance_m": D_MM / 1000},
        "camera": {"focal_length_mm": focal_mm, "sensor_width_mm": 36, "pixels": list(pixels),
                   "position_mm": [cx, 0, -D_MM], "yaw_deg": incidence_deg},
        "render": {"samples_per_pixel": spp, "seed": 5},
        "viewing": {"mode": "reflection", "back_face": back_face},
    })


def _sphere(R_mm):
    """A sphere of radius |R| with its vertex on the nominal front plane: R > 0 concave (seen from the camera)."""
    aperture = 1500.0
    sag = abs(R_mm) - math.sqrt(R_mm * R_mm - aperture * aperture)
    return [{"kind": "spherical_cap", "radius_mm": R_mm, "aperture_mm": aperture},
            {"kind": "plane", "offset_mm": -math.copysign(sag, R_mm)}]


def _geometry(incidence_deg=0.0):
    return ReflectionGeometry(distance_m=(D_MM - THICK / 2) / 1000, incidence_deg=incidence_deg)


def _hit_points(scene):
    """Each pixel's hit point (u, v) on the nominal front plane, its incidence cosine and tangential u component."""
    a = pixel_directions(scene.camera, *pixel_grid(scene.camera))
    cam = np.asarray(scene.camera.position_mm, float)
    t = (-THICK / 2 - cam[2]) / a[..., 2]
    u, v = cam[0] + t * a[..., 0], cam[1] + t * a[..., 1]
    n = np.hypot(a[..., 0], a[..., 1])
    tu = np.where(n > 1e-12, a[..., 0] / np.maximum(n, 1e-300), 1.0)
    return u, v, a[..., 2], tu


def _interior(res, sigmas=3.0):
    return ndimage.binary_erosion(res.trusted, iterations=max(1, int(round(sigmas * res.effective_sigma_mm / res.mm_per_px))))


def _analyze(scene, incidence_deg=0.0, **kw):
    img, ref = render_scene(scene), render_scene(scene, reference=True)
    return analyze_reflection(img, pitch_mm=scene.backdrop.pitch_mm, geometry=_geometry(incidence_deg), reference=ref, **kw)


# --- the geometry alone ---------------------------------------------------------------------------------------------

def test_coddington_sphere_principal_powers():
    """A sphere's Hessian -1/R (concave) gives principal powers -2/(R cos) and -2 cos/R along t and s."""
    R, th = 20000.0, 30.0
    c = math.cos(math.radians(th))
    P = coddington_power((-1 / R, 0.0, -1 / R), th) * 1e6  # mD
    assert P[0, 0] == pytest.approx(-2e6 / (R * c), rel=1e-12)
    assert P[1, 1] == pytest.approx(-2e6 * c / R, rel=1e-12)
    eff, shear, total, _ = power_channels(P)
    assert eff == pytest.approx(-2e6 / R * (1 / c + c), rel=1e-12)
    assert shear == pytest.approx(2e6 / R * (1 / c - c), rel=1e-12)


def test_power_from_strain_inverts_the_mirror_landing_gradient():
    """The board strain of a mirror (module notes: grad_x delta = 2 D diag(1/cos^2, 1) Hess Z, X = m x) gives Coddington's P."""
    rng = np.random.default_rng(2)
    g = ReflectionGeometry(distance_m=2.0, camera_distance_m=3.0, incidence_deg=35.0, plane_deg=25.0)
    Dm, m = 2000.0, g.magnification
    c = math.cos(math.radians(g.incidence_deg))
    a = math.radians(g.plane_deg)
    Q = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])  # rows t, s
    for _ in range(5):
        h = rng.normal(size=3) * 1e-5
        Hxy = np.array([[h[0], h[1]], [h[1], h[2]]])
        Hts = Q @ Hxy @ Q.T
        G_ts = 2 * Dm * np.diag([1 / c**2, 1.0]) @ Hts / m  # d delta / d X (board), t-s frame
        G = Q.T @ G_ts @ Q
        eps = 0.5 * (G + G.T) * m / Dm  # scaled as power_from_strain expects (1/mm)
        P = power_from_strain(eps, g.incidence_deg, g.plane_deg)
        want = coddington_power((h[0], h[1], h[2]), g.incidence_deg, (math.cos(a), math.sin(a)))
        np.testing.assert_allclose(P, want, rtol=1e-10, atol=1e-16)


def test_fresnel_reflectance_of_uncoated_glass():
    """Normal incidence ((n - 1) / (n + 1))^2; 1 beyond the critical angle; Brewster's p-wave zero."""
    n = 1.52
    assert fresnel_reflectance(1.0, 1 / n) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12)
    assert fresnel_reflectance(math.cos(math.radians(60)), n) == 1.0  # beyond asin(1/1.52) = 41 deg inside
    b = math.atan(n)
    rs = (math.cos(b) - n * math.cos(math.asin(math.sin(b) / n))) / (math.cos(b) + n * math.cos(math.asin(math.sin(b) / n)))
    assert fresnel_reflectance(math.cos(b), 1 / n) == pytest.approx(0.5 * rs * rs, rel=1e-9)


# --- the tracer and the analytical model ------------------------------------------------------------------------------

def test_tracer_landing_shift_is_two_d_times_the_slope():
    """Camera in the board plane, normal incidence at the centre: the board sees the pane point x at 2x, and the
    landing shift is 2 D Z_t / cos^2(theta) along each pixel's plane of incidence, 2 D Z_s across it, within
    0.5 % (the height term 2 Z tan(theta) and the slopes' second order)."""
    R = 20000.0
    scene = _scene(_sphere(R), pixels=(64, 48))
    L = landing_points(scene)
    u, v, c, tu = _hit_points(scene)
    D = D_MM - THICK / 2
    x0 = L.without_glass_mm[..., 0] - 2 * u
    np.testing.assert_allclose(x0, x0.mean(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(L.without_glass_mm[..., 1], 2 * v, rtol=0, atol=1e-9)
    tv = np.sqrt(np.maximum(0.0, 1 - tu * tu)) * np.sign(v)  # the plane of incidence of each pixel
    zu, zv = -u / R, -v / R  # grad Z, Z = -r^2 / 2R
    zt, zs = tu * zu + tv * zv, -tv * zu + tu * zv
    dt, ds = 2 * D * zt / c**2, 2 * D * zs
    truth = np.stack([tu * dt - tv * ds, tv * dt + tu * ds], -1)
    err = np.linalg.norm(L.displacement_mm - truth, axis=-1)
    assert err.max() < 0.005 * np.linalg.norm(truth, axis=-1).max()


@pytest.mark.parametrize("incidence_deg", [0.0, 20.0])
def test_model_matches_tracer_on_the_roll_wave(incidence_deg):
    """The analytical model (mirror law on the slope) against the exact tracer: within 2 % of the displacement's range."""
    wave = [{"kind": "roller_wave", "amplitude_mm": 0.1, "wavelength_mm": 400}]
    scene = _scene(wave, incidence_deg=incidence_deg, pixels=(96, 72), focal_mm=105)
    exact = landing_points(scene).displacement_mm
    model = predict_displacement(scene).displacement_mm
    assert np.abs(model - exact).max() < 0.02 * np.ptp(exact[..., 0])


# --- the analyzer on ray-traced renders -------------------------------------------------------------------------------

@pytest.mark.parametrize("R_mm", [20000.0, -20000.0])
def test_sphere_at_normal_incidence_reads_minus_4000_over_R(R_mm):
    """A concave mirror (converging) reads phi_eff = -4000/R mD < 0, a convex one +4000/R, within 1 %."""
    res = _analyze(_scene(_sphere(R_mm)), detrend_degree=0)
    got = float(np.median(res.phi_eff_mD[_interior(res)]))
    want = -4000.0 / (R_mm / 1000.0)
    assert np.sign(got) == np.sign(want)
    assert got == pytest.approx(want, rel=0.01)


def test_sphere_with_the_camera_behind_the_board():
    """--camera-distance-m: the camera 1 m behind the board plane (C = 3 m, m = 1 + D/C = 5/3) reads the same power."""
    scene = _scene(_sphere(20000.0)).with_changes(camera={"position_mm": [0, 0, -3000], "focal_length_mm": 300})
    img, ref = render_scene(scene), render_scene(scene, reference=True)
    geometry = ReflectionGeometry(distance_m=(D_MM - THICK / 2) / 1000, camera_distance_m=(3000 - THICK / 2) / 1000)
    res = analyze_reflection(img, pitch_mm=12, geometry=geometry, reference=ref, detrend_degree=0)
    assert float(np.median(res.phi_eff_mD[_interior(res)])) == pytest.approx(-200.0, rel=0.01)


def test_sphere_at_30_deg_reads_tangential_and_sagittal_powers():
    """At 30 deg incidence the principal powers of a concave sphere: -2000/(R cos) and -2000 cos/R, within 1 %."""
    R_m, th = 20.0, 30.0
    res = _analyze(_scene(_sphere(R_m * 1000), incidence_deg=th), incidence_deg=th, detrend_degree=0)
    inner = _interior(res)
    eff, shear = res.phi_eff_mD[inner], res.phi_shear_mD[inner]
    tangential, sagittal = np.median((eff - shear) / 2), np.median((eff + shear) / 2)
    c = math.cos(math.radians(th))
    assert tangential == pytest.approx(-2000 / (R_m * c), rel=0.01)
    assert sagittal == pytest.approx(-2000 * c / R_m, rel=0.01)


def _roll_wave_truth(scene, res, A, lam):
    """tr P of Z = A sin(2 pi u / lam) at each pixel (Coddington with the pixel's own incidence), Gaussian-smoothed."""
    u, _, c, tu = _hit_points(scene)
    k = 2 * math.pi / lam
    zuu = -A * k * k * np.sin(k * u) * math.exp(-0.5 * (k * res.effective_sigma_mm) ** 2)
    return 2 * zuu * (tu**2 / c + (1 - tu**2) * c) * 1e6


@pytest.mark.parametrize("incidence_deg", [0.0, 20.0])
def test_roll_wave_maps(incidence_deg):
    """phi_eff of a 0.1 mm, 400 mm roll wave against its Coddington truth over the interior: gain within 2 %.

    The reflected roll wave's period is within 1 %, and its power amplitude within 3 % of
    2 A (2 pi / lam)^2 F, F = 1 / cos(theta) for a wave across the plane of incidence's trace
    (1 at normal incidence).
    """
    A, lam = 0.1, 400.0
    wave = [{"kind": "roller_wave", "amplitude_mm": A, "wavelength_mm": lam}]
    scene = _scene(wave, incidence_deg=incidence_deg, pixels=(448, 336), focal_mm=105, pitch_mm=20, spp=4)
    res = _analyze(scene, incidence_deg, detrend_degree=0, sigma_mm=14.0)
    truth = _roll_wave_truth(scene, res, A, lam)
    inner = _interior(res)
    gain = float(np.sum(res.phi_eff_mD[inner] * truth[inner]) / np.sum(truth[inner] ** 2))
    assert gain == pytest.approx(1.0, abs=0.02)
    rw = standard_measures(res).reflection
    assert rw["period_mm"] == pytest.approx(lam, rel=0.01)
    F = 1 / math.cos(math.radians(incidence_deg))
    assert rw["power_amplitude_mD"] == pytest.approx(2 * A * (2 * math.pi / lam) ** 2 * F * 1e6, rel=0.03)


def test_flat_pane_reads_below_half_a_millidioptre():
    """A flat pane through the spheres' capture: p95 |phi_eff| <= 0.5 mD (Comparative, default smoothing, 16 spp)."""
    res = _analyze(_scene([]), detrend_degree=0)
    assert np.percentile(np.abs(res.phi_eff_mD[res.trusted]), 95) <= 0.5


def test_back_face_ghost_moves_the_roll_wave_reading_by_under_one_percent():
    """Uncoated 6 mm glass at 20 deg (ghost offset 2.8 mm on the board, 20 mm pitch): with the back face's
    Fresnel-weighted ghost the roll wave's map gain stays within 1 % of the truth (docs/reflection.md: 1.0008)."""
    A, lam, th = 0.1, 400.0, 20.0
    wave = [{"kind": "roller_wave", "amplitude_mm": A, "wavelength_mm": lam}]
    scene = _scene(wave, incidence_deg=th, pixels=(448, 336), focal_mm=105, pitch_mm=20, spp=4, back_face=True)
    res = _analyze(scene, th, detrend_degree=0, sigma_mm=14.0)
    truth = _roll_wave_truth(scene, res, A, lam)
    inner = _interior(res)
    gain = float(np.sum(res.phi_eff_mD[inner] * truth[inner]) / np.sum(truth[inner] ** 2))
    assert gain == pytest.approx(1.0, abs=0.01)


def test_back_face_ghost_renders_with_fresnel_weights():
    """The ghost (back face) changes the image of a flat 6 mm pane only where its copy of the board is displaced."""
    flat = render_scene(_scene([], pixels=(64, 48)))
    ghost = render_scene(_scene([], pixels=(64, 48), back_face=True))
    assert ghost.shape == flat.shape and np.isfinite(ghost).all()
    assert 0 < np.abs(ghost - flat).max() < 1


# --- the command line ---------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sphere_photos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("reflection")
    scene = _scene(_sphere(20000.0), pixels=(256, 192), focal_mm=160)
    write_png16(folder / "pane.png", render_scene(scene))
    write_png16(folder / "flat.png", render_scene(scene, reference=True))
    return folder


def test_cli_reflection_comparative_and_direct(sphere_photos, capsys):
    """Both methods run in reflection; summary.json names the optics and geometry; the Direct Method's notes the uniform power."""
    f = sphere_photos
    common = ["--optics", "reflection", "--pitch-mm", "12", "--distance-m", "1.997", "--detrend-degree", "0", "--quiet"]
    assert main(["analyze", str(f / "pane.png"), "--reference", str(f / "flat.png"), *common, "--out", str(f / "c")]) == 0
    s = json.loads((f / "c" / "summary.json").read_text())
    assert s["optics"]["optics"] == "reflection" and s["optics"]["magnification"] == pytest.approx(2.0)
    assert s["distance_m"] == pytest.approx(1.997)
    assert s["statistics"]["phi_eff_mD"]["mean"] == pytest.approx(-200.0, rel=0.02)
    assert main(["analyze", str(f / "pane.png"), *common, "--out", str(f / "d")]) == 0
    s = json.loads((f / "d" / "summary.json").read_text())
    assert any("absorbed by the homography" in n for n in s["optics"]["notes"])


def test_cli_reflection_options_need_reflection(sphere_photos, capsys):
    f = sphere_photos
    code = main(["analyze", str(f / "pane.png"), "--pitch-mm", "12", "--distance-m", "2", "--incidence-deg", "20",
                 "--out", str(f / "x")])
    assert code == 2
    assert "--optics reflection" in capsys.readouterr().err


def _reflection_spec(folder, max_mD=300.0):
    spec = {"name": "reflection_line", "description": "reflected phi_eff limit, board at 1.997 m",
            "protocol": {"optics": "reflection", "method": "comparative", "distance_m": 1.997, "pitch_mm": 12,
                         "detrend_degree": 0},
            "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": max_mD}]}
    path = folder / f"spec_{int(max_mD)}.json"
    path.write_text(json.dumps(spec))
    return path


def test_spec_pins_reflection_and_judges_reflected_power(sphere_photos, capsys):
    """A specification's protocol pins the optics: the run is in reflection without the option, PASS at 300 mD and
    FAIL (exit 3) at 150 mD on the -200 mD sphere; an option contradicting the pin exits 2."""
    f = sphere_photos
    args = ["analyze", str(f / "pane.png"), "--reference", str(f / "flat.png"), "--quiet"]
    assert main([*args, "--spec", str(_reflection_spec(f)), "--out", str(f / "s1")]) == 0
    s = json.loads((f / "s1" / "summary.json").read_text())
    assert s["optics"]["optics"] == "reflection" and s["verdict"]["passed"]
    assert main([*args, "--spec", str(_reflection_spec(f, 150.0)), "--out", str(f / "s2")]) == 3
    assert main([*args, "--spec", str(_reflection_spec(f)), "--optics", "transmission", "--out", str(f / "s3")]) == 2
    assert "contradicts the protocol" in capsys.readouterr().err


def test_batch_runs_reflection_through_the_spec(sphere_photos):
    """A batch pane whose specification pins reflection is analysed in reflection."""
    f = sphere_photos
    manifest = f / "manifest.csv"
    manifest.write_text(f"id,image,reference,spec\nsphere,pane.png,flat.png,{_reflection_spec(f).name}\n")
    assert main(["batch", str(manifest), "--out", str(f / "batch")]) == 0
    s = json.loads(next((f / "batch").rglob("summary.json")).read_text())
    assert s["optics"]["optics"] == "reflection"
    assert s["statistics"]["phi_eff_mD"]["mean"] == pytest.approx(-200.0, rel=0.02)

