"""The web application: uploads, limits and errors over HTTP, then end to end in headless Chromium."""

from __future__ import annotations

import json
import shutil
import socket
import sys
import threading
import time
from pathlib import Path

import pytest

pytest.importorskip("fastapi", reason="the web application needs glassdist[web]")
uvicorn = pytest.importorskip("uvicorn", reason="the web application needs glassdist[web]")

from glassdist.web import create_app  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "examples" / "data"
STRICT = {"name": "site check", "criteria": [{"channel": "phi_eff", "statistic": "p95_abs", "max_mD": 40}]}


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


def test_errors_limits_and_no_path_traversal(server, tmp_path):
    import httpx

    url, app = server
    with httpx.Client(timeout=60) as client:
        r = client.post(f"{url}/jobs", data={"pitch_mm": "5", "distance_m": "1"})
        assert r.status_code == 400 and "choose a photo of the grid" in r.text

        big = b"\x89PNG\r\n\x1a\n" + bytes(9 * 2**20)  # over the 8 MB limit of this server
        r = client.post(f"{url}/jobs", files={"image": ("big.png", big)}, data={"pitch_mm": "5", "distance_m": "1"})
        assert r.status_code == 413 and "larger than the 8 MB" in r.text
        assert len(list(app.state.store.root.iterdir())) == 0  # refused uploads leave nothing behind

        # a client file name is never a path; a field value never becomes an option
        r = client.post(f"{url}/jobs", files={"image": ("../../evil.png", (DATA / "reference.png").read_bytes())},
                        data={"pitch_mm": "--out=/tmp/x", "distance_m": "1"}, follow_redirects=False)
        assert r.status_code == 303
        job_id = r.headers["location"].rsplit("/", 1)[1]
        status = _wait(client, url, job_id)
        assert status["state"] == "failed" and status["error"].count("\n") == 0
        assert "argument --pitch-mm: must be a number, got '--out=/tmp/x'" in status["error"]
        job = app.state.store.get(job_id)
        assert sorted(p.name for p in job.folder.iterdir()) == ["image.png"]
        assert not (tmp_path.parent / "evil.png").exists()
        for name in ("../image.png", "%2e%2e/image.png", "/etc/passwd", "summary.json"):
            assert client.get(f"{url}/jobs/{job_id}/files/{name}").status_code == 404
        assert client.get(f"{url}/jobs/nosuchjob").status_code == 404


def _chromium():
    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        pytest.skip("the browser test needs chromium on PATH (e.g. apt-get install chromium)")
    pytest.importorskip("playwright.sync_api", reason="the browser test needs glassdist[browser-tests] (playwright)")
    return exe


def test_upload_result_and_report_in_headless_chromium(server, tmp_path):
    exe = _chromium()  # skips without chromium or playwright: checked before anything is imported
    from playwright.sync_api import sync_playwright

    url, _ = server
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps(STRICT))
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--headless", "--no-sandbox", "--disable-gpu",
                                                               "--disable-background-networking"])
        try:
            page = browser.new_page(accept_downloads=True, viewport={"width": 1280, "height": 1000})
            page.goto(url)
            page.set_input_files("#image", str(DATA / "distorted_waves.bmp"))
            page.set_input_files("#reference", str(DATA / "reference.png"))
            page.set_input_files("#spec", str(spec))
            page.fill("#pitch_mm", "5")
            page.fill("#distance_m", "0.5")
            page.select_option("#pattern", "checkerboard")
            page.fill("#detrend_degree", "3")
            page.fill("#pane_id", "north facade W12")
            page.click("#submit")
            page.wait_for_selector("#progress, #verdict")  # the job page, polling its status
            page.wait_for_selector("#verdict", timeout=240_000)
            assert page.inner_text("#verdict") == "FAIL"
            assert "p95 |phi_eff| <= 40 mD" in page.inner_text("#checks")
            summary = page.request.get(page.url + "/files/summary.json").json()
            assert summary["warnings"] and all(w in page.inner_text("#warnings") for w in summary["warnings"])
            assert page.locator(".zoom img").count() >= 4
            assert page.evaluate("document.querySelector('.zoom img').naturalWidth") > 100  # the heatmap loaded
            with page.expect_download() as info:
                page.click("text=HTML report")
            report = Path(info.value.path()).read_text(encoding="utf-8")
            assert info.value.suggested_filename == "report.html"
            assert "FAIL" in report and "image.bmp" in report  # the upload's name in its job folder
            assert "north facade W12" in report
            page.goto(url)
            assert "distorted_waves.bmp" in page.inner_text("#jobs")  # recent jobs

            page.set_input_files("#image", files=[{"name": "notes.txt", "mimeType": "text/plain",
                                                   "buffer": b"pitch 5 mm, distance 0.5 m"}])
            page.fill("#pitch_mm", "5")
            page.fill("#distance_m", "0.5")
            page.click("#submit")
            page.wait_for_selector("#error", timeout=120_000)
            error = page.inner_text("#error")
            assert "\n" not in error.strip() and "'notes.txt' has an unsupported extension '.txt'" in error
        finally:
            browser.close()


@pytest.mark.filterwarnings("ignore:Using `httpx` with `starlette.testclient`")
def test_the_browser_test_skips_without_playwright(monkeypatch, tmp_path):
    """Without glassdist[browser-tests] the browser test is skipped, not failed (nothing else is touched)."""
    for name in ("playwright", "playwright.sync_api"):
        monkeypatch.setitem(sys.modules, name, None)  # importing it raises ImportError
    with pytest.raises(pytest.skip.Exception):
        test_upload_result_and_report_in_headless_chromium(None, tmp_path)


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
