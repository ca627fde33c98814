"""Acceptance content of a specification: pinned protocol, zones on the pane, worst regions, per-zone statistics."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from glassdist.acceptance.regions import all_worst_regions, regions_csv, worst_regions
from glassdist.acceptance.spec import Protocol, Spec, Zone, check_capture, resolve_protocol, spec_limits, spec_verdict
from glassdist.acceptance.stats import result_statistics
from glassdist.acceptance.zones import pane_frame, pane_frame_from_corners, pane_frame_from_region, zone_masks, zone_statistics
from glassdist.errors import InputError

# ----------------------------------------------------------------- protocol


def test_pinned_values_fill_omitted_options_and_sources_are_recorded():
    p = Protocol(distance_m=1.0, pitch_mm=5.0, pattern="checkerboard", sigma_mm=12.0, detrend_degree=3,
                 method="comparative")
    r = resolve_protocol(p, reference_given=True)
    assert (r.pitch_mm, r.distance_m, r.pattern, r.sigma_mm, r.detrend_degree) == (5.0, 1.0, "checkerboard", 12.0, 3)
    assert r.params_overrides == {"pattern": "checkerboard", "detrend_degree": 3, "sigma_mm": 12.0}
    assert set(r.sources.values()) == {"spec"}
    d = r.to_dict()
    assert d["resolved"]["sigma_mm"] == 12.0 and d["pinned"]["distance_m"] == 1.0


def test_equal_option_is_accepted_and_options_fill_what_is_not_pinned():
    r = resolve_protocol(Protocol(distance_m=1.0), reference_given=False, distance_m=1.0, pitch_mm=4.0)
    assert r.method == "direct" and r.sources["distance_m"] == "option" and r.pitch_mm == 4.0
    # unpinned sigma: 2 carrier periods (line grid: the pitch)
    assert r.sigma_mm == pytest.approx(8.0) and r.sources["sigma_mm"] == "default"
    assert "sigma_mm" not in r.params_overrides


@pytest.mark.parametrize("option, value, words", [
    ("sigma_mm", 60.0, "--sigma-mm 60 contradicts"),
    ("distance_m", 3.0, "--distance-m 3 contradicts"),
    ("pitch_mm", 6.0, "--pitch-mm 6 contradicts"),
    ("detrend_degree", 2, "--detrend-degree 2 contradicts"),
    ("pattern", "lines", "--pattern lines contradicts"),
])
def test_contradicting_option_is_refused_in_one_line(option, value, words):
    p = Protocol(distance_m=1.0, pitch_mm=5.0, pattern="checkerboard", sigma_mm=14.0, detrend_degree=3)
    with pytest.raises(InputError) as info:
        resolve_protocol(p, reference_given=True, **{option: value}, spec_label="spec.json")
    msg = str(info.value)
    assert msg.startswith(words) and "spec.json" in msg and "leave" in msg and "\n" not in msg


def test_sigma_periods_pin_resolves_through_pitch_and_pattern():
    p = Protocol(sigma_periods=3.0, pattern="checkerboard")
    r = resolve_protocol(p, reference_given=True, pitch_mm=5.0, distance_m=1.0)
    assert r.sigma_mm == pytest.approx(3.0 * 5.0 * np.sqrt(2.0))
    resolve_protocol(p, reference_given=True, pitch_mm=5.0, distance_m=1.0, sigma_mm=15.0 * np.sqrt(2.0))
    with pytest.raises(InputError, match="sigma_periods = 3"):
        resolve_protocol(p, reference_given=True, pitch_mm=5.0, distance_m=1.0, sigma_mm=10.0)
    with pytest.raises(ValueError, match="not both"):
        Protocol(sigma_mm=1.0, sigma_periods=2.0)


def test_method_and_missing_settings_are_input_errors():
    with pytest.raises(InputError, match="requires the comparative method; give --reference"):
        resolve_protocol(Protocol(method="comparative"), reference_given=False, pitch_mm=5, distance_m=1)
    with pytest.raises(InputError, match="requires the direct method; leave --reference out"):
        resolve_protocol(Protocol(method="direct"), reference_given=True, pitch_mm=5, distance_m=1)
    with pytest.raises(InputError, match="--pitch-mm is required"):
        resolve_protocol(None, reference_given=True, distance_m=1.0)
    with pytest.raises(InputError, match="--distance-m is required"):
        resolve_protocol(Protocol(pitch_mm=5.0), reference_given=True)


def test_params_file_contradicting_a_pin_is_refused():
    from glassdist.analyzer import load_params

    params = load_params({"detrend_degree": 4})
    with pytest.raises(InputError, match="--params file sets detrend_degree = 4"):
        resolve_protocol(Protocol(detrend_degree=3), reference_given=True, pitch_mm=5, distance_m=1, params=params)
    r = resolve_protocol(Protocol(), reference_given=True, pitch_mm=5, distance_m=1, params=params)
    assert r.detrend_degree == 4 and r.sources["detrend_degree"] == "params"


def test_capture_limit_is_an_input_error():
    res = SimpleNamespace(px_per_period=6.0)  # the shorter of the carrier periods 6.0 and 6.5 px
    check_capture(Protocol(min_px_per_period=6.0), res)
    with pytest.raises(InputError, match="6 px per grid carrier period .* at least 8"):
        check_capture(Protocol(min_px_per_period=8.0), res)


# ----------------------------------------------------------------- zones

def _rect_frame(w_mm=400.0, h_mm=300.0, scale=2.0, shape=(200, 260), x0=20.5, y0=10.5):
    """A rectangular pane seen frontally: w_mm x h_mm at `scale` mm per px, top-left corner at (x0, y0) px."""
    x1, y1 = x0 + w_mm / scale, y0 + h_mm / scale
    return pane_frame_from_corners([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], (w_mm, h_mm), shape)


def test_rectangle_inset_and_edge_band_areas_match_closed_form():
    w, h, s = 400.0, 300.0, 2.0
    frame = _rect_frame(w, h, s)
    assert frame.area_mm2(frame.inside) == pytest.approx(w * h)
    for b in (20.0, 50.0):
        m = zone_masks(frame, [Zone(name="edge", edge_band_mm=b), Zone(name="vision", inset_mm=b)])
        # pixels are s mm wide: the band's inner edge is placed to within half a pixel along the perimeter
        tol = 0.5 * s * 2 * ((w - 2 * b) + (h - 2 * b)) + 4 * s * s
        assert frame.area_mm2(m["vision"]) == pytest.approx((w - 2 * b) * (h - 2 * b), abs=tol)
        assert frame.area_mm2(m["edge"]) == pytest.approx(w * h - (w - 2 * b) * (h - 2 * b), abs=tol)
        assert not np.any(m["edge"] & m["vision"]) and np.array_equal(m["edge"] | m["vision"], frame.inside)


def test_polygon_zone_area_and_placement():
    frame = _rect_frame()
    (m,) = zone_masks(frame, [Zone(name="box", polygon_mm=[[100, 50], [300, 50], [300, 150], [100, 150]])]).values()
    assert frame.area_mm2(m) == pytest.approx(200 * 100)
    yy, xx = np.nonzero(m)
    u, v = frame.to_mm(xx, yy)
    assert u.min() >= 99 and u.max() <= 301 and v.min() >= 49 and v.max() <= 151


def test_perspective_pane_area_is_exact_through_the_jacobian():
    # a trapezoid in the photo: the pane's area in mm does not depend on the view
    corners = [[40.3, 30.7], [220.2, 50.1], [210.6, 180.4], [50.9, 170.2]]
    frame = pane_frame_from_corners(corners, (500.0, 400.0), (200, 260))
    assert frame.area_mm2(frame.inside) == pytest.approx(500.0 * 400.0, rel=0.02)
    u, v = frame.to_mm(np.array([40.3, 210.6]), np.array([30.7, 180.4]))
    assert np.allclose([u[0], v[0], u[1], v[1]], [0, 0, 500, 400], atol=1e-9)


def test_outline_found_in_image_or_standing_in():
    valid = np.zeros((120, 160), bool)
    valid[20:100, 30:130] = True
    f = pane_frame_from_region(valid, 0.5, grow_px=5.0)
    assert f.source == "image" and not f.warning and f.units == "backdrop_mm"
    assert f.area_mm2(f.inside) == pytest.approx((80 + 10) * (100 + 10) * 0.25, rel=0.03)
    whole = pane_frame_from_region(np.ones((120, 160), bool), 0.5, grow_px=5.0)
    assert whole.source == "analysed_region" and "stands in" in whole.warning


class _PixelGridResult(SimpleNamespace):
    """Known fields with the analyzer's result interface, on an analysis grid that is the pixel grid itself.

    Statistics and verdicts are checked against closed forms here; a real analysis cannot hold
    such fields. The interface is the real one (``grid_field``, ``grid_valid``, ``grid_trusted``,
    ``carriers``): the production code has no second path for it.
    """

    def field_specs(self):
        from glassdist.analyzer.result import FIELDS

        return tuple(f for f in FIELDS if f.name in self.__dict__)

    def grid_field(self, name):
        return getattr(self, name)

    pixel_field = grid_field

    def pixel_rows(self, names, max_pixels=1 << 21):
        from glassdist.analyzer.result import row_blocks

        return row_blocks({n: self.pixel_field(n) for n in names}, max_pixels)

    @property
    def px_per_period(self):
        return float(min(self.carriers.k1.period_px, self.carriers.k2.period_px))

    @property
    def pattern(self):
        return self.params.pattern

    @property
    def grid_valid(self):
        return self.valid

    @property
    def grid_trusted(self):
        return self.trusted

    @property
    def trusted(self):
        return self.__dict__.get("trusted_px", self.valid)

    @trusted.setter
    def trusted(self, value):
        self.__dict__["trusted_px"] = value

    @property
    def analysis_grid(self):
        from glassdist.analyzer.fourier import SamplingGrid

        return SamplingGrid(self.valid.shape, self.valid.shape)


def _field_result(shape=(200, 260)):
    eff = np.zeros(shape)
    eff[:, :130] = 10.0  # left half 10 mD, right half 0
    return _PixelGridResult(phi_eff_mD=eff, phi_shear_mD=np.abs(eff) / 2, phi_total_mD=np.abs(eff),
                           valid=np.ones(shape, bool), method="comparative", sigma_mm=2.0, detrend_degree=2,
                           mm_per_px=2.0, carrier_period_mm=5.0, pitch_mm=5.0, distance_m=1.0, optics=None,
                           margin_px=(0.0, 0.0),
                           params=SimpleNamespace(border_periods=1.5, pattern="lines"),
                           carriers=SimpleNamespace(k1=SimpleNamespace(period_px=2.5), k2=SimpleNamespace(period_px=2.5)))


def test_per_zone_statistics_and_coverage_against_the_zone():
    res = _field_result()
    frame = _rect_frame()
    zones = [Zone(name="left", polygon_mm=[[0, 0], [200, 0], [200, 300], [0, 300]]),
             Zone(name="vision", inset_mm=50)]
    # an intentional mask: only the vision area was analysed
    m = zone_masks(frame, zones)
    res.valid = m["vision"].copy()
    zs = zone_statistics(res, frame, zones)
    assert zs["vision"]["trusted_percent"] == pytest.approx(100.0)
    # pane x < 200 mm is image x < 120.5 px: all at 10 mD
    assert zs["left"]["statistics"]["phi_eff"]["mean_abs"] == pytest.approx(10.0)
    assert zs["left"]["trusted_percent"] == pytest.approx(100 * 150 * 200 / (200 * 300), rel=0.03)
    spec = Spec(name="z", zones=zones, criteria=[
        {"channel": "phi_eff", "statistic": "max_abs", "max_mD": 5, "zone": "vision"},
        {"channel": "phi_eff", "statistic": "mean_abs", "max_mD": 9.9, "zone": "left"}])
    stats = result_statistics(res, over_limits_mD=spec_limits(spec))
    v = spec_verdict(spec, stats, res, zones=zs)
    assert [c.passed for c in v.checks] == [False, False]
    assert "in zone 'vision'" in v.checks[0].criterion and v.checks[0].value == pytest.approx(10.0)


def test_zone_coverage_limit_and_unknown_zone():
    with pytest.raises(ValueError, match="zone 'nope'"):
        Spec(name="z", criteria=[{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 5, "zone": "nope"}])
    with pytest.raises(ValueError, match="exactly one"):
        Zone(name="a", inset_mm=5, edge_band_mm=5)
    res = _field_result()
    frame = _rect_frame()
    zones = [Zone(name="vision", inset_mm=50, min_valid_percent=90)]
    res.valid[:, :100] = False
    zs = zone_statistics(res, frame, zones)
    spec = Spec(name="z", zones=zones, criteria=[{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 50}])
    v = spec_verdict(spec, result_statistics(res), res, zones=zs)
    assert v.checks[0].criterion == "trusted area >= 90 % of zone 'vision'" and not v.checks[0].passed


# ----------------------------------------------------------------- worst regions

def test_worst_regions_of_known_blobs():
    rng = np.random.default_rng(3)
    shape = (300, 400)
    f = rng.uniform(-1, 1, shape)
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    blobs = [(100.0, 120.0, 30.0, 40.0), (250.0, 200.0, 20.0, -25.0)]  # (x, y, radius px, value mD)
    for x, y, r, val in blobs:
        f[(xx - x) ** 2 + (yy - y) ** 2 <= r * r] = val
    s = 0.5
    frame = pane_frame_from_region(np.ones(shape, bool), s)
    regs = worst_regions(f, np.ones(shape, bool), frame, 10.0)
    assert len(regs) == 2
    assert [r.number for r in regs] == [1, 2] and regs[0].peak_mD == 40.0 and regs[1].peak_mD == -25.0
    for reg, (x, y, r, val) in zip(regs, blobs):
        # frame origin at the region's top-left pixel edge: u = (x + 0.5) s
        assert reg.centroid_mm == pytest.approx(((x + 0.5) * s, (y + 0.5) * s), abs=1e-9)
        assert reg.area_mm2 == pytest.approx(np.pi * r * r * s * s, rel=0.01)
        assert reg.mean_abs_mD == pytest.approx(abs(val))
        assert reg.extent_mm == pytest.approx(((x - r + 0.5) * s, (x + r + 0.5) * s, (y - r + 0.5) * s,
                                               (y + r + 0.5) * s))
    # restricted to the valid region, and a minimum area
    valid = np.ones(shape, bool)
    valid[:, :200] = False
    assert [r.peak_mD for r in worst_regions(f, valid, frame, 10.0)] == [-25.0]
    assert worst_regions(f, np.ones(shape, bool), frame, 10.0, min_area_mm2=np.pi * 25 * 25 * s * s) == regs[:1]


def test_region_thresholds_from_spec_or_default_and_csv():
    res = _field_result()
    frame = pane_frame(res)
    spec = Spec(name="s", criteria=[{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 5}])
    found = all_worst_regions(res, frame, spec)
    assert found["phi_eff"]["threshold_mD"] == 5 and found["phi_eff"]["threshold_source"] == "spec limit"
    (reg,) = found["phi_eff"]["regions"]
    assert reg.area_mm2 == pytest.approx(130 * 200 * 4.0)
    assert found["phi_shear"]["threshold_source"] == "p95"
    text = regions_csv(found)
    assert text.splitlines()[0].startswith("channel,number,threshold_mD,centroid_x_mm")
    assert text.splitlines()[1].startswith("phi_eff,1,5,")


# ----------------------------------------------------------------- through the command line

@pytest.fixture(scope="module")
def lens_photos(tmp_path_factory):
    """A small synthetic pane (a converging lens) and its reference; a spec pinning the protocol, with two zones."""
    import json

    from conftest import write_lens_pair

    root = write_lens_pair(tmp_path_factory.mktemp("lens"))
    spec = {
        "name": "zoned",
        "protocol": {"method": "comparative", "pitch_mm": 2.0, "distance_m": 1.0, "sigma_mm": 1.5,
                     "detrend_degree": 2},
        "pane": {"corners_px": [[-0.5, -0.5], [159.5, -0.5], [159.5, 159.5], [-0.5, 159.5]], "size_mm": [40, 40]},
        "zones": [{"name": "edge", "edge_band_mm": 5}, {"name": "vision", "inset_mm": 5, "min_valid_percent": 50}],
        "criteria": [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1000, "zone": "vision"},
                     {"channel": "phi_shear", "statistic": "p95_abs", "max_mD": 1000, "zone": "edge"}],
    }
    (root / "spec.json").write_text(json.dumps(spec))
    (root / "coarse.json").write_text(json.dumps(dict(spec, protocol={"min_px_per_period": 20})))
    return root


def _main(capsys, *argv):
    from glassdist.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_spec_pins_the_protocol_and_records_it_per_zone(lens_photos, tmp_path, capsys):
    import json

    out = tmp_path / "o"
    code, stdout, err = _main(capsys, "analyze", lens_photos / "pane.png", "--reference", lens_photos / "reference.png",
                              "--spec", lens_photos / "spec.json", "--pane-id", "P-7", "--site", "line 2",
                              "--report", "--out", out)
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["protocol"]["resolved"] == {"method": "comparative", "pitch_mm": 2.0, "distance_m": 1.0,
                                         "pattern": "lines", "detrend_degree": 2, "sigma_mm": 1.5}
    assert s["protocol"]["sources"]["distance_m"] == "spec" and s["protocol"]["used"]["sigma_mm"] == 1.5
    assert s["parameters"]["sigma_mm"] == 1.5 and s["distance_m"] == 1.0
    assert s["pane"]["source"] == "spec" and s["pane"]["area_mm2"] == pytest.approx(1600.0)
    assert s["zones"]["edge"]["area_mm2"] == pytest.approx(1600 - 30 * 30, abs=1.0)
    assert set(s["zones"]["vision"]["statistics"]) >= {"phi_eff", "phi_shear"}
    assert s["metadata"]["pane_id"] == "P-7" and s["metadata"]["camera"] is None
    assert "zone vision:" in stdout and "worst_regions.csv" in s["outputs"]
    html = (out / "report.html").read_text()
    assert "P-7" in html and 'id="zones"' in html and 'id="worst-regions"' in html


def test_contradicting_option_exits_2_and_writes_nothing(lens_photos, tmp_path, capsys):
    out = tmp_path / "o"
    code, stdout, err = _main(capsys, "analyze", lens_photos / "pane.png", "--reference", lens_photos / "reference.png",
                              "--spec", lens_photos / "spec.json", "--distance-m", 3, "--out", out)
    assert code == 2 and stdout == ""
    assert err.strip().splitlines() == [err.strip()] and "--distance-m 3 contradicts" in err and "leave" in err
    assert not out.exists()
    code, _, err = _main(capsys, "analyze", lens_photos / "pane.png", "--spec", lens_photos / "spec.json",
                         "--out", out)
    assert code == 2 and "requires the comparative method" in err


def test_capture_limit_refuses_the_photo(lens_photos, tmp_path, capsys):
    out = tmp_path / "o"
    code, _, err = _main(capsys, "analyze", lens_photos / "pane.png", "--reference", lens_photos / "reference.png",
                         "--pitch-mm", 2, "--distance-m", 1, "--spec", lens_photos / "coarse.json", "--out", out)
    assert code == 2 and "px per grid carrier period" in err and "at least 20" in err
    assert not (out / "summary.json").exists()


# ----------------------------------------------------------------- Python API

def test_api_analyze_takes_paths_and_settings_and_evaluate_spec(lens_photos):
    import json

    import glassdist
    from glassdist.io import read_image

    assert {"analyze", "evaluate_spec"} <= set(glassdist.__all__)
    kw = dict(pitch_mm=2.0, distance_m=1.0, detrend_degree=1, sigma_mm=1.5)
    by_path = glassdist.analyze(lens_photos / "pane.png", reference=str(lens_photos / "reference.png"), **kw)
    by_array = glassdist.analyze(read_image(lens_photos / "pane.png"),
                                 reference=read_image(lens_photos / "reference.png"),
                                 params={"detrend_degree": 1, "sigma_mm": 1.5}, pitch_mm=2.0, distance_m=1.0)
    assert by_path.detrend_degree == 1 and by_path.sigma_mm == 1.5
    assert np.array_equal(by_path.phi_eff_mD, by_array.phi_eff_mD, equal_nan=True)
    # the keyword overrides the parameters
    over = glassdist.analyze(lens_photos / "pane.png", reference=lens_photos / "reference.png", pitch_mm=2.0,
                             distance_m=1.0, params={"detrend_degree": 3}, detrend_degree=2)
    assert over.detrend_degree == 2
    spec = json.loads((lens_photos / "spec.json").read_text())
    v_path = glassdist.evaluate_spec(by_path, lens_photos / "spec.json")
    v_dict = glassdist.evaluate_spec(by_path, spec)
    # detrend 1 against the pinned 2: the protocol check fails, the criteria are evaluated all the same
    assert not v_path.passed and [c.passed for c in v_path.checks] == [c.passed for c in v_dict.checks]
    failed = [c.criterion for c in v_path.checks if not c.passed]
    assert failed == ["protocol: detrend_degree = 2"]
    assert v_path.spec_sha256 and v_dict.spec_sha256 == ""
    with pytest.raises(InputError, match="unknown key 'colour'"):
        glassdist.evaluate_spec(by_path, dict(spec, colour=1))


def test_mask_coverage_is_of_the_mask():
    import glassdist
    from glassdist.synthetic import lens_displacement, synthetic_capture

    cap = synthetic_capture((320, 320), pitch_mm=2.0, mm_per_px=0.25,
                            displacement=lens_displacement(0.05, 1.0, radius_mm=7.0), rng=0)
    mask = np.zeros((320, 320), bool)
    mask[40:280, 40:280] = True  # an intentional vision-area mask: 56 % of the image
    masked = glassdist.analyze(cap.image, reference=cap.reference, pitch_mm=2.0, distance_m=1.0, mask=mask)
    assert not any("could be analysed" in w for w in masked.warnings), masked.warnings
    spec = {"name": "cover", "min_valid_percent": 60,
            "criteria": [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1e6}]}
    assert not glassdist.evaluate_spec(masked, spec).passed  # under 56 % of the image ...
    assert glassdist.evaluate_spec(masked, spec, mask=mask).passed  # ... but most of the region asked for


def test_statistics_and_regions_use_the_trusted_pixels():
    from glassdist.acceptance.assess import assess

    res = _field_result()
    res.trusted = res.valid.copy()
    res.trusted[:, :20] = False  # e.g. a guard band: reported, not trusted
    res.phi_eff_mD = res.phi_eff_mD.copy()
    res.phi_eff_mD[:, :20] = 500.0
    acc = assess(res, Spec(name="t", criteria=[{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 20}]))
    assert acc.stats["phi_eff"]["max_abs"] == pytest.approx(10.0) and acc.verdict.passed
    assert all(r.peak_mD < 500 for r in acc.regions["phi_eff"]["regions"])
    assert acc.trusted_percent == pytest.approx(100.0 * 240 / 260)
    assert acc.measured_percent == pytest.approx(100.0)  # the guard band is measured, not trusted


def test_api_write_report_from_arrays_and_with_a_spec(lens_photos, tmp_path):
    import json

    import glassdist

    assert "write_report" in glassdist.__all__
    res = glassdist.analyze(lens_photos / "pane.png", reference=lens_photos / "reference.png", pitch_mm=2.0,
                            distance_m=1.0, sigma_mm=1.5)
    # the result alone: no photo path, no specification
    path = glassdist.write_report(res, tmp_path / "bare")
    assert path == tmp_path / "bare" / "report.html" and path.is_file()
    s = json.loads((tmp_path / "bare" / "summary.json").read_text())
    assert s["verdict"] is None and "worst_regions" in s
    # with the spec file, the photo and the pane's facts
    path = glassdist.write_report(res, tmp_path / "full", spec=lens_photos / "spec.json", image=lens_photos / "pane.png",
                                  reference=lens_photos / "reference.png", pane_id="P-9", operator="C. D.")
    s = json.loads((tmp_path / "full" / "summary.json").read_text())
    assert s["verdict"]["result"] == "PASS" and s["verdict"]["spec_sha256"]
    assert s["metadata"]["pane_id"] == "P-9" and set(s["zones"]) == {"edge", "vision"}
    html = path.read_text()
    assert "P-9" in html and "C. D." in html


@pytest.mark.parametrize("radius", [0.5, 1.0, 2.5, 3.0, 4.2])
def test_grow_region_is_the_distance_threshold(radius):
    """The disk dilation keeps exactly the pixels within ``radius`` of the region (exact Euclidean distance)."""
    from glassdist.acceptance.zones import distance_to_outside, grow_region

    rng = np.random.default_rng(5)
    mask = rng.random((90, 130)) < 0.01
    mask[20:40, 30:70] = True
    assert np.array_equal(grow_region(mask, radius), distance_to_outside(~mask) <= radius)
    assert not grow_region(np.zeros((9, 9), bool), radius).any()


def test_coverage_is_of_the_mask_asked_for():
    """With a mask, coverage is the measured share of the mask (closed form), else of the image."""
    from glassdist.acceptance.assess import assess

    res = _field_result()  # 200 x 260 px, every pixel measured
    res.valid = res.valid.copy()
    res.valid[:, :65] = False  # a quarter of the image not measured
    mask = np.zeros(res.valid.shape, bool)
    mask[:, :130] = True  # the left half asked for: half of it measured
    assert assess(res, None, mask=mask).trusted_percent == pytest.approx(50.0)
    assert assess(res, None).trusted_percent == pytest.approx(75.0)
    # every measured pixel is trusted here: the measured share is the same number
    assert assess(res, None, mask=mask).measured_percent == pytest.approx(50.0)
    # the specification's area check judges that same share and names what it is of
    spec = Spec(name="cover", min_valid_percent=60,
                criteria=[{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1e6}])
    for asked, share, where in ((mask, 50.0, "the mask"), (None, 75.0, "the image")):
        (check,) = [c for c in assess(res, spec, mask=asked).verdict.checks if c.criterion.startswith("trusted area")]
        assert check.criterion == f"trusted area >= 60 % of {where}" and check.value == pytest.approx(share)


def test_caption_says_clipped_only_beyond_the_colour_limit():
    from glassdist.report.maps import describe_clipping

    f = np.array([[1.0, -10.0], [4.0, np.nan]])
    ok = np.ones(f.shape, bool)
    assert describe_clipping(f, ok, vmax=20.0) == "max |phi| 10 mD"  # well under the limit
    assert describe_clipping(f, ok, vmax=10.0) == "max |phi| 10 mD"  # at it
    clipped = describe_clipping(f, ok, vmax=5.0)
    assert clipped.startswith("max |phi| 10 mD; colours clipped at 5 mD") and "(33 % of the trusted region beyond)" in clipped


def test_the_frame_warning_is_given_only_where_zones_need_the_frame():
    """Without a pane in the spec the analysed region stands in for it: a warning only when zones use it."""
    from glassdist.acceptance.assess import assess

    res = _field_result()
    crit = [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 50}]
    plain = assess(res, Spec(name="p", criteria=crit))
    assert plain.frame.warning and plain.warnings == ()
    zoned = assess(res, Spec(name="z", zones=[Zone(name="vision", inset_mm=50)], criteria=crit))
    assert zoned.warnings == (zoned.frame.warning,)


def test_camera_metadata_from_exif(tmp_path):
    """The camera's EXIF tags, the sub-IFD's too; blank text tags left out; a file without EXIF gives None."""
    from PIL import Image

    from glassdist.io import camera_metadata

    im = Image.fromarray(np.full((16, 16), 128, np.uint8))
    exif = Image.Exif()
    exif[0x010F] = "Canon"  # make
    exif[0x0110] = " \x00 "  # model, blank
    sub = exif.get_ifd(0x8769)
    sub[0x920A] = 50.0  # focal length, mm
    sub[0x8827] = 200  # ISO
    im.save(tmp_path / "photo.jpg", exif=exif)
    assert camera_metadata(tmp_path / "photo.jpg") == {"make": "Canon", "focal_length_mm": 50.0, "iso": 200.0}
    im.save(tmp_path / "plain.png")
    assert camera_metadata(tmp_path / "plain.png") is None


def test_heatmap_axes_and_overlays_keep_the_frame_limits():
    """Axes in the pane's mm when the frame is axis-aligned (backdrop mm without a pane), and the
    overlays (zones, worst regions) leave the heatmap's limits where the extent put them."""
    from matplotlib.figure import Figure

    from glassdist.acceptance.assess import assess
    from glassdist.report.maps import draw_overlays, heatmap_axes

    res = _field_result()
    crit = [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 50}]
    spec = Spec(name="z", zones=[Zone(name="vision", inset_mm=50)], criteria=crit,
                pane={"corners_px": [[20, 10], [220, 10], [220, 160], [20, 160]], "size_mm": [400, 300]})
    acc = assess(res, spec)
    extent, to_axes, label = heatmap_axes(acc.frame, res.mm_per_px, res.valid.shape)
    assert acc.frame.units == "pane_mm" and label == "pane mm"
    assert heatmap_axes(pane_frame_from_region(res.valid, res.mm_per_px), res.mm_per_px, res.valid.shape)[2] == "backdrop mm"
    ax = Figure().add_subplot()
    draw_overlays(ax, acc, "phi_eff", to_axes, extent)
    assert ax.get_xlim() == pytest.approx(extent[:2]) and ax.get_ylim() == pytest.approx(extent[2:])


def test_assess_records_colour_limits_protocol_and_camera_as_asked():
    """On a real small analysis: a numeric colour limit is used as given and 'spec' takes each channel's smallest
    limit; the protocol record (with what the run used) comes with a resolved protocol alone, as written (no empty
    pins) from a spec alone; the camera is recorded only when given."""
    import glassdist
    from glassdist.acceptance.assess import assess
    from glassdist.synthetic import lens_displacement, synthetic_capture

    cap = synthetic_capture((160, 160), pitch_mm=2.0, mm_per_px=0.25,
                            displacement=lens_displacement(0.05, 1.0, radius_mm=7.0), rng=0)
    res = glassdist.analyze(cap.image, reference=cap.reference, pitch_mm=2.0, distance_m=1.0)
    crit = [{"channel": "phi_eff", "statistic": "max_abs", "max_mD": 40}, {"channel": "phi_eff", "statistic": "p95_abs",
            "max_mD": 25}, {"channel": "phi_shear", "statistic": "p95_abs", "max_mD": 30}]
    fixed = assess(res, Spec(name="f", criteria=crit, figures={"colour_limit": 7.5}))
    assert fixed.colour_limits == {"phi_eff": 7.5, "phi_shear": 7.5}
    by_spec = assess(res, Spec(name="s", criteria=crit, figures={"colour_limit": "spec"}, protocol={"pitch_mm": 2.0}))
    assert by_spec.colour_limits == {"phi_eff": 25.0, "phi_shear": 30.0}
    assert by_spec.protocol["pinned"] == {"pitch_mm": 2.0}
    assert by_spec.protocol["used"]["pitch_mm"] == 2.0 and "camera" not in by_spec.metadata
    alone = assess(res, protocol=resolve_protocol(Protocol(), reference_given=True, pitch_mm=2.0, distance_m=1.0),
                   camera={"model": "X"})
    assert alone.verdict is None and alone.protocol["used"]["method"] == "comparative"
    assert alone.metadata["camera"] == {"model": "X"}
