"""The `bump` deformation (a lens of compact support): closed forms and finite differences."""

import numpy as np

from glassdist.scene import load_scene
from glassdist.scene.surfaces import PolynomialBump

_SCENES = __import__("pathlib").Path(__file__).resolve().parents[1] / "examples" / "scenes"


def test_bump_height_slopes_and_curvatures():
    t = PolynomialBump(kind="bump", amplitude_mm=0.05, radius_mm=175.0, order=3, center_mm=(10.0, -5.0))
    rng = np.random.default_rng(1)
    u, v = rng.uniform(-250, 250, (2, 400))
    h = 1e-3
    gu, gv = t.gradient(u, v)
    assert np.allclose(gu, (t.height(u + h, v) - t.height(u - h, v)) / (2 * h), atol=1e-9)
    assert np.allclose(gv, (t.height(u, v + h) - t.height(u, v - h)) / (2 * h), atol=1e-9)
    huu, huv, hvv = t.hessian(u, v)
    assert np.allclose(huu, (t.gradient(u + h, v)[0] - t.gradient(u - h, v)[0]) / (2 * h), atol=1e-9)
    assert np.allclose(huv, (t.gradient(u, v + h)[0] - t.gradient(u, v - h)[0]) / (2 * h), atol=1e-9)
    assert np.allclose(hvv, (t.gradient(u, v + h)[1] - t.gradient(u, v - h)[1]) / (2 * h), atol=1e-9)
    # Closed forms: A at the centre, curvature -2 m A / R^2 there; zero (flat glass) outside R.
    assert t.height(10.0, -5.0) == 0.05
    assert np.allclose(t.hessian(10.0, -5.0), (-2 * 3 * 0.05 / 175**2, 0.0, -2 * 3 * 0.05 / 175**2))
    out = np.hypot(u - 10, v + 5) >= 175
    assert out.any() and not np.any(t.height(u, v)[out]) and not np.any(np.stack(t.hessian(u, v))[:, out])
    # order 2: curvature steps at the rim, still zero outside
    t2 = PolynomialBump(kind="bump", amplitude_mm=0.05, radius_mm=175.0, order=2)
    assert not np.any(t2.hessian(200.0, 0.0))


def test_large_lens_scene_power_at_its_centre():
    # Thin-lens power of the thickening 2 A q^m: (n - 1) 4 m A / R^2 = 10.19 mD for the example scene.
    scene = load_scene(_SCENES / "large_lens.yaml")
    front, back = scene.pane.deformation.front[0], scene.pane.deformation.back[0]
    assert front.kind == back.kind == "bump" and front.amplitude_mm == -back.amplitude_mm
    curv = back.hessian(0.0, 0.0)[0] - front.hessian(0.0, 0.0)[0]  # d^2 (thickness) / du^2, 1/mm
    power_mD = -(scene.pane.refractive_index - 1) * curv * 1e6
    assert abs(power_mD - 10.19) < 0.01
