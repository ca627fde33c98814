"""The console lines of a run: a zone with nothing to judge says so, never 'nan %'."""

from types import SimpleNamespace

from glassdist.report.console import acceptance_lines


def _acceptance(zones):
    return SimpleNamespace(verdict=None, zones=zones, warnings=())


def test_a_zone_outside_the_photo_is_named_not_nan():
    lines = acceptance_lines(_acceptance({"vision": {"trusted_percent": float("nan"), "statistics": {}}}))
    assert lines == ["zone vision: not in the photo, nothing of it judged"]
    assert not any("nan" in line for line in lines)


def test_a_zone_without_trusted_statistics_reads_n_a():
    zones = {"edge": {"trusted_percent": 0.0, "statistics": {"phi_eff": {"p95_abs": float("nan")}}},
             "vision": {"trusted_percent": 71.97, "statistics": {"phi_eff": {"p95_abs": 70.83},
                                                                  "phi_shear": {"p95_abs": 73.22}}}}
    lines = acceptance_lines(_acceptance(zones))
    assert lines[0] == "zone edge: trusted 0 % of the zone, p95 |phi_eff| n/a, p95 |phi_shear| n/a"
    assert lines[1] == "zone vision: trusted 71.97 % of the zone, p95 |phi_eff| 70.83 mD, p95 |phi_shear| 73.22 mD"
