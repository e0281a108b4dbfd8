"""Look-ahead (issue 32, its first part): from the robot's live pose, a handful of short
simulated rollouts of the rest of its plan, and the chance that it goes on for the horizon
without a stop the loop would make or a fall.

Each rollout drops the simulated robot at the live pose (x, y, yaw in the world frame [m],
[rad]) moved by the pose's noise (a draw of position_sd and yaw_sd_deg), and drives it with the
scene's driver along the plan from the path's point nearest the pose on (its turns on the spot
re-indexed), for `horizon` seconds. It fails when the simulation ends it (fell, flipped,
missed) or when, at any frame of its trajectory, the robot loop's own safety checks
(robot/_safety.py check_pose: outside the planning area, off standable ground, too far off
the path) would stop the real robot there. Reaching the goal within the horizon, or still
going at its end, is a rollout that holds.

What it does not model yet: the legs' phase (each rollout starts from the standing pose, its
legs where a reset puts them) and the pose's latency (the pose is taken as now). The world's
robot is the scene's, so a scene naming a fitted robot file looks ahead with the fit.

A pure function of its inputs and seed: rollout k draws from np.random.default_rng((seed, k)).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from roachplan._settings import check_settings, integer, non_negative, positive
from roachplan._settings import setting as s

from ._safety import SafetyConfig, SafetyMap, check_pose

if TYPE_CHECKING:
    from roachplan.scenes import World


@dataclass(frozen=True, kw_only=True)
class LookAheadConfig:
    """How far and how often the simulation looks ahead of the robot."""

    horizon: float = s(3.0, positive("s", 60.0))
    """Simulated time each rollout walks [s]."""
    draws: int = s(8, integer(1, 256))
    """Rollouts per look-ahead."""
    position_sd: float = s(0.01, non_negative("m"))
    """Standard deviation of the pose's position error, each horizontal axis [m]."""
    yaw_sd_deg: float = s(3.0, non_negative("deg"))
    """Standard deviation of the pose's heading error [deg]."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class LookAhead:
    """One look-ahead's rollouts from one pose."""

    start: tuple[float, float, float]
    """The live pose it looked ahead from: x, y [m], yaw [rad], world frame."""
    horizon: float
    """[s]"""
    rollouts: int
    holds: int
    """Rollouts that went on for the horizon (or reached the goal) with no stop or fall."""
    failures: tuple[tuple[float, float, str], ...]
    """Where each failed rollout ended (x, y [m]) and why (a stop reason or an outcome)."""
    wall_time: float
    """Wall time of the look-ahead [s]."""

    @property
    def p_hold(self) -> float:
        """The predicted chance that the robot goes on for the horizon without a stop or a
        fall [-]."""
        return self.holds / self.rollouts

    def to_json(self) -> dict:
        return {
            "start": list(self.start),
            "horizon": self.horizon,
            "rollouts": self.rollouts,
            "holds": self.holds,
            "p_hold": self.p_hold,
            "failures": [list(f) for f in self.failures],
            "wall_time": self.wall_time,
        }


def remaining_path(
    path_xyz: np.ndarray, spins, xy
) -> tuple[np.ndarray, tuple[tuple[int, float], ...]]:
    """The plan from the point of path_xyz ((N, 3) world frame [m]) nearest xy on: that point,
    then the waypoints after it; spins ((waypoint index, heading [rad]) each) re-indexed to it,
    those behind it dropped."""
    path = np.asarray(path_xyz, dtype=float)
    if len(path) < 2:
        return path.copy(), tuple((0, float(h)) for _, h in spins)
    a, b = path[:-1], path[1:]
    d = b - a
    p = np.asarray(xy, dtype=float)[:2]
    length2 = np.maximum(np.einsum("ij,ij->i", d[:, :2], d[:, :2]), 1e-18)
    u = np.clip(np.einsum("ij,ij->i", p - a[:, :2], d[:, :2]) / length2, 0.0, 1.0)
    k = int(np.argmin(np.linalg.norm(a[:, :2] + d[:, :2] * u[:, None] - p, axis=1)))
    nearest = a[k] + d[k] * u[k]
    rest = np.vstack([nearest, path[k + 1 :]])
    # waypoint i > k is row i - k of rest; a spin at waypoint k or before is behind the robot
    kept = tuple((int(i) - k, float(h)) for i, h in spins if i > k)
    return rest, kept


def look_ahead(
    world: World,
    path_xyz: np.ndarray,
    spins,
    pose: tuple[float, float, float],
    cfg: LookAheadConfig,
    *,
    safety: SafetyConfig,
    safety_map: SafetyMap,
    seed: int,
) -> LookAhead:
    """cfg.draws rollouts of the plan (path_xyz, spins) from the live pose for cfg.horizon
    seconds (module docstring), checked by the loop's safety settings on safety_map."""
    from roachplan.experiments import drive

    t0 = time.perf_counter()
    x0, y0, yaw0 = (float(v) for v in pose)
    rest, rest_spins = remaining_path(path_xyz, spins, (x0, y0))
    ahead = world.with_sim(
        world.scene.sim, dataclasses.replace(world.scene.driver, time_limit=cfg.horizon)
    )
    path_xy = np.asarray(path_xyz, dtype=float)[:, :2]
    holds = 0
    failures: list[tuple[float, float, str]] = []
    for k in range(cfg.draws):
        rng = np.random.default_rng((seed, k))
        dx, dy = rng.normal(0.0, cfg.position_sd, 2)
        dyaw = math.radians(float(rng.normal(0.0, cfg.yaw_sd_deg)))
        start = (x0 + float(dx), y0 + float(dy), yaw0 + dyaw)
        stopped: list[tuple[float, float, str]] = []

        def on_frame(f, stopped=stopped) -> None:
            if stopped:
                return
            stop = check_pose(
                safety, safety_map, path_xy, now=0.0, t_receive=0.0, position_world=f.p_world_body
            )
            if stop is not None:
                stopped.append((float(f.p_world_body[0]), float(f.p_world_body[1]), stop.reason))

        driven = drive(ahead, rest, start=start, on_frame=on_frame, spins=rest_spins)
        if stopped:
            failures.append(stopped[0])
        elif driven.outcome in ("success", "timeout"):
            holds += 1
        else:
            _, x, y, _ = driven.trajectory[-1]
            failures.append((float(x), float(y), driven.outcome))
    return LookAhead(
        start=(x0, y0, yaw0),
        horizon=cfg.horizon,
        rollouts=cfg.draws,
        holds=holds,
        failures=tuple(failures),
        wall_time=time.perf_counter() - t0,
    )
