"""Pinhole intrinsics: presets (Kinect v2, PrimeSense / Kinect v1, RealSense D435, the TUM
RGB-D cameras), and readers for the calibration files people bring (Open3D / simple JSON, PCL
grabber XML, OpenCV calibration YAML, ROS CameraInfo YAML), some of which also carry the depth
scale and the camera's pose on the robot."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ._errors import CaptureError
from ._settings import PinholeNumbers
from ._yaml import load_yaml_documents, short_repr


@dataclass(frozen=True, kw_only=True)
class Intrinsics:
    """Pinhole camera: pixel (u, v) of a camera-frame point (x right, y down, z forward) [m] is
    (fx x / z + cx, fy y / z + cy)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def rays(self) -> np.ndarray:
        """(H, W, 3) camera-frame directions with z = 1 for every pixel centre."""
        u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
        return np.stack(
            [(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones(u.shape)], axis=-1
        )

    def scaled(self, width: int, height: int) -> Intrinsics:
        sx, sy = width / self.width, height / self.height
        return Intrinsics(
            width=width,
            height=height,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5,
            cy=(self.cy + 0.5) * sy - 0.5,
        )

    def to_json(self) -> dict:
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }


# Kinect v2 nominal intrinsics (iai_kinect2 / libfreenect2 defaults): the IR/depth camera, and
# the colour camera's full HD mode and its quarter ("QHD", Tong 2018's choice) mode, to which
# iai_kinect2 registers depth.
_HD = Intrinsics(width=1920, height=1080, fx=1081.37, fy=1081.37, cx=959.5, cy=539.5)
# PrimeSense Carmine / Kinect v1 (OpenNI), 640x480: the ROS default model that the TUM RGB-D
# page also gives for these sensors.
_PRIMESENSE = Intrinsics(width=640, height=480, fx=525.0, fy=525.0, cx=319.5, cy=239.5)
# Intel RealSense D435 depth stream, nominal: fx = fy = 640 px at 1280x720 (a 90 deg horizontal
# field of view); the other 16:9 modes are that image scaled, 640x480 is a 4:3 crop scaled by
# 0.6. Read off one D435's `rs-enumerate-devices -c` listing (realsense-ros issue #2788: 640.35
# px at 1280x720 times exactly these factors) and rounded, principal point at the image centre.
# Every unit's factory calibration differs by about 1 % and its principal point by a few pixels:
# when the camera's own numbers are at hand (its CameraInfo, rs-enumerate-devices), pass those.
_D435_SCALES = {
    (1280, 720): 1.0,
    (848, 480): 0.6625,
    (640, 480): 0.6,
    (640, 360): 0.5,
    (480, 270): 0.375,
    (424, 240): 0.33125,
}
# TUM RGB-D benchmark (vision.in.tum.de/data/datasets/rgbd-dataset/file_formats): OpenNI
# registered its depth images to the colour camera (pixels correspond 1:1), so the colour ("RGB")
# calibration of each Freiburg Kinect is the depth PNG's pinhole; the page's IR calibrations
# describe the unregistered depth sensor, which no published depth PNG is in.
_TUM = {
    "tum-fr1": (517.3, 516.5, 318.6, 255.3),
    "tum-fr2": (520.9, 521.0, 325.1, 249.7),
    "tum-fr3": (535.4, 539.2, 320.1, 247.6),
}
PRESETS: dict[str, Intrinsics] = {
    "kinect2-sd": Intrinsics(width=512, height=424, fx=365.5, fy=365.5, cx=255.5, cy=211.5),
    "kinect2-qhd": _HD.scaled(960, 540),
    "kinect2-hd": _HD,
    "primesense": _PRIMESENSE,
    "kinect1": _PRIMESENSE,
    **{
        f"realsense-d435-{w}x{h}": Intrinsics(
            width=w, height=h, fx=640.0 * k, fy=640.0 * k, cx=(w - 1) / 2, cy=(h - 1) / 2
        )
        for (w, h), k in _D435_SCALES.items()
    },
    **{
        name: Intrinsics(width=640, height=480, fx=fx, fy=fy, cx=cx, cy=cy)
        for name, (fx, fy, cx, cy) in _TUM.items()
    },
}
PRESET_DEPTH_SCALES: dict[str, float] = {name: 5000.0 for name in _TUM}
"""Depth units per metre of a preset's images when it is not 1000 (mm): TUM's PNGs are 5000."""

CALIBRATION_FORMATS = (
    "JSON {fx, fy, cx, cy, width, height[, depth_scale]} or Open3D's {width, height, "
    "intrinsic_matrix}; PCL grabber XML (<depth><focal_length_x>...); OpenCV calibration YAML "
    "(%YAML:1.0, camera_matrix {rows, cols, data}, image_width, image_height[, local_transform]); "
    "ROS CameraInfo YAML (camera_calibration's camera_matrix, or a message's width, height, K/k)"
)
"""What a calibration file may be, for messages."""
MAX_CALIBRATION_BYTES = 1024**2
"""Largest calibration file read [bytes]; the biggest real one (a ROS CameraInfo dump) is a
few kilobytes."""
MAX_IMAGE_SIDE = 100_000
"""Widest or tallest image any intrinsics may describe [px]: no depth camera comes near."""


class Calibration(NamedTuple):
    """What a calibration source says about a depth camera."""

    intrinsics: Intrinsics
    base_from_camera: np.ndarray | None
    """(4, 4) transform of camera-frame points into the robot's base frame (z up) [m], or
    None when the source does not say (OpenCV YAML's local_transform)."""
    depth_scale: float | None
    """Depth units per metre of the camera's images, or None when the source does not say."""


def load_intrinsics(spec: str | Path | Mapping | PinholeNumbers) -> Intrinsics:
    """The intrinsics of a preset, a calibration file or numbers; see load_calibration."""
    return load_calibration(spec).intrinsics


def load_calibration(
    spec: str | Path | Mapping | PinholeNumbers, size: tuple[int, int] | None = None
) -> Calibration:
    """A preset name (PRESETS), a calibration file (CALIBRATION_FORMATS; a .yaml/.yml or a file
    starting with %YAML is read as YAML, .xml or '<' as XML, anything else as JSON), or numbers
    {fx, fy, cx, cy[, width, height]}. size (width, height) of the image fills a missing image
    size. Lens distortion is ignored: depth images from these drivers are rectified."""
    if isinstance(spec, PinholeNumbers):
        spec = spec.to_json()
    if isinstance(spec, Mapping):
        return Calibration(intrinsics_from_mapping(dict(spec), "intrinsics", size), None, None)
    name = str(spec)
    if name in PRESETS:
        return Calibration(PRESETS[name], None, PRESET_DEPTH_SCALES.get(name))
    path = Path(spec)
    try:
        exists = path.exists()
    except (OSError, ValueError):  # a name too long, or with a NUL byte
        exists = False
    if not exists:
        raise CaptureError(
            f"intrinsics {short_repr(name)}: no such file, and not a preset; accepted: a preset "
            f"({', '.join(PRESETS)}) or a calibration file: {CALIBRATION_FORMATS}"
        )
    if not path.is_file():
        raise CaptureError(f"{path}: not a calibration file (a folder, pipe or device)")
    try:
        size_bytes = path.stat().st_size
        if size_bytes > MAX_CALIBRATION_BYTES:
            raise CaptureError(
                f"{path}: a calibration file of {size_bytes} bytes; at most "
                f"{MAX_CALIBRATION_BYTES // 1024} KiB are read: {CALIBRATION_FORMATS}"
            )
        text = path.read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise CaptureError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    return parse_calibration(text, path, size)


def parse_calibration(text: str, path: Path, size: tuple[int, int] | None = None) -> Calibration:
    """A calibration file's text -> what it says (see load_calibration); path names the file
    in messages and its suffix picks the format with the text's first characters. Any text
    gives a Calibration or a CaptureError."""
    suffix = path.suffix.lower()
    if "\0" in text:
        raise CaptureError(
            f"{path}: not a calibration file (binary content): {CALIBRATION_FORMATS}"
        )
    if suffix == ".xml" or text.lstrip().startswith("<"):
        return Calibration(_from_pcl_xml(path, text), None, xml_depth_scale(text))
    if suffix in (".yaml", ".yml") or text.lstrip().startswith("%YAML"):
        return _from_yaml(path, text, size)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise CaptureError(
            f"{path}: not JSON ({str(exc)[:120] or 'nested too deep'}); accepted calibration "
            f"files: {CALIBRATION_FORMATS}"
        ) from None
    intr = intrinsics_from_mapping(data, str(path), size)
    return Calibration(intr, None, _scale_of(data, path, ("depth_scale",)))


def intrinsics_from_mapping(
    data: dict, where: str, size: tuple[int, int] | None = None
) -> Intrinsics:
    """From {"fx", "fy", "cx", "cy", "width", "height"} or Open3D's intrinsic_matrix form;
    size (width, height) fills a missing image size."""
    if not isinstance(data, dict):
        raise CaptureError(
            f"{where}: expected a mapping with fx, fy, cx, cy, width, height; accepted "
            f"calibration files: {CALIBRATION_FORMATS}"
        )
    if "intrinsic_matrix" in data:  # Open3D PinholeCameraIntrinsic, column-major
        k = _matrix(where, "intrinsic_matrix", data["intrinsic_matrix"], ((3, 3),)).T
        data = {**data, "fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2]}
    if size is not None:
        data = {"width": size[0], "height": size[1], **data}
    missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in data]
    if missing:
        raise CaptureError(
            f"{where}: intrinsics lack {', '.join(missing)}; accepted calibration files: "
            f"{CALIBRATION_FORMATS}"
        )
    for k in ("width", "height", "fx", "fy", "cx", "cy"):
        if isinstance(data[k], bool) or not isinstance(data[k], int | float | str | np.number):
            raise CaptureError(
                f"{where}: intrinsics {k}: expected a number, got {short_repr(data[k])}"
            )
    try:
        out = Intrinsics(
            width=int(data["width"]),
            height=int(data["height"]),
            fx=float(data["fx"]),
            fy=float(data["fy"]),
            cx=float(data["cx"]),
            cy=float(data["cy"]),
        )
    except (TypeError, ValueError, OverflowError) as exc:
        raise CaptureError(f"{where}: intrinsics must be numbers ({str(exc)[:120]})") from None
    if (
        not 1 <= min(out.width, out.height) <= max(out.width, out.height) <= MAX_IMAGE_SIDE
        or not min(out.fx, out.fy) > 0
        or not np.isfinite([out.fx, out.fy, out.cx, out.cy]).all()
    ):
        raise CaptureError(
            f"{where}: intrinsics need width and height of 1-{MAX_IMAGE_SIDE} px and finite "
            f"fx, fy > 0: {out}"
        )
    return out


# OpenCV's FileStorage writes a YAML 1.0 directive ("%YAML:1.0") and !!opencv-matrix tags, both
# of which PyYAML refuses; neither changes the data, so they are dropped before parsing.
_OPENCV_TAG = re.compile(r"!!opencv-[\w-]+")
_MATRIX_KEYS = ("camera_matrix", "K", "k")
_FLAT_PREFIXES = ("Camera.", "Camera1.")  # ORB-SLAM settings (e.g. its TUM1.yaml)


def _yaml_mapping(path: Path, text: str):
    """The first document of a (possibly OpenCV-flavoured) YAML file."""
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("%YAML")]
    # A `rostopic echo` dump may hold many messages: the first one is enough.
    documents = load_yaml_documents(_OPENCV_TAG.sub("", "\n".join(lines)), str(path), CaptureError)
    return next((d for d in documents if d is not None), None)


def is_calibration_yaml(path: Path) -> bool:
    """Whether a YAML file beside a depth image is a camera calibration (and not, say, a scene);
    a file that does not parse counts, so that its error is shown."""
    try:
        if path.stat().st_size > MAX_CALIBRATION_BYTES:
            return True  # so that load_calibration says why it is refused
        data = _yaml_mapping(path, path.read_bytes().decode("utf-8", errors="replace"))
    except (CaptureError, OSError):
        return True
    return isinstance(data, dict) and any(
        k in data for k in (*_MATRIX_KEYS, "fx", "intrinsic_matrix", "Camera.fx", "Camera1.fx")
    )


def _matrix(path, key: str, value, shapes: tuple[tuple[int, int], ...]) -> np.ndarray:
    """{rows, cols, data} (OpenCV, camera_calibration) or a list of numbers -> a matrix of one
    of the shapes."""
    rows = cols = None
    if isinstance(value, dict):
        rows, cols, value = value.get("rows"), value.get("cols"), value.get("data")
    try:
        a = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError, OverflowError, RecursionError):
        a = np.zeros(0)
    want = [
        s for s in shapes if s[0] * s[1] == a.size and rows in (None, s[0]) and cols in (None, s[1])
    ]
    if not want or not np.isfinite(a).all():
        shown = " or ".join(f"{r}x{c}" for r, c in shapes)
        raise CaptureError(
            f"{path}: {key}: expected a {shown} matrix ({{rows, cols, data}} or a list of "
            f"numbers, row by row), got {short_repr(value)}"
        )
    return a.reshape(want[0])


def _scale_of(data: dict, path: Path, keys: tuple[str, ...]) -> float | None:
    """Depth units per metre under one of the keys, if any."""
    for k in keys:
        if data.get(k) is not None:
            v = data[k]
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v < float("inf"):
                raise CaptureError(
                    f"{path}: {k}: expected units per metre > 0, got {short_repr(v)}"
                )
            return float(v)
    return None


def _from_yaml(path: Path, text: str, size: tuple[int, int] | None) -> Calibration:
    """OpenCV calibration YAML, ROS CameraInfo YAML (camera_calibration's file or a message
    dump), ORB-SLAM's Camera.fx... settings, or a flat {fx, fy, cx, cy, ...} mapping."""
    data = _yaml_mapping(path, text)
    if not isinstance(data, dict):
        raise CaptureError(
            f"{path}: expected a mapping with a camera matrix; accepted: {CALIBRATION_FORMATS}"
        )
    prefix = next((p for p in _FLAT_PREFIXES if f"{p}fx" in data), None)
    if prefix:
        flat = {k[len(prefix) :]: v for k, v in data.items() if k.startswith(prefix)}
        data = {**data, **flat}
    key = next((k for k in _MATRIX_KEYS if k in data), None)
    if key is not None:
        k = _matrix(path, key, data[key], ((3, 3),))
        numbers = {"fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2]}
    elif "fx" in data:
        numbers = {n: data[n] for n in ("fx", "fy", "cx", "cy") if n in data}
    else:
        raise CaptureError(
            f"{path}: no camera matrix: expected camera_matrix {{rows, cols, data}} (OpenCV, "
            f"ROS camera_calibration), K or k (a ROS CameraInfo message) or fx, fy, cx, cy; "
            f"it has {', '.join(map(str, data)) or 'no keys'}"
        )
    for w, h in (("image_width", "image_height"), ("width", "height")):
        if data.get(w) and data.get(h):  # a CameraInfo message's 0 means "not set"
            numbers |= {"width": data[w], "height": data[h]}
            break
    intr = intrinsics_from_mapping(numbers, str(path), size)
    pose = None
    if data.get("local_transform") is not None:
        pose = _rigid(path, "local_transform", data["local_transform"])
    return Calibration(intr, pose, _scale_of(data, path, ("depth_scale", "DepthMapFactor")))


def _rigid(path: Path, key: str, value) -> np.ndarray:
    """A 3x4 or 4x4 rigid transform -> (4, 4), its rotation made exactly orthonormal (files
    print ~9 digits)."""
    m = _matrix(path, key, value, ((3, 4), (4, 4)))
    rot = m[:3, :3]
    err = np.abs(rot.T @ rot - np.eye(3)).max()
    if (
        err > 1e-3
        or np.linalg.det(rot) <= 0
        or (m.shape[0] == 4 and not np.allclose(m[3], (0, 0, 0, 1)))
    ):
        raise CaptureError(
            f"{path}: {key}: the first 3 columns must be a rotation (orthonormal, determinant "
            f"+1; R^T R is off by {err:.2g}) and a 4x4's last row 0 0 0 1"
        )
    u, _, vt = np.linalg.svd(rot)
    out = np.eye(4)
    out[:3, :3] = u @ vt
    out[:3, 3] = m[:3, 3]
    return out


def _from_pcl_xml(path: Path, text: str) -> Intrinsics:
    try:
        root = ET.fromstring(f"<root>{text.split('?>', 1)[-1]}</root>")
    except ET.ParseError as exc:
        raise CaptureError(f"{path}: not valid XML ({exc})") from None
    node = root.find("depth")
    if node is None:
        raise CaptureError(f"{path}: no <depth> element with focal_length_x etc.")
    get = {c.tag: c.text for c in node}
    keys = {
        "fx": "focal_length_x",
        "fy": "focal_length_y",
        "cx": "principal_point_x",
        "cy": "principal_point_y",
    }
    try:
        vals = {k: float(get[tag] or "") for k, tag in keys.items()}  # (no text: refused)
    except (KeyError, TypeError, ValueError):
        raise CaptureError(f"{path}: <depth> needs {', '.join(keys.values())}") from None
    if not (
        np.isfinite(list(vals.values())).all()
        and 0 < min(vals["cx"], vals["cy"]) < MAX_IMAGE_SIDE / 2
    ):
        raise CaptureError(
            f"{path}: <depth>: expected finite numbers and a principal point inside the image, "
            f"got {', '.join(f'{k} {v:g}' for k, v in vals.items())}"
        )
    # PCL's grabber files carry no image size: the principal point is at the centre.
    size = {"width": max(round(2 * vals["cx"]), 1), "height": max(round(2 * vals["cy"]), 1)}
    return intrinsics_from_mapping({**size, **vals}, str(path))


def xml_depth_scale(text: str) -> float | None:
    """Depth units per metre from a PCL grabber XML's <z_multiplication_factor> (metres per
    unit), if it has a usable one."""
    try:
        root = ET.fromstring(f"<root>{text.split('?>', 1)[-1]}</root>")
        z = float(root.findtext("depth/z_multiplication_factor") or "")
    except (ET.ParseError, ValueError):
        return None
    scale = 1.0 / z if z > 0 else None
    return scale if scale is not None and np.isfinite(scale) else None
