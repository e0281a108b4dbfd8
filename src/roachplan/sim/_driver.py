"""Path following, and the drive loop that turns a planned path into a trial outcome.

Two followers: `reference`, Tong 2018's algorithm 1 (steer to the next waypoint, advance past
the ones within r_path) with the exponential differential-drive P-controller of algorithm 2,
kept exactly as the report gives them for tables 7.1-7.3; and `tracking` (the default, issue
18), pure pursuit on the path's arc length: the robot's progress along the path only grows, so
a waypoint it has passed is never chased back (algorithm 1 circles one it keeps overshooting),
and the turn it is asked for is converted to a motor ratio through the calibrated turning
model instead of a tuned gain. Where a plan turns on the spot (a spin: a waypoint and the
heading to turn to there), the tracking driver's progress stops at the spin's waypoint; it
runs the two sides in opposite directions until the heading is within spin_tolerance of the
spin's, then goes on with pure pursuit. The reference driver has no spins (the report's
algorithms turn only on arcs) and ignores them."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from ._config import DriverConfig
from ._engine import Simulation

Outcome = Literal["success", "fell", "flipped", "stuck", "timeout", "missed"]


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
    timeout: still going at time_limit; missed: went past the goal wider than r_end (tracking
    driver: it turns on the spot only at a plan's spins, not to come back)."""
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
    path_xy: Sequence[Sequence[float]], i: int, p_xy, r_path: float, r_end: float
) -> tuple[int, bool]:
    """Algorithm 1: advance past every intermediate waypoint within r_path [m]; report whether
    the last one is within r_end [m]. Returns (index of the waypoint to steer to, arrived)."""
    n = len(path_xy)
    while i < n - 1 and math.dist(path_xy[i], p_xy) < r_path:
        i += 1
    arrived = i == n - 1 and math.dist(path_xy[i], p_xy) < r_end
    return i, arrived


def _failure(
    pos, quat, path: np.ndarray, standing: float, fall_drop: float, *, top: float = math.inf
):
    """(outcome, reason) if the robot diverged, flipped or dropped off the planned surface.
    top: the path's highest point [m] (its z's maximum), if known."""
    if not all(map(math.isfinite, pos)):
        return "fell", "the simulation diverged (non-finite body position)"
    qx, qy = quat[0], quat[1]
    if 1 - 2 * (qx * qx + qy * qy) < 0.0:  # the body's z axis points down
        return "flipped", f"flipped over at ({pos[0]:.2f}, {pos[1]:.2f})"
    # Off the surface the path runs on: compare with the path's surface height nearby. No
    # waypoint is higher than top, so a body within fall_drop of top's standing height has
    # not dropped, whichever waypoint is nearest (rounding is monotonic: the same verdict).
    if top + standing - pos[2] <= fall_drop:
        return None
    near = int(np.argmin(np.sum((path[:, :2] - pos[:2]) ** 2, axis=1)))
    drop = path[near, 2] + standing - pos[2]
    if drop > fall_drop:
        return (
            "fell",
            f"dropped {drop:.2f} m below the planned surface at ({pos[0]:.2f}, {pos[1]:.2f})",
        )
    return None


Spin = tuple[int, float]
"""A turn on the spot: (index of the waypoint where it is made, heading to turn to there [rad],
world frame, counter-clockwise from +x)."""


def check_spins(spins, n_waypoints: int) -> tuple[Spin, ...]:
    """The spins as (int, float) pairs sorted by waypoint; ValueError naming the spin when an
    index is not a waypoint of the n_waypoints or a heading is not a finite number."""
    out = []
    for k, item in enumerate(spins):
        try:
            index, yaw = item
            ok = float(index).is_integer() and 0 <= index < n_waypoints and math.isfinite(yaw)
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(
                f"spin {k} {item!r}: expected (waypoint index from 0 to "
                f"{n_waypoints - 1}, finite heading [rad])"
            )
        out.append((int(index), float(yaw)))
    return tuple(sorted(out))


def drive_path(
    sim: Simulation,
    path_xyz: np.ndarray,
    cfg: DriverConfig,
    on_frame: Callable[[Frame], None] | None = None,
    *,
    spins=(),
) -> DriveResult:
    """Drive the (already reset) robot along path_xyz ((N, 3) world frame [m], z on the terrain
    surface; one waypoint: stand at it) until it arrives, falls, flips, gets stuck or runs out
    of time. spins: the plan's turns on the spot, (waypoint index, heading [rad]) each (Spin);
    the tracking driver makes them, the reference driver ignores them.

    Every control_period the controller reads the body pose, checks the outcome, lets the
    follower (cfg.kind) advance along the path and set the motor speeds; in between, the
    simulation steps with nothing of ours but the leg targets and the energy meter. (A
    worker's rollouts in lockstep, sim/_lockstep.py, run the same Drive per rollout.)
    """
    drive = Drive(path_xyz, cfg, spins, robot=sim.robot)
    steps_per_control = max(1, round(cfg.control_period / sim.cfg.timestep))
    while True:
        pos, quat = sim.pose()
        if on_frame is not None and sim.time >= drive.next_frame:
            on_frame(
                Frame(
                    t=sim.time,
                    p_world_body=pos,
                    quat_world_body=quat,
                    leg_angles=tuple(sim.joint_angles().tolist()),
                )
            )
        speeds = drive.control(sim.time, pos, quat)
        if speeds is None:
            return drive.result(sim.time, pos, sim.energy_per_leg)
        sim.set_leg_speeds(*speeds)
        sim.advance(steps_per_control)


class Drive:
    """One drive's controller and bookkeeping, apart from the engine that moves the robot:
    each control period `control` takes the body pose and says the motor speeds, or None once
    the outcome is decided; `result` then gives it. The same for one simulation (drive_path)
    and for rollouts stepped together (sim/_lockstep.py)."""

    def __init__(self, path_xyz, cfg: DriverConfig, spins, *, robot) -> None:
        """path_xyz: (N, 3) world frame [m]; spins: (waypoint index, heading [rad]) each;
        robot: the RobotConfig driven (its standing height and motor limit)."""
        self.follower = make_follower(np.asarray(path_xyz, dtype=float), cfg, spins)
        self.path = self.follower.path
        self.top = float(self.path[:, 2].max())
        """The path's highest point [m]."""
        self.cfg = cfg
        self.omega_max = omega_limit(robot.max_motor_speed, cfg)
        self.standing = robot.standing_height
        self.trajectory: list[tuple[float, float, float, float]] = []
        """Body positions (t [s], x, y, z [m]), one per frame period."""
        self.next_frame = 0.0
        """When the next trajectory sample is due [s]."""
        # Progress: the follower advanced (reference: to its next waypoint), or its gap to go
        # got stuck_distance smaller, since last_progress [s].
        self.last_progress, self.best_gap = 0.0, math.inf
        self.outcome: Outcome = "timeout"
        self.reason = f"did not reach the goal within {cfg.time_limit:g} s"

    def control(self, t: float, pos, quat) -> tuple[float, float] | None:
        """At time t [s] with the body at pos (x, y, z) [m], orientation quat (xyzw): the
        (left, right) motor speeds [rad/s] until the next control period, or None when the
        drive has ended (self.outcome, self.reason say how)."""
        cfg = self.cfg
        if t >= self.next_frame:
            self.trajectory.append((t, *pos))
            self.next_frame += cfg.frame_period
        failure = _failure(pos, quat, self.path, self.standing, cfg.fall_drop, top=self.top)
        if failure is not None:
            self.outcome, self.reason = failure
            return None
        follower = self.follower
        ended = follower.update(pos, quat)
        if ended is not None:
            self.outcome, self.reason = ended
            return None
        gap = follower.gap
        if follower.advanced or gap < self.best_gap - cfg.stuck_distance:
            self.last_progress, self.best_gap = t, gap
        elif t - self.last_progress >= cfg.stuck_time:
            self.outcome = "stuck"
            self.reason = (
                f"no progress for {cfg.stuck_time:g} s at ({pos[0]:.2f}, {pos[1]:.2f}), "
                + follower.where()
            )
            return None
        if t >= cfg.time_limit:
            return None
        return follower.speeds(pos, quat, self.omega_max)

    def result(self, t: float, pos, energy_per_leg: np.ndarray) -> DriveResult:
        """The drive's result, ended at time t [s] with the body at pos [m], the motors having
        spent energy_per_leg ((6,) [J])."""
        if self.trajectory[-1][0] != t:
            self.trajectory.append((t, *pos))
        return DriveResult(
            outcome=self.outcome,
            reason=self.reason,
            drive_time=t,
            energy=float(np.sum(energy_per_leg)),
            energy_per_leg=tuple(np.asarray(energy_per_leg).tolist()),
            trajectory=tuple(self.trajectory),
        )


class Follower(Protocol):
    """A path follower: what turns the robot's pose into motor speeds along a path, the same
    for the simulated robot (drive_path) and a real one (roachplan.robot's loop). Made by
    make_follower; stateful (its progress along the path), one per drive."""

    path: np.ndarray
    """(N >= 2, 3) the path it follows, world frame [m]."""
    advanced: bool
    """The last update moved the progress on (reference: to its next waypoint)."""
    gap: float
    """What is left to go [m] (reference: to its waypoint; tracking: along the path)."""

    def update(self, pos, quat) -> tuple[Outcome, str] | None:
        """Advance the progress from the body position pos (x, y, z) [m] and orientation quat
        (xyzw); (outcome, reason) when the drive has ended ("success", or the tracking
        driver's "missed"), else None."""
        ...

    def speeds(self, pos, quat, omega_max: float) -> tuple[float, float]:
        """(left, right) motor speeds [rad/s] for the pose, each at most omega_max [rad/s]."""
        ...

    def where(self) -> str:
        """Where along the path the robot is, for a message."""
        ...


def make_follower(path_xyz, cfg: DriverConfig, spins=()) -> Follower:
    """The follower cfg.kind names ("tracking" or "reference") for path_xyz ((N >= 1, 3) world
    frame [m]; one waypoint: stand at it) and the plan's spins ((waypoint index, heading [rad])
    each; the reference follower ignores them). ValueError for a path of another shape or a
    spin that names no waypoint."""
    path = np.asarray(path_xyz, dtype=float)
    if path.ndim != 2 or path.shape[1] != 3 or len(path) < 1:
        raise ValueError(f"path must be (N>=1, 3), got {path.shape}")
    spins = check_spins(spins, len(path))
    if len(path) == 1:  # a path to stand on: its goal is its start (both followers need two)
        path = np.vstack([path, path])
    if cfg.kind == "reference":
        return ReferenceFollower(path, cfg)
    return TrackingFollower(path, cfg, spins)


def omega_limit(robot_max_speed: float, cfg: DriverConfig) -> float:
    """The fastest a follower may run a motor [rad/s]: the motor's limit, or the driver's
    max_ratio x omega0, whichever is lower."""
    return min(robot_max_speed, cfg.max_ratio * cfg.omega0)


class ReferenceFollower:
    """Algorithms 1 and 2 of Tong 2018, as the report gives them."""

    def __init__(self, path: np.ndarray, cfg: DriverConfig) -> None:
        self.path = path
        self.path_xy = [tuple(q) for q in path[:, :2].tolist()]
        self.cfg = cfg
        self.i = 1
        self.advanced = False
        self.gap = math.inf

    def update(self, pos, quat=None) -> tuple[Outcome, str] | None:
        # (quat, the body's orientation, is the tracking driver's: algorithm 1 needs only pos)
        i_before = self.i
        self.i, arrived = next_waypoint(
            self.path_xy, self.i, pos[:2], self.cfg.r_path, self.cfg.r_end
        )
        if arrived:
            return "success", "reached the goal"
        self.advanced = self.i != i_before
        self.gap = math.dist(self.path_xy[self.i], pos[:2])
        return None

    def where(self) -> str:
        return f"{self.gap:.2f} m from waypoint {self.i} of {len(self.path_xy) - 1}"

    def speeds(self, pos, quat, omega_max: float) -> tuple[float, float]:
        theta = heading_error(pos, quat, self.path_xy[self.i])
        return motor_speeds(theta, self.cfg.omega0, self.cfg.gain, omega_max)


class TrackingFollower:
    """Pure pursuit on the path's arc length, stopping to turn on the spot at the plan's spins
    (see the module docstring)."""

    def __init__(self, path: np.ndarray, cfg: DriverConfig, spins: tuple[Spin, ...] = ()) -> None:
        self.path = path
        self.xy = path[:, :2]
        seg = np.diff(self.xy, axis=0)
        self.seg_len = np.linalg.norm(seg, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.total = float(self.cum[-1])
        # The same as plain floats: the projection runs every control period over a window of
        # a few segments, where numpy's call overhead is most of its cost; scalar math with the
        # same operations in the same order gives the same bits (tests/test_driver.py).
        self._xy = [tuple(q) for q in self.xy.tolist()]
        self._seg_len, self._cum = self.seg_len.tolist(), self.cum.tolist()
        self.end, self.end_dir = self.xy[-1], self._direction_into(len(self.xy) - 1)
        self._end, self._end_dir = tuple(self.end.tolist()), tuple(self.end_dir.tolist())
        self.cfg = cfg
        self.s = 0.0
        """Progress: arc length of the robot's nearest point on the path, never decreasing [m]."""
        self.advanced = False
        self.gap = self.total
        self.spins = list(spins)
        """Spins not yet made, in path order: (waypoint index, heading [rad])."""
        self.spinning = False
        """The robot is turning on the spot at self.spins[0]."""
        self.spin_error = 0.0
        """Heading of the spin minus the robot's, in (-pi, pi] [rad] (while spinning)."""
        self.spin_best = math.inf
        """Smallest |spin_error| of this spin so far [rad]: progress for stuck detection."""

    def _direction_into(self, k: int) -> np.ndarray:
        """Unit direction of the last segment of non-zero length that ends at or before
        waypoint k ((1, 0) when there is none)."""
        moving = np.nonzero(self.seg_len[:k] > 1e-9)[0]
        if not len(moving):
            return np.array([1.0, 0.0])
        j = moving[-1]
        return (self.xy[j + 1] - self.xy[j]) / self.seg_len[j]

    def _project(self, p, upto: int) -> float:
        """Arc length of the point of the path nearest p ((x, y) [m]) among the segments from
        the progress to a lookahead and a bit beyond (not the whole path: a path that comes
        back near itself must not pull the progress forward or back), and not past waypoint
        `upto`."""
        seg_len, cum, xy = self._seg_len, self._cum, self._xy
        last = len(seg_len) - 1  # at the path's end the window is its last segment
        k0 = min(max(0, bisect.bisect_right(cum, self.s) - 1), last, upto - 1)
        k1 = bisect.bisect_right(cum, self.s + 2 * self.cfg.lookahead + 0.1)
        k1 = min(max(k1, k0 + 1), len(seg_len), upto)
        px, py = float(p[0]), float(p[1])
        best, k_best, u_best = math.inf, k0, 0.0
        for k in range(k0, k1):
            (ax, ay), (bx, by), length = xy[k], xy[k + 1], seg_len[k]
            dx, dy = bx - ax, by - ay
            u = ((px - ax) * dx + (py - ay) * dy) / max(length * length, 1e-18)
            u = 0.0 if u < 0.0 else 1.0 if u > 1.0 else u
            ex, ey = ax + dx * u - px, ay + dy * u - py
            dist = math.sqrt(ex * ex + ey * ey)
            if dist < best:  # (the first of equals, as argmin)
                best, k_best, u_best = dist, k, u
        return cum[k_best] + u_best * seg_len[k_best]

    def _point_at(self, s: float, upto: int) -> tuple[float, float]:
        """The path's point (x, y) [m] at arc length s [m]; past waypoint `upto` (the end, or
        a spin not yet made), on the straight line on through it."""
        cum, xy = self._cum, self._xy
        if s >= cum[upto]:
            direction = self.end_dir if upto == len(xy) - 1 else self._direction_into(upto)
            (x, y), d = xy[upto], s - cum[upto]
            return x + float(direction[0]) * d, y + float(direction[1]) * d
        k = min(bisect.bisect_right(cum, s) - 1, len(self._seg_len) - 1)
        u = (s - cum[k]) / max(self._seg_len[k], 1e-18)
        (ax, ay), (bx, by) = xy[k], xy[k + 1]
        return ax + (bx - ax) * u, ay + (by - ay) * u

    @property
    def _hold(self) -> int:
        """The waypoint the progress may not pass: the next spin's, else the last."""
        return self.spins[0][0] if self.spins else len(self.xy) - 1

    def update(self, pos, quat=None) -> tuple[Outcome, str] | None:
        """Advance the progress from the body position pos (x, y, z) [m] and, at a spin, its
        orientation quat (xyzw); the outcome when the drive has ended, else None."""
        p = (float(pos[0]), float(pos[1]))
        to_end = (p[0] - self._end[0], p[1] - self._end[1])
        off = math.sqrt(to_end[0] * to_end[0] + to_end[1] * to_end[1])
        if off < self.cfg.r_end and not self.spins:  # the goal, once every spin is made
            return "success", "reached the goal"
        self.advanced = False
        hold = self._hold
        if self.spins and not self.spinning:
            at = float(self.cum[hold])
            self.s = at if hold == 0 or self.s >= at else max(self.s, self._project(p, hold))
            self.spinning = self.s >= at - 1e-9
            if self.spinning:
                self.advanced, self.spin_best = True, math.inf
        if self.spinning:
            assert quat is not None, "a spin needs the body's orientation"  # drive_path gives it
            x, y, z, w = quat  # the heading of the body's forward axis, horizontally
            yaw = math.atan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z))
            self.spin_error = math.remainder(self.spins[0][1] - yaw, 2 * math.pi)
            if abs(self.spin_error) < self.cfg.spin_tolerance:  # made: on with pure pursuit
                self.spins.pop(0)
                self.spinning = False
                ended = self.update(pos, quat)
                self.advanced = True  # (the update from the spin's point may not advance)
                return ended
            if abs(self.spin_error) < self.spin_best - self.cfg.stuck_angle:
                self.spin_best, self.advanced = abs(self.spin_error), True
            self.gap = self.total - self.s
            return None
        if not self.spins:
            self.s = max(self.s, self._project(p, hold))
        self.gap = self.total - self.s
        past = to_end[0] * self._end_dir[0] + to_end[1] * self._end_dir[1]
        if self.s >= self.total and past > self.cfg.r_end:
            return "missed", (
                f"passed the goal {off:.2f} m from it (success is within {self.cfg.r_end:g} m) "
                f"at ({pos[0]:.2f}, {pos[1]:.2f})"
            )
        return None

    def where(self) -> str:
        spin = (
            f", turning on the spot {abs(self.spin_error):.2f} rad from the heading of its spin"
            if self.spinning
            else ""
        )
        return f"{self.s:.2f} m along the {self.total:.2f} m path{spin}"

    def speeds(self, pos, quat, omega_max: float) -> tuple[float, float]:
        cfg = self.cfg
        if self.spinning:  # the sides in opposite directions: left backwards turns left
            w = min(cfg.spin_speed, omega_max)
            return (-w, w) if self.spin_error > 0 else (w, -w)
        target = self._point_at(self.s + cfg.lookahead, self._hold)
        theta = heading_error(pos, quat, target)
        reach = max(math.dist(pos[:2], target), 1e-6)
        # The arc through the target (pure pursuit); a target behind asks for the tightest turn.
        curvature = 2 * math.sin(theta) / reach if abs(theta) < math.pi / 2 else math.inf
        ratio = cfg.turning.ratio_for(curvature, cfg.max_ratio)
        fast = min(cfg.omega0 * ratio, omega_max)
        return (cfg.omega0, fast) if theta > 0 else (fast, cfg.omega0)
