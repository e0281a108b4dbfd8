"""Re-levelling a loaded capture without uploading it again: a ground point clicked in the page,
or the camera's height, pitch and roll typed in, become the capture's `perception:` settings
(ground_point, camera_pose) in the upload's scene file, which is then loaded again.

Camera pose convention (the one `Reconstruction.report()` reads back): the world is z up; the
camera's optical frame is x right, y down, z forward. A camera at height h [m] with pitch p
(degrees the optical axis points below the horizon) and roll r (degrees about the optical axis,
positive when the image's right side drops, i.e. world up seen in the image turns toward +x)
and heading yaw (the optical axis's heading on the ground less 90 degrees: 0 looks along +y) has
    R_world_camera = Rz(yaw) @ R_level @ Rx(-p) @ Rz(-r),
with R_level the level camera looking along world +y (x -> x, y -> -z, z -> +y). Its position
keeps the x, y the capture last had, so the terrain stays where it was drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from roachplan.perception import load_yaml

_LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Columns: the level camera's x, y, z axes in the world (looking along world +y)."""


@dataclass(frozen=True, kw_only=True)
class CaptureView:
    """What the app keeps of a loaded capture to re-level it."""

    scene_path: Path
    """The upload's scene file (one capture object)."""
    world_from_camera: np.ndarray
    """(4, 4) transform of capture-frame points into the world frame [m]."""
    report: dict
    """Reconstruction.report() of the load."""

    @property
    def has_camera(self) -> bool:
        """Whether the capture is in a camera frame (a pose to show and edit)."""
        return self.report.get("camera_pose") is not None


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def heading_deg(world_from_camera: np.ndarray) -> float:
    """The camera's yaw [deg]: the heading of its optical axis on the ground less 90 (roll does
    not turn the optical axis); its x axis's heading when it looks straight up or down."""
    r = np.asarray(world_from_camera)[:3, :3]
    if math.hypot(r[0, 2], r[1, 2]) > 1e-6:
        return math.degrees(math.atan2(r[1, 2], r[0, 2])) - 90.0
    return math.degrees(math.atan2(r[1, 0], r[0, 0]))


def camera_pose_from(
    height: float,
    pitch_down_deg: float,
    roll_deg: float,
    *,
    x: float = 0.0,
    y: float = 0.0,
    yaw_deg: float = 0.0,
) -> list[float]:
    """[x, y, z, qx, qy, qz, qw] of a camera at height [m] with pitch and roll [deg] (module
    docstring), for the `camera_pose` capture setting."""
    from scipy.spatial.transform import Rotation

    if not (math.isfinite(height) and height > 0):
        raise ValueError(f"camera height: expected a number of metres > 0, got {height!r}")
    if not -90.0 <= pitch_down_deg <= 90.0:
        raise ValueError(f"camera pitch: expected -90 to 90 degrees, got {pitch_down_deg!r}")
    rot = (
        _rz(math.radians(yaw_deg))
        @ _LEVEL
        @ _rx(-math.radians(pitch_down_deg))
        @ _rz(-math.radians(roll_deg))
    )
    quat = Rotation.from_matrix(rot).as_quat()
    return [float(x), float(y), float(height), *(round(float(q), 9) for q in quat)]


def ground_point_in_capture(world_from_camera: np.ndarray, p_world) -> list[float]:
    """A world point [m] in the capture's frame [m] (for the `ground_point` setting)."""
    inv = np.linalg.inv(np.asarray(world_from_camera, dtype=np.float64))
    p = inv[:3, :3] @ np.asarray(p_world, dtype=np.float64) + inv[:3, 3]
    return [round(float(v), 5) for v in p]


def rewrite_capture_settings(scene_path: Path, changes: dict) -> None:
    """Set (or, for None, remove) keys of the capture object's `perception:` block in an
    upload's scene file, and drop its start, goal and bounds (the terrain moves: they are
    picked again on the next load)."""
    raw = load_yaml(Path(scene_path).read_bytes(), Path(scene_path).name)
    obj = next(o for o in raw["terrain"] if "capture" in o)
    settings = dict(obj.get("perception") or {})
    for k, v in changes.items():
        if v is None:
            settings.pop(k, None)
        else:
            settings[k] = v
    obj["perception"] = settings
    for k in ("robot", "goal", "bounds"):
        raw.pop(k, None)
    Path(scene_path).write_text(yaml.safe_dump(raw, sort_keys=False))


def adopt_capture_scene(scene_path: Path, folder: Path) -> Path:
    """A scene file in folder, which the app may rewrite, for a capture scene that came from
    elsewhere (the library, `serve --scene`): the capture and a calibration file beside it by
    absolute path, its perception settings and the scene's other keys kept; start, goal and
    bounds left out (they are picked again)."""
    from roachplan.scenes import TERRAIN_SUFFIXES

    scene_path = Path(scene_path).resolve()
    if scene_path.suffix.lower() in TERRAIN_SUFFIXES:  # a capture file as a scene of its own
        raw = {
            "description": f"{scene_path.name}, re-meshed in the page",
            "terrain": [{"capture": str(scene_path)}],
            "ground": None,
        }
    else:
        raw = load_yaml(scene_path.read_bytes(), scene_path.name)
        obj = next(o for o in raw["terrain"] if "capture" in o)
        obj["capture"] = str((scene_path.parent / obj["capture"]).resolve())
        settings = obj.get("perception") or {}
        intrinsics = settings.get("intrinsics")
        if isinstance(intrinsics, str) and (scene_path.parent / intrinsics).is_file():
            settings["intrinsics"] = str((scene_path.parent / intrinsics).resolve())
        for k in ("robot", "goal", "bounds"):
            raw.pop(k, None)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{scene_path.stem}.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def relevel_at(view: CaptureView, p_world) -> dict:
    """The capture-setting changes that make the ground the plane through a clicked world point:
    the camera pose is then found again (an explicit pose would override the ground)."""
    return {
        "ground_point": ground_point_in_capture(view.world_from_camera, p_world),
        "camera_pose": None,
    }


def repose(view: CaptureView, height: float, pitch_down_deg: float, roll_deg: float) -> dict:
    """The capture-setting changes for a typed-in camera height, pitch and roll (the heading and
    the camera's x, y stay as loaded)."""
    t = np.asarray(view.world_from_camera)[:3, 3]
    pose = camera_pose_from(
        height,
        pitch_down_deg,
        roll_deg,
        x=round(float(t[0]), 5),
        y=round(float(t[1]), 5),
        yaw_deg=heading_deg(view.world_from_camera),
    )
    return {"camera_pose": pose, "ground_point": None}
