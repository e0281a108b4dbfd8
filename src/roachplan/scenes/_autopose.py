"""Start, goal and planning area for a terrain nobody placed them on (a capture, a mesh, a
model).

A model on a ground plane is something to cross: the planning area reaches past it onto the
ground on every side, and start and goal stand on the ground at either end of its long axis,
so a plan crosses it where the robot can, or goes round it. Otherwise (a capture, whose floor
is the ground; a model too large to go round) they go inside the largest region where the
robot can stand and move about (its places and headings joined by steps and turns, on the
4 cm standable map), as far apart as that region allows up to a cap (a trial's drive time
grows with the distance): at the ends of its longest walk, then, as long as a plan does not
join them, at the ends of shorter stretches of it, within a few seconds' planning in all.
Either way each is valid and a plan joins them.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import cast

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import ConvexHull, QhullError

from roachplan.planning import VALID, PlanningError, check_states, plan_path, standable_map

MAX_AUTO_DISTANCE = 4.0
"""Longest start-goal distance picked automatically [m]: on a room's floor the far wall is
reached; on a 300 m lidar survey the trial still takes seconds, not hours."""
MIN_AUTO_DISTANCE = 1.0
"""Start and goal are at least this far apart where the region is that large [m]."""
MAX_AUTO_EXTENT = 10.0
"""Largest side of the planning area chosen automatically [m] (the height field is 1 cm)."""
PICK_BUDGET = 8.0
"""Planning time a pick spends trying pairs, all its tries together [s]."""
CORE_EXTENT = 0.7
"""Start and goal go as far inside the region's edge (and away from places the robot stands at
some headings only) as leaves two places this fraction as far apart as the region's own two
farthest apart [-]."""
PICK_MILESTONES = 200
"""A roadmap planner's (PRM's) milestones in one try of a pair [-]: the try's result then
does not hang on the machine's speed (its time limit is a safety net)."""
CORRIDOR_SLACK = 1.3
"""A try's planner samples round the walks between the pair at most this many times the
shortest [-]..."""
CORRIDOR_CELLS = 8
"""...plus this many cells (32 cm) [-]."""
_ROADMAPS = ("prm", "prmstar")
"""Planners whose iteration budget counts milestones (planning/_ompl.py grows their roadmap
in fixed batches)."""
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
    yaw_valid: np.ndarray | None = None
    """The standable map's checks over the scene's bounds (StandableMap.yaw_valid; None: not
    made), for World.regions to reuse rather than make again."""


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


def pick_start_goal(world, *, seed: int = 0, budget: float = PICK_BUDGET) -> AutoPoses:
    """Start and goal on the world's terrain (see the module docstring); PlanningError saying
    why when there is nowhere to stand or no two places a plan joins, and how far apart two
    places of the region are at most. budget: planning time of all the tries together [s]."""
    across = across_the_model(world, seed=seed)
    if across is not None:
        return across
    sc, hf, fp = world.scene, world.heightfield, world.footprint
    bounds = sc.bounds
    (xa, ya), (xb, yb) = bounds
    sm = standable_map(hf, fp, sc.planner.validity, bounds, ((xa + xb) / 2, (ya + yb) / 2))
    region = _largest_region(sm.yaw_valid, along_heading=sc.planner.turning_radius is not None)
    area = float(region.sum()) * sm.cell**2
    walks = _Geodesic(region)
    cap = MAX_AUTO_DISTANCE / sm.cell
    core = _core(region, sm.yaw_valid, cap)
    a, b, _ = _farthest_pair(core, cap)
    spine = _Geodesic(core).walk(a, b)
    xy = lambda c: np.array([sm.x0, sm.y0]) + np.asarray(c)[::-1] * sm.cell  # noqa: E731
    extent = _farthest_pair(region, np.inf)[2] * sm.cell  # what could be done at most [m]
    planner = _quick(sc.planner)
    failures: list[tuple[float, str]] = []
    deadline = time.perf_counter() + budget
    for ca, cb in _candidates(spine, cap):
        remaining = deadline - time.perf_counter()
        if remaining <= 0.0:
            break
        pa, pb = xy(ca), xy(cb)
        d = float(np.linalg.norm(pb - pa))
        heading = float(np.arctan2(pb[1] - pa[1], pb[0] - pa[0]))
        start, goal = _valid_pose(world, pa, heading), _valid_pose(world, pb, heading)
        if start is None or goal is None:
            failures.append((d, "no valid heading at a picked place"))
            continue
        # A try may spend what is left, but only half of it while a shorter pair could follow.
        cfg = dataclasses.replace(
            planner,
            time_limit=min(planner.time_limit, max(remaining / 2, min(remaining, 1.0))),
            max_iterations=(
                min(planner.max_iterations, PICK_MILESTONES)
                if planner.name in _ROADMAPS
                else planner.max_iterations
            ),
        )
        # The planner samples round the walk between them (a path it finds there is a path
        # of the scene's plan; over a whole room its roadmap takes many times longer).
        regions = dataclasses.replace(sm, reachable=walks.corridor(ca, cb))
        try:
            result = plan_path(
                hf, fp, start, goal, bounds=bounds, cfg=cfg, seed=seed, regions=regions
            )
        except PlanningError as exc:
            failures.append((d, str(exc)))
            continue
        if result.found:
            note = (
                f"start and goal picked automatically {d:.2f} m apart in the largest "
                f"region the robot can stand and move in ({area:.1f} m^2)"
            )
            if failures:
                note += f"; the planner joined no pair further apart ({_said(failures)})"
            elif d < MIN_AUTO_DISTANCE:
                note += f"; two places in it are at most {extent:.2f} m apart"
            return AutoPoses(
                start=start,
                goal=goal,
                distance=d,
                region_area=area,
                note=note,
                yaw_valid=sm.yaw_valid,
            )
        failures.append((d, result.message))
    why = _said(failures) if failures else "the region is a single place"
    if failures and planner.name in _ROADMAPS:
        why += f" (each try at most {PICK_MILESTONES} milestones; {budget:g} s for all)"
    elif failures:
        why += f" ({budget:g} s for all the tries)"
    raise PlanningError(
        f"could not pick a start and goal the planner joins in the largest region the robot "
        f"can stand and move in ({area:.2f} m^2; two places in it at most {extent:.2f} m "
        f"apart): {why}; give start and goal"
    )


def _said(failures: list[tuple[float, str]]) -> str:
    """The planner's reasons for not joining pairs ((distance [m], reason) each), each reason
    once, after the distances it was given for."""
    by_reason: dict[str, list[float]] = {}
    for d, why in failures:
        by_reason.setdefault(why, []).append(d)
    return "; ".join(
        f"{', '.join(f'{d:.2f}' for d in ds)} m apart: {why}" for why, ds in by_reason.items()
    )


def _largest_region(yaw_valid: np.ndarray, *, along_heading: bool) -> np.ndarray:
    """(ny, nx) bool: the cells of the largest region the robot can stand *and* move about in,
    from yaw_valid ((ny, nx, n_yaw) bool: valid at a cell's centre at yaw k * 2 pi / n_yaw).
    Two valid (cell, yaw) are joined by a step: the same yaw in the next cell along that
    heading, forward or back (along_heading: a drivable plan's robot walks where it faces), or
    in any 4-neighbouring cell (a raw plan's states move any way); or by a turn on the spot:
    neighbouring yaws in one cell, the last next to the first. Cells where the robot stands at
    some yaw, 4-connected, can still be several such regions (a neck it cannot turn in, a
    strip it stands across but cannot walk along). PlanningError when it stands nowhere."""
    if not yaw_valid.any():
        raise PlanningError(
            "the robot can stand nowhere on this terrain (no place is flat, wide and clear "
            "enough for its six feet): check the ground found, or give start and goal"
        )
    ny, nx, n_yaw = yaw_valid.shape
    j, i, k = np.nonzero(yaw_valid)
    node = np.full(yaw_valid.shape, -1)
    node[j, i, k] = np.arange(len(j))
    rows, cols = [], []
    for yaw in range(n_yaw):
        valid, here = yaw_valid[..., yaw], node[..., yaw]
        if along_heading:
            angle = yaw * 2 * np.pi / n_yaw
            step = (round(math.sin(angle)), round(math.cos(angle)))  # (dj, di)
            steps = [step if step > (0, 0) else (-step[0], -step[1])]  # forward or back alike
        else:
            steps = [(0, 1), (1, 0)]
        for dj, di in steps:
            a, b = _pairs_of_cells(dj, di, (ny, nx))
            ok = valid[a] & valid[b]
            rows.append(here[a][ok])
            cols.append(here[b][ok])
        turn = valid & yaw_valid[..., (yaw + 1) % n_yaw]
        rows.append(here[turn])
        cols.append(node[..., (yaw + 1) % n_yaw][turn])
    edges = (np.concatenate(rows), np.concatenate(cols))
    graph = coo_matrix((np.ones(len(edges[0])), edges), shape=(len(j), len(j)))
    _, component = connected_components(graph, directed=False)
    # A region's size: the cells where it holds at least one heading (each (region, cell)
    # once, by one integer key: np.unique over rows sorts several times slower).
    held = np.unique(component.astype(np.int64) * (ny * nx) + j * nx + i) // (ny * nx)
    largest = component == int(np.argmax(np.bincount(held)))
    region = np.zeros((ny, nx), dtype=bool)
    region[j[largest], i[largest]] = True
    return region


def _pairs_of_cells(dj: int, di: int, shape: tuple[int, int]) -> tuple[tuple, tuple]:
    """Index expressions (a, b) into a (ny, nx) grid: a selects the cells that have a
    neighbour at (dj, di) (dj >= 0), b those neighbours, in the same order."""
    ny, nx = shape
    a = (slice(0, ny - dj), slice(max(0, -di), nx - max(0, di)))
    b = (slice(dj, ny), slice(max(0, di), nx - max(0, -di)))
    return a, b


def _core(region: np.ndarray, yaw_valid: np.ndarray, cap: float) -> np.ndarray:
    """Where in the region ((ny, nx) bool) to put start and goal: as far inside its edge as
    3 cells (12 cm), and at each depth where the robot stands at every tried heading
    (yaw_valid: (ny, nx, n_yaw) bool) rather than at some, as still holds two places
    CORE_EXTENT as far apart as the region's own two farthest apart (up to cap [cells]). A
    pose on the rim of a noisy capture is valid by a hair, one beside a chair leg is a
    collision waiting for the first step, and a capture's far floor (noise spikes, dropouts)
    holds some headings only and a roadmap grows slowly there; but a strip of floor in front
    of the desks is only a few cells wide."""
    clean = region & yaw_valid.all(axis=-1)
    options = []
    for rounds in (3, 2, 1, 0):
        for mask in (clean, region):
            part = _largest_part(
                ndimage.binary_erosion(mask, iterations=rounds) if rounds else mask
            )
            if part.any():
                options.append((part, _farthest_pair(part, cap)[2]))
    keep = CORE_EXTENT * max(span for _, span in options)
    return next(part for part, span in options if span >= keep)


def _largest_part(mask: np.ndarray) -> np.ndarray:
    """(ny, nx) bool: the largest 8-connected part of mask ((ny, nx) bool; empty: itself)."""
    labels, m = cast("tuple[np.ndarray, int]", ndimage.label(mask, np.ones((3, 3))))
    if not m:
        return mask
    return labels == 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))


def _farthest_pair(mask: np.ndarray, cap: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The two cells ((2,) j, i each) of mask ((ny, nx) bool, not empty) farthest apart in a
    straight line, at most cap [cells] (on a room's floor, opposite corners or the cap; along
    a strip, its ends), the pair whose straight line is the more in the mask among those
    within a cell of that; and their distance [cells]."""
    cells = np.argwhere(mask)
    best, best_key = (0, 0), (-1, -1.0)
    for a in _outermost(cells):
        straight = np.linalg.norm(cells - cells[a], axis=1)
        b = int(np.argmax(np.where(straight <= cap, straight, -1.0)))
        key = (round(float(straight[b])), _in_sight(mask, cells[a], cells[b]))
        if key > best_key:
            best, best_key = (a, b), key
    a, b = cells[best[0]], cells[best[1]]
    return a, b, float(np.linalg.norm(b - a))


def _in_sight(mask: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """The fraction of the straight line from cell a to cell b ((2,) j, i) in mask."""
    n = int(np.ceil(np.hypot(*(b - a)))) + 1
    on = np.rint(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)).astype(int)
    return float(mask[on[:, 0], on[:, 1]].mean())


def _outermost(cells: np.ndarray) -> np.ndarray:
    """Indices of the cells ((K, 2) j, i) on their convex hull (where the two farthest apart
    are), or of the outermost along 16 directions when the hull is flat (a one-cell strip)."""
    try:
        return np.sort(ConvexHull(cells).vertices)
    except QhullError:
        angles = np.arange(16) * np.pi / 8
        return np.unique(np.argmax(cells @ np.stack([np.sin(angles), np.cos(angles)]), axis=0))


@dataclass(frozen=True, eq=False)
class _Spine:
    """A walk through a region between two places: cells[path] from one to the other, each
    step to an 8-neighbour."""

    cells: np.ndarray
    """(K, 2) the region's cells, j, i."""
    path: np.ndarray
    """(L,) indices into cells, from one end to the other."""
    length: np.ndarray
    """(L,) distance walked along the path from its first cell [cells]."""


class _Geodesic:
    """Distances walked within a mask ((ny, nx) bool, 8-connected) [cells] (scipy's Dijkstra
    over the grid's graph)."""

    def __init__(self, mask: np.ndarray) -> None:
        self.mask = mask
        self.cells = np.argwhere(mask)  # (K, 2) j, i
        self.index = np.full(mask.shape, -1)
        self.index[mask] = np.arange(len(self.cells))
        ny, nx = mask.shape
        rows, cols, weights = [], [], []
        for dj, di in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a, b = _pairs_of_cells(dj, di, (ny, nx))
            ok = mask[a] & mask[b]
            rows.append(self.index[a][ok])
            cols.append(self.index[b][ok])
            weights.append(np.full(int(ok.sum()), math.hypot(dj, di)))
        k = len(self.cells)
        edges = (np.concatenate(rows), np.concatenate(cols))
        self.graph = coo_matrix((np.concatenate(weights), edges), shape=(k, k)).tocsr()

    def walk(self, a: np.ndarray, b: np.ndarray) -> _Spine:
        """The shortest walk from cell a to cell b ((2,) j, i, both in one part of the mask)."""
        ka, kb = int(self.index[tuple(a)]), int(self.index[tuple(b)])
        walked, previous = dijkstra(
            self.graph, directed=False, indices=ka, return_predecessors=True
        )
        path = [kb]
        while path[-1] != ka:
            path.append(int(previous[path[-1]]))
        path = np.array(path[::-1])
        return _Spine(cells=self.cells, path=path, length=walked[path])

    def corridor(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """(ny, nx) bool: the cells of the mask on a walk from cell a to cell b ((2,) j, i,
        both in the mask) at most CORRIDOR_SLACK times the shortest, plus CORRIDOR_WIDTH."""
        ka, kb = self.index[tuple(a)], self.index[tuple(b)]
        walked = dijkstra(self.graph, directed=False, indices=[ka, kb])
        keep = walked.sum(axis=0) <= CORRIDOR_SLACK * walked[0, kb] + CORRIDOR_CELLS
        out = np.zeros_like(self.mask)
        out[tuple(self.cells[keep].T)] = True
        return out


def _candidates(spine: _Spine, cap: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pairs of cells ((2,) j, i each) to try, longest first, at most cap [cells] apart: the
    spine's ends, then stretches of it 0.6, 0.35 and 0.2 as long (each try that fails halves
    the distance, about), at its middle and at either end (the planner may fail in one part
    of the region and not in another)."""
    total = float(spine.length[-1])
    pairs: dict[tuple[int, int], float] = {}
    for fraction in (1.0, 0.6, 0.35, 0.2):
        span = fraction * total
        for lo in ((total - span) / 2, 0.0, total - span):
            ka = int(np.searchsorted(spine.length, lo - 1e-9))
            kb = min(int(np.searchsorted(spine.length, lo + span - 1e-9)), len(spine.path) - 1)
            pair = (int(spine.path[ka]), int(spine.path[kb]))
            apart = float(np.linalg.norm(spine.cells[pair[0]] - spine.cells[pair[1]]))
            if pair[0] != pair[1] and apart <= cap:
                pairs.setdefault(pair, apart)
    order = sorted(pairs, key=lambda p: -pairs[p])  # stable: the middle first among equals
    return [(spine.cells[a], spine.cells[b]) for a, b in order]


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
    hf, fp = world.heightfield, world.footprint
    # The standable map is made here, not inside the plan's short time limit.
    regions = standable_map(hf, fp, sc.planner.validity, sc.bounds, start[:2])
    cfg = _quick(sc.planner)
    result = plan_path(hf, fp, start, goal, bounds=sc.bounds, cfg=cfg, seed=seed, regions=regions)
    if not result.found:
        return None
    d = float(np.hypot(goal[0] - start[0], goal[1] - start[1]))
    note = (
        f"start and goal picked automatically on the ground at either end of the model "
        f"({extents[long]:.2f} m long), {d:.2f} m apart"
    )
    return AutoPoses(
        start=start,
        goal=goal,
        distance=d,
        region_area=float("nan"),
        note=note,
        yaw_valid=regions.yaw_valid,
    )


def _quick(cfg):
    """The scene's planner with a short budget: the check only asks whether a path exists."""
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
