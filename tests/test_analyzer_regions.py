"""One region, one definition: statistics (trusted) within the A2 fit (detrend_region) within valid.

``valid`` adds to the fit region only the ring of partial analysis blocks along its borders,
at most one block wide; the Virtual Pipeline's comparison detrends its truth on the fit region.
"""

import numpy as np
import pytest
from scipy import ndimage

from glassdist import analyze
from glassdist.scene import load_scene
from glassdist.synthetic import lens_displacement, synthetic_capture
from glassdist.theory import predict_displacement
from glassdist.virtual import compare_with_scene
from test_validate import EXAMPLES


@pytest.fixture(scope="module")
def capture():
    cap = synthetic_capture((256, 320), pitch_mm=8.0, mm_per_px=1.0, displacement=lens_displacement(0.02, 2.0, radius_mm=90.0),
                            noise_std=0.01, rng=5)
    yy, xx = np.mgrid[0:256, 0:320]
    img = np.where(np.hypot(yy - 100, xx - 200) < 30, 0.1, cap.image)  # an opaque drop: borders inside the view
    return img, cap.reference


@pytest.mark.parametrize("method", ["comparative", "direct"])
def test_trusted_within_detrend_region_within_valid(capture, method):
    img, ref = capture
    res = analyze(img, pitch_mm=8.0, distance_m=2.0, reference=ref if method == "comparative" else None,
                  params={"sigma_mm": 16.0})
    fit, valid, trusted = res.detrend_region, res.valid, res.trusted
    assert trusted.sum() > 0.3 * trusted.size
    assert not (trusted & ~fit).any()
    assert not (fit & ~valid).any()
    ring = valid & ~fit
    assert ring.any()  # the partial blocks are reported ...
    # ... within one analysis block of the fit region
    dist = ndimage.distance_transform_edt(~fit)
    assert dist[ring].max() <= res.block_px + 1.0
    # the statistics are over the trusted pixels
    assert res.statistics()["phi_eff_mD"]["n_valid"] == int(np.count_nonzero(trusted & np.isfinite(res.phi_eff_mD)))


def test_compare_with_scene_detrends_the_truth_on_the_fit_region(tmp_path):
    scene = load_scene(EXAMPLES / "wavy_slab.yaml").with_changes(
        camera={"pixels": [320, 240]}, backdrop={"pitch_mm": 48.4, "line_width_mm": 10},
        render={"samples_per_pixel": 2, "seed": 2},
    )
    from glassdist.render import render_scene
    from glassdist.theory import analysis_params

    img = render_scene(scene, engine="exact")
    ref = render_scene(scene, engine="exact", reference=True)
    params = analysis_params(scene)  # a wider smoothing: Block A runs on blocks, with partial ones at the borders
    res = analyze(img, pitch_mm=scene.backdrop.pitch_mm, distance_m=scene.backdrop.distance_m, reference=ref,
                  params=params.model_copy(update={"sigma_mm": 4 * params.sigma_mm}))
    val = compare_with_scene(res, scene, model=predict_displacement(scene))
    assert (res.valid & ~res.detrend_region).any()
    # the model's channels exist only where it was detrended: on the fit region, not on the ring
    finite = np.isfinite(val.analytical.phi_eff_mD)
    assert finite.any() and not (finite & ~res.detrend_region).any()
    # the earlier records' yardstick (benchmarks/bench_yardstick.py): detrended on valid, ring included
    old = compare_with_scene(res, scene, model=predict_displacement(scene), truth_region=res.valid)
    ring = np.isfinite(old.analytical.phi_eff_mD) & ~res.detrend_region
    assert ring.any() and not (ring & ~res.valid).any()


def test_trimmed_pixels_take_the_cause_of_their_trim():
    from glassdist.analyzer import fourier as F
    from glassdist.analyzer.region import ANALYSED, BEYOND_RANGE, LOW_MODULATION, pixel_quality

    grid = F.SamplingGrid((32, 32), (8, 8))  # 4 px per sample
    q = np.full((8, 8), ANALYSED, np.uint8)
    q[:, 6:] = BEYOND_RANGE
    valid = np.zeros((32, 32), bool)
    valid[:, :20] = True  # the reported region stops a sample short of the beyond-range area
    out = pixel_quality(q, grid, valid)
    assert (out[:, 20:24] == BEYOND_RANGE).all()  # trimmed next to it: the same cause
    assert (out[:, :20] == ANALYSED).all() and (out[:, 24:] == BEYOND_RANGE).all()
    # with no excluded sample anywhere, a trimmed pixel is low modulation (non-finite values)
    out = pixel_quality(np.full((8, 8), ANALYSED, np.uint8), grid, valid)
    assert (out[:, 20:] == LOW_MODULATION).all()
