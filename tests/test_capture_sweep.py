"""Every capture a scene: a sample of the synthetic captures benchmarks/bench_captures.py sweeps
(every library scene x every Kinect 2 and RealSense preset x three views), each made by
`synth-capture` and used as a scene by `trial --json`, as a user would: no internal error, JSON
alone on standard output, and a path planned and driven at least 1 m where the view holds that
much standable ground."""

from __future__ import annotations

import json
import math

import pytest

from conftest import roachplan, synth_capture
from roachplan.perception import survey_views
from roachplan.scenes import build_terrain_mesh, load_scene

SAMPLE = [
    # (The report's resolution, kinect2-qhd of the double bridge, where no pick was found
    # before: tests/test_autopose.py's joined pick; the benchmark drives it.)
    ("plywood_bridge", "realsense-d435-1280x720", "oblique"),
    ("heightmap", "kinect2-sd", "low-near"),
    ("double_bridge_rough", "kinect2-hd", "oblique"),  # 1920x1080
]


@pytest.mark.slow
@pytest.mark.parametrize(("scene", "camera", "view"), SAMPLE)
def test_a_synthetic_capture_is_planned_and_driven(tmp_path, scene, camera, view):
    eye, target = survey_views(build_terrain_mesh(load_scene(scene)).bounds)[view]
    cap = synth_capture(tmp_path / "cap.png", scene, camera, eye, target)
    done = roachplan("trial", "--scene", str(cap), "--seed", "1", "--json", timeout=600)
    assert "internal error" not in done.stderr
    assert done.returncode == 0, done.stderr
    trial = json.loads(done.stdout)  # nothing but the JSON on stdout
    assert trial["path_found"], trial["reason"]
    assert math.dist(trial["start"][:2], trial["goal"][:2]) >= 1.0
    assert trial["drive_time"] > 0 and len(trial["trajectory"]) > 1
