"""The Direct Method on a small view with a local lens: the homography's take, stated from the data, against the truth.

A view of about 9 x 7 carrier periods (512 x 384 px, 200 mm grid at L = 10 m, camera 5 m from
the pane) with a converging lens of compact support (a polynomial bump on both faces) covering
a fifth to a third of it, off-centre, and a weak oblique ripple; N = 1, sigma one carrier
period. The homography fitted to the whole view takes in part of the lens (its scale and
keystone). The truth: the tracer's landing displacement through the plain, independent
evaluation (:func:`glassdist.experiments.transfer.independent_phi_eff`) at the result's N and
sigma, over its trusted pixels; single renders.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import glassdist
from glassdist.experiments.transfer import independent_phi_eff
from glassdist.render import landing_points, render_scene
from glassdist.scene import landing_jacobian, scene_from_dict

SAID = re.compile(r"biased by ([+-]\d+)% in mean \|phi_eff\|.* and ([+-]\d+)% in p95 \|phi_eff\|")


def _scene(amplitude_mm, radius_mm, center_u_mm):
    bump = {"kind": "bump", "radius_mm": radius_mm, "order": 3, "center_mm": [center_u_mm, 40.0]}
    return scene_from_dict({
        "pane": {"size_mm": [1400, 1000], "thickness_mm": 10, "refractive_index": 1.52, "deformation": {
            "both": [{"kind": "roller_wave", "amplitude_mm": 0.01, "wavelength_mm": 240, "direction_deg": 35}],
            "front": [{**bump, "amplitude_mm": -amplitude_mm}], "back": [{**bump, "amplitude_mm": amplitude_mm}]}},
        "backdrop": {"pattern": "lines", "pitch_mm": 200.0, "line_width_mm": 50.0, "distance_m": 10},
        "camera": {"focal_length_mm": 300, "sensor_width_mm": 36, "pixels": [512, 384], "position_mm": [0, 0, -5000]},
        "render": {"samples_per_pixel": 4, "seed": 3}})


def _biases(sc):
    """(true, stated) biases in % of (mean, p95) |phi_eff| of the Direct reading; stated None without the warning."""
    res = glassdist.analyze(render_scene(sc), pitch_mm=200.0, distance_m=10,
                            params={"detrend_degree": 1, "pattern": "lines", "sigma_mm": 200.0})
    land = landing_points(sc)
    truth = independent_phi_eff(np.nan_to_num(land.displacement_mm), res.valid, jacobian=landing_jacobian(sc),
                                sigma_px=res.sigma_mm / res.mm_per_px, degree=1, distance_m=res.distance_m)
    ok = res.trusted & np.isfinite(truth)
    m, t = np.abs(res.phi_eff_mD[ok]), np.abs(truth[ok])
    true = (100 * (m.mean() / t.mean() - 1), 100 * (np.percentile(m, 95) / np.percentile(t, 95) - 1))
    said = [SAID.search(w) for w in res.warnings if "takes in part of a local feature" in w]
    return true, (None if not said or said[0] is None else (float(said[0].group(1)), float(said[0].group(2))))


@pytest.mark.slow
@pytest.mark.parametrize("lens, both", [((0.09, 170.0, -90.0), True), ((0.07, 150.0, 60.0), True),
                                        ((0.05, 200.0, -60.0), False), ((0.09, 130.0, -120.0), False)],
                         ids=["r170", "r150", "r200", "r130"])
def test_homography_take_of_a_local_lens_is_stated(lens, both):
    """The Direct reading is short inside the lens (mean |phi_eff| 25-38 % below the truth's); the warning states
    the bias from the data (the homography refitted to the glass around the feature). Measured, stated / true, mean
    and p95: r170 -31 / -38.0 and -29 / -28.9; r150 -24 / -25.1 and -18 / -14.0; r200 -25 / -25.2 and -23 / -13.4;
    r130 -12 / -25.2 and -29 / -31.3. Both within a third of the truth on r170 and r150; on r200 and r130 one of
    the two (the other overstates the p95's by 10 points, or understates the mean's by half)."""
    true, said = _biases(_scene(*lens))
    assert min(true) < -10.0
    assert said is not None and max(said) < 0  # the sign: the reading is short
    close = [abs(s - t) <= abs(t) / 3 for s, t in zip(said, true)]
    assert all(close) if both else any(close), (said, true)


@pytest.mark.slow
def test_no_take_stated_for_a_wave_over_the_whole_view():
    """A roller wave on one face (thickness ripple, 1.3 periods in view) and no local lens: nothing to state."""
    sc = _scene(0.0, 150.0, 0.0).with_changes(pane={"deformation": {"both": [], "back": [], "front": [
        {"kind": "roller_wave", "amplitude_mm": 0.05, "wavelength_mm": 450, "direction_deg": 20}]}})
    _, said = _biases(sc)
    assert said is None
