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


@pytest.mark.slow
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
        wait_until(
            lambda: app.view._roots["/plans"].visible and app.view._roots["/trajectories"].visible,
            10,
        )


@pytest.mark.slow
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
        # (the loop sets the path to drive, then redraws the lines: wait for both)
        wait_until(lambda: app.drive_path == 1, 10)
        wait_until(lambda: [h.thickness for h in lines] == [3.0, 7.0, 3.0], 10)
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


def in_view(camera, points) -> np.ndarray:
    """Whether each world point ((N, 3) [m]) is in front of a reported camera (position,
    look_at, vertical fov [rad], aspect) and within its vertical and horizontal fields."""
    position, look_at, fov, aspect = camera
    forward = (look_at - position) / np.linalg.norm(look_at - position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = np.asarray(points, dtype=float) - position
    depth = rel @ forward
    tan_v, tan_h = np.tan(fov / 2), aspect * np.tan(fov / 2)
    return (
        (depth > 0)
        & (np.abs(rel @ up) <= tan_v * depth + 1e-9)
        & (np.abs(rel @ right) <= tan_h * depth + 1e-9)
    )


def framed(cameras, lo, hi, points) -> bool:
    """Whether one of the reported cameras looks at a point within the box lo..hi ((3,) [m])
    with every point in view."""
    for position, look_at, fov, aspect in cameras:
        inside = np.all((lo - 1e-6 <= look_at) & (look_at <= hi + 1e-6))
        if inside and in_view((position, look_at, fov, aspect), points).all():
            return True
    return False


@pytest.mark.slow
def test_every_load_and_re_mesh_frames_the_terrain_with_start_and_goal(app, artifacts):
    """The camera each browser reports back (not what the server asked for) after a capture is
    loaded and after it is re-meshed: it looks at a point within the terrain's bounds, from a
    distance at which the terrain's corners and both markers are all in view - though the
    camera was inside the terrain, looking away, before."""
    from roachplan.app._draw import on_surface
    from roachplan.scenes import LIBRARY
    from test_app import upload

    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        (client,) = app.server.get_clients().values()
        reported = []
        client.camera.on_update(
            lambda cam: reported.append(
                (
                    cam.position.copy(),
                    cam.look_at.copy(),
                    cam.fov,
                    cam.image_width / cam.image_height,
                )
            )
        )
        set_value(page, "Voxel [m]", "0.02")  # (a lighter mesh for software WebGL)
        for k, step in enumerate(("load", "re-mesh")):
            with client.atomic():  # inside the terrain to come, looking away from it
                client.camera.position = (0.3, 0.2, 0.05)
                client.camera.look_at = (40.0, -30.0, 0.05)
            before = app.world
            if step == "load":
                upload(page, LIBRARY / "kinect_bridge_depth.png")
            else:
                set_value(page, "Grid cell [m]", "0.03")
                page.get_by_role("button", name="Re-mesh loaded capture").click()
            wait_until(lambda: app.world is not before, 180)  # noqa: B023 - called at once
            world, n = app.world, len(reported)
            assert "kinect_bridge_depth" in world.scene.name
            lo, hi = world.mesh.bounds
            corners = np.array(
                [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
            )
            markers = [on_surface(world, p) for p in (world.scene.start, world.scene.goal)]

            shown = [*corners, *markers]
            wait_until(lambda: framed(reported[n - 1 :], lo, hi, shown), 30)  # noqa: B023
            page.wait_for_timeout(1000)
            page.screenshot(path=artifacts / f"view-10-framed-after-{step}.png")
            assert not in_view(
                ((0.3, 0.2, 0.05), np.array([40.0, -30.0, 0.05]), 1.0, 1.4), corners
            ).all()  # (the camera set before did not show it)
            print(
                f"{step} {k + 1}: framed; camera {np.round(client.camera.position, 2)} -> "
                f"{np.round(client.camera.look_at, 2)}"
            )
