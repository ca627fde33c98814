"""Regenerate ``docs/user-guide/web_app.png``: the web application's result page in headless Chromium.

The job of the caption in ``docs/user-guide/web-app.md``: the factory example
(``examples/images/factory_pane.png`` with ``factory_reference.png`` and
``examples/factory/spec.json``, whose protocol pins the pitch, the distance, the pattern and the
analysis), pane ID F-001; the page at 1240 px, from the top to the end of the first row of maps.

Usage::

    python scripts/web_app_screenshot.py [--chromium /usr/bin/chromium] [--out docs/user-guide/web_app.png]

Needs ``glassdist[web]``, Playwright and a Chromium executable.
"""

from __future__ import annotations

import argparse
import shutil
import socket
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--chromium", default=shutil.which("chromium") or shutil.which("chromium-browser"))
    p.add_argument("--out", type=Path, default=REPO / "docs" / "user-guide" / "web_app.png")
    args = p.parse_args(argv)
    if not args.chromium:
        print("needs a chromium executable (--chromium)", file=sys.stderr)
        return 2
    import uvicorn
    from playwright.sync_api import sync_playwright

    from glassdist.web import create_app

    app = create_app(db="off")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    while not server.started:
        time.sleep(0.05)
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=args.chromium, args=["--headless", "--no-sandbox"])
            page = browser.new_page(viewport={"width": 1240, "height": 1000})
            page.goto(f"http://127.0.0.1:{port}/")
            page.set_input_files("#image", str(EXAMPLES / "images" / "factory_pane.png"))
            page.set_input_files("#reference", str(EXAMPLES / "images" / "factory_reference.png"))
            page.set_input_files("#spec", str(EXAMPLES / "factory" / "spec.json"))
            page.fill("#pane_id", "F-001")
            page.click("#submit")
            page.wait_for_selector("#verdict", timeout=600_000)
            page.wait_for_function("[...document.images].every(i => i.complete && i.naturalWidth > 0)")
            bottom = page.evaluate("document.querySelector('#fig-phi_shear').getBoundingClientRect().bottom"
                                   " + window.scrollY")
            page.screenshot(path=str(args.out), full_page=True,
                            clip={"x": 0, "y": 0, "width": 1240, "height": bottom + 16})
            browser.close()
    finally:
        server.should_exit = True
        thread.join(timeout=60)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
