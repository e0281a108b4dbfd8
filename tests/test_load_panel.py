"""The load panel in headless Chromium with real third-party files: a depth PNG with its
calibration uploaded first, re-levelling a real Kinect cloud by clicking its floor (then planning
and driving on it), and a model in millimetres reloaded with Scale x0.001."""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml

from test_app import CHROMIUM, browser_pages, set_value, title, upload
from test_perception import REAL

pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed")


def _scene_of(app) -> dict:
    return yaml.safe_load(app.world.scene.path.read_text())


def test_depth_png_with_its_calibration_uploaded_first(app, artifacts):
    rtab = REAL / "rtabmap"
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        upload(page, rtab / "calib_154.yaml")  # its name differs from the image's
        page.get_by_text(re.compile(r"Pending calibration")).wait_for(timeout=30_000)
        assert "double_bridge" in title(page)  # a calibration is kept, not loaded
        upload(page, rtab / "depth_154.png")
        page.get_by_text(re.compile(r"Loaded `?depth_154")).wait_for(timeout=120_000)
        page.screenshot(path=artifacts / "load-01-rtabmap-depth-with-calibration.png")
        raw = _scene_of(app)
        assert raw["terrain"][0]["perception"]["intrinsics"] == "calib_154.yaml"
        assert (app.world.scene.path.parent / "calib_154.yaml").is_file()
        # The floor is found 0.42 m under the camera (the calibration says 0.43 m above the base).
        shown = page.get_by_text(re.compile(r"Camera \d+\.\d\d m above the ground")).inner_text()
        said = re.search(r"Camera (\d+\.\d\d) m", shown)
        assert said is not None, shown
        height = float(said.group(1))
        assert 0.35 < height < 0.5, shown
        # Start and goal as `roachplan trial --scene depth_154.png` picks them: over a metre apart.
        start, goal = app.world.scene.start, app.world.scene.goal
        assert np.hypot(goal[0] - start[0], goal[1] - start[1]) >= 1.0, app.world.notes
        page.get_by_text("Start and goal are valid.").wait_for(timeout=10_000)
        # Notifications and panels name the files, never the app's upload folders.
        assert str(app.upload_dir) not in page.content()


def test_a_depth_png_and_its_calibration_in_one_zip_load_together(app, artifacts, tmp_path):
    import zipfile

    rtab = REAL / "rtabmap"
    bundle = tmp_path / "depth_154_and_calibration.zip"
    with zipfile.ZipFile(bundle, "w") as z:
        z.write(rtab / "depth_154.png", "depth_154.png")
        z.write(rtab / "calib_154.yaml", "calib_154.yaml")
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        upload(page, bundle)
        page.get_by_text(re.compile(r"Loaded `?depth_154")).wait_for(timeout=120_000)
        page.screenshot(path=artifacts / "load-01b-rtabmap-zip-with-calibration.png")
        assert _scene_of(app)["terrain"][0]["perception"]["intrinsics"] == "calib_154.yaml"
        shown = page.get_by_text(re.compile(r"Camera \d+\.\d\d m above the ground")).inner_text()
        said = re.search(r"Camera (\d+\.\d\d) m", shown)
        assert said is not None, shown
        assert 0.35 < float(said.group(1)) < 0.5, shown


def test_click_the_floor_to_relevel_then_plan_and_drive(app, artifacts):
    pcd = REAL / "tutorials_region_growing_rgb_tutorial.pcd"
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        set_value(page, "Voxel [m]", "0.02")  # (a lighter mesh for software WebGL)
        upload(page, pcd)
        page.get_by_text(re.compile(r"Loaded `?tutorials_region_growing")).wait_for(timeout=120_000)
        before = app.world.mesh.bounds.copy()
        page.get_by_text("Pick ground", exact=True).click()
        page.wait_for_timeout(500)
        page.mouse.click(700, 455)  # just right of the view's centre: the floor (screenshot 02a)
        page.screenshot(path=artifacts / "load-02a-clicked.png")
        page.get_by_text(re.compile(r"meshing the capture tutorials_region_growing")).wait_for(
            timeout=30_000
        )
        page.get_by_text(re.compile(r"Loaded `?tutorials_region_growing")).wait_for(timeout=120_000)
        page.screenshot(path=artifacts / "load-02-relevelled.png")
        raw = _scene_of(app)
        gp = raw["terrain"][0]["perception"]["ground_point"]
        assert len(gp) == 3 and gp[2] > 0.5  # a point in front of the camera, capture frame [m]
        shown = page.get_by_text(re.compile(r"Camera \d+\.\d\d m above the ground")).inner_text()
        said = re.search(r"Camera (\d+\.\d\d) m", shown)
        assert said is not None, shown
        height = float(said.group(1))
        assert 0.75 < height < 0.85, shown  # the floor: 0.80 m under the Kinect
        assert app.load_panel.pick_ground.value is False  # one click, one re-level
        assert np.allclose(app.world.mesh.bounds[:, 2], before[:, 2], atol=0.05)

        # The typed pose round-trips: the same height and pitch give the same camera back.
        set_value(page, "Camera height [m]", "0.9")
        page.get_by_role("button", name="Re-mesh with this camera pose").click()
        page.get_by_text(re.compile(r"Camera 0\.90 m above the ground")).wait_for(timeout=120_000)
        assert "camera_pose" in _scene_of(app)["terrain"][0]["perception"]

        page.get_by_text("Start and goal are valid.").wait_for(timeout=10_000)
        set_value(page, "Playback speed [x real time]", "10")
        page.get_by_role("button", name="Plan").click()
        page.get_by_text(re.compile(r"Path found in")).wait_for(timeout=90_000)
        page.get_by_role("button", name="Drive").click()
        status = page.get_by_text(re.compile(r"Trial 1: "))
        status.wait_for(timeout=180_000)
        page.screenshot(path=artifacts / "load-03-relevelled-driven.png")
        assert re.search(r"(success|fell|flipped|stuck|timeout)", status.inner_text())


def test_a_model_in_millimetres_is_refused_then_scaled(app, artifacts, tmp_path):
    model = tmp_path / "plate.scad"
    model.write_text("cube([400, 300, 20]);\n")
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        upload(page, model)
        page.get_by_text(re.compile(r"most likely a model in millimetres")).wait_for(
            timeout=120_000
        )
        page.screenshot(path=artifacts / "load-04-millimetres-refused.png")
        assert "double_bridge" in title(page)
        assert str(app.upload_dir) not in page.content()
        page.get_by_role("button", name="Scale x0.001").click()
        page.get_by_text(re.compile(r"Loaded `?plate")).wait_for(timeout=120_000)
        page.screenshot(path=artifacts / "load-05-millimetres-scaled.png")
        assert "plate" in title(page)
        assert np.allclose(app.world.mesh.extents, (0.4, 0.3, 0.02), atol=1e-6)
        assert _scene_of(app)["terrain"][0]["scale"] == 0.001
        assert page.get_by_role("button", name="Scale x0.001").count() == 0 or not (
            page.get_by_role("button", name="Scale x0.001").is_visible()
        )
