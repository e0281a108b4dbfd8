"""Captures: what a depth camera saw, read from the files people bring.

Point clouds: PCL's .pcd (ascii, binary, binary_compressed; organized or not, via pypcd4),
.ply (Open3D), .xyz/.pts (text), .npy ((N, 3) or organized (H, W, 3)). Depth images: 16-bit
PNG with a depth scale (units per metre) and pinhole intrinsics. ROS bags (ROS 1 .bag, ROS 2
.db3/.mcap) with sensor_msgs/PointCloud2 or a depth sensor_msgs/Image + CameraInfo, read with
`rosbags` (no ROS installation). Everything comes out as points in the camera frame, metres
(x right, y down, z forward for depth images).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from ._camera import Intrinsics, intrinsics_from_mapping, load_intrinsics, xml_depth_scale
from ._errors import CaptureError

CLOUD_SUFFIXES = (".pcd", ".ply", ".xyz", ".pts", ".npy")
DEPTH_SUFFIXES = (".png",)
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
CAPTURE_SUFFIXES = CLOUD_SUFFIXES + DEPTH_SUFFIXES + BAG_SUFFIXES
Units = Literal["m", "mm"]


@dataclass(frozen=True, eq=False)
class Capture:
    """Points a depth camera saw."""

    points: np.ndarray
    """(N, 3) float64, camera frame [m]; rows of NaN are pixels without a measurement."""
    shape: tuple[int, int] | None
    """(H, W) when organized: N == H * W, row-major, as the sensor's pixels."""
    source: str
    """Where it came from, for messages."""
    intrinsics: Intrinsics | None = None
    sensor_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The camera's centre in the points' frame [m] (PCD VIEWPOINT; else the origin)."""

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: rows with a finite measurement."""
        return np.all(np.isfinite(self.points), axis=1)

    def finite_points(self) -> np.ndarray:
        return self.points[self.valid]


def load_capture(
    path: str | Path,
    *,
    intrinsics: str | Path | None = None,
    depth_scale: float | None = None,
    topic: str | None = None,
    units: Units = "m",
) -> Capture:
    """Read a capture file; CaptureError names the file and what is wrong with it.

    intrinsics / depth_scale: for depth PNGs (default: a sidecar .json/.xml next to the image,
    and 1000 units per metre, i.e. millimetres, or the sidecar XML's factor). topic: which
    topic of a bag (default: the first PointCloud2, else the first depth Image). units: "mm"
    when a point cloud is stored in millimetres.
    """
    path = Path(path)
    if not path.exists():
        raise CaptureError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in CAPTURE_SUFFIXES:
        raise CaptureError(
            f"{path}: unknown capture type {suffix!r}; accepted: {', '.join(CAPTURE_SUFFIXES)}"
        )
    if suffix in DEPTH_SUFFIXES:
        cap = _load_depth_png(path, intrinsics, depth_scale)
    elif suffix in BAG_SUFFIXES:
        cap = _load_bag(path, topic, depth_scale)
    else:
        cap = {".pcd": _load_pcd, ".ply": _load_ply, ".npy": _load_npy}.get(suffix, _load_text)(
            path
        )
    if units == "mm":
        cap = dataclasses.replace(cap, points=cap.points * 1e-3)
    return check_capture(cap)


def check_capture(cap: Capture) -> Capture:
    """Refuse captures nothing useful can come from, saying why."""
    if len(cap.points) == 0:
        raise CaptureError(f"{cap.source}: the capture has no points")
    pts = cap.finite_points()
    if len(pts) == 0:
        raise CaptureError(f"{cap.source}: every point is invalid (NaN or zero depth)")
    depth = np.median(np.linalg.norm(pts - np.asarray(cap.sensor_origin), axis=1))
    if depth > 20.0:
        raise CaptureError(
            f"{cap.source}: the median distance from the camera is {depth:.0f} - this looks "
            f"like millimetres, not metres; convert the file, or pass units mm (--units mm)"
        )
    return cap


def depth_to_points(depth_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """(H, W) depth along the optical axis [m] (0 or NaN = none) -> (H*W, 3) camera-frame
    points [m], NaN where there is no depth."""
    z = np.where(depth_m > 0, depth_m, np.nan)
    pts = intr.rays() * z[..., None]
    return pts.reshape(-1, 3)


# -- formats --------------------------------------------------------------------------------


def _head(path: Path, n: int) -> bytes:
    """The first n bytes of a file (without reading a large capture whole)."""
    with open(path, "rb") as f:
        return f.read(n)


def _sniff(path: Path, magic: tuple[bytes, ...], what: str) -> None:
    head = _head(path, 64)
    if not any(head.startswith(m) for m in magic):
        raise CaptureError(f"{path}: not a {what} file (it starts with {head[:16]!r})")


def _load_pcd(path: Path) -> Capture:
    from pypcd4 import PointCloud

    head = _head(path, 256)
    if not (head.startswith(b"#") or head.startswith(b"VERSION") or head.startswith(b"FIELDS")):
        raise CaptureError(f"{path}: not a PCD file (no PCD header; starts with {head[:16]!r})")
    try:
        pc = PointCloud.from_path(path)
    except Exception as exc:  # noqa: BLE001 - pypcd4 raises many kinds on a damaged file
        raise CaptureError(f"{path}: cannot read this PCD file: {exc}") from None
    missing = [f for f in "xyz" if f not in pc.fields]
    if missing:
        raise CaptureError(f"{path}: the PCD has fields {pc.fields}; it needs x, y and z")
    pts = np.asarray(pc.numpy(("x", "y", "z")), dtype=np.float64)
    w, h = pc.metadata.width, pc.metadata.height
    vp = pc.metadata.viewpoint
    return Capture(
        points=pts, shape=(h, w) if h > 1 and w * h == len(pts) else None, source=str(path),
        sensor_origin=(float(vp[0]), float(vp[1]), float(vp[2])),
    )  # fmt: skip


def _load_ply(path: Path) -> Capture:
    import open3d as o3d

    _sniff(path, (b"ply",), "PLY")
    cloud = o3d.io.read_point_cloud(str(path), remove_nan_points=False)
    pts = np.asarray(cloud.points, dtype=np.float64)
    return Capture(points=pts, shape=None, source=str(path))


def _load_text(path: Path) -> Capture:
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError:
        raise CaptureError(f"{path}: not a text point list (binary content)") from None
    rows = [ln.split() for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]
    if rows and len(rows[0]) == 1:  # .pts files may start with the point count
        rows = rows[1:]
    try:
        pts = np.array([[float(v) for v in r[:3]] for r in rows if len(r) >= 3], dtype=np.float64)
    except ValueError as exc:
        raise CaptureError(f"{path}: expected lines of 'x y z [...]' numbers ({exc})") from None
    if len(rows) and len(pts) != len(rows):
        raise CaptureError(f"{path}: every line needs at least x y z")
    return Capture(points=pts.reshape(-1, 3), shape=None, source=str(path))


def _load_npy(path: Path) -> Capture:
    _sniff(path, (b"\x93NUMPY",), "NumPy .npy")
    try:
        a = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise CaptureError(f"{path}: cannot read this .npy ({exc})") from None
    if a.ndim == 3 and a.shape[2] >= 3:
        h, w = a.shape[:2]
        return Capture(points=a[..., :3].reshape(-1, 3).astype(np.float64), shape=(h, w),
                       source=str(path))  # fmt: skip
    if a.ndim == 2 and a.shape[1] >= 3:
        return Capture(points=a[:, :3].astype(np.float64), shape=None, source=str(path))
    raise CaptureError(f"{path}: expected an (N, 3) or (H, W, 3) array, got shape {a.shape}")


def _sidecars(path: Path) -> list[Path]:
    stems = [path.stem]
    if "_depth" in path.stem:
        stems.append(path.stem.split("_depth")[0])
    return [path.with_name(s + ext) for s in stems for ext in (".json", ".xml")]


def _load_depth_png(path: Path, intrinsics, depth_scale: float | None) -> Capture:
    from PIL import Image

    _sniff(path, (b"\x89PNG\r\n\x1a\n",), "PNG")
    with Image.open(path) as im:
        if im.mode not in ("I;16", "I;16B", "I", "I;16L"):
            raise CaptureError(
                f"{path}: a depth PNG must be 16-bit greyscale (mode I;16), this one is "
                f"{im.mode} - an 8-bit or colour image has no depth in it"
            )
        depth = np.asarray(im, dtype=np.float64)
    sidecar = next((p for p in _sidecars(path) if p.is_file()), None)
    if intrinsics is None:
        if sidecar is None:
            raise CaptureError(
                f"{path}: a depth image needs intrinsics: pass --intrinsics FILE.json|xml or a "
                f"preset (kinect2-sd, kinect2-qhd, kinect2-hd), or put {path.stem}.json beside it"
            )
        intrinsics = sidecar
    intr = load_intrinsics(intrinsics)
    if depth_scale is None:
        depth_scale = xml_depth_scale(sidecar) if sidecar and sidecar.suffix == ".xml" else None
        depth_scale = depth_scale or _json_depth_scale(sidecar) or 1000.0
    h, w = depth.shape
    if (intr.width, intr.height) != (w, h):
        if abs(intr.width / w - intr.height / h) > 1e-6:
            raise CaptureError(
                f"{path}: the image is {w}x{h}, the intrinsics are for "
                f"{intr.width}x{intr.height} (another aspect ratio)"
            )
        intr = intr.scaled(w, h)
    if not np.any(depth > 0):
        raise CaptureError(f"{path}: every pixel is 0 (no depth measured)")
    pts = depth_to_points(depth / depth_scale, intr)
    return Capture(points=pts, shape=(h, w), source=str(path), intrinsics=intr)


def _json_depth_scale(sidecar: Path | None) -> float | None:
    import json

    if sidecar is None or sidecar.suffix != ".json":
        return None
    try:
        v = json.loads(sidecar.read_text()).get("depth_scale")
    except (ValueError, AttributeError, OSError):
        return None
    return float(v) if isinstance(v, int | float) and v > 0 else None


# -- ROS bags -------------------------------------------------------------------------------

_PC2_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def pointcloud2_to_points(msg) -> tuple[np.ndarray, tuple[int, int] | None]:
    """sensor_msgs/PointCloud2 -> ((N, 3) float64 points, (H, W) if organized)."""
    fields = {f.name: f for f in msg.fields}
    if not all(k in fields for k in "xyz"):
        raise CaptureError(f"PointCloud2 has fields {list(fields)}; it needs x, y and z")
    end = ">" if msg.is_bigendian else "<"
    dtype = np.dtype({
        "names": list("xyz"),
        "formats": [end + _PC2_TYPES[fields[k].datatype] for k in "xyz"],
        "offsets": [fields[k].offset for k in "xyz"],
        "itemsize": msg.point_step,
    })  # fmt: skip
    h, w = msg.height, msg.width
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(h, msg.row_step)
    rows = raw[:, : w * msg.point_step].copy().view(dtype).reshape(-1)
    pts = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    return pts, ((h, w) if h > 1 else None)


def _load_bag(path: Path, topic: str | None, depth_scale: float | None) -> Capture:
    from rosbags.highlevel import AnyReader

    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises its own error types per format
        raise CaptureError(f"{path}: cannot open this bag: {exc}") from None
    try:
        conns = reader.connections
        types = {c.topic: c.msgtype for c in conns}
        wanted = [c for c in conns if topic is None or c.topic == topic]
        if topic is not None and not wanted:
            raise CaptureError(f"{path}: no topic {topic!r}; it has {sorted(types)}")
        clouds = [c for c in wanted if c.msgtype == "sensor_msgs/msg/PointCloud2"]
        images = [c for c in wanted if c.msgtype == "sensor_msgs/msg/Image"]
        if clouds:
            _, _, raw = next(reader.messages(connections=clouds[:1]))
            msg = reader.deserialize(raw, clouds[0].msgtype)
            pts, shape = pointcloud2_to_points(msg)
            return Capture(points=pts, shape=shape, source=f"{path} ({clouds[0].topic})")
        if images:
            return _bag_depth_image(reader, path, images[0], depth_scale)
        raise CaptureError(
            f"{path}: no sensor_msgs/PointCloud2 or depth sensor_msgs/Image topic; topics: "
            f"{', '.join(f'{t} ({m})' for t, m in sorted(types.items())) or 'none'}"
        )
    finally:
        reader.close()


def _bag_depth_image(reader, path: Path, conn, depth_scale: float | None) -> Capture:
    _, _, raw = next(reader.messages(connections=[conn]))
    img = reader.deserialize(raw, conn.msgtype)
    enc = img.encoding.lower()
    if enc in ("16uc1", "mono16"):
        dt, scale = np.dtype(">u2" if img.is_bigendian else "<u2"), depth_scale or 1000.0
    elif enc == "32fc1":
        dt, scale = np.dtype(">f4" if img.is_bigendian else "<f4"), depth_scale or 1.0
    else:
        raise CaptureError(
            f"{path} ({conn.topic}): depth encoding {img.encoding!r}; accepted: 16UC1, 32FC1"
        )
    rows = np.frombuffer(bytes(img.data), dtype=np.uint8).reshape(img.height, img.step)
    depth = rows[:, : img.width * dt.itemsize].copy().view(dt).astype(np.float64)
    info = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/CameraInfo"]
    if not info:
        raise CaptureError(
            f"{path}: a depth Image needs a sensor_msgs/CameraInfo topic for its intrinsics"
        )
    _, _, raw = next(reader.messages(connections=info[:1]))
    ci = reader.deserialize(raw, info[0].msgtype)
    k = np.asarray(getattr(ci, "k", None) if hasattr(ci, "k") else ci.K, dtype=float).reshape(3, 3)
    intr = intrinsics_from_mapping(
        {"width": img.width, "height": img.height, "fx": k[0, 0], "fy": k[1, 1],
         "cx": k[0, 2], "cy": k[1, 2]}, f"{path} ({info[0].topic})",
    )  # fmt: skip
    depth = np.nan_to_num(depth / scale, nan=0.0)
    if not np.any(depth > 0):
        raise CaptureError(f"{path} ({conn.topic}): every pixel is 0 (no depth measured)")
    return Capture(points=depth_to_points(depth, intr), shape=(img.height, img.width),
                   source=f"{path} ({conn.topic})", intrinsics=intr)  # fmt: skip
