"""Acceptance specifications: loading (one-line errors) and verdicts on fields of known statistics."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from glassdist.acceptance.spec import load_spec, spec_limits, spec_verdict
from glassdist.acceptance.stats import acceptance_statistics, area_over_percent, result_statistics
from glassdist.errors import InputError


def _write(tmp_path, data, name="spec.json"):
    p = tmp_path / name
    p.write_text(json.dumps(data) if not isinstance(data, str) else data, encoding="utf-8")
    return p


def _known_result(shape=(100, 100), valid=None):
    """phi_eff = -50 mD on 30 % of the pixels, 0 elsewhere; phi_shear = 10 mD on 2 %, 1 mD elsewhere."""
    from glassdist.storage import StoredResult

    eff = np.zeros(shape)
    eff[:30] = -50.0
    shear = np.ones(shape)
    shear[-2:] = 10.0
    return StoredResult.on_pixel_grid(
        {"phi_eff_mD": eff, "phi_shear_mD": shear, "phi_total_mD": np.hypot(eff, shear)},
        np.ones(shape, bool) if valid is None else valid, method="comparative", sigma_mm=2.0, detrend_degree=2,
    )


SPEC = {
    "name": "line 2",
    "criteria": [
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 60},
        {"channel": "phi_shear", "statistic": "max_abs", "max_mD": 10},
        {"channel": "phi_eff", "statistic": "area_over", "threshold_mD": 40, "max_percent": 30},
    ],
}


def _verdict(tmp_path, spec, result=None):
    loaded = load_spec(_write(tmp_path, spec))
    s, sha = loaded.spec, loaded.sha256
    result = result if result is not None else _known_result()
    stats = result_statistics(result, over_limits_mD=spec_limits(s))
    return spec_verdict(s, stats, result, spec_path="spec.json", spec_sha256=sha)


def test_statistics_match_closed_form():
    r = _known_result()
    s = acceptance_statistics(r.pixel_field("phi_eff_mD"), r.valid, over_limits_mD=[40, 60])
    assert s["mean_abs"] == pytest.approx(15.0)
    assert s["mean"] == pytest.approx(-15.0)
    assert s["std"] == pytest.approx(np.sqrt(0.3 * 0.7) * 50.0)
    assert s["p95_abs"] == pytest.approx(50.0)
    assert s["max_abs"] == pytest.approx(50.0)
    assert s["area_over_40"] == pytest.approx(30.0)
    assert s["area_over_60"] == 0.0
    assert s["n_valid"] == 10_000


def test_statistics_ignore_invalid_and_nan():
    field = np.full((10, 10), 100.0)
    valid = np.zeros((10, 10), bool)
    valid[:5] = True
    field[:5] = 2.0
    field[0, 0] = np.nan
    s = acceptance_statistics(field, valid)
    assert s["max_abs"] == 2.0 and s["n_valid"] == 49
    assert area_over_percent(field, valid, 1.0) == 100.0
    assert np.isnan(acceptance_statistics(field, np.zeros_like(valid))["p95_abs"])


def test_limits_are_inclusive_and_verdict_passes(tmp_path):
    v = _verdict(tmp_path, SPEC)
    assert [c.passed for c in v.checks] == [True, True, True]
    assert v.passed and v.label == "PASS"
    assert v.lines()[-1] == "VERDICT: PASS (3/3 criteria passed) spec 'line 2'"


def test_each_criterion_can_fail(tmp_path):
    spec = dict(SPEC, criteria=[
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 49.9},
        {"channel": "phi_shear", "statistic": "max_abs", "max_mD": 9.99},
        {"channel": "phi_eff", "statistic": "area_over", "threshold_mD": 40, "max_percent": 29.9},
        {"channel": "phi_shear", "statistic": "mean_abs", "max_mD": 2.0, "label": "mean shear"},
    ])
    v = _verdict(tmp_path, spec)
    assert [c.passed for c in v.checks] == [False, False, False, True]
    assert not v.passed
    lines = v.lines()
    assert lines[0].startswith("FAIL  p95 |phi_eff| <= 49.9 mD")
    assert lines[3].startswith("PASS  mean shear")
    assert v.to_dict()["checks"][2]["value"] == pytest.approx(30.0)


def test_empty_region_fails_and_coverage_is_checked(tmp_path):
    r = _known_result(valid=np.zeros((100, 100), bool))
    v = _verdict(tmp_path, dict(SPEC, min_valid_percent=10), r)
    assert not any(c.passed for c in v.checks)
    assert "no valid pixel" in v.checks[1].note
    assert v.to_dict()["checks"][1]["value"] is None  # NaN -> null in JSON


def test_protocol_mismatch_fails(tmp_path):
    v = _verdict(tmp_path, dict(SPEC, protocol={"method": "direct", "sigma_mm": 2.0, "detrend_degree": 4}))
    assert [c.passed for c in v.checks[:3]] == [False, True, False]
    assert not v.passed


@pytest.mark.parametrize(
    "data, words",
    [
        (dict(SPEC, colour="red"), "unknown key 'colour'"),
        (dict(SPEC, criteria=[{"channel": "phi_eff", "statistic": "area_over", "threshold_mD": 4}]), "max_percent"),
        (dict(SPEC, criteria=[{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": -1}]), "max_mD"),
        (dict(SPEC, criteria=[{"channel": "phi_x", "statistic": "p95_abs", "max_mD": 1}]), "channel"),
        (dict(SPEC, criteria=[]), "criteria"),
        ({"criteria": SPEC["criteria"]}, "name"),
        ("{not json", "not valid JSON"),
        ("[1, 2]", "JSON object"),
    ],
)
def test_bad_specs_give_one_line_errors(tmp_path, data, words):
    with pytest.raises(InputError) as info:
        load_spec(_write(tmp_path, data))
    msg = str(info.value)
    assert words in msg and "\n" not in msg


def test_missing_spec_file(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_spec(tmp_path / "nope.json")


def test_comment_key_is_allowed_and_hash_is_of_the_file(tmp_path):
    import hashlib

    p = _write(tmp_path, dict(SPEC, **{"$comment": "example"}))
    loaded = load_spec(p)
    assert loaded.spec.name == "line 2" and loaded.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()
    assert spec_limits(loaded.spec) == loaded.limits == {"phi_eff": [40.0, 60.0], "phi_shear": [10.0]}


def test_example_specifications_and_manifest_measure_alike_on_the_line_and_on_site():
    """The factory and contract examples pin the same capture and analysis but the method, so that the
    in-situ record is on the acceptance's axis; the manifest's in-situ row runs without a reference."""
    from pathlib import Path

    from glassdist.jobs.batch import read_manifest

    examples = Path(__file__).resolve().parents[1] / "examples"
    factory = load_spec(examples / "factory" / "spec.json").spec
    contract = load_spec(examples / "insitu" / "contract_spec.json").spec
    assert factory.protocol.method == "comparative" and contract.protocol.method == "direct"
    assert factory.protocol.model_dump(exclude={"method"}) == contract.protocol.model_dump(exclude={"method"})
    assert factory.zones == contract.zones and factory.criteria == contract.criteria
    panes = read_manifest(examples / "batch" / "manifest.csv")
    direct = [p for p in panes if p.reference is None]
    assert len(direct) == 1 and all(p.spec.name == "contract_spec.json" for p in direct)
    assert all(p.spec.name == "spec.json" for p in panes if p.reference is not None)


def test_one_name_per_evaluate_spec():
    """``glassdist.evaluate_spec(result, spec)`` is the only function of that name; the engine has its own."""
    import glassdist
    import glassdist.acceptance.spec as spec_module
    from glassdist._api import evaluate_spec

    assert glassdist.evaluate_spec is evaluate_spec
    assert not hasattr(spec_module, "evaluate_spec")
    assert "spec_verdict" in spec_module.__all__


def test_uncertainty_criteria_fail_a_noisy_capture_and_pass_a_clean_one():
    """A spec may require a precise enough measurement: p95 of phi_eff_sigma_mD under a limit."""
    import glassdist
    from glassdist.acceptance.assess import assess
    from glassdist.acceptance.spec import as_spec
    from glassdist.synthetic import synthetic_capture, wave_displacement

    spec = as_spec({"name": "precision", "criteria": [
        {"channel": "phi_eff_sigma", "statistic": "p95_abs", "max_mD": 0.02},
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1e5}]})
    sigmas = {}
    for noise in (0.0, 0.08):
        cap = synthetic_capture((200, 260), pitch_mm=8.0, mm_per_px=1.0, displacement=wave_displacement(0.4, 90.0, 20.0),
                                noise_std=noise, rng=5)
        res = glassdist.analyze(cap.image, pitch_mm=8.0, distance_m=10.0, reference=cap.reference)
        acc = assess(res, spec)
        s = np.asarray(res.phi_eff_sigma_mD)[res.trusted]
        assert acc.stats["phi_eff_sigma"]["p95_abs"] == pytest.approx(np.percentile(s, 95), rel=1e-5)
        assert acc.verdict.checks[-2].criterion == "p95 |sigma(phi_eff)| <= 0.02 mD"
        sigmas[noise] = (acc.stats["phi_eff_sigma"]["p95_abs"], acc.verdict.passed)
    assert sigmas[0.0][1] and not sigmas[0.08][1], sigmas
    assert "phi_eff_sigma" not in assess(res).stats  # judged only when a criterion asks


def test_pane_corners_must_be_a_convex_quadrilateral():
    """Convex in either order is accepted; concave, self-crossing or with three corners on a line is refused."""
    import pydantic

    from glassdist.acceptance.spec import Pane

    square = [[0, 0], [100, 0], [100, 80], [0, 80]]
    for corners in (square, square[::-1]):
        assert Pane(corners_px=corners, size_mm=[500, 400])
    dart = [[0, 0], [100, 0], [40, 30], [0, 80]]  # concave at the third corner
    bow_tie = [[0, 0], [100, 80], [100, 0], [0, 80]]  # self-crossing
    flat = [[0, 0], [50, 0], [100, 0], [100, 100]]  # three corners on a line
    for corners in (dart, dart[::-1], bow_tie, flat, flat[::-1]):
        with pytest.raises(pydantic.ValidationError, match="convex quadrilateral"):
            Pane(corners_px=corners, size_mm=[500, 400])


def test_protocol_sigma_in_carrier_periods_of_a_checkerboard():
    """sigma_periods counts carrier periods: pitch for lines, pitch * sqrt(2) for a checkerboard."""
    from glassdist.acceptance.spec import Protocol, resolve_protocol

    for pattern, period in (("lines", 5.0), ("checkerboard", 5.0 * np.sqrt(2.0))):
        r = resolve_protocol(Protocol(sigma_periods=2, pattern=pattern), reference_given=True, pitch_mm=5.0,
                             distance_m=1.0)
        assert r.sigma_mm == pytest.approx(2 * period), pattern


# --- the specification's own validation and protocol rules, one by one -------------------------------------------

def test_pane_needs_positive_sizes_and_a_convex_quadrilateral_at_any_scale():
    from glassdist.acceptance.spec import Pane

    square = ((0.0, 0.0), (0.5, 0.0), (0.5, 0.5), (0.0, 0.5))  # half a pixel a side: convexity has no scale
    assert Pane(corners_px=square, size_mm=(0.5, 100.0)).size_mm == (0.5, 100.0)
    assert Pane(corners_px=square[::-1], size_mm=(10.0, 10.0))  # the other winding
    for size in ((-5.0, 100.0), (0.0, 100.0)):
        with pytest.raises(ValueError, match="two positive numbers"):
            Pane(corners_px=square, size_mm=size)
    dart = ((0.0, 0.0), (10.0, 0.0), (3.0, 3.0), (0.0, 10.0))
    with pytest.raises(ValueError, match="convex"):
        Pane(corners_px=dart, size_mm=(10.0, 10.0))


def test_colour_limit_is_auto_spec_or_a_positive_number():
    from glassdist.acceptance.spec import Figures

    assert Figures(colour_limit=0.5).colour_limit == 0.5
    assert Figures(colour_limit="spec").colour_limit == "spec"
    for bad in (0.0, -2.0):
        with pytest.raises(ValueError, match="positive number"):
            Figures(colour_limit=bad)


def _spec(**extra):
    from glassdist.acceptance.spec import Spec

    return Spec.model_validate({"name": "t", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 5}],
                                **extra})


def test_zones_are_named_once_and_found_by_name():
    s = _spec(zones=[{"name": "a", "inset_mm": 0}, {"name": "b", "edge_band_mm": 20}])
    assert s.zone("b").edge_band_mm == 20 and s.zone("a").inset_mm == 0
    with pytest.raises(ValueError, match="given twice"):
        _spec(zones=[{"name": "a", "inset_mm": 0}, {"name": "a", "inset_mm": 5}])
    with pytest.raises(ValueError, match=r"not in 'zones' \(none defined\)"):
        _spec(criteria=[{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 5, "zone": "edge"}])


def test_a_criterion_needs_its_own_limit():
    from glassdist.acceptance.spec import Criterion

    with pytest.raises(ValueError, match="needs 'max_mD'"):
        Criterion(channel="phi_eff", statistic="p95_abs")
    with pytest.raises(ValueError, match="needs 'threshold_mD' and 'max_percent'"):
        Criterion(channel="phi_eff", statistic="area_over", threshold_mD=5.0)


def test_protocol_resolution_defaults_pins_and_what_the_errors_name():
    from glassdist.acceptance.spec import Protocol, resolve_protocol
    from glassdist.analyzer import load_params

    r = resolve_protocol(Protocol(pitch_mm=5.0, distance_m=1.0), reference_given=False)
    assert (r.detrend_degree, r.pattern, r.sigma_mm) == (2, "lines", 10.0)  # the defaults: N = 2, 2 periods
    assert r.pinned == {"pitch_mm": 5.0, "distance_m": 1.0}  # as written, no empty entries
    assert r.to_dict()["pinned"] == {"pitch_mm": 5.0, "distance_m": 1.0}
    # a parameter file without sigma_periods leaves the default two carrier periods
    r = resolve_protocol(Protocol(), reference_given=False, pitch_mm=4.0, distance_m=1.0,
                         params=load_params({"detrend_degree": 3}))
    assert r.sigma_mm == 8.0 and r.sources["sigma_mm"] == "default" and r.detrend_degree == 3
    # sigma pinned in carrier periods reaches the analysis as an override
    r = resolve_protocol(Protocol(sigma_periods=3.0), reference_given=True, pitch_mm=4.0, distance_m=1.0)
    assert r.params_overrides["sigma_mm"] == 12.0 and r.sources["sigma_mm"] == "spec"
    with pytest.raises(InputError, match=r"--pitch-mm is required \(the grid pitch, mm\)"):
        resolve_protocol(Protocol(), reference_given=False, distance_m=1.0)
    with pytest.raises(InputError, match=r"--distance-m is required \(the glass-to-grid distance L, m\)"):
        resolve_protocol(Protocol(), reference_given=False, pitch_mm=4.0)
    with pytest.raises(InputError, match="^--sigma-mm 10 contradicts"):
        resolve_protocol(Protocol(sigma_periods=3.0), reference_given=True, pitch_mm=4.0, distance_m=1.0, sigma_mm=10.0)
    with pytest.raises(InputError, match="^the --params file's sigma_mm 10 contradicts"):
        resolve_protocol(Protocol(sigma_periods=3.0), reference_given=True, pitch_mm=4.0, distance_m=1.0,
                         params=load_params({"sigma_mm": 10.0}))


def test_lens_calibration_source_required_by_the_protocol():
    from glassdist.acceptance.spec import Protocol, check_lens_source

    either = Protocol(lens_calibration="photo_or_file")
    check_lens_source(either, lens_photo=True, camera_file=False)
    check_lens_source(either, lens_photo=False, camera_file=True)
    with pytest.raises(InputError, match="--lens-photo PHOTO or --camera-file FILE"):
        check_lens_source(either, lens_photo=False, camera_file=False)
    with pytest.raises(InputError, match="give --lens-photo PHOTO$"):
        check_lens_source(Protocol(lens_calibration="photo"), lens_photo=False, camera_file=True)


def test_protocol_checks_and_zone_coverage_at_their_limits():
    from glassdist.acceptance.spec import Protocol, spec_verdict

    spec = _spec(protocol=Protocol(sigma_periods=2.0).model_dump(exclude_none=True),
                 zones=[{"name": "z", "inset_mm": 0, "min_valid_percent": 50}],
                 criteria=[{"channel": "phi_eff", "statistic": "area_over", "threshold_mD": 2, "max_percent": 10}])
    result = SimpleNamespace(carrier_period_mm=8.0, sigma_mm=16.0, method="direct")
    stats = {"phi_eff": {"area_over_2": 10.0}}  # at the limit: <= passes
    v = spec_verdict(spec, stats, result, zones={"z": {"trusted_percent": 50.0}}, trusted_percent=100.0)
    by = {c.criterion: c for c in v.checks}
    assert by["protocol: sigma_mm = 16 mm"].passed  # 2 periods of 8 mm
    assert by["trusted area >= 50 % of zone 'z'"].passed  # at the limit: >= passes
    area = next(c for c in v.checks if c.comparison == "<=")
    assert area.passed and area.unit == "%"  # an area_over limit is a share, not mD
    assert v.passed
    v = spec_verdict(spec, stats, SimpleNamespace(carrier_period_mm=8.0, sigma_mm=12.0, method="direct"),
                     zones={"z": {"trusted_percent": 49.9}}, trusted_percent=100.0)
    assert not v.passed
