"""Perception: real-format capture files in, terrain meshes out (Tong 2018, 3.1-3.2).

Real files from ../shared/testdata/real (PCL and ROS), files written here by the real writers
(pypcd4, rosbags, Pillow), and synthetic Kinect captures of known geometry."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TypedDict

import numpy as np
import pytest
import trimesh

from conftest import ROOT, roachplan
from roachplan.perception import (
    NO_NOISE,
    PRESETS,
    CaptureError,
    MeshingConfig,
    NoiseModel,
    capture_settings,
    load_capture,
    look_at,
    mesh_capture,
    reconstruct,
    render_depth,
    save_depth,
)


def _real_data() -> Path:
    """The project's real sensor files: $ROACHPLAN_TESTDATA, or ../shared/testdata/real beside
    the repository (the team's layout), or the workplace copy."""
    candidates = [
        os.environ.get("ROACHPLAN_TESTDATA"),
        ROOT.parent / "shared" / "testdata" / "real",
        "/work/shared/testdata/real",
    ]
    for c in candidates:
        if c and (Path(c) / "frame_20121214T142255.814212.pcd").is_file():
            return Path(c)
    raise RuntimeError(
        "the real test captures were not found: set ROACHPLAN_TESTDATA to the folder holding "
        f"frame_20121214T142255.814212.pcd (looked in {[str(c) for c in candidates if c]})"
    )


REAL = _real_data()
FRAME_PCD = REAL / "frame_20121214T142255.814212.pcd"
FRAME_PNG = REAL / "frame_20121214T142255.814212_depth_mm.png"
FRAME_XML = REAL / "frame_20121214T142255.814212.xml"
FLOOR_PCD = REAL / "tutorials_region_growing_rgb_tutorial.pcd"
WATERCAN_BAG = REAL / "jsk_watercan.bag"


class _Box(TypedDict):
    size: tuple[float, float, float]
    centre: tuple[float, float]


BOX: _Box = {"size": (0.30, 0.20, 0.15), "centre": (0.20, 0.10)}  # [m], on the floor at z = 0
EYE, TARGET = (-1.5, -1.0, 1.4), (0.0, 0.0, 0.0)


def box_scene() -> trimesh.Trimesh:
    floor = trimesh.creation.box((4.0, 4.0, 0.02))
    floor.apply_translation((0, 0, -0.01))
    sx, sy, sz = BOX["size"]
    box = trimesh.creation.box((sx, sy, sz))
    box.apply_translation((*BOX["centre"], sz / 2))
    return floor + box  # concatenated (Trimesh.__add__, typed where util.concatenate is not)


@pytest.fixture(scope="module")
def box_capture(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A noisy Kinect v2 QHD capture of the box on the floor, as a depth PNG + sidecar JSON."""
    out = tmp_path_factory.mktemp("capture") / "box.png"
    pose = look_at(EYE, TARGET)
    depth = render_depth(
        box_scene(), PRESETS["kinect2-qhd"], pose, NoiseModel(), np.random.default_rng(0)
    )
    save_depth(out, depth, PRESETS["kinect2-qhd"], world_from_camera=pose)
    return out, pose


# -- real files -----------------------------------------------------------------------------


def test_real_binary_compressed_pcd_is_read_organized():
    cap = load_capture(FRAME_PCD)
    assert cap.shape == (480, 640) and cap.points.shape == (307200, 3)
    assert cap.valid.sum() == 271575  # NaN marks the pixels without depth


def test_depth_png_with_pcl_xml_intrinsics_reproduces_the_real_cloud():
    png, pcd = load_capture(FRAME_PNG), load_capture(FRAME_PCD)  # the .xml is found beside it
    assert png.intrinsics is not None
    assert png.intrinsics.fx == 525 and png.intrinsics.cx == 320
    assert np.array_equal(png.valid, pcd.valid)
    assert np.max(np.abs(png.points[png.valid] - pcd.points[pcd.valid])) < 1e-6


def test_pcd_written_ascii_and_binary_reads_back(tmp_path):
    from pypcd4.pypcd4 import Encoding, PointCloud  # the package re-exports them implicitly

    src = load_capture(FLOOR_PCD)
    pts = src.points.astype(np.float32)
    for enc in (Encoding.ASCII, Encoding.BINARY):
        pc = PointCloud.from_xyz_points(pts)
        pc.metadata.width, pc.metadata.height = 640, 480
        path = tmp_path / f"floor_{enc.value}.pcd"
        pc.save(path, encoding=enc)
        assert (b"DATA ascii" if enc == Encoding.ASCII else b"DATA binary") in path.read_bytes()[
            :400
        ]
        back = load_capture(path)
        assert back.shape == (480, 640)
        assert np.array_equal(back.valid, src.valid)
        np.testing.assert_allclose(back.points[back.valid], src.points[src.valid], atol=1e-6)


def test_real_ros1_bag_pointcloud2():
    cap = load_capture(WATERCAN_BAG)
    assert len(cap.points) == 13966 and cap.valid.all() and cap.shape is None
    assert 0.3 < np.median(cap.points[:, 2]) < 3.0  # metres in front of the sensor


@pytest.mark.parametrize(("storage", "suffix"), [("SQLITE3", ".db3"), ("MCAP", ".mcap")])
def test_ros2_bag_written_here_with_an_organized_pointcloud2(tmp_path, storage, suffix):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    h, w = 4, 5
    pts = np.random.default_rng(1).uniform(0.5, 2.0, (h * w, 3)).astype(np.float32)
    pts[7] = np.nan
    header = T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="kinect"
    )
    # 16-byte points (x, y, z, padding), as drivers lay them out.
    data = np.zeros((h * w, 4), np.float32)
    data[:, :3] = pts
    msg = T["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=h,
        width=w,
        fields=[
            T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)
            for i, n in enumerate("xyz")
        ],
        is_bigendian=False,
        point_step=16,
        row_step=16 * w,
        data=data.view(np.uint8).reshape(-1),
        is_dense=False,
    )
    bag = tmp_path / "cloud_bag"
    with Writer(bag, version=8, storage_plugin=StoragePlugin[storage]) as writer:
        conn = writer.add_connection("/kinect2/qhd/points", msg.__msgtype__, typestore=ts)
        writer.write(conn, 1, ts.serialize_cdr(msg, msg.__msgtype__))
    cap = load_capture(next(bag.glob(f"*{suffix}")))
    assert cap.shape == (h, w)
    np.testing.assert_array_equal(cap.points[cap.valid], pts[~np.isnan(pts).any(axis=1)])
    assert not cap.valid[7]


def test_ros1_bag_written_here_with_a_depth_image_and_camera_info(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    png = load_capture(FRAME_PNG)
    from PIL import Image

    depth_mm = np.asarray(Image.open(FRAME_PNG), dtype=np.uint16)
    header = T["std_msgs/msg/Header"](
        seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="depth"
    )
    img = T["sensor_msgs/msg/Image"](
        header=header,
        height=480,
        width=640,
        encoding="16UC1",
        is_bigendian=0,
        step=1280,
        data=depth_mm.view(np.uint8).reshape(-1),
    )
    info = T["sensor_msgs/msg/CameraInfo"](
        header=header,
        height=480,
        width=640,
        distortion_model="plumb_bob",
        D=np.zeros(5),
        K=np.array([525.0, 0, 320, 0, 525, 240, 0, 0, 1]),
        R=np.eye(3).ravel(),
        P=np.zeros(12),
        binning_x=0,
        binning_y=0,  # ROS 1 spells them D, K, R, P
        roi=T["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        ),
    )
    bag = tmp_path / "depth.bag"
    with Writer(bag) as writer:
        for topic, msg in (("/camera/depth/image_raw", img), ("/camera/depth/camera_info", info)):
            conn = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
            writer.write(conn, 1, ts.serialize_ros1(msg, msg.__msgtype__))
    cap = load_capture(bag)
    assert cap.shape == (480, 640)
    np.testing.assert_allclose(cap.points[cap.valid], png.points[png.valid], atol=1e-9)


def test_organized_npy_and_text_formats(tmp_path):
    src = load_capture(FRAME_PCD)
    np.save(tmp_path / "cloud.npy", src.points.reshape(480, 640, 3))
    assert load_capture(tmp_path / "cloud.npy").shape == (480, 640)
    pts = src.finite_points()[:500]
    np.savetxt(tmp_path / "cloud.xyz", pts)
    (tmp_path / "cloud.pts").write_text(f"{len(pts)}\n" + (tmp_path / "cloud.xyz").read_text())
    for name in ("cloud.xyz", "cloud.pts"):
        np.testing.assert_allclose(load_capture(tmp_path / name).points, pts, atol=1e-9)
    trimesh.PointCloud(pts).export(tmp_path / "cloud.ply")
    np.testing.assert_allclose(load_capture(tmp_path / "cloud.ply").points, pts, atol=1e-6)


# -- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("empty.xyz", b"", "has no points"),
        ("nan.xyz", b"nan nan nan\nnan nan nan\n", "every point is invalid"),
        ("fake.pcd", b"\x89PNG\r\n\x1a\nnot a cloud", "not a PCD file"),
        ("fake.png", b"VERSION 0.7\nFIELDS x y z\n", "not a PNG file"),
        ("fake.npy", b"x y z\n1 2 3\n", "not a NumPy .npy file"),
        ("mm.xyz", b"100 200 1500\n-300 50 2400\n10 20 1800\n", "looks like millimetres"),
        ("words.xyz", b"a b c\n", "expected lines of 'x y z"),
        ("cloud.las", b"LASF", "unknown capture type '.las'"),
    ],
)
def test_bad_captures_get_clear_errors(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(CaptureError, match=message) as err:
        load_capture(path)
    assert str(path) in str(err.value)


def test_all_zero_depth_png_and_missing_intrinsics(tmp_path):
    from PIL import Image

    Image.fromarray(np.zeros((424, 512), np.uint16)).save(tmp_path / "zero.png")
    with pytest.raises(CaptureError, match="needs intrinsics"):
        load_capture(tmp_path / "zero.png")
    with pytest.raises(CaptureError, match="every pixel is 0"):
        load_capture(tmp_path / "zero.png", intrinsics="kinect2-sd")
    Image.fromarray(np.zeros((424, 512), np.uint8)).save(tmp_path / "gray8.png")
    with pytest.raises(CaptureError, match="16-bit"):
        load_capture(tmp_path / "gray8.png", intrinsics="kinect2-sd")


def test_mm_cloud_loads_with_units_mm(tmp_path):
    (tmp_path / "mm.xyz").write_text("100 200 1500\n-300 50 2400\n10 20 1800\n")
    cap = load_capture(tmp_path / "mm.xyz", units="mm")
    np.testing.assert_allclose(cap.points[0], [0.1, 0.2, 1.5])


def test_mesh_cli_leaves_nothing_half_written_on_error(tmp_path):
    bad = tmp_path / "empty.xyz"
    bad.write_text("")
    out = tmp_path / "terrain.stl"
    done = roachplan("mesh", str(bad), "-o", str(out))
    assert done.returncode == 2 and "has no points" in done.stderr
    assert not out.exists() and not list(tmp_path.glob(".*part"))
    done = roachplan("mesh", str(FRAME_PCD), "-o", str(out), "--voxel", "0.01,0.02")
    assert done.returncode == 2 and "--voxel" in done.stderr and not out.exists()


# -- geometry ---------------------------------------------------------------------------------


def _to_true_world(rec, pose_true: np.ndarray) -> np.ndarray:
    """Mesh vertices mapped from the reconstruction's world frame to the scene's."""
    a = pose_true @ np.linalg.inv(rec.world_from_camera)
    v = rec.mesh.vertices
    return v @ a[:3, :3].T + a[:3, 3]


@pytest.mark.parametrize("given_pose", [False, True])
def test_box_on_floor_is_meshed_where_it_is(box_capture, given_pose):
    """Box position and height within the voxel size (1 cm), ground plane at z = 0."""
    path, pose = box_capture
    from scipy.spatial.transform import Rotation

    cfg = MeshingConfig()
    if given_pose:
        q = Rotation.from_matrix(pose[:3, :3]).as_quat()
        cfg = MeshingConfig(camera_pose=(*pose[:3, 3], *q))
    rec = reconstruct(load_capture(path), cfg)
    v = rec.mesh.vertices if given_pose else _to_true_world(rec, pose)
    voxel = cfg.voxel[0]
    # The recovered world frame has the floor at z = 0 in its own frame too.
    floor_own = rec.mesh.vertices[np.abs(rec.mesh.vertices[:, 2]) < 0.05][:, 2]
    assert abs(np.median(floor_own)) < 0.003
    sx, sy, sz = BOX["size"]
    top = v[v[:, 2] > sz - voxel]  # the top surface
    (cx, cy) = BOX["centre"]
    assert abs(np.median(top[:, 2]) - sz) < voxel
    assert (
        abs(top[:, 0].min() - (cx - sx / 2)) < voxel
        and abs(top[:, 0].max() - (cx + sx / 2)) < voxel
    )
    assert (
        abs(top[:, 1].min() - (cy - sy / 2)) < voxel
        and abs(top[:, 1].max() - (cy + sy / 2)) < voxel
    )
    # Nothing stands above the box or rises elsewhere (beyond the flying pixels the sensor
    # leaves along its edges, within two voxels of it).
    assert v[:, 2].max() < sz + voxel
    m = 2 * voxel
    outside = (np.abs(v[:, 0] - cx) > sx / 2 + m) | (np.abs(v[:, 1] - cy) > sy / 2 + m)
    assert np.all(v[outside, 2] < 0.02)


@pytest.mark.parametrize("method", ["sensor", "grid", "poisson", "ball-pivot"])
def test_every_facet_faces_the_camera(box_capture, method):
    """Section 3.2: <x_i, n_i> <= 0 in camera coordinates, for every facet; and (a height
    field) every facet faces up in the world."""
    path, _ = box_capture
    rec = reconstruct(load_capture(path), MeshingConfig(method=method, voxel=(0.02, 0.02, 0.02)))
    m = rec.mesh
    cam_from_world = np.linalg.inv(rec.world_from_camera)
    centres = m.triangles_center @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    normals = m.face_normals @ cam_from_world[:3, :3].T
    assert len(m.faces) > 1000
    assert np.all(np.einsum("ij,ij->i", centres, normals) <= 1e-9)
    if method == "grid":
        assert np.all(m.face_normals[:, 2] > 0)


@pytest.mark.parametrize("method", ["sensor", "grid"])
def test_the_mesh_does_not_bridge_the_shadow_behind_the_box(box_capture, method):
    """The floor the box hides from the camera stays open rather than being spanned."""
    path, pose = box_capture
    rec = reconstruct(load_capture(path), MeshingConfig(method=method))
    v = _to_true_world(rec, pose)
    eye = np.asarray(EYE)
    # A point on the floor just behind the box, along the line of sight over its far top edge.
    behind = np.array([BOX["centre"][0] + 0.2, BOX["centre"][1] + 0.2])
    d = np.linalg.norm(v[:, :2] - behind, axis=1)
    assert d.min() > 0.03, "the shadow behind the box was filled in"
    assert np.linalg.norm(behind - eye[:2]) > np.linalg.norm(np.asarray(BOX["centre"]) - eye[:2])


# -- voxel study, scene, CLI --------------------------------------------------------------------


def test_voxel_study_of_a_wall_at_6_m(tmp_path):
    """Table 3.1's setup: a wall 6 m in front, a 2 m x 2 m square of it. Bigger voxels keep
    fewer points; the iterative 5-sigma fit discards injected gross outliers."""
    from roachplan.perception._voxel_study import voxel_study

    wall = trimesh.creation.box((4.0, 0.05, 4.0))
    wall.apply_translation((0, 6.025, 0))
    intr = PRESETS["kinect2-qhd"]
    depth = render_depth(
        wall, intr, look_at((0, 0, 0), (0, 6, 0)), NoiseModel(), np.random.default_rng(3)
    )
    save_depth(tmp_path / "wall.png", depth, intr)
    done = roachplan(
        "voxel-study",
        str(tmp_path / "wall.png"),
        "--square",
        "2",
        "--csv",
        str(tmp_path / "study.csv"),
    )
    assert done.returncode == 0, done.stderr
    rows = [r.split(",") for r in (tmp_path / "study.csv").read_text().splitlines()[1:]]
    points = [int(r[1]) for r in rows]
    assert [r[0] for r in rows] == ["", "1.0", "2.0", "5.0", "10.0", "20.0"]
    assert points == sorted(points, reverse=True) and points[-1] < points[0] / 50
    sigma_6m = 1.5 - 0.5 * 6 + 0.3 * 36  # the noise model's axial sigma at 6 m [mm]
    assert abs(float(rows[0][3]) - sigma_6m) < 1.0
    cap = load_capture(tmp_path / "wall.png")
    pts = cap.finite_points()
    pts = pts[(np.abs(pts[:, 0]) <= 1) & (np.abs(pts[:, 1]) <= 1)]
    bad = pts[:100] + np.array([0, 0, 0.5])  # 100 points 50 cm off the wall
    raw = voxel_study(np.vstack([pts, bad]), [])[0]
    assert raw.points == len(pts) + 100 and raw.kept <= len(pts)


def test_kinect_bridge_scene_matches_the_model_it_was_captured_from():
    """The shipped synthetic capture, through the pipeline, puts the plank where the model has
    it: top at 12 cm, along x."""
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene("kinect_bridge"))
    hf = world.heightfield
    on_plank = np.array([[x, y] for x in np.linspace(-0.35, 0.35, 15) for y in (-0.08, 0, 0.08)])
    np.testing.assert_allclose(hf.sample(on_plank), 0.12, atol=0.01)
    floor = np.array([[x, -0.4] for x in np.linspace(-1.0, 1.0, 9)])
    np.testing.assert_allclose(hf.sample(floor), 0.0, atol=0.01)
    side = json.loads((ROOT / "scenes" / "library" / "kinect_bridge_depth.json").read_text())
    assert side["width"] == 960 and side["depth_scale"] == 1000


def test_mesh_cli_on_the_real_depth_png(tmp_path):
    out = tmp_path / "desk.stl"
    done = roachplan("mesh", str(FRAME_PNG), "-o", str(out), "--voxel", "0.02")
    assert done.returncode == 0, done.stderr
    mesh = trimesh.load_mesh(out)
    assert len(mesh.faces) > 1000
    rec = mesh_capture(FRAME_PNG, capture_settings({"voxel": 0.02}))
    camera = rec.world_from_camera[:3, 3]  # every facet faces it (section 3.2)
    toward = np.einsum("ij,ij->i", mesh.triangles_center - camera, mesh.face_normals)
    assert np.all(toward <= 1e-9)
    assert "camera pose in the world" in done.stdout
    assert all(stage in done.stdout for stage in ("voxel", "outliers", "ground", "mesh"))


def test_synth_capture_cli_is_seeded(tmp_path):
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    for out in (a, b):
        done = roachplan(
            "synth-capture",
            "plywood_bridge",
            "-o",
            str(out),
            "--eye",
            "0,-2.2,1.5",
            "--target",
            "0,0,0",
            "--intrinsics",
            "kinect2-sd",
            "--seed",
            "4",
        )
        assert done.returncode == 0, done.stderr
    np.testing.assert_array_equal(np.load(a), np.load(b))


def test_noise_free_render_measures_the_true_depth():
    """Depth along the optical axis of pixels that see the floor: where their ray meets z = 0."""
    intr = PRESETS["kinect2-sd"]
    pose = look_at(EYE, TARGET)
    depth = render_depth(box_scene(), intr, pose, NO_NOISE)
    for u, v in ((256, 212), (40, 400), (480, 300)):
        ray = pose[:3, :3] @ np.array([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, 1.0])
        assert depth[v, u] == pytest.approx(-EYE[2] / ray[2], abs=1e-4)
