"""One result contract: :class:`~glassdist.analyzer.result.Result`, met by the analysis's result and by a stored one.

* both classes implement every member of the protocol (checked by mypy on this file, and here
  at run time), and a run read back from its folder answers each member as the analysis did;
* acceptance judges a stored result as it judges the analysis's own (same statistics, same
  verdict), reflection results included (the typed :class:`~glassdist.analyzer.result.Optics`);
* no module reads ``_deferred`` outside its own, and none tells results apart by probing for
  attributes (``hasattr(result, ...)``, ``getattr(result, "...", default)``): an AST test.
"""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import numpy as np
import pytest

import glassdist
from glassdist.acceptance.assess import assess
from glassdist.acceptance.spec import Spec
from glassdist.acceptance.stats import regions_statistics, result_statistics
from glassdist.analyzer.result import FIELDS, AnalysisResult, Optics, Result
from glassdist.storage import StoredResult, load_result
from glassdist.synthetic import lens_displacement, synthetic_capture

SRC = Path(__file__).resolve().parents[1] / "src" / "glassdist"


Analysed = tuple[AnalysisResult, StoredResult, StoredResult]


def _as_result(r: AnalysisResult | StoredResult) -> Result:
    """Type-checked: mypy holds both classes to the protocol here."""
    return r


def _members() -> list[str]:
    return sorted(n for n in Result.__dict__ if not n.startswith("_") and n not in ("register",))


@pytest.fixture(scope="module")
def analysed(tmp_path_factory: pytest.TempPathFactory) -> Analysed:
    cap = synthetic_capture((240, 300), pitch_mm=6.0, mm_per_px=1.0, rng=5,
                            displacement=lens_displacement(-0.04, 2.0, center_mm=(10.0, -5.0), radius_mm=70.0))
    res = glassdist.analyze(cap.image, pitch_mm=6.0, distance_m=2.0, reference=cap.reference)
    stored = []
    for layout in ("analysis", "pixel"):
        out = tmp_path_factory.mktemp(layout)
        glassdist.write_outputs(res, out, fields=layout, history=False)
        stored.append(load_result(out))
    return res, stored[0], stored[1]


def test_the_protocol_names_what_downstream_code_reads() -> None:
    names = set(_members())
    assert {"valid", "trusted", "mm_per_px", "optics", "method", "pattern", "field_specs", "pixel_field",
            "pixel_rows", "grid_fields", "with_grid_fields", "analysis_grid", "grid_valid"} <= names


@pytest.mark.parametrize("cls", [AnalysisResult, StoredResult])
def test_both_classes_implement_every_member(cls: type) -> None:
    missing = [n for n in _members() if not hasattr(cls, n) and n not in getattr(cls, "__dataclass_fields__", {})]
    assert missing == []
    for name in _members():  # the methods take what the protocol's take
        proto = Result.__dict__[name]
        if inspect.isfunction(proto):
            want = list(inspect.signature(proto).parameters)
            assert list(inspect.signature(getattr(cls, name)).parameters)[:len(want)] == want, name


@pytest.mark.parametrize("layout", [1, 2])
def test_a_stored_result_answers_as_the_analysis_did(analysed: Analysed, layout: int) -> None:
    res, stored = _as_result(analysed[0]), _as_result(analysed[layout])
    assert isinstance(analysed[layout], Result)
    for name in ("method", "pattern", "mm_per_px", "pitch_mm", "distance_m", "sigma_mm", "carrier_period_mm",
                 "detrend_degree", "px_per_period", "margin_px", "optics"):
        assert getattr(stored, name) == getattr(res, name), name
    assert [f.name for f in stored.field_specs()] == [f.name for f in res.field_specs()]
    np.testing.assert_array_equal(stored.valid, res.valid)
    np.testing.assert_array_equal(stored.trusted, res.trusted)
    np.testing.assert_array_equal(stored.detrend_region, res.detrend_region)
    for name in ("phi_eff_mD", "axis_deg", "quality"):
        np.testing.assert_array_equal(stored.pixel_field(name), res.pixel_field(name))
    blocks = list(stored.pixel_rows(["phi_eff_mD"], max_pixels=300 * 50))
    assert len(blocks) == 5
    np.testing.assert_array_equal(np.concatenate([b["phi_eff_mD"] for _, b in blocks]), res.pixel_field("phi_eff_mD"))


@pytest.mark.parametrize("layout", [1, 2])
def test_acceptance_judges_a_stored_result_as_the_analysis(analysed: Analysed, layout: int) -> None:
    res, stored = analysed[0], analysed[layout]
    assert result_statistics(stored) == result_statistics(res)
    regions = {"trusted": res.trusted, "left": res.trusted & (np.arange(300) < 150)[None, :]}
    assert regions_statistics(stored, regions) == regions_statistics(res, regions)
    spec = Spec.model_validate({"name": "s", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1000}]})
    a, b = assess(res, spec), assess(stored, spec)
    assert a.verdict is not None and b.verdict is not None
    assert b.verdict.to_dict() == a.verdict.to_dict() and b.stats == a.stats


def test_the_reflection_geometry_is_a_typed_record() -> None:
    from glassdist.analyzer.reflection import ReflectionGeometry

    geometry = ReflectionGeometry(distance_m=1.5, camera_distance_m=3.0, incidence_deg=12.0)
    o = geometry.optics(("a note",))
    assert isinstance(o, Optics) and o.magnification == pytest.approx(1.5) and o.camera_in_board_plane is False
    d = o.to_dict()
    assert d["optics"] == "reflection" and d["notes"] == ["a note"] and d["effective_distance_m"] == pytest.approx(1.0)
    assert Optics.from_dict(d) == o
    on_disk = StoredResult.on_pixel_grid({}, np.ones((4, 4), bool), optics=d)
    assert on_disk.optics == o


def test_with_grid_fields_keeps_the_class(analysed: Analysed) -> None:
    res, stored = analysed[0], analysed[1]
    f = res.grid_fields()
    assert type(res.with_grid_fields(f)) is AnalysisResult
    changed = stored.with_grid_fields(stored.grid_fields(), sigma_mm=99.0)
    assert type(changed) is StoredResult and changed.sigma_mm == 99.0 and stored.sigma_mm != 99.0


# ------------------------------------------------------------------- no second path around the contract

_RESULT_NAMES = ("result", "res", "stored", "reading")


def _names_a_result(node: ast.expr) -> bool:
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return any(name == n or name.endswith("_" + n) or name.startswith(n + "_") for n in _RESULT_NAMES)


def _sniffing(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr == "_deferred":
            found.append((node.lineno, "reads _deferred"))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.args:
            probe = node.func.id == "hasattr" or (node.func.id == "getattr" and len(node.args) == 3)
            if probe and _names_a_result(node.args[0]):
                found.append((node.lineno, f"{node.func.id}({ast.unparse(node.args[0])}, ...)"))
    return found


def test_the_sniffing_check_sees_what_it_is_for() -> None:
    bad = ("x = result._deferred\nif hasattr(result, 'pixel_rows'): pass\n"
           "y = getattr(stored_a, 'optics', None)\nz = getattr(result, name)\n")
    assert [w for _, w in _sniffing(ast.parse(bad))] == ["reads _deferred", "hasattr(result, ...)",
                                                        "getattr(stored_a, ...)"]


def test_no_module_reaches_around_the_result_contract() -> None:
    owner = SRC / "analyzer" / "result.py"
    found = [f"{path.relative_to(SRC)}:{line}: {what}"
             for path in sorted(SRC.rglob("*.py")) if path != owner
             for line, what in _sniffing(ast.parse(path.read_text(encoding="utf-8")))]
    assert found == []


def test_every_field_of_a_stored_file_is_a_registered_field(analysed: Analysed) -> None:
    assert set(analysed[1].fields) <= {f.name for f in FIELDS}
