"""The Voxel study folder in headless Chromium on a real Kinect capture (issue 14, item 6): a
square clicked on the floor, the ground plane, and a square over the chair, which is said not to
be planar; table 3.1's columns in the panel and as a CSV download."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from test_app import CHROMIUM, browser_pages, set_value, upload
from test_perception import REAL

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed")

NOT_FLAT = "does not look like one flat surface"
"""planarity_warning's words."""


def _table(page) -> list[list[str]]:
    """The study's table in the panel: its body rows' cells."""
    table = page.locator("table", has=page.get_by_text("points kept"))
    header = table.locator("thead").inner_text()
    for column in ("voxel size [cm]", "points", "points kept", "error [mm]"):
        assert column in header, header
    rows = table.locator("tbody tr")
    return [rows.nth(k).locator("td").all_inner_texts() for k in range(rows.count())]


def _check_rows(rows: list[list[str]], sizes: Sequence[float]) -> list[tuple[int, int, float]]:
    """Every row is (size, points, kept, error) with numbers; kept <= points; the voxel sizes
    in order after the raw points' N/A row. Returns (points, kept, error) per row."""
    assert [r[0].strip() for r in rows] == ["N/A", *(f"{s:g}" for s in sizes)], rows
    out = []
    for r in rows:
        points, kept, error = int(r[1]), int(r[2]), float(r[3])
        assert 4 <= kept <= points, r
        assert math.isfinite(error) and error > 0, r
        out.append((points, kept, error))
    # A coarser voxel grid leaves at most as many points (the same region, fewer cells).
    assert all(a[0] >= b[0] for a, b in zip(out[1:], out[2:])), out
    assert out[0][0] > out[1][0], out  # 1 cm voxels thin a Kinect cloud
    return out


def _pick_square(page, app, x: int, y: int) -> tuple[float, float]:
    page.get_by_text("Pick square centre").click()
    page.wait_for_timeout(500)
    page.mouse.click(x, y)
    page.get_by_text(re.compile(r"Square of 0\.5 m at")).wait_for(timeout=30_000)
    assert app.voxel_panel.pick_centre.value is False  # one click, one centre
    return app.voxel_panel.centre


def _world_points(app) -> np.ndarray:
    """(N, 3) the capture's finite points in the loaded world's frame [m]."""
    from roachplan.perception import load_capture

    raw = load_capture(REAL / "tutorials_region_growing_rgb_tutorial.pcd").finite_points()
    wfc = app.load_panel.view.world_from_camera
    return raw @ wfc[:3, :3].T + wfc[:3, 3]


def _chair_seat(app) -> np.ndarray:
    """(3,) the middle of the chair's seat [m]: the capture's points 0.3-0.6 m up (the
    planner's height field has the floor there: the seat is overhead)."""
    pts = _world_points(app)
    return np.median(pts[(pts[:, 2] > 0.3) & (pts[:, 2] < 0.6)], axis=0)


def _on_screen(app, p_world: np.ndarray) -> tuple[int, int]:
    """The pixel (x, y) where the one browser's camera shows the world point p_world [m]."""
    (client,) = app.server.get_clients().values()
    cam = client.camera
    forward = np.asarray(cam.look_at) - np.asarray(cam.position)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(cam.up_direction))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = p_world - np.asarray(cam.position)
    t = np.tan(cam.fov / 2)
    u, v = (d @ right) / (d @ forward) / (t * cam.aspect), (d @ up) / (d @ forward) / t
    return round((u + 1) / 2 * cam.image_width), round((1 - v) / 2 * cam.image_height)


def _points_in_square(app, centre, side: float) -> int:
    """The capture's finite points whose world x, y lie in the square, counted here from the
    file and the loaded capture's transform (not by the app's study)."""
    world = _world_points(app)
    h = side / 2
    return int(
        np.sum((np.abs(world[:, 0] - centre[0]) <= h) & (np.abs(world[:, 1] - centre[1]) <= h))
    )


def _check_csv(
    page, path: Path, sizes: Sequence[float], shown: list[tuple[int, int, float]]
) -> None:
    """The study's CSV download, saved at path: a header, then one row per row of the table
    shown ((points, kept, error) per row, as _check_rows returns them)."""
    with page.expect_download() as dl:
        page.get_by_role("button", name="Download study CSV").click()
    dl.value.save_as(path)
    lines = path.read_text().splitlines()
    assert lines[0] == "voxel_cm,points,points_kept,error_mm" and len(lines) == len(sizes) + 2
    csv_rows = [line.split(",") for line in lines[1:]]
    assert [(int(p), int(k)) for _, p, k, _ in csv_rows] == [(p, k) for p, k, _ in shown]
    assert all(abs(float(r[3]) - f[2]) < 1e-3 for r, f in zip(csv_rows, shown))


@pytest.mark.slow
def test_voxel_study_on_a_floor_square_the_ground_plane_and_the_chair(app, artifacts, tmp_path):
    pcd = REAL / "tutorials_region_growing_rgb_tutorial.pcd"
    sizes = [1, 2, 5, 10, 20]
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        set_value(page, "Voxel [m]", "0.02")  # (a lighter mesh for software WebGL)
        upload(page, pcd)
        page.get_by_text(re.compile(r"Loaded `?tutorials_region_growing")).wait_for(timeout=120_000)

        # Typed voxel sizes are checked before any work, in one line naming the field.
        set_value(page, "Voxel sizes [cm]", "1,x")
        page.get_by_role("button", name="Run voxel study").click()
        page.get_by_text(
            re.compile(r"Voxel sizes \[cm\] '1,x': expected 1 to \d+ numbers > 0")
        ).first.wait_for(timeout=30_000)
        set_value(page, "Voxel sizes [cm]", ",".join(map(str, sizes)))

        # A square on the floor, just right of the view's centre (screenshot voxel-01).
        centre = _pick_square(page, app, 700, 455)
        assert abs(float(app.world.heightfield.sample(np.array([centre]))[0])) < 0.02  # floor
        page.get_by_role("button", name="Run voxel study").click()
        page.get_by_text(re.compile(r"Voxel study of the 0\.5 m square")).wait_for(timeout=60_000)
        page.screenshot(path=artifacts / "voxel-01-floor-square.png")
        floor = _check_rows(_table(page), sizes)
        assert floor[0][0] == _points_in_square(app, centre, 0.5)  # the square clicked
        assert floor[0][2] < 20.0  # a Kinect's noise on a floor, not furniture [mm]
        assert NOT_FLAT not in app.voxel_panel.info.content
        _check_csv(page, tmp_path / "study.csv", sizes, floor)

        # The ground plane the load found: the whole floor, many more points than the square.
        page.locator("input[value='Square']").first.click()
        page.get_by_role("option", name="Ground plane").click()
        page.get_by_role("button", name="Run voxel study").click()
        page.get_by_text(re.compile(r"Voxel study of the ground plane")).wait_for(timeout=60_000)
        page.screenshot(path=artifacts / "voxel-02-ground-plane.png")
        plane = _check_rows(_table(page), sizes)
        assert plane[0][0] > 5 * floor[0][0] and plane[0][2] < 20.0
        assert NOT_FLAT not in app.voxel_panel.info.content

        # A square over the chair (clicked where the floor under its seat is on this browser's
        # screen): not one flat surface.
        page.locator("input[value='Ground plane']").first.click()
        page.get_by_role("option", name="Square").click()
        under_seat = _chair_seat(app) * [1.0, 1.0, 0.0]  # the floor under it: the click's hit
        centre = _pick_square(page, app, *_on_screen(app, under_seat))
        pts = _world_points(app)
        inside = np.all(np.abs(pts[:, :2] - centre) <= 0.25, axis=1)
        assert np.sum(inside & (pts[:, 2] > 0.1)) > 1000  # the chair is in the square
        page.get_by_role("button", name="Run voxel study").click()
        # The notification (its title: the whole of it is also under the status line).
        note = page.locator(".mantine-Notification-title", has_text="Region not planar")
        note.wait_for(timeout=60_000)
        page.screenshot(path=artifacts / "voxel-03-chair-not-planar.png")
        chair = _check_rows(_table(page), sizes)
        assert chair[0][2] > 20.0  # the chair's height, not a sensor's noise [mm]
        assert NOT_FLAT in page.locator("body").inner_text()  # and in the panel
        assert NOT_FLAT in app.voxel_panel.info.content


@pytest.mark.parametrize("text", ["", "1,x", "0", "-2,5", "nan", "inf", ",".join(["1"] * 32)])
def test_voxel_sizes_are_refused_in_one_line(text):
    from roachplan.app._voxel_panel import parse_sizes
    from roachplan.perception import CaptureError

    with pytest.raises(CaptureError) as err:
        parse_sizes(text)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"Voxel sizes [cm] {text!r}: expected")


def test_voxel_sizes_are_read_as_typed():
    from roachplan.app._voxel_panel import parse_sizes

    assert parse_sizes(" 1, 2.5 ,20") == (1.0, 2.5, 20.0)
