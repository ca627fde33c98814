"""Statistics and worst regions taken block by block of image rows equal those of the whole fields.

The acceptance stage never holds a full-size copy of a channel: it brings the fields to the
pixel grid a block of rows at a time (:meth:`AnalysisResult.pixel_rows`). Against the whole
pixel-grid fields: counts, maxima and the 95th percentile are identical, the mean and the
standard deviation equal float64 sums of the whole field to 1e-9 (and numpy's float32
pairwise sums to their own 1e-5), and the worst regions are the same regions.
"""

import numpy as np
import pytest

import glassdist
from glassdist.acceptance import stats as S
from glassdist.acceptance.regions import all_worst_regions, worst_regions
from glassdist.acceptance.zones import measured_region, pane_frame
from glassdist.synthetic import lens_displacement, synthetic_capture, wave_displacement


@pytest.fixture(scope="module")
def result():
    def disp(X, Y):  # two lenses of opposite signs on a wave: signed phi_eff, several worst regions
        a = lens_displacement(-0.04, 2.0, center_mm=(120.0, -40.0), radius_mm=60.0)(X, Y)
        b = lens_displacement(0.04, 2.0, center_mm=(-130.0, 50.0), radius_mm=60.0)(X, Y)
        c = wave_displacement(0.1, 90.0, 25.0)(X, Y)
        return a[0] + b[0] + c[0], a[1] + b[1] + c[1]

    cap = synthetic_capture((420, 560), pitch_mm=6.0, mm_per_px=1.0, displacement=disp, noise_std=0.01, rng=3)
    return glassdist.analyze(cap.image, pitch_mm=6.0, distance_m=2.0, reference=cap.reference)


def _whole(res, region, ch):
    return S.acceptance_statistics(getattr(res, S.STATISTIC_FIELDS[ch]), region, over_limits_mD=(5.0, 20.0))


@pytest.mark.parametrize("max_pixels", [560, 560 * 37, 1 << 21])
def test_blockwise_statistics_equal_the_whole_field(result, max_pixels):
    trusted = measured_region(result)
    half = trusted.copy()
    half[:, 300:] = False
    channels = ("phi_eff", "phi_shear", "phi_total", "phi_eff_sigma")
    got = S.regions_statistics(result, {"all": trusted, "left": half}, channels=channels,
                               over_limits_mD={c: (5.0, 20.0) for c in channels}, max_pixels=max_pixels)
    for key, region in (("all", trusted), ("left", half)):
        for ch in channels:
            ref, new = _whole(result, region, ch), got[key][ch]
            assert set(ref) == set(new)
            for k in ("n_valid", "max_abs", "p95_abs", "area_over_5", "area_over_20"):
                assert new[k] == ref[k], (key, ch, k)
            f = getattr(result, S.STATISTIC_FIELDS[ch])
            x = f[region & np.isfinite(f)].astype(np.float64)  # float64 sums of the whole field
            for k, v in (("mean_abs", np.abs(x).mean()), ("mean", x.mean()), ("std", x.std())):
                assert new[k] == pytest.approx(v, rel=1e-9, abs=1e-12 * ref["max_abs"]), (key, ch, k)
                assert new[k] == pytest.approx(ref[k], rel=1e-5, abs=1e-6 * ref["mean_abs"]), (key, ch, k)


def test_a_missed_bracket_still_gives_the_exact_percentile(result, monkeypatch):
    from glassdist.analyzer import metrics

    # a bracket far above every value: the rank check fails and the whole field is used
    monkeypatch.setattr(metrics, "percentile_bracket", lambda sample, q=95.0, **kw: (1e6, 2e6))
    trusted = measured_region(result)
    got = S.regions_statistics(result, {"all": trusted}, channels=("phi_eff",), max_pixels=560 * 50)["all"]["phi_eff"]
    assert got["p95_abs"] == _whole(result, trusted, "phi_eff")["p95_abs"]


def test_an_empty_region_reads_nan(result):
    got = S.regions_statistics(result, {"none": np.zeros(result.valid.shape, bool)}, channels=("phi_eff",))
    st = got["none"]["phi_eff"]
    assert st["n_valid"] == 0 and np.isnan(st["mean_abs"]) and np.isnan(st["p95_abs"])


def test_blockwise_worst_regions_equal_the_whole_field(result):
    frame = pane_frame(result, None)
    found = all_worst_regions(result, frame)
    valid = measured_region(result)
    for ch, entry in found.items():
        ref = worst_regions(getattr(result, S.CHANNEL_FIELDS[ch]), valid, frame, entry["threshold_mD"], channel=ch)
        assert len(ref) > 1  # the scene is built to have several
        assert entry["regions"] == ref
