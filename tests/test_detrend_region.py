"""The region the A2 detrend was fitted on, written with the result and read back.

``detrend_region`` (the whole analysis blocks of the reported region) is where the analyzer
fits the A2 polynomial; ``valid`` adds a ring of partial blocks where the fit is extrapolated.
A truth detrended on ``valid`` instead is a different truth, so the region is written into
``result.npz`` (both layouts) and described in ``summary.json``, and a truth built from the
files alone, detrended there and compared on the statistics region (``trusted``),
reproduces the analyzer's maps.
"""

import json

import numpy as np
import pytest

from _truth import evaluate
from glassdist import analyze, load_result, write_outputs
from glassdist.synthetic import synthetic_capture, wave_displacement

L = 10.0
PITCH = 8.0


@pytest.fixture(scope="module")
def capture():
    """Two waves and a cubic bow (what the detrend removes), with an opaque drop: borders inside the view."""
    w1, w2 = wave_displacement(0.3, 110.0, 25.0), wave_displacement(0.2, 160.0, 100.0, "transverse")

    def disp(X, Y):
        a, b = w1(X, Y), w2(X, Y)
        return a[0] + b[0] + 2e-7 * X**2 * Y, a[1] + b[1] + 2e-7 * Y**3

    cap = synthetic_capture((256, 320), pitch_mm=PITCH, mm_per_px=1.0, displacement=disp, noise_std=0.005, rng=3)
    yy, xx = np.mgrid[0:256, 0:320]
    image = np.where(np.hypot(yy - 110, xx - 210) < 28, 0.1, cap.image)
    return cap, image


def _analyze(capture, method):
    cap, image = capture
    return analyze(image, pitch_mm=PITCH, distance_m=L, reference=cap.reference if method == "comparative" else None,
                   params={"sigma_mm": 24.0, "detrend_degree": 2})


@pytest.fixture(scope="module")
def comparative(capture):
    return _analyze(capture, "comparative")


@pytest.mark.parametrize("layout", ["analysis", "pixel"])
def test_detrend_region_is_written_described_and_read_back(comparative, tmp_path, layout):
    res = comparative
    assert (res.valid & ~res.detrend_region).any()  # the ring: the two regions differ here
    write_outputs(res, tmp_path, fields=layout, history=False)
    with np.load(tmp_path / "result.npz") as z:
        assert "detrend_region" in z.files
        if layout == "pixel":
            np.testing.assert_array_equal(z["detrend_region"], res.detrend_region)
        else:  # the analysis grid's samples the fit saw, and its pixels
            assert z["detrend_region"].shape == res.analysis_grid.shape and z["detrend_region"].dtype == bool
            assert not (z["detrend_region"] & ~z["grid_valid"]).any() and (z["grid_valid"] & ~z["detrend_region"]).any()
    stored = load_result(tmp_path)
    np.testing.assert_array_equal(stored.detrend_region, res.detrend_region)
    np.testing.assert_array_equal(stored.to_pixel_grid()["detrend_region"], res.detrend_region)
    s = json.loads((tmp_path / "summary.json").read_text())
    assert "detrend_region" in s["fields"]["keys"]
    reg = s["regions"]["detrend_region"]
    assert "A2 detrend was fitted on" in reg["description"]
    assert reg["pixels"] == int(res.detrend_region.sum())
    assert reg["image_percent"] == pytest.approx(100.0 * res.detrend_region.mean())
    # one inside the next: trusted within the fit region within valid
    assert s["regions"]["trusted"]["pixels"] <= reg["pixels"] < s["regions"]["valid"]["pixels"]


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_a_truth_detrended_on_the_written_region_reproduces_the_maps(capture, comparative, tmp_path, method):
    """The truth from the files alone: detrended on the stored ``detrend_region``, compared on ``trusted``.

    Measured (Comparative / Direct): the detrended displacement's RMS error 2.8 / 2.4 % of its
    RMS on the written region, 6.4 / 3.4 % when the truth is detrended on ``valid``;
    phi_eff, phi_shear, phi_total ratios 0.988-1.003, correlation > 0.999.
    """
    cap, _ = capture
    res = comparative if method == "comparative" else _analyze(capture, method)
    write_outputs(res, tmp_path, fields="analysis", history=False)
    stored = load_result(tmp_path)
    s = stored.summary
    trusted = stored.pixel_field("quality") == 0  # the statistics region, from the file
    assert trusted.sum() > 20000 and not (trusted & ~stored.detrend_region).any()

    def truth(fit):
        return evaluate(cap.displacement_mm, stored.valid, distance_m=s["distance_m"], mm_per_px=s["mm_per_px"],
                        detrend_degree=s["detrend_degree"], sigma_mm=s["sigma_mm"], jacobian=cap.jacobian, fit_mask=fit)

    def rel_rms(tr):
        a, b = stored.pixel_field("displacement_detrended_mm")[trusted], tr.displacement_detrended_mm[trusted]
        return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))

    on_fit, on_valid = truth(stored.detrend_region), truth(stored.valid)
    assert rel_rms(on_fit) < 0.04, rel_rms(on_fit)
    assert rel_rms(on_valid) > 1.2 * rel_rms(on_fit), (rel_rms(on_valid), rel_rms(on_fit))  # the region matters
    for ch in ("phi_eff_mD", "phi_shear_mD", "phi_total_mD"):
        a, b = stored.pixel_field(ch)[trusted], getattr(on_fit, ch)[trusted]
        assert np.isfinite(a).all() and np.isfinite(b).all()
        assert np.mean(np.abs(a)) / np.mean(np.abs(b)) == pytest.approx(1.0, abs=0.02), ch
        assert np.corrcoef(a, b)[0, 1] > 0.999, ch
