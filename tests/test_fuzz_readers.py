"""Property-based fuzzing of the capture readers' header parsers and the calibration readers
(issue 15): for any bytes, and for valid headers mutated (tokens swapped for hostile values,
lines dropped or repeated, bytes flipped, the file cut short), a parser returns a header that
keeps its promises (sizes within the limits, the data it describes inside the file) or raises
CaptureError, never another exception. Brief under the "test" profile, long under `make fuzz`."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from roachplan.perception import CaptureError, load_capture
from roachplan.perception._camera import MAX_IMAGE_SIDE, parse_calibration
from roachplan.perception._headers import (
    HEAD_BYTES,
    LZF_MAX_RATIO,
    MAX_CLOUD_POINTS,
    MAX_DEPTH_PIXELS,
    parse_netpbm_header,
    parse_pcd_header,
    parse_ply_header,
    parse_png_header,
)
from test_perception import REAL

HOSTILE_TOKENS = [
    "0",
    "-1",
    "1",
    "3",
    "4",
    "8",
    "12",
    "1000000000",
    "99999999999999",
    "4294967295",
    "nan",
    "inf",
    "-inf",
    "1e309",
    "abc",
    "",
    "x",
    "y",
    "z",
    "_",
    "F",
    "U",
    "I",
    "Q",
    "ascii",
    "binary",
    "binary_compressed",
    "float",
    "list",
    "uchar",
    "vertex",
    "end_header",
    "DATA",
    "\xff",
    "0x10",
    "1.5",
    "  ",
    "\n",
]


@st.composite
def mutated(draw, valid: bytes, header_end: int) -> bytes:
    """valid with 1-4 mutations, mostly within its first header_end bytes (the header)."""
    data = bytearray(valid)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(
            st.sampled_from(["token", "token", "drop_line", "repeat_line", "flip", "insert", "cut"])
        )
        lines = bytes(data[:header_end]).split(b"\n")
        if op == "token" and lines:
            i = draw(st.integers(0, len(lines) - 1))
            words = lines[i].split(b" ")
            j = draw(st.integers(0, len(words) - 1))
            words[j] = draw(st.sampled_from(HOSTILE_TOKENS)).encode("utf-8")
            lines[i] = b" ".join(words)
        elif op in ("drop_line", "repeat_line") and len(lines) > 1:
            i = draw(st.integers(0, len(lines) - 2))
            lines[i : i + 1] = [] if op == "drop_line" else [lines[i], lines[i]]
        if op in ("token", "drop_line", "repeat_line"):
            head = b"\n".join(lines)
            data[:header_end] = head
            header_end = len(head)
        elif op == "flip" and data:
            i = draw(st.integers(0, len(data) - 1))
            data[i] ^= draw(st.integers(1, 255))
        elif op == "insert":
            i = draw(st.integers(0, len(data)))
            data[i:i] = draw(st.binary(min_size=1, max_size=8))
        elif op == "cut":
            del data[draw(st.integers(0, len(data))) :]
    return bytes(data)


def _pcd(data: str, body: bytes, **over: str) -> bytes:
    header = {
        "VERSION": "0.7",
        "FIELDS": "x y z rgb",
        "SIZE": "4 4 4 4",
        "TYPE": "F F F U",
        "COUNT": "1 1 1 1",
        "WIDTH": "3",
        "HEIGHT": "2",
        "VIEWPOINT": "0 0 0 1 0 0 0",
        "POINTS": "6",
        "DATA": data,
        **over,
    }
    return "".join(f"{k} {v}\n" for k, v in header.items()).encode() + body


PTS = np.arange(24, dtype="<f4").reshape(6, 4) / 7
PCD_BINARY = _pcd("binary", PTS.tobytes())
PCD_ASCII = _pcd("ascii", "".join(" ".join(f"{v:.9g}" for v in row) + "\n" for row in PTS).encode())
PCD_COMPRESSED = (
    _pcd("binary_compressed", b"")
    + np.array([99, 96], "<u4").tobytes()
    + bytes([31])
    + PTS.T.tobytes()[:32]
    + bytes([31])
    + PTS.T.tobytes()[32:64]
    + bytes([31])
    + PTS.T.tobytes()[64:]
)
"""LZF of literal runs (a control byte of 31 then 32 bytes) holds the fields one after another."""
PLY_HEADER = (
    b"ply\nformat binary_little_endian 1.0\ncomment fuzz\nelement vertex 6\n"
    b"property float x\nproperty float y\nproperty float z\nproperty float w\n"
    b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
)
PLY_BINARY = PLY_HEADER + PTS.tobytes() + b"\x03" + np.array([0, 1, 2], "<i4").tobytes()
PLY_ASCII = (
    PLY_HEADER.replace(b"binary_little_endian", b"ascii")
    + PCD_ASCII.split(b"ascii\n")[1]
    + b"3 0 1 2\n"
)
PGM = b"P5\n# fuzz\n3 2\n65535\n" + np.arange(6, dtype=">u2").tobytes()
PPM_ASCII = b"P3\n2 1\n1000\n1 2 3 4 5 6\n"
PNG = (REAL / "rtabmap" / "depth_154.png").read_bytes()[:64]

CALIBRATIONS = {
    ".yaml": (REAL / "rtabmap" / "calib_154.yaml").read_text(),
    ".xml": (REAL / "frame_20121214T142255.814212.xml").read_text(),
    ".json": json.dumps(
        {
            "width": 640,
            "height": 480,
            "fx": 525.0,
            "fy": 525.0,
            "cx": 319.5,
            "cy": 239.5,
            "depth_scale": 1000,
        }
    ),
    ".yml": "image_width: 640\nimage_height: 480\ncamera_name: c\ncamera_matrix:\n  rows: 3\n"
    "  cols: 3\n  data: [525, 0, 319.5, 0, 525, 239.5, 0, 0, 1]\n",
}


def _header_end(valid: bytes, end: bytes) -> int:
    return valid.index(end) + len(end)


# -- the parsers' promises ------------------------------------------------------------------


def check_pcd(data: bytes, file_size: int | None = None) -> None:
    size = len(data) if file_size is None else file_size
    try:
        h = parse_pcd_header(data[: HEAD_BYTES + 8], size, "fuzz.pcd")
    except CaptureError as exc:
        assert str(exc).startswith("fuzz.pcd: ")
        return
    assert 0 < h.points == h.width * h.height <= MAX_CLOUD_POINTS
    assert {"x", "y", "z"} <= {f.name for f in h.fields}
    assert all(f.count >= 1 for f in h.fields) and len(h.viewpoint) == 7
    assert all(map(math.isfinite, h.viewpoint))
    if h.data == "binary":
        assert h.data_offset + h.points * h.point_step <= size
    elif h.data == "binary_compressed":
        assert h.data_offset + 8 + h.compressed_size <= size
        assert h.points * h.point_step <= LZF_MAX_RATIO * h.compressed_size
    else:
        assert h.data_offset + 2 * h.points * h.values_per_point - 1 <= size


def check_ply(data: bytes, file_size: int | None = None) -> None:
    size = len(data) if file_size is None else file_size
    try:
        h = parse_ply_header(data[:HEAD_BYTES], size, "fuzz.ply")
    except CaptureError as exc:
        assert str(exc).startswith("fuzz.ply: ")
        return
    assert 0 < h.vertex.count <= MAX_CLOUD_POINTS
    assert {"x", "y", "z"} <= {p.name for p in h.vertex.properties if p.list_count is None}
    if h.format != "ascii":
        assert h.data_offset + sum(e.count * e.min_bytes for e in h.elements) <= size


def check_netpbm(data: bytes) -> None:
    try:
        h = parse_netpbm_header(data[:4096], len(data), "fuzz.pgm")
    except CaptureError as exc:
        assert str(exc).startswith("fuzz.pgm: ")
        return
    assert 1 <= h.width * h.height <= MAX_DEPTH_PIXELS and 255 < h.maxval <= 65535
    per_sample = 2 if h.binary else 1
    assert h.data_offset + per_sample * h.samples <= len(data) + (0 if h.binary else 1)


def check_png(data: bytes) -> None:
    try:
        h = parse_png_header(data, "fuzz.png")
    except CaptureError as exc:
        assert str(exc).startswith("fuzz.png: ")
        return
    assert 1 <= h.width * h.height <= MAX_DEPTH_PIXELS and (h.bit_depth, h.colour_type) == (16, 0)


def check_calibration(text: str, suffix: str) -> None:
    try:
        cal = parse_calibration(text, Path("fuzz" + suffix), size=(640, 480))
    except CaptureError as exc:
        assert "fuzz" in str(exc) and len(str(exc)) < 3000
        return
    k = cal.intrinsics
    assert 1 <= min(k.width, k.height) and max(k.width, k.height) <= MAX_IMAGE_SIDE
    assert k.fx > 0 and k.fy > 0 and all(map(math.isfinite, (k.fx, k.fy, k.cx, k.cy)))
    assert cal.depth_scale is None or 0 < cal.depth_scale < math.inf


# -- the valid inputs really are valid (or the fuzzing proves nothing) ----------------------


def test_the_seeds_parse(tmp_path):
    for data in (PCD_BINARY, PCD_ASCII, PCD_COMPRESSED):
        assert parse_pcd_header(data, len(data), "seed.pcd").points == 6
        (tmp_path / "seed.pcd").write_bytes(data)
        np.testing.assert_allclose(
            load_capture(tmp_path / "seed.pcd").points, PTS[:, :3], rtol=1e-6
        )
    for data in (PLY_BINARY, PLY_ASCII):
        assert parse_ply_header(data, len(data), "seed.ply").vertex.count == 6
        (tmp_path / "seed.ply").write_bytes(data)
        np.testing.assert_allclose(
            load_capture(tmp_path / "seed.ply").points, PTS[:, :3], rtol=1e-6
        )
    assert parse_netpbm_header(PGM, len(PGM), "seed.pgm").samples == 6
    assert parse_png_header(PNG, "seed.png").width == 640
    for suffix, text in CALIBRATIONS.items():
        assert parse_calibration(text, Path("seed" + suffix), (640, 480)).intrinsics.fx == 525


# -- arbitrary bytes ------------------------------------------------------------------------


@given(st.binary(max_size=600), st.integers(0, 2**40))
def test_pcd_header_of_any_bytes(data, file_size):
    check_pcd(data, max(file_size, len(data)))
    check_pcd(b"VERSION 0.7\n" + data)


@given(st.binary(max_size=600), st.integers(0, 2**40))
def test_ply_header_of_any_bytes(data, file_size):
    check_ply(data, max(file_size, len(data)))
    check_ply(b"ply\nformat ascii 1.0\n" + data)


@given(st.binary(max_size=300))
def test_netpbm_and_png_headers_of_any_bytes(data):
    for magic in (b"", b"P5", b"P2", b"P6 ", b"P3\n"):
        check_netpbm(magic + data)
    check_png(data)
    check_png(b"\x89PNG\r\n\x1a\n" + data)


@given(st.text(max_size=400), st.sampled_from([".json", ".yaml", ".xml", ".txt"]))
def test_calibration_of_any_text(text, suffix):
    check_calibration(text, suffix)


# -- valid files, mutated -------------------------------------------------------------------


@given(
    st.sampled_from([PCD_BINARY, PCD_ASCII, PCD_COMPRESSED]).flatmap(
        lambda v: mutated(v, _header_end(v, b"\nDATA ") + 20)
    )
)
def test_pcd_header_mutated(data):
    check_pcd(data)


@given(
    st.sampled_from([PLY_BINARY, PLY_ASCII]).flatmap(
        lambda v: mutated(v, _header_end(v, b"end_header\n"))
    )
)
def test_ply_header_mutated(data):
    check_ply(data)


@given(st.sampled_from([PGM, PPM_ASCII]).flatmap(lambda v: mutated(v, 24)), mutated(PNG, 26))
def test_netpbm_and_png_headers_mutated(netpbm, png):
    check_netpbm(netpbm)
    check_png(png)


@given(
    st.sampled_from(sorted(CALIBRATIONS)).flatmap(
        lambda s: st.tuples(st.just(s), mutated(CALIBRATIONS[s].encode(), len(CALIBRATIONS[s])))
    )
)
def test_calibration_mutated(case):
    suffix, data = case
    check_calibration(data.decode("utf-8", errors="replace"), suffix)


@given(
    st.sampled_from([".pcd", ".ply"]).flatmap(
        lambda s: st.tuples(
            st.just(s),
            mutated(
                *{
                    ".pcd": (PCD_COMPRESSED, _header_end(PCD_COMPRESSED, b"\nDATA ") + 20),
                    ".ply": (PLY_BINARY, _header_end(PLY_BINARY, b"end_header\n")),
                }[s]
            ),
        )
    )
    | st.tuples(st.just(".pcd"), mutated(PCD_ASCII, len(PCD_ASCII)))
)
def test_mutated_clouds_load_or_refuse(tmp_path, case):
    """The decoders behind the headers: a mutated file loads (finite or NaN points, as many as
    its header says) or is refused with a CaptureError."""
    suffix, data = case
    path = tmp_path / ("fuzz" + suffix)
    path.write_bytes(data)
    try:
        cap = load_capture(path, units="m")
    except CaptureError:
        return
    assert cap.points.ndim == 2 and cap.points.shape[1] == 3 and len(cap.points) > 0
    assert cap.shape is None or cap.shape[0] * cap.shape[1] == len(cap.points)


def test_captured_output_restores_the_terminal(capfd):
    """The PLY fallback silences Open3D on file descriptors 1 and 2, then gives them back."""
    from roachplan.perception._read_ply import _captured_output

    with _captured_output() as said:
        os.write(1, b"hidden out\n")
        os.write(2, b"hidden err\n")
    os.write(1, b"shown\n")
    out, err = capfd.readouterr()
    assert "hidden" not in out + err and "shown" in out
    assert "hidden out" in said.getvalue() and "hidden err" in said.getvalue()
