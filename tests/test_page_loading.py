"""What the page's loading does, without a browser: a capture is meshed once per load; a depth
image uploaded with its calibration gets the start and goal `roachplan trial` picks; a capture
scene from elsewhere is copied before it is re-meshed; a scene file outside the library joins
the scene picker; one budget bounds a whole multi-path plan."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import yaml

from conftest import free_port
from roachplan.app._jobs import load_world
from roachplan.app._relevel import adopt_capture_scene, rewrite_capture_settings
from roachplan.app._uploads import prepare_upload_scene, scene_from_upload
from roachplan.scenes import LIBRARY, build_world, load_scene
from test_perception import REAL

RTAB = REAL / "rtabmap"


@pytest.fixture
def count_meshing(monkeypatch):
    """Calls of perception.mesh_capture made through scenes (where a load meshes)."""
    import roachplan.scenes._world as world_module

    calls = []
    original = world_module.mesh_capture

    def counting(source, settings):
        calls.append(source)
        return original(source, settings)

    monkeypatch.setattr(world_module, "mesh_capture", counting)
    return calls


def test_an_uploaded_capture_is_meshed_once_and_its_camera_shown(tmp_path, count_meshing):
    data = (LIBRARY / "kinect_bridge_depth.png").read_bytes()
    path = scene_from_upload("bridge.png", data, tmp_path, {"intrinsics": "kinect2-qhd"})
    world, view = load_world(str(path), from_upload=True)
    assert len(count_meshing) == 1, count_meshing
    assert view is not None and view.scene_path == path
    assert view.report["camera_height_m"] == pytest.approx(1.5, abs=0.05)
    assert len(world.mesh.faces) > 1000


def test_the_page_picks_start_and_goal_as_the_command_line_does(tmp_path):
    """The RTAB-Map depth PNG with its OpenCV calibration, uploaded together with the page's
    default meshing, is the same scene as `roachplan trial --scene depth.png` with the
    calibration beside it: the same start and goal, at least a metre apart."""
    cli_dir = tmp_path / "cli"
    cli_dir.mkdir()
    shutil.copy(RTAB / "depth_154.png", cli_dir / "depth_154.png")
    shutil.copy(RTAB / "calib_154.yaml", cli_dir / "depth_154.yaml")  # found beside the image
    cli = build_world(load_scene(cli_dir / "depth_154.png"))

    from roachplan.app._load_panel import DEFAULTS

    page_settings = {}  # the load panel passes only what differs from DEFAULTS
    assert DEFAULTS.voxel[0] == pytest.approx(0.01) and DEFAULTS.method == "sensor"
    path = scene_from_upload(
        "depth_154.png",
        (RTAB / "depth_154.png").read_bytes(),
        tmp_path,
        page_settings,
        calibration=RTAB / "calib_154.yaml",
    )
    page = prepare_upload_scene(path)
    assert page.scene.start == pytest.approx(cli.scene.start, abs=1e-3)
    assert page.scene.goal == pytest.approx(cli.scene.goal, abs=1e-3)
    start, goal = page.scene.start, page.scene.goal
    assert start is not None and goal is not None  # picked when the world was built
    distance = np.hypot(*(np.subtract(goal[:2], start[:2])))
    assert distance >= 1.0, page.notes


def test_a_capture_from_elsewhere_is_copied_then_remeshed(tmp_path):
    """A command-line capture (and a calibration beside it) is never rewritten: re-meshing
    writes a scene of its own that points at it, with the crop box in world coordinates."""
    src = tmp_path / "src"
    src.mkdir()
    shutil.copy(RTAB / "depth_154.png", src / "depth_154.png")
    shutil.copy(RTAB / "calib_154.yaml", src / "depth_154.yaml")
    before = {p.name: p.read_bytes() for p in src.iterdir()}
    world, view = load_world(str(src / "depth_154.png"), from_upload=False)
    assert view is not None
    own = adopt_capture_scene(view.scene_path, tmp_path / "edited")
    lo, hi = world.mesh.bounds
    crop = [[float(lo[0]) + 0.5, float(lo[1]), -1.0], [float(hi[0]) - 0.5, float(hi[1]), 1.0]]
    rewrite_capture_settings(own, {"crop": crop, "voxel": 0.02, "method": None})
    raw = yaml.safe_load(own.read_text())
    assert raw["terrain"][0]["capture"] == str((src / "depth_154.png").resolve())
    assert raw["terrain"][0]["perception"] == {"crop": crop, "voxel": 0.02}
    cropped, _ = load_world(str(own), from_upload=True)
    assert cropped.mesh.bounds[0][0] >= crop[0][0] - 0.03
    assert cropped.mesh.bounds[1][0] <= crop[1][0] + 0.03
    assert cropped.mesh.extents[0] < world.mesh.extents[0] - 0.8
    assert {p.name: p.read_bytes() for p in src.iterdir()} == before


def test_a_scene_file_outside_the_library_joins_the_picker(tmp_path):
    """`serve --scene FILE.yaml` named like no library scene (the issue's islands.yaml) starts
    (viser refused a dropdown value outside its options)."""
    from roachplan.app._server import RoachApp

    scene = tmp_path / "islands.yaml"
    text = (LIBRARY / "flat.yaml").read_text()
    scene.write_text(text)
    app = RoachApp(build_world(load_scene(scene)), host="127.0.0.1", port=free_port())
    try:
        assert app.scene_picker.value == "file: islands.yaml"
        assert "file: islands.yaml" in app.scene_picker.options
        assert "flat" in app.scene_picker.options  # the library is still there
    finally:
        app.stop()


def test_a_multi_path_plan_keeps_one_budget(world):
    """plan_many with a budget: 20 paths asked, 1.5 s for all the tries (not each)."""
    from roachplan.experiments import plan_many

    attempts = []
    plans = plan_many(
        world, 20, seed=0, budget=1.5, on_attempt=lambda seed, lp: attempts.append((seed, lp))
    )
    assert len(plans) < 20 and len(attempts) < 3 * 20 + 10  # the budget ended it
    assert [s for s, _ in attempts] == list(range(len(attempts)))
    assert [lp for _, lp in attempts if lp is not None] == plans
