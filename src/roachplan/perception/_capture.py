"""Captures: what a depth camera saw, read from the files people bring.

Point clouds: PCL's .pcd (ascii, binary, binary_compressed; organized or not), .ply (ascii
or binary), .xyz/.pts (text), .npy ((N, 3) or organized (H, W, 3)). Depth images: 16-bit
PNG or netpbm PGM/PPM with a depth scale (units per metre) and pinhole intrinsics (a preset, a
calibration file, or numbers; see _camera.load_calibration). ROS bags (ROS 1 .bag, ROS 2
.db3/.mcap) with sensor_msgs/PointCloud2 or a depth sensor_msgs/Image + CameraInfo, read with
`rosbags` (no ROS installation); a ROS 2 bag may also be given as its folder. Everything
comes out as points in the camera frame, metres (x right, y down, z forward for depth images).

Every reader checks its header against the file's real size before allocating anything
(_headers), and refuses more than MAX_CLOUD_POINTS points or MAX_DEPTH_PIXELS pixels.
"""

from __future__ import annotations

import dataclasses
import io
import os
import re
import struct
import sys
import tempfile
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
from ._choices import DEPTH_UNITS, DepthUnits
from ._errors import CaptureError
from ._headers import (
    HEAD_BYTES,
    MAX_CLOUD_POINTS,
    PcdHeader,
    PlyHeader,
    check_pixels,
    parse_netpbm_header,
    parse_pcd_header,
    parse_ply_header,
    parse_png_header,
)
from ._yaml import short_repr

CLOUD_SUFFIXES = (".pcd", ".ply", ".xyz", ".pts", ".npy")
DEPTH_SUFFIXES = (".png", ".pgm", ".ppm")
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
CAPTURE_SUFFIXES = CLOUD_SUFFIXES + DEPTH_SUFFIXES + BAG_SUFFIXES
SIDECAR_SUFFIXES = (".json", ".xml", ".yaml", ".yml")
MAX_TEXT_BYTES = 4 * 1024**3
"""Largest text point list read [bytes] (about 100 million lines of x y z)."""
MAX_BAG_CHUNK_BYTES = 1024**3
"""Largest decompressed chunk of a ROS 1 bag [bytes]; a bag's chunk holds a few seconds of
messages, and a bz2 or lz4 block can otherwise decompress to any size."""
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
    depth_units: DepthUnits | None = None,
) -> Capture:
    """Read a capture file (or a ROS 2 bag's folder); CaptureError names the file and what is
    wrong with it: every reader checks its header against the file's size before allocating.

    intrinsics / depth_scale / depth_units: for depth images (.png, .pgm, .ppm). intrinsics: a
    preset name, a calibration file, or numbers {fx, fy, cx, cy[, width, height]}; default: a
    calibration file beside the image (SIDECAR_SUFFIXES; same stem, or the stem before
    "_depth"). depth_scale [units per metre]: default the calibration's (a preset's, e.g. TUM
    5000; PCL XML's z factor; a JSON/YAML depth_scale), else the sidecar's, else 1000
    (millimetres). depth_units: "kinect-disparity" when the samples are a Kinect v1's raw
    disparity (kinect_disparity_to_m); None: depth in units of the depth scale, unless no
    depth scale was given and the samples plainly are raw Kinect disparity (converted, with a
    note; refused, naming both settings, when they only may be: kinect_disparity_verdict).
    topic: which topic of a bag (default: the first PointCloud2, else the first depth Image).
    units: "mm" when a point cloud is stored in millimetres, "m" in metres; None: metres
    unless the cloud can only be millimetres (see check_capture).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    try:  # a folder we may not enter: is_dir raises PermissionError
        is_bag = suffix in BAG_SUFFIXES or (path.is_dir() and (path / "metadata.yaml").is_file())
        if topic is not None and not is_bag:
            raise CaptureError(
                f"{path}: a topic ({short_repr(topic)}; --topic, `topic:` in a scene) was given, "
                f"but only a bag ({', '.join(BAG_SUFFIXES)}, or a ROS 2 bag's folder) has topics"
            )
        if depth_units is not None and suffix not in DEPTH_SUFFIXES:
            raise CaptureError(
                f"{path}: depth units ({short_repr(depth_units)}; --depth-units, `depth_units:` "
                f"in a scene) were given, but only a depth image ({', '.join(DEPTH_SUFFIXES)}) "
                f"has them"
            )
        if is_bag and path.is_dir():
            cap = _load_bag(path, topic, depth_scale)
        else:
            _check_file(path)
            if suffix in DEPTH_SUFFIXES:
                cap = _load_depth_image(path, intrinsics, depth_scale, depth_units)
            elif is_bag:
                cap = _load_bag(path, topic, depth_scale)
            else:
                read = {".pcd": _load_pcd, ".ply": _load_ply, ".npy": _load_npy}
                cap = read.get(suffix, _load_text)(path)
    except OSError as exc:  # unreadable (permissions, an I/O error): not a traceback
        raise CaptureError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    except MemoryError:
        raise CaptureError(
            f"{path}: too large to read into the memory this process may use "
            f"(the machine's, or the limit set by ROACHPLAN_CHILD_MEMORY)"
        ) from None
    if units == "mm":
        cap = dataclasses.replace(
            cap,
            points=cap.points * 1e-3,
            sensor_origin=tuple(float(v) * 1e-3 for v in cap.sensor_origin),
        )
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


def _check_file(path: Path) -> None:
    """A capture is a regular, non-empty file of a known type (a folder, FIFO or device would
    block a reader or read forever)."""
    if not path.exists():
        raise CaptureError(f"{path}: no such file")
    if path.is_dir():
        raise CaptureError(
            f"{path}: is a folder; expected a capture file ({', '.join(CAPTURE_SUFFIXES)}) or a "
            f"ROS 2 bag's folder (with a metadata.yaml)"
        )
    if not path.is_file():
        raise CaptureError(
            f"{path}: not a regular file (a pipe or device); expected a capture file"
        )
    suffix = path.suffix.lower()
    if suffix not in CAPTURE_SUFFIXES:
        raise CaptureError(
            f"{path}: unknown capture type {suffix!r}; accepted: {', '.join(CAPTURE_SUFFIXES)}"
        )
    if path.stat().st_size == 0:
        raise CaptureError(f"{path}: the file is empty (0 bytes): the capture has no points")


def _head(path: Path, n: int) -> bytes:
    """The first n bytes of a file (without reading a large capture whole)."""
    with open(path, "rb") as f:
        return f.read(n)


def _sniff(path: Path, magic: tuple[bytes, ...], what: str) -> None:
    head = _head(path, 64)
    if not any(head.startswith(m) for m in magic):
        raise CaptureError(f"{path}: not a {what} file (it starts with {head[:16]!r})")


def _load_pcd(path: Path) -> Capture:
    """PCL's .pcd: the header is parsed and checked against the file's size first (pypcd4, which
    reads these too, trusts its header: a truncated file came out short, a lying one empty)."""
    h = parse_pcd_header(_head(path, HEAD_BYTES + 8), path.stat().st_size, str(path))
    with open(path, "rb") as f:
        f.seek(h.data_offset)
        if h.data == "ascii":
            pts = _pcd_ascii(path, f, h)
        elif h.data == "binary":
            data = f.read(h.points * h.point_step)
            rows = np.frombuffer(data, dtype=_pcd_dtype(h), count=h.points)
            pts = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
        else:
            pts = _pcd_compressed(path, f, h)
    vp = h.viewpoint
    organized = h.height > 1
    return Capture(
        points=pts,
        shape=(h.height, h.width) if organized else None,
        source=str(path),
        sensor_origin=(vp[0], vp[1], vp[2]),
        frame="camera" if organized else None,  # organized: a camera's pixels, optical frame
    )


def _pcd_dtype(h: PcdHeader) -> np.dtype:
    """One binary point's x, y, z within its point_step bytes."""
    return np.dtype(
        {
            "names": list("xyz"),
            "formats": [h.field(k).dtype for k in "xyz"],
            "offsets": [h.byte_offset(k) for k in "xyz"],
            "itemsize": h.point_step,
        }
    )


def _pcd_compressed(path: Path, f, h: PcdHeader) -> np.ndarray:
    """binary_compressed: the 8-byte sizes, then LZF of the fields one after another (all
    points' x, then all y, ...). lzf is pypcd4's own dependency."""
    import lzf

    f.seek(8, os.SEEK_CUR)
    size = h.points * h.point_step
    try:  # the sizes were checked: this allocates at most `size`, which the file can hold
        raw = lzf.decompress(f.read(h.compressed_size), size)
    except ValueError:
        raw = None
    if raw is None or len(raw) != size:
        raise CaptureError(
            f"{path}: the PCD's compressed data is damaged: it does not decode (LZF) to the "
            f"{size} bytes its header describes"
        )
    return np.stack(
        [
            np.frombuffer(
                raw, dtype=h.field(k).dtype, count=h.points, offset=h.points * h.byte_offset(k)
            ).astype(np.float64)
            for k in "xyz"
        ],
        axis=1,
    )


def _pcd_ascii(path: Path, f, h: PcdHeader) -> np.ndarray:
    values = _read_rows(path, f, h.points, "PCD ascii data")
    if values.shape != (h.points, h.values_per_point):
        raise CaptureError(
            f"{path}: the PCD header says {h.points} points of {h.values_per_point} values "
            f"(FIELDS {' '.join(x.name for x in h.fields)[:60]}), the ascii data has "
            f"{values.shape[0]} rows of {values.shape[1]} values"
        )
    return values[:, [h.column(k) for k in "xyz"]]


def _read_rows(path: Path, f, rows: int, what: str, usecols=None) -> np.ndarray:
    """Up to `rows` whitespace-separated rows of numbers from a binary file object, as (R, C)
    float64; CaptureError for a row that is not numbers or has another number of them."""
    try:
        with warnings.catch_warnings():  # an empty input warns; the caller counts the rows
            warnings.simplefilter("ignore", UserWarning)
            out = np.loadtxt(
                io.TextIOWrapper(f, encoding="ascii"),
                dtype=np.float64,
                ndmin=2,
                max_rows=rows,
                comments=None,
                usecols=usecols,
            )
    except UnicodeDecodeError:
        raise CaptureError(f"{path}: the {what} holds non-text bytes") from None
    except ValueError as exc:
        raise CaptureError(f"{path}: bad {what}: {str(exc)[:200]}") from None
    return out


def _load_ply(path: Path) -> Capture:
    """A .ply's vertices. The header is parsed and checked against the file's size first; the
    usual layouts (vertices of scalar properties, after elements of fixed size or in ascii) are
    read here with numpy, others by Open3D with its messages captured (it prints to the
    terminal and returns an empty cloud when it fails)."""
    h = parse_ply_header(_head(path, HEAD_BYTES), path.stat().st_size, str(path))
    before = h.elements[: h.elements.index(h.vertex)]
    vertex = h.vertex
    if vertex.fixed and h.format == "ascii":
        with open(path, "rb") as f:
            f.seek(h.data_offset)
            for _ in range(sum(e.count for e in before)):  # ascii: one line per entry
                f.readline()
            names = [p.name for p in vertex.properties]
            pts = _read_rows(path, f, vertex.count, "PLY ascii vertex data")
            if pts.shape != (vertex.count, len(names)):
                raise CaptureError(
                    f"{path}: the PLY header says {vertex.count} vertices of {len(names)} "
                    f"properties, the ascii data has {pts.shape[0]} rows of {pts.shape[1]} values"
                )
            pts = pts[:, [names.index(k) for k in "xyz"]]
    elif vertex.fixed and all(e.fixed for e in before):
        dtype = np.dtype([(p.name, h.endian + p.type) for p in vertex.properties])
        with open(path, "rb") as f:
            f.seek(h.data_offset + sum(e.count * e.min_bytes for e in before))
            rows = np.frombuffer(f.read(vertex.count * dtype.itemsize), dtype=dtype)
        pts = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    else:
        pts = _ply_by_open3d(path, h)
    return Capture(points=pts, shape=None, source=str(path))


def _ply_by_open3d(path: Path, h: PlyHeader) -> np.ndarray:
    import open3d as o3d

    with _captured_output() as said:
        cloud = o3d.io.read_point_cloud(os.fspath(path), remove_nan_points=False)  # pyright: ignore[reportArgumentType] (its stubs ask for PathLike; it takes a str)
    pts = np.asarray(cloud.points, dtype=np.float64)
    told = " ".join(re.sub(r"\x1b\[[0-9;]*m|\[Open3D \w+\]", "", said.getvalue()).split())
    # When RPly fails part way Open3D still returns the vertex count, of uninitialised values.
    if len(pts) != h.vertex.count or re.search(r"fail|error", told, re.IGNORECASE):
        raise CaptureError(
            f"{path}: the PLY could not be read (Open3D: {told[:300] or 'no message'}; the header says "
            f"{', '.join(f'{e.count} {e.name}' for e in h.elements)[:120]})"
        )
    return pts


class _captured_output:  # noqa: N801 - used as a context manager, like contextlib's
    """Collect what a C library prints on the process's stdout and stderr (file descriptors 1
    and 2, which Python's sys.stdout cannot redirect) into .getvalue()."""

    def __enter__(self) -> _captured_output:
        sys.stdout.flush()
        sys.stderr.flush()
        self._file = tempfile.TemporaryFile()
        self._saved = [os.dup(1), os.dup(2)]
        for fd in (1, 2):
            os.dup2(self._file.fileno(), fd)
        return self

    def __exit__(self, *exc) -> None:
        for fd, saved in zip((1, 2), self._saved, strict=True):
            os.dup2(saved, fd)
            os.close(saved)
        self._file.seek(0)
        self._text = self._file.read(20_000).decode("utf-8", "replace")
        self._file.close()

    def getvalue(self) -> str:
        return self._text


def _load_text(path: Path) -> Capture:
    """x y z [...] per line; # comments; a .pts may start with its point count."""
    size = path.stat().st_size
    if size > MAX_TEXT_BYTES:
        raise CaptureError(
            f"{path}: a text point list of {size / 1e9:.1f} GB; at most "
            f"{MAX_TEXT_BYTES / 1e9:.1f} GB are read (use a binary .pcd or .ply)"
        )
    head = _head(path, 65536)
    if b"\0" in head:
        raise CaptureError(f"{path}: not a text point list (binary content)")
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not just a character cut at the end of the sample
            raise CaptureError(f"{path}: not a text point list (binary content)") from None
    skip = 0
    for line in head.splitlines(keepends=True):  # .pts: a first line of one number is the count
        if line.strip() and not line.lstrip().startswith(b"#"):
            if len(line.split()) == 1:
                skip += len(line)
            break
        skip += len(line)
    with open(path, "rb") as f:
        f.seek(skip if skip < len(head) else 0)
        try:
            with warnings.catch_warnings():  # an empty list warns; it is refused below
                warnings.simplefilter("ignore", UserWarning)
                pts = np.loadtxt(
                    io.TextIOWrapper(f, encoding="utf-8"),
                    dtype=np.float64,
                    ndmin=2,
                    comments="#",
                    usecols=(0, 1, 2),
                    max_rows=MAX_CLOUD_POINTS + 1,
                )
        except UnicodeDecodeError:
            raise CaptureError(f"{path}: not a text point list (binary content)") from None
        except ValueError as exc:
            raise CaptureError(
                f"{path}: expected lines of 'x y z [...]' numbers, every line at least x y z "
                f"({str(exc)[:200]})"
            ) from None
    if len(pts) > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"{path}: more than {MAX_CLOUD_POINTS} points; clouds of at most "
            f"{MAX_CLOUD_POINTS // 1_000_000} million points are read"
        )
    return Capture(points=pts.reshape(-1, 3), shape=None, source=str(path))


def _load_npy(path: Path) -> Capture:
    """A NumPy array of numbers, (N, >= 3) or organized (H, W, >= 3); its header is read and
    checked against the file's size before anything is allocated."""
    _sniff(path, (b"\x93NUMPY",), "NumPy .npy")
    fmt = np.lib.format
    with open(path, "rb") as f:
        try:
            version = fmt.read_magic(f)
            read = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}
            if version not in read:
                raise ValueError(f"format version {version[0]}.{version[1]} (1.0 and 2.0 are read)")
            shape, _, dtype = read[version](f)
        except ValueError as exc:
            raise CaptureError(f"{path}: cannot read this .npy ({str(exc)[:200]})") from None
        offset = f.tell()
    if dtype.names is not None or dtype.kind not in "iuf":
        raise CaptureError(f"{path}: an array of {dtype}; expected numbers (integers or floats)")
    if not ((len(shape) == 3 and shape[2] >= 3) or (len(shape) == 2 and shape[1] >= 3)):
        raise CaptureError(f"{path}: expected an (N, 3) or (H, W, 3) array, got shape {shape}")
    points = int(np.prod(shape[:-1]))
    if points > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"{path}: shape {shape} is {points} points; clouds of at most "
            f"{MAX_CLOUD_POINTS // 1_000_000} million points are read"
        )
    need = int(np.prod(shape)) * dtype.itemsize
    if path.stat().st_size - offset < need:
        raise CaptureError(
            f"{path}: the .npy header says shape {shape} of {dtype} ({need} bytes), but "
            f"{path.stat().st_size - offset} bytes follow it: the file is truncated"
        )
    a = np.load(path, mmap_mode="r", allow_pickle=False)
    pts = np.array(a[..., :3], dtype=np.float64).reshape(-1, 3)
    return Capture(points=pts, shape=shape[:2] if len(shape) == 3 else None, source=str(path))


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


def _needs_intrinsics(
    path: Path, why: str = "a depth image needs intrinsics", size: tuple[int, int] | None = None
) -> CaptureError:
    """The refusal of a depth image without usable intrinsics; with the image's size (w, h),
    the presets of that size come first."""
    fits = [k for k, v in PRESETS.items() if size is not None and (v.width, v.height) == size]
    names = [*fits, *(k for k in PRESETS if k not in fits)]
    lead = f"presets of {size[0]}x{size[1]}: {', '.join(fits)}; " if fits and size else ""
    return CaptureError(
        f"{path}: {why}: {lead}pass --intrinsics with a preset "
        f"({', '.join(names)}) or a calibration file, or the numbers --fx --fy --cx --cy "
        f"(`intrinsics: {{fx, fy, cx, cy}}` in a scene), or put {path.stem}.json, .xml, .yaml "
        f"or .yml beside it. Calibration files: {CALIBRATION_FORMATS}"
    )


def _load_depth_image(
    path: Path, intrinsics, depth_scale: float | None, depth_units: DepthUnits | None = None
) -> Capture:
    _check_depth_units(path, depth_scale, depth_units)
    if path.suffix.lower() == ".png":
        raw, notes = _read_depth_png(path), []
    else:
        raw, note = _read_netpbm(path)
        notes = [note] if note else []
    h, w = raw.shape
    sidecar = find_sidecar(path)
    spec = intrinsics if intrinsics is not None else sidecar
    if spec is None:
        raise _needs_intrinsics(path)
    calib = load_calibration(spec, size=(w, h))
    intr = calib.intrinsics
    # Raw Kinect disparity is looked for only when no depth scale was given: a scale given
    # says the samples are depth. A calibration's scale does not: it is the camera's usual
    # one, not a statement about this file.
    disparity = depth_units == "kinect-disparity"
    if depth_units is None and depth_scale is None:
        disparity = _recognise_disparity(path, raw, notes)
    if disparity:
        raw = _as_disparity(path, raw, notes, told=depth_units is not None)
        depth_m, depth_scale = kinect_disparity_to_m(raw), None
    else:
        if depth_scale is None:
            depth_scale = calib.depth_scale
        if depth_scale is None and sidecar is not None and intrinsics is not None:
            depth_scale = _sidecar_depth_scale(sidecar, (w, h))
        depth_scale = depth_scale or 1000.0
        depth_m = raw.astype(np.float64) / depth_scale
    if (intr.width, intr.height) != (w, h):
        if abs(intr.width / w - intr.height / h) > 1e-6:
            raise _needs_intrinsics(
                path,
                f"the image is {w}x{h}, the intrinsics are for {intr.width}x"
                f"{intr.height} (another aspect ratio)",
                size=(w, h),
            )
        intr = intr.scaled(w, h)
    if not np.any(raw > 0):
        raise CaptureError(f"{path}: every pixel is 0 (no depth measured)")
    if not np.any(depth_m > 0):
        raise CaptureError(
            f"{path}: no pixel holds a Kinect disparity within its model (every "
            f"one is {KINECT_NO_READING}, 0 or beyond {KINECT_MAX_DEPTH_M:g} m)"
        )
    pts = depth_to_points(depth_m, intr)
    return Capture(
        points=pts,
        shape=(h, w),
        source=str(path),
        intrinsics=intr,
        frame="camera",
        base_from_camera=calib.base_from_camera,
        depth_scale=depth_scale,
        notes=tuple(notes),
    )


def _sidecar_depth_scale(sidecar: Path, size: tuple[int, int]) -> float | None:
    """Intrinsics given, the depth scale may still be written beside the image."""
    try:
        return load_calibration(sidecar, size=size).depth_scale
    except CaptureError:
        return None


def _check_depth_units(path: Path, depth_scale: float | None, depth_units) -> None:
    if depth_units is not None and depth_units not in DEPTH_UNITS:
        raise CaptureError(
            f"{path}: depth_units {short_repr(depth_units)}: accepted: "
            f"{', '.join(DEPTH_UNITS)} (or none: depth in units of the depth "
            f"scale)"
        )
    if depth_units is not None and depth_scale is not None:
        raise CaptureError(
            f"{path}: both a depth scale ({depth_scale:g}) and depth units ({depth_units}) "
            f"were given: a depth scale is for depth stored in units, {depth_units} is "
            f"converted by the sensor's own model; give one of them"
        )


# -- raw Kinect v1 disparity ------------------------------------------------------------------

KINECT_NO_READING = 2047
"""A Kinect v1's raw 11-bit disparity for a pixel without a reading (libfreenect's
FREENECT_DEPTH_11BIT, NYU Depth v2's raw dumps)."""
KINECT_DISPARITY_MODEL = (351.3, 1092.5)
"""(a, b) of depth [m] = a / (b - d) for raw disparity d: NYU Depth v2's toolbox
(camera_params.m, depthParam1/2). Chosen over ROS/OpenKinect's 1 / (3.3309495161 - 0.0030711016
d) because NYU's raw dumps are where raw disparity files come from, and with their own model
the metres agree with the dataset's released depth maps; the two differ by 5 % at 1 m, 3 % at
2 m, under 2 % at 3-4 m and 7 % at 6 m."""
KINECT_MAX_DEPTH_M = 10.0
"""Farthest depth taken from disparity [m] (NYU's maxDepth): beyond it the model's metres per
disparity step exceed a quarter of a metre; such pixels, like 0, 2047 and d >= 1092.5 (no
depth in the model), are no reading rather than NYU's clamp to 10 m (a wall that is not
there)."""
KINECT_NEAR_M = 0.4
"""Nearest depth a Kinect v1 reads [m] (rated 0.8 m, 0.4 m in near mode)."""
MARKER_SHARE = 0.001
"""Share of pixels at 2047 from which it counts as the no-reading marker: a Kinect frame has
its shadow band at the left edge and dropouts on dark or shiny surfaces (NYU frames: several
%); a depth image in millimetres has only scattered pixels at 2.047 m."""
MODEL_SHARE = 0.95
"""Share of the other non-zero samples that must be disparities of KINECT_NEAR_M to
KINECT_MAX_DEPTH_M for raw disparity to be taken without being told."""


def kinect_disparity_to_m(raw: np.ndarray) -> np.ndarray:
    """(H, W) raw Kinect v1 disparity -> depth [m] by KINECT_DISPARITY_MODEL; 0 (no reading)
    where the sample is 0 or KINECT_NO_READING, or out of the model (d >= 1092.5, or further
    than KINECT_MAX_DEPTH_M)."""
    a, b = KINECT_DISPARITY_MODEL
    d = np.asarray(raw, dtype=np.float64)
    ok = (d > 0) & (d < KINECT_NO_READING) & (d < b)
    depth = np.zeros_like(d)
    depth[ok] = a / (b - d[ok])
    depth[depth > KINECT_MAX_DEPTH_M] = 0.0
    return depth


def _disparity_of(depth_m: float) -> float:
    a, b = KINECT_DISPARITY_MODEL
    return b - a / depth_m


def kinect_disparity_verdict(raw: np.ndarray) -> tuple[str, str]:
    """Whether a depth image's samples are a Kinect v1's raw disparity, by what they look like:
    ("yes" | "maybe" | "no", the evidence in words). Disparity is 11 bits (nothing above
    2047), with 2047 marking no reading - a spike: the values just below it are no disparity
    the model maps to a depth - on a share of the pixels (MARKER_SHARE); and nearly all the other
    samples (MODEL_SHARE) are disparities of 0.4-10 m (214-1057), which in millimetres would be
    a scene within 1.06 m with many pixels at exactly 2.047 m. "maybe": 11 bits with the marker,
    but the rest not so."""
    v = np.asarray(raw).ravel()
    if v.size == 0 or int(v.max()) > KINECT_NO_READING:
        return "no", ""
    marker = int(np.count_nonzero(v == KINECT_NO_READING))
    below = int(np.count_nonzero((v >= KINECT_NO_READING - 10) & (v < KINECT_NO_READING)))
    if marker < MARKER_SHARE * v.size or marker < 20 * (below / 10 + 1):
        return "no", ""
    rest = v[(v > 0) & (v < KINECT_NO_READING)]
    lo, hi = _disparity_of(KINECT_NEAR_M), _disparity_of(KINECT_MAX_DEPTH_M)
    share = float(np.mean((rest >= lo) & (rest <= hi))) if rest.size else 0.0
    evidence = (
        f"11-bit samples, {100 * marker / v.size:.1f} % of the pixels at "
        f"{KINECT_NO_READING} (the Kinect's no-reading value), {100 * share:.0f} % of "
        f"the others disparities of {KINECT_NEAR_M:g}-{KINECT_MAX_DEPTH_M:g} m "
        f"({lo:.0f}-{hi:.0f})"
    )
    return ("yes" if share >= MODEL_SHARE else "maybe"), evidence


def _swapped(raw: np.ndarray) -> np.ndarray:
    r = np.asarray(raw, dtype=np.uint16)
    return ((r & 0xFF) << 8) | (r >> 8)


TELL_DISPARITY = "pass --depth-units kinect-disparity (depth_units: kinect-disparity in a scene)"
TELL_DEPTH = "pass its depth scale (--depth-scale N; 1000 for millimetres)"


def _recognise_disparity(path: Path, raw: np.ndarray, notes: list[str]) -> bool:
    """Whether to read a depth image given no depth scale or depth units as raw Kinect
    disparity (a note says so); CaptureError, naming disparity and both settings, when it
    may be disparity but is not plainly so. A netpbm file's samples are also judged
    byte-swapped: NYU's dumps are read either way by the tools people use."""
    verdict, evidence = kinect_disparity_verdict(raw)
    if verdict == "no" and path.suffix.lower() != ".png":
        verdict, evidence = kinect_disparity_verdict(_swapped(raw))
        evidence += " once its bytes are swapped" if evidence else ""
    if verdict == "maybe":
        raise CaptureError(
            f"{path}: this may be a Kinect v1's raw disparity, not depth ({evidence}), but it "
            f"is not plainly so: if it is disparity, {TELL_DISPARITY}; if it is depth, "
            f"{TELL_DEPTH}"
        )
    return verdict == "yes"


def _as_disparity(path: Path, raw: np.ndarray, notes: list[str], *, told: bool) -> np.ndarray:
    """raw as 11-bit disparity, byte-swapped if that is what makes it so (a netpbm file written
    little-endian, against netpbm's rule); the note that says how it was read."""
    a, b = KINECT_DISPARITY_MODEL
    swapped = ""
    if int(raw.max()) > KINECT_NO_READING:
        if path.suffix.lower() == ".png" or int(_swapped(raw).max()) > KINECT_NO_READING:
            raise CaptureError(
                f"{path}: depth units kinect-disparity were given, but samples reach "
                f"{int(raw.max())}: raw Kinect disparity has 11 bits (at most "
                f"{KINECT_NO_READING}); if it is depth, {TELL_DEPTH}"
            )
        raw, swapped = _swapped(raw), " (its 16-bit samples little-endian)"
    how = "as told" if told else "recognised by its values"
    notes.append(
        f"read as a Kinect v1's raw disparity, {how}{swapped}, and converted by NYU Depth v2's "
        f"model: depth = {a:g} / ({b:g} - d) m; {KINECT_NO_READING}, 0 and disparities beyond "
        f"{KINECT_MAX_DEPTH_M:g} m are no reading"
        + ("" if told else f". If it is depth, {TELL_DEPTH}")
    )
    return raw


def _read_depth_png(path: Path) -> np.ndarray:
    """A 16-bit greyscale PNG -> (H, W) raw depth units. The size, bit depth and colour type
    are checked on the IHDR chunk (always the first) before Pillow decodes anything."""
    from PIL import Image

    parse_png_header(_head(path, 26), str(path))
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
    except (OSError, SyntaxError, ValueError, Image.DecompressionBombError) as exc:
        raise CaptureError(f"{path}: cannot decode this PNG: {str(exc)[:200]}") from None


def read_netpbm_depth(path: Path) -> np.ndarray:
    """A 16-bit netpbm image -> (H, W) uint16 raw depth units (_read_netpbm, without its note)."""
    return _read_netpbm(path)[0]


def _read_netpbm(path: Path) -> tuple[np.ndarray, str]:
    """A 16-bit netpbm image -> (H, W) uint16 raw depth units: PGM (P5 binary, P2 ASCII) or PPM
    (P6, P3), of which only the first channel is read (a colour pixmap has no depth; a depth
    tool that writes PPM repeats the depth in every channel). maxval > 255 means 16 bits per
    sample, big-endian (netpbm's rule); the samples are not rescaled by maxval. The header is
    checked against the file's real size before anything is allocated (parse_netpbm_header).
    Pillow is not used: it reads 16-bit PGM but not 16-bit PPM, and trusts the header's size.
    The note: samples that exceed maxval as netpbm orders their bytes but fit it swapped were
    written little-endian (some depth tools do), and are read so."""
    h = parse_netpbm_header(_head(path, 4096), path.stat().st_size, str(path))
    samples = h.samples
    with open(path, "rb") as f:
        f.seek(h.data_offset)
        if h.binary:
            data = np.frombuffer(f.read(2 * samples), dtype=">u2")
        else:
            words = f.read().split()
            if len(words) < samples or not all(w.isdigit() for w in words[:samples]):
                raise CaptureError(
                    f"{path}: the ASCII netpbm image needs {samples} decimal samples after the "
                    f"header, it has {len(words)} words (or some are not numbers)"
                )
            try:
                data = np.array(words[:samples], dtype=np.int64)
            except OverflowError:  # more digits than any 16-bit sample has
                raise CaptureError(
                    f"{path}: a sample is over {h.maxval}, the header's maxval"
                ) from None
    note = ""
    if data.max() > h.maxval and h.binary and _swapped(data).max() <= h.maxval:
        data = _swapped(data)
        note = (
            f"its 16-bit samples are little-endian (netpbm's are big-endian): as written "
            f"they exceed the header's maxval {h.maxval}, swapped they do not"
        )
    if data.max() > h.maxval:
        raise CaptureError(
            f"{path}: a sample is {data.max()}, above the header's maxval {h.maxval}"
        )
    return data.reshape(h.height, h.width, h.channels)[..., 0].astype(np.uint16), note


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
        where = (
            f"{(near + far) * 100:.0f} % of the measured pixels are outside {span} "
            f"({far * 100:.0f} % beyond, {near * 100:.0f} % nearer)"
        )
    msg = f"{cap.source}: {where} at {cap.depth_scale:g} units per metre"
    raw = z * cap.depth_scale
    inside = {
        s: float(np.mean((raw / s >= lo) & (raw / s <= hi)))
        for s in STANDARD_DEPTH_SCALES
        if s != cap.depth_scale
    }
    top = max(inside.values(), default=0.0)
    if top <= 0.5:
        return msg + "; no standard depth scale puts most of them inside: check the depth scale"
    # A wide depth range fits two scales (TUM's 5000 and 10000 both put a room inside
    # 0.3-8 m): of those within 5 points of the best, take the one whose median depth is
    # nearest a depth camera's typical working distance.
    median = float(np.median(raw))
    best = min(
        (s for s, f in inside.items() if f >= top - 0.05),
        key=lambda s: abs(np.log(median / s / TYPICAL_DEPTH_M)),
    )
    return (
        f"{msg}; with a depth scale of {best:g} ({STANDARD_DEPTH_SCALES[best]}) "
        f"{inside[best] * 100:.0f} % fall within {span}: pass --depth-scale {best:g} "
        f"(depth_scale: {best:g} in a scene)"
    )


# -- ROS bags -------------------------------------------------------------------------------

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


def _load_bag(path: Path, topic: str | None, depth_scale: float | None) -> Capture:
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
        head = _head(path, 64)
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
