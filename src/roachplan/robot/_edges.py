"""Drop-offs, as the planner's validity checks see them (feet on ground, no pit under the
body): how far a plan keeps from them (edge_margin), when the guard holds a robot drifting
towards one (at_edge), and where a robot standing at one steps in to before its re-plan
(step_in). All in the world frame: x, y [m], headings [rad] counter-clockwise from +x."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from roachplan.scenes import World

EDGE_STEP = 0.01
"""edge_margin's and step_in's offsets are whole multiples of this [m]."""


def _stands(world: World, states) -> np.ndarray:
    """(N,) bool: the planner's validity of states ((N, 3) x, y [m], yaw [rad])."""
    from roachplan.planning import check_states

    hf, fp, validity = world.heightfield, world.footprint, world.scene.planner.validity
    return check_states(hf, fp, validity, np.asarray(states, dtype=float)).valid


def _sideways(xy, yaw, offsets) -> np.ndarray:
    """(len(offsets), 2, N, 3): the poses xy ((N, 2) [m]) at headings yaw ((N,) [rad]) moved
    each offset [m] to their left (index 0) and right (1), heading kept."""
    normal = np.column_stack([-np.sin(yaw), np.cos(yaw)])  # (N, 2): the heading's left
    return np.stack(
        [
            np.stack([np.column_stack([xy + side * m * normal, yaw]) for side in (1.0, -1.0)])
            for m in offsets
        ]
    )


def _offsets(keep: float) -> np.ndarray:
    """The sideways offsets measured up to `keep` [m]: EDGE_STEP, 2 EDGE_STEP, ... (one at
    least) [m]."""
    return EDGE_STEP * np.arange(1, max(math.floor(keep / EDGE_STEP + 1e-9), 1) + 1)


def _keeps(world: World, xy, yaw, keep: float) -> np.ndarray:
    """(N,) int: how many of the offsets up to `keep` [m] (_offsets) the poses (xy (N, 2) [m],
    yaw (N,) [rad]) can be moved to either side, every smaller one passing too, and still
    stand (all of them, len(_offsets(keep)): the pose keeps `keep`)."""
    moved = _sideways(xy, yaw, _offsets(keep))
    ok = _stands(world, moved.reshape(-1, 3)).reshape(moved.shape[:3]).all(axis=1)
    return np.cumprod(ok, axis=0).sum(axis=0)


def edge_margin(world: World, path_xyz, keep: float, *, skip: float = 0.10) -> float:
    """How far the robot could drift sideways off a path ((N, >=2) world frame [m]) and still
    stand where the planner would let it (its validity checks: feet on ground, no pit under the
    body), up to `keep` [m]: the least over the path's waypoints of the largest offset, to
    either side of its heading there (the direction to the next waypoint) and in EDGE_STEP
    steps, at which the footprint and every smaller offset pass; `keep` where every waypoint
    passes it. The first `skip` [m] of the path are not measured (a plan from a robot the guard
    held at a bridge's edge starts near it; drive_robot measures a plan from step_in's pose
    before the walk to it is put in front). A
    path along a bridge's inner edge, or cutting its corner, keeps 0-3 cm: a robot drifting
    the 4 cm the guard's edge hold once allowed fell off."""
    xy = np.asarray(path_xyz, dtype=float)[:, :2]
    if len(xy) >= 2:  # (a spin repeats its waypoint: it has no heading of its own)
        xy = xy[np.concatenate([[True], np.linalg.norm(np.diff(xy, axis=0), axis=1) > 1e-9])]
    if len(xy) < 2 or keep <= 0:
        return float(keep)
    step = np.diff(xy, axis=0)
    yaw = np.arctan2(step[:, 1], step[:, 0])
    yaw = np.append(yaw, yaw[-1])
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(step, axis=1))])
    xy, yaw = xy[along >= skip], yaw[along >= skip]
    if not len(xy):
        return float(keep)
    n = len(_offsets(keep))
    least = int(_keeps(world, xy, yaw, keep).min())
    return float(keep) if least == n else float(EDGE_STEP * least)


EDGE_OFF = 0.02
"""The guard's edge hold: a robot further off its path than this [m], whose footprint EDGE_ROOM
further from the path would not stand, is held (at_edge). Not nearer: a path may run within
EDGE_ROOM of an edge where none keeps more (edge_margin 0-1 cm), and a robot on it is not held;
at 3 cm, robots on paths that keep 2 cm fell 9 times in 48 in the scripted drives
(docs/robot.md)."""
EDGE_ROOM = 0.01
"""How much room the guard's edge hold leaves a drifting robot before the edge [m]: the
motion capture's noise and the stop's slide (a robot held drifts on 0.7 cm, a median; the
robot's own footprint is checked, so this is all the margin there is)."""


def at_edge(world: World, pose, toward, *, room: float = EDGE_ROOM) -> bool:
    """Whether the robot at pose (x, y [m], yaw [rad]) would no longer stand, its footprint
    moved `room` [m] in the direction `toward` ((dx, dy), any length: from the nearest point
    of its path to it) with its heading kept: the edge of the ground it can stand on (the
    planner's validity checks, feet on ground and no pit under the body: a drop-off, or
    ground too steep or rough for it) lies within `room` on the side it drifted to. The guard's
    edge hold (watch_ahead: with EDGE_OFF).

    Scripted drives in PyBullet (a robot walking a straight path along a bridge that keeps 2
    or 4 cm from its edge, heading 0-12 deg towards it and veering to it, 96 drives a rule;
    benchmarks/bench_edges.py): with the drift hold only, 27 fell; held where this says (and
    2 cm off), none fell, and 9 of the 36 held would not have fallen. Held where the 4 cm
    safety map's edge is (the hold before it), 22 fell."""
    dx, dy = float(toward[0]), float(toward[1])
    norm = math.hypot(dx, dy)
    if norm <= 0.0:
        return False
    x, y, yaw = (float(v) for v in pose)
    moved = [[x + room * dx / norm, y + room * dy / norm, yaw]]
    return not bool(_stands(world, moved)[0])


def stands_on(world: World, poses, ground: float) -> np.ndarray:
    """(N,) bool: the poses ((N, 3) x, y [m], yaw [rad]) the planner takes, inside the planning
    area, on the surface at height `ground` [m] (their support plane within the planner's
    body_band of it: not the floor below a bridge's edge; nan: any surface). plan_start's
    and step_in's candidates."""
    from roachplan.planning import check_states

    hf, fp, validity = world.heightfield, world.footprint, world.scene.planner.validity
    poses = np.asarray(poses, dtype=float)
    checked = check_states(hf, fp, validity, poses)
    ok = checked.valid.copy()
    if math.isfinite(ground):
        ok &= np.abs(checked.z_surface - ground) <= validity.body_band
    (xa, ya), (xb, yb) = world.bounds
    ok &= (poses[:, 0] >= xa) & (poses[:, 0] <= xb) & (poses[:, 1] >= ya) & (poses[:, 1] <= yb)
    return ok


STEP_REACH = 0.15
"""How far step_in may walk a robot from where it stands [m] (a body length and a half)."""
_STEP_DIRECTIONS = 36
"""Directions step_in tries on each ring (every 10 deg)."""
_STEP_LINE = (0.25, 0.5, 0.75)
"""Points along the line to a step_in point checked standing too (fractions of its length)."""


def step_in(
    world: World, here: tuple[float, float, float], keep: float, *, reach: float = STEP_REACH
) -> tuple[float, float, float] | None:
    """Where a robot standing at `here` (x, y [m], yaw [rad]) within `keep` [m] of an edge
    (its footprint moved `keep` or less to one side of its heading would not stand) walks
    before it is re-planned: the pose (x, y, heading [rad]) on rings every EDGE_STEP out to
    `reach` whose footprint, heading from here to it, keeps `keep` either side and whose
    straight line from here stands, the least turn from here's heading first, then the
    nearest. None where here keeps `keep` already, or where no such pose lies within reach
    (the re-plan is then made from here, as before).

    The re-plan from a robot held at a bridge's edge started there, heading along the edge or
    towards it: in scripted drives in PyBullet (24 robots held at the four edges of the double
    bridge, heading 5-15 deg towards them, the motors' mismatch left after trimming 0.03 or
    0.09 towards them), 5 fell, each held again by the edge hold; re-planned from the pose this
    gives (a turn of the least there is, a line of at most 15 cm), none fell and 3 were held
    again. Stepping to the nearest such pose instead, turning to face it on the spot, the turn
    took robots the 2 cm the edge hold allows (8 of 24 held again), and a plan with arcs from
    a pose facing the edge was mostly not found."""
    x, y, yaw = (float(v) for v in here)
    if keep <= 0:
        return None
    n = len(_offsets(keep))
    if int(_keeps(world, np.array([[x, y]]), np.array([yaw]), keep)[0]) == n:
        return None
    rings = EDGE_STEP * np.arange(1, math.floor(reach / EDGE_STEP + 1e-9) + 1)
    angles = np.linspace(-math.pi, math.pi, _STEP_DIRECTIONS, endpoint=False)
    r, a = (v.ravel() for v in np.meshgrid(rings, angles, indexing="ij"))
    xy = np.column_stack([x + r * np.cos(a), y + r * np.sin(a)])
    ground = float(world.heightfield.sample(np.array([x, y])))
    ok = stands_on(world, np.column_stack([xy, a]), ground)  # (on its own surface)
    ok &= _keeps(world, xy, a, keep) == n
    for f in _STEP_LINE:
        ok &= _stands(world, np.column_stack([x + f * r * np.cos(a), y + f * r * np.sin(a), a]))
    if not ok.any():
        return None
    turn = np.abs((a - yaw + math.pi) % (2 * math.pi) - math.pi)
    # (the least turn; of equal turns, the nearest ring: lexsort's last key is its first)
    k = int(np.lexsort((r, np.round(turn, 9), ~ok))[0])
    return float(xy[k, 0]), float(xy[k, 1]), float(a[k])
