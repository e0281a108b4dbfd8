"""The input kinds: which files roachplan takes, what each one is and which reader reads it, in
one table (INPUT_KINDS) used wherever a file comes in: the command line (`roachplan mesh`,
load_capture), the scene loader (a terrain file as a scene of its own, scenes.load_scene) and
the page's upload.

The decision, in order: the suffix names the rows that may hold the file; where two do (.ply:
a point cloud, or a mesh), its header decides (ply_has_faces); the row gives the kind - a
capture (points a sensor saw: read here by the row's reader, then meshed by _pipeline), a mesh
(triangles, read by scenes with trimesh) or a model (OpenSCAD, rendered by scenes) - and the
reader. Each capture reader then checks the file's signature and header against the file's
size before it allocates anything (_headers), and refuses more than MAX_CLOUD_POINTS points or
MAX_DEPTH_PIXELS pixels; everything comes out as points in the camera frame [m] (x right, y
down, z forward for a depth image).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ._camera import PinholeNumbers
from ._capture import Capture, check_capture
from ._choices import DepthUnits
from ._errors import CaptureError
from ._read_bag import read_bag
from ._read_depth import read_depth_image
from ._read_npy import read_npy
from ._read_pcd import read_pcd
from ._read_ply import read_ply
from ._read_text import read_text_points
from ._yaml import short_repr

Kind = Literal["capture", "mesh", "model"]
FormatName = Literal["pcd", "ply", "text", "npy", "depth-image", "bag", "mesh", "scad"]
Units = Literal["m", "mm"]
IntrinsicsSpec = str | Path | Mapping | PinholeNumbers


@dataclass(frozen=True, kw_only=True)
class ReadOptions:
    """What a capture reader may be told besides the file (load_capture's arguments)."""

    intrinsics: IntrinsicsSpec | None = None
    """A depth image's intrinsics: a preset name, a calibration file or numbers."""
    depth_scale: float | None = None
    """A depth image's (or a bag's depth Image's) units per metre."""
    topic: str | None = None
    """Which topic of a bag."""
    depth_units: DepthUnits | None = None
    """A depth image's samples: "kinect-disparity", or None for depth."""


Reader = Callable[[Path, ReadOptions], Capture]


@dataclass(frozen=True, kw_only=True)
class InputKind:
    """One row of the table of input kinds: a file format, what its files are, who reads it."""

    name: FormatName
    """The format (and so the reader)."""
    suffixes: tuple[str, ...]
    """The suffixes of its files, lower case."""
    kind: Kind
    """What its files are: a capture (meshed by perception: its floor is the ground, no ground
    plane), a mesh or a model (rendered by OpenSCAD); a mesh or model stands on a ground plane
    when it is a scene of its own."""
    what: str
    """The format in words, for people."""
    reader: Reader | None = None
    """A capture's reader, (path, ReadOptions) -> Capture in the camera frame [m], as read
    (load_capture checks what it read); None for a mesh or model, which scenes reads."""

    @property
    def takes_topic(self) -> bool:
        """A bag: it has topics to choose from."""
        return self.name == "bag"

    @property
    def is_depth_image(self) -> bool:
        """A depth image: it needs intrinsics and a depth scale (or depth units)."""
        return self.name == "depth-image"


def _depth_image(path: Path, o: ReadOptions) -> Capture:
    return read_depth_image(path, o.intrinsics, o.depth_scale, o.depth_units)


def _bag(path: Path, o: ReadOptions) -> Capture:
    return read_bag(path, o.topic, o.depth_scale)


INPUT_KINDS: tuple[InputKind, ...] = (
    InputKind(
        name="pcd",
        suffixes=(".pcd",),
        kind="capture",
        what="a PCL point cloud",
        reader=lambda path, _: read_pcd(path),
    ),
    InputKind(
        name="ply",
        suffixes=(".ply",),
        kind="capture",
        what="a PLY point cloud (no faces)",
        reader=lambda path, _: read_ply(path),
    ),
    InputKind(
        name="text",
        suffixes=(".xyz", ".pts"),
        kind="capture",
        what="a text point list",
        reader=lambda path, _: read_text_points(path),
    ),
    InputKind(
        name="npy",
        suffixes=(".npy",),
        kind="capture",
        what="a NumPy point array",
        reader=lambda path, _: read_npy(path),
    ),
    InputKind(
        name="depth-image",
        suffixes=(".png", ".pgm", ".ppm"),
        kind="capture",
        what="a depth image",
        reader=_depth_image,
    ),
    InputKind(
        name="bag",
        suffixes=(".bag", ".db3", ".mcap"),
        kind="capture",
        what="a ROS bag",
        reader=_bag,
    ),
    InputKind(
        name="mesh",
        suffixes=(".stl", ".obj", ".ply", ".glb"),
        kind="mesh",
        what="a mesh (PLY: with faces)",
    ),
    InputKind(name="scad", suffixes=(".scad",), kind="model", what="an OpenSCAD model"),
)
"""Every format roachplan reads, in the order messages list their suffixes. A suffix in two
rows (.ply) is decided by the file's header: input_kind."""


def _suffixes(kind: Kind) -> tuple[str, ...]:
    return tuple(s for row in INPUT_KINDS if row.kind == kind for s in row.suffixes)


CAPTURE_SUFFIXES = _suffixes("capture")
"""Captures: point clouds, depth images and bags (a .ply without faces)."""
MESH_SUFFIXES = _suffixes("mesh")
"""Meshes (a .ply with faces), in metres."""
MODEL_SUFFIXES = _suffixes("model")
"""OpenSCAD models."""
INPUT_SUFFIXES = tuple(sorted({s for row in INPUT_KINDS for s in row.suffixes}))
"""Every file roachplan reads as terrain: a scene of its own wherever a scene is taken."""
BAG_SUFFIXES = next(row.suffixes for row in INPUT_KINDS if row.takes_topic)
"""Bags: they have topics."""
DEPTH_SUFFIXES = next(row.suffixes for row in INPUT_KINDS if row.is_depth_image)
"""Depth images: they need intrinsics."""


def ply_has_faces(path: Path) -> bool:
    """A .ply whose header declares faces is a mesh; without, a point cloud (a capture). Only
    the header's first 4 kB are looked at: a damaged header is its reader's to refuse."""
    with open(path, "rb") as f:
        head = f.read(4096).split(b"end_header", 1)[0]
    m = re.search(rb"element face (\d+)", head)
    return bool(m and int(m.group(1)) > 0)


def is_bag_folder(path: Path) -> bool:
    """A ROS 2 bag given as its folder (one holding a metadata.yaml)."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def input_kind(path: str | Path) -> InputKind | None:
    """The row of INPUT_KINDS that reads the file at path: a folder holding a metadata.yaml is
    a ROS 2 bag; a file is known by its suffix, and a .ply by its header too (a mesh when it
    declares faces); None for anything else. Reads at most the first 4 kB of a .ply (OSError
    when it cannot), nothing of any other file."""
    path = Path(path)
    if is_bag_folder(path):
        return _BAG_ROW
    suffix = path.suffix.lower()
    rows = [row for row in INPUT_KINDS if suffix in row.suffixes]
    if len(rows) > 1:  # .ply: a point cloud, or a mesh
        mesh = ply_has_faces(path)
        rows = [row for row in rows if (row.kind == "mesh") == mesh]
    return rows[0] if rows else None


_BAG_ROW = next(row for row in INPUT_KINDS if row.takes_topic)


def capture_reader(suffix: str) -> InputKind | None:
    """The capture row of INPUT_KINDS for a file suffix (a .ply's vertices are read as a cloud
    whether or not it has faces), or None."""
    suffix = suffix.lower()
    return next(
        (row for row in INPUT_KINDS if row.kind == "capture" and suffix in row.suffixes), None
    )


def load_capture(
    path: str | Path,
    *,
    intrinsics: IntrinsicsSpec | None = None,
    depth_scale: float | None = None,
    topic: str | None = None,
    units: Units | None = None,
    depth_units: DepthUnits | None = None,
) -> Capture:
    """Read a capture file (or a ROS 2 bag's folder) with its format's reader (INPUT_KINDS);
    CaptureError names the file and what is wrong with it: every reader checks its header
    against the file's size before allocating.

    intrinsics / depth_scale / depth_units: for depth images (.png, .pgm, .ppm). intrinsics: a
    preset name, a calibration file, or numbers {fx, fy, cx, cy[, width, height]}; default: a
    calibration file beside the image (_read_depth.SIDECAR_SUFFIXES; same stem, or the stem
    before "_depth"). depth_scale [units per metre]: default the calibration's (a preset's,
    e.g. TUM 5000; PCL XML's z factor; a JSON/YAML depth_scale), else the sidecar's, else 1000
    (millimetres). depth_units: "kinect-disparity" when the samples are a Kinect v1's raw
    disparity (kinect_disparity_to_m); None: depth in units of the depth scale, unless no
    depth scale was given and the samples plainly are raw Kinect disparity (converted, with a
    note; refused, naming both settings, when they only may be: kinect_disparity_verdict).
    topic: which topic of a bag (default: the first PointCloud2, else the first depth Image).
    units: "mm" when a point cloud is stored in millimetres, "m" in metres; None: metres
    unless the cloud can only be millimetres (see check_capture).
    """
    path = Path(path)
    row = capture_reader(path.suffix)
    options = ReadOptions(
        intrinsics=intrinsics, depth_scale=depth_scale, topic=topic, depth_units=depth_units
    )
    try:  # a folder we may not enter: is_dir raises PermissionError
        is_bag = (row is not None and row.takes_topic) or is_bag_folder(path)
        if topic is not None and not is_bag:
            raise CaptureError(
                f"{path}: a topic ({short_repr(topic)}; --topic, `topic:` in a scene) was given, "
                f"but only a bag ({', '.join(BAG_SUFFIXES)}, or a ROS 2 bag's folder) has topics"
            )
        if depth_units is not None and not (row is not None and row.is_depth_image):
            raise CaptureError(
                f"{path}: depth units ({short_repr(depth_units)}; --depth-units, `depth_units:` "
                f"in a scene) were given, but only a depth image ({', '.join(DEPTH_SUFFIXES)}) "
                f"has them"
            )
        if is_bag and path.is_dir():
            row = _BAG_ROW
        else:
            _check_file(path)  # (a file of a capture's suffix: row is its reader's)
        assert row is not None and row.reader is not None
        cap = row.reader(path, options)
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
