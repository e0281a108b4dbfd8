"""The user's own files, in the page, as they come: real third-party captures (../shared/
testdata/real, none written here) loaded with no setting changed and no marker placed by
hand are planned and driven between the start and goal the page picked (headless Chromium)."""

from __future__ import annotations

import re
import time
import zipfile

import pytest

from test_app import CHROMIUM, browser_pages, upload
from test_perception import REAL

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not CHROMIUM, reason="needs chromium")]


def _zip(tmp_path, name: str, *files) -> str:
    """A .zip of files (a depth image and its calibration travel together)."""
    out = tmp_path / name
    with zipfile.ZipFile(out, "w") as z:
        for f in files:
            z.write(f, f.name)
    return str(out)


def _load(app, page, path, timeout: float = 240) -> None:
    before = app.world
    upload(page, path)
    end = time.monotonic() + timeout
    while not (app.world is not before and app.status.content.startswith("Loaded")):
        assert time.monotonic() < end, f"{path} did not load: {app.status.content}"
        time.sleep(0.2)


def test_real_captures_as_they_come_are_planned_and_driven(app, artifacts, tmp_path):
    """A room (organized PCD), a low camera's depth image with its OpenCV calibration (a
    .zip), an outdoor lidar patch (world frame) and a desk (PCD): each loads, Plan finds a
    path between the picked start and goal, and Drive reaches the goal."""
    rtab = REAL / "rtabmap"
    files = [
        REAL / "tutorials_region_growing_rgb_tutorial.pcd",
        _zip(tmp_path, "rtabmap_154.zip", rtab / "depth_154.png", rtab / "calib_154.yaml"),
        REAL / "rough_ground_ouster_4x4m.pcd",
        REAL / "frame_20121214T142255.814212.pcd",
    ]
    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        for k, path in enumerate(files, start=1):
            _load(app, page, path)
            sc = app.world.scene
            assert tuple(sc.start[:2]) != tuple(sc.goal[:2]), app.world.notes
            page.get_by_role("button", name="Plan").click()
            _until(lambda: "Path found" in app.status.content, 90, app)
            page.get_by_role("button", name="Drive").click()
            _until(lambda: len(app.scene_trials) == 1, 180, app)  # each scene counts its own
            page.get_by_text(re.compile(r"Trial 1: ")).first.wait_for(timeout=30_000)
            page.screenshot(path=artifacts / f"real-files-{k:02d}.png")
            trial = app.scene_trials[0]
            assert trial["outcome"] == "success", (path, trial["reason"])


def _until(done, timeout: float, app) -> None:
    end = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < end, app.status.content
        time.sleep(0.2)
