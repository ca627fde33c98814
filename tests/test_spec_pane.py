"""A specification judges only what the photo measured: its pane and zones are checked against the photo.

The pane must lie inside the photo and its corners' span in backdrop millimetres (by the
measured scale) must agree with its stated size for the capture geometry, or the run is
refused (exit 2). A pane given as fractions of the image (``corners_frac``) serves every
resolution of one set-up. Every criterion states the trusted share of what it judges. A
mistyped key gets a suggestion and a person's (1-based) item number.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from glassdist.acceptance.spec import Pane, Spec, Zone, load_spec
from glassdist.acceptance.zones import PANE_SCALE_RANGE, check_pane
from glassdist.errors import InputError

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "data" / "real-checkerboard-water"
#: the factory example's pane as it was written for the 1024 px photos, in their pixels
PANE_1024_PX = {"corners_px": [[-0.5, -0.5], [1023.5, -0.5], [1023.5, 1023.5], [-0.5, 1023.5]], "size_mm": [730, 730]}

needs_real = pytest.mark.skipif(not (REAL / "distorted_waves.bmp").is_file(),
                                reason=f"the real photographs are not in {REAL}")


# ----------------------------------------------------------------- the spec's own errors

def test_a_mistyped_key_gets_a_suggestion_and_a_person_s_item_number(tmp_path):
    p = tmp_path / "spec.json"
    p.write_text(json.dumps({"name": "s", "criteria": [
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 40},
        {"channel": "phi_eff", "statistic": "p95_abs", "max_md": 40}]}))
    with pytest.raises(InputError) as err:
        load_spec(p)
    msg = str(err.value)
    assert "unknown key 'max_md' in criterion 2 (did you mean 'max_mD'?)" in msg
    assert "criteria.1" not in msg and "criteria.0" not in msg and "\n" not in msg
    p.write_text(json.dumps({"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 4}],
                             "zones": [{"name": "a", "inset_mm": 5, "min_valid_pct": 3}], "protocl": {}}))
    with pytest.raises(InputError) as err:
        load_spec(p)
    assert "unknown key 'min_valid_pct' in zone 1 (did you mean 'min_valid_percent'?)" in str(err.value)
    assert "unknown key 'protocl' (did you mean 'protocol'?)" in str(err.value)


# ----------------------------------------------------------------- the pane's forms

def test_corners_as_fractions_of_the_image_land_on_every_resolution():
    pane = Pane(corners_frac=[[0, 0], [1, 0], [1, 1], [0, 1]], size_mm=[730, 730])
    np.testing.assert_array_equal(pane.corners_in((1024, 1024)), PANE_1024_PX["corners_px"])
    np.testing.assert_array_equal(pane.corners_in((3072, 4096)), [[-0.5, -0.5], [4095.5, -0.5], [4095.5, 3071.5],
                                                                   [-0.5, 3071.5]])
    with pytest.raises(ValueError, match="exactly one"):
        Pane(corners_frac=[[0, 0], [1, 0], [1, 1], [0, 1]], corners_px=PANE_1024_PX["corners_px"], size_mm=[7, 7])
    with pytest.raises(ValueError, match="exactly one"):
        Pane(size_mm=[7, 7])
    with pytest.raises(ValueError, match="between 0 and 1"):
        Pane(corners_frac=[[0, 0], [1.2, 0], [1, 1], [0, 1]], size_mm=[7, 7])


def _photo(shape=(100, 200), mm_per_px=2.0):
    return SimpleNamespace(valid=np.ones(shape, bool), mm_per_px=mm_per_px, optics=None)


FULL = [[-0.5, -0.5], [199.5, -0.5], [199.5, 99.5], [-0.5, 99.5]]  # the whole 200 x 100 px photo: 400 x 200 mm


@pytest.mark.parametrize("size_mm", [(400, 200), (200, 100), (400 / 1.3, 200 / 1.3), (480, 240)])
def test_a_pane_consistent_with_the_measured_scale_is_accepted(size_mm):
    """Spanning 1 to 3 times its size on the backdrop (a pane nearer the camera than the grid), or a little less."""
    check_pane(Pane(corners_px=FULL, size_mm=size_mm), (), _photo())


@pytest.mark.parametrize("size_mm, why", [
    ((1200, 600), "ratio 0.33"),  # the corners of a photo three times smaller
    ((100, 50), "ratio 4"),  # beyond the capture geometry
    ((200, 400), "ratio 2 x 0.5"),  # width and height swapped
])
def test_a_pane_at_odds_with_the_measured_scale_is_refused(size_mm, why):
    with pytest.raises(InputError) as err:
        check_pane(Pane(corners_px=FULL, size_mm=size_mm), (), _photo(), spec_label="the specification 's.json'")
    msg = str(err.value)
    assert "the pane of the specification 's.json' spans 400 x 200 mm on the backdrop" in msg and why in msg
    assert "corners_frac" in msg and "\n" not in msg
    assert PANE_SCALE_RANGE["transmission"] == (0.75, 3.0)


def test_a_pane_or_zone_outside_the_photo_is_refused():
    corners = [[-0.5, -0.5], [299.5, -0.5], [299.5, 99.5], [-0.5, 99.5]]
    with pytest.raises(InputError, match=r"corner at \(299.5, -0.5\) px, outside the 200 x 100 px photo"):
        check_pane(Pane(corners_px=corners, size_mm=(600, 200)), (), _photo())
    pane = Pane(corners_px=FULL, size_mm=(400, 200))
    with pytest.raises(InputError, match=r"zone 2 \('p'\) .* reaches beyond the 400 x 200 mm pane"):
        check_pane(pane, (Zone(name="v", inset_mm=10), Zone(name="p", polygon_mm=[[0, 0], [450, 0], [0, 100]])),
                   _photo())
    with pytest.raises(InputError, match=r"zone 1 \('v'\) .* is empty: an inset of 100 mm"):
        check_pane(pane, (Zone(name="v", inset_mm=100),), _photo())


def test_every_criterion_states_the_trusted_share_it_judges():
    from glassdist.acceptance.spec import spec_verdict

    res = SimpleNamespace(method="comparative", sigma_mm=1.0, detrend_degree=2)  # what the protocol checks read
    spec = Spec(name="s", zones=[Zone(name="vision", inset_mm=1)], criteria=[
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 4, "zone": "vision"},
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 4}])
    zones = {"vision": {"statistics": {"phi_eff": {"p95_abs": 1.0}}, "trusted_percent": 42.5}}
    v = spec_verdict(spec, {"phi_eff": {"p95_abs": 2.0}}, res, zones=zones, trusted_percent=66.25)
    assert [(c.covers_percent, c.covers) for c in v.checks] == [(42.5, "zone 'vision'"), (66.25, "the image")]
    assert v.checks[0].line().endswith("(value 1 mD; over the trusted 42.5 % of zone 'vision')")
    assert v.to_dict()["checks"][1]["covers_percent"] == 66.25


# ----------------------------------------------------------------- the bundled photos, upscaled

def _factory_spec(**pane):
    from conftest import REAL_PAIR_SPEC

    spec = json.loads(json.dumps(REAL_PAIR_SPEC))
    return dict(spec, pane=pane) if pane else spec


def _upscaled(folder: Path, factor=3) -> tuple[Path, Path]:
    import cv2

    out = []
    for name, stem in (("distorted_waves.bmp", "waves"), ("reference.png", "reference")):
        im = cv2.imread(str(REAL / name), cv2.IMREAD_UNCHANGED)
        path = folder / f"{stem}_x{factor}.png"
        cv2.imwrite(str(path), cv2.resize(im, None, fx=factor, fy=factor, interpolation=cv2.INTER_CUBIC))
        out.append(path)
    return out[0], out[1]


@pytest.fixture(scope="module")
def pair_x3(tmp_path_factory):
    if not (REAL / "distorted_waves.bmp").is_file():
        pytest.skip(f"the real photographs are not in {REAL}")
    return _upscaled(tmp_path_factory.mktemp("x3"))


@pytest.fixture(scope="module")
def analyses(pair_x3):
    """The factory protocol's analysis of the bundled pair at 1024 px and upscaled 3 x (3072 px)."""
    import glassdist

    kw = {"pattern": "checkerboard", "pitch_mm": 5.0, "distance_m": 1.0, "detrend_degree": 2}  # the spec's protocol
    one = glassdist.analyze(REAL / "distorted_waves.bmp", reference=REAL / "reference.png", **kw)
    three = glassdist.analyze(pair_x3[0], reference=pair_x3[1], **kw)
    assert three.valid.shape == (3072, 3072)
    return one, three


@needs_real
@pytest.mark.slow
def test_a_spec_written_for_1024_px_on_the_upscaled_photo_exits_2_naming_the_pane(pair_x3, tmp_path, capsys):
    """Once the zones sat in the photo's top-left corner and the pane passed 14/14 with exit 0."""
    from glassdist.cli import main

    spec = tmp_path / "spec_1024px.json"
    spec.write_text(json.dumps(_factory_spec(**PANE_1024_PX)))
    code = main(["analyze", str(pair_x3[0]), "--reference", str(pair_x3[1]), "--spec", str(spec),
                 "--out", str(tmp_path / "out")])
    out, err = capsys.readouterr()
    assert code == 2, err
    line = err.strip()
    assert "\n" not in line and "VERDICT" not in out
    assert "the pane of the specification" in line and "'corners_px' were written for another resolution" in line
    assert "size_mm is 730 x 730 mm" in line and "corners_frac" in line
    assert not (tmp_path / "out" / "summary.json").exists()


@needs_real
@pytest.mark.slow
def test_a_resolution_independent_pane_gives_the_same_verdict_at_1024_px_and_3x(analyses):
    from glassdist.acceptance.assess import assess

    one, three = analyses
    spec = _factory_spec()
    assert "corners_frac" in spec["pane"]
    v1, v3 = assess(one, spec).verdict, assess(three, spec).verdict
    # the pixel-corner form still serves the resolution it was written for, with the same verdict
    v1_px = assess(one, _factory_spec(**PANE_1024_PX)).verdict
    assert [(c.criterion, c.value, c.passed) for c in v1_px.checks] == [(c.criterion, c.value, c.passed)
                                                                          for c in v1.checks]
    with pytest.raises(InputError, match="the pane of the specification spans"):
        assess(three, _factory_spec(**PANE_1024_PX))
    assert [c.criterion for c in v1.checks] == [c.criterion for c in v3.checks]
    assert [c.passed for c in v1.checks] == [c.passed for c in v3.checks]
    assert v1.label == v3.label == "FAIL" and sum(c.passed for c in v1.checks) == 11
    p95 = [(a.value, b.value) for a, b in zip(v1.checks, v3.checks) if a.criterion.startswith("p95")]
    assert len(p95) == 4
    for a, b in p95:
        assert b == pytest.approx(a, rel=0.02)
    for a, b in zip(v1.checks, v3.checks):  # each criterion on the channels says what share it judged
        if a.covers:
            assert a.covers == b.covers and a.covers_percent == pytest.approx(b.covers_percent, abs=2.0)
            assert "over the trusted" in a.line() and 50 < a.covers_percent < 100
