"""The web application: uploads, limits and errors over HTTP, then end to end in headless Chromium."""

from __future__ import annotations

import html
import json
import shutil
import socket
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

pytest.importorskip("fastapi", reason="the web application needs glassdist[web]")
uvicorn = pytest.importorskip("uvicorn", reason="the web application needs glassdist[web]")

from glassdist.jobs.request import RecordAs  # noqa: E402
from glassdist.web import create_app  # noqa: E402
from glassdist.web._jobs import LABELS, form_language  # noqa: E402

#: The lens pair of :func:`conftest.write_lens_pair` reads p95 |phi_eff| = 38 mD (Comparative Method): this fails it.
STRICT = {"name": "site check", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 20}]}


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """A synthetic pane and its reference (160 x 160 px, 2 mm pitch, L = 1 m): ``pane.png``, ``reference.png``."""
    from conftest import write_lens_pair

    return write_lens_pair(tmp_path_factory.mktemp("pair"))


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """The application served by uvicorn in a thread on a free local port; yields (base URL, app)."""
    app = create_app(max_upload_mb=8)
    port = _free_port()
    srv = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=srv.run, daemon=True)
    thread.start()
    t0 = time.monotonic()
    while not srv.started:
        assert thread.is_alive() and time.monotonic() - t0 < 30, "the server did not start"
        time.sleep(0.05)
    yield f"http://127.0.0.1:{port}", app
    srv.should_exit = True
    thread.join(timeout=60)
    assert not app.state.store.root.exists()  # every job folder is removed when the server stops


def _wait(client, url, job_id, seconds=180):
    t0 = time.monotonic()
    while True:
        status = client.get(f"{url}/jobs/{job_id}/status").json()
        if status["state"] in ("done", "failed"):
            return status
        assert time.monotonic() - t0 < seconds, status
        time.sleep(0.2)


def test_errors_limits_and_no_path_traversal(server, pair, tmp_path):
    import httpx

    url, app = server
    with httpx.Client(timeout=60) as client:
        r = client.post(f"{url}/jobs", data={"pitch_mm": "5", "distance_m": "1"})
        assert r.status_code == 400 and "choose a photo of the grid" in r.text

        big = b"\x89PNG\r\n\x1a\n" + bytes(9 * 2**20)  # over the 8 MB limit of this server
        r = client.post(f"{url}/jobs", files={"image": ("big.png", big)}, data={"pitch_mm": "5", "distance_m": "1"})
        assert r.status_code == 413 and "larger than the 8 MB" in r.text
        assert len(list(app.state.store.root.iterdir())) == 0  # refused uploads leave nothing behind

        # a field value never becomes an option: the request reads it as its field's type, and refuses it in
        # the form's words (the field as the form names it; the value as typed, quoted, left as it is)
        before = len(app.state.store.recent())
        r = client.post(f"{url}/jobs", files={"image": ("pane.png", (pair / "reference.png").read_bytes())},
                        data={"pitch_mm": "--out=/tmp/x", "distance_m": "1"}, follow_redirects=False)
        assert r.status_code == 400 and len(app.state.store.recent()) == before
        assert "\u201cgrid pitch, mm\u201d: must be a number, got '--out=/tmp/x'" in html.unescape(r.text)
        # a client file name is never a path
        r = client.post(f"{url}/jobs", files={"image": ("../../evil.png", (pair / "reference.png").read_bytes())},
                        data={"pitch_mm": "-5", "distance_m": "1"}, follow_redirects=False)
        assert r.status_code == 303
        job_id = r.headers["location"].rsplit("/", 1)[1]
        status = _wait(client, url, job_id)
        assert status["state"] == "failed" and status["error"].count("\n") == 0
        # a range the analysis checks, as on the command line, in the form's words
        assert status["error"] == "\u201cgrid pitch, mm\u201d: must be positive, got -5.0"
        job = app.state.store.get(job_id)
        assert sorted(p.name for p in job.folder.iterdir()) == ["image.png"]
        assert not (tmp_path.parent / "evil.png").exists()
        for name in ("../image.png", "%2e%2e/image.png", "/etc/passwd", "summary.json"):
            assert client.get(f"{url}/jobs/{job_id}/files/{name}").status_code == 404
        assert client.get(f"{url}/jobs/nosuchjob").status_code == 404


def test_errors_speak_the_form_s_language(server, pair):
    """The required fields, missing: refused on the form (no job) without a specification, and by analyze with one
    that pins neither; both name the fields as the form's labels do, never an option or the command's help."""
    import httpx

    url, app = server
    pitch = f"\u201c{LABELS['pitch_mm']}\u201d"
    with httpx.Client(timeout=60) as client:
        page = client.get(url).text
        assert f'<label for="pitch_mm">{LABELS["pitch_mm"]}</label>' in page
        assert f'<label for="distance_m">{LABELS["distance_m"]}</label>' in page
        before = len(app.state.store.recent())
        r = client.post(f"{url}/jobs", files={"image": ("pane.png", (pair / "pane.png").read_bytes())},
                        data={"distance_m": "1"})
        assert r.status_code == 400 and len(app.state.store.recent()) == before
        assert f"fill in {pitch} (or choose an acceptance specification whose protocol pins it)" in r.text
        assert 'name="distance_m" value="1"' in r.text  # the form comes back as it was filled in

        r = client.post(f"{url}/jobs", files={"image": ("pane.png", (pair / "pane.png").read_bytes()),
                                              "spec": ("site.json", json.dumps(STRICT).encode())},
                        follow_redirects=False)
        assert r.status_code == 303
        status = _wait(client, url, r.headers["location"].rsplit("/", 1)[1])
        assert status["state"] == "failed"
        assert status["error"] == f"fill in {pitch} (or choose an acceptance specification whose protocol pins it)"


@pytest.mark.parametrize("line, expected", [
    (("glassdist analyze: error: the following arguments are required: --pitch-mm, --distance-m "
      "(see glassdist analyze --help)"),
     ("fill in \u201cgrid pitch, mm\u201d and \u201cglass-to-grid distance L, m\u201d (or choose an acceptance "
      "specification whose protocol pins them)")),
    (("glassdist analyze: error: --distance-m 3 contradicts the protocol of the specification "
      "'spec.json' (distance_m = 1 m); leave --distance-m out to use the specification's value"),
     ("\u201cglass-to-grid distance L, m\u201d = 3 contradicts the protocol of the specification 'site.json' "
      "(distance_m = 1 m); leave \u201cglass-to-grid distance L, m\u201d out to use the specification's value")),
    (("glassdist analyze: error: argument --distance-m: must be a number, got 'one' (see glassdist "
      "analyze --help)"),
     "\u201cglass-to-grid distance L, m\u201d: must be a number, got 'one'"),
    (("glassdist analyze: error: the reference 'reference.png' is the same photo as the image "
      "(identical pixels); give a photo of the grid taken without the glass, or leave out "
      "--reference (Direct Method)"),
     ("the reference 'my flat.png' is the same photo as the image (identical pixels); give a photo "
      "of the grid taken without the glass, or leave out \u201cglass-less reference\u201d (Direct Method)")),
    (("Direct Method with detrend degree 2: p95 |phi_eff| moves by -32% with --detrend-degree 3: "
      "calibrate the lens (--lens-photo, --camera-file) or use the Comparative Method"),
     ("Direct Method with detrend degree 2: p95 |phi_eff| moves by -32% with \u201cdetrend degree N\u201d = "
      "3: calibrate the lens (--lens-photo, --camera-file on the command line) or use the "
      "Comparative Method")),
    ("--camera-distance-m without --optics reflection; add --pattern=lines, or --sigma-mm 2.5.",
     ("\u201ccamera-to-pane distance C, m\u201d without \u201coptics\u201d = reflection; add \u201cpattern\u201d = lines, or "
      "\u201csmoothing sigma, mm\u201d = 2.5.")),
])
def test_form_language_of_analyze_lines(line, expected):
    names, display = {"reference": "reference.png", "spec": "spec.json"}, {"reference": "my flat.png", "spec": "site.json"}
    assert form_language(line, names, display) == expected


def _chromium():
    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        pytest.skip("the browser test needs chromium on PATH (e.g. apt-get install chromium)")
    pytest.importorskip("playwright.sync_api", reason="the browser test needs glassdist[browser-tests] (playwright)")
    return exe


@contextmanager
def _browser(exe):
    """Headless Chromium at ``exe`` (from :func:`_chromium`), closed on leaving."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--headless", "--no-sandbox", "--disable-gpu",
                                                               "--disable-background-networking"])
        try:
            yield browser
        finally:
            browser.close()


def _submit(page, url, files: dict, fields: dict, options: dict = ()) -> None:
    """Open the form at ``url``, attach ``files``, fill ``fields``, pick ``options`` (``{id: value}``), submit, and
    wait for the verdict."""
    page.goto(url)
    for key, path in files.items():
        page.set_input_files(f"#{key}", str(path))
    for key, value in fields.items():
        page.fill(f"#{key}", value)
    for key, value in dict(options).items():
        page.select_option(f"#{key}", value)
    page.click("#submit")
    page.wait_for_selector("#verdict", timeout=240_000)


#: For each image: its box, its container's inner box, its natural size and how it is fitted.
_IMAGE_BOXES = """imgs => imgs.map(i => {
  const b = i.getBoundingClientRect(), box = i.parentElement, c = box.getBoundingClientRect();
  return {src: i.getAttribute("src"), x: b.x, y: b.y, w: b.width, h: b.height, nw: i.naturalWidth, nh: i.naturalHeight,
          cx: c.x + box.clientLeft, cy: c.y + box.clientTop, cw: box.clientWidth, ch: box.clientHeight,
          fit: getComputedStyle(i).objectFit};
})"""


def _assert_whole(page, selector: str, *, fills: bool = True) -> int:
    """Every image ``selector`` matches is drawn whole: loaded, its box inside its container's inner box (which
    clips), and the picture drawn in it at its natural aspect ratio; ``fills``: as wide or as tall as the box (not
    a thumbnail in it). Returns how many."""
    page.wait_for_function(f"[...document.querySelectorAll({json.dumps(selector)})]"
                           ".every(i => i.complete && i.naturalWidth > 0)")
    boxes = page.eval_on_selector_all(selector, _IMAGE_BOXES)
    for b in boxes:
        assert b["x"] >= b["cx"] - 1 and b["y"] >= b["cy"] - 1, b
        assert b["x"] + b["w"] <= b["cx"] + b["cw"] + 1 and b["y"] + b["h"] <= b["cy"] + b["ch"] + 1, b  # not cut
        assert b["fit"] in ("fill", "contain"), b  # "cover" or "none" would crop
        scale = min(b["w"] / b["nw"], b["h"] / b["nh"]) if b["fit"] == "contain" else None
        drawn = (b["nw"] * scale, b["nh"] * scale) if scale else (b["w"], b["h"])
        assert drawn[0] / drawn[1] == pytest.approx(b["nw"] / b["nh"], rel=0.01), b
        assert not fills or drawn[0] >= 0.9 * b["cw"] or drawn[1] >= 0.9 * b["ch"], b
    return len(boxes)


def _assert_no_dead_link(page) -> int:
    """Every link on the page answers 200. Returns how many distinct links."""
    hrefs = set(page.eval_on_selector_all("a[href]", "links => links.map(a => a.href)"))
    for href in hrefs:
        assert page.request.get(href).status == 200, href
    return len(hrefs)


#: Each list box and its widest choice (measured on a copy left to size itself), and each text field and its hint.
_CONTROL_BOXES = """() => {
  const out = [];
  for (const sel of document.querySelectorAll("select")) {
    const copy = sel.cloneNode(true);
    Object.assign(copy.style, {width: "auto", minWidth: "0", maxWidth: "none", position: "absolute"});
    sel.parentElement.appendChild(copy);
    out.push({id: sel.id, kind: "select", need: copy.getBoundingClientRect().width,
              have: sel.getBoundingClientRect().width, scroll: sel.scrollWidth, client: sel.clientWidth});
    copy.remove();
  }
  const ctx = document.createElement("canvas").getContext("2d");
  for (const input of document.querySelectorAll("input[placeholder]")) {
    const s = getComputedStyle(input);
    ctx.font = `${s.fontStyle} ${s.fontWeight} ${s.fontSize} ${s.fontFamily}`;
    const pad = parseFloat(s.paddingLeft) + parseFloat(s.paddingRight);
    out.push({id: input.id, kind: "hint", need: ctx.measureText(input.placeholder).width,
              have: input.clientWidth - pad});
  }
  return out;
}"""


def _assert_controls_readable(page) -> int:
    """Every list box is at least as wide as it needs to show its longest choice whole, its text not scrolled; every
    text field's hint fits inside it. Returns how many controls were measured."""
    controls = page.evaluate(_CONTROL_BOXES)
    for c in controls:
        assert c["have"] >= c["need"] - 0.5, c
        if c["kind"] == "select":
            assert c["scroll"] <= c["client"], c
    return len(controls)


def test_form_controls_are_readable_in_headless_chromium(server):
    """The lists show their longest choice whole ('auto (from the photo)', not 'auto (from the ph'), the text fields
    their hints, on the form and on the history page; and the form's links all lead somewhere."""
    exe = _chromium()
    url, _ = server
    with _browser(exe) as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        page.goto(url)
        assert page.locator("#pattern option").first.inner_text() == "auto (from the photo)"
        assert _assert_controls_readable(page) >= 2 + 4  # pattern, optics; the hints of four fields
        _assert_no_dead_link(page)
        page.set_viewport_size({"width": 700, "height": 900})
        assert _assert_controls_readable(page) >= 2 + 4
        assert page.evaluate("document.documentElement.scrollWidth <= document.documentElement.clientWidth")
        page.goto(url + "/history")
        assert _assert_controls_readable(page) >= 1 + 8  # verdict; the filters' hints
        _assert_no_dead_link(page)


def test_upload_result_and_report_in_headless_chromium(server, pair, tmp_path):
    exe = _chromium()  # skips without chromium or playwright: checked before anything is imported
    url, _ = server
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(STRICT))
    with _browser(exe) as browser:
        page = browser.new_page(accept_downloads=True, viewport={"width": 1280, "height": 1000})
        page.goto(url)
        page.set_input_files("#image", str(pair / "pane.png"))
        page.set_input_files("#reference", str(pair / "reference.png"))
        page.set_input_files("#spec", str(spec))
        page.fill("#pitch_mm", "2")
        page.fill("#distance_m", "1")
        page.select_option("#pattern", "lines")
        page.fill("#detrend_degree", "2")
        page.fill("#pane_id", "north facade W12")
        page.check("#report")
        page.click("#submit")
        page.wait_for_selector("#progress, #verdict")  # the job page, polling its status
        page.wait_for_selector("#verdict", timeout=240_000)
        assert page.inner_text("#verdict") == "FAIL"
        assert "p95 |phi_eff| <= 20 mD" in page.inner_text("#checks")
        # every map whole in its box, the quality and uncertainty maps among them
        assert _assert_whole(page, ".zoom img") >= 8
        for name in ("phi_eff", "phi_shear", "axis", "quality", "uncertainty", "input_region", "histograms",
                     "mask_phi_eff_20mD"):
            assert page.locator(f"#fig-{name} img").count() == 1, name
        assert page.inner_text("#fig-mask_phi_eff_20mD figcaption").startswith("|phi_eff| over 20 mD")
        assert page.locator("#open-report").count() == 1 and page.locator("#no-report").count() == 0
        assert _assert_no_dead_link(page) >= 8 + 5
        with page.expect_download() as info:
            page.click("text=HTML report")
        report = Path(info.value.path()).read_text(encoding="utf-8")
        assert info.value.suggested_filename == "report.html"
        assert "FAIL" in report and "image.png" in report  # the upload's name in its job folder
        assert "north facade W12" in report
        page.goto(url)
        assert "pane.png" in page.inner_text("#jobs")  # recent jobs

        page.set_input_files("#image", files=[{"name": "notes.txt", "mimeType": "text/plain",
                                               "buffer": b"pitch 5 mm, distance 0.5 m"}])
        page.fill("#pitch_mm", "5")
        page.fill("#distance_m", "0.5")
        page.click("#submit")
        page.wait_for_selector("#error", timeout=120_000)
        error = page.inner_text("#error")
        assert "\n" not in error.strip() and "'notes.txt' has an unsupported extension '.txt'" in error


def test_direct_method_without_report_in_headless_chromium(server, pair):
    """A job without the report: no link to it (every link on the page answers), the maps whole, and the
    analyzer's warnings in the form's words (the detrend degree as the form's field, not as an option)."""
    exe = _chromium()
    url, app = server
    with _browser(exe) as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        _submit(page, url, {"image": pair / "pane.png"}, {"pitch_mm": "2", "distance_m": "1"})
        job = app.state.store.get(page.url.rsplit("/", 1)[1])
        assert "report.html" not in job.outputs()
        assert page.locator("#open-report").count() == 0 and page.locator("text=open the report").count() == 0
        assert LABELS["report"] in page.inner_text("#no-report")  # says how to get one, in the form's words
        _assert_no_dead_link(page)
        assert page.request.get(page.url + "/files/report.html").status == 404  # the link would have been dead
        assert _assert_whole(page, ".zoom img") >= 7
        shown = page.locator("#warnings li").all_inner_texts()
        written = job.summary()["warnings"]
        assert shown and len(shown) == len(written)
        assert any("--detrend-degree" in w for w in written)  # what the command line says ...
        assert not any("--detrend-degree" in w for w in shown)  # ... the page says in its own words
        assert any(f"\u201c{LABELS['detrend_degree']}\u201d = 3" in w for w in shown)
        page.set_viewport_size({"width": 700, "height": 900})  # a narrow window: the maps shrink, whole, no side-scroll
        assert _assert_whole(page, ".zoom img") >= 7
        assert page.evaluate("document.documentElement.scrollWidth <= document.documentElement.clientWidth")


def test_errors_in_headless_chromium(server, pair):
    """The photo alone: the page names the missing fields by their labels as shown, on one line inside its box."""
    exe = _chromium()
    url, _ = server
    with _browser(exe) as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        page.goto(url)
        page.set_input_files("#image", str(pair / "pane.png"))
        page.click("#submit")
        page.wait_for_selector("#error")
        error = page.inner_text("#error")
        for key in ("pitch_mm", "distance_m"):
            assert f"\u201c{page.inner_text(f'label[for={key}]')}\u201d" in error
        assert "--" not in error and "help" not in error
        box = page.evaluate("(e => ({s: e.scrollWidth, c: e.clientWidth}))(document.getElementById('error'))")
        assert box["s"] <= box["c"]


def test_contract_spec_with_the_form_as_it_loads_in_headless_chromium(server, pair, tmp_path):
    """A contract specification whose protocol pins the capture, and the photo, nothing else touched: the pinned
    fields are shown as pinned and not sent, the empty ones not sent either, and the verdict page comes back."""
    exe = _chromium()
    url, app = server
    protocol = {"method": "direct", "distance_m": 1.0, "pitch_mm": 2.0, "pattern": "lines", "sigma_periods": 2,
                "detrend_degree": 3}
    spec = tmp_path / "contract.json"
    spec.write_text(json.dumps({"name": "contract", "protocol": protocol, "criteria": [
        {"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 1}]}))
    with _browser(exe) as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        page.goto(url)
        # report and export opt-in, their cost stated; the kept jobs' budget stated
        assert not page.is_checked("#report") and not page.is_checked("#export")
        assert "1.9 GB" in page.inner_text("#job-form") and "2048 MB" in page.inner_text("#kept")
        page.set_input_files("#image", str(pair / "pane.png"))
        page.set_input_files("#spec", str(spec))
        page.wait_for_function("document.getElementById('pitch_mm').disabled")
        for key in ("pitch_mm", "distance_m", "pattern", "detrend_degree"):
            assert page.is_disabled(f"#{key}")
            value = protocol[key]
            shown = f"{value:g}" if isinstance(value, float) else str(value)
            assert f"pinned by the specification: {shown}" in page.inner_text(f"#pin-{key}")
        assert page.is_disabled("#sigma_mm") and "carrier periods" in page.inner_text("#pin-sigma_mm")
        assert page.eval_on_selector("#pattern", "s => s.options[s.selectedIndex].text") == "lines"  # the pinned one
        _assert_controls_readable(page)  # a pinned list still shows its choice whole
        page.click("#submit")
        page.wait_for_selector("#verdict", timeout=240_000)
        assert page.inner_text("#verdict") == "FAIL"
        job = app.state.store.get(page.url.rsplit("/", 1)[1])
        # only the photo, the specification and the output folder: no field, no report, no export
        assert job.request.options() == ["analyze", "--spec=spec.json", "--out=out", "--", "image.png"]
        assert job.request.record_as == RecordAs(source="web", job=job.id)  # recorded as this web job
        assert not any(n.startswith(("report", "fields", "tiff")) for n in job.outputs())


def test_reflection_in_headless_chromium(server, tmp_path):
    """The form's optics field: a concave mirror (R = 20 m, board at 1.997 m, camera in the board plane) rendered
    in reflection reads -4000/R = -200 mD, and the job page names the reflection geometry and shows the front
    face's height and slope maps."""
    from glassdist.io import write_png16
    from glassdist.render import render_scene
    from glassdist.scene import scene_from_dict

    exe = _chromium()
    sag = 20000.0 - (20000.0**2 - 1500.0**2) ** 0.5
    scene = scene_from_dict({
        "pane": {"size_mm": [2400, 1600], "thickness_mm": 6, "refractive_index": 1.52, "deformation": {"both": [
            {"kind": "spherical_cap", "radius_mm": 20000.0, "aperture_mm": 1500.0}, {"kind": "plane", "offset_mm": -sag}]}},
        "backdrop": {"pattern": "lines", "pitch_mm": 12, "line_width_mm": 3, "distance_m": 2},
        "camera": {"focal_length_mm": 160, "sensor_width_mm": 36, "pixels": [256, 192], "position_mm": [0, 0, -2000]},
        "viewing": {"mode": "reflection"}})
    write_png16(tmp_path / "pane.png", render_scene(scene))
    write_png16(tmp_path / "flat.png", render_scene(scene, reference=True))
    url, _ = server
    with _browser(exe) as browser:
        page = browser.new_page()
        _submit(page, url, {"image": tmp_path / "pane.png", "reference": tmp_path / "flat.png"},
                {"pitch_mm": "12", "distance_m": "1.997", "detrend_degree": "0"}, {"optics": "reflection"})
        assert "reflective power on the pane" in page.inner_text("#optics")
        summary = page.request.get(page.url + "/files/summary.json").json()
        assert summary["optics"]["optics"] == "reflection"
        assert summary["statistics"]["phi_eff_mD"]["mean"] == pytest.approx(-200.0, rel=0.02)
        for name in ("surface_height.png", "surface_slope.png"):  # the flatness figures beside the power figures
            assert page.locator(f'img[src$="{name}"]').count() == 1


def test_kept_jobs_have_a_disk_budget(tmp_path):
    """The oldest finished jobs go while the kept ones take more than max_disk_mb; the newest always stays."""
    from glassdist.web._jobs import JobStore

    store = JobStore(tmp_path / "jobs", max_jobs=10, max_disk_mb=2.5)
    jobs = []
    for i in range(4):
        job = store.new_job()
        (job.folder / "out.bin").write_bytes(bytes(1 << 20))  # 1 MB each
        job.state, job.created = "done", 1000.0 + i
        store._jobs[job.id] = job
        jobs.append(job)
    with store._lock:
        store._evict()
    assert [j.id for j in store.recent()] == [jobs[3].id, jobs[2].id]  # 2 MB kept, under 2.5 MB
    assert not jobs[0].folder.exists() and not jobs[1].folder.exists() and jobs[2].folder.exists()
    assert store.disk_bytes() == 2 << 20
    store.close()


def test_the_browser_test_skips_without_playwright(monkeypatch, tmp_path):
    """Without glassdist[browser-tests] the browser test is skipped, not failed (nothing else is touched)."""
    for name in ("playwright", "playwright.sync_api"):
        monkeypatch.setitem(sys.modules, name, None)  # importing it raises ImportError
    with pytest.raises(pytest.skip.Exception):
        test_upload_result_and_report_in_headless_chromium(None, None, tmp_path)


def test_a_server_reachable_from_elsewhere_says_so(capsys, monkeypatch):
    from fastapi.testclient import TestClient

    import glassdist.web._app as web_app

    with TestClient(create_app(public_host="0.0.0.0:8000")) as client:
        assert 'id="public-warning"' in client.get("/").text
    with TestClient(create_app()) as client:
        assert 'id="public-warning"' not in client.get("/").text
    monkeypatch.setattr("uvicorn.run", lambda app, **kw: None)  # serve() without serving
    web_app.serve("0.0.0.0", 8123)
    err = capsys.readouterr().err
    assert "warning: listening on 0.0.0.0:8123, reachable from other machines" in err
    web_app.serve("127.0.0.1", 8123)
    assert "warning" not in capsys.readouterr().err


def test_history_page_filters_by_lot_shows_the_chart_and_links_kept_jobs(server, tmp_path, monkeypatch):
    """Runs recorded before (lots A and B) and a job run from the page (lot A): the page filtered by lot A."""
    from conftest import write_lens_pair
    from glassdist.history import open_store
    from glassdist.history.store import insert_runs, run_rows

    exe = _chromium()
    url, _ = server
    monkeypatch.setenv("GLASSDIST_DB", str(tmp_path / "history.sqlite"))  # read by the page and the jobs alike
    values = {"A": [10.0, 11.0, 10.5, 10.2, 30.0, 10.4], "B": [50.0, 51.0]}
    with open_store(write=True) as store:
        insert_runs(store, [run_rows({"metadata": {"pane_id": f"{lot}{i}", "lot": lot},
                                      "a4": {"statistics": {"phi_eff": {"p95_abs": v}}}}, exit_code=0, out_dir=tmp_path)
                            for lot, vs in values.items() for i, v in enumerate(vs)])
    pane = write_lens_pair(tmp_path)
    with _browser(exe) as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 1000})
        _submit(page, url, {"image": pane / "pane.png", "reference": pane / "reference.png"},
                {"pitch_mm": "2", "distance_m": "1", "pane_id": "W-1", "lot": "A"})
        job_url = page.url
        page.click("#nav-history")
        assert "9 run(s)" in page.inner_text("#history-count")
        page.fill("#f-lot", "A")
        page.click("#filter")
        page.wait_for_selector("#trend-chart")
        assert "7 run(s)" in page.inner_text("#history-count")
        lots = page.eval_on_selector_all("#history tr td:nth-child(4)", "tds => tds.map(t => t.textContent)")
        assert lots == ["A"] * 7
        assert page.evaluate("document.querySelector('#trend-chart').naturalWidth") > 300  # the chart loaded
        assert _assert_whole(page, "#trend-chart", fills=False) == 1  # shown whole, whatever its size
        assert page.inner_text("#value-unit") == "mD" and "value (mD)" in page.inner_text("#history tr >> nth=0")
        panes = page.eval_on_selector_all("#history tr td:nth-child(3)", "tds => tds.map(t => t.textContent)")
        assert panes[:6] == [f"A{i}" for i in range(6)] and panes[6] == "W-1"
        chart = page.request.get(url + page.locator("#trend-chart").get_attribute("src"))
        assert chart.ok and chart.headers["content-type"] == "image/png"
        link = page.locator("#history a[href^='/jobs/']")
        assert link.count() == 1  # the web job, kept by the server: its page
        link.click()
        page.wait_for_selector("#verdict")
        assert page.url == job_url
