"""Path following (Tong 2018, algorithm 1) and the exponential differential-drive P-controller
(algorithm 2), and the drive loop that turns a planned path into a trial outcome."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ._config import DriverConfig
from ._simulation import Simulation

Outcome = Literal["success", "fell", "timeout"]


@dataclass(frozen=True, kw_only=True)
class Frame:
    """One animation sample of a drive."""

    t: float
    """Simulated time since the drive started [s]."""
    p_world_body: tuple[float, float, float]
    """Body position [m]."""
    quat_world_body: tuple[float, float, float, float]
    """Body orientation, xyzw."""
    leg_angles: tuple[float, ...]
    """(6,) leg joint angles [rad], hip order L1 L2 L3 R1 R2 R3."""


@dataclass(frozen=True, kw_only=True)
class DriveResult:
    """What happened when the roach drove a path."""

    outcome: Outcome
    """success: within r_end of the goal in time; fell: dropped off the surface or flipped."""
    reason: str
    """Human-readable cause of the outcome."""
    drive_time: float
    """Simulated time until the outcome was decided [s]."""
    energy: float
    """Sum over legs of sum_t |omega_t tau_t| dt [J] (Tong 2018, section 3.4)."""
    energy_per_leg: tuple[float, ...]
    """(6,) the same per leg [J]."""
    trajectory: tuple[tuple[float, float, float, float], ...]
    """Body positions (t [s], x, y, z [m]), one per frame period and one at the end."""


def quat_to_matrix(quat_xyzw: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of an xyzw unit quaternion."""
    x, y, z, w = quat_xyzw
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def heading_error(p_world_body: np.ndarray, R_world_body: np.ndarray, target: np.ndarray) -> float:
    """Angle theta from the body's forward axis to the target, positive to the left [rad].

    Tong 2018, section 3.5: theta = atan(x_d . y' / x_d . x') with x' and y' the body's forward
    and left axes. We take atan2 so a target behind the robot gives |theta| > pi/2, and use the
    horizontal part of x_d so a target on the surface below the body does not bias it.
    """
    d = np.asarray(target[:2], dtype=float) - p_world_body[:2]
    return float(np.arctan2(d @ R_world_body[:2, 1], d @ R_world_body[:2, 0]))


def motor_speeds(theta: float, omega0: float, gain: float, omega_max: float) -> tuple[float, float]:
    """(left, right) motor speeds [rad/s] of algorithm 2: one side at omega0, the other at
    omega0 * exp(|p theta|); the faster side is the one away from the turn, and it is capped
    at omega_max."""
    fast = min(omega0 * float(np.exp(abs(gain * theta))), omega_max)
    return (omega0, fast) if theta > 0 else (fast, omega0)


def next_waypoint(
    path_xy: np.ndarray, i: int, p_xy: np.ndarray, r_path: float, r_end: float
) -> tuple[int, bool]:
    """Algorithm 1: advance past every intermediate waypoint within r_path [m]; report whether
    the last one is within r_end [m]. Returns (index of the waypoint to steer to, arrived)."""
    n = len(path_xy)
    while i < n - 1 and np.linalg.norm(path_xy[i] - p_xy) < r_path:
        i += 1
    arrived = i == n - 1 and bool(np.linalg.norm(path_xy[i] - p_xy) < r_end)
    return i, arrived


def drive_path(
    sim: Simulation,
    path_xyz: np.ndarray,
    cfg: DriverConfig,
    on_frame: Callable[[Frame], None] | None = None,
) -> DriveResult:
    """Drive the (already reset) robot along path_xyz ((N, 3) world frame [m], z on the terrain
    surface) until it arrives, falls or runs out of time."""
    path = np.asarray(path_xyz, dtype=float)
    if path.ndim != 2 or path.shape[1] != 3 or len(path) < 2:
        raise ValueError(f"path must be (N>=2, 3), got {path.shape}")
    steps_per_control = max(1, round(cfg.control_period / sim.cfg.timestep))
    omega_max = min(sim.robot.max_motor_speed, cfg.max_ratio * cfg.omega0)
    standing = sim.robot.standing_height
    trajectory: list[tuple[float, float, float, float]] = []
    next_frame = 0.0
    i = 1
    outcome: Outcome = "timeout"
    reason = f"did not reach the goal within {cfg.time_limit:g} s"
    while True:
        p_body, quat = sim.body_pose()
        t = sim.time
        if t >= next_frame:
            trajectory.append((t, *p_body.tolist()))
            if on_frame is not None:
                on_frame(
                    Frame(
                        t=t,
                        p_world_body=tuple(p_body.tolist()),
                        quat_world_body=tuple(quat.tolist()),
                        leg_angles=tuple(sim.joint_angles().tolist()),
                    )
                )
            next_frame += cfg.frame_period
        if not np.all(np.isfinite(p_body)):
            outcome, reason = "fell", "the simulation diverged (non-finite body position)"
            break
        R = quat_to_matrix(quat)
        if R[2, 2] < 0.0:
            outcome, reason = "fell", "flipped over"
            break
        # Off the surface the path runs on: compare with the path's surface height nearby.
        near = int(np.argmin(np.sum((path[:, :2] - p_body[:2]) ** 2, axis=1)))
        drop = path[near, 2] + standing - p_body[2]
        if drop > cfg.fall_drop:
            outcome = "fell"
            reason = f"dropped {drop:.2f} m below the planned surface at ({p_body[0]:.2f}, {p_body[1]:.2f})"
            break
        i, arrived = next_waypoint(path[:, :2], i, p_body[:2], cfg.r_path, cfg.r_end)
        if arrived:
            outcome, reason = "success", "reached the goal"
            break
        if t >= cfg.time_limit:
            break
        theta = heading_error(p_body, R, path[i])
        sim.set_leg_speeds(*motor_speeds(theta, cfg.omega0, cfg.gain, omega_max))
        for _ in range(steps_per_control):
            sim.step()
    if trajectory[-1][0] != sim.time:
        trajectory.append((sim.time, *p_body.tolist()))
    return DriveResult(
        outcome=outcome,
        reason=reason,
        drive_time=sim.time,
        energy=sim.energy,
        energy_per_leg=tuple(sim.energy_per_leg.tolist()),
        trajectory=tuple(trajectory),
    )
