"""Start, goal and planning area for a terrain nobody placed them on (a capture, a mesh, a
model).

A model on a ground plane is something to cross: the planning area reaches past it onto the
ground on every side, and start and goal stand on the ground at either end of its long axis,
so a plan crosses it where the robot can, or goes round it. Otherwise (a capture, whose floor
is the ground; a model too large to go round) they go inside the largest connected region
where the robot can stand, as far apart as that region allows up to a cap (a trial's drive
time grows with the distance). Either way each is valid and a plan joins them (a region
4-connected at 4 cm can still hold a neck the robot cannot turn through).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import cast

import numpy as np
from scipy import ndimage

from roachplan.planning import VALID, PlanningError, check_states, plan_path, standable_map

MAX_AUTO_DISTANCE = 4.0
"""Longest start-goal distance picked automatically [m]: on a room's floor the far wall is
reached; on a 300 m lidar survey the trial still takes seconds, not hours."""
MIN_AUTO_DISTANCE = 1.0
"""Start and goal are at least this far apart where the region is that large [m]."""
MAX_AUTO_EXTENT = 10.0
"""Largest side of the planning area chosen automatically [m] (the height field is 1 cm)."""
GROUND_APRON = 0.5
"""On a terrain with a ground plane, the planning area reaches this far past the model on
every side [m]: room to start and stop on the ground and to go round it."""
GROUND_CLEARANCE = 0.25
"""Start and goal stand on the ground this far beyond the model's ends [m] (the robot's feet
and legs reach 7 cm from its centre)."""


@dataclass(frozen=True, kw_only=True)
class AutoPoses:
    start: tuple[float, float, float]
    """x [m], y [m], yaw [rad]."""
    goal: tuple[float, float, float]
    distance: float
    """Straight-line distance start-goal [m]."""
    region_area: float
    """Area of the region they are in [m^2]."""
    note: str
    """How they were chosen, for the user."""


def auto_bounds(mesh_bounds: np.ndarray, *, ground: bool):
    """((xmin, ymin), (xmax, ymax)) for the robot's centre over a terrain whose mesh has these
    (2, 3) bounds [m]: on a ground plane (ground), GROUND_APRON past them on every side; else
    (a capture) the terrain's own (a place at its edge fails the feet's check by itself); at
    most MAX_AUTO_EXTENT a side around the centre; and a note when the terrain was larger."""
    apron = GROUND_APRON if ground else 0.0
    lo = np.asarray(mesh_bounds)[0][:2] - apron
    hi = np.asarray(mesh_bounds)[1][:2] + apron
    note = ""
    centre = (lo + hi) / 2
    if np.any(hi - lo > MAX_AUTO_EXTENT):
        half = np.minimum((hi - lo) / 2, MAX_AUTO_EXTENT / 2)
        note = (
            f"the terrain is {(hi - lo)[0]:.0f} m x {(hi - lo)[1]:.0f} m: planning within "
            f"{2 * half[0]:.0f} m x {2 * half[1]:.0f} m at its centre (set bounds, or crop)"
        )
        lo, hi = centre - half, centre + half
    return ((float(lo[0]), float(lo[1])), (float(hi[0]), float(hi[1]))), note


def pick_start_goal(world, *, seed: int = 0, tries: int = 4) -> AutoPoses:
    """Start and goal on the world's terrain (see the module docstring); PlanningError saying
    why when there is nowhere to stand or no two places a plan joins."""
    across = across_the_model(world, seed=seed)
    if across is not None:
        return across
    sc, hf, fp = world.scene, world.heightfield, world.footprint
    vcfg = sc.planner.validity
    bounds = sc.bounds
    (xa, ya), (xb, yb) = bounds
    sm = standable_map(hf, fp, vcfg, bounds, ((xa + xb) / 2, (ya + yb) / 2))
    region = _largest_region(sm.standable)
    area = float(region.sum()) * sm.cell**2
    region = _inside(region)
    cells = np.argwhere(region)  # (K, 2) rows j, i
    centroid = cells.mean(axis=0)
    first = tuple(cells[np.argmin(np.sum((cells - centroid) ** 2, axis=1))])
    a = _farthest(region, first)[0]
    _, dist = _farthest(region, a)
    cap = MAX_AUTO_DISTANCE / sm.cell
    xy = lambda c: np.array([sm.x0 + c[1] * sm.cell, sm.y0 + c[0] * sm.cell])  # noqa: E731
    pa = xy(a)
    reach = np.where(np.isfinite(dist), dist, -1.0)
    failures = []
    for attempt in range(tries):
        limit = cap * (0.7**attempt)
        ok = (reach >= 0) & (reach <= limit)
        centres = np.column_stack(
            [sm.x0 + np.nonzero(ok)[1] * sm.cell, sm.y0 + np.nonzero(ok)[0] * sm.cell]
        )
        if len(centres) < 2:
            break
        pb = centres[np.argmax(np.linalg.norm(centres - pa, axis=1))]
        heading = float(np.arctan2(pb[1] - pa[1], pb[0] - pa[0]))
        start = _valid_pose(world, pa, heading)
        goal = _valid_pose(world, pb, heading)
        if start is None or goal is None:
            failures.append("no valid heading at a picked place")
            continue
        planner = _quick(sc.planner)
        try:
            result = plan_path(hf, fp, start, goal, bounds=bounds, cfg=planner, seed=seed)
        except PlanningError as exc:
            failures.append(str(exc))
            continue
        if result.found:
            d = float(np.linalg.norm(pb - pa))
            note = (
                f"start and goal picked automatically {d:.2f} m apart in the largest "
                f"region the robot can stand in ({area:.1f} m^2)"
            )
            if d < MIN_AUTO_DISTANCE:
                note += f"; it allows no more than {d:.2f} m"
            return AutoPoses(start=start, goal=goal, distance=d, region_area=area, note=note)
        failures.append(_why_not(result, float(np.linalg.norm(pb - pa))))
    distinct = list(dict.fromkeys(failures))  # the same reason twice is said once
    raise PlanningError(
        f"could not pick a start and goal the planner joins in the largest standable region "
        f"({area:.2f} m^2): {'; '.join(distinct[-2:]) or 'the region is a single place'}; "
        f"give start and goal"
    )


def _largest_region(standable: np.ndarray) -> np.ndarray:
    """(ny, nx) bool: the largest 4-connected region of standable ((ny, nx) bool);
    PlanningError when there is none."""
    labels, n = cast("tuple[np.ndarray, int]", ndimage.label(standable))
    if n == 0:
        raise PlanningError(
            "the robot can stand nowhere on this terrain (no place is flat, wide and clear "
            "enough for its six feet): check the ground found, or give start and goal"
        )
    sizes = ndimage.sum(np.ones_like(labels), labels, index=np.arange(1, n + 1))
    return labels == (1 + int(np.argmax(sizes)))


def _inside(region: np.ndarray) -> np.ndarray:
    """The region ((ny, nx) bool) away from its edge where it is wide enough (up to 3 cells,
    12 cm, keeping at least a quarter of it): a pose on the rim of a noisy capture is valid by
    a hair, and one beside a chair leg is a collision waiting for the first step."""
    area = region.sum()
    for rounds in (3, 2, 1):
        inner = ndimage.binary_erosion(region, iterations=rounds)
        labels, m = cast("tuple[np.ndarray, int]", ndimage.label(inner))
        if m:
            sizes = ndimage.sum(np.ones_like(labels), labels, np.arange(1, m + 1))
            inner = labels == (1 + int(np.argmax(sizes)))
            if inner.sum() >= 0.25 * area:
                return inner
    return region


def _why_not(result, distance: float) -> str:
    """The planner's own reason for not joining two places `distance` [m] apart."""
    return f"{distance:.2f} m apart: {result.message}"


def across_the_model(world, *, seed: int = 0) -> AutoPoses | None:
    """Start and goal on the ground at either end of the model's long axis (the longer side
    of the smallest rectangle round its footprint), GROUND_CLEARANCE past it, facing along the
    axis, when the scene has a ground plane, the model fits in the planning area, the robot
    can stand there (moved up to 20 cm further out, or aside, if not) and a plan joins them;
    else None."""
    import trimesh

    sc, mesh = world.scene, world.mesh
    if sc.ground is None or len(mesh.faces) == 0:
        return None
    xy = np.unique(np.asarray(mesh.vertices)[:, :2].round(6), axis=0)
    (xa, ya), (xb, yb) = sc.bounds
    if xy[:, 0].min() < xa or xy[:, 0].max() > xb or xy[:, 1].min() < ya or xy[:, 1].max() > yb:
        return None  # larger than the area planned over: as for any terrain
    try:
        transform, extents = trimesh.bounds.oriented_bounds_2D(xy)
    except Exception:  # a footprint with no area (a model that is a line): as any terrain
        return None
    world_from_box = np.linalg.inv(transform)  # (3, 3) homogeneous 2D: box frame -> world
    long = int(np.argmax(extents))
    axis = world_from_box[:2, long]
    if axis[np.argmax(np.abs(axis))] < 0:  # start at the -x (or -y) end, whatever the fit's sign
        axis = -axis
    centre = world_from_box[:2, 2]
    heading = float(np.arctan2(axis[1], axis[0]))
    half = extents[long] / 2 + GROUND_CLEARANCE
    side = np.array([-axis[1], axis[0]])
    ends = []
    for sign in (-1.0, 1.0):
        pose = None
        for out in np.arange(0.0, 0.201, 0.02):  # further out first, then aside
            for aside in (0.0, 0.05, -0.05, 0.1, -0.1, 0.2, -0.2):
                p = centre + sign * (half + out) * axis + aside * side
                if xa <= p[0] <= xb and ya <= p[1] <= yb:
                    pose = _valid_pose(world, p, heading, exact=True)
                if pose is not None:
                    break
            if pose is not None:
                break
        if pose is None:
            return None
        ends.append(pose)
    start, goal = ends
    result = plan_path(
        world.heightfield,
        world.footprint,
        start,
        goal,
        bounds=sc.bounds,
        cfg=_quick(sc.planner),
        seed=seed,
    )
    if not result.found:
        return None
    d = float(np.hypot(goal[0] - start[0], goal[1] - start[1]))
    note = (
        f"start and goal picked automatically on the ground at either end of the model "
        f"({extents[long]:.2f} m long), {d:.2f} m apart"
    )
    return AutoPoses(start=start, goal=goal, distance=d, region_area=float("nan"), note=note)


def _quick(cfg):
    """The scene's planner with a short budget: the check only asks whether a path exists."""
    import dataclasses

    return dataclasses.replace(cfg, time_limit=min(cfg.time_limit, 5.0))


def _valid_pose(
    world, xy: np.ndarray, heading: float, exact: bool = False
) -> tuple[float, float, float] | None:
    """(x, y, yaw) at xy with the yaw nearest heading (in 16 steps; exact: heading only) where
    the robot stands."""
    sc = world.scene
    # Checked as a scene file will hold it (x, y to 0.1 mm, yaw to 0.001 deg): on a rough
    # capture 0.1 mm can cross a height-field cell and make a checked pose invalid.
    # Rounded inward at the planning area's edge: a cell centre on the edge, rounded out by
    # 0.05 mm, was refused by the planner as outside the planning area.
    (xa, ya), (xb, yb) = sc.bounds
    x = min(max(round(float(xy[0]), 4), math.ceil(xa * 1e4) / 1e4), math.floor(xb * 1e4) / 1e4)
    y = min(max(round(float(xy[1]), 4), math.ceil(ya * 1e4) / 1e4), math.floor(yb * 1e4) / 1e4)
    x, y = x + 0.0, y + 0.0  # not -0.0
    steps = [0] if exact else [0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5, 6, -6, 7, -7, 8]
    yaws = heading + np.array(steps) * np.pi / 8
    yaws = np.radians(np.round(np.degrees(np.arctan2(np.sin(yaws), np.cos(yaws))), 3))
    states = np.column_stack([np.full(len(yaws), x), np.full(len(yaws), y), yaws])
    code = check_states(world.heightfield, world.footprint, sc.planner.validity, states).code
    ok = np.flatnonzero(code == VALID)
    if not len(ok):
        return None
    return (x, y, float(yaws[ok[0]]) + 0.0)


def _farthest(mask: np.ndarray, source: tuple[int, int]) -> tuple[tuple[int, int], np.ndarray]:
    """Breadth-first (4-connected) distances [cells] within mask ((ny, nx) bool) from source
    (j, i): (the farthest cell, (ny, nx) distances, inf outside the source's component)."""
    dist = np.full(mask.shape, np.inf)
    dist[source] = 0.0
    queue = deque([source])
    far = source
    ny, nx = mask.shape
    while queue:
        j, i = queue.popleft()
        d = dist[j, i] + 1
        for dj, di in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            a, b = j + dj, i + di
            if 0 <= a < ny and 0 <= b < nx and mask[a, b] and dist[a, b] == np.inf:
                dist[a, b] = d
                queue.append((a, b))
                far = (a, b)
    return far, dist
