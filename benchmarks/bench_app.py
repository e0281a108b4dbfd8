"""The app's latency in a real browser (headless Chromium + Playwright), on double_bridge.

    make bench        (or: .venv/bin/python benchmarks/bench_app.py)

click-to-path: from the click on Plan to the "Path found" status on the page (the plan runs in
a fresh child process; the path is drawn in the same update). Round trip: a value typed in the
page reaching the server, plus a status the server sets reaching the page; measured idle and
while a 20-trial batch runs on all cores. Targets (issue 8): click-to-path <= 1 s; the server
stays responsive during a batch.
"""

from __future__ import annotations

import re
import shutil
import socket
import statistics
import time

from roachplan.app._server import RoachApp
from roachplan.scenes import build_world, load_scene


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def round_trip(app: RoachApp, page, k: int) -> float:
    """Type K into the page until the server has it, then show a status until the page has it."""
    box = (
        page.locator("xpath=//label[text()='Paths (K)']/ancestor::div[.//input][1]")
        .locator("input")
        .last
    )
    value = 1 + k % 2
    t0 = time.perf_counter()
    box.fill(str(value))
    box.press("Enter")
    while int(app.count.value) != value:
        time.sleep(0.001)
    app.title.content = f"ping {k}"  # the title: nothing else writes it during a batch
    page.get_by_text(f"ping {k}", exact=True).wait_for(timeout=30_000)
    return time.perf_counter() - t0


def main() -> None:
    from playwright.sync_api import sync_playwright

    world = build_world(load_scene("double_bridge"))
    world.regions  # noqa: B018
    app = RoachApp(world, host="127.0.0.1", port=free_port())
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=shutil.which("chromium"),
                                         args=["--no-sandbox", "--disable-gpu"])  # fmt: skip
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.goto(f"http://127.0.0.1:{app.port}")
            plan = page.get_by_role("button", name="Plan")
            plan.wait_for(timeout=60_000)
            latencies = []
            for k in range(6):
                t0 = time.perf_counter()
                plan.click()
                page.get_by_text(re.compile(rf"Path found in .*seed {k}\)")).wait_for(
                    timeout=60_000
                )
                latencies.append(time.perf_counter() - t0)
            idle = [round_trip(app, page, k) for k in range(10)]
            row = page.locator("xpath=//label[text()='Trials (N)']/ancestor::div[.//input][1]")
            row.locator("input").last.fill("20")
            row.locator("input").last.press("Enter")
            page.get_by_role("button", name="Run trials").click()
            page.get_by_text(re.compile(r"/20 trials, \d+ successes, ETA")).wait_for(
                timeout=120_000
            )
            busy = [round_trip(app, page, 100 + k) for k in range(10)]
            page.get_by_text(re.compile(r"Batch finished: 20/20")).wait_for(timeout=600_000)
            browser.close()
    finally:
        app.stop()
    print("click-to-path, each [s]:", " ".join(f"{v:.2f}" for v in latencies))
    med = statistics.median
    print(f"click-to-path on double_bridge: median {med(latencies):.3f} s, max "
          f"{max(latencies):.3f} s over {len(latencies)} plans (target <= 1 s; "
          f"{1.0 / med(latencies):.1f}x under)")  # fmt: skip
    print(f"GUI round trip idle: median {med(idle) * 1e3:.0f} ms, max {max(idle) * 1e3:.0f} ms")
    print(f"GUI round trip during a 20-trial batch: median {med(busy) * 1e3:.0f} ms, max "
          f"{max(busy) * 1e3:.0f} ms ({med(busy) / med(idle):.1f}x idle)")  # fmt: skip


if __name__ == "__main__":
    main()
