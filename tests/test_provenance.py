"""One record whatever the entry point: the Python API keeps its inputs, prints nothing, and writes the command line's summary.

``glassdist.analyze(path, reference=path)`` keeps each file it read with the SHA-256 of the
bytes decoded (``result.sources``); ``write_outputs(result, out, report=True)`` records them
without further keywords (the report names the photo and its SHA-256 and draws
``input_region.png``); nothing reaches stdout or stderr; and ``glassdist analyze``, a
``glassdist batch`` pane and the API write the same ``summary.json`` for the same inputs.
"""

import hashlib
import json

import pytest

import glassdist
from conftest import run_cli, write_lens_pair
from glassdist.errors import InputError


@pytest.fixture()
def pair(tmp_path):
    return write_lens_pair(tmp_path)


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_analyze_keeps_its_input_files_with_their_sha256(pair):
    res = glassdist.analyze(pair / "pane.png", reference=pair / "reference.png", pitch_mm=2.0, distance_m=1.0)
    assert res.sources["image"] == str(pair / "pane.png")
    assert res.sources["image_sha256"] == _sha(pair / "pane.png")
    assert res.sources["reference"] == str(pair / "reference.png")
    assert res.sources["reference_sha256"] == _sha(pair / "reference.png")
    assert res.sources["camera"] is None  # a PNG without EXIF
    assert res.sources["given"] == ()  # every setting defaulted
    arrays = glassdist.analyze(glassdist.read_image(pair / "pane.png"), pitch_mm=2.0, distance_m=1.0, detrend_degree=3)
    assert arrays.sources == {"given": ("detrend_degree",)}  # no file read


def test_api_records_its_inputs_and_prints_nothing(pair, tmp_path, capfd):
    """As the README shows it: the report states the photo and its SHA-256, input_region.png is written, the
    history row names the image; stdout and stderr (the file descriptors, not only Python's streams) stay empty."""
    capfd.readouterr()
    # 500 m: a warning to print (millimetres typed as metres), had the API printed its warnings
    res = glassdist.analyze(pair / "pane.png", reference=pair / "reference.png", pitch_mm=2.0, distance_m=500.0)
    assert any("implausible distance" in w for w in res.warnings)
    out = tmp_path / "out"
    assert glassdist.write_outputs(res, out, report=True) == 0
    printed = capfd.readouterr()
    assert printed.out == "" and printed.err == ""
    summary = json.loads((out / "summary.json").read_text())
    assert summary["inputs"]["image_sha256"] == _sha(pair / "pane.png")
    assert summary["inputs"]["reference_sha256"] == _sha(pair / "reference.png")
    assert "input_region.png" in summary["outputs"]
    html = (out / "report.html").read_text()
    assert _sha(pair / "pane.png") in html and "pane.png" in html and _sha(pair / "reference.png") in html
    rows = glassdist.history(as_frame=False)
    assert rows and rows[-1]["image_sha256"] == _sha(pair / "pane.png")
    assert rows[-1]["image"].endswith("pane.png")


def test_a_photo_changed_since_its_analysis_is_not_recorded(pair, tmp_path):
    """The record states the SHA-256 of what was analysed: a file rewritten in between is an error, not a false record."""
    res = glassdist.analyze(pair / "pane.png", reference=pair / "reference.png", pitch_mm=2.0, distance_m=1.0)
    (pair / "pane.png").write_bytes((pair / "reference.png").read_bytes())
    with pytest.raises(InputError, match="changed since it was analysed"):
        glassdist.write_outputs(res, tmp_path / "out", history=False)


#: What may differ between two records of the same analysis: where and when they were written.
_WHERE_AND_WHEN = {"outputs", "recorded_utc", "created_utc", "timestamp", "out_dir", "duration_s", "wall_s"}


def _comparable(obj):
    """``summary.json`` less the output files' digests, times and the input paths (each entry point names them its way)."""
    if isinstance(obj, dict):
        return {k: _comparable(v) for k, v in obj.items() if k not in _WHERE_AND_WHEN and k not in ("image", "reference",
                                                                                                   "mask", "path", "name")}
    if isinstance(obj, list):
        return [_comparable(v) for v in obj]
    return obj


def _summary(folder):
    return json.loads((folder / "summary.json").read_text())


#: The same settings as options of ``glassdist analyze``, keywords of ``analyze`` and fields of a batch pane.
SETTINGS = {
    "defaults": ([], {}),
    "chosen": (["--pattern", "lines", "--detrend-degree", "3", "--sigma-mm", "6"],
               {"pattern": "lines", "detrend_degree": 3, "sigma_mm": 6.0}),
}


@pytest.mark.parametrize("settings", [pytest.param("defaults"), pytest.param("chosen", marks=pytest.mark.slow)])
def test_command_line_batch_and_api_write_the_same_summary(pair, tmp_path, settings):
    from glassdist.jobs.batch import Pane, run_batch

    options, keywords = SETTINGS[settings]
    cli = run_cli("analyze", pair / "pane.png", "--reference", pair / "reference.png", "--pitch-mm", "2",
                  "--distance-m", "1", *options, "--pane-id", "P-1", "--out", tmp_path / "cli", "-q")
    assert cli.returncode == 0, cli.stderr
    res = glassdist.analyze(pair / "pane.png", reference=pair / "reference.png", pitch_mm=2.0, distance_m=1.0,
                            **keywords)
    assert glassdist.write_outputs(res, tmp_path / "api", metadata={"pane_id": "P-1"}) == 0
    pane = Pane(id="P-1", image=pair / "pane.png", reference=pair / "reference.png", pitch_mm=2.0, distance_m=1.0,
                **keywords)
    run_batch([pane], tmp_path / "batch", progress=False, echo=lambda s: None)
    a, b, c = (_summary(f) for f in (tmp_path / "cli", tmp_path / "api", tmp_path / "batch" / "panes" / "P-1"))
    assert _comparable(b) == _comparable(a)
    assert _comparable(c) == _comparable(a)
    for s in (a, b, c):  # the same input digests
        assert s["inputs"]["image_sha256"] == _sha(pair / "pane.png")


def test_api_prints_nothing_in_a_process_of_its_own(pair, tmp_path):
    """Without the test runner's log capture: logging's last-resort handler would print the warnings on stderr."""
    import subprocess
    import sys

    from conftest import child_env

    code = ("import glassdist, sys; p = sys.argv[1]; "
            "res = glassdist.analyze(p + '/pane.png', reference=p + '/reference.png', pitch_mm=2.0, distance_m=500.0); "
            "assert any('implausible distance' in w for w in res.warnings); "
            "glassdist.write_outputs(res, sys.argv[2], report=True)")
    run = subprocess.run([sys.executable, "-c", code, str(pair), str(tmp_path / "out")], env=child_env(),
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout == "" and run.stderr == ""
    assert (tmp_path / "out" / "input_region.png").exists()
