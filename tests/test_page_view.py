"""What the page shows, in headless Chromium (issue 16): only the current plan's paths and
trajectories; the roadmap and standability toggles acting at once; K paths told apart, the one
Drive takes marked and chosen; the robot big enough to see when zoomed to or followed.
In-process servers, to read what the server has drawn. Screenshots go to test-artifacts/."""

from __future__ import annotations

import io
import re
import time

import numpy as np
import pytest
from test_app import CHROMIUM, browser_pages, set_value

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed")


def nodes(app, prefix: str) -> list[str]:
    """The names of the scene nodes the server holds (and so every browser draws) under prefix."""
    return [n for n in app.server.scene._handle_from_node_name if n.startswith(prefix)]


def wait_until(condition, timeout: float) -> float:
    """Seconds until condition() held; fails after timeout [s]."""
    t0 = time.monotonic()
    while not condition():
        assert time.monotonic() - t0 < timeout, "timed out"
        time.sleep(0.02)
    return time.monotonic() - t0


def dropdown(page, label: str, option: str) -> None:
    row = page.locator(f"xpath=//label[text()='{label}']/ancestor::div[.//input][1]")
    row.locator("input:visible").first.click()
    page.get_by_role("option", name=option, exact=True).click()


def robot_pixels_by_camera(app) -> float:
    """The robot body's length [px] on the one client's screen, from that client's camera
    (vertical fov, position, image height) and the body's 10 cm at the robot's position."""
    from roachplan.app._draw import projected_pixels

    (client,) = app.server.get_clients().values()
    cam = client.camera
    distance = float(np.linalg.norm(cam.position - np.asarray(app.view.robot_node.position)))
    return projected_pixels(app.world.robot.body_length, distance, cam.fov, cam.image_height)


def robot_pixels_in_screenshot(page, path) -> float:
    """The larger side [px] of the legs' bounding box in a screenshot, found by their orange
    (200, 80, 40) under any lighting (green/red < 0.55, blue/red < 0.3: unlike the tan terrain,
    every path colour and the markers' pink arrows) within 150 px of the 3D view's centre,
    where the camera looks when following or zoomed; 0 when no leg is seen."""
    from PIL import Image

    png = page.screenshot(path=path)
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    legs = (r > 90) & (g < 0.55 * r) & (b < 0.3 * r)
    box = page.locator("canvas").first.bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    ys, xs = np.nonzero(legs)
    near = (np.abs(xs - cx) <= 150) & (np.abs(ys - cy) <= 150)
    if near.sum() < 10:
        return 0.0
    xs, ys = xs[near], ys[near]
    return float(max(xs.max() - xs.min(), ys.max() - ys.min()) + 1)


def blue_pixels(page, path) -> int:
    """Pixels of the trajectory's blue (0, 90, 255 under any lighting: blue well above red and
    green) in a screenshot."""
    from PIL import Image

    png = page.screenshot(path=path)
    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=float)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.sum((b > 120) & (r < 0.35 * b) & (g < 0.6 * b)))


def test_a_framed_view_holds_its_points_and_the_robot_distance_gives_its_size():
    from roachplan.app._draw import framing, projected_pixels, robot_distance

    rng = np.random.default_rng(16)
    for _ in range(50):
        pts = rng.uniform(-3, 3, size=(int(rng.integers(2, 6)), 3))
        fov = float(rng.uniform(0.5, 1.6))
        position, look_at = framing(pts, fov)
        forward = (look_at - position) / np.linalg.norm(look_at - position)
        rel = pts - position
        depth = rel @ forward
        assert np.all(depth > 0)
        # Every point within the half-angle fov / 2 of the view's axis (a cone inside both the
        # vertical and the wider horizontal field).
        off_axis = np.linalg.norm(rel - depth[:, None] * forward, axis=1) / depth
        assert np.all(off_axis <= np.tan(fov / 2) + 1e-9)
        d = robot_distance(0.1, fov, 900, 160.0)
        assert np.isclose(projected_pixels(0.1, d, fov, 900), 160.0)


def check_the_standability_overlay(app, page, artifacts) -> None:
    """Show where it can stand: ticked, the start's region green and other standable cells
    yellow; unticked, hidden."""
    page.get_by_text("Show where it can stand").click()
    both = ["/standable/other", "/standable/region"]
    wait_until(lambda: sorted(nodes(app, "/standable/")) == both, 30)
    region = app.server.scene._handle_from_node_name["/standable/region"]
    assert tuple(region.color) == (40, 200, 80)
    # The start stands inside its region: in one of the region's draped squares.
    x, y, _ = app.markers.pose("start")
    squares = np.asarray(region.vertices).reshape(-1, 4, 3)[:, :, :2]
    lo, hi = squares.min(axis=1), squares.max(axis=1)
    assert np.any(np.all((lo - 0.01 <= [x, y]) & ([x, y] <= hi + 0.01), axis=1))
    # The floor inside the bridges' frame is standable, but not from the start.
    other = app.server.scene._handle_from_node_name["/standable/other"]
    assert np.asarray(other.vertices)[:, 2].max() < np.asarray(region.vertices)[:, 2].max()
    page.wait_for_timeout(1500)
    page.screenshot(path=artifacts / "view-04-standable.png")
    page.get_by_text("Show where it can stand").click()
    overlay = app.server.scene._handle_from_node_name["/standable"]
    wait_until(lambda: not overlay.visible, 5)


def test_a_new_plan_clears_the_old_and_the_toggles_act_at_once(app, artifacts):
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        # The first view is on start and goal (not the terrain's bounds).
        (client,) = app.server.get_clients().values()
        ends = np.array([app.world.scene.start[:2], app.world.scene.goal[:2]])
        wait_until(lambda: np.allclose(client.camera.look_at[:2], ends.mean(axis=0), atol=0.05), 10)
        set_value(page, "Playback speed [x real time]", "10")
        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
        page.get_by_role("button", name="Drive").click()
        page.get_by_text(re.compile(r"Trial 1: ")).wait_for(timeout=180_000)
        assert nodes(app, "/trajectories/"), "the drive's trajectory is drawn"
        page.screenshot(path=artifacts / "view-01-driven.png")

        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
        assert nodes(app, "/trajectories/") == [], "no old trajectory after a new Plan"
        assert sorted(nodes(app, "/plans/")) == ["/plans/0", "/plans/0/label"]
        page.screenshot(path=artifacts / "view-02-replanned.png")

        # The roadmap (kept by every plan) shows and goes at once, without a new Plan.
        assert "/plans/roadmap" not in nodes(app, "/plans/")
        page.get_by_text("Show roadmap").click()
        shown = wait_until(lambda: "/plans/roadmap" in nodes(app, "/plans/"), 10)
        roadmap = app.server.scene._handle_from_node_name["/plans/roadmap"]
        assert len(roadmap.points) > 10
        page.wait_for_timeout(1500)
        page.screenshot(path=artifacts / "view-03-roadmap-on.png")
        page.get_by_text("Show roadmap").click()
        hidden = wait_until(lambda: "/plans/roadmap" not in nodes(app, "/plans/"), 10)
        assert shown < 2.0 and hidden < 2.0, (shown, hidden)
        print(f"roadmap shown {shown:.2f} s, hidden {hidden:.2f} s after the click")

        check_the_standability_overlay(app, page, artifacts)

        # Best path: only the best path and its new trajectory are drawn.
        assert app.scene_trials[0]["outcome"] == "success", app.scene_trials[0]["reason"]
        page.get_by_text("Show roadmap").click()
        wait_until(lambda: "/plans/roadmap" in nodes(app, "/plans/"), 10)
        page.get_by_role("button", name="Best path").click()
        page.get_by_text(re.compile(r"Trial 2: ")).wait_for(timeout=180_000)
        assert nodes(app, "/plans/") == ["/plans/best"]
        assert nodes(app, "/trajectories/") == ["/trajectories/current"]
        page.screenshot(path=artifacts / "view-05-best-path.png")

        # Show trajectories / Show paths hide and show at once, and hold for what comes next.
        blue_before = blue_pixels(page, artifacts / "view-05b-trajectory-shown.png")
        page.get_by_text("Show trajectories").click()
        wait_until(lambda: not app.view._roots["/trajectories"].visible, 10)
        page.wait_for_timeout(1000)
        blue_after = blue_pixels(page, artifacts / "view-05c-trajectory-hidden.png")
        # (the goal marker is blue too: what goes is the trajectory's line)
        assert blue_before - blue_after > 150, (blue_before, blue_after)
        page.get_by_text("Show paths").click()
        wait_until(lambda: not app.view._roots["/plans"].visible, 10)
        page.get_by_role("button", name="Plan").click()  # a new plan, drawn hidden
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=60_000)
        assert nodes(app, "/plans/") and not app.view._roots["/plans"].visible
        page.get_by_text("Show paths").click()
        page.get_by_text("Show trajectories").click()
        wait_until(lambda: app.view._roots["/plans"].visible
                   and app.view._roots["/trajectories"].visible, 10)  # fmt: skip


def test_k_paths_told_apart_drive_takes_the_chosen_one_robot_seen(app, artifacts):
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        set_value(page, "Paths (K)", "3")
        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"3 paths found")).wait_for(timeout=90_000)
        handles = app.server.scene._handle_from_node_name
        lines = [handles[f"/plans/{k}"] for k in range(3)]
        colours = [tuple(np.asarray(h.colors).reshape(-1, 3)[0]) for h in lines]
        assert len(set(colours)) == 3, colours
        assert [h.thickness for h in lines] == [7.0, 3.0, 3.0], "path 1 is marked for Drive"

        dropdown(page, "Drive path", "2")
        wait_until(lambda: app.drive_path == 1, 10)
        assert [h.thickness for h in lines] == [3.0, 7.0, 3.0]
        page.screenshot(path=artifacts / "view-06-three-paths-second-marked.png")

        # Follow the robot through the drive; look halfway.
        page.get_by_text("Follow robot").click()
        page.get_by_role("button", name="Drive").click()
        page.get_by_text(re.compile(r"Drive: [3-9]\d % of the path")).wait_for(timeout=120_000)
        page.wait_for_timeout(500)  # (the browser draws the camera's last move)
        by_camera = robot_pixels_by_camera(app)
        on_screen = robot_pixels_in_screenshot(page, artifacts / "view-07-drive-followed.png")
        assert by_camera > 40 and on_screen > 40, (by_camera, on_screen)
        print(f"followed: robot {by_camera:.0f} px by camera, legs {on_screen:.0f} px on screen")
        page.get_by_text(re.compile(r"Trial 1: ")).wait_for(timeout=180_000)
        driven = np.asarray(app.scene_trials[0]["path"])
        chosen, first = app.plans[1].plan.path_xyz, app.plans[0].plan.path_xyz
        assert driven.shape == chosen.shape and np.allclose(driven, chosen)
        assert driven.shape != first.shape or not np.allclose(driven, first)

        # Far away again, then Zoom to robot.
        page.get_by_text("Follow robot").click()
        (client,) = app.server.get_clients().values()
        with client.atomic():
            client.camera.look_at = (0.0, 0.0, 0.0)
            client.camera.position = (6.0, -8.0, 6.0)
        page.wait_for_timeout(1000)
        far = robot_pixels_in_screenshot(page, artifacts / "view-08-far.png")
        assert robot_pixels_by_camera(app) < 40 and far < 40, far
        print(f"far: robot {robot_pixels_by_camera(app):.0f} px by camera, {far:.0f} on screen")
        page.get_by_role("button", name="Zoom to robot").click()
        wait_until(lambda: robot_pixels_by_camera(app) > 40, 10)
        page.wait_for_timeout(1000)
        by_camera = robot_pixels_by_camera(app)
        on_screen = robot_pixels_in_screenshot(page, artifacts / "view-09-zoomed.png")
        assert by_camera > 40 and on_screen > 40, (by_camera, on_screen)
        print(f"zoomed: robot {by_camera:.0f} px by camera, legs {on_screen:.0f} px on screen")
