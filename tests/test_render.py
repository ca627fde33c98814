import math

import numpy as np
import pytest

from glassdist.errors import InputError
from glassdist.render import ExactTracer, Renderer, get_renderer, landing_points, render_scene, trace_rays
from glassdist.render.tracer import strata
from glassdist.scene import landing_jacobian
from test_scene_helpers import make_scene

AXIS = np.array([[0.0, 0.0, 1.0]])
N, D, L_MM = 1.52, 20.0, 10000.0


@pytest.mark.parametrize("alpha_deg", [0.0, 15.0, 30.0, 45.0])
def test_flat_slab_lateral_shift_matches_closed_form(alpha_deg):
    # pane turned by +alpha about the vertical axis; the on-axis ray exits shifted to +X by
    # s = d sin(alpha - beta) / cos(beta) (Hecht 2017 §4.4), parallel to itself
    scene = make_scene(yaw=alpha_deg)
    dx, dy = trace_rays(scene, AXIS).landing_mm[0]
    a = math.radians(alpha_deg)
    b = math.asin(math.sin(a) / N)
    assert dx == pytest.approx(D * math.sin(a - b) / math.cos(b), abs=1e-9)
    assert dy == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("slope", [1e-3, 1e-2, -5e-3])
def test_thin_prism_deviation_matches_closed_form(slope):
    # back face h = slope * u: a wedge thicker towards +x for slope > 0. At normal entry the
    # ray meets the back face at gamma = atan(slope) and leaves at theta, sin(theta) = n sin(gamma);
    # it deviates by theta - gamma towards the thick side over the path L - d/2 to the backdrop.
    scene = make_scene(deformation={"back": [{"kind": "plane", "slope": [slope, 0.0]}]})
    dx, dy = trace_rays(scene, AXIS).landing_mm[0]
    g = math.atan(slope)
    th = math.asin(N * math.sin(g))
    assert dx == pytest.approx((L_MM - D / 2) * math.tan(th - g), rel=1e-9, abs=1e-9)
    assert np.sign(dx) == np.sign(slope)  # sign: a +x wedge deflects the landing point to +x
    assert dy == pytest.approx(0.0, abs=1e-9)


def test_thin_lens_power_through_a_pinhole():
    # biconvex caps, |R| = 100 m: P = 2 (n - 1) / R; far-background reading through a pinhole
    # at Dc: phi_eff = -2 P Dc / (Dc + L) (converging lens -> phi_eff < 0)
    R = 100_000.0
    dc = 3000.0 - D / 2
    scene = make_scene(
        pixels=(48, 48),
        deformation={"front": [{"kind": "spherical_cap", "radius_mm": -R, "aperture_mm": 400}],
                     "back": [{"kind": "spherical_cap", "radius_mm": R, "aperture_mm": 400}]},
    )
    lp = landing_points(scene)
    flat = landing_points(make_scene(pixels=(48, 48)))
    # the lens alone: remove the flat slab's own (angle-dependent) lateral shift
    delta, X = lp.displacement_mm - flat.displacement_mm, lp.without_glass_mm
    c = slice(14, 34)
    ddx = np.gradient(delta[..., 0], axis=1) / np.gradient(X[..., 0], axis=1)
    ddy = np.gradient(delta[..., 1], axis=0) / np.gradient(X[..., 1], axis=0)
    phi_eff_mD = np.mean((ddx + ddy)[c, c]) / 10.0 * 1000.0
    P_mD = 2 * (N - 1) / (R / 1000.0) * 1000.0
    expected = -2 * P_mD * dc / (dc + L_MM)
    assert phi_eff_mD < 0
    assert phi_eff_mD == pytest.approx(expected, rel=0.01)


def test_rays_missing_the_pane_go_straight_and_the_frame_blocks():
    scene = make_scene(pane_size=(200, 200), frame={"width_mm": 20}, yaw=10.0)
    lp = landing_points(scene)
    status, delta = lp.status, lp.displacement_mm
    assert {0, 1, 2} <= set(np.unique(status))
    assert np.all(delta[status == 0] == 0.0)
    assert np.all(np.isnan(delta[status == 2]))
    assert np.all(np.abs(delta[status == 1][:, 0]) > 0.1)


def test_render_is_deterministic_and_seeded():
    scene = make_scene(pixels=(48, 32), deformation={"both": [{"kind": "roller_wave", "amplitude_mm": 0.2,
                                                               "wavelength_mm": 100}]},
                       render={"samples_per_pixel": 4, "seed": 3},
                       imaging={"noise": {"full_well_e": 5000, "read_noise": 0.002}})
    a, b = render_scene(scene), render_scene(scene)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, render_scene(scene, seed=4))
    ref = render_scene(scene, reference=True)
    assert ref.shape == (32, 48) and 0.0 <= ref.min() and ref.max() <= 1.0
    assert not np.array_equal(a, ref)


def test_stratified_supersampling_keeps_line_positions_unbiased():
    # glass-less view of vertical lines; the carrier phase along x must sit where the
    # backdrop geometry puts it, to within 0.01 px
    pitch = 97.5  # 8 px, 16 whole periods across the image
    scene = make_scene(pixels=(128, 16), backdrop=dict(pitch_mm=pitch, line_width_mm=20, offset_mm=[31.0, 0]),
                       render={"samples_per_pixel": 4, "seed": 0})
    img = render_scene(scene, reference=True)
    prof = img.mean(axis=0)
    J = landing_jacobian(scene)
    mmpx = J[8, 64, 0, 0]
    col = np.arange(128) + 0.5
    X = (col - 64) * mmpx  # on-axis camera: X is linear in col to 1e-6
    k = 2 * np.pi / pitch
    z = np.sum((prof - prof.mean()) * np.exp(-1j * k * X))
    # dark lines at X = offset + m * pitch: the fundamental is -cos(k (X - offset))
    measured_offset_mm = (-np.angle(-z) / k) % pitch
    assert abs(measured_offset_mm - 31.0) / mmpx < 0.01


def test_imaging_effects_change_the_image_as_documented():
    base = dict(pixels=(48, 32), render={"samples_per_pixel": 1, "seed": 0})
    clean = render_scene(make_scene(**base), reference=True)
    blurred = render_scene(make_scene(imaging={"blur_px": 2.0}, **base), reference=True)
    vign = render_scene(make_scene(imaging={"vignetting": 0.3}, **base), reference=True)
    lit = render_scene(make_scene(imaging={"lighting": {"gradient": 0.2}}, **base), reference=True)
    assert blurred.std() < clean.std()
    assert vign[0, 0] < clean[0, 0] and vign[16, 24] == pytest.approx(clean[16, 24], rel=0.01)
    assert lit[:, -4:].mean() > lit[:, :4].mean()


def test_engine_registry_and_protocol():
    eng = get_renderer("exact")
    assert isinstance(eng, ExactTracer) and isinstance(eng, Renderer)
    with pytest.raises(InputError, match="unknown render engine"):
        get_renderer("raymarcher")
    assert strata(16) == (4, 4) and strata(8) == (4, 2) and strata(7) == (7, 1)
