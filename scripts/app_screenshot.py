"""The README's screenshot (docs/app.png): the app on `double_bridge` in headless Chromium,
after Plan and part of a Drive, so the terrain, the roach, the planned path (black) and the
driven trajectory (blue) are all in view. Regenerated on purpose only:

    .venv/bin/python scripts/app_screenshot.py [-o docs/app.png] [--drive-s 8] [--zoom 8]
"""

from __future__ import annotations

import argparse
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# The launch arguments the browser tests use on this machine (tests/test_app.py).
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_http(url: str, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            urllib.request.urlopen(url, timeout=2).close()
            return
        except OSError:
            time.sleep(0.5)
    raise SystemExit(f"the app did not answer at {url} within {seconds:.0f} s")


def main() -> int:
    parser = argparse.ArgumentParser(description="The README's screenshot (docs/app.png).")
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "app.png"))
    parser.add_argument("--drive-s", type=float, default=8.0, help="seconds of Drive to show")
    parser.add_argument("--zoom", type=int, default=8, help="mouse-wheel steps towards the bridge")
    args = parser.parse_args()
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium is not installed (make test installs it)")
    from playwright.sync_api import sync_playwright

    port = free_port()
    url = f"http://127.0.0.1:{port}"
    roachplan = Path(sys.executable).parent / "roachplan"
    cmd = [str(roachplan), "serve", "--scene", "double_bridge", "--port", str(port)]
    server = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_for_http(url, 60)
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=ARGS)
            page = browser.new_context(viewport={"width": 1280, "height": 800}).new_page()
            page.goto(url)
            plan = page.get_by_role("button", name="Plan")
            plan.wait_for(timeout=60_000)
            page.wait_for_timeout(3000)  # the terrain's first frames
            plan.click()
            page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
            # Software WebGL's warning would cover the top left of the view.
            close = page.locator(".mantine-Notification-closeButton")
            if close.count():
                close.first.click()
            page.mouse.move(560, 470)
            for _ in range(args.zoom):
                page.mouse.wheel(0, -100)
                page.wait_for_timeout(150)
            page.get_by_role("button", name="Drive").click()
            page.wait_for_timeout(int(args.drive_s * 1000))
            page.screenshot(path=args.output)
            browser.close()
    finally:
        server.terminate()
        server.wait(timeout=30)
    print(args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
