"""What an uploaded file becomes: a scene file in its own folder, or a clear refusal."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
import yaml
from trimesh.exchange.ply import export_ply
from trimesh.exchange.stl import export_stl

from conftest import ROOT
from roachplan.app._uploads import prepare_upload_scene, safe_name, scene_from_upload
from roachplan.scenes import LIBRARY, SceneError

CAPTURE = {"method": "grid", "voxel": 0.02, "intrinsics": "kinect2-qhd"}


@pytest.mark.parametrize(
    ("given", "safe"),
    [
        ("../../etc/passwd", "passwd"),
        ("C:\\x\\rock.stl", "rock.stl"),
        ("a b;c.pcd", "a_b_c.pcd"),
        (".hidden.scad", "hidden.scad"),
        ("", "upload"),
    ],
)
def test_upload_names_cannot_leave_their_folder(given, safe):
    assert safe_name(given) == safe


def test_a_depth_capture_becomes_a_capture_scene_with_valid_poses(tmp_path):
    data = (LIBRARY / "kinect_bridge_depth.png").read_bytes()
    path = scene_from_upload("kinect_bridge_depth.png", data, tmp_path, CAPTURE)
    assert path.parent.parent == tmp_path
    world = prepare_upload_scene(path)
    raw = yaml.safe_load(path.read_text())
    assert raw["terrain"][0]["capture"] == "kinect_bridge_depth.png" and raw["ground"] is None
    from roachplan.scenes import pose_problem

    start, goal = world.scene.start, world.scene.goal
    assert start is not None and goal is not None  # picked when the world was built
    assert pose_problem(world, start) == "" and pose_problem(world, goal) == ""
    # The two poses lie along the bridge (the capture's longer side), well apart.
    assert abs(goal[0] - start[0]) > 1.0


def test_a_mesh_upload_stands_on_a_ground_plane(tmp_path):
    box = trimesh.creation.box((1.0, 0.6, 0.1))
    box.apply_translation((0, 0, 0.05))
    path = scene_from_upload("step.stl", export_stl(box), tmp_path, CAPTURE)
    world = prepare_upload_scene(path)
    assert world.scene.ground == 0.0 and len(world.mesh.faces) == 12
    assert np.isclose(world.heightfield.sample(np.array([[0.0, 0.0]]))[0], 0.1, atol=0.01)


def test_a_ply_with_faces_is_a_mesh_and_without_a_cloud(tmp_path):
    box = trimesh.creation.box((1.0, 1.0, 0.1))
    mesh_path = scene_from_upload("t.ply", export_ply(box), tmp_path, CAPTURE)
    cloud = trimesh.PointCloud(np.random.default_rng(0).uniform(0, 1, (50, 3)))
    cloud_path = scene_from_upload("c.ply", export_ply(cloud), tmp_path, CAPTURE)
    assert "mesh" in yaml.safe_load(mesh_path.read_text())["terrain"][0]
    assert "capture" in yaml.safe_load(cloud_path.read_text())["terrain"][0]


def test_refusals(tmp_path):
    with pytest.raises(SceneError, match="cannot load .exe"):
        scene_from_upload("tool.exe", b"MZ", tmp_path, CAPTURE)
    with pytest.raises(SceneError, match="over the"):
        scene_from_upload("big.pcd", b"0" * (64 * 1024 * 1024 + 1), tmp_path, CAPTURE)
    evil = "terrain:\n  - mesh: /etc/hostname\nrobot: {start: [0, 0]}\ngoal: [1, 0]\nbounds: [[-1, -1], [1, 1]]\n"
    with pytest.raises(SceneError, match="outside the upload"):
        scene_from_upload("evil.yaml", evil.encode(), tmp_path, CAPTURE)


def test_an_uploaded_scene_yaml_may_use_library_files(tmp_path):
    text = (LIBRARY / "double_bridge.yaml").read_text()
    path = scene_from_upload("mine.yaml", text.encode(), tmp_path, CAPTURE)
    world = prepare_upload_scene(path)
    assert world.scene.start == pytest.approx((0.0, -1.6, np.pi / 2))
    assert len(world.mesh.faces) > 0 and (path.parent / "double_bridge.scad").is_file()
    assert ROOT not in path.parents  # written under the upload folder, not the repository
