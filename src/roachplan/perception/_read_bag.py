"""ROS bags: ROS 1 .bag, ROS 2 .db3/.mcap (or a ROS 2 bag's folder), read with `rosbags` (no
ROS installation), holding a sensor_msgs/PointCloud2 or a depth sensor_msgs/Image with its
CameraInfo; a sensor_msgs/Imu gives the up direction. A ROS 1 bag's records are checked against
the file's size, and its chunks decompress to a bounded size, before rosbags reads them."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path
from typing import Literal

import numpy as np

from ._camera import intrinsics_from_mapping
from ._capture import Capture, depth_to_points
from ._errors import CaptureError
from ._headers import MAX_CLOUD_POINTS, check_pixels
from ._read_common import file_head
from ._yaml import short_repr

MAX_BAG_CHUNK_BYTES = 1024**3
"""Largest decompressed chunk of a ROS 1 bag [bytes]; a bag's chunk holds a few seconds of
messages, and a bz2 or lz4 block can otherwise decompress to any size."""

_PC2_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def pointcloud2_to_points(msg) -> tuple[np.ndarray, tuple[int, int] | None]:
    """sensor_msgs/PointCloud2 -> ((N, 3) float64 points, (H, W) if organized). Its layout
    (types, offsets, steps) is checked against the bytes it carries before they are read."""
    fields = {f.name: f for f in msg.fields}
    if not all(k in fields for k in "xyz"):
        raise CaptureError(f"PointCloud2 has fields {list(fields)[:12]}; it needs x, y and z")
    h, w, step, row = int(msg.height), int(msg.width), int(msg.point_step), int(msg.row_step)
    for k in "xyz":
        f = fields[k]
        if f.datatype not in _PC2_TYPES:
            raise CaptureError(
                f"PointCloud2 field {k}: datatype {f.datatype}; accepted: 1-8 (INT8 ... FLOAT64)"
            )
        if f.offset + int(_PC2_TYPES[f.datatype][1]) > step:
            raise CaptureError(
                f"PointCloud2 field {k}: offset {f.offset} runs past point_step {step}"
            )
    if h * w > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"PointCloud2 of {h}x{w} points; clouds of at most "
            f"{MAX_CLOUD_POINTS // 1_000_000} million points are read"
        )
    if h * w == 0:
        raise CaptureError(f"PointCloud2 of {h}x{w} points: no points")
    if row < w * step or len(msg.data) < h * row:
        raise CaptureError(
            f"PointCloud2 of {h}x{w} points of {step} bytes, rows of {row} bytes, carries "
            f"{len(msg.data)} bytes: its row_step or data is too short"
        )
    end = ">" if msg.is_bigendian else "<"
    dtype = np.dtype(
        {
            "names": list("xyz"),
            "formats": [end + _PC2_TYPES[fields[k].datatype] for k in "xyz"],
            "offsets": [fields[k].offset for k in "xyz"],
            "itemsize": msg.point_step,
        }
    )
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8, count=h * row).reshape(h, row)
    rows = raw[:, : w * step].copy().view(dtype).reshape(-1)
    pts = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    return pts, ((h, w) if h > 1 else None)


BAG_MAGIC = {
    ".bag": ("a ROS 1 bag", b"#ROSBAG V2.0\n"),
    ".db3": ("a ROS 2 SQLite bag", b"SQLite format 3\0"),
    ".mcap": ("an MCAP bag", b"\x89MCAP0\r\n"),
}
"""Suffix -> what it is and what it starts with (ROS 1: format 2.0, the only one rosbags
reads)."""


MAX_BAG_METADATA_BYTES = 16 * 1024**2
"""Largest ROS 2 metadata.yaml read [bytes]; a bag of a thousand topics has a few hundred kB."""


def read_bag(path: Path, topic: str | None, depth_scale: float | None) -> Capture:
    """A bag file, or a ROS 2 bag's folder. The file's kind is checked on its first bytes, a
    ROS 1 bag's records against the file's size (check_ros1_bag); whatever rosbags raises
    on a damaged bag, while opening or reading a message, becomes a CaptureError."""
    from rosbags.highlevel import AnyReader

    meta = path / "metadata.yaml"
    if path.is_dir() and meta.stat().st_size > MAX_BAG_METADATA_BYTES:
        raise CaptureError(
            f"{meta}: {meta.stat().st_size} bytes; a ROS 2 bag's metadata.yaml of at most "
            f"{MAX_BAG_METADATA_BYTES // 1024**2} MiB is read"
        )
    if path.is_file():
        what, magic = BAG_MAGIC[path.suffix.lower()]
        head = file_head(path, 64)
        if head.startswith(b"#ROSBAG V") and not head.startswith(magic):
            raise CaptureError(
                f"{path}: a ROS 1 bag of format {head[9:12].decode('latin-1')!r}; only format "
                f"2.0 (ROS 1 since 2010) is read: convert it with `rosbag fix`"
            )
        if not head.startswith(magic):
            raise CaptureError(
                f"{path}: not {what} ({path.suffix.lower()}): it starts with {head[:16]!r}, "
                f"{what} with {magic!r}"
            )
        if path.suffix.lower() == ".bag":
            check_ros1_bag(path)
    _bound_ros1_decompression()
    try:
        reader = AnyReader([path])
        reader.open()
    except CaptureError as exc:  # the bounded decompressors know no file name
        raise CaptureError(f"{path}: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own error types per format
        raise CaptureError(f"{path}: cannot open this bag: {_said(exc)}") from None
    try:
        return _read_bag(reader, path, topic, depth_scale)
    except CaptureError as exc:
        if str(exc).startswith(str(path)):
            raise
        raise CaptureError(f"{path}: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - a damaged message: rosbags, struct, numpy errors
        raise CaptureError(f"{path}: a damaged bag: {_said(exc)}") from None
    finally:
        reader.close()


def _said(exc: BaseException) -> str:
    """An exception from a library, bounded, for a message."""
    return f"{type(exc).__name__}: {' '.join(str(exc).split())[:240]}"


def check_ros1_bag(path: Path) -> None:
    """Walk a ROS 1 bag's records (header length, header, data length, data) and refuse one
    that runs past the end of the file, an unknown chunk compression, or a chunk larger than
    MAX_BAG_CHUNK_BYTES: before rosbags reads (and allocates) what they claim. Only the small
    record headers are read."""
    size = path.stat().st_size
    pos, n = 13, 0
    with open(path, "rb") as f:
        while pos < size:
            f.seek(pos)
            lengths = f.read(4)
            hlen = struct.unpack("<I", lengths)[0] if len(lengths) == 4 else size
            if pos + 8 + hlen > size or hlen > 16 * 1024**2:
                raise CaptureError(
                    f"{path}: record {n} of the bag, at byte {pos}, has a header of "
                    f"{hlen} bytes, but the file ends at byte {size}: the bag is truncated"
                )
            fields = _ros1_fields(path, f.read(hlen), pos)
            if "op" not in fields:
                raise CaptureError(
                    f"{path}: the bag's record at byte {pos} has no op field: damaged"
                )
            dlen = struct.unpack("<I", f.read(4))[0]
            if pos + 8 + hlen + dlen > size:
                raise CaptureError(
                    f"{path}: record {n} of the bag, at byte {pos}, holds {dlen} bytes, but "
                    f"the file ends at byte {size}: the bag is truncated"
                )
            if fields.get("op") == b"\x05":  # a chunk: its compression and unpacked size
                kind = fields.get("compression", b"").decode("latin-1")
                unpacked = fields.get("size", b"")
                unpacked = struct.unpack("<I", unpacked)[0] if len(unpacked) == 4 else -1
                if kind not in ("none", "bz2", "lz4") or not 0 <= unpacked <= MAX_BAG_CHUNK_BYTES:
                    raise CaptureError(
                        f"{path}: chunk at byte {pos}: compression {kind[:16]!r}, size "
                        f"{unpacked}; accepted: none, bz2 or lz4, at most "
                        f"{MAX_BAG_CHUNK_BYTES // 1024**2} MiB unpacked"
                    )
            pos, n = pos + 8 + hlen + dlen, n + 1


def _ros1_fields(path: Path, header: bytes, pos: int) -> dict[str, bytes]:
    """A ROS 1 record header: fields of a 4-byte length then name=value."""
    fields, i = {}, 0
    while i < len(header):
        if i + 4 > len(header):
            raise CaptureError(f"{path}: the bag's record at byte {pos} has a damaged header")
        n = struct.unpack("<I", header[i : i + 4])[0]
        name, eq, value = header[i + 4 : i + 4 + n].partition(b"=")
        if i + 4 + n > len(header) or not eq:
            raise CaptureError(f"{path}: the bag's record at byte {pos} has a damaged header")
        fields[name.decode("latin-1")] = value
        i += 4 + n
    return fields


def _bound_ros1_decompression() -> None:
    """Make rosbags' ROS 1 reader decompress a chunk to at most MAX_BAG_CHUNK_BYTES: a bz2 or
    lz4 block of a few kilobytes can unpack to gigabytes, and rosbags unpacks whole chunks
    with no limit. Its reader looks its decompressors up in a module dict on every chunk;
    replacing them there is the only hook it offers."""
    import bz2

    import lz4.frame
    from rosbags.rosbag1 import reader

    def bounded(make):
        def decompress(data: bytes) -> bytes:
            out = bytearray()
            while data:  # bz2.decompress, which rosbags calls, reads streams one after another
                stream = make()
                out += stream.decompress(data, max_length=MAX_BAG_CHUNK_BYTES + 1 - len(out))
                if len(out) > MAX_BAG_CHUNK_BYTES:
                    raise CaptureError(
                        f"a chunk of the bag unpacks to more than "
                        f"{MAX_BAG_CHUNK_BYTES // 1024**2} MiB: damaged, or crafted to fill the "
                        f"memory"
                    )
                if not stream.eof:
                    raise ValueError("a compressed chunk ends before its end-of-stream marker")
                data = stream.unused_data
            return bytes(out)

        return decompress

    reader.decompressors["bz2"] = bounded(bz2.BZ2Decompressor)
    reader.decompressors["lz4"] = bounded(lz4.frame.LZ4FrameDecompressor)


def _read_bag(reader, path: Path, topic: str | None, depth_scale: float | None) -> Capture:
    conns = reader.connections
    types = {c.topic: c.msgtype for c in conns}
    wanted = [c for c in conns if topic is None or c.topic == topic]
    if topic is not None and not wanted:
        raise CaptureError(
            f"{path}: no topic {short_repr(topic)}; it has {', '.join(sorted(types))[:400] or 'no topics'}"
        )
    clouds = [c for c in wanted if c.msgtype == "sensor_msgs/msg/PointCloud2"]
    images = [c for c in wanted if c.msgtype == "sensor_msgs/msg/Image"]
    if clouds:
        raw = _first_message(reader, path, clouds[0])
        msg = reader.deserialize(raw, clouds[0].msgtype)
        try:
            pts, shape = pointcloud2_to_points(msg)
        except CaptureError as exc:
            raise CaptureError(f"{path} ({clouds[0].topic}): {exc}") from None
        cap = Capture(
            points=pts,
            shape=shape,
            source=f"{path} ({clouds[0].topic})",
            frame=_frame_of(msg.header.frame_id),
        )
        return _with_imu_gravity(reader, cap, msg.header.frame_id)
    if images:
        cap = _bag_depth_image(reader, path, images[0], depth_scale)
        return _with_imu_gravity(reader, cap, None)
    raise CaptureError(
        f"{path}: no sensor_msgs/PointCloud2 or depth sensor_msgs/Image topic; topics: "
        f"{', '.join(f'{t} ({m})' for t, m in sorted(types.items())) or 'none'}"
    )


def _first_message(reader, path: Path, conn) -> bytes:
    """The raw first message of a connection."""
    first = next(reader.messages(connections=[conn]), None)
    if first is None:
        raise CaptureError(f"{path}: the topic {conn.topic} ({conn.msgtype}) has no messages")
    return first[2]


def _frame_of(frame_id: str) -> Literal["camera", "world"]:
    """ROS frames are z up (REP 103) unless they are a camera's optical frame (REP 103's
    `_optical` suffix: x right, y down, z forward)."""
    return "camera" if "optical" in frame_id.lower() else "world"


def _with_imu_gravity(reader, cap: Capture, cloud_frame: str | None) -> Capture:
    """The capture with the up direction of the bag's IMU, if it has a sensor_msgs/Imu topic:
    at rest an accelerometer reads the reaction to gravity, +9.8 m/s^2 pointing up. The mean
    of its first 100 readings is taken as up in the IMU's frame, assumed aligned with the
    cloud's (a bag seldom carries the transform between them; said in the notes)."""
    imus = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/Imu"]
    if not imus:
        return cap
    acc, frame_id = [], ""
    for k, (conn, _, raw) in enumerate(reader.messages(connections=imus[:1])):
        msg = reader.deserialize(raw, conn.msgtype)
        a = msg.linear_acceleration
        acc.append((a.x, a.y, a.z))
        frame_id = msg.header.frame_id
        if k >= 99:
            break
    mean = np.mean(np.asarray(acc, dtype=np.float64), axis=0) if acc else np.zeros(3)
    g = float(np.linalg.norm(mean))
    if not np.isfinite(g) or not 5.0 <= g <= 15.0:  # not at rest, or not in m/s^2
        return dataclasses.replace(
            cap,
            notes=(
                *cap.notes,
                f"the IMU ({imus[0].topic}) reads {g:.1f} m/s^2, not gravity: its up was not used",
            ),
        )
    note = f"up from the IMU ({imus[0].topic}, frame {frame_id or '?'})"
    if cloud_frame is not None and frame_id and frame_id.strip("/") != cloud_frame.strip("/"):
        note += f", assumed aligned with the cloud's frame {cloud_frame}"
    up = tuple(float(v) for v in mean / g)
    return dataclasses.replace(cap, up=up, notes=(*cap.notes, note))


def _bag_depth_image(reader, path: Path, conn, depth_scale: float | None) -> Capture:
    img = reader.deserialize(_first_message(reader, path, conn), conn.msgtype)
    enc = img.encoding.lower()
    if enc in ("16uc1", "mono16"):
        dt, scale = np.dtype(">u2" if img.is_bigendian else "<u2"), depth_scale or 1000.0
    elif enc == "32fc1":
        dt, scale = np.dtype(">f4" if img.is_bigendian else "<f4"), depth_scale or 1.0
    else:
        raise CaptureError(
            f"{path} ({conn.topic}): depth encoding {img.encoding!r}; accepted: 16UC1, 32FC1"
        )
    h, w, step = int(img.height), int(img.width), int(img.step)
    check_pixels(f"{path} ({conn.topic})", w, h)
    if step < w * dt.itemsize or len(img.data) < h * step:
        raise CaptureError(
            f"{path} ({conn.topic}): a {w}x{h} {img.encoding} image with rows of {step} bytes "
            f"carries {len(img.data)} bytes: its step or data is too short"
        )
    rows = np.frombuffer(bytes(img.data), dtype=np.uint8, count=h * step).reshape(h, step)
    depth = rows[:, : img.width * dt.itemsize].copy().view(dt).astype(np.float64)
    info = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/CameraInfo"]
    if not info:
        raise CaptureError(
            f"{path}: a depth Image needs a sensor_msgs/CameraInfo topic for its intrinsics"
        )
    ci = reader.deserialize(_first_message(reader, path, info[0]), info[0].msgtype)
    k = np.asarray(getattr(ci, "k", None) if hasattr(ci, "k") else ci.K, dtype=float).reshape(3, 3)
    intr = intrinsics_from_mapping(
        {
            "width": img.width,
            "height": img.height,
            "fx": k[0, 0],
            "fy": k[1, 1],
            "cx": k[0, 2],
            "cy": k[1, 2],
        },
        f"{path} ({info[0].topic})",
    )
    depth = np.nan_to_num(depth / scale, nan=0.0)
    if not np.any(depth > 0):
        raise CaptureError(f"{path} ({conn.topic}): every pixel is 0 (no depth measured)")
    return Capture(
        points=depth_to_points(depth, intr),
        shape=(img.height, img.width),
        source=f"{path} ({conn.topic})",
        intrinsics=intr,
        frame="camera",
        depth_scale=scale,
    )
