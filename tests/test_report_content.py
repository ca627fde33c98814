"""The output stage (glassdist.write_outputs): verdict and exit code, summary.json, exports, and the HTML report's content."""

from __future__ import annotations

import base64
import csv
import hashlib
import json
import shutil
import subprocess
import tempfile
from html.parser import HTMLParser

import numpy as np
import pytest

import glassdist
from conftest import write_lens_pair
from glassdist.acceptance.assess import assess
from glassdist.report.console import acceptance_lines
from glassdist.storage import EXIT_SPEC_FAIL, write_outputs

PASSING = {"name": "lenient", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1000}]}
FAILING = {
    "name": "strict",
    "criteria": [
        {"channel": "phi_eff", "statistic": "max_abs", "max_mD": 1000},
        {"channel": "phi_shear", "statistic": "p95_abs", "max_mD": 5},
        {"channel": "phi_eff", "statistic": "area_over", "threshold_mD": 20, "max_percent": 1},
    ],
}


class _Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.links, self.ids, self.scripts = [], [], {}, {}
        self._stack = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a)
        for key in ("href", "src"):
            if key in a and tag != "img":
                self.links.append(a[key])
        self._stack.append(a.get("id"))

    def handle_endtag(self, tag):
        if self._stack:
            self._stack.pop()

    def handle_data(self, data):
        if self._stack and self._stack[-1]:
            self.ids[self._stack[-1]] = self.ids.get(self._stack[-1], "") + data


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    """One real analysis (160 x 160 px lens, -100 mD at its centre, Comparative) written twice: with a
    failing spec + report + exports, and with a passing spec; and the same photo by the Direct Method."""
    root = write_lens_pair(tmp_path_factory.mktemp("finish"))
    image, ref = root / "pane.png", root / "reference.png"
    result = glassdist.analyze(image, reference=ref, pitch_mm=2.0, distance_m=1.0)
    (root / "fail.json").write_text(json.dumps(FAILING))
    (root / "pass.json").write_text(json.dumps(PASSING))
    out_fail, out_pass = root / "out_fail", root / "out_pass"
    code_fail = write_outputs(result, out_fail, image_path=image, reference_path=ref, spec=root / "fail.json",
                              report=True, export=True, history=False)
    code_pass = write_outputs(result, out_pass, image_path=image, spec=root / "pass.json", history=False)
    lines = acceptance_lines(assess(result, root / "fail.json"))
    return dict(root=root, image=image, ref=ref, out=out_fail, out_pass=out_pass, lines=lines,
                code_fail=code_fail, code_pass=code_pass, result=result)


def test_exit_codes_and_printed_verdict(analysed):
    assert analysed["code_fail"] == EXIT_SPEC_FAIL == 3
    assert analysed["code_pass"] == 0
    lines = analysed["lines"]
    assert lines[0].startswith("PASS  max |phi_eff| <= 1000 mD")
    assert lines[1].startswith("FAIL  p95 |phi_shear| <= 5 mD")
    assert lines[2].startswith("FAIL  area |phi_eff| > 20 mD <= 1 %")
    assert lines[3] == "VERDICT: FAIL (1/3 criteria passed) spec 'strict'"


def test_summary_keeps_existing_keys_and_gains_verdict(analysed):
    s = json.loads((analysed["out"] / "summary.json").read_text())
    assert s["method"] == "comparative"
    assert s["verdict"]["result"] == "FAIL" and [c["passed"] for c in s["verdict"]["checks"]] == [True, False, False]
    assert s["a4"]["inputs"]["image"]["sha256"] == hashlib.sha256(analysed["image"].read_bytes()).hexdigest()
    assert s["a4"]["inputs"]["reference"]["sha256"] == hashlib.sha256(analysed["ref"].read_bytes()).hexdigest()
    assert s["a4"]["statistics"]["phi_eff"]["area_over_20"] > 1.0
    assert json.loads((analysed["out_pass"] / "summary.json").read_text())["verdict"]["result"] == "PASS"


def test_statistics_csv_and_a4_pngs(analysed):
    out = analysed["out"]
    rows = list(csv.DictReader((out / "statistics.csv").open()))
    assert [r["channel"] for r in rows] == ["phi_eff", "phi_shear", "phi_total"]
    trusted = analysed["result"].trusted
    assert float(rows[0]["max_abs_mD"]) == pytest.approx(np.nanmax(np.abs(analysed["result"].phi_eff_mD[trusted])), rel=1e-4)
    assert "area_over_20_percent" in rows[0]
    for name in ("input_region.png", "histograms.png", "mask_phi_eff_20mD.png", "mask_phi_shear_5mD.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"
    assert not any(p.name.endswith(".tmp") for p in out.iterdir())


def test_exports_npz_and_float32_tiff(analysed):
    import tifffile

    out = analysed["out"]
    ref = analysed["result"]
    with np.load(out / "fields.npz") as z:
        assert z["displacement_mm"].shape == (160, 160, 2) and z["phi_eff_mD"].dtype == np.float32
        np.testing.assert_allclose(z["phi_eff_mD"], ref.phi_eff_mD, rtol=1e-6)
        assert str(z["version"]) == glassdist.__version__ and float(z["distance_m"]) == 1.0
    eff = tifffile.imread(out / "tiff" / "phi_eff_mD.tif")
    assert eff.dtype == np.float32
    np.testing.assert_allclose(eff, ref.phi_eff_mD, rtol=1e-6)
    dx = tifffile.imread(out / "tiff" / "displacement_x_mm.tif")
    np.testing.assert_allclose(dx, ref.displacement_mm[..., 0], rtol=1e-6)
    with tifffile.TiffFile(out / "tiff" / "phi_shear_mD.tif") as t:
        assert json.loads(t.pages[0].description)["unit"] == "mD"
        assert t.pages[0].predictor == 3  # floating-point predictor before deflate (smaller, as fast)
    import zipfile

    with zipfile.ZipFile(out / "fields.npz") as z:  # floats stored (deflate barely shrank them), masks deflated
        how = {i.filename: i.compress_type for i in z.infolist()}
    assert how["phi_eff_mD.npy"] == zipfile.ZIP_STORED and how["valid.npy"] == zipfile.ZIP_DEFLATED


def test_report_is_self_contained_with_hash_version_verdict(analysed):
    html = (analysed["out"] / "report.html").read_text(encoding="utf-8")
    p = _Collector()
    p.feed(html)
    assert p.ids["verdict"].strip() == "FAIL"
    assert p.ids["version"] == glassdist.__version__
    sha = hashlib.sha256(analysed["image"].read_bytes()).hexdigest()
    assert sha in html and hashlib.sha256(analysed["ref"].read_bytes()).hexdigest() in html
    assert not p.links  # nothing external: no stylesheet, script or link to fetch
    names = {i["alt"] for i in p.imgs}
    assert {"input_region", "phi_eff", "phi_shear", "axis", "histograms", "mask_phi_eff_20mD"} <= names
    for img in p.imgs:
        assert img["src"].startswith("data:image/png;base64,")
        assert base64.b64decode(img["src"].split(",", 1)[1])[:4] == b"\x89PNG"
    data = json.loads(p.ids["glassdist-report-data"])
    assert data["inputs"]["image"]["sha256"] == sha
    assert data["verdict"]["result"] == "FAIL" and data["glassdist_version"] == glassdist.__version__
    assert data["pitch_mm"] == 2.0 and data["distance_m"] == 1.0
    for words in ("Capture geometry", "Comparative method", "p95 |phi_shear| &lt;= 5 mD", "strict"):
        assert words in html


def test_report_renders_in_headless_chromium(analysed, tmp_path):
    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        pytest.skip("headless rendering check needs chromium on PATH (e.g. apt-get install chromium)")
    shot = tmp_path / "report.png"
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             f"--user-data-dir={profile}", f"--screenshot={shot}", "--window-size=1200,2000",
             (analysed["out"] / "report.html").as_uri()],
            check=True, capture_output=True, timeout=120,
        )
    import cv2

    img = cv2.imread(str(shot))
    assert img is not None and img.shape[:2] == (2000, 1200)
    # The FAIL banner (light red, #ffd7d5) is drawn near the top of the page.
    top = img[:400].reshape(-1, 3).astype(int)
    banner = np.all(np.abs(top - np.array([0xD5, 0xD7, 0xFF])) <= 6, axis=1)  # BGR
    assert banner.sum() > 2000
    assert img.std() > 20  # text, tables and figures were drawn, not a blank page


def _report_data(html):
    p = _Collector()
    p.feed(html)
    return p, json.loads(p.ids["glassdist-report-data"])


def test_report_parameters_show_the_smoothing_used(analysed):
    # the parameters leave sigma_mm at its default (None = 2 carrier periods); the report shows the value used
    html = (analysed["out"] / "report.html").read_text(encoding="utf-8")
    _, data = _report_data(html)
    assert data["parameters"]["sigma_mm"] == data["sigma_mm"] == 4.0  # 2 carrier periods of the 2 mm grid
    assert '"sigma_mm": null' not in html and '&quot;sigma_mm&quot;: 4.0' in html


def test_direct_report_shows_the_homography_fit(analysed):
    from glassdist.acceptance.stats import result_statistics
    from glassdist.report.html import render_report

    result = glassdist.analyze(analysed["image"], pitch_mm=2.0, distance_m=1.0)  # the Direct Method
    fit = result.homography_fit
    assert 0.3 < fit.inlier_fraction <= 1.0 and fit.n_points > 100
    inputs = {"image": {"name": "pane.png", "sha256": "0" * 64, "size": "160 x 160 px"}, "reference": None}
    html = render_report(result, stats=result_statistics(result), figures=[], inputs=inputs)
    p, data = _report_data(html)
    assert data["homography_fit"]["n_points"] == fit.n_points
    assert data["homography_fit"]["inlier_fraction"] == pytest.approx(fit.inlier_fraction)
    assert data["homography_fit"]["rms_inlier_px"] == pytest.approx(fit.rms_inlier_px)
    words = p.ids["homography-fit"].split()
    assert words[0] == "inliers" and float(words[1]) == pytest.approx(100 * fit.inlier_fraction, abs=0.05)
    assert f"of {fit.n_points} grid points, RMS inlier reprojection error" in p.ids["homography-fit"]
    assert float(words[-2]) == pytest.approx(fit.rms_inlier_px, rel=0.01) and words[-1] == "px"
    # a Comparative report has no homography, hence no fit row
    comp = analysed["result"]
    html = render_report(comp, stats=result_statistics(comp), figures=[], inputs=inputs)
    assert 'id="homography-fit"' not in html and _report_data(html)[1]["homography_fit"] is None
