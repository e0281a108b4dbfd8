"""When the robot must stop, decided as values: a pose too old, the robot outside the planning
area or the places it can stand, or too far off its path. Pure functions over a SafetyMap
made once per drive; the loop (robot/_loop.py) calls check_pose every control period."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from roachplan._settings import check_settings, positive
from roachplan._settings import setting as s

if TYPE_CHECKING:
    from roachplan.scenes import World

StopReason = Literal[
    "goal",
    "missed",
    "stuck",
    "timeout",
    "no_pose",
    "pose_stale",
    "outside_area",
    "off_standable",
    "deviation",
    "lookahead",
    "drift",
    "stall",
    "stop",
    "cancel",
    "signal",
    "error",
]
"""Why a drive ended. goal: reached (the only success); missed: passed the goal wide (the
tracking driver's outcome); stuck: no progress for the driver's stuck_time; timeout: not there
within the driver's time_limit; no_pose: no pose at Go; pose_stale: the newest pose older than
max_pose_age; outside_area: the robot's centre outside the planning area by more than
area_margin; off_standable: further than standable_margin from any place the robot can stand;
deviation: further than max_deviation from the path; lookahead: the look-ahead's chance of
going on without a stop or a fall fell under RobotSettings.guard; drift: with the guard on,
further than RobotSettings.guard_drift from the path and, with guard_drift_lead, drifting so
that the deviation stop would come within the lead (held before it), or at the edge of the
ground it can stand on; stall: with the guard on, no progress for RobotSettings.guard_stuck of
the driver's stuck_time (held before the stuck stop); stop / cancel: the user's Stop or
Cancel; signal: SIGINT (Ctrl-C) or SIGTERM; error: an exception in the loop (a link down)."""


@dataclass(frozen=True, kw_only=True)
class SafetyConfig:
    """When the robot is stopped, and how."""

    max_pose_age: float = s(0.2, positive("s", 10.0))
    """A pose older than this stops the robot [s] (the mocap lost it, or the stream died)."""
    area_margin: float = s(0.05, positive("m", 10.0))
    """How far the robot's centre may be outside the planning area [m]."""
    standable_margin: float = s(0.05, positive("m", 10.0))
    """How far the robot's centre may be from the nearest place it can stand (the World's
    standable map, 4 cm cells) [m]: past a bridge's edge, it is falling."""
    max_deviation: float = s(0.15, positive("m", 10.0))
    """How far the robot's centre may be from the path [m] (1.5 body lengths: the tracking
    driver keeps within a few cm on the library's scenes)."""
    stop_hold: float = s(0.5, positive("s", 60.0))
    """After a stop, zero commands go on at the control rate this long [s], so a robot that
    missed one datagram still gets one."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class Stop:
    """A stop, as a value."""

    reason: StopReason
    detail: str
    """The same for people, with the numbers."""


@dataclass(frozen=True, eq=False)
class SafetyMap:
    """Where the robot may be: the planning area, and the distance from each cell of the
    standable map to the nearest standable cell it can reach from the scene's start (a floor
    below a bridge is standable but not reachable: a robot there fell off)."""

    bounds: tuple[tuple[float, float], tuple[float, float]]
    x0: float
    y0: float
    cell: float
    distance: np.ndarray
    """(ny, nx) [m]: 0 on a standable cell."""

    @classmethod
    def from_world(cls, world: World) -> SafetyMap:
        from scipy.ndimage import distance_transform_edt

        regions = world.regions
        assert world.scene.bounds is not None  # build_world sets them
        # (the start's component: a robot on the standable floor between two bridges fell,
        # and was taken for one standing, 0 m from standable ground)
        standable = np.asarray(regions.reachable, dtype=bool)
        if not standable.any():  # (no cell reachable from the start: every standable one)
            standable = np.asarray(regions.standable, dtype=bool)
        if standable.any():
            dist = np.asarray(distance_transform_edt(~standable)) * regions.cell
        else:
            dist = np.full(standable.shape, np.inf)
        return cls(
            bounds=world.scene.bounds,
            x0=regions.x0,
            y0=regions.y0,
            cell=regions.cell,
            distance=dist,
        )

    def off_standable(self, x: float, y: float) -> float:
        """Distance from the map's cell nearest (x, y) [m] to the nearest standable cell it can
        reach [m]: 0 on one (inf outside the map)."""
        i = round((x - self.x0) / self.cell)
        j = round((y - self.y0) / self.cell)
        ny, nx = self.distance.shape
        if not (0 <= i < nx and 0 <= j < ny):
            return math.inf
        return float(self.distance[j, i])


def distance_to_path(xy, path_xy: np.ndarray) -> float:
    """Distance from xy [m] to the polyline path_xy ((N, 2) [m])."""
    return nearest_on_path(xy, path_xy)[1]


def nearest_on_path(xy, path_xy: np.ndarray) -> tuple[np.ndarray, float]:
    """(the point of the polyline path_xy ((N, 2) [m]) nearest xy [m] ((2,) [m]), its distance
    from xy [m])."""
    p = np.asarray(xy, dtype=float)[:2]
    if len(path_xy) < 2:
        q = np.asarray(path_xy[0], dtype=float)[:2]
        return q, float(np.linalg.norm(q - p))
    a, b = path_xy[:-1], path_xy[1:]
    d = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    u = np.clip(np.einsum("ij,ij->i", p - a, d) / length2, 0.0, 1.0)
    near = a + d * u[:, None]
    dist = np.linalg.norm(near - p, axis=1)
    k = int(np.argmin(dist))
    return near[k], float(dist[k])


def check_pose(
    cfg: SafetyConfig,
    safety_map: SafetyMap,
    path_xy: np.ndarray,
    *,
    now: float,
    t_receive: float | None,
    position_world,
) -> Stop | None:
    """Why the robot must stop now [s, monotonic] given its newest pose, received at
    t_receive [s] (None: none yet) at position_world [m]; None when it may go on."""
    if t_receive is None:
        return Stop(reason="no_pose", detail="no pose of the robot has come from the source")
    age = now - t_receive
    if age > cfg.max_pose_age:
        return Stop(
            reason="pose_stale",
            detail=f"the newest pose is {age * 1000:.0f} ms old (max_pose_age "
            f"{cfg.max_pose_age * 1000:.0f} ms): the tracker lost the robot or the stream stopped",
        )
    x, y = float(position_world[0]), float(position_world[1])
    (xa, ya), (xb, yb) = safety_map.bounds
    m = cfg.area_margin
    if not (xa - m <= x <= xb + m and ya - m <= y <= yb + m):
        return Stop(
            reason="outside_area",
            detail=f"the robot at ({x:.3f}, {y:.3f}) is outside the planning area "
            f"x {xa:g}..{xb:g}, y {ya:g}..{yb:g} by more than {m:g} m",
        )
    off = safety_map.off_standable(x, y)
    if off > cfg.standable_margin:
        return Stop(
            reason="off_standable",
            detail=f"the robot at ({x:.3f}, {y:.3f}) is {off:.3f} m from the nearest place it "
            f"can stand (standable_margin {cfg.standable_margin:g} m)",
        )
    dev = distance_to_path((x, y), path_xy)
    if dev > cfg.max_deviation:
        return Stop(
            reason="deviation",
            detail=f"the robot at ({x:.3f}, {y:.3f}) is {dev:.3f} m off its path "
            f"(max_deviation {cfg.max_deviation:g} m)",
        )
    return None
