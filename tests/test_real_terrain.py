"""Real captures nobody here wrote become plannable scenes, with the ground found right
(issue 14): the ground facts of ../shared/testdata/real/README.md, `mesh --json`, each floor
capture used directly as a scene that plans and drives, world-frame and georeferenced clouds,
and scenes without a start or goal."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from conftest import roachplan
from test_perception import REAL

RTAB = REAL / "rtabmap"
# file, extra `mesh` flags, README's up in the camera frame, README's camera height [m]
GROUND_FACTS = [
    ("tutorials_region_growing_rgb_tutorial.pcd", (), (0.06, -0.84, -0.53), 0.80),
    ("table_scene_mug_stereo_textured.pcd", (), (0.02, -0.84, -0.54), 0.53),
    ("tutorials_pairwise_capture0002.pcd", (), (-0.01, -1.00, -0.07), 0.85),
    (
        "rtabmap/depth_154.png",
        ("--intrinsics", str(RTAB / "calib_154.yaml")),
        (0.01, -1.00, 0.06),
        0.42,
    ),
    ("frame_20121214T142255.814212.pcd", (), (0.07, -0.69, -0.72), 0.72),
    ("office_desk_160x120.pcd", (), (-0.10, -0.92, -0.39), 1.25),
]
# file, least start-goal distance picked [m]: a room's or the ground's 1 m; a table's or a
# desk's 0.5 m, or what the captured surface holds (its README: the mug's table is seen over
# 0.5 m x 0.4 m, the mug in its middle; the office's floor is a strip 1 m long in front of
# the desks)
SCENE_CAPTURES = [
    ("tutorials_region_growing_rgb_tutorial.pcd", 1.0),
    ("tutorials_pairwise_capture0002.pcd", 1.0),
    ("rtabmap/depth_154.png", 1.0),
    ("rough_ground_ouster_4x4m.pcd", 1.0),
    ("frame_20121214T142255.814212.pcd", 0.5),
    ("office_desk_160x120.pcd", 0.5),
    ("table_scene_mug_stereo_textured.pcd", 0.25),
]


def _mesh_json(tmp_path, name: str, *flags: str) -> dict:
    out = tmp_path / "out.ply"
    done = roachplan("mesh", str(REAL / name), "-o", str(out), "--json", *flags)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    report = json.loads(done.stdout)
    assert out.is_file()
    return report


@pytest.mark.parametrize(
    ("name", "flags", "up", "height"), GROUND_FACTS, ids=[g[0] for g in GROUND_FACTS]
)
def test_the_ground_found_matches_the_measured_ground(tmp_path, name, flags, up, height):
    """Within 5 deg and 3 cm of the README's plane, although on the staircase room the wall
    has three times the floor's points and on the table capture a background surface has
    twice the table's."""
    r = _mesh_json(tmp_path, name, *flags)
    n = np.asarray(r["ground"]["normal_in_capture_frame"])
    angle = math.degrees(math.acos(np.clip(n @ (np.asarray(up) / np.linalg.norm(up)), -1, 1)))
    assert angle <= 5.0, (angle, n)
    assert abs(r["camera_height_m"] - height) <= 0.03
    pose = r["camera_pose"]
    assert len(pose) == 7 and pose[2] == pytest.approx(r["camera_height_m"], abs=1e-3)
    assert np.linalg.norm(pose[3:]) == pytest.approx(1.0, abs=1e-6)
    assert r["triangles"] > 1000 and isinstance(r["warnings"], list)
    # The camera's height and tilt agree with the up vector found.
    assert r["pitch_down_deg"] == pytest.approx(math.degrees(math.asin(-n[2])), abs=0.5)


def test_the_calibrations_camera_pose_is_the_gravity_prior(tmp_path):
    r = _mesh_json(tmp_path, "rtabmap/depth_154.png", "--intrinsics", str(RTAB / "calib_154.yaml"))
    assert "calibration" in r["up_source"]


def test_an_up_override_turns_the_choice(tmp_path):
    """Told that up is the camera's -z (looking straight down), the pipeline takes the back
    wall of the staircase room as the ground, and says it was given."""
    r = _mesh_json(tmp_path, "tutorials_pairwise_capture0002.pcd", "--up", "0,0,-1")
    n = np.asarray(r["ground"]["normal_in_capture_frame"])
    assert n[2] < -0.9 and r["up_source"].startswith("given")


def test_clicking_a_point_on_a_surface_makes_it_the_ground(tmp_path):
    """--ground-point (the page's re-levelling click) beats the gravity prior: a point on the
    staircase room's back wall makes the wall the ground; a point on the floor, the floor."""
    name = "tutorials_pairwise_capture0002.pcd"
    wall = _mesh_json(tmp_path, name, "--up", "0,0,-1")
    n, h = np.asarray(wall["ground"]["normal_in_capture_frame"]), wall["camera_height_m"]
    point = ",".join(f"{v:.4f}" for v in -h * n)
    picked = _mesh_json(tmp_path, name, f"--ground-point={point}")
    assert np.asarray(picked["ground"]["normal_in_capture_frame"]) @ n > 0.99
    floor = _mesh_json(tmp_path, name)
    n, h = np.asarray(floor["ground"]["normal_in_capture_frame"]), floor["camera_height_m"]
    q = np.array([0.0, h, 2.0])  # 2 m ahead of the camera, then onto the floor plane
    point = ",".join(f"{v:.4f}" for v in q - (n @ q + h) * n)
    back = _mesh_json(tmp_path, name, f"--ground-point={point}")
    assert back["camera_height_m"] == pytest.approx(h, abs=0.01)


def test_an_airborne_lidar_in_utm_is_recentred_not_taken_for_millimetres(tmp_path):
    r = _mesh_json(tmp_path, "terrain_samp11-utm.pcd")
    assert r["frame"] == "world" and r["camera_pose"] is None
    east, north, _ = r["origin_in_capture_frame"]
    assert 4e5 < east < 6e5 and 5e6 < north < 6e6
    (x0, y0, _), (x1, y1, _) = r["bounds"]
    assert x0 < 0 < x1 and y0 < 0 < y1 and max(x1 - x0, y1 - y0) < 1000
    assert any("recentred" in n for n in r["notes"])


def test_long_range_lidar_in_metres_is_not_millimetres(tmp_path):
    """A 360-degree lidar sweep in metres (median range ~56 m, points behind the sensor) is a
    z-up world frame; the same sweep in millimetres is refused with the advice to say so."""
    rng = np.random.default_rng(0)
    az = rng.uniform(-np.pi, np.pi, 40000)
    rad = rng.uniform(5.0, 110.0, 40000)
    pts = np.column_stack(
        [rad * np.cos(az), rad * np.sin(az), -1.8 + 0.02 * rng.standard_normal(40000)]
    )
    m = tmp_path / "sweep_m.xyz"
    np.savetxt(m, pts, fmt="%.4f")
    r = _mesh_json(tmp_path, str(m), "--voxel", "0.2")
    assert r["frame"] == "world" and r["ground"] is not None
    mm = tmp_path / "sweep_mm.xyz"
    np.savetxt(mm, pts * 1000, fmt="%.1f")
    done = roachplan("mesh", str(mm), "-o", str(tmp_path / "x.ply"))
    assert done.returncode == 2 and "--units mm" in done.stderr and "Traceback" not in done.stderr
    ok = roachplan(
        "mesh", str(mm), "-o", str(tmp_path / "x.ply"), "--units", "mm", "--voxel", "0.2"
    )
    assert ok.returncode == 0, ok.stderr


def test_mesh_refuses_to_overwrite_its_input(tmp_path):
    src = tmp_path / "cloud.ply"
    src.write_bytes((REAL / "tutorials_pairwise_capture0002.pcd").read_bytes()[:0] + b"ply\n")
    before = src.read_bytes()
    done = roachplan("mesh", str(src), "-o", str(src))
    assert done.returncode == 2 and "overwrite" in done.stderr
    assert src.read_bytes() == before


@pytest.mark.parametrize(("name", "least"), SCENE_CAPTURES, ids=[c[0] for c in SCENE_CAPTURES])
def test_a_capture_with_a_floor_or_table_is_a_scene_that_plans_and_drives(tmp_path, name, least):
    """`roachplan trial --scene CAPTURE`: start and goal picked at least `least` apart in the
    largest region the robot can stand in, a plan joins them, and the roach drives it."""
    capture = REAL / name
    if name.endswith(".png"):  # its calibration has another stem: a scene file names it
        scene = tmp_path / "depth.yaml"
        scene.write_text(
            yaml.safe_dump(
                {
                    "terrain": [
                        {
                            "capture": str(capture),
                            "perception": {"intrinsics": str(RTAB / "calib_154.yaml")},
                        }
                    ],
                    "ground": None,
                }
            )
        )
        capture = scene
    done = roachplan("trial", "--scene", str(capture), "--json", timeout=600)
    assert done.returncode == 0, done.stderr
    r = json.loads(done.stdout)
    assert r["path_found"]
    assert math.dist(r["start"][:2], r["goal"][:2]) >= least
    assert r["outcome"] == "success", r["reason"]
    # Route labels name obstacles the robot could go round, not the capture's noise (26 holes
    # on one room before): a few at most on a room's floor.
    assert r["route"] == "direct" or r["route"].count("h") <= 4, r["route"]


def test_a_scene_file_may_omit_start_goal_and_bounds(tmp_path):
    """The picked poses are valid, joined, and the same on every build (workers rebuild it)."""
    from roachplan.scenes import build_world, load_scene, pose_problem

    scene = tmp_path / "floor.yaml"
    scene.write_text(
        yaml.safe_dump({"terrain": [{"scad": str(tmp_path / "slab.scad")}], "ground": None})
    )
    (tmp_path / "slab.scad").write_text("translate([-1.5, -0.4, -0.02]) cube([3, 0.8, 0.02]);")
    a, b = build_world(load_scene(scene)), build_world(load_scene(scene))
    assert a.scene.start == b.scene.start and a.scene.goal == b.scene.goal
    start, goal = a.scene.start, a.scene.goal
    assert start is not None and goal is not None  # picked when the world was built
    assert pose_problem(a, start) == "" and pose_problem(a, goal) == ""
    assert math.dist(start[:2], goal[:2]) >= 2.0  # along the 3 m slab
    assert any("picked automatically" in n for n in a.notes)


def test_nowhere_to_stand_is_a_clear_error(tmp_path):
    scene = tmp_path / "spikes.scad"
    scene.write_text(
        "for (i = [0:20]) for (j = [0:20]) translate([i * 0.05, j * 0.05, 0]) "
        "cylinder(h = 0.3, r = 0.01, $fn = 6);"
    )
    y = tmp_path / "spikes.yaml"
    y.write_text(yaml.safe_dump({"terrain": [{"scad": "spikes.scad"}], "ground": None}))
    done = roachplan("trial", "--scene", str(y))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "stand nowhere" in done.stderr or "could not pick" in done.stderr


def test_a_millimetre_model_as_a_scene_is_refused_then_scaled(tmp_path):
    scad = tmp_path / "slab.scad"
    scad.write_text("translate([-1500, -300, -20]) cube([3000, 600, 20]);")
    done = roachplan("trial", "--scene", str(scad))
    assert done.returncode == 2 and "scale: 0.001" in done.stderr and "Traceback" not in done.stderr
    done = roachplan("trial", "--scene", str(scad), "--scale", "0.001", "--json")
    assert done.returncode == 0, done.stderr
    r = json.loads(done.stdout)
    assert r["outcome"] == "success" and math.dist(r["start"][:2], r["goal"][:2]) >= 1.0


def _tilted_room_bag(path, with_imu: bool) -> np.ndarray:
    """A ROS 2 bag (MCAP) from a sensor mounted 75 degrees off level, in its own frame (not an
    optical one): a 2 m x 2 m floor, and a 2 m x 1 m wall standing on it whose normal lies 15
    degrees from the frame's z axis, so that "z is up" would take the wall for the ground. With
    with_imu, an Imu topic reads gravity's reaction along the floor's normal. Returns that
    normal (the sensor frame's true up)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    a = np.radians(75.0)
    rot = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    u, v = np.meshgrid(np.arange(-1, 1, 0.02), np.arange(-1, 1, 0.02))
    floor = np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)])
    wu, wh = np.meshgrid(np.arange(-1, 1, 0.02), np.arange(0.02, 1, 0.02))
    wall = np.column_stack([wu.ravel(), np.full(wu.size, 1.0), wh.ravel()])  # the y = 1 side
    pts = ((np.vstack([floor, wall]) - [0, 0, 1.2]) @ rot.T).astype(np.float32)
    up = rot @ np.array([0.0, 0.0, 1.0])
    header = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="sensor"
    )
    cloud = T["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=1,
        width=len(pts),
        fields=[
            T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)
            for i, n in enumerate("xyz")
        ],
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(pts),
        data=pts.view(np.uint8).reshape(-1),
        is_dense=True,
    )
    vec = T["geometry_msgs/msg/Vector3"]
    quat = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    rng = np.random.default_rng(0)
    with Writer(path, version=8, storage_plugin=StoragePlugin["MCAP"]) as writer:
        c = writer.add_connection("/points", cloud.__msgtype__, typestore=ts)
        writer.write(c, 1, ts.serialize_cdr(cloud, cloud.__msgtype__))
        if with_imu:
            i = writer.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
            for k in range(20):
                acc = 9.81 * up + rng.normal(0, 0.05, 3)  # at rest: the reaction to gravity
                msg = T["sensor_msgs/msg/Imu"](
                    header=header,
                    orientation=quat,
                    orientation_covariance=np.zeros(9),
                    angular_velocity=vec(x=0.0, y=0.0, z=0.0),
                    angular_velocity_covariance=np.zeros(9),
                    linear_acceleration=vec(x=float(acc[0]), y=float(acc[1]), z=float(acc[2])),
                    linear_acceleration_covariance=np.zeros(9),
                )
                writer.write(i, 2 + k, ts.serialize_cdr(msg, msg.__msgtype__))
    return up


@pytest.mark.parametrize("with_imu", [True, False])
def test_a_bags_imu_gives_up_and_the_floor_not_the_wall_is_the_ground(tmp_path, with_imu):
    _tilted_room_bag(tmp_path / "room", with_imu)
    bag = next((tmp_path / "room").glob("*.mcap"))
    done = roachplan("mesh", str(bag), "-o", str(tmp_path / "room.stl"), "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    ground = report.get("ground") or {}
    # The floor has 10,000 points, the wall 4,900: the ground's support says which was taken.
    if with_imu:
        assert report["up_source"] == "the IMU" and any("IMU" in n for n in report["notes"])
        assert ground.get("support_points", 0) > 9000, report
    else:  # the frame's z is 75 degrees off the true up: the floor is not the ground found
        assert report["up_source"] != "the IMU"
        assert ground.get("support_points", 0) < 9000, report


def test_a_capture_is_a_scene_for_plan_and_for_an_experiment_spec(tmp_path):
    """Wherever a scene is taken, a capture file works directly: `plan --scene CAPTURE` plans
    between the picked start and goal, and an experiment spec whose scene is the capture runs
    trials on it (start and goal picked the same way in every worker)."""
    capture = REAL / "tutorials_region_growing_rgb_tutorial.pcd"
    planned = roachplan("plan", "--scene", str(capture), "--json", timeout=600)
    assert planned.returncode == 0, planned.stderr
    r = json.loads(planned.stdout)
    assert len(r["path"]) >= 2 and "picked automatically" in planned.stderr
    spec = tmp_path / "room.yaml"
    spec.write_text(yaml.safe_dump({"scene": str(capture), "trials_per_route": 2, "seed": 0}))
    out = tmp_path / "results"
    done = roachplan(
        "experiment",
        str(spec),
        "--trials",
        "2",
        "--workers",
        "1",
        "--out",
        str(out),
        "--repeats",
        "0",
        "--quiet",
        timeout=900,
    )
    assert done.returncode == 0, done.stderr
    records = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    trials = [t for t in records if t.get("kind") == "trial"]
    assert len(trials) == 2 and all(t["path_found"] for t in trials)
    for t in trials:  # the same pick as `plan` made (plan --json rounds to 0.01 mm)
        assert np.allclose(t["start"], r["states"][0], atol=1e-5)


def test_a_world_frame_cloud_given_as_such_and_a_depth_range(tmp_path):
    """--frame world takes a cloud as z up already (no camera, no gravity guess); --depth-range
    keeps only the points at those distances from the sensor."""
    rng = np.random.default_rng(1)
    xy = rng.uniform(-2.0, 2.0, (30000, 2))
    floor = np.column_stack([xy, 0.003 * rng.standard_normal(30000)])
    cloud = tmp_path / "floor_world.xyz"
    np.savetxt(cloud, floor, fmt="%.4f")
    r = _mesh_json(tmp_path, str(cloud), "--frame", "world", "--voxel", "0.05")
    assert r["frame"] == "world" and r["camera_pose"] is None
    (x0, y0, z0), (x1, y1, z1) = r["bounds"]
    assert x1 - x0 > 3.5 and y1 - y0 > 3.5 and z1 - z0 < 0.05  # flat, as given
    depth = RTAB / "depth_154.png"
    calib = ("--intrinsics", str(RTAB / "calib_154.yaml"))
    full = _mesh_json(tmp_path, "rtabmap/depth_154.png", *calib)
    near = _mesh_json(tmp_path, str(depth), *calib, "--depth-range", "0.3,2.0")
    assert near["counts"]["depth range"] < full["counts"]["depth range"]
    assert near["bounds"][1][1] - near["bounds"][0][1] < full["bounds"][1][1] - full["bounds"][0][1]
