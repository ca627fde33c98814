"""Reflection off the plane of incidence: the oblique power tensor against the exact reflection.

The tangential and sagittal factors and the cross term of :func:`power_from_strain` (with
:func:`slope_strain`) are checked on the exact tracer's landing field of cylinders at
0-60 deg incidence turned 0-90 deg to the plane of incidence, against Coddington's closed
form evaluated independently (``tests/_truth.py``); then the analyzer on ray-traced roll
waves running across the plane of incidence, single captures, against the same truth over
the result's interior (3 sigma inside its trusted region, smoothed on its detrend region).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import _truth
from glassdist.analyzer.reflection import _components_ts, analyze_reflection, power_from_strain, slope_strain
from glassdist.render import landing_points, render_scene
from test_reflection import D_MM, NOISY_CAMERA, THICK, _geometry, _hit_points, _interior, _rms_percent, _scene

#: A cylinder of radius 200 m: a roller wave of 40 m period at its crest, less its crest height (a plane offset).
CYL_R_MM, CYL_PERIOD_MM = 200_000.0, 40_000.0
CYL_A_MM = 1.0 / (CYL_R_MM * (2 * math.pi / CYL_PERIOD_MM) ** 2)


def _cylinder(turn_deg):
    return [{"kind": "roller_wave", "amplitude_mm": CYL_A_MM, "wavelength_mm": CYL_PERIOD_MM, "direction_deg": turn_deg,
             "phase_deg": 90.0}, {"kind": "plane", "offset_mm": -CYL_A_MM}]


def _wave_height(amplitude_mm, period_mm, turn_deg, phase_deg=0.0):
    b, k = math.radians(turn_deg), 2 * math.pi / period_mm
    return lambda u, v: amplitude_mm * np.sin(k * (np.cos(b) * u + np.sin(b) * v) + math.radians(phase_deg))


def _exact_power(scene, incidence_deg):
    """P (mD, image frame) from the exact landing field: centred differences through the glass-less Jacobian,
    :func:`slope_strain` and :func:`power_from_strain` at each pixel's incidence and plane of incidence."""
    L = landing_points(scene)
    J, G = (np.stack([np.stack(np.gradient(f[..., c])[::-1], -1) for c in range(2)], -2)
            for f in (L.without_glass_mm, L.displacement_mm))
    grad = G @ np.linalg.inv(J)
    eps = 0.5 * (grad + np.swapaxes(grad, -1, -2))
    u, v, _, _ = _hit_points(scene)
    geometry = _geometry(incidence_deg)
    vx, vy = u - (-D_MM * math.tan(math.radians(incidence_deg))), v
    theta = np.degrees(np.arctan(np.hypot(vx, vy) / geometry.camera_distance_mm))
    plane = np.degrees(np.arctan2(vy, vx))
    eps = slope_strain(eps, L.displacement_mm, vx, vy, geometry) * (1e3 / geometry.effective_distance_m)
    return power_from_strain(eps, theta, plane), u, v, plane


@pytest.mark.parametrize("incidence_deg, bound", [(0.0, 0.01), (20.0, 0.01), (40.0, 0.01), (60.0, 0.05)])
def test_oblique_tensor_against_the_exact_reflection_of_a_cylinder(incidence_deg, bound):
    """A concave cylinder (R = 200 m) turned 0, 30, 45, 60, 90 deg to the plane of incidence: P_tt, P_ss and P_ts
    (Coddington: 2 Z_tt / cos, 2 Z_ss cos, 2 Z_ts) from the exact tracer within 1 % of the tensor's size at 0-40 deg
    incidence (measured 0.47 / 0.47 / 0.80 % at 0 / 20 / 40 deg, worst component), 5 % at 60 deg (3.84 %: the
    slopes' second order), and each significant component's median within 0.5 % of the truth's (the factors:
    measured 0.9985-1.0036). A narrow view (focal 300 mm): the height term 2 Z / C that the definition leaves out
    stays under 0.3 %."""
    th = incidence_deg
    for turn in (0.0, 30.0, 45.0, 60.0, 90.0):
        scene = _scene(_cylinder(turn), incidence_deg=th, pixels=(96, 72), focal_mm=300).with_changes(
            pane={"size_mm": [8000, 6000]})
        P, u, v, plane = _exact_power(scene, th)
        height = _wave_height(CYL_A_MM, CYL_PERIOD_MM, turn, 90.0)
        truth = 1e6 * _truth.reflective_power(lambda a, b: height(a, b) - CYL_A_MM, u, v,
                                              foot_mm=(-D_MM * math.tan(math.radians(th)), 0.0),
                                              camera_distance_mm=D_MM - THICK / 2, step_mm=5.0)
        a = np.radians(plane)
        inner = (slice(2, -2), slice(2, -2))
        got = _components_ts(P, np.cos(a), np.sin(a))
        want = _components_ts(truth, np.cos(a), np.sin(a))
        scale = float(np.median(np.linalg.norm(truth[inner], axis=(-2, -1))))
        b, c = math.radians(turn), math.cos(math.radians(th))  # the truth's trace at the centre: concave, < 0
        assert np.median(np.trace(truth[inner], axis1=-2, axis2=-1)) == pytest.approx(
            -2e6 / CYL_R_MM * (math.cos(b) ** 2 / c + c * math.sin(b) ** 2), rel=0.02)
        for g, w in zip(got, want):
            assert np.abs(g[inner] - w[inner]).max() <= bound * scale, (turn, np.abs(g - w)[inner].max() / scale)
            if abs(np.median(w[inner])) > 0.1 * scale:
                assert np.median(g[inner]) == pytest.approx(np.median(w[inner]), rel=0.005), turn


ROLL_A_MM, ROLL_PERIOD_MM = 0.05, 350.0


@pytest.fixture(scope="module", params=[(0.0, 30.0), (20.0, 60.0), (45.0, 30.0), (45.0, 90.0)],
                ids=lambda p: f"{p[0]:.0f}deg-turn{p[1]:.0f}")
def roll_wave_run(request):
    """A roll wave (350 mm, 0.05 mm) turned to the plane of incidence, 28 mm board pitch, 512 x 384 px, camera
    noise, one sample per pixel; both methods on the one render, and the truth of each result."""
    th, turn = request.param
    wave = [{"kind": "roller_wave", "amplitude_mm": ROLL_A_MM, "wavelength_mm": ROLL_PERIOD_MM, "direction_deg": turn}]
    scene = _scene(wave, incidence_deg=th, pixels=(512, 384), focal_mm=105, pitch_mm=28).with_changes(
        imaging=NOISY_CAMERA, pane={"size_mm": [4000, 3000]})
    img, ref = render_scene(scene), render_scene(scene, reference=True)
    u, v, _, _ = _hit_points(scene)
    P = _truth.reflective_power(_wave_height(ROLL_A_MM, ROLL_PERIOD_MM, turn), u, v,
                                foot_mm=(-D_MM * math.tan(math.radians(th)), 0.0), camera_distance_mm=D_MM - THICK / 2)
    out = {}
    for method, reference in (("comparative", ref), ("direct", None)):
        res = analyze_reflection(img, pitch_mm=28, geometry=_geometry(th), reference=reference, detrend_degree=0)
        out[method] = res, _truth.reflected_channels(P, res.detrend_region, res.effective_sigma_mm / res.mm_per_px)
    return out


def _ratio(res, truth, inner):
    return float(np.mean(np.abs(res.phi_eff_mD[inner])) / np.mean(np.abs(truth[0][inner])))


def test_roll_wave_across_the_plane_of_incidence_comparative(roll_wave_run):
    """Comparative: mean |phi_eff| within 1 % of the truth's (measured 0.998 / 1.001 / 1.001 / 1.005); the phi_eff
    map and the astigmatism tensor within 4 % RMS of the truth's RMS (measured 0.85 / 2.30 / 3.07 / 2.16 % and
    1.31 / 2.90 / 3.49 / 2.72 %: the camera noise on a pane seen foreshortened, 0.05 mm of wave)."""
    res, truth = roll_wave_run["comparative"]
    inner = _interior(res)
    assert inner.mean() > 0.15
    scale = np.sqrt(np.mean(truth[0][inner] ** 2))
    assert _ratio(res, truth, inner) == pytest.approx(1.0, abs=0.01)
    assert max(_rms_percent(res, (truth[0], truth[1], truth[3]), inner, scale)) <= 4.0


def test_roll_wave_across_the_plane_of_incidence_direct(roll_wave_run):
    """Direct: with each power component's best-fit plane removed from the difference (the homography takes a
    uniform power and the keystone ramps, module notes of glassdist.analyzer.reflection), phi_eff and the
    astigmatism tensor within 4 % RMS of the truth's RMS (measured 0.39 / 1.99 / 2.99 / 3.57 % and
    0.60 / 2.53 / 3.13 / 3.76 %). With the planes kept the mean |phi_eff| reads 1.002 / 1.100 / 1.001 / 1.010 of
    the truth's: a wave of two periods in view is not orthogonal to the homography's terms."""
    res, truth = roll_wave_run["direct"]
    inner = _interior(res)
    scale = np.sqrt(np.mean(truth[0][inner] ** 2))
    assert max(_rms_percent(res, (truth[0], truth[1], truth[3]), inner, scale, planes=True)) <= 4.0


@pytest.mark.parametrize("incidence_deg, floor_mD", [(0.0, 0.45), (20.0, 0.8)])
def test_flat_pane_direct_floor(incidence_deg, floor_mD):
    """A flat pane, no camera noise, 512 x 384 px, 28 mm board pitch, Direct Method: p95 |phi_eff| at the floor the
    module notes of glassdist.analyzer.reflection state (measured 0.35 mD at normal incidence, 0.67 mD at 20 deg,
    the same with 16 samples per pixel; the Comparative Method reads 0.000 on the same render). The claim of
    0.5 mD holds for the Comparative Method (test_reflection.py) and not, at oblique incidence, for the Direct."""
    scene = _scene([], incidence_deg=incidence_deg, pixels=(512, 384), focal_mm=105, pitch_mm=28)
    img = render_scene(scene)
    res = analyze_reflection(img, pitch_mm=28, geometry=_geometry(incidence_deg), detrend_degree=0)
    assert np.percentile(np.abs(res.phi_eff_mD[res.trusted]), 95) <= floor_mD
    ref = render_scene(scene, reference=True)
    res = analyze_reflection(img, pitch_mm=28, geometry=_geometry(incidence_deg), reference=ref, detrend_degree=0)
    assert np.percentile(np.abs(res.phi_eff_mD[res.trusted]), 95) <= 0.01
