"""Depth cameras: calibration files (OpenCV, ROS CameraInfo, ORB-SLAM YAML), presets with their
depth scale, calibration beside the image, the camera's pose on the robot, 16-bit netpbm depth
images, size limits checked on the header, and depth-scale advice.

The real rtabmap depth PNG and its OpenCV calibration from ../shared/testdata/real; the other
files are written here by the real writers (Pillow, PyYAML, bytes as netpbm specifies them)."""

from __future__ import annotations

import shutil
import struct
import tracemalloc
import zlib
from typing import TypedDict

import numpy as np
import pytest
import yaml
from PIL import Image

from conftest import roachplan
from roachplan.perception import (
    PRESETS,
    CaptureError,
    capture_settings,
    depth_scale_advice,
    load_calibration,
    load_capture,
    load_intrinsics,
)
from test_perception import REAL

RTAB_PNG = REAL / "rtabmap" / "depth_154.png"
RTAB_YAML = REAL / "rtabmap" / "calib_154.yaml"
RTAB_K = {"fx": 525.0, "fy": 525.0, "cx": 319.5, "cy": 239.5}


def _raw_mm() -> np.ndarray:
    """The rtabmap frame's raw depth, (480, 640) uint16 millimetres."""
    with Image.open(RTAB_PNG) as im:
        return np.asarray(im).astype(np.uint16)


def _write_png16(path, depth: np.ndarray) -> None:
    Image.fromarray(depth.astype(np.uint16)).save(path)


class _PgmOptions(TypedDict, total=False):
    """_write_pgm's keyword arguments."""

    channels: int
    ascii_: bool
    comment: bool


def _write_pgm(
    path, depth: np.ndarray, *, channels: int = 1, ascii_: bool = False, comment: bool = True
) -> None:
    """netpbm as specified: magic, (comments,) width, height, maxval, one whitespace,
    big-endian 16-bit samples."""
    h, w = depth.shape
    magic = {(1, False): "P5", (1, True): "P2", (3, False): "P6", (3, True): "P3"}[
        (channels, ascii_)
    ]
    samples = np.repeat(depth[..., None], channels, axis=2).astype(np.uint16)
    if channels == 3:  # colour channels other than the first carry no depth
        samples[..., 1] = 7
        samples[..., 2] = 65535
    head = f"{magic}\n" + ("# written by test_cameras\n" if comment else "")
    head += f"{w} {h}\n65535\n"
    body = (
        (" ".join(map(str, samples.reshape(-1))) + "\n").encode()
        if ascii_
        else samples.astype(">u2").tobytes()
    )
    path.write_bytes(head.encode() + body)


# -- OpenCV calibration YAML and the camera's pose ------------------------------------------


def test_real_depth_png_with_its_opencv_calibration():
    cap = load_capture(RTAB_PNG, intrinsics=RTAB_YAML)
    k = cap.intrinsics
    assert k is not None
    assert (k.fx, k.fy, k.cx, k.cy, k.width, k.height) == (525, 525, 319.5, 239.5, 640, 480)
    assert cap.depth_scale == 1000  # no scale in the file: millimetres
    z = cap.finite_points()[:, 2]
    assert 1.0 < np.median(z) < 6.0  # metres, a room
    assert 0.3 < np.percentile(z, 1) and np.percentile(z, 99) < 12.0
    # local_transform: the camera 0.429 m above the base, optical y (image down) pointing down
    T = cap.base_from_camera
    assert T is not None
    assert T.shape == (4, 4) and np.allclose(T[3], (0, 0, 0, 1))
    assert abs(T[2, 3] - 0.4289) < 1e-3
    assert T[:3, 1] @ (0, 0, 1) < -0.99  # camera y in the base frame: down
    assert T[:3, 2] @ (1, 0, 0) > 0.99  # optical axis: the robot's forward
    assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
    # in the base frame the floor (the largest surface) lies at z = 0
    p_base = cap.finite_points() @ T[:3, :3].T + T[:3, 3]
    assert np.mean(np.abs(p_base[:, 2]) < 0.03) > 0.25


def test_opencv_yaml_without_pose_and_damaged_pose(tmp_path):
    text = RTAB_YAML.read_text()
    plain = tmp_path / "plain.yaml"
    plain.write_text(text.split("local_transform:")[0])
    cal = load_calibration(plain)
    assert cal.intrinsics.cx == 319.5 and cal.base_from_camera is None and cal.depth_scale is None
    assert load_intrinsics(plain) == cal.intrinsics  # the old entry point keeps its return
    # a local_transform that is no rotation is refused, naming the key
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        text.split("local_transform:")[0] + "local_transform:\n   rows: 3\n   cols: 4\n"
        "   data: [ 2., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0. ]\n"
    )
    with pytest.raises(CaptureError, match=r"bad\.yaml: local_transform: .*rotation"):
        load_calibration(bad)
    # no camera matrix at all: the file, what is missing, what is accepted
    empty = tmp_path / "other.yaml"
    empty.write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n")
    with pytest.raises(
        CaptureError, match=r"other\.yaml: no camera matrix: .*camera_matrix.*K or k"
    ):
        load_calibration(empty)


# -- ROS CameraInfo YAML ----------------------------------------------------------------------

CAMERA_INFO = {  # camera_calibration's ost.yaml layout
    "image_width": 848,
    "image_height": 480,
    "camera_name": "depth",
    "camera_matrix": {
        "rows": 3,
        "cols": 3,
        "data": [421.5, 0.0, 422.1, 0.0, 421.9, 241.3, 0.0, 0.0, 1.0],
    },
    "distortion_model": "plumb_bob",
    "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.0] * 5},
    "rectification_matrix": {"rows": 3, "cols": 3, "data": [1, 0, 0, 0, 1, 0, 0, 0, 1]},
    "projection_matrix": {
        "rows": 3,
        "cols": 4,
        "data": [421.5, 0, 422.1, 0, 0, 421.9, 241.3, 0, 0, 0, 1, 0],
    },
}


def test_ros_camera_info_yaml_both_forms(tmp_path):
    ost = tmp_path / "ost.yaml"
    ost.write_text(yaml.safe_dump(CAMERA_INFO))
    k = load_intrinsics(ost)
    assert (k.width, k.height, k.fx, k.fy, k.cx, k.cy) == (848, 480, 421.5, 421.9, 422.1, 241.3)
    # `rostopic echo` (ROS 1, K) of two messages, and `ros2 topic echo` (k)
    for key in ("K", "k"):
        msg = {
            "header": {"frame_id": "camera_depth_optical_frame"},
            "height": 480,
            "width": 848,
            "distortion_model": "plumb_bob",
            "D": [0.0] * 5,
            key: [421.5, 0.0, 422.1, 0.0, 421.9, 241.3, 0.0, 0.0, 1.0],
        }
        dump = tmp_path / f"info_{key}.yml"
        dump.write_text(
            yaml.safe_dump(msg) + "---\n" + yaml.safe_dump({**msg, "width": 1}) + "---\n"
        )
        assert load_intrinsics(dump) == k
    # a wrong matrix is named
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        yaml.safe_dump({**CAMERA_INFO, "camera_matrix": {"rows": 3, "cols": 3, "data": [1, 2, 3]}})
    )
    with pytest.raises(CaptureError, match=r"broken\.yaml: camera_matrix: expected a 3x3 matrix"):
        load_intrinsics(broken)


def test_orbslam_settings_carry_the_depth_scale(tmp_path):
    """ORB-SLAM's TUM1.yaml: %YAML:1.0, Camera.fx..., DepthMapFactor 5000, no image size."""
    f = tmp_path / "TUM1.yaml"
    f.write_text(
        "%YAML:1.0\n\n# Camera Parameters\nCamera.fx: 517.306408\nCamera.fy: 516.469215\n"
        "Camera.cx: 318.643040\nCamera.cy: 255.313989\nCamera.fps: 30.0\n"
        "DepthMapFactor: 5000.0\n"
    )
    cal = load_calibration(f, size=(640, 480))
    assert cal.depth_scale == 5000 and cal.intrinsics.cy == 255.313989
    assert (cal.intrinsics.width, cal.intrinsics.height) == (640, 480)
    with pytest.raises(CaptureError, match=r"TUM1\.yaml: intrinsics lack width, height"):
        load_calibration(f)  # no image to take the size from


# -- presets and the depth scale they carry -------------------------------------------------


def test_presets():
    assert PRESETS["primesense"] == PRESETS["kinect1"]
    assert (PRESETS["kinect1"].fx, PRESETS["kinect1"].cx, PRESETS["kinect1"].cy) == (
        525,
        319.5,
        239.5,
    )
    for w, h in ((1280, 720), (848, 480), (640, 480), (640, 360), (480, 270), (424, 240)):
        k = PRESETS[f"realsense-d435-{w}x{h}"]
        assert (k.width, k.height) == (w, h)
        fov = np.degrees(2 * np.arctan(w / 2 / k.fx))
        assert (85 < fov < 92) if w / h > 1.5 else (78 < fov < 82)  # D435: ~87x58 deg (16:9)
    assert PRESETS["tum-fr1"].fx == 517.3 and PRESETS["tum-fr3"].cy == 247.6
    assert load_calibration("tum-fr2").depth_scale == 5000
    assert load_calibration("kinect1").depth_scale is None  # millimetres, the default


def test_tum_image_at_5000_per_metre_and_the_advice_when_read_at_1000(tmp_path):
    mm = _raw_mm()
    tum = tmp_path / "1305031102.160407.png"  # TUM's file naming: a timestamp
    _write_png16(tum, mm.astype(np.int64) * 5)  # 5000 units per metre
    ref = load_capture(RTAB_PNG, intrinsics=RTAB_YAML)
    cap = load_capture(tum, intrinsics="tum-fr1")
    assert cap.depth_scale == 5000
    assert np.allclose(cap.points[:, 2], ref.points[:, 2], equal_nan=True, atol=1e-12)
    assert cap.intrinsics is not None and cap.intrinsics.fx == 517.3
    assert depth_scale_advice(cap, (0.3, 8.0)) is None
    # the same image read as millimetres: five times too far
    wrong = load_capture(tum, intrinsics="tum-fr1", depth_scale=1000)
    advice = depth_scale_advice(wrong, (0.3, 8.0))
    assert advice is not None
    assert "beyond 8 m at 1000 units per metre" in advice
    assert "depth scale of 5000 (TUM" in advice and "--depth-scale 5000" in advice
    frac = float(advice.split(" % of the measured")[0].rsplit(" ", 1)[-1])
    z = wrong.finite_points()[:, 2]
    assert abs(frac - 100 * np.mean(z > 8.0)) < 0.5 and frac > 50
    # point clouds get no advice; neither does a depth image read right
    assert depth_scale_advice(ref, (0.3, 8.0)) is None
    cloud = load_capture(REAL / "tutorials_region_growing_rgb_tutorial.pcd")
    assert cloud.depth_scale is None and depth_scale_advice(cloud, (0.3, 0.4)) is None


def test_depth_scale_so_wrong_the_capture_is_refused_says_which_scale(tmp_path):
    with pytest.raises(
        CaptureError,
        match=r"depth_154\.png: .* at 10 units per metre; .*"
        r"--depth-scale 1000",
    ):
        load_capture(RTAB_PNG, intrinsics=RTAB_YAML, depth_scale=10)


# -- calibration beside the image -------------------------------------------------------------


def test_sidecar_found_by_stem(tmp_path):
    png = tmp_path / "scan.png"
    shutil.copy(RTAB_PNG, png)
    with pytest.raises(
        CaptureError,
        match=r"needs intrinsics.*realsense-d435-848x480.*tum-fr1"
        r".*--fx --fy --cx --cy.*scan\.json, \.xml, \.yaml",
    ):
        load_capture(png)
    # an uploaded capture's scene file has the capture's stem: not a calibration, passed over
    (tmp_path / "scan.yaml").write_text(yaml.safe_dump({"terrain": [{"capture": "scan.png"}]}))
    with pytest.raises(CaptureError, match="needs intrinsics"):
        load_capture(png)
    shutil.copy(RTAB_YAML, tmp_path / "scan.yml")
    cap = load_capture(png)
    assert cap.intrinsics is not None and cap.intrinsics.cx == 319.5
    assert cap.base_from_camera is not None
    # the _depth rule: frame_depth.pgm finds frame.yaml
    pgm = tmp_path / "frame_depth.pgm"
    _write_pgm(pgm, _raw_mm())
    shutil.copy(RTAB_YAML, tmp_path / "frame.yaml")
    T = load_capture(pgm).base_from_camera
    assert T is not None and T[2, 3] == pytest.approx(0.4289, abs=1e-3)
    # intrinsics given: the sidecar JSON still gives the depth scale
    json_side = tmp_path / "tum.json"
    json_side.write_text('{"depth_scale": 5000, "fx": 1, "fy": 1, "cx": 1, "cy": 1}')
    _write_png16(tmp_path / "tum.png", _raw_mm().astype(np.int64) * 5)
    assert load_capture(tmp_path / "tum.png", intrinsics="kinect1").depth_scale == 5000


# -- 16-bit netpbm ------------------------------------------------------------------------------


def test_pgm_and_ppm_round_trip_to_the_png_points(tmp_path):
    ref = load_capture(RTAB_PNG, intrinsics=RTAB_YAML)
    mm = _raw_mm()
    files: list[tuple[str, _PgmOptions]] = [
        ("d.pgm", {}),
        ("a.pgm", {"ascii_": True}),
        ("c.ppm", {"channels": 3}),
        ("n.pgm", {"comment": False}),
    ]
    for name, kw in files:
        _write_pgm(tmp_path / name, mm, **kw)
        cap = load_capture(tmp_path / name, intrinsics=RTAB_YAML)
        assert cap.shape == (480, 640)
        np.testing.assert_array_equal(cap.points, ref.points)


def test_lying_or_bad_netpbm_headers_are_refused_without_allocating(tmp_path):
    bad = tmp_path / "bad.pgm"
    cases = [
        (b"P5\n60000 60000\n65535\n" + bytes(64), r"3600 megapixels.*at most 100 megapixels"),
        (b"P5\n9000 9000\n65535\n" + bytes(64), r"9000x9000x1 .* need 162000000 bytes, but 64"),
        (b"P6\n640 480\n65535\n" + bytes(640 * 480 * 2), r"need 1843200 bytes, but 614400"),
        (b"P2\n3000 3000\n65535\n1 2 3\n", r"need 17999999 bytes or more, but 6 follow"),
        (b"P5\n640 abc\n65535\n", r"bad netpbm header: expected width, height and maxval"),
        (b"P5\n640 480\n0\n", r"maxval 0 \(expected .*maxval 1-65535\)"),
        (b"P5\n4 4\n255\n" + bytes(16), r"8-bit netpbm image \(maxval 255\) has no depth"),
        (b"P7\nWIDTH 4\n", r"not a netpbm image"),
        (b"P5\n99999999999999 2\n65535\n", r"bad netpbm header"),
    ]
    for data, message in cases:
        bad.write_bytes(data)
        tracemalloc.start()
        with pytest.raises(CaptureError, match=r"bad\.pgm: .*" + message):
            load_capture(bad, intrinsics="kinect1")
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < 4_000_000, (data[:24], peak)  # bytes: nothing sized by the header


def test_png_over_the_pixel_limit_is_refused_before_decoding(tmp_path):
    """A PNG's IHDR may claim any size; the image data here is a few bytes."""
    ihdr = struct.pack(">IIBBBBB", 20000, 20000, 16, 0, 0, 0, 0)
    chunk = struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))
    idat = zlib.compress(b"\0" * 1000)
    data = (
        b"\x89PNG\r\n\x1a\n"
        + chunk
        + struct.pack(">I", len(idat))
        + b"IDAT"
        + idat
        + struct.pack(">I", zlib.crc32(b"IDAT" + idat))
    )
    big = tmp_path / "big.png"
    big.write_bytes(data)
    with pytest.raises(
        CaptureError,
        match=r"big\.png: the header says 20000x20000 pixels \(400 "
        r"megapixels\); .* at most 100 megapixels",
    ):
        load_capture(big, intrinsics="kinect1")
    truncated = tmp_path / "cut.png"
    truncated.write_bytes(RTAB_PNG.read_bytes()[:5000])
    with pytest.raises(CaptureError, match=r"cut\.png: cannot decode this PNG"):
        load_capture(truncated, intrinsics="kinect1")


# -- intrinsics as numbers: settings and the command line --------------------------------------


def test_intrinsics_mapping_in_capture_settings(tmp_path):
    s = capture_settings({"intrinsics": dict(RTAB_K)})
    cap = load_capture(RTAB_PNG, intrinsics=s.intrinsics)
    ref = load_capture(RTAB_PNG, intrinsics=RTAB_YAML)
    np.testing.assert_array_equal(cap.points, ref.points)
    assert hash(s)  # settings stay a frozen, hashable value
    sized = capture_settings({"intrinsics": {**RTAB_K, "width": 320, "height": 240}})
    half = load_capture(RTAB_PNG, intrinsics=sized.intrinsics)  # scaled up to the image
    assert half.intrinsics is not None
    assert half.intrinsics.fx == 1050 and half.intrinsics.width == 640
    for bad, message in (
        ({**RTAB_K, "fx": -1}, r"intrinsics\.fx: expected a number > 0"),
        ({**RTAB_K, "cy": "x"}, r"intrinsics\.cy: expected a number > 0"),
        ({"fx": 1, "fy": 1}, r"intrinsics: .*missing cx, cy"),
        ({**RTAB_K, "f": 1}, r"intrinsics: .*unknown f"),
        ({**RTAB_K, "width": 1.5}, r"intrinsics\.width: expected a whole"),
    ):
        with pytest.raises(CaptureError, match=message):
            capture_settings({"intrinsics": bad})


def test_cli_fx_fy_cx_cy_flags(tmp_path):
    png = tmp_path / "room.png"
    shutil.copy(RTAB_PNG, png)
    out = tmp_path / "room.stl"
    flags = ["--fx", "525", "--fy", "525", "--cx", "319.5", "--cy", "239.5"]
    r = roachplan("mesh", str(png), "-o", str(out), "--voxel", "0.03", *flags)
    assert r.returncode == 0, r.stderr
    assert out.is_file() and out.stat().st_size > 10_000
    r = roachplan("mesh", str(png), "-o", str(out), "--fx", "525", "--cy", "239.5")
    assert r.returncode == 2
    assert "roachplan: error: --fx --fy --cx --cy go together" in r.stderr
    assert "missing --fy --cx" in r.stderr and "Traceback" not in r.stderr
    r = roachplan("mesh", str(png), "-o", str(out), *flags[:-1], "-3")
    assert r.returncode == 2 and "--cy -3: expected a number of pixels > 0" in r.stderr
    r = roachplan("mesh", str(png), "-o", str(out), *flags, "--intrinsics", "kinect1")
    assert r.returncode == 2 and "either --intrinsics or --fx" in r.stderr


def test_a_preset_of_another_aspect_ratio_is_refused_naming_the_presets_that_fit(tmp_path):
    """A 640x480 image read with a Kinect v2 QHD preset (960x540, the page's default camera):
    the refusal names the presets of the image's size first, and the page says it in its own
    terms (the Camera choice), not as a command-line flag."""
    from roachplan.app._uploads import public_message

    png = tmp_path / "frame.png"
    shutil.copy(REAL / "frame_20121214T142255.814212_depth_mm.png", png)
    done = roachplan("mesh", str(png), "-o", str(tmp_path / "f.ply"), "--intrinsics", "kinect2-qhd")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "the image is 640x480, the intrinsics are for 960x540" in done.stderr
    fit = done.stderr.split("presets of 640x480: ", 1)[1].split(";", 1)[0].split(", ")
    assert fit and "primesense" in fit and "kinect2-qhd" not in fit
    page = public_message(done.stderr.removeprefix("roachplan: error: "), tmp_path)
    assert "--" not in page and "Camera (next capture)" in page, page
