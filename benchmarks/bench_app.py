"""The app's latency in a real browser (headless Chromium + Playwright), on double_bridge.

    make bench        (or: .venv/bin/python benchmarks/bench_app.py)

click-to-path: from the click on Plan to the "Path found" status on the page (the plan runs in
a fresh child process; the path is drawn in the same update), the first click (as soon as the
page shows its Plan button) apart from the median. Drive playback: during a drive at 1x real
time, the frames the page draws (requestAnimationFrame callbacks) and the messages the server
sends it (robot poses, the trajectory line, the status) per second. Round trip: a value typed
in the page reaching the server, plus a status the server sets reaching the page; measured idle
and while a 20-trial batch runs on all cores. Targets (issues 8, 16): click-to-path <= 1 s, the
first click included; the server stays responsive during a batch. The machine's load average
is printed with the figures: other work on its cores slows every number here.

    --no-batch    skip the batch part (the round trip during a batch)
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import statistics
import sys
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


COUNTERS = """
window.__frames = 0;
const tick = () => { window.__frames += 1; requestAnimationFrame(tick); };
requestAnimationFrame(tick);
"""
"""The frames the page draws: requestAnimationFrame callbacks (one per frame the browser
presents; a page busy drawing its 3D view in software WebGL runs them seldom)."""


def count_messages(page) -> list[int]:
    """[n]: the websocket messages the page has received so far, counted as they arrive (viser
    batches the scene and panel updates of one server tick into a message; its socket lives in
    a worker, where a page script cannot count, so Playwright does)."""
    n = [0]

    def on_socket(ws) -> None:
        ws.on("framereceived", lambda _: n.__setitem__(0, n[0] + 1))

    page.on("websocket", on_socket)
    return n


def click_to_path(app: RoachApp, page) -> float:
    """Click Plan; seconds until the page shows the path found from a seed not used before."""
    plan = page.get_by_role("button", name="Plan")
    seeds = "|".join(str(s) for s in range(app.core.next_seed, app.core.next_seed + 40))
    found = page.get_by_text(re.compile(rf"Path found in .*\(seed ({seeds})\)"))
    t0 = time.perf_counter()
    plan.click()
    found.wait_for(timeout=60_000)
    return time.perf_counter() - t0


def drive_playback(app: RoachApp, page, messages: list[int]) -> tuple[float, float, float]:
    """Drive the planned path at 1x real time: (frames drawn per second, messages received per
    second, wall time of the drive [s]), from the click on Drive to the trial's record."""
    n = len(app.scene_trials) + 1
    f0, m0 = page.evaluate("window.__frames"), messages[0]
    t0 = time.perf_counter()
    page.get_by_role("button", name="Drive").click()
    page.get_by_text(re.compile(rf"Trial {n}: ")).wait_for(timeout=300_000)
    wall = time.perf_counter() - t0
    f1, m1 = page.evaluate("window.__frames"), messages[0]
    return (f1 - f0) / wall, (m1 - m0) / wall, wall


def round_trips_in_a_batch(app: RoachApp, page) -> list[float]:
    """GUI round trips while a 20-trial batch runs on all cores (it is waited for to end)."""
    row = page.locator("xpath=//label[text()='Trials (N)']/ancestor::div[.//input][1]")
    row.locator("input").last.fill("20")
    row.locator("input").last.press("Enter")
    page.get_by_role("button", name="Run trials").click()
    page.get_by_text(re.compile(r"/20 trials, \d+ successes, ETA")).wait_for(timeout=120_000)
    busy = [round_trip(app, page, 100 + k) for k in range(10)]
    page.get_by_text(re.compile(r"Batch finished: 20/20")).wait_for(timeout=600_000)
    return busy


def main() -> None:
    from playwright.sync_api import sync_playwright

    batch = "--no-batch" not in sys.argv[1:]
    load_before = os.getloadavg()

    world = build_world(load_scene("double_bridge"))
    world.regions  # noqa: B018
    app = RoachApp(world, host="127.0.0.1", port=free_port())
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(
                executable_path=shutil.which("chromium"), args=["--no-sandbox", "--disable-gpu"]
            )
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.add_init_script(COUNTERS)
            received = count_messages(page)
            page.goto(f"http://127.0.0.1:{app.port}")
            page.get_by_role("button", name="Plan").wait_for(timeout=60_000)
            latencies = [click_to_path(app, page) for _ in range(6)]
            fps, messages, drive_wall = drive_playback(app, page, received)
            idle = [round_trip(app, page, k) for k in range(10)]
            busy = [] if not batch else round_trips_in_a_batch(app, page)
            browser.close()
    finally:
        app.stop()
    report(
        latencies,
        idle,
        busy,
        fps=fps,
        messages=messages,
        drive_wall=drive_wall,
        load_before=load_before,
    )


def report(latencies, idle, busy, *, fps, messages, drive_wall, load_before) -> None:
    med = statistics.median
    print("click-to-path, each [s]:", " ".join(f"{v:.2f}" for v in latencies))
    print(
        f"click-to-path on double_bridge: median {med(latencies):.3f} s, first click "
        f"{latencies[0]:.3f} s, max {max(latencies):.3f} s over {len(latencies)} plans "
        f"(target <= 1 s, the first included)"
    )
    print(
        f"drive playback at 1x (software WebGL): {fps:.1f} frames/s drawn, {messages:.1f} "
        f"server messages/s received, over a {drive_wall:.1f} s drive"
    )
    print(f"GUI round trip idle: median {med(idle) * 1e3:.0f} ms, max {max(idle) * 1e3:.0f} ms")
    if busy:
        print(
            f"GUI round trip during a 20-trial batch: median {med(busy) * 1e3:.0f} ms, max "
            f"{max(busy) * 1e3:.0f} ms ({med(busy) / med(idle):.1f}x idle)"
        )
    after = os.getloadavg()
    print(
        f"machine: {os.cpu_count()} cores, load average (1 min) {load_before[0]:.2f} before, "
        f"{after[0]:.2f} after"
    )


if __name__ == "__main__":
    main()
