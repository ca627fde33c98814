"""The paper's virtual experiments (§3): reduced runs against the bounds of issue 5, and the committed full runs.

Reduced runs use half-size images (512 x 384 px) and 4 samples per pixel; they
check the same bounds as the full runs in ``docs/records/experiments/`` (parity ratios and
Procrustes scale within 2 %, rotation below 0.1 deg; pitch spread within ±2 %,
Direct vs Comparative within 3 %; rotation ratio within 2 %).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from glassdist.cli import main
from glassdist.experiments import run_pitch, run_rotation, scaled_scene
from glassdist.experiments._common import relative_difference

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs" / "records" / "experiments"
REDUCED = {"scale": 0.5, "spp": 4}


def _failed(record: dict) -> list[str]:
    """Bounds not met (``record["bounds"]``)."""
    return [f"{b['what']}: {b['value']:.4g}" for b in record["bounds"].values() if not b["met"]]


#: What the reduced runs measured (docs/records/experiments/README.md, "Reduced versions"): the tests hold
#: them at these figures. The exact tracer is seeded and deterministic; the margins (0.003 on
#: ratios, 0.005 on Direct / truth, 0.02 deg) cover the platform's arithmetic, not a change of
#: method (re-measure, then update the docs and these figures).
PARITY_HALF = {"ratios": {"phi_eff": 0.9929, "phi_shear": 0.9915, "phi_total": 0.9923}, "scale": 0.9818,
               "rotation_deg": 0.032}
#: The half-size pitch run's Direct phi_shear spread across pitches: 1.32 % since F5 grows into the
#: strong local frequencies and works on a grid fine enough for them (bound 2 %; it read 2.76 % when F5
#: kept to the one pass's region and grid, 2.37 % before F5: the 160 mm lens spans under two carrier
#: periods of the 96.9 mm grid at half size). Held to +-0.2 points: more is a regression, less a docs update.
PITCH_HALF_SPREAD_SHEAR = 0.0132
PITCH_HALF_DIRECT_VS_EXACT = {"phi_eff": {"coarse": 1.034, "medium": 1.006, "fine": 1.001},
                              "phi_shear": {"coarse": 1.020, "medium": 1.008, "fine": 1.004}}


@pytest.mark.slow
def test_parity_reduced_cli(tmp_path):
    """§3.1 at half size through the command line: files written, Table 2 within 2 %, frame within 0.1 deg."""
    code = main(["experiment", "parity", "--out", str(tmp_path), "--scale", "0.5", "--spp", "4", "--no-progress"])
    assert code == 0
    for f in ("parity.json", "parity.md", "fig6_parity.png"):
        assert (tmp_path / f).stat().st_size > 0
    rec = json.loads((tmp_path / "parity.json").read_text())
    assert rec["image_size"] == [512, 384] and rec["detrend_degree"] == 0
    assert not _failed(rec), _failed(rec)
    for name, r in rec["direct"]["ratios_vs_model"].items():
        assert r == pytest.approx(PARITY_HALF["ratios"][name], abs=0.003), (name, r)
    pro = rec["direct"]["procrustes_vs_model"]
    assert pro["scale"] == pytest.approx(PARITY_HALF["scale"], abs=0.003)
    assert pro["rotation_deg"] == pytest.approx(PARITY_HALF["rotation_deg"], abs=0.02)
    # ablation: the isotropic bandpass must not rotate the recovered frame on this scene
    iso = rec["ablation"]["isotropic_bandpass"]
    assert iso["procrustes_vs_model"]["rotation_deg"] == pytest.approx(PARITY_HALF["rotation_deg"], abs=0.02)
    assert "glassdist experiment parity" in rec["command"]


@pytest.mark.slow
def test_pitch_reduced():
    """§3.2 at half size: Direct spread within ±2 %, Direct vs Comparative within 3 %.

    Checked on the region common to all runs (each grid's own region differs, and the
    exact truth through the same stack moves by ~3 % with the region alone) and on the
    interior region (common, at least 3 sigma inside its border), where the bounds are judged.
    """
    res = run_pitch(**REDUCED)
    rec = res.record
    assert not _failed(rec), _failed(rec)
    assert rec["bounds"]["spread_direct_phi_shear"]["value"] == pytest.approx(PITCH_HALF_SPREAD_SHEAR, abs=0.002)
    inner = rec["summary"]["interior"]
    assert rec["interior_region_fraction"] > 0.1
    for ch in ("phi_eff", "phi_shear"):
        for n in ("coarse", "medium", "fine"):
            # the analyzer against the exact truth (docs: the coarse grid reads ~3-4 % high at half size)
            got = inner["direct_vs_exact"][ch][n]
            assert got == pytest.approx(PITCH_HALF_DIRECT_VS_EXACT[ch][n], abs=0.005), (ch, n, got)
    for n in ("coarse", "medium", "fine"):  # one physical smoothing scale for every pitch
        assert rec["pitches"][n]["direct"]["sigma_mm"] == rec["sigma_mm"]


@pytest.mark.slow
def test_rotation_reduced():
    """§3.3 at half size: mean |phi_eff| of aligned and rotated grids within 2 %."""
    res = run_rotation(**REDUCED)
    assert res.record["ratio"] >= 0.98, res.record["ratio"]
    assert res.record["ratio"] == pytest.approx(0.9957, abs=0.003)  # measured at half size (docs/records/experiments)
    assert res.record["runs"]["rotated"]["grid_rotation_deg"] != res.record["runs"]["aligned"]["grid_rotation_deg"]
    assert res.passed


@pytest.mark.parametrize("name", ["parity", "pitch", "rotation"])
def test_committed_full_runs_meet_bounds(name):
    """The committed documents: the full-size runs under docs/records/experiments/ meet every bound of issue 5.

    A check of the documents, not of the code (a full run takes minutes; the reduced runs above
    recompute): it fails when a committed record is replaced by one that misses a bound.
    """
    rec = json.loads((DOCS / f"{name}.json").read_text())
    assert rec["command"].startswith("glassdist experiment " + name)
    assert rec["image_size"] == [1024, 768] and rec["engine"] == "exact"
    assert not _failed(rec), _failed(rec)
    assert (DOCS / f"{name}.md").is_file()


def test_relative_difference_and_scaled_scene():
    """Helpers: the paper's relative difference, and scaling keeps the field of view."""
    assert relative_difference(8.42, 7.84) == pytest.approx(0.0689, abs=1e-4)
    assert relative_difference(0.0, 0.0) == 0.0
    from glassdist.scene import load_scene
    from glassdist.theory import nominal_mm_per_px

    sc = load_scene(REPO / "examples" / "scenes" / "wavy_slab.yaml")
    half = scaled_scene(sc, scale=0.5, spp=2)
    assert half.camera.pixels == (512, 384) and half.render.samples_per_pixel == 2
    assert half.camera.sensor_width_mm == sc.camera.sensor_width_mm
    assert nominal_mm_per_px(half) == pytest.approx(2 * nominal_mm_per_px(sc), rel=1e-9)


def test_cli_bad_input(tmp_path, capsys):
    """Unknown experiment is an argparse error; a bad scale a one-line error (exit 2)."""
    with pytest.raises(SystemExit):
        main(["experiment", "nope", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        main(["experiment", "parity", "--out", str(tmp_path), "--scale", "-1"])
    assert main(["experiment", "parity", "--out", str(tmp_path), "--spp", "0", "--no-progress"]) == 2
    assert "error" in capsys.readouterr().err


def test_accuracy_subset_cli(tmp_path):
    """The accuracy experiment through the command line on two scenes at half size, 2 spp.

    The wavy slab reads within its clean bounds against the exact truth (mean |phi_eff|
    within 2 %, correlations >= 0.98) and flat glass with noise stays under p95 0.4 mD.
    """
    code = main(["experiment", "accuracy", "--scenes", "wavy_slab,flat_noisy", "--scale", "0.5", "--spp", "2",
                 "--no-progress", "--out", str(tmp_path)])
    assert code == 0
    rec = json.loads((tmp_path / "accuracy.json").read_text())
    assert rec["command"].startswith("glassdist experiment accuracy")
    assert [s["name"] for s in rec["scenes"]] == ["wavy_slab", "flat_noisy"]
    for s in rec["scenes"]:
        for method, run in s["runs"].items():
            for key in ("ratio_phi_eff", "r_phi_eff", "r_phi_shear", "p95_phi_eff"):
                if key in run["checks"]:
                    assert run["checks"][key]["met"], (s["name"], method, key, run["checks"][key])
    assert "## Against the acceptance bounds" in (tmp_path / "accuracy.md").read_text()


def test_accuracy_takes_analyzer_parameters_and_refuses_bad_ones(tmp_path, capsys, monkeypatch):
    import glassdist.experiments.accuracy as A

    seen = []
    monkeypatch.setattr(A, "measure", lambda inputs, method, params, kind: seen.append(params) or {"method": method,
                                                                                                   "error": "skipped"})
    f5 = tmp_path / "f5.json"
    f5.write_text('{"deformation_min_deviation": 0}')
    out = tmp_path / "out"
    assert main(["experiment", "accuracy", "--scenes", "wavy_slab", "--scale", "0.25", "--spp", "1", "--params", str(f5),
                 "--no-progress", "--out", str(out)]) == 0
    assert [p.deformation_min_deviation for p in seen] == [0.0, 0.0]
    assert seen[0].sigma_mm == 40.0  # the scene's own analysis settings stay under the file's
    assert "--params" in json.loads((out / "accuracy.json").read_text())["command"]
    bad = tmp_path / "bad.json"
    bad.write_text('{"deformation_min_deviaton": 0}')
    assert main(["experiment", "accuracy", "--params", str(bad), "--out", str(tmp_path / "o2"), "--no-progress"]) == 2
    assert "deformation_min_deviaton" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["parity", "pitch", "rotation", "transfer"])
def test_every_experiment_takes_analyzer_parameters_and_refuses_bad_ones_before_rendering(name, tmp_path, capsys,
                                                                                          monkeypatch):
    import glassdist.experiments._common as C

    bad = tmp_path / "bad.json"
    bad.write_text('{"deformation_min_deviaton": 0}')
    # nothing renders: a render would fail this test
    monkeypatch.setattr(C, "render_inputs", lambda *a, **k: pytest.fail("rendered before the parameters were checked"))
    monkeypatch.setattr(C.RunOptions, "render", lambda *a, **k: pytest.fail("rendered before the parameters were checked"))
    assert main(["experiment", name, "--params", str(bad), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert "deformation_min_deviaton" in capsys.readouterr().err


def test_parity_runs_with_analyzer_parameters(tmp_path):
    f5 = tmp_path / "f5.json"
    f5.write_text('{"deformation_min_deviation": 0}')
    out = tmp_path / "out"
    assert main(["experiment", "parity", "--scale", "0.25", "--spp", "1", "--params", str(f5), "--no-progress",
                 "--out", str(out)]) == 0
    rec = json.loads((out / "parity.json").read_text())
    assert rec["params"]["deformation_min_deviation"] == 0.0  # the file's, over the shipped 0.2
    assert rec["detrend_degree"] == 0  # the experiment's own setting stays over the file
    assert "--params" in rec["command"]


def test_accuracy_unknown_scene_is_bad_input(tmp_path, capsys):
    assert main(["experiment", "accuracy", "--scenes", "nope", "--out", str(tmp_path), "--no-progress"]) == 2
    assert "unknown accuracy scene" in capsys.readouterr().err
