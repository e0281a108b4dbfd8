"""Pinhole intrinsics: presets for the Kinect v2's three modes, and readers for the files
people bring (Open3D / simple JSON, PCL grabber XML, ROS CameraInfo fields)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._errors import CaptureError


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
            width=width, height=height, fx=self.fx * sx, fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5, cy=(self.cy + 0.5) * sy - 0.5,
        )  # fmt: skip

    def to_json(self) -> dict:
        return {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
                "cx": self.cx, "cy": self.cy}  # fmt: skip


# Kinect v2 nominal intrinsics (iai_kinect2 / libfreenect2 defaults): the IR/depth camera, and
# the colour camera's full HD mode and its quarter ("QHD", Tong 2018's choice) mode, to which
# iai_kinect2 registers depth.
_HD = Intrinsics(width=1920, height=1080, fx=1081.37, fy=1081.37, cx=959.5, cy=539.5)
PRESETS: dict[str, Intrinsics] = {
    "kinect2-sd": Intrinsics(width=512, height=424, fx=365.5, fy=365.5, cx=255.5, cy=211.5),
    "kinect2-qhd": _HD.scaled(960, 540),
    "kinect2-hd": _HD,
}


def load_intrinsics(spec: str | Path) -> Intrinsics:
    """A preset name (kinect2-sd, kinect2-qhd, kinect2-hd) or a file: JSON with width, height,
    fx, fy, cx, cy (or Open3D's {"width", "height", "intrinsic_matrix": 9 numbers,
    column-major}), or PCL's grabber XML (<depth><focal_length_x>...)."""
    name = str(spec)
    if name in PRESETS:
        return PRESETS[name]
    path = Path(spec)
    if not path.is_file():
        raise CaptureError(
            f"intrinsics {name!r}: no such file, and not a preset ({', '.join(PRESETS)})"
        )
    text = path.read_text(errors="replace")
    if path.suffix.lower() == ".xml" or text.lstrip().startswith("<"):
        return _from_pcl_xml(path, text)
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise CaptureError(f"{path}: intrinsics must be JSON or PCL XML ({exc})") from None
    return intrinsics_from_mapping(data, str(path))


def intrinsics_from_mapping(
    data: dict, where: str, size: tuple[int, int] | None = None
) -> Intrinsics:
    """From {"fx", "fy", "cx", "cy", "width", "height"} or Open3D's intrinsic_matrix form;
    size (width, height) fills a missing image size."""
    if not isinstance(data, dict):
        raise CaptureError(f"{where}: expected a JSON object with fx, fy, cx, cy, width, height")
    if "intrinsic_matrix" in data:  # Open3D PinholeCameraIntrinsic, column-major
        k = np.asarray(data["intrinsic_matrix"], dtype=float).reshape(3, 3).T
        data = {**data, "fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2]}
    if size is not None:
        data = {"width": size[0], "height": size[1], **data}
    missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in data]
    if missing:
        raise CaptureError(f"{where}: intrinsics lack {', '.join(missing)}")
    try:
        out = Intrinsics(
            width=int(data["width"]), height=int(data["height"]), fx=float(data["fx"]),
            fy=float(data["fy"]), cx=float(data["cx"]), cy=float(data["cy"]),
        )  # fmt: skip
    except (TypeError, ValueError) as exc:
        raise CaptureError(f"{where}: intrinsics must be numbers ({exc})") from None
    if min(out.width, out.height) < 1 or min(out.fx, out.fy) <= 0:
        raise CaptureError(f"{where}: intrinsics need width, height >= 1 and fx, fy > 0: {out}")
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
    keys = {"fx": "focal_length_x", "fy": "focal_length_y", "cx": "principal_point_x",
            "cy": "principal_point_y"}  # fmt: skip
    try:
        vals = {k: float(get[tag]) for k, tag in keys.items()}
    except (KeyError, TypeError, ValueError):
        raise CaptureError(f"{path}: <depth> needs {', '.join(keys.values())}") from None
    # PCL's grabber files carry no image size: the principal point is at the centre.
    return Intrinsics(
        width=round(2 * vals["cx"]), height=round(2 * vals["cy"]), **vals
    )  # fmt: skip


def xml_depth_scale(path: Path) -> float | None:
    """Depth units per metre from PCL's <z_multiplication_factor> (metres per unit), if any."""
    try:
        root = ET.fromstring(f"<root>{path.read_text().split('?>', 1)[-1]}</root>")
        z = float(root.find("depth").find("z_multiplication_factor").text)
    except (ET.ParseError, AttributeError, TypeError, ValueError, OSError):
        return None
    return 1.0 / z if z > 0 else None
