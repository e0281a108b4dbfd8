"""Hostile captures (issue 15): malformed, lying, truncated and wrongly named point clouds,
depth images, bags and calibration files, each given to `roachplan mesh` or `roachplan
voxel-study`, which must refuse it with exit 2, a message naming the file and what is wrong,
no traceback, and no noise from a C library. Files are written here (or cut from the real
captures in ../shared/testdata/real); each case exits while reading, before any meshing."""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from hostile import Case, run_case
from test_perception import REAL

FRAME_PCD = REAL / "frame_20121214T142255.814212.pcd"  # binary_compressed, 640x480
RTAB_PNG = REAL / "rtabmap" / "depth_154.png"
RTAB_YAML = REAL / "rtabmap" / "calib_154.yaml"
FRAME_XML = REAL / "frame_20121214T142255.814212.xml"
BAG = REAL / "jsk_watercan.bag"

Data = bytes | Callable[[Path], bytes]


# -- file makers ----------------------------------------------------------------------------


def pcd(body: bytes = b"", *, drop: tuple[str, ...] = (), **lines: str) -> bytes:
    """A PCD header of x y z float32 (keywords overridden by lines, e.g. WIDTH="5", or left
    out by drop) followed by body."""
    header = {
        "VERSION": "0.7",
        "FIELDS": "x y z",
        "SIZE": "4 4 4",
        "TYPE": "F F F",
        "COUNT": "1 1 1",
        "WIDTH": "4",
        "HEIGHT": "1",
        "VIEWPOINT": "0 0 0 1 0 0 0",
        "POINTS": "4",
        "DATA": "binary",
    }
    header.update(lines)
    text = "".join(f"{k} {v}\n" for k, v in header.items() if k not in drop)
    return text.encode() + body


def xyz_f4(n: int) -> bytes:
    """n points 1-2 m in front of a camera, float32 x y z."""
    pts = np.random.default_rng(0).uniform(-0.5, 0.5, (n, 3)).astype("<f4")
    pts[:, 2] += 1.5
    return pts.tobytes()


def lzf_block(uncompressed: int, compressed: bytes) -> bytes:
    return struct.pack("<II", len(compressed), uncompressed) + compressed


def ply(
    body: bytes = b"",
    *,
    fmt: str = "binary_little_endian 1.0",
    vertices: str = "4",
    props: str = "property float x\nproperty float y\nproperty float z\n",
    end: str = "end_header\n",
) -> bytes:
    return f"ply\nformat {fmt}\nelement vertex {vertices}\n{props}{end}".encode() + body


def png(
    width: int, height: int, depth: int = 16, colour: int = 0, pixels: bytes | None = None
) -> bytes:
    """A PNG whose IHDR says width x height; its image data is `pixels` (zlib'd) or a few
    bytes only (a header that lies)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    idat = zlib.compress(pixels if pixels is not None else b"\0" * 1000)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def depth_png() -> bytes:
    """A valid 64x48 16-bit depth PNG (1.5 m everywhere)."""
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(np.full((48, 64), 1500, np.uint16)).save(out, format="PNG")
    return out.getvalue()


def cut(path: Path, n: int) -> Callable[[Path], bytes]:
    return lambda _: path.read_bytes()[:n]


def patched(path: Path, old: bytes, new: bytes) -> Callable[[Path], bytes]:
    def make(_: Path) -> bytes:
        data = path.read_bytes()
        assert data.count(old) >= 1, old
        return data.replace(old, new, 1)

    return make


def _write(tmp: Path, name: str, data: Data) -> Path:
    path = tmp / name
    path.write_bytes(data(tmp) if callable(data) else data)
    return path


def mesh(name: str, data: Data, *flags: str) -> Callable[[Path], list[str]]:
    """`roachplan mesh NAME -o out.stl FLAGS` on a file holding data."""
    return lambda tmp: ["mesh", str(_write(tmp, name, data)), "-o", str(tmp / "out.stl"), *flags]


def voxel(name: str, data: Data, *flags: str) -> Callable[[Path], list[str]]:
    """`roachplan voxel-study NAME FLAGS` on a file holding data."""
    return lambda tmp: ["voxel-study", str(_write(tmp, name, data)), *flags]


def with_calibration(name: str, text: str | bytes) -> Callable[[Path], list[str]]:
    """A valid depth PNG read with --intrinsics a calibration file holding text."""

    def make(tmp: Path) -> list[str]:
        calib = _write(tmp, name, text.encode() if isinstance(text, str) else text)
        image = _write(tmp, "depth.png", depth_png())
        return ["mesh", str(image), "-o", str(tmp / "out.stl"), "--intrinsics", str(calib)]

    return make


def in_folder(tmp: Path) -> list[str]:
    (tmp / "scan.pcd").mkdir()
    return ["mesh", str(tmp / "scan.pcd"), "-o", str(tmp / "out.stl")]


def fake_ros2_folder(tmp: Path) -> list[str]:
    bag = tmp / "rosbag2_run"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  version: 99\n")
    return ["mesh", str(bag), "-o", str(tmp / "out.stl")]


def fifo(tmp: Path) -> list[str]:
    os.mkfifo(tmp / "cloud.pcd")  # opening it to read would wait for a writer forever
    return ["mesh", str(tmp / "cloud.pcd"), "-o", str(tmp / "out.stl")]


def device(tmp: Path) -> list[str]:
    (tmp / "zero.pcd").symlink_to("/dev/zero")  # reads forever
    return ["voxel-study", str(tmp / "zero.pcd")]


def onto_itself(tmp: Path) -> list[str]:
    _write(tmp, "scan.ply", ply(xyz_f4(4)))
    return ["mesh", str(tmp / "scan.ply"), "-o", str(tmp / "scan.ply")]


def _cloud_msg(types, height: int, width: int):
    """A PointCloud2 of height x width float32 x y z points that carries 2000 points' bytes."""
    T = types
    pts = np.random.default_rng(1).uniform(0.5, 2.0, (2000, 3)).astype(np.float32)
    fields = [
        T["sensor_msgs/msg/PointField"](name=n, offset=4 * i, datatype=7, count=1)
        for i, n in enumerate("xyz")
    ]
    stamp = T["builtin_interfaces/msg/Time"](sec=0, nanosec=0)
    header = (
        T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="cam")
        if "seq" in T["std_msgs/msg/Header"].__dataclass_fields__
        else T["std_msgs/msg/Header"](stamp=stamp, frame_id="cam")
    )
    return T["sensor_msgs/msg/PointCloud2"](
        header=header,
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=12,
        row_step=12 * width,
        data=pts.view(np.uint8).reshape(-1),
        is_dense=False,
    )


def ros1_bag_that_lies(tmp: Path) -> list[str]:
    """A ROS 1 bag (rosbags' writer) whose PointCloud2 says 4000x50 points and carries 2000."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    msg = _cloud_msg(ts.types, 4000, 50)
    with Writer(tmp / "lie.bag") as writer:
        conn = writer.add_connection("/points", msg.__msgtype__, typestore=ts)
        writer.write(conn, 1, ts.serialize_ros1(msg, msg.__msgtype__))
    return ["mesh", str(tmp / "lie.bag"), "-o", str(tmp / "out.stl")]


def ros2_bag_cut(storage: str) -> Callable[[Path], list[str]]:
    """A ROS 2 bag (rosbags' writer: SQLITE3 or MCAP) whose storage file is cut in half."""

    def make(tmp: Path) -> list[str]:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        ts = get_typestore(Stores.ROS2_HUMBLE)
        msg = _cloud_msg(ts.types, 40, 50)
        with Writer(tmp / "run", version=8, storage_plugin=StoragePlugin[storage]) as writer:
            conn = writer.add_connection("/points", msg.__msgtype__, typestore=ts)
            writer.write(conn, 1, ts.serialize_cdr(msg, msg.__msgtype__))
        whole = next(p for p in (tmp / "run").iterdir() if p.suffix in (".db3", ".mcap"))
        half = tmp / f"half{whole.suffix}"
        half.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])
        return ["voxel-study", str(half)]

    return make


def npy_header(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    header = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}"
    header += " " * (63 - (10 + len(header)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode()


BILLION_LAUGHS = (
    "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
    + "".join(
        f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n"
        for p, c in zip("abcdefgh", "bcdefghi", strict=True)
    )
    + "camera_matrix: *i\n"
)
NEST = "[" * 5000 + "]" * 5000


# -- the table ------------------------------------------------------------------------------

CASES = [
    # PCD: headers that lie about the size, disagree with themselves, or are not PCD at all
    Case(
        "pcd_claims_a_billion_points",
        mesh("big.pcd", pcd(bytes(1200), WIDTH="1000000000", POINTS="1000000000")),
        ("big.pcd", "1000000000 points", "at most 100 million"),
    ),
    Case(
        "pcd_binary_truncated",
        mesh("cut.pcd", pcd(xyz_f4(1000)[:5000], WIDTH="1000", POINTS="1000")),
        ("cut.pcd", "12000 bytes", "5000 bytes follow", "truncated"),
    ),
    Case(
        "pcd_real_compressed_truncated",
        mesh("cut.pcd", cut(FRAME_PCD, 400_000)),
        ("cut.pcd", "compressed block", "truncated"),
    ),
    Case(
        "pcd_real_compressed_garbled",
        mesh(
            "garbled.pcd",
            lambda _: (
                (b := FRAME_PCD.read_bytes())[:2000]
                + bytes(x ^ 0x5A for x in b[2000:4000])
                + b[4000:]
            ),
        ),
        ("garbled.pcd", "damaged", "LZF"),
    ),
    Case(
        "pcd_compressed_size_lies",
        mesh("lie.pcd", pcd(lzf_block(999, b"\0" * 40), DATA="binary_compressed")),
        ("lie.pcd", "48 bytes", "decodes to 999 bytes"),
    ),
    Case(
        "pcd_compressed_ratio_impossible",
        mesh(
            "bomb.pcd",
            pcd(
                lzf_block(12 * 10_000_000, b"\xe0\xff\x00" * 4),
                WIDTH="10000000",
                POINTS="10000000",
                DATA="binary_compressed",
            ),
        ),
        ("bomb.pcd", "cannot decode to 120000000 bytes", "88"),
    ),
    Case(
        "pcd_size_fewer_than_fields",
        mesh("mix.pcd", pcd(xyz_f4(4), SIZE="4 4")),
        ("mix.pcd", "SIZE has 2 entries", "FIELDS names 3"),
    ),
    Case(
        "pcd_count_fewer_than_fields",
        voxel("mix.pcd", pcd(xyz_f4(4), COUNT="1")),
        ("mix.pcd", "COUNT has 1 entry"),
    ),
    Case(
        "pcd_unknown_type",
        mesh("t.pcd", pcd(xyz_f4(4), TYPE="F Q F")),
        ("t.pcd", "TYPE 'Q'", "accepted: F 4|8"),
    ),
    Case(
        "pcd_points_not_width_x_height",
        mesh("p.pcd", pcd(xyz_f4(4), WIDTH="2", HEIGHT="3")),
        ("p.pcd", "POINTS 4", "2 x 3 = 6", "must agree"),
    ),
    Case(
        "pcd_no_xyz_fields",
        mesh("n.pcd", pcd(xyz_f4(4), FIELDS="a b c")),
        ("n.pcd", "needs x, y and z"),
    ),
    Case("pcd_no_data_line", mesh("d.pcd", pcd(drop=("DATA",))), ("d.pcd", "no 'DATA' line")),
    Case(
        "pcd_unknown_encoding",
        mesh("d.pcd", pcd(xyz_f4(4), DATA="zip")),
        ("d.pcd", "DATA 'zip'", "accepted: ascii, binary, binary_compressed"),
    ),
    Case(
        "pcd_negative_width",
        mesh("w.pcd", pcd(xyz_f4(4), WIDTH="-4")),
        ("w.pcd", "WIDTH '-4'", "whole number"),
    ),
    Case("pcd_zero_points", voxel("z.pcd", pcd(WIDTH="0", POINTS="0")), ("z.pcd", "0 points")),
    Case(
        "pcd_viewpoint_not_numbers",
        mesh("v.pcd", pcd(xyz_f4(4), VIEWPOINT="0 0 nan 1 0 0 0")),
        ("v.pcd", "VIEWPOINT", "7 finite numbers"),
    ),
    Case(
        "pcd_keyword_twice",
        mesh("k.pcd", pcd(xyz_f4(4), FIELDS="x y z\nWIDTH 4")),
        ("k.pcd", "WIDTH is given twice"),
    ),
    Case(
        "pcd_binary_bytes_in_header",
        mesh("b.pcd", pcd(xyz_f4(4)).replace(b"y z\n", b"y \xffz\n", 1)),
        ("b.pcd", "non-text byte on line 2"),
    ),
    Case(
        "pcd_ascii_truncated",
        mesh("a.pcd", pcd(b"1 2 3\n" * 3, DATA="ascii", WIDTH="1000", POINTS="1000")),
        ("a.pcd", "1000 points of 3 values", "truncated"),
    ),
    Case(
        "pcd_ascii_words",
        mesh("a.pcd", pcd(b"1 2 3\n4 five 6\n7 8 9\n1 1 1\n", DATA="ascii")),
        ("a.pcd", "ascii data", "five"),
    ),
    Case(
        "pcd_ascii_short_rows",
        voxel("a.pcd", pcd(b"1 2\n4 5\n7 8\n1 1\n" * 2, DATA="ascii")),
        ("a.pcd", "4 points of 3 values", "4 rows of 2 values"),
    ),
    Case("pcd_empty_file", mesh("e.pcd", b""), ("e.pcd", "empty")),
    Case("pcd_holding_a_png", mesh("photo.pcd", png(4, 4)), ("photo.pcd", "not a PCD file")),
    # PLY: Open3D's RPly prints its own complaint and returns no points; ours names the line
    Case(
        "ply_vertex_count_not_a_number",
        mesh("bad.ply", ply(bytes(100), vertices="abc")),
        ("bad.ply", "element 'vertex' count 'abc'", "whole number"),
    ),
    Case(
        "ply_claims_a_billion_vertices",
        mesh("big.ply", ply(bytes(100), vertices="1000000000")),
        ("big.ply", "1000000000 vertices", "at most 100 million"),
    ),
    Case(
        "ply_binary_truncated",
        mesh("cut.ply", ply(xyz_f4(1000)[:3000], vertices="1000")),
        ("cut.ply", "12000 bytes or more", "3000 bytes follow", "truncated"),
    ),
    Case("ply_no_end_header", voxel("h.ply", ply(end="")), ("h.ply", "no 'end_header' line")),
    Case(
        "ply_unknown_format",
        mesh("f.ply", ply(xyz_f4(4), fmt="binary_middle_endian 1.0")),
        ("f.ply", "binary_middle_endian", "accepted: ascii"),
    ),
    Case(
        "ply_unknown_property_type",
        mesh("p.ply", ply(xyz_f4(4), props="property quad x\n")),
        ("p.ply", "property type 'quad'"),
    ),
    Case(
        "ply_without_vertices",
        mesh(
            "n.ply",
            b"ply\nformat ascii 1.0\nelement face 0\n"
            b"property list uchar int vertex_indices\nend_header\n",
        ),
        ("n.ply", "no vertex element"),
    ),
    Case(
        "ply_vertices_without_z",
        mesh("n.ply", ply(xyz_f4(4), props="property float x\nproperty float y\n")),
        ("n.ply", "need x, y and z"),
    ),
    Case(
        "ply_ascii_words",
        mesh("a.ply", ply(b"1 2 3\n4 5 six\n7 8 9\n1 1 1\n", fmt="ascii 1.0")),
        ("a.ply", "ascii vertex data", "six"),
    ),
    Case(
        "ply_faces_first_that_lie",
        mesh(
            "lie.ply",
            lambda _: ply(b"\x03" + bytes(12) + b"\xff" * 1100, vertices="5").replace(
                b"element vertex",
                b"element face 1000\nproperty list uchar int vertex_indices\nelement vertex",
            ),
        ),
        ("lie.ply", "could not be read", "Read PLY failed", "1000 face"),
        fork=False,
    ),
    Case("ply_holding_a_pcd", mesh("cloud.ply", pcd(xyz_f4(4))), ("cloud.ply", "not a PLY file")),
    # depth images: bombs, wrong bit depths, lying netpbm headers
    Case(
        "png_15000_squared",
        mesh("bomb.png", png(15000, 15000), "--intrinsics", "kinect1"),
        ("bomb.png", "15000x15000", "225 megapixels", "at most 100 megapixels"),
    ),
    Case(
        "png_8_bit_grey",
        mesh("grey.png", png(4, 4, depth=8), "--intrinsics", "kinect1"),
        ("grey.png", "16-bit greyscale", "8-bit greyscale"),
    ),
    Case(
        "png_16_bit_rgb",
        voxel("rgb.png", png(4, 4, colour=2), "--intrinsics", "kinect1"),
        ("rgb.png", "16-bit greyscale", "16-bit RGB"),
    ),
    Case(
        "png_zero_width",
        mesh("empty.png", png(0, 480), "--intrinsics", "kinect1"),
        ("empty.png", "0x480", "empty image"),
    ),
    Case(
        "png_real_truncated",
        mesh("cut.png", cut(RTAB_PNG, 5000), "--intrinsics", "kinect1"),
        ("cut.png", "cannot decode this PNG"),
    ),
    Case(
        "pgm_60000_squared",
        mesh("bomb.pgm", b"P5\n60000 60000\n65535\n" + bytes(64), "--intrinsics", "kinect1"),
        ("bomb.pgm", "3600 megapixels", "at most 100 megapixels"),
    ),
    Case(
        "pgm_8_bit",
        mesh("grey.pgm", b"P5\n4 4\n255\n" + bytes(16), "--intrinsics", "kinect1"),
        ("grey.pgm", "8-bit netpbm", "maxval 255"),
    ),
    Case(
        "pgm_truncated",
        voxel("cut.pgm", b"P5\n640 480\n65535\n" + bytes(1000), "--intrinsics", "kinect1"),
        ("cut.pgm", "614400 bytes", "truncated"),
    ),
    Case(
        "ppm_ascii_words",
        mesh("w.ppm", b"P3\n2 1\n65535\n1 2 3 4 5 six\n", "--intrinsics", "kinect1"),
        ("w.ppm", "decimal samples"),
    ),
    Case(
        "pgm_sample_over_maxval",
        mesh("m.pgm", b"P2\n2 1\n1000\n5 99999999999999999999999\n", "--intrinsics", "kinect1"),
        ("m.pgm", "maxval"),
    ),
    # bags
    Case(
        "bag_of_random_bytes",
        mesh("rand.bag", bytes(range(256)) * 16),
        ("rand.bag", "not a ROS 1 bag", "#ROSBAG V2.0"),
    ),
    Case("bag_real_truncated", mesh("cut.bag", cut(BAG, 100_000)), ("cut.bag", "truncated")),
    Case("bag_real_header_only", voxel("cut.bag", cut(BAG, 4200)), ("cut.bag", "truncated")),
    Case(
        "bag_old_format",
        mesh("old.bag", b"#ROSBAG V1.2\n" + bytes(100)),
        ("old.bag", "format '1.2'", "only format 2.0"),
    ),
    Case(
        "bag_unknown_compression",
        mesh("z.bag", patched(BAG, b"compression=none", b"compression=zstd")),
        ("z.bag", "compression 'zstd'", "none, bz2 or lz4"),
    ),
    Case(
        "bag_cloud_claims_more_than_it_carries",
        ros1_bag_that_lies,
        ("lie.bag", "4000x50 points", "24000 bytes", "too short"),
    ),
    Case("db3_real_writer_cut_in_half", ros2_bag_cut("SQLITE3"), ("half.db3", "malformed")),
    Case(
        "mcap_real_writer_cut_in_half", ros2_bag_cut("MCAP"), ("half.mcap", "cannot open this bag")
    ),
    Case(
        "db3_of_random_bytes",
        mesh("rand.db3", bytes(range(256)) * 4),
        ("rand.db3", "not a ROS 2 SQLite bag"),
    ),
    Case("mcap_of_text", voxel("t.mcap", b"hello\n" * 50), ("t.mcap", "not an MCAP bag")),
    Case(
        "bag_topic_not_in_it",
        mesh("w.bag", lambda _: BAG.read_bytes(), "--topic", "/nope"),
        ("w.bag", "no topic '/nope'"),
    ),
    Case(
        "topic_on_a_pcd",
        mesh("c.pcd", pcd(xyz_f4(4)), "--topic", "/points"),
        ("c.pcd", "topic", "only a bag"),
    ),
    Case(
        "ros2_folder_with_a_bad_metadata", fake_ros2_folder, ("rosbag2_run", "cannot open this bag")
    ),
    # calibration files
    Case(
        "calibration_json_malformed",
        with_calibration("cam.json", '{"fx": 525, "fy":'),
        ("cam.json", "not JSON"),
    ),
    Case(
        "calibration_json_nested_5000_deep",
        with_calibration("cam.json", NEST),
        ("cam.json", "not JSON"),
    ),
    Case(
        "calibration_json_infinite_width",
        with_calibration(
            "cam.json",
            '{"fx": 525, "fy": 525, "cx": 32, "cy": 24, "width": Infinity, "height": 48}',
        ),
        ("cam.json", "intrinsics must be numbers"),
    ),
    Case(
        "calibration_json_huge_image",
        with_calibration(
            "cam.json",
            '{"fx": 5, "fy": 5, "cx": 3, "cy": 2, "width": 64000000, "height": 48000000}',
        ),
        ("cam.json", "1-100000 px"),
    ),
    Case(
        "calibration_open3d_matrix_of_5",
        with_calibration(
            "cam.json", '{"width": 64, "height": 48, "intrinsic_matrix": [1, 2, 3, 4, 5]}'
        ),
        ("cam.json", "intrinsic_matrix", "3x3 matrix"),
    ),
    Case(
        "calibration_yaml_malformed",
        with_calibration("cam.yaml", "camera_matrix: [1, 2\n  - x: }"),
        ("cam.yaml", "YAML"),
    ),
    Case(
        "calibration_yaml_billion_laughs",
        with_calibration("cam.yaml", BILLION_LAUGHS),
        ("cam.yaml", "alias"),
    ),
    Case(
        "calibration_xml_malformed",
        with_calibration("cam.xml", "<depth><focal_length_x>5</depth>"),
        ("cam.xml", "not valid XML"),
    ),
    Case(
        "calibration_xml_infinite_centre",
        with_calibration(
            "cam.xml",
            FRAME_XML.read_text().replace("<principal_point_x>320", "<principal_point_x>inf"),
        ),
        ("cam.xml", "<depth>", "principal point"),
    ),
    Case(
        "calibration_binary_file",
        with_calibration("cam.json", bytes(range(256))),
        ("cam.json", "binary content"),
    ),
    Case(
        "calibration_too_big",
        with_calibration("cam.yaml", b"# padding\n" * 120_000),
        ("cam.yaml", "at most 1024 KiB"),
    ),
    # whatever else a user might pass
    Case("folder_as_mesh_input", in_folder, ("scan.pcd", "is a folder")),
    Case("fifo_named_pcd", fifo, ("cloud.pcd", "not a regular file"), timeout=60),
    Case("symlink_to_dev_zero", device, ("zero.pcd", "not a regular file"), timeout=60),
    Case(
        "unknown_extension",
        mesh("scan.las", b"LASF" + bytes(300)),
        ("scan.las", "unknown capture type '.las'"),
    ),
    Case(
        "npy_claims_a_huge_shape",
        mesh("big.npy", npy_header((1_000_000_000, 3)) + bytes(96)),
        ("big.npy", "1000000000 points", "at most 100 million"),
    ),
    Case(
        "npy_truncated",
        voxel("cut.npy", npy_header((1000, 3)) + bytes(96)),
        ("cut.npy", "24000 bytes", "truncated"),
    ),
    Case(
        "npy_of_text",
        mesh("s.npy", npy_header((4, 3), "<U8") + bytes(384)),
        ("s.npy", "expected numbers"),
    ),
    Case("xyz_holding_binary", mesh("b.xyz", bytes(range(256))), ("b.xyz", "binary content")),
    Case("output_onto_the_input", onto_itself, ("scan.ply", "overwrite"), keep=("scan.ply",)),
]


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_hostile_capture(case: Case, tmp_path: Path):
    proc = run_case(case, tmp_path)
    out = proc.stdout + proc.stderr
    # One message of ours, no printout of a C library's (Open3D's RPly, libpng) beside it.
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("roachplan: error: "), out[-2000:]
    assert "[Open3D" not in out and "\x1b[" not in out, out[-2000:]
    assert not (tmp_path / "out.stl").exists()


def test_table_is_large_and_names_are_unique():
    names = [c.name for c in CASES]
    assert len(names) >= 45 and len(set(names)) == len(names)


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_a_bag_chunk_that_unpacks_past_its_declared_size_is_refused(
    tmp_path, monkeypatch, compression
):
    """rosbags unpacks a whole chunk with no limit; a chunk header may lie about its size.
    Here the limit is lowered (a real bomb of 1 GiB takes long to build) and the header says
    100 bytes for a chunk of some 25 kB."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    import roachplan.perception._read_bag as bag_reader
    from roachplan.perception import CaptureError, load_capture

    ts = get_typestore(Stores.ROS1_NOETIC)
    msg = _cloud_msg(ts.types, 40, 50)
    bag = tmp_path / "packed.bag"
    writer = Writer(bag)
    writer.set_compression(Writer.CompressionFormat[compression.upper()])
    with writer:
        conn = writer.add_connection("/points", msg.__msgtype__, typestore=ts)
        writer.write(conn, 1, ts.serialize_ros1(msg, msg.__msgtype__))
    assert load_capture(bag).points.shape == (2000, 3)  # as written, it reads
    data = bag.read_bytes()
    at = data.index(b"size=", data.index(b"compression=" + compression.encode()) - 40)
    bag.write_bytes(data[: at + 5] + struct.pack("<I", 100) + data[at + 9 :])
    monkeypatch.setattr(bag_reader, "MAX_BAG_CHUNK_BYTES", 1000)
    with pytest.raises(CaptureError, match=r"packed\.bag: a chunk of the bag unpacks to more than"):
        load_capture(bag)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads a file of mode 000: nothing to refuse")
def test_unreadable_capture(tmp_path: Path):
    """chmod 000: as a user the file cannot be opened, which is an error, not a traceback."""
    path = tmp_path / "locked.pcd"
    path.write_bytes(pcd(xyz_f4(4)))
    path.chmod(0)
    run_case(
        Case(
            "unreadable",
            lambda tmp: ["mesh", str(path), "-o", str(tmp / "o.stl")],
            ("locked.pcd", "cannot read it", "permission"),
        ),
        tmp_path,
    )
