import json
from pathlib import Path

import numpy as np
import pytest

from glassdist.errors import InputError
from glassdist.scene import (
    EdgeLift,
    GaussianBump,
    Pillow,
    Plane,
    RollerWave,
    SphericalCap,
    landing_jacobian,
    load_scene,
    pattern_intensity,
)
from glassdist.theory import carrier_period_mm, nominal_mm_per_px
from test_scene_helpers import make_scene

EXAMPLES = sorted((Path(__file__).parents[1] / "examples" / "scenes").glob("*.yaml"))

TERMS = [
    RollerWave(kind="roller_wave", amplitude_mm=0.2, wavelength_mm=150, direction_deg=25, phase_deg=10,
               harmonics=[{"order": 2, "amplitude_mm": 0.03, "phase_deg": 40}]),
    Pillow(kind="pillow", amplitude_mm=1.0, size_mm=(900, 700), center_mm=(20, -10)),
    SphericalCap(kind="spherical_cap", radius_mm=-20000, aperture_mm=300, center_mm=(10, 5)),
    GaussianBump(kind="gaussian", amplitude_mm=0.05, sigma_mm=40, center_mm=(-5, 8)),
    Plane(kind="plane", slope=(1e-3, -2e-3), offset_mm=0.1),
    EdgeLift(kind="edge_lift", height_mm=0.3, width_mm=60, size_mm=(300, 260), center_mm=(10, -5)),
]


@pytest.mark.parametrize("term", TERMS, ids=lambda t: t.kind)
def test_term_derivatives_match_finite_differences(term):
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-200, 200, (2, 50))
    h = 1e-3
    gu, gv = term.gradient(u, v)
    fd_u = (term.height(u + h, v) - term.height(u - h, v)) / (2 * h)
    fd_v = (term.height(u, v + h) - term.height(u, v - h)) / (2 * h)
    scale = max(np.abs(gu).max(), np.abs(gv).max(), 1e-12)
    assert np.allclose(gu, fd_u, atol=1e-5 * scale) and np.allclose(gv, fd_v, atol=1e-5 * scale)
    huu, huv, hvv = term.hessian(u, v)
    fd_uu = (term.gradient(u + h, v)[0] - term.gradient(u - h, v)[0]) / (2 * h)
    fd_uv = (term.gradient(u, v + h)[0] - term.gradient(u, v - h)[0]) / (2 * h)
    fd_vv = (term.gradient(u, v + h)[1] - term.gradient(u, v - h)[1]) / (2 * h)
    hs = max(np.abs(huu).max(), np.abs(hvv).max(), 1e-12)
    for a, b in ((huu, fd_uu), (huv, fd_uv), (hvv, fd_vv)):
        assert np.allclose(a, b, atol=1e-5 * hs)
    hg = term.height_gradient(u, v)
    assert np.allclose(hg[0], term.height(u, v)) and np.allclose(hg[1], gu) and np.allclose(hg[2], gv)


def test_edge_lift_height_is_the_quadratic_of_the_distance_in_from_each_edge():
    """h (1 - d / w)^2 within w of each named edge (d from that edge, top = smaller v), 0 further in, h beyond the
    edge; the two edges' lifts add at a corner; slope -2 h / w at the edge, pointing out of the pane."""
    t = EdgeLift(kind="edge_lift", height_mm=0.4, width_mm=60, size_mm=(800, 600), center_mm=(100, 50))
    left, top = 100 - 400, 50 - 300
    d = np.array([0.0, 15.0, 30.0, 59.0, 60.0, 200.0])
    want = 0.4 * np.clip(1 - d / 60, 0, None) ** 2
    v0 = np.full_like(d, 50.0)
    np.testing.assert_allclose(t.height(left + d, v0), want, atol=1e-15)  # left edge
    np.testing.assert_allclose(t.height(100 + 400 - d, v0), want, atol=1e-15)  # right
    np.testing.assert_allclose(t.height(100 + 0 * d, top + d), want, atol=1e-15)  # top: v = centre - b / 2
    np.testing.assert_allclose(t.height(100 + 0 * d, 50 + 300 - d), want, atol=1e-15)  # bottom
    assert t.height(left + 10.0, top + 20.0) == pytest.approx(0.4 * ((5 / 6) ** 2 + (2 / 3) ** 2), rel=1e-12)
    assert t.height(left - 5.0, 50.0) == pytest.approx(0.4)  # beyond the edge: the edge's height
    gu, gv = t.gradient(np.array([left, 100 + 400.0]), np.array([50.0, 50.0]))
    np.testing.assert_allclose(gu, [-2 * 0.4 / 60, 2 * 0.4 / 60], rtol=1e-12)
    only = EdgeLift(kind="edge_lift", height_mm=0.4, width_mm=60, size_mm=(800, 600), center_mm=(100, 50),
                    edges=("top",))
    assert only.height(left, 50.0) == 0.0 and only.height(100.0, top) == pytest.approx(0.4)


@pytest.mark.parametrize("span_mm", [200.0, 600.0], ids=["inside", "across the edge"])
def test_pillow_height_gradient_is_height_and_gradient_exactly(span_mm):
    """The tracer's fused call gives the same values, bit for bit, as height and gradient, whether the
    points all lie on the dome or some lie beyond it (where all three are 0)."""
    term = TERMS[1]
    u, v = np.random.default_rng(1).uniform(-span_mm, span_mm, (2, 400))
    h, hu, hv = term.height_gradient(u, v)
    gu, gv = term.gradient(u, v)
    assert np.array_equal(h, term.height(u, v)) and np.array_equal(hu, gu) and np.array_equal(hv, gv)
    outside = (np.abs(u - 20) >= 450) | (np.abs(v + 10) >= 350)
    assert outside.any() == (span_mm > 400) and not np.any(np.c_[h, hu, hv][outside])


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_examples_load_and_resolve_the_carrier(path):
    scene = load_scene(path)
    period_px = carrier_period_mm(scene) / nominal_mm_per_px(scene)
    assert period_px >= 6.0


def test_example_set_covers_the_paper_cases():
    names = {p.stem for p in EXAMPLES}
    assert {"wavy_slab", "biconvex_lens_p96", "biconvex_lens_p64", "biconvex_lens_p48",
            "mild_slab_aligned", "mild_slab_rotated", "pillowed_igu"} <= names


def test_bad_scenes_raise_one_line_input_errors(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_scene(tmp_path / "missing.yaml")
    good = make_scene().model_dump(mode="json")
    for mutate, pattern in (
        (lambda d: d["pane"].__setitem__("thickness_mm", -1), "thickness_mm"),
        (lambda d: d["pane"].__setitem__("colour", "green"), "unknown key 'pane.colour'"),
        (lambda d: d.pop("camera"), "missing key 'camera'"),
        (lambda d: d["camera"].__setitem__("position_mm", [0, 0, 500]), "in front of the pane"),
        (lambda d: d["pane"]["deformation"].__setitem__("both", [{"kind": "ripple"}]), "deformation"),
    ):
        data = json.loads(json.dumps(good))
        mutate(data)
        f = tmp_path / "bad.json"
        f.write_text(json.dumps(data))
        with pytest.raises(InputError, match=pattern) as exc:
            load_scene(f)
        assert "\n" not in str(exc.value)
    f = tmp_path / "broken.yaml"
    f.write_text("pane: [1, 2\n")
    with pytest.raises(InputError, match="cannot be parsed"):
        load_scene(f)


def test_box_filtered_pattern_has_the_printed_duty_cycle():
    scene = make_scene(backdrop=dict(pitch_mm=20.0, line_width_mm=5.0))
    x = np.linspace(0, 20, 2001)[:-1]
    cover = pattern_intensity(scene.backdrop, x, np.full_like(x, 10.0))
    b, w = scene.backdrop.black, scene.backdrop.white
    assert np.mean(cover) == pytest.approx(w - (w - b) * 0.25, abs=1e-3)
    # a box spanning whole periods averages to the same value everywhere
    boxed = pattern_intensity(scene.backdrop, x, np.full_like(x, 10.0), (np.full_like(x, 20.0), 0.0))
    assert np.allclose(boxed, w - (w - b) * 0.25)
    cb = make_scene(backdrop=dict(pattern="checkerboard", pitch_mm=30.0, line_width_mm=None))
    assert pattern_intensity(cb.backdrop, 1.0, 1.0) == pytest.approx(cb.backdrop.white)
    assert pattern_intensity(cb.backdrop, 31.0, 1.0) == pytest.approx(cb.backdrop.black)


@pytest.mark.parametrize("pattern", ["lines", "checkerboard"])
@pytest.mark.parametrize("points", ["all boxes", "some points"])
def test_box_filtered_pattern_is_the_printed_patterns_mean_over_the_box(pattern, points):
    """Against a midpoint rule over the printed pattern (4 000 samples a side), boxes of 0.3-15 mm on a
    7.7 mm pitch; with some half-widths 0 (point samples: the printed value) among them."""
    spec = dict(pattern=pattern, pitch_mm=7.7, line_width_mm=2.1 if pattern == "lines" else None)
    bd = make_scene(backdrop=spec).backdrop
    rng = np.random.default_rng(4)
    x, y = rng.uniform(-60, 60, (2, 40))
    hx, hy = rng.uniform(0.3, 15.0, (2, 40))
    if points == "some points":
        hx[::3], hy[::4] = 0.0, 0.0
    t = (np.arange(4000) + 0.5) / 4000 * 2 - 1  # midpoints of [-1, 1]
    u, v = x[:, None] + hx[:, None] * t, y[:, None] + hy[:, None] * t
    p, b, w = bd.pitch_mm, bd.black, bd.white
    if pattern == "lines":  # line of width 2.1 mm centred on every multiple of the pitch
        on_u, on_v = (np.abs((u + p / 2) % p - p / 2) < 1.05).mean(1), (np.abs((v + p / 2) % p - p / 2) < 1.05).mean(1)
        truth = w - (w - b) * (1 - (1 - on_u) * (1 - on_v))
    else:  # +1 on [0, p) of each 2p, the product of the two square waves
        su, sv = np.where(u % (2 * p) < p, 1.0, -1.0).mean(1), np.where(v % (2 * p) < p, 1.0, -1.0).mean(1)
        truth = (w + b) / 2 + (w - b) / 2 * su * sv
    got = pattern_intensity(bd, x, y, (hx, hy))
    assert np.allclose(got, truth, atol=2e-3 * (w - b))


def test_backdrop_frame_follows_the_image_axes():
    scene = make_scene(pixels=(64, 48))
    J = landing_jacobian(scene)
    # +col moves the landing point to +X, +row to +Y (camera without roll)
    assert np.all(J[..., 0, 0] > 0) and np.all(J[..., 1, 1] > 0)
    assert np.abs(J[..., 0, 1]).max() < 1e-9 * J[..., 0, 0].max() + 1e-12
    # mm per px = pixel pitch * distance / f
    assert J[24, 32, 0, 0] == pytest.approx(36 / 64 * 13000 / 300, rel=1e-4)
