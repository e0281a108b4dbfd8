"""Path following (Tong 2018, algorithm 1) and the exponential differential-drive P-controller
(algorithm 2), and the drive loop that turns a planned path into a trial outcome."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ._config import DriverConfig
from ._simulation import Simulation

Outcome = Literal["success", "fell", "flipped", "stuck", "timeout"]


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
    """success: within r_end of the goal in time; fell: dropped off the planned surface (or
    the simulation diverged); flipped: on its back; stuck: no progress for stuck_time;
    timeout: still going at time_limit."""
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


def heading_error(p_xy, quat_xyzw, target_xy) -> float:
    """Angle theta from the body's forward axis to the target, positive to the left [rad].

    Tong 2018, section 3.5: theta = atan(x_d . y' / x_d . x') with x' and y' the body's forward
    and left axes (quat_xyzw rotated). We take atan2 so a target behind the robot gives
    |theta| > pi/2, and use the horizontal part of x_d so a target on the surface below the
    body does not bias it. Scalar math: it runs at every controller update.
    """
    x, y, z, w = quat_xyzw
    dx, dy = target_xy[0] - p_xy[0], target_xy[1] - p_xy[1]
    forward = dx * (1 - 2 * (y * y + z * z)) + dy * 2 * (x * y + z * w)  # x_d . x'
    left = dx * 2 * (x * y - z * w) + dy * (1 - 2 * (x * x + z * z))  # x_d . y'
    return math.atan2(left, forward)


def motor_speeds(theta: float, omega0: float, gain: float, omega_max: float) -> tuple[float, float]:
    """(left, right) motor speeds [rad/s] of algorithm 2: one side at omega0, the other at
    omega0 * exp(|p theta|); the faster side is the one away from the turn, and it is capped
    at omega_max."""
    fast = min(omega0 * math.exp(abs(gain * theta)), omega_max)
    return (omega0, fast) if theta > 0 else (fast, omega0)


def next_waypoint(
    path_xy: np.ndarray, i: int, p_xy: np.ndarray, r_path: float, r_end: float
) -> tuple[int, bool]:
    """Algorithm 1: advance past every intermediate waypoint within r_path [m]; report whether
    the last one is within r_end [m]. Returns (index of the waypoint to steer to, arrived)."""
    n = len(path_xy)
    while i < n - 1 and math.dist(path_xy[i], p_xy) < r_path:
        i += 1
    arrived = i == n - 1 and math.dist(path_xy[i], p_xy) < r_end
    return i, arrived


def _failure(pos, quat, path: np.ndarray, standing: float, fall_drop: float):
    """(outcome, reason) if the robot diverged, flipped or dropped off the planned surface."""
    if not all(map(math.isfinite, pos)):
        return "fell", "the simulation diverged (non-finite body position)"
    qx, qy = quat[0], quat[1]
    if 1 - 2 * (qx * qx + qy * qy) < 0.0:  # the body's z axis points down
        return "flipped", f"flipped over at ({pos[0]:.2f}, {pos[1]:.2f})"
    # Off the surface the path runs on: compare with the path's surface height nearby.
    near = int(np.argmin(np.sum((path[:, :2] - pos[:2]) ** 2, axis=1)))
    drop = path[near, 2] + standing - pos[2]
    if drop > fall_drop:
        return (
            "fell",
            f"dropped {drop:.2f} m below the planned surface at ({pos[0]:.2f}, {pos[1]:.2f})",
        )
    return None


def drive_path(
    sim: Simulation,
    path_xyz: np.ndarray,
    cfg: DriverConfig,
    on_frame: Callable[[Frame], None] | None = None,
) -> DriveResult:
    """Drive the (already reset) robot along path_xyz ((N, 3) world frame [m], z on the terrain
    surface) until it arrives, falls, flips, gets stuck or runs out of time.

    Every control_period the controller reads the body pose, checks the outcome, advances the
    waypoint (algorithm 1) and sets the motor speeds (algorithm 2); in between, the simulation
    steps with nothing of ours but the leg targets and the energy meter.
    """
    path = np.asarray(path_xyz, dtype=float)
    if path.ndim != 2 or path.shape[1] != 3 or len(path) < 2:
        raise ValueError(f"path must be (N>=2, 3), got {path.shape}")
    path_xy = [tuple(q) for q in path[:, :2].tolist()]
    steps_per_control = max(1, round(cfg.control_period / sim.cfg.timestep))
    omega_max = min(sim.robot.max_motor_speed, cfg.max_ratio * cfg.omega0)
    standing = sim.robot.standing_height
    trajectory: list[tuple[float, float, float, float]] = []
    next_frame = 0.0
    i = 1
    # Progress: the waypoint index advanced, or the robot got stuck_distance closer to its
    # waypoint, since last_progress [s].
    last_progress, best_gap = 0.0, math.inf
    outcome: Outcome = "timeout"
    reason = f"did not reach the goal within {cfg.time_limit:g} s"
    while True:
        pos, quat = sim.pose()
        t = sim.time
        if t >= next_frame:
            trajectory.append((t, *pos))
            if on_frame is not None:
                on_frame(
                    Frame(t=t, p_world_body=pos, quat_world_body=quat,
                          leg_angles=tuple(sim.joint_angles().tolist()))
                )  # fmt: skip
            next_frame += cfg.frame_period
        failure = _failure(pos, quat, path, standing, cfg.fall_drop)
        if failure is not None:
            outcome, reason = failure
            break
        i_before = i
        i, arrived = next_waypoint(path_xy, i, pos[:2], cfg.r_path, cfg.r_end)
        if arrived:
            outcome, reason = "success", "reached the goal"
            break
        gap = math.dist(path_xy[i], pos[:2])
        if i != i_before or gap < best_gap - cfg.stuck_distance:
            last_progress, best_gap = t, gap
        elif t - last_progress >= cfg.stuck_time:
            outcome = "stuck"
            reason = (
                f"no progress for {cfg.stuck_time:g} s at ({pos[0]:.2f}, {pos[1]:.2f}), "
                f"{gap:.2f} m from waypoint {i} of {len(path_xy) - 1}"
            )
            break
        if t >= cfg.time_limit:
            break
        theta = heading_error(pos, quat, path_xy[i])
        sim.set_leg_speeds(*motor_speeds(theta, cfg.omega0, cfg.gain, omega_max))
        sim.advance(steps_per_control)
    if trajectory[-1][0] != sim.time:
        trajectory.append((sim.time, *pos))
    return DriveResult(
        outcome=outcome,
        reason=reason,
        drive_time=sim.time,
        energy=sim.energy,
        energy_per_leg=tuple(sim.energy_per_leg.tolist()),
        trajectory=tuple(trajectory),
    )
