"""Where a reset stands the robot: pure geometry over an engine's ray cast down, shared by
every engine (sim/_pybullet.py, sim/_mujoco.py), so that both put the robot on the same
ground and the same support plane.

An engine gives `surface_height(x, y, below)`: the height of the highest surface at (x, y)
under z = below [m], -inf if none. Frames: world z up [m]; the body frame is RobotConfig's.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ._errors import SimError
from ._robot import RobotConfig

SurfaceHeight = Callable[..., float]
"""An engine's `surface_height(x, y, below=50.0)` [m]."""
Ground = Callable[[float, float], float]
"""The ground the robot stands on at (x, y) [m] (ground_height with the planner's surface)."""

DROP_CLEARANCE = 0.004
"""How far above its stance a reset drops the body [m]: feet just clear of the ground, so the
first contacts are made by the settling, not found already penetrating."""
TABLE_GAP = 0.1
"""A surface more than this above the planner's [m] is over what the plan stands on (a table
over the floor), and the ground is looked for under it."""


def ground_height(
    surface_height: SurfaceHeight, x: float, y: float, surface: float | None
) -> float:
    """The surface the robot stands on at (x, y) [m]: the highest, unless the planner's
    surface [m] there lies more than TABLE_GAP under it (a table over the floor): then the
    highest just above the planner's (cast from the top first, so that a start with nothing
    over it is placed exactly as without a surface given)."""
    z = surface_height(x, y)
    if surface is not None and np.isfinite(surface) and z > surface + TABLE_GAP:
        z = surface_height(x, y, surface + TABLE_GAP)
    return z


def foot_points(robot: RobotConfig, x: float, y: float, yaw: float) -> np.ndarray:
    """(6, 2) world xy of the feet [m] of the robot standing level at (x, y) [m], heading yaw
    [rad], legs pointing down."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.asarray(robot.foot_points_xy) @ np.array([[c, s], [-s, c]]) + (x, y)


def start_height(ground: Ground, robot: RobotConfig, x: float, y: float, yaw: float) -> float:
    """The ground's height under the start (x, y) [m] heading yaw [rad]: under the centre, or,
    where a capture's mesh has a sensor dropout under the centre alone, the highest under the
    feet (the planner checked that the feet stand); SimError when there is none."""
    z0 = ground(x, y)
    if not np.isfinite(z0):
        z0 = max(ground(f[0], f[1]) for f in foot_points(robot, x, y, yaw))
    if not np.isfinite(z0):
        raise SimError(f"no terrain under the start position ({x:.3f}, {y:.3f})")
    return z0


def support_plane_pose(
    ground: Ground, robot: RobotConfig, x: float, y: float, yaw: float
) -> tuple[tuple[float, float, float], tuple[float, float, float, float]] | None:
    """(p_world_body (3,) [m], quat_world_body xyzw) of the body standing on the plane fitted
    (least squares) to the ground under its feet at (x, y) [m], heading yaw [rad],
    DROP_CLEARANCE above its stance: on a slope a level body would put its uphill feet into the
    ground (an 11 deg lidar slope flipped it within 0.2 s). None when the ground under the
    feet is level (the body is then placed exactly as on flat ground) or a foot has no
    ground."""
    feet = foot_points(robot, x, y, yaw)
    c, s = np.cos(yaw), np.sin(yaw)
    z = np.array([ground(f[0], f[1]) for f in feet])
    if not np.all(np.isfinite(z)) or np.ptp(z) < 1e-6:
        return None
    a, b, cy = np.linalg.lstsq(np.column_stack([np.ones(6), feet]), z, rcond=None)[0]
    up = np.array([-b, -cy, 1.0]) / np.linalg.norm([-b, -cy, 1.0])
    forward = np.array([c, s, 0.0]) - up * (up @ np.array([c, s, 0.0]))
    forward /= np.linalg.norm(forward)
    rot = np.column_stack([forward, np.cross(up, forward), up])  # body axes in the world
    centre = np.array([x, y, a + b * x + cy * y]) + up * (robot.standing_height + DROP_CLEARANCE)
    from scipy.spatial.transform import Rotation

    px, py, pz = centre.tolist()
    qx, qy, qz, qw = Rotation.from_matrix(rot).as_quat().tolist()
    return (px, py, pz), (qx, qy, qz, qw)


def terrain_arrays(
    vertices: np.ndarray, faces: np.ndarray, ground_height: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """An engine's terrain as float64 vertices (V, 3) [m] and int64 faces (F, 3); SimError
    for another shape, or for a world with neither triangles nor a ground plane."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise SimError(f"terrain vertices must be (V, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise SimError(f"terrain faces must be (F, 3), got {faces.shape}")
    if len(faces) == 0 and ground_height is None:
        raise SimError("a world needs terrain triangles or a ground plane; it has neither")
    return vertices, faces
