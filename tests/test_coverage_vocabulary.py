"""One coverage vocabulary: the measured and the trusted share, one name and one number everywhere.

Two real analyses of the small lens pair (one of the whole image, one of a mask), each with a
specification whose area limits judge the trusted share and with ``--report``, run as a
two-pane batch: ``summary.json``, the console, ``report.html``, the batch index (CSV and
HTML) and the web application's job page must all state the same two numbers.
"""

from __future__ import annotations

import contextlib
import csv
import html
import io
import json
import re

import numpy as np
import pytest

from conftest import write_lens_pair

SPEC = {"name": "cover", "min_valid_percent": 10, "zones": [{"name": "vision", "inset_mm": 2, "min_valid_percent": 10}],
        "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1e5}]}


def _g4(v):
    """How every output prints a share: four significant figures."""
    return f"{v:.4g}"


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    """A two-pane batch of real in-process ``glassdist analyze`` runs; ``(out, {pane: console text})``."""
    from glassdist.cli import main
    from glassdist.io import write_png16
    from glassdist.jobs.batch import Pane, run_batch
    from glassdist.jobs.runner import PaneOutcome

    root = write_lens_pair(tmp_path_factory.mktemp("vocabulary"))
    (root / "spec.json").write_text(json.dumps(SPEC))
    mask = np.zeros((160, 160), np.uint16)
    mask[:, :100] = 65535  # the left 100 columns asked for
    write_png16(root / "mask.png", mask)
    consoles = {}

    def runner(pane, out_dir, *, report=False, export=False):
        args = ["analyze", str(pane.image), "--reference", str(root / "reference.png"), "--pitch-mm", "2",
                "--distance-m", "1", "--spec", str(root / "spec.json"), "--report", "--fields", "pixel", "--out", str(out_dir)]
        args += ["--mask", str(root / "mask.png")] if pane.id == "masked" else []
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            code = main(args)
        consoles[pane.id] = buf.getvalue()
        return PaneOutcome(code, buf.getvalue())

    panes = [Pane(id=i, image=root / "pane.png", pitch_mm=2.0, distance_m=1.0) for i in ("whole", "masked")]
    out = root / "batch"
    assert run_batch(panes, out, report=True, runner=runner, progress=False, echo=lambda s: None) == 0
    return out, consoles


def _shares(summary):
    return summary["measured_percent"], summary["trusted_percent"]


@pytest.mark.parametrize("pane, of", [("whole", "the image"), ("masked", "the mask")])
def test_one_name_and_one_number_for_each_share(batch, pane, of):
    from glassdist.web._app import _TEMPLATES
    from glassdist.web._jobs import Job

    out, consoles = batch
    folder = out / "panes" / pane
    summary = json.loads((folder / "summary.json").read_text())
    measured, trusted = _shares(summary)
    # the old names are gone, and the two shares are distinct quantities (the guard band is measured, not trusted)
    flat = json.dumps(summary)
    for old in ("valid_fraction", "trusted_fraction", "coverage_percent", "valid_percent\""):
        assert old not in flat, old
    assert 0 < trusted < measured <= 100
    # independent truth: the shares of the region asked for, from result.npz (pixel layout)
    with np.load(folder / "result.npz") as npz:
        valid = npz["valid"]
    asked = np.ones_like(valid) if pane == "whole" else np.zeros_like(valid)
    if pane == "masked":
        asked[:, :100] = True
    assert measured == pytest.approx(100.0 * np.count_nonzero(valid & asked) / np.count_nonzero(asked), abs=1e-9)
    counts = summary["quality_counts"]
    if pane == "whole":
        assert trusted == pytest.approx(100.0 * counts["analysed"] / valid.size, abs=1e-9)

    # console: the run line, the spec's area check and the zone line
    console = consoles[pane]
    assert f"measured {_g4(measured)} %, trusted {_g4(trusted)} % of {of}" in console
    assert f"trusted area >= 10 % of {of}  (value {_g4(trusted)} %)" in console
    zone = summary["zones"]["vision"]["trusted_percent"]
    assert f"zone vision: trusted {_g4(zone)} % of the zone" in console
    check = next(c for c in summary["verdict"]["checks"] if c["criterion"] == f"trusted area >= 10 % of {of}")
    assert check["value"] == trusted

    # report.html: the capture-geometry rows and the embedded data
    report = (folder / "report.html").read_text()
    assert f'<span id="measured-percent">{_g4(measured)}</span> % of {of}' in report
    assert f'<span id="trusted-percent">{_g4(trusted)}</span> % of {of}' in report
    data = json.loads(re.search(r'id="glassdist-report-data">(.*?)</script>', report, re.S).group(1))
    assert (data["measured_percent"], data["trusted_percent"]) == (measured, trusted)
    assert data["zones"]["vision"]["trusted_percent"] == zone

    # the batch index: CSV columns and HTML cells
    with (out / "index.csv").open() as fh:
        row = {r["id"]: r for r in csv.DictReader(fh)}[pane]
    assert (row["measured_percent"], row["trusted_percent"]) == (_g4(measured), _g4(trusted))
    index = (out / "index.html").read_text()
    assert "<th rowspan=\"2\">measured %</th><th rowspan=\"2\">trusted %</th>" in index
    cells = re.search(rf'<tr [^>]*id="pane-{pane}">(.*?)</tr>', index).group(1)
    assert f"<td>{_g4(measured)}</td><td>{_g4(trusted)}</td>" in cells

    # the web application's job page, rendered from the same summary.json
    job = Job(id="j1", folder=folder, display={"image": "pane.png"})
    job.state = "done"
    page = _TEMPLATES.env.get_template("job.html").render(
        job=job, summary=summary, verdict=summary["verdict"], statistics=summary["a4"]["statistics"],
        figures=[], downloads=[], masks=[], request=None)
    text = html.unescape(re.sub(r"\s+", " ", page))
    assert (f'measured <span id="measured-percent">{_g4(measured)}</span> %, trusted '
            f'<span id="trusted-percent">{_g4(trusted)}</span> % of {of}') in text
