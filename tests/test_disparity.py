"""Raw Kinect v1 disparity in a depth image (NYU Depth v2's raw PGM dumps: 11 bits, 2047 = no
reading): recognised by its values and converted with NYU's model, or refused naming disparity
and the settings that say what it is; real depth images in millimetres are never taken for it.

The disparity images are derived from a real depth PNG (millimetres) with the inverse model, so
the converted depth can be checked against the original to the model's quantisation: one
disparity step, i.e. |351.3 / z' - 351.3 / z| <= 0.5."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from roachplan.perception import CaptureError, capture_settings, load_capture, mesh_capture
from test_perception import REAL

A, B = 351.3, 1092.5  # NYU Depth v2's model: depth [m] = A / (B - d)
RTAB = REAL / "rtabmap"
CALIB = str(RTAB / "calib_154.yaml")


def depth_mm(path) -> np.ndarray:
    return np.asarray(Image.open(path)).astype(np.float64)


def disparity_of(mm: np.ndarray) -> np.ndarray:
    """Depth [mm] (0 = none) -> raw Kinect disparity (2047 = none), rounded to whole steps."""
    z = mm / 1000.0
    d = np.round(B - A / np.where(z > 0, z, 1.0))
    return np.where(z > 0, d, 2047).astype(np.uint16)


def write_pgm(path, raw: np.ndarray, *, maxval: int = 65535, little_endian: bool = False):
    """A binary 16-bit PGM; little_endian: as some tools write it, against netpbm's rule."""
    h, w = raw.shape
    data = raw.astype("<u2" if little_endian else ">u2").tobytes()
    path.write_bytes(f"P5\n{w} {h}\n{maxval}\n".encode() + data)
    return path


def depth_image(cap) -> np.ndarray:
    """A depth image capture's depth along the optical axis [m], NaN where none, (H, W)."""
    return cap.points[:, 2].reshape(cap.shape)


@pytest.mark.parametrize(
    ("maxval", "little_endian"), [(65535, False), (2047, False), (65535, True), (2047, True)]
)
def test_raw_disparity_is_recognised_and_converted_by_nyus_model(tmp_path, maxval, little_endian):
    mm = depth_mm(RTAB / "depth_154.png")
    pgm = write_pgm(
        tmp_path / "raw_154.pgm", disparity_of(mm), maxval=maxval, little_endian=little_endian
    )
    cap = load_capture(pgm, intrinsics=CALIB)
    assert cap.depth_scale is None  # (no depth scale to advise on: it is not one)
    assert any("raw disparity" in n and "351.3 / (1092.5 - d)" in n for n in cap.notes), cap.notes
    z, z_true = depth_image(cap), mm / 1000.0
    # Every pixel measured in the original (0.9-4.7 m: inside the model) and no other.
    assert np.array_equal(np.isfinite(z), z_true > 0)
    ok = z_true > 0
    steps = np.abs(A / z[ok] - A / z_true[ok])  # disparity steps between them
    assert steps.max() <= 0.5 + 1e-9, steps.max()
    # ... and the points are the original's, at that depth, through the same intrinsics.
    same = load_capture(RTAB / "depth_154.png", intrinsics=CALIB)
    ratio = cap.points[ok.ravel()] / same.points[ok.ravel()]
    assert np.allclose(ratio, ratio[:, 2:3], rtol=1e-9)


def test_a_mesh_from_disparity_finds_the_same_floor_as_from_millimetres(tmp_path):
    pgm = write_pgm(tmp_path / "raw_154.pgm", disparity_of(depth_mm(RTAB / "depth_154.png")))
    settings = capture_settings({"intrinsics": CALIB, "voxel": 0.02})
    from_disparity = mesh_capture(pgm, settings).report()
    from_mm = mesh_capture(RTAB / "depth_154.png", settings).report()
    assert abs(from_disparity["camera_height_m"] - from_mm["camera_height_m"]) < 0.02
    assert abs(from_disparity["pitch_down_deg"] - from_mm["pitch_down_deg"]) < 1.0


@pytest.mark.parametrize(
    "name", ["rtabmap/depth_154.png", "frame_20121214T142255.814212_depth_mm.png"]
)
def test_real_millimetre_depth_is_never_taken_for_disparity(tmp_path, name):
    """The desk frame's samples all fit 11 bits (0.67-1.71 m); neither image has 2047 as a
    no-reading marker. As PNG and as PGM alike, they are depth at 1000 units per metre."""
    mm = depth_mm(REAL / name)
    for path in (REAL / name, write_pgm(tmp_path / "same.pgm", mm.astype(np.uint16))):
        cap = load_capture(path, intrinsics="kinect1")
        assert cap.depth_scale == 1000.0 and not cap.notes, cap.notes
        z = depth_image(cap)
        assert np.allclose(z[mm > 0], mm[mm > 0] / 1000.0)


def test_disparity_that_is_not_plainly_so_is_refused_naming_both_settings(tmp_path):
    """11 bits and the 2047 marker, but a fifth of the other samples are no disparity of
    0.4-10 m: neither reading is safe to guess."""
    raw = disparity_of(depth_mm(RTAB / "depth_154.png"))
    rows = np.arange(raw.shape[0]) % 5 == 0
    raw[rows] = np.where(raw[rows] < 2047, 150, 2047)
    pgm = write_pgm(tmp_path / "odd.pgm", raw)
    with pytest.raises(CaptureError) as err:
        load_capture(pgm, intrinsics=CALIB)
    message = str(err.value)
    assert "raw disparity" in message and "2047" in message
    assert "--depth-units kinect-disparity" in message and "--depth-scale" in message
    assert "10000" not in message  # (no depth scale is advised for it)
    # Told, either reading is taken.
    told = load_capture(pgm, intrinsics=CALIB, depth_units="kinect-disparity")
    assert told.depth_scale is None and "as told" in told.notes[0]
    as_depth = load_capture(pgm, intrinsics=CALIB, depth_scale=1000.0)
    assert as_depth.depth_scale == 1000.0 and not as_depth.notes


def test_depth_units_are_validated_with_the_other_capture_settings(tmp_path):
    assert capture_settings({"depth_units": "kinect-disparity"}).depth_units == "kinect-disparity"
    with pytest.raises(CaptureError, match=r"depth_units: 'disparity' is not one of kinect-disp"):
        capture_settings({"depth_units": "disparity"})
    mm = RTAB / "depth_154.png"  # samples up to 4643: not 11-bit disparity
    with pytest.raises(CaptureError, match=r"samples reach 4643: raw Kinect disparity has 11"):
        load_capture(mm, intrinsics=CALIB, depth_units="kinect-disparity")
    with pytest.raises(CaptureError, match=r"both a depth scale \(1000\) and depth units"):
        load_capture(mm, intrinsics=CALIB, depth_scale=1000.0, depth_units="kinect-disparity")
    with pytest.raises(CaptureError, match=r"only a depth image .* has them"):
        load_capture(REAL / "office_desk_160x120.pcd", depth_units="kinect-disparity")
