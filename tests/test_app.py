"""The whole app in headless Chromium: loading files, placing markers, batches, results export,
two browsers at once. Screenshots go to test-artifacts/."""

from __future__ import annotations

import re
import shutil
from contextlib import contextmanager

import numpy as np
import pytest

from conftest import ROOT, free_port

CHROMIUM = shutil.which("chromium")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed")
ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
]


@contextmanager
def browser_pages(url: str, n: int = 1):
    """n pages, each in its own browser context (its own session), failing on page errors."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        errors: list[str] = []
        pages = []
        for _ in range(n):
            page = browser.new_context(viewport={"width": 1280, "height": 900}).new_page()
            page.on("pageerror", lambda exc: errors.append(str(exc)))
            page.goto(url)
            page.get_by_role("button", name="Plan").wait_for(timeout=60_000)
            pages.append(page)
        yield pages
        browser.close()
        assert not errors, f"page errors: {errors}"


def upload(page, path) -> None:
    with page.expect_file_chooser() as chooser:
        page.get_by_role("button", name="Load file").click()
    chooser.value.set_files(str(path))


def set_value(page, label: str, value: str) -> None:
    """Type into the number box of the GUI row labelled `label` (sliders have one too)."""
    row = page.locator(f"xpath=//label[text()='{label}']/ancestor::div[.//input][1]")
    box = row.locator("input").last
    box.fill(value)
    box.press("Enter")


def title(page) -> str:
    return page.get_by_text(re.compile(r"roachplan — scene")).inner_text()


def test_upload_a_capture_and_the_terrain_changes(server_url, artifacts):
    capture = ROOT / "scenes" / "library" / "kinect_bridge_depth.png"
    with browser_pages(server_url) as (page,):
        assert "double_bridge" in title(page)
        set_value(page, "Voxel [m]", "0.02")  # (a lighter mesh for software WebGL)
        upload(page, capture)  # a depth PNG: meshed with the page's camera preset (QHD)
        page.get_by_text(re.compile(r"Loaded kinect_bridge_depth")).wait_for(timeout=120_000)
        assert "kinect_bridge_depth" in title(page)
        page.get_by_text("Start and goal are valid.").wait_for(timeout=10_000)
        page.screenshot(path=artifacts / "app-01-capture-loaded.png")
        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
        page.screenshot(path=artifacts / "app-02-capture-planned.png")


def test_a_broken_file_gives_an_error_and_the_scene_stays(server_url, artifacts, tmp_path):
    broken = tmp_path / "broken.pcd"
    broken.write_bytes(b"\x00\x01 this is not a point cloud")
    with browser_pages(server_url) as (page,):
        upload(page, broken)
        page.get_by_text(re.compile(r"not a PCD file")).wait_for(timeout=60_000)
        page.screenshot(path=artifacts / "app-03-broken-upload.png")
        assert "double_bridge" in title(page)
        assert page.get_by_text(re.compile(r"the scene double_bridge stays")).count() == 1
        # ... and the server still serves: a plan works.
        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)


def test_scene_picker_switches_scenes(server_url, artifacts):
    with browser_pages(server_url) as (page,):
        page.locator("input[value='double_bridge']").first.click()
        page.get_by_role("option", name="heightmap").click()
        page.get_by_text(re.compile(r"Loaded heightmap")).first.wait_for(timeout=120_000)
        assert "heightmap" in title(page)
        page.screenshot(path=artifacts / "app-04-heightmap.png")


def test_two_browsers_plan_and_drive_at_once(server_url, artifacts):
    with browser_pages(server_url, n=2) as (a, b):
        for page in (a, b):
            set_value(page, "Playback speed [x real time]", "10")
        a.get_by_role("button", name="Plan").click()
        b.get_by_role("button", name="Plan").click()
        a.get_by_text(re.compile(r"Path found in .*seed 1\)")).wait_for(timeout=60_000)
        a.get_by_role("button", name="Drive").click()
        b.get_by_role("button", name="Drive").click()
        for page in (a, b):
            page.get_by_text(re.compile(r"Trial 2: ")).wait_for(timeout=180_000)
        for k, page in enumerate((a, b)):
            page.screenshot(path=artifacts / f"app-05-two-browsers-{k}.png")
            rows = page.locator("table").first.get_by_role("row")
            assert rows.count() == 3, "header and the two trials, in both browsers"


def test_batch_of_trials_with_progress_then_export(server_url, artifacts, tmp_path):
    with browser_pages(server_url) as (page,):
        set_value(page, "Trials (N)", "4")
        set_value(page, "Workers", "2")
        page.get_by_role("button", name="Run trials").click()
        page.get_by_text(re.compile(r"\d/4 trials, \d successes, ETA")).wait_for(timeout=120_000)
        page.screenshot(path=artifacts / "app-06-batch-running.png")
        page.get_by_text(re.compile(r"Batch finished: 4/4 trials")).wait_for(timeout=180_000)
        page.screenshot(path=artifacts / "app-07-batch-done.png")
        rows = page.locator("table").first.get_by_role("row")
        assert rows.count() == 5
        # The per-route summary counts the same trials.
        summary = page.locator("table").nth(1).inner_text()
        assert re.search(r"number of trials\s+\d", summary)
        n = sum(int(v) for v in re.findall(r"number of trials((?:\s+\d+)+)", summary)[0].split())
        assert n == 4
        with page.expect_download() as dl:
            page.get_by_role("button", name="Export CSV").click()
        path = tmp_path / "trials.csv"
        dl.value.save_as(path)
        lines = path.read_text().splitlines()
        assert lines[0].startswith("trial,label,scene,seed") and len(lines) == 5
        assert all(line.split(",")[1] == "batch" for line in lines[1:])
        # Best path re-drives the cheapest success.
        set_value(page, "Playback speed [x real time]", "10")
        page.get_by_role("button", name="Best path").click()
        page.get_by_text(re.compile(r"Trial 5: ")).wait_for(timeout=120_000)
        assert "best (trial" in page.locator("table").first.inner_text()


def test_click_places_the_start_and_invalid_markers_say_why(artifacts):
    """In-process server: a click on the terrain (viser's ray, intersected with the terrain) moves
    the start; a start dragged into the gap is shown invalid with the failed condition."""
    from roachplan.app._commands import MarkersCmd
    from roachplan.app._server import RoachApp
    from roachplan.scenes import build_world, load_scene

    app = RoachApp(build_world(load_scene("double_bridge")), host="127.0.0.1", port=free_port())
    try:
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            page.locator("input[value='nothing']").first.click()
            page.get_by_role("option", name="start").click()
            page.wait_for_timeout(500)
            page.mouse.click(480, 450)  # the middle of the 3D view: the terrain
            page.get_by_text(re.compile(r"Start placed at")).wait_for(timeout=30_000)
            x, y, _ = app.controls["start"].position
            assert abs(x) < 1.5 and abs(y) < 2.0
            # Drag the start onto the inner edge of the left bridge, facing across it (as the
            # transform control and the yaw slider would): a foot over the edge.
            app.controls["start"].position = (-0.46, 0.0, 0.2)
            app.start_yaw.value = 0
            app.commands.put(MarkersCmd(None))
            page.get_by_text(re.compile(r"start invalid")).wait_for(timeout=30_000)
            reason = page.get_by_text(re.compile(r"a foot has no ground under it \(leg [LR]\d\)"))
            reason.wait_for(timeout=10_000)
            page.screenshot(path=artifacts / "app-08-invalid-start.png")
            assert np.allclose(app.balls["start"].color, (220, 30, 30))
    finally:
        app.stop()


def test_cancel_a_batch_show_a_trial_and_the_roadmap(artifacts):
    """In-process server (to read its state): a batch cancelled after its first trial stops
    short; picking a trial draws it again; Show roadmap draws the planner's graph."""
    from roachplan.app._server import RoachApp
    from roachplan.scenes import build_world, load_scene

    app = RoachApp(
        build_world(load_scene("double_bridge")),
        host="127.0.0.1",
        port=free_port(),
        max_upload_bytes=1000,
    )
    try:
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            set_value(page, "Trials (N)", "40")
            set_value(page, "Workers", "2")
            page.get_by_role("button", name="Run trials").click()
            # The first trial done (on a busy machine the page may show 2/40 first).
            page.get_by_text(re.compile(r"\b[1-9]\d?/40 trials")).wait_for(timeout=120_000)
            page.get_by_role("button", name="Cancel batch").click()
            done = page.get_by_text(re.compile(r"Batch cancelled: \d+/40 trials"))
            done.wait_for(timeout=60_000)
            said = re.search(r"cancelled: (\d+)/40", done.inner_text())
            assert said is not None
            n = int(said.group(1))
            assert 1 <= n < 40 and len(app.scene_trials) == n
            page.screenshot(path=artifacts / "app-09-batch-cancelled.png")

            page.locator("input[value='-']").first.click()
            page.get_by_role("option", name="1", exact=True).click()
            page.get_by_text(
                re.compile(r"^Trial 1: (success|fell|flipped|stuck|timeout)")
            ).wait_for(timeout=30_000)
            handles = app.server.scene._handle_from_node_name
            assert "/plans/shown" in handles and "/trajectories/shown" in handles

            page.get_by_text("Show roadmap").click()
            page.get_by_role("button", name="Plan").click()
            page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
            assert "/plans/roadmap" in app.server.scene._handle_from_node_name
            page.screenshot(path=artifacts / "app-10-roadmap.png")

            big = ROOT / "scenes" / "library" / "double_bridge.scad"  # > 1000 bytes
            upload(page, big)
            page.get_by_text("File too large").wait_for(timeout=30_000)
            assert "double_bridge" in title(page)
    finally:
        app.stop()
