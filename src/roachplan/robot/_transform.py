"""The mocap frame to the scene's world frame: T_world_mocap.

A motion-capture system has its own origin (Motive's: where the calibration square lay);
the scene has its own (the terrain's). The user gives the transform (x, y, z and a yaw, or a
quaternion), or measures it: the robot placed at the scene's start, one pose sample fixes it
(measure_transform), as long as the mocap's up axis is the world's (both z up: a yaw and a
translation, no tilt, so a robot standing on a slightly tilted spot does not tilt the world).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._errors import RobotError


def quat_multiply(a, b) -> tuple[float, float, float, float]:
    """a * b, xyzw quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def quat_rotate(q, v) -> tuple[float, float, float]:
    """v rotated by the unit quaternion q (xyzw)."""
    x, y, z, w = q
    vx, vy, vz = v
    # v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
    cx, cy, cz = y * vz - z * vy, z * vx - x * vz, x * vy - y * vx
    return (
        vx + 2 * (w * cx + y * cz - z * cy),
        vy + 2 * (w * cy + z * cx - x * cz),
        vz + 2 * (w * cz + x * cy - y * cx),
    )


def yaw_of(quat) -> float:
    """Heading of the body's forward (x) axis projected on the horizontal [rad]."""
    x, y, z, w = quat
    return math.atan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z))


def yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    """The rotation by yaw [rad] about z, xyzw."""
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


@dataclass(frozen=True, kw_only=True)
class FrameTransform:
    """T_world_mocap: p_world = R p_mocap + t."""

    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """t [m]."""
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    """R as a unit quaternion, xyzw."""

    def __post_init__(self) -> None:
        norm = math.sqrt(sum(c * c for c in self.quat))
        if not all(map(math.isfinite, (*self.translation, *self.quat))) or abs(norm - 1) > 1e-3:
            raise RobotError(
                f"mocap transform: translation {list(self.translation)} must be finite and "
                f"quaternion {list(self.quat)} a unit quaternion [x, y, z, w]"
            )
        object.__setattr__(self, "quat", tuple(c / norm for c in self.quat))

    @classmethod
    def from_xyz_yaw(cls, x: float, y: float, z: float, yaw: float) -> FrameTransform:
        """A translation [m] and a turn yaw [rad] about z."""
        return cls(translation=(x, y, z), quat=yaw_quat(yaw))

    def apply(self, position, quat) -> tuple[tuple[float, float, float], tuple]:
        """(p_world [m], quat_world xyzw) of a pose in the mocap frame."""
        p = quat_rotate(self.quat, position)
        t = self.translation
        return (p[0] + t[0], p[1] + t[1], p[2] + t[2]), quat_multiply(self.quat, quat)

    def to_json(self) -> dict:
        return {"translation": list(self.translation), "quat": list(self.quat)}


def measure_transform(
    position, quat, start: tuple[float, float, float], start_z: float
) -> FrameTransform:
    """The transform that puts the robot, seen by the mocap at position [m] with orientation
    quat (xyzw, mocap frame, z up), at the scene's start (x [m], y [m], yaw [rad]) with its body
    centre at height start_z [m] (the terrain under the start plus the robot's standing
    height): the mocap's heading of the robot becomes the start's, its position the start's."""
    p = np.asarray(position, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise RobotError(f"measure the transform: the pose sample {position!r} is no position")
    turn = start[2] - yaw_of(quat)
    q = yaw_quat(turn)
    rotated = quat_rotate(q, p)
    return FrameTransform(
        translation=(start[0] - rotated[0], start[1] - rotated[1], start_z - rotated[2]),
        quat=q,
    )
