"""Captures: what a depth camera saw, read from the files people bring.

Point clouds: PCL's .pcd (ascii, binary, binary_compressed; organized or not, via pypcd4),
.ply (Open3D), .xyz/.pts (text), .npy ((N, 3) or organized (H, W, 3)). Depth images: 16-bit
PNG or netpbm PGM/PPM with a depth scale (units per metre) and pinhole intrinsics (a preset, a
calibration file, or numbers; see _camera.load_calibration). ROS bags (ROS 1 .bag, ROS 2
.db3/.mcap) with sensor_msgs/PointCloud2 or a depth sensor_msgs/Image + CameraInfo, read with
`rosbags` (no ROS installation). Everything comes out as points in the camera frame, metres
(x right, y down, z forward for depth images).
"""

from __future__ import annotations

import dataclasses
import struct
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from ._camera import (
    CALIBRATION_FORMATS,
    PRESETS,
    Intrinsics,
    PinholeNumbers,
    intrinsics_from_mapping,
    is_calibration_yaml,
    load_calibration,
)
from ._errors import CaptureError

CLOUD_SUFFIXES = (".pcd", ".ply", ".xyz", ".pts", ".npy")
DEPTH_SUFFIXES = (".png", ".pgm", ".ppm")
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
CAPTURE_SUFFIXES = CLOUD_SUFFIXES + DEPTH_SUFFIXES + BAG_SUFFIXES
SIDECAR_SUFFIXES = (".json", ".xml", ".yaml", ".yml")
MAX_DEPTH_PIXELS = 100_000_000
"""Largest depth image read [pixels], checked on the header before decoding: a small file can
claim (PNG's compression, a netpbm header that lies) an image that would fill the memory."""
Units = Literal["m", "mm"]
IntrinsicsSpec = str | Path | Mapping | PinholeNumbers


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
    up: tuple[float, float, float] | None = None
    """Measured up direction in the points' frame (an IMU's gravity), if the file has one."""
    frame: Literal["camera", "world"] | None = None
    """What the file says of its frame: a camera's optical frame (x right, y down, z forward),
    a z-up world or robot frame (REP 103), or None when it does not say."""
    notes: tuple[str, ...] = ()
    """What the reader assumed, for the user."""
    base_from_camera: np.ndarray | None = None
    """(4, 4) transform of camera-frame points into the robot's base frame (z up) [m], when
    the calibration says (OpenCV YAML's local_transform); a gravity prior, not the world."""
    depth_scale: float | None = None
    """Depth units per metre the depth image was read with; None for point clouds."""

    @property
    def valid(self) -> np.ndarray:
        """(N,) bool: rows with a finite measurement."""
        return np.all(np.isfinite(self.points), axis=1)

    def finite_points(self) -> np.ndarray:
        return self.points[self.valid]


def load_capture(
    path: str | Path,
    *,
    intrinsics: IntrinsicsSpec | None = None,
    depth_scale: float | None = None,
    topic: str | None = None,
    units: Units | None = None,
) -> Capture:
    """Read a capture file; CaptureError names the file and what is wrong with it.

    intrinsics / depth_scale: for depth images (.png, .pgm, .ppm). intrinsics: a preset name, a
    calibration file, or numbers {fx, fy, cx, cy[, width, height]}; default: a calibration file
    beside the image (SIDECAR_SUFFIXES; same stem, or the stem before "_depth"). depth_scale
    [units per metre]: default the calibration's (a preset's, e.g. TUM 5000; PCL XML's z
    factor; a JSON/YAML depth_scale), else the sidecar's, else 1000 (millimetres). topic: which
    topic of a bag (default: the first PointCloud2, else the first depth Image). units: "mm"
    when a point cloud is stored in millimetres, "m" in metres; None: metres unless the cloud
    can only be millimetres (see check_capture).
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
        cap = _load_depth_image(path, intrinsics, depth_scale)
    elif suffix in BAG_SUFFIXES:
        cap = _load_bag(path, topic, depth_scale)
    else:
        cap = {".pcd": _load_pcd, ".ply": _load_ply, ".npy": _load_npy}.get(suffix, _load_text)(
            path
        )
    if units == "mm":
        cap = dataclasses.replace(
            cap, points=cap.points * 1e-3,
            sensor_origin=tuple(float(v) * 1e-3 for v in cap.sensor_origin),
        )  # fmt: skip
    return check_capture(cap, units_given=units is not None)


GEOREFERENCED_M = 1000.0
"""A cloud whose centre is this far from its origin [m], and much farther than the cloud is
wide, is in a map frame (UTM, a site grid): it is recentred, and never taken for millimetres."""
MAX_RANGE_M = 200.0
"""No depth camera or ordinary lidar sees a median point this far away [m]: a camera-frame
cloud whose median distance is larger is in millimetres (a depth camera's nearest range,
0.3 m, is already 300 in millimetres)."""


def is_georeferenced(points: np.ndarray) -> bool:
    """points: (N, 3) finite. Its centre lies far from the origin compared with its size."""
    centre = np.median(points, axis=0)
    size = float(np.max(np.percentile(points, 98, axis=0) - np.percentile(points, 2, axis=0)))
    far = float(np.linalg.norm(centre))
    return far > GEOREFERENCED_M and far > 20.0 * max(size, 1e-9)


def check_capture(cap: Capture, units_given: bool = False) -> Capture:
    """Refuse captures nothing useful can come from, saying why. Without units given, a
    sensor-frame cloud whose median distance is beyond any sensor's range is refused as
    millimetres; a georeferenced cloud (far from its origin, small beside that distance) is
    not judged by its distance."""
    if len(cap.points) == 0:
        raise CaptureError(f"{cap.source}: the capture has no points")
    pts = cap.finite_points()
    if len(pts) == 0:
        raise CaptureError(f"{cap.source}: every point is invalid (NaN or zero depth)")
    if units_given or is_georeferenced(pts):
        return cap
    depth = np.median(np.linalg.norm(pts - np.asarray(cap.sensor_origin), axis=1))
    if depth > MAX_RANGE_M and cap.depth_scale is not None:  # a depth image: its scale is off
        raise CaptureError(
            depth_scale_advice(cap, (0.3, 8.0))  # a depth camera's range [m]
            or f"{cap.source}: the median depth is {depth:.0f} m at {cap.depth_scale:g} units "
            f"per metre: check the depth scale (--depth-scale)"
        )
    if depth > MAX_RANGE_M:
        raise CaptureError(
            f"{cap.source}: the median distance from the sensor is {depth:.0f}; in metres that "
            f"is beyond any depth camera or lidar, so it looks like millimetres: pass units mm "
            f"(--units mm), or units m (--units m) if it really is in metres"
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
    organized = h > 1 and w * h == len(pts)
    return Capture(
        points=pts, shape=(h, w) if organized else None, source=str(path),
        sensor_origin=(float(vp[0]), float(vp[1]), float(vp[2])),
        frame="camera" if organized else None,  # organized: a camera's pixels, optical frame
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
    return [path.with_name(s + ext) for s in stems for ext in SIDECAR_SUFFIXES]


def find_sidecar(path: Path) -> Path | None:
    """The calibration file beside a depth image, if any: the same stem (or the stem before
    "_depth") with a SIDECAR_SUFFIXES suffix. A YAML file there that is no calibration (an
    uploaded capture's scene file is named like it) is passed over."""
    for p in _sidecars(path):
        if p.is_file() and (p.suffix.lower() not in (".yaml", ".yml") or is_calibration_yaml(p)):
            return p
    return None


def _needs_intrinsics(path: Path) -> CaptureError:
    return CaptureError(
        f"{path}: a depth image needs intrinsics: pass --intrinsics with a preset "
        f"({', '.join(PRESETS)}) or a calibration file, or the numbers --fx --fy --cx --cy "
        f"(`intrinsics: {{fx, fy, cx, cy}}` in a scene), or put {path.stem}.json, .xml, .yaml "
        f"or .yml beside it. Calibration files: {CALIBRATION_FORMATS}"
    )


def _load_depth_image(path: Path, intrinsics, depth_scale: float | None) -> Capture:
    reader = _read_depth_png if path.suffix.lower() == ".png" else read_netpbm_depth
    depth = reader(path).astype(np.float64)
    h, w = depth.shape
    sidecar = find_sidecar(path)
    spec = intrinsics if intrinsics is not None else sidecar
    if spec is None:
        raise _needs_intrinsics(path)
    calib = load_calibration(spec, size=(w, h))
    intr = calib.intrinsics
    if depth_scale is None:
        depth_scale = calib.depth_scale
    if depth_scale is None and sidecar is not None and intrinsics is not None:
        try:  # intrinsics given, the depth scale may still be written beside the image
            depth_scale = load_calibration(sidecar, size=(w, h)).depth_scale
        except CaptureError:
            pass
    depth_scale = depth_scale or 1000.0
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
    return Capture(points=pts, shape=(h, w), source=str(path), intrinsics=intr, frame="camera",
                   base_from_camera=calib.base_from_camera, depth_scale=depth_scale)  # fmt: skip


def _check_pixels(path: Path, width: int, height: int) -> None:
    if width * height > MAX_DEPTH_PIXELS:
        raise CaptureError(
            f"{path}: the header says {width}x{height} pixels ({width * height / 1e6:.0f} "
            f"megapixels); depth images of at most {MAX_DEPTH_PIXELS / 1e6:.0f} megapixels are "
            f"read (a larger one is damaged, or crafted to fill the memory)"
        )


def _read_depth_png(path: Path) -> np.ndarray:
    """A 16-bit greyscale PNG -> (H, W) raw depth units. The size is checked on the IHDR chunk
    (always the first) before Pillow decodes anything."""
    from PIL import Image

    _sniff(path, (b"\x89PNG\r\n\x1a\n",), "PNG")
    head = _head(path, 24)
    if head[12:16] != b"IHDR":
        raise CaptureError(f"{path}: a damaged PNG (its first chunk is not IHDR)")
    width, height = struct.unpack(">II", head[16:24])
    _check_pixels(path, width, height)
    try:
        with warnings.catch_warnings():  # the size is checked above, against our own limit
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                if im.mode not in ("I;16", "I;16B", "I", "I;16L"):
                    raise CaptureError(
                        f"{path}: a depth PNG must be 16-bit greyscale (mode I;16), this one is "
                        f"{im.mode} - an 8-bit or colour image has no depth in it"
                    )
                return np.asarray(im)
    except (OSError, SyntaxError, Image.DecompressionBombError) as exc:
        raise CaptureError(f"{path}: cannot decode this PNG: {exc}") from None


_NETPBM = {b"P2": (1, False), b"P5": (1, True), b"P3": (3, False), b"P6": (3, True)}
"""Magic -> (channels, binary)."""


def read_netpbm_depth(path: Path) -> np.ndarray:
    """A 16-bit netpbm image -> (H, W) uint16 raw depth units: PGM (P5 binary, P2 ASCII) or PPM
    (P6, P3), of which only the first channel is read (a colour pixmap has no depth; a depth
    tool that writes PPM repeats the depth in every channel). maxval > 255 means 16 bits per
    sample, big-endian (netpbm's rule); the samples are not rescaled by maxval. The header is
    checked against the file's real size before anything is allocated. Pillow is not used: it
    reads 16-bit PGM but not 16-bit PPM, and trusts the header's size."""
    head = _head(path, 4096)
    if head[:2] not in _NETPBM:
        raise CaptureError(
            f"{path}: not a netpbm image (it starts with {head[:16]!r}; accepted: P5/P2 "
            f"greymaps and P6/P3 pixmaps)"
        )
    channels, binary = _NETPBM[head[:2]]
    width, height, maxval, pos = _netpbm_header(path, head)
    samples = width * height * channels
    available = path.stat().st_size - pos
    # binary: 2 bytes per sample; ASCII: at least a digit and a separator per sample
    needed = 2 * samples if binary else 2 * samples - 1
    if available < needed:
        raise CaptureError(
            f"{path}: the netpbm header says {width}x{height}x{channels} 16-bit samples, which "
            f"need {needed} bytes{'' if binary else ' or more'}, but {max(available, 0)} follow "
            f"the header: the file is truncated or its header is wrong"
        )
    with open(path, "rb") as f:
        f.seek(pos)
        if binary:
            data = np.frombuffer(f.read(needed), dtype=">u2")
        else:
            words = f.read().split()
            if len(words) < samples or not all(w.isdigit() for w in words[:samples]):
                raise CaptureError(
                    f"{path}: the ASCII netpbm image needs {samples} decimal samples after the "
                    f"header, it has {len(words)} words (or some are not numbers)"
                )
            data = np.array(words[:samples], dtype=np.int64)
    if data.max() > maxval:
        raise CaptureError(f"{path}: a sample is {data.max()}, above the header's maxval {maxval}")
    return data.reshape(height, width, channels)[..., 0].astype(np.uint16)


def _netpbm_header(path: Path, head: bytes) -> tuple[int, int, int, int]:
    """A netpbm file's first bytes -> (width, height, maxval, offset of the pixels), checked:
    a 16-bit image within MAX_DEPTH_PIXELS."""
    numbers, pos = [], 2
    while len(numbers) < 3:  # width, height, maxval, between whitespace and # comments
        while pos < len(head) and (head[pos : pos + 1].isspace() or head[pos] == ord("#")):
            if head[pos] == ord("#"):
                end = head.find(b"\n", pos)
                pos = len(head) if end < 0 else end + 1
            else:
                pos += 1
        start = pos
        while pos < len(head) and head[pos : pos + 1].isdigit() and pos - start < 10:
            pos += 1
        if pos >= len(head):
            raise CaptureError(
                f"{path}: bad netpbm header: it ends (or its comments run past "
                f"{len(head)} bytes) before width, height and maxval are all given"
            )
        if pos == start or not head[pos : pos + 1].isspace():
            raise CaptureError(
                f"{path}: bad netpbm header: expected width, height and maxval (decimal numbers "
                f"between whitespace) after {head[:2].decode()}, found {head[start:start + 16]!r}"
            )
        numbers.append(int(head[start:pos]))
    width, height, maxval = numbers
    pos += 1  # the single whitespace character that ends the header
    if min(width, height) < 1 or not 1 <= maxval <= 65535:
        raise CaptureError(
            f"{path}: bad netpbm header: width {width}, height {height}, maxval {maxval} "
            f"(expected width, height >= 1 and maxval 1-65535)"
        )
    if maxval <= 255:
        raise CaptureError(
            f"{path}: an 8-bit netpbm image (maxval {maxval}) has no depth in it; a depth image "
            f"has maxval > 255 (16 bits per sample)"
        )
    _check_pixels(path, width, height)
    return width, height, maxval, pos


STANDARD_DEPTH_SCALES: dict[float, str] = {
    1.0: "metres, e.g. 32-bit float images",
    100.0: "centimetres",
    1000.0: "millimetres: Kinect, PrimeSense, RealSense D435, PCL, rtabmap",
    5000.0: "TUM RGB-D",
    10000.0: "0.1 mm, e.g. RealSense D405",
}
"""Depth units per metre that depth datasets and drivers use, with who uses them."""
TYPICAL_DEPTH_M = 2.5
"""Median depth of a typical depth-camera capture [m] (Kinect, PrimeSense and RealSense work
best at about 0.5-5 m); only breaks ties between depth scales that fit equally well."""


def depth_scale_advice(cap: Capture, depth_range: tuple[float, float]) -> str | None:
    """When most (> 50 %) of a depth image's measured pixels fall outside depth_range (near,
    far along the optical axis [m]), a message saying how many and which standard depth scale
    (STANDARD_DEPTH_SCALES) would put most of them inside; None when the capture is no depth
    image or most pixels are inside."""
    if cap.depth_scale is None:
        return None
    z = cap.points[cap.valid, 2]
    if len(z) == 0:
        return None
    lo, hi = depth_range
    near, far = float(np.mean(z < lo)), float(np.mean(z > hi))
    if near + far <= 0.5:
        return None
    span = f"{lo:g}–{hi:g} m"
    if near == 0 or far == 0:
        where = f"beyond {hi:g} m" if far > 0 else f"nearer than {lo:g} m"
        where = f"{(near + far) * 100:.0f} % of the measured pixels are {where}"
    else:
        where = (f"{(near + far) * 100:.0f} % of the measured pixels are outside {span} "
                 f"({far * 100:.0f} % beyond, {near * 100:.0f} % nearer)")  # fmt: skip
    msg = f"{cap.source}: {where} at {cap.depth_scale:g} units per metre"
    raw = z * cap.depth_scale
    inside = {s: float(np.mean((raw / s >= lo) & (raw / s <= hi)))
              for s in STANDARD_DEPTH_SCALES if s != cap.depth_scale}  # fmt: skip
    top = max(inside.values(), default=0.0)
    if top <= 0.5:
        return msg + "; no standard depth scale puts most of them inside: check the depth scale"
    # A wide depth range fits two scales (TUM's 5000 and 10000 both put a room inside
    # 0.3-8 m): of those within 5 points of the best, take the one whose median depth is
    # nearest a depth camera's typical working distance.
    median = float(np.median(raw))
    best = min((s for s, f in inside.items() if f >= top - 0.05),
               key=lambda s: abs(np.log(median / s / TYPICAL_DEPTH_M)))  # fmt: skip
    return (
        f"{msg}; with a depth scale of {best:g} ({STANDARD_DEPTH_SCALES[best]}) "
        f"{inside[best] * 100:.0f} % fall within {span}: pass --depth-scale {best:g} "
        f"(depth_scale: {best:g} in a scene)"
    )


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
            cap = Capture(points=pts, shape=shape, source=f"{path} ({clouds[0].topic})",
                          frame=_frame_of(msg.header.frame_id))  # fmt: skip
            return _with_imu_gravity(reader, cap, msg.header.frame_id)
        if images:
            cap = _bag_depth_image(reader, path, images[0], depth_scale)
            return _with_imu_gravity(reader, cap, None)
        raise CaptureError(
            f"{path}: no sensor_msgs/PointCloud2 or depth sensor_msgs/Image topic; topics: "
            f"{', '.join(f'{t} ({m})' for t, m in sorted(types.items())) or 'none'}"
        )
    finally:
        reader.close()


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
        return dataclasses.replace(cap, notes=(*cap.notes, f"the IMU ({imus[0].topic}) reads "
                                   f"{g:.1f} m/s^2, not gravity: its up was not used"))  # fmt: skip
    note = f"up from the IMU ({imus[0].topic}, frame {frame_id or '?'})"
    if cloud_frame is not None and frame_id and frame_id.strip("/") != cloud_frame.strip("/"):
        note += f", assumed aligned with the cloud's frame {cloud_frame}"
    up = tuple(float(v) for v in mean / g)
    return dataclasses.replace(cap, up=up, notes=(*cap.notes, note))  # type: ignore[arg-type]


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
                   source=f"{path} ({conn.topic})", intrinsics=intr, frame="camera",
                   depth_scale=scale)  # fmt: skip
