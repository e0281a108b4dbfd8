"""Scene files, the mesh pipeline and the scene library, against the real OpenSCAD and PyBullet."""

from __future__ import annotations

import copy
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
import yaml

from conftest import roachplan
from roachplan.scenes import (
    LIBRARY,
    SceneError,
    build_world,
    list_scenes,
    load_scene,
    looks_like_millimetres,
    scaled_scene,
)

# -- every scene in the library -------------------------------------------------------------


@pytest.mark.parametrize("name", list_scenes())
def test_library_scene_loads_settles_and_walks_one_second(name):
    world = build_world(load_scene(name))
    scene = world.scene
    assert scene.start is not None  # build_world picks it when the scene gives none
    x, y, yaw = scene.start
    with world.simulation() as sim:
        sim.reset(x, y, yaw)
        pos, _ = sim.body_pose()
        ground = float(world.heightfield.sample(pos[:2]))
        # Settled on the surface under the start: standing on its legs, not hovering or sunk.
        assert (
            0.5 * world.robot.standing_height < pos[2] - ground < 1.5 * world.robot.standing_height
        )
        sim.set_leg_speeds(scene.driver.omega0, scene.driver.omega0)
        lowest = np.inf
        for _ in range(round(1.0 / scene.sim.timestep)):
            sim.step()
            pos, quat = sim.body_pose()
            assert np.all(np.isfinite(pos)) and np.all(np.isfinite(quat))
            lowest = min(lowest, pos[2] - float(world.heightfield.sample(pos[:2])))
    assert lowest > 0.0, "the body went below the terrain surface"
    walked = np.dot(pos[:2] - (x, y), (np.cos(yaw), np.sin(yaw)))
    assert walked > 0.05, f"walked only {walked:.3f} m forward in 1 s"


# -- bad scene files -----------------------------------------------------------------------------


@pytest.fixture
def box_stl(tmp_path) -> Path:
    """A 1 x 1 x 0.1 m block, its top at z = 0.1."""
    path = tmp_path / "block.stl"
    box = trimesh.creation.box((1.0, 1.0, 0.1))
    box.apply_translation((0, 0, 0.05))
    box.export(path)
    return path


VALID = {
    "terrain": [{"mesh": "block.stl", "position": [0, 0, 0], "orientation": [0, 0, 0, 1]}],
    "ground": None,
    "robot": {"start": [0.0, -0.3, 90]},
    "goal": [0.0, 0.3, 90],
    "bounds": [[-0.3, -0.35], [0.3, 0.35]],
    "planner": {"name": "rrtconnect"},
}


def write_scene(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def edited(**changes) -> dict:
    data = copy.deepcopy(VALID)
    for dotted, value in changes.items():
        *parents, last = dotted.split("__")
        node: Any = data  # the scene's YAML: dicts and lists within each other
        for k in parents:
            node = node[int(k)] if isinstance(node, list) else node[k]
        if value is KeyError:
            del node[last]
        else:
            node[int(last) if isinstance(node, list) else last] = value
    return data


def test_the_valid_example_loads(tmp_path, box_stl):
    world = build_world(load_scene(write_scene(tmp_path, VALID)))
    assert world.mesh.bounds[1][2] == pytest.approx(0.1)
    assert world.scene.planner.name == "rrtconnect"


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        (edited(colour="red"), ["colour", "unknown key", "terrain", "robot"]),
        (edited(planner={"name": "rrt", "time_limt": 3}), ["planner.time_limt", "time_limit"]),
        (edited(planner={"name": "dijkstra"}), ["planner.name", "'dijkstra'", "prm", "bitstar"]),
        (edited(sim={"timestep": -0.001}), ["sim.timestep", "positive"]),
        (edited(sim={"solver_iterations": 2.5}), ["sim.solver_iterations", "integer"]),
        (edited(seed="zero"), ["seed", "non-negative integer", "'zero'"]),
        (edited(goal=[0.0, "north"]), ["goal[1]", "number", "'north'"]),
        (edited(robot__start=KeyError), ["goal", "give both robot.start and goal, or neither"]),
        (
            edited(terrain__0__mesh="nothere.stl"),
            ["terrain[0].mesh", "nothere.stl", "does not exist"],
        ),
        (
            edited(terrain__0__mesh="scene.yaml"),
            ["terrain[0].mesh", ".stl or .obj or .ply or .glb"],
        ),
        (
            edited(terrain__0__orientation=[0, 0, 0, 2]),
            ["terrain[0].orientation", "norm 2", "unit quaternion"],
        ),
        (edited(terrain__0__params={"h": 1}), ["terrain[0].params", "only a scad object"]),
        (edited(terrain=[]), ["terrain", "empty only with a ground"]),
        (edited(bounds=[[1, 1], [0, 0]]), ["bounds", "below max"]),
        (edited(goal=[0.0, 2.0, 90]), ["goal", "outside bounds"]),
    ],
    ids=lambda v: v[0] if isinstance(v, list) else None,
)
def test_bad_scene_files_are_refused_with_the_key_and_what_is_accepted(
    tmp_path, box_stl, data, expected
):
    path = write_scene(tmp_path, data)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    message = str(err.value)
    assert message.startswith(str(path))
    for fragment in expected:
        assert fragment in message


def test_a_start_off_the_terrain_is_refused(tmp_path, box_stl):
    data = edited(robot__start=[0.0, -0.6, 90], bounds=[[-0.3, -0.7], [0.3, 0.7]])
    with pytest.raises(
        SceneError, match=r"robot\.start: \(0, -0\.6\) is off the terrain.*covers x in"
    ):
        build_world(load_scene(write_scene(tmp_path, data)))


def test_bounds_too_large_to_plan_over_are_refused_before_any_memory_is_used(tmp_path, box_stl):
    # 100 m x 100 m at 1 cm would be 100 M height-field cells (tens of GB).
    data = edited(bounds=[[-50, -50], [50, 50]], ground=0.0)
    with pytest.raises(SceneError, match=r"bounds: 100\.0 m x 100\.0 m .* give bounds at most"):
        build_world(load_scene(write_scene(tmp_path, data)))


def test_a_start_where_the_robot_cannot_stand_names_the_condition_and_leg(tmp_path, box_stl):
    # Facing +x at the block's edge: the rear legs hang over nothing.
    data = edited(robot__start=[-0.47, 0.0, 0], bounds=[[-0.5, -0.35], [0.3, 0.35]])
    with pytest.raises(
        SceneError, match=r"robot\.start: the robot cannot stand at .*\(leg [LR]3\)"
    ):
        build_world(load_scene(write_scene(tmp_path, data)))


def test_a_mesh_in_millimetres_is_called_a_unit_error(tmp_path):
    big = trimesh.creation.box((1000.0, 1000.0, 100.0))
    big.export(tmp_path / "block.stl")
    with pytest.raises(
        SceneError, match=r"terrain\[0\]\.mesh: the mesh is 1000 m across.*millimetres"
    ):
        build_world(load_scene(write_scene(tmp_path, VALID)))


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"", "is an empty file"),
        (b"solid x\nthis is not an stl\n", "contains no triangles: it is not a valid STL file"),
    ],
)
def test_an_unreadable_mesh_file_is_refused(tmp_path, content, expected):
    (tmp_path / "block.stl").write_bytes(content)
    with pytest.raises(SceneError, match=rf"terrain\[0\]\.mesh: .*block\.stl {expected}"):
        build_world(load_scene(write_scene(tmp_path, VALID)))


FLAT_XY = {
    "drawing.obj": b"v 0 0\nv 1 0\nv 1 1\nv 0 1\nf 1 2 3\nf 1 3 4\n",
    "drawing.ply": (
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        b"0 0\n1 0\n0 1\n3 0 1 2\n"
    ),
}


@pytest.mark.parametrize("name", sorted(FLAT_XY))
def test_a_mesh_of_2d_vertices_is_refused_as_having_no_height(tmp_path, name):
    """A mesh file whose vertices have x and y alone is a drawing (the OBJ's was an internal
    error, the PLY's "cannot be read as a mesh: 'z'"); the OpenSCAD case is a 2-D model."""
    (tmp_path / name).write_bytes(FLAT_XY[name])
    with pytest.raises(SceneError) as err:
        build_world(load_scene(tmp_path / name))
    assert f"terrain[0].mesh: {tmp_path / name} is 2-D: its vertices have no z coordinate" in str(
        err.value
    )
    assert "no height" in str(err.value)


def test_a_flat_mesh_is_a_patch_of_floor(tmp_path):
    """A mesh of x, y, z with no extent in z stays what it is, a patch of floor (it is not
    thickened, nor refused): on the ground plane of its own scene, or the only floor."""
    quad = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 3]])
    quad.export(tmp_path / "patch.stl")
    world = build_world(load_scene(tmp_path / "patch.stl"))
    assert len(world.mesh.faces) == 2
    assert np.allclose(world.mesh.extents, [1.0, 1.0, 0.0])
    assert world.scene.ground == 0.0


def test_meshes_are_cleaned_and_turned_to_face_up(tmp_path):
    # An open 2 x 2 quad grid, wound downward, with a duplicated corner, a degenerate face and
    # a triangle on a NaN vertex: cleaning keeps exactly the 8 real triangles, facing up.
    g = np.array([[x, y, 0.0] for y in (-0.5, 0, 0.5) for x in (-0.5, 0, 0.5)])
    faces = []
    for j in range(2):
        for i in range(2):
            a, b, c, d = 3 * j + i, 3 * j + i + 1, 3 * j + i + 4, 3 * j + i + 3
            faces += [[a, c, b], [a, d, c]]  # clockwise from above: normals down
    vertices = np.vstack([g, g[4], [np.nan, 0, 0]])  # 9 = copy of the centre, 10 = NaN
    faces += [[0, 1, 1], [0, 10, 1]]
    faces[0] = [0, 9, 1]  # was [0, 4, 1]: now on the duplicate of the centre
    trimesh.Trimesh(vertices, faces, process=False).export(tmp_path / "block.ply")
    data = edited(
        terrain__0__mesh="block.ply",
        robot__start=[0.0, -0.2, 90],
        goal=[0.0, 0.2, 90],
        bounds=[[-0.1, -0.3], [0.1, 0.3]],
        ground=-1.0,
    )
    mesh = build_world(load_scene(write_scene(tmp_path, data))).mesh
    assert len(mesh.faces) == 8 and len(mesh.vertices) == 9
    assert np.all(mesh.face_normals[:, 2] > 0.99)


# -- the command line ------------------------------------------------------------------------------


def test_scene_check_reports_each_file_and_fails_on_a_bad_one(tmp_path, box_stl):
    bad = write_scene(tmp_path, edited(terrain__0__orientation=[0, 0, 1, 1]))
    out = roachplan("scene", "check", "double_bridge", str(bad), "flat")
    assert out.returncode == 1
    lines = out.stdout.splitlines()
    # 40 triangles by backend auto's manifold (the binary cuts the same faces into 32).
    assert lines[0].startswith("ok   double_bridge: 1 terrain object(s), 40 triangles")
    assert lines[1].startswith(f"FAIL {bad}: {bad}: terrain[0].orientation: quaternion")
    assert lines[2].startswith("ok   flat: 0 terrain object(s)")
    assert len(lines) == 3  # one line per file; who rendered it goes to stderr
    assert "roachplan: double_bridge: double_bridge.scad: rendered with manifold" in out.stderr
    assert "Traceback" not in out.stderr


def test_scene_build_exports_the_assembled_terrain(tmp_path):
    out = roachplan("scene", "build", "double_bridge", "-o", str(tmp_path / "bridge.obj"))
    assert out.returncode == 0, out.stderr
    mesh = trimesh.load_mesh(tmp_path / "bridge.obj")
    np.testing.assert_allclose(mesh.bounds, [[-1.0, -1.5, 0.0], [1.0, 1.5, 0.2]], atol=1e-6)
    assert mesh.is_watertight


def test_trial_takes_a_scene_file_path(tmp_path, box_stl):
    out = roachplan("trial", "--scene", str(write_scene(tmp_path, VALID)), "--json")
    assert out.returncode == 0, out.stderr
    assert '"scene": "scene"' in out.stdout and '"outcome": "success"' in out.stdout


@pytest.mark.slow
def test_the_documented_example_is_a_valid_scene(tmp_path):
    page = (Path(__file__).resolve().parent.parent / "docs" / "scenes.md").read_text()
    example = page.split("## A complete example", 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "example.yaml").write_text(example)
    shutil.copy(LIBRARY / "double_bridge.scad", tmp_path)
    (tmp_path / "meshes").mkdir()
    trimesh.creation.box((0.1, 0.1, 0.05)).export(tmp_path / "meshes" / "rock.stl")
    (tmp_path / "captures").mkdir()
    shutil.copy(LIBRARY / "kinect_bridge_depth.png", tmp_path / "captures" / "bridge.png")
    world = build_world(load_scene(tmp_path / "example.yaml"))
    assert [o.kind for o in world.scene.terrain] == ["scad", "mesh", "capture"]
    # The captured plywood bridge's floor, moved 4 m along y, reaches past y = 5 m.
    assert world.mesh.bounds[1][1] > 5.0
    assert dict(world.scene.terrain[0].params) == {"separation": 0.8, "left_bump_height": 0.015}
    assert world.scene.planner.validity.max_slope_deg == 25.0
    # The bridges moved 0.1 m closer to the middle; the 5 cm rock, centred on z = 0, at (0.8, 1.7).
    hf = world.heightfield
    assert hf.sample(np.array([-0.45, 0.0])) > 0.199 and hf.sample(np.array([-0.35, 0.0])) == 0.0
    assert hf.sample(np.array([0.8, 1.7])) == pytest.approx(0.025)


# -- models in millimetres: `scale:` and --scale ---------------------------------------------------


@pytest.fixture
def millimetre_stl(tmp_path) -> Path:
    """The 1 x 1 x 0.1 m block of box_stl, as CAD exports it: in millimetres."""
    path = tmp_path / "block.stl"
    box = trimesh.creation.box((1000.0, 1000.0, 100.0))
    box.apply_translation((0, 0, 50))
    box.export(path)
    return path


def test_a_mesh_in_millimetres_loads_with_scale(tmp_path, millimetre_stl):
    with pytest.raises(
        SceneError,
        match=r"terrain\[0\]\.mesh: the mesh is 1000 m across; scenes are in metres, so this is "
        r"most likely a model in millimetres: add `scale: 0\.001` to this terrain object",
    ):
        build_world(load_scene(write_scene(tmp_path, VALID)))
    assert looks_like_millimetres(trimesh.load_mesh(millimetre_stl))
    world = build_world(load_scene(write_scene(tmp_path, edited(terrain__0__scale=0.001))))
    np.testing.assert_allclose(world.mesh.bounds, [[-0.5, -0.5, 0], [0.5, 0.5, 0.1]], atol=1e-9)
    assert not looks_like_millimetres(world.mesh)


def test_scale_applies_per_axis_before_the_placement(tmp_path, box_stl):
    data = edited(
        terrain__0__scale=[2, 1, 0.5],
        terrain__0__position=[0.5, 0, 1],
        terrain__0__orientation=[0, 0, 0.7071068, 0.7071068],  # 90 deg about z: x -> y
        bounds=[[0.2, -0.6], [0.8, 0.6]],
        robot__start=[0.5, -0.5, 90],
        goal=[0.5, 0.5, 90],
    )
    mesh = build_world(load_scene(write_scene(tmp_path, data))).mesh
    # The 2 x 1 x 0.05 m block, turned to lie along y, its centre moved to (0.5, 0).
    np.testing.assert_allclose(mesh.bounds, [[0, -1, 1], [1, 1, 1.05]], atol=1e-6)


@pytest.mark.parametrize("scale", [0, -0.001, "0.001", True, [1, 1], [1, 0, 1], [1, "a", 1], None])
def test_a_bad_scale_is_refused_with_the_key(tmp_path, box_stl, scale):
    path = write_scene(tmp_path, edited(terrain__0__scale=scale))
    with pytest.raises(SceneError) as err:
        load_scene(path)
    assert str(err.value).startswith(
        f"{path}: terrain[0].scale: expected a positive number (0.001 for a model in millimetres) "
        f"or a list of 3 positive numbers [x, y, z], got {scale!r}"
    )


def test_scaled_scene_scales_every_terrain_object_on_top_of_its_own_scale(tmp_path, box_stl):
    data = edited(terrain__0__scale=[1, 2, 1])
    data["terrain"].append({"mesh": "block.stl", "position": [3, 0, 0]})
    scene = scaled_scene(load_scene(write_scene(tmp_path, data)), 0.5)
    assert [o.scale for o in scene.terrain] == [(0.5, 1.0, 0.5), (0.5, 0.5, 0.5)]
    assert scene.terrain[1].position == (3.0, 0.0, 0.0)
    with pytest.raises(SceneError, match=r"--scale: expected a positive number"):
        scaled_scene(scene, -1.0)


@pytest.mark.slow
def test_scene_build_takes_scale_and_scad_timeout(tmp_path, millimetre_stl):
    path = write_scene(tmp_path, VALID)
    out = roachplan("scene", "build", str(path), "-o", str(tmp_path / "mm.stl"))
    assert out.returncode == 2
    assert "add `scale: 0.001` to this terrain object (or --scale 0.001)" in out.stderr
    out = roachplan(
        "scene",
        "build",
        str(path),
        "-o",
        str(tmp_path / "m.stl"),
        "--scale",
        "0.001",
        "--scad-timeout",
        "900",
    )
    assert out.returncode == 0, out.stderr
    mesh = trimesh.load_mesh(tmp_path / "m.stl")
    np.testing.assert_allclose(mesh.bounds, [[-0.5, -0.5, 0], [0.5, 0.5, 0.1]], atol=1e-6)
    for flag, value, expected in (
        ("--scale", "-1", "--scale: expected a positive number"),
        (
            "--scad-timeout",
            "1e9",
            "--scad-timeout: expected a number of seconds above 0 and at most 86400",
        ),
    ):
        out = roachplan("scene", "build", str(path), "-o", str(tmp_path / "x.stl"), flag, value)
        assert out.returncode == 2 and f"roachplan: error: {expected}" in out.stderr
        assert "Traceback" not in out.stderr


@pytest.mark.parametrize("inside_out", [False, True])
def test_solids_meeting_along_an_edge_are_wound_outward(inside_out):
    """Two blocks sharing an edge: closed, yet not watertight to trimesh, so its up and down
    faces cancel and the sign of their rounding noise once chose which way it faced."""
    from roachplan.scenes._mesh import clean_terrain_mesh

    a = trimesh.creation.box((0.2, 0.2, 0.1))
    b = trimesh.creation.box((0.2, 0.2, 0.1))
    b.apply_translation((0.2, 0.2, 0.0))
    pair = trimesh.util.concatenate([a, b])
    assert isinstance(pair, trimesh.Trimesh)
    if inside_out:
        pair.invert()
    out = clean_terrain_mesh(pair, "edge blocks")
    assert not out.is_watertight
    assert out.volume == pytest.approx(2 * 0.2 * 0.2 * 0.1)
    t = out.triangles  # (normals from the winding itself: trimesh's cache of them may lag it)
    up = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, 2] > 0
    assert np.allclose(out.triangles_center[up][:, 2], 0.05)  # the tops face up
