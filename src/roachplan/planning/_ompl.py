"""Every call into OMPL lives here: state space, terrain sampler, validity checker, planners.

We use OMPL 1.7.0's Python bindings because they let a state-space sampler written in Python
reach every planner (`space.setStateSamplerAllocator`), and they expose STRIDE, LazyPRM, SPARS,
EST and SBL, which the 2.x wheels do not.

Determinism: our sampler draws from a numpy Generator seeded by the plan's seed; OMPL's own
process-global RNG (RRT's goal bias, PRM's roadmap expansion, KPIECE's cell choice, the
informed samplers once a solution exists, the path simplifier) is seeded from the same seed,
which takes effect only before OMPL's first random draw in a process; so every plan runs in a
child forked from a process that never drew (roachplan.processes, planning/_isolated.py).
Planners stop on an iteration budget rather than on
the clock, optimizing planners at their first solution unless asked to optimize, and PRM's and
PRM*'s roadmaps are grown in this thread in fixed batches (OMPL's PRM.solve grows it in a second
thread and stops whenever that thread notices a solution, which is timing-dependent).

Which planners call the terrain sampler (tests/test_planning.py checks it): all 16. Most ask
the space's sampler allocator; BIT* and Informed RRT* ask for the space's *default* sampler
(through their informed sampler, before a first solution), which `_TerrainSpace` overrides.
When optimizing past the first solution, those two draw inside the informed ellipse from OMPL's
own path-length sampler.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from roachplan.processes import Child

from ._config import PlannerConfig
from ._drivable import DrivablePath, drivable_path, spin_states
from ._heightfield import HeightField
from ._isolated import Method
from ._names import PLANNER_NAMES, PlanningError
from ._ompl_import import ob, og, ou
from ._regions import StandableMap, homology_signature, standable_map
from ._validity import Footprint, ValidityConfig, check_states, describe_state

_OMPL_CLASS: dict[str, str] = {
    "prm": "PRM",
    "stride": "STRIDE",
    "rrt": "RRT",
    "rrtconnect": "RRTConnect",
    "rrtstar": "RRTstar",
    "prmstar": "PRMstar",
    "lazyprm": "LazyPRM",
    "bitstar": "BITstar",
    "est": "EST",
    "sbl": "SBL",
    "kpiece1": "KPIECE1",
    "bkpiece1": "BKPIECE1",
    "lbkpiece1": "LBKPIECE1",
    "fmt": "FMT",
    "trrt": "TRRT",
    "informedrrtstar": "InformedRRTstar",
}
assert set(PLANNER_NAMES) == set(_OMPL_CLASS)

ou.setLogLevel(ou.LOG_WARN)


DRIVABLE_ATTEMPTS = 5
"""Routes searched, at most, for one the robot can follow (drivable plans) [-]."""


@dataclass(frozen=True, kw_only=True, eq=False)
class PlanResult:
    """What the planner returned."""

    found: bool
    """An exact path from start to goal was found."""
    planner: str
    """Planner name."""
    seed: int
    """Seed of every random choice of this plan."""
    states: np.ndarray
    """(K, 3) planner states x [m], y [m], yaw [rad]; empty when not found."""
    path_xyz: np.ndarray
    """(M, 3) waypoints every `waypoint_spacing`, z on the terrain surface [m]; empty when not found."""
    plan_time: float
    """Wall time spent planning [s] (for a non-optimizing plan: time to the first solution)."""
    message: str
    """Why planning failed, or a note on the solution."""
    signature: tuple[int, ...] = ()
    """Homology signature of the path round the terrain's holes (see _regions); () when not found."""
    validity_checks: int = 0
    """States whose validity was computed [-]."""
    validity_time: float = 0.0
    """Wall time spent computing validity [s]."""
    sampler_calls: int = 0
    """Samples drawn from the terrain sampler [-]."""
    roadmap: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    """(E, 2, 2) the planner's graph as xy segments [m] (with keep_roadmap; else empty)."""
    graph_states: int = 0
    """Vertices of the planner's graph, connected or not [-] (with keep_roadmap; else 0)."""
    turning_radius: float | None = None
    """The path is drivable: arcs of this radius [m] and straight lines (None: the planner's
    raw path, straight motions in (x, y, yaw))."""
    spins: tuple[tuple[int, float], ...] = ()
    """Turns on the spot, (index k into path_xyz, heading [rad]) each, in path order: at
    waypoint k the robot turns on the spot to that heading before it goes on (states[k + 1] and
    path_xyz[k + 1] repeat the position, with that heading). The tracking driver makes them
    (drive_path's spins)."""


class _TerrainSampler(ob.StateSampler):
    """The terrain-projected sampler (Tong 2018, section 4.4): (x, y) uniform over the cells where
    the robot can stand, yaw uniform; height, roll and pitch follow from projecting the robot
    onto the terrain, which the validity checker does.

    Uniform samples are drawn 256 at a time and checked in one vectorised call; the validity
    checker then finds their verdict in `known` instead of checking them one by one.
    """

    BLOCK = 256

    def __init__(
        self,
        space,
        *,
        rng: np.random.Generator,
        cells: np.ndarray,
        cell: float,
        lo,
        hi,
        check,
        known: dict[tuple[float, float, float], bool],
    ) -> None:
        """cells: (K, 2) centres of standable cells of size `cell` [m]; lo, hi: (2,) bounds of
        (x, y) [m]; check: vectorised validity of (N, 3) states; known: the verdict cache this
        sampler fills (shared by every sampler of one plan)."""
        super().__init__(space)
        self._rng, self._cells, self._cell = rng, cells, cell
        self._lo, self._hi, self._check = np.asarray(lo), np.asarray(hi), check
        self._block: list = []
        self.known = known
        self.calls = 0

    def _clip(self, x: float, y: float, yaw: float) -> tuple[float, float, float]:
        return (
            min(max(float(x), self._lo[0]), self._hi[0]),
            min(max(float(y), self._lo[1]), self._hi[1]),
            float((yaw + np.pi) % (2 * np.pi) - np.pi),
        )

    @staticmethod
    def _set(state, xyyaw: tuple[float, float, float]) -> None:
        state.setX(xyyaw[0])
        state.setY(xyyaw[1])
        state.setYaw(xyyaw[2])

    def _refill(self) -> None:
        rng, n = self._rng, self.BLOCK
        centre = self._cells[rng.integers(len(self._cells), size=n)]
        xy = centre + rng.uniform(-self._cell / 2, self._cell / 2, size=(n, 2))
        block = [self._clip(x, y, a) for (x, y), a in zip(xy, rng.uniform(-np.pi, np.pi, n))]
        valid = self._check(np.array(block))
        self.known.update(zip(block, valid.tolist(), strict=True))
        self._block = block[::-1]

    def sampleUniform(self, state) -> None:
        self.calls += 1
        if not self._block:
            self._refill()
        self._set(state, self._block.pop())

    def sampleUniformNear(self, state, near, distance: float) -> None:
        self.calls += 1
        d = self._rng.uniform(-distance, distance, size=3)
        self._set(state, self._clip(near.getX() + d[0], near.getY() + d[1], near.getYaw() + d[2]))

    def sampleGaussian(self, state, mean, std_dev: float) -> None:
        self.calls += 1
        d = self._rng.normal(0.0, std_dev, size=3)
        self._set(state, self._clip(mean.getX() + d[0], mean.getY() + d[1], mean.getYaw() + d[2]))


class _BatchMotionValidator(ob.MotionValidator):
    """Checks every state along a motion in one vectorised call instead of one Python callback
    per state: motions hold most of a planner's validity checks."""

    def __init__(self, si, fp: Footprint, check, resolution: float):
        super().__init__(si)
        self._check, self._res = check, resolution
        # A yaw change moves the outermost body point by radius * dyaw.
        self._radius = fp.radius

    def checkMotion(self, s1, s2, *_last_valid) -> bool:
        a = np.array([s1.getX(), s1.getY(), s1.getYaw()])
        b = np.array([s2.getX(), s2.getY(), s2.getYaw()])
        dyaw = (b[2] - a[2] + np.pi) % (2 * np.pi) - np.pi
        length = max(np.hypot(*(b[:2] - a[:2])), abs(dyaw) * self._radius)
        n = max(1, int(np.ceil(length / self._res)))
        f = np.arange(1, n + 1)[:, None] / n  # the motion's end state included, its start not
        states = a + f * np.array([b[0] - a[0], b[1] - a[1], dyaw])
        return bool(self._check(states).all())


class _TerrainSpace(ob.SE2StateSpace):
    """SE(2) whose sampler allocator *and* default sampler are the terrain sampler (`alloc`):
    informed samplers (BIT*, Informed RRT*) ask the space for its default sampler, bypassing
    the allocator."""

    def __init__(self, alloc) -> None:
        super().__init__()
        self._alloc = alloc
        self.setStateSamplerAllocator(ob.StateSamplerAllocator(alloc))

    def allocDefaultStateSampler(self):
        return self._alloc(self)


def _se2_state(space, xyyaw):
    s = ob.State(space)
    s().setX(float(xyyaw[0]))
    s().setY(float(xyyaw[1]))
    # OMPL's SO(2) bounds are [-pi, pi): a heading of exactly pi (180 deg in a scene) is out of
    # them, and a start or goal out of bounds is skipped ("There are no valid initial states!").
    s().setYaw((float(xyyaw[2]) + math.pi) % (2 * math.pi) - math.pi)
    return s


def _fn_ptc(fn):
    return ob.PlannerTerminationCondition(ob.PlannerTerminationConditionFn(fn))


def _budget_ptc(max_calls: int, deadline: float):
    """Stops after max_calls evaluations (deterministic) or at the wall-clock deadline."""
    calls = [0]

    def done() -> bool:
        calls[0] += 1
        return calls[0] > max_calls or time.perf_counter() > deadline

    return _fn_ptc(done)


def _roadmap_path(si, planner) -> list | None:
    """Shortest start-goal path through PRM's current roadmap, as vertex states, or None."""
    pd = ob.PlannerData(si)
    planner.getPlannerData(pd)
    n = pd.numVertices()
    if pd.numStartVertices() == 0 or pd.numGoalVertices() == 0:
        return None
    rows, cols, weights = [], [], []
    out = ou.vectorUint()
    for v in range(n):
        pd.getEdges(v, out)
        sv = pd.getVertex(v).getState()
        for w in out:
            rows.append(v)
            cols.append(w)
            weights.append(si.distance(sv, pd.getVertex(w).getState()) + 1e-12)
    if not rows:
        return None
    graph = coo_matrix((weights, (rows, cols)), shape=(n, n)).tocsr()
    start, goal = pd.getStartIndex(0), pd.getGoalIndex(0)
    dist, pred = dijkstra(graph, directed=False, indices=start, return_predecessors=True)
    if not np.isfinite(dist[goal]):
        return None
    chain = [goal]
    while chain[-1] != start:
        chain.append(int(pred[chain[-1]]))
    return [pd.getVertex(v).getState() for v in reversed(chain)]


class _Checker:
    """Vectorised validity of (N, 3) states, counting states and time for the benchmark."""

    def __init__(self, hf: HeightField, fp: Footprint, vcfg: ValidityConfig) -> None:
        self._args = (hf, fp, vcfg)
        self.states, self.seconds = 0, 0.0

    def __call__(self, states: np.ndarray) -> np.ndarray:
        t = time.perf_counter()
        valid = check_states(*self._args, states).valid
        self.seconds += time.perf_counter() - t
        self.states += len(states)
        return valid


def plan_path(
    hf: HeightField,
    fp: Footprint,
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    *,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    cfg: PlannerConfig,
    seed: int,
    regions: StandableMap | None = None,
    isolation: Method = "auto",
) -> PlanResult:
    """Plan a path for the robot's (x, y, yaw) from start to goal over the height field.

    bounds: ((xmin, ymin), (xmax, ymax)) of the body centre [m]; regions: the standable map of
    these bounds from start (computed when not given; pass it to save ~50 ms per plan).
    Raises PlanningError when the start or goal is itself invalid (naming the failed condition
    and leg); returns found=False when the planner gives up. Runs in a child process
    (roachplan.processes; isolation: how it starts), so the same seed gives the same plan
    whatever ran in this process before.
    """
    return start_plan(
        hf, fp, start, goal, bounds=bounds, cfg=cfg, seed=seed, regions=regions, isolation=isolation
    ).result()


def start_plan(
    hf: HeightField,
    fp: Footprint,
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    *,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    cfg: PlannerConfig,
    seed: int,
    regions: StandableMap | None = None,
    isolation: Method = "auto",
) -> Child[PlanResult]:
    """plan_path's child process, started and not waited for: its result() is what plan_path
    returns (PlanningError for an invalid start or goal is raised here, before any child).
    Plans started together run on as many cores, each the same plan as alone: a plan stops on
    its iteration budget, and each child is a fresh fork of this process; unless it hits its
    time limit (cfg.time_limit: such plans are not reproducible), which plans sharing a busy
    core reach sooner."""
    vcfg = cfg.validity
    (xa, ya), (xb, yb) = bounds
    for label, pose in (("start", start), ("goal", goal)):
        if not (xa <= pose[0] <= xb and ya <= pose[1] <= yb):
            raise PlanningError(
                f"{label} ({pose[0]:.3f}, {pose[1]:.3f}) is invalid: outside the planning area "
                f"x in [{xa:g}, {xb:g}], y in [{ya:g}, {yb:g}]"
            )
        verdict = describe_state(hf, fp, vcfg, np.asarray(pose))
        if verdict != "valid":
            raise PlanningError(
                f"{label} ({pose[0]:.3f}, {pose[1]:.3f}, yaw {np.degrees(pose[2]):.0f} deg) "
                f"is invalid: {verdict}"
            )
    request: dict[str, Any] = dict(
        start=start, goal=goal, bounds=bounds, cfg=cfg, seed=seed, regions=regions
    )
    return Child(
        _plan_here, (hf, fp), request, start=isolation, preload=(__name__,), task="planning"
    )


def _seed_ompl(seed: int) -> None:
    ompl_seed = int(seed) % (2**31 - 1) + 1  # OMPL rejects seed 0
    ou.RNG.setSeed(ompl_seed)
    if ou.RNG.getSeed() != ompl_seed:
        raise PlanningError(
            "OMPL's random generator was used in this process before planning, so the seed "
            "cannot take effect: plan only through plan_path"
        )


def _simplified(si, states: list, cfg: PlannerConfig) -> np.ndarray:
    """The solution's states after the simplification and smoothing cfg asks for, (K, 3)."""
    path = og.PathGeometric(si)
    for s in states:
        path.append(s)
    simplifier = og.PathSimplifier(si)
    if cfg.simplify:
        simplifier.reduceVertices(path)
        simplifier.collapseCloseVertices(path)
        simplifier.partialShortcutPath(path)
    if cfg.smooth:
        simplifier.smoothBSpline(path)
    return np.array([[s.getX(), s.getY(), s.getYaw()] for s in path.getStates()])


def _plan_here(
    hf, fp, *, start, goal, bounds, cfg: PlannerConfig, seed: int, regions
) -> PlanResult:
    t0 = time.perf_counter()
    _seed_ompl(seed)
    lo, hi = np.asarray(bounds[0], dtype=float), np.asarray(bounds[1], dtype=float)
    check = _Checker(hf, fp, cfg.validity)
    if regions is None:
        regions = standable_map(hf, fp, cfg.validity, bounds, start[:2])

    def inside_and_valid(st: np.ndarray) -> np.ndarray:
        # OMPL keeps its own states within the bounds; a Dubins curve must be kept there.
        inside = np.all((st[:, :2] >= lo) & (st[:, :2] <= hi), axis=1)
        return inside & check(st) if inside.all() else np.zeros(len(st), dtype=bool)

    if np.hypot(goal[0] - start[0], goal[1] - start[1]) < cfg.goal_radius:
        return _coinciding(
            hf,
            fp,
            start=start,
            goal=goal,
            cfg=cfg,
            seed=seed,
            regions=regions,
            is_valid=inside_and_valid,
            t0=t0,
        )
    problem = _Problem.build(
        fp, start=start, goal=goal, lo=lo, hi=hi, cfg=cfg, rng=np.random.default_rng(seed),
        regions=regions, check=check,
    )  # fmt: skip
    deadline = t0 + cfg.time_limit
    route = problem.search(cfg, deadline, start_yaw=start[2], spin_step=_spin_step(fp, cfg),
                           is_valid=inside_and_valid)  # fmt: skip
    stats: dict[str, Any] = dict(
        validity_checks=check.states,
        validity_time=check.seconds,
        sampler_calls=sum(smp.calls for smp in problem.samplers),
    )
    if cfg.keep_roadmap:
        stats["roadmap"], stats["graph_states"] = _graph_segments(problem.si, problem.planner)
    if route.xyyaw is None:
        why = "time limit" if time.perf_counter() > deadline else "iteration budget"
        message = f"{cfg.name} found no path within its {why}"
        if route.undrivable:
            message = (
                f"{cfg.name} found {route.undrivable} route(s), but none the robot can follow "
                f"with turns of radius {cfg.turning_radius:g} m"
            )
        return PlanResult(
            found=False,
            planner=cfg.name,
            seed=seed,
            states=np.zeros((0, 3)),
            path_xyz=np.zeros((0, 3)),
            plan_time=time.perf_counter() - t0,
            message=message,
            **stats,
        )
    xyyaw, path_xyz, spins = route.xyyaw, None, ()
    if route.drivable is not None:
        # The curve is sampled every check_resolution; the driver gets every waypoint_spacing,
        # and both states of every spin (where it begins and the heading it ends at).
        drivable = route.drivable
        every = max(1, round(cfg.waypoint_spacing / cfg.check_resolution))
        at = np.asarray(drivable.spins, dtype=int)
        keep = np.unique(
            np.r_[np.arange(0, len(drivable.states), every), len(drivable.states) - 1, at, at + 1]
        )
        xyyaw = drivable.states[keep]
        path_xyz = np.column_stack([xyyaw[:, :2], hf.sample(xyyaw[:, :2])])
        k = np.searchsorted(keep, at)
        spins = tuple((int(i), float(xyyaw[i + 1, 2])) for i in k)
    return PlanResult(
        found=True,
        planner=cfg.name,
        seed=seed,
        states=xyyaw,
        path_xyz=(
            waypoints_on_surface(hf, xyyaw[:, :2], cfg.waypoint_spacing)
            if path_xyz is None
            else path_xyz
        ),
        plan_time=time.perf_counter() - t0,
        message=f"{len(xyyaw)} states"
        + (
            f", drivable with turns of radius {cfg.turning_radius:g} m"
            if cfg.turning_radius is not None
            else ""
        )
        + _spins_note(spins),
        signature=homology_signature(regions.holes, xyyaw[:, :2]),
        turning_radius=cfg.turning_radius,
        spins=spins,
        **stats,
    )


@dataclass(frozen=True, eq=False)
class _Route:
    """What a search found: the planner's route (simplified, (K, 3) x, y, yaw) or None, its
    drivable path (with turning_radius) and how many routes no drivable path followed."""

    xyyaw: np.ndarray | None
    drivable: DrivablePath | None
    undrivable: int


@dataclass(frozen=True, eq=False)
class _Problem:
    """One OMPL problem over the terrain: the space, its information, the problem
    definition, the planner, and the terrain samplers it made (kept alive: OMPL holds only a
    C++ reference to them)."""

    si: Any  # ompl.base.SpaceInformation (the bindings are untyped)
    pdef: Any  # ompl.base.ProblemDefinition
    planner: Any  # an ompl.geometric planner
    samplers: list

    @staticmethod
    def build(
        fp, *, start, goal, lo, hi, cfg: PlannerConfig, rng, regions, check: _Checker
    ) -> _Problem:
        """Set up the SE(2) problem from start to goal within lo, hi ((2,) [m]): the terrain
        sampler over the standable map, the validity checker and the batch motion validator,
        the planner cfg.name."""
        # Sample where the robot can stand, one cell of margin round it (the map is coarse).
        cells = regions.cell_centres(ndimage.binary_dilation(regions.reachable))
        if len(cells) == 0:
            cells = regions.cell_centres(np.ones_like(regions.reachable))
        samplers: list[_TerrainSampler] = []
        known: dict[tuple[float, float, float], bool] = {}  # one verdict cache for every sampler

        def alloc(sp):
            sampler = _TerrainSampler(
                sp, rng=rng, cells=cells, cell=regions.cell, lo=lo, hi=hi, check=check, known=known
            )
            samplers.append(sampler)
            return sampler

        space = _TerrainSpace(alloc)
        rv = ob.RealVectorBounds(2)
        for k in range(2):
            rv.setLow(k, float(lo[k]))
            rv.setHigh(k, float(hi[k]))
        space.setBounds(rv)
        si = ob.SpaceInformation(space)

        def is_valid(s) -> bool:
            key = (s.getX(), s.getY(), s.getYaw())
            verdict = known.get(key)
            if verdict is None:
                verdict = bool(check(np.array([key]))[0])
            return verdict

        si.setStateValidityChecker(ob.StateValidityCheckerFn(is_valid))
        si.setMotionValidator(_BatchMotionValidator(si, fp, check, cfg.check_resolution))
        si.setup()
        pdef = ob.ProblemDefinition(si)
        pdef.setStartAndGoalStates(_se2_state(space, start), _se2_state(space, goal))
        objective = ob.PathLengthOptimizationObjective(si)
        # An infinite threshold is met by any path: optimizing planners stop at their first one.
        objective.setCostThreshold(ob.Cost(0.0 if cfg.optimize else float("inf")))
        pdef.setOptimizationObjective(objective)
        planner = getattr(og, _OMPL_CLASS[cfg.name])(si)
        planner.setProblemDefinition(pdef)
        planner.setup()
        return _Problem(si=si, pdef=pdef, planner=planner, samplers=samplers)

    def search(
        self, cfg: PlannerConfig, deadline: float, *, start_yaw: float, spin_step: float, is_valid
    ) -> _Route:
        """Solve until deadline [s, perf_counter]; with turning_radius, turn each route into a
        drivable path (is_valid: (N, 3) states -> (N,) bool), searching again from scratch for
        a route with a turn too tight for the space round it, up to DRIVABLE_ATTEMPTS."""
        si, pdef, planner = self.si, self.pdef, self.planner
        undrivable = 0
        while True:
            if cfg.name in ("prm", "prmstar") and not cfg.optimize:
                states = _solve_prm(si, planner, cfg, deadline)
            else:
                planner.solve(_budget_ptc(cfg.max_iterations, deadline))
                states = pdef.getSolutionPath().getStates() if pdef.hasExactSolution() else None
            if states is None:
                return _Route(None, None, undrivable)
            xyyaw = _simplified(si, states, cfg)
            if cfg.turning_radius is None:
                return _Route(xyyaw, None, undrivable)
            drivable = drivable_path(
                xyyaw[:, :2],
                start_yaw,
                cfg.turning_radius,
                is_valid,
                cfg.check_resolution,
                spin_margin=cfg.spin_margin,
                spin_step=spin_step,
            )
            if drivable is not None:
                return _Route(xyyaw, drivable, undrivable)
            # The planner's random stream goes on, so the next route differs.
            undrivable += 1
            if undrivable >= DRIVABLE_ATTEMPTS or time.perf_counter() > deadline:
                return _Route(None, None, undrivable)
            planner.clear()
            pdef.clearSolutionPaths()


def _spins_note(spins) -> str:
    """How many turns on the spot a plan has, for its message ("" for none)."""
    if not spins:
        return ""
    return f" and {len(spins)} turn{'s' if len(spins) > 1 else ''} on the spot"


def _spin_step(fp: Footprint, cfg: PlannerConfig) -> float:
    """Heading step of a spin's validity checks [rad]: the footprint's outermost point moves
    at most check_resolution, as along a motion (_BatchMotionValidator)."""
    return cfg.check_resolution / fp.radius


def _coinciding(
    hf, fp, *, start, goal, cfg: PlannerConfig, seed: int, regions, is_valid, t0: float
) -> PlanResult:
    """The trivial plan between a start and goal closer than goal_radius: the robot stands
    where the goal counts as reached. A drivable plan (turning_radius and spin_margin set)
    turns on the spot to the goal's heading first when it differs and every heading of the
    turn is valid, checked as drivable_path checks a spin. The raw plan is OMPL's for it: the
    start and the goal states."""
    apart = float(np.hypot(goal[0] - start[0], goal[1] - start[1]))
    turn = math.remainder(goal[2] - start[2], 2 * math.pi)
    states = [np.asarray(start, dtype=float)]
    spins: tuple[tuple[int, float], ...] = ()
    what = "nothing to drive"
    if cfg.turning_radius is not None and abs(turn) > 1e-9:
        turnable = cfg.spin_margin is not None and bool(
            np.all(
                is_valid(
                    spin_states(
                        np.asarray(start[:2], dtype=float),
                        start[2],
                        goal[2],
                        cfg.spin_margin,
                        _spin_step(fp, cfg),
                    )
                )
            )
        )
        if turnable:
            states.append(np.array([start[0], start[1], goal[2]]))
            spins = ((0, float(goal[2])),)
            what = f"a turn on the spot of {math.degrees(turn):.0f} deg to the goal's heading"
        else:
            what += (
                f" (the goal's heading is {math.degrees(turn):.0f} deg away; turns on the "
                f"spot {'are off' if cfg.spin_margin is None else 'are not valid here'})"
            )
    if apart > 0 or cfg.turning_radius is None:  # the goal's own state ends the path
        states.append(np.asarray(goal, dtype=float))
    xyyaw = np.array(states)
    return PlanResult(
        found=True,
        planner=cfg.name,
        seed=seed,
        states=xyyaw,
        path_xyz=np.column_stack([xyyaw[:, :2], hf.sample(xyyaw[:, :2])]),
        plan_time=time.perf_counter() - t0,
        message=(
            f"start and goal coincide ({apart:.3f} m apart, within the goal radius "
            f"{cfg.goal_radius:g} m): {what}"
        ),
        signature=homology_signature(regions.holes, xyyaw[:, :2]),
        turning_radius=cfg.turning_radius,
        spins=spins,
    )


def _graph_segments(si, planner) -> tuple[np.ndarray, int]:
    """(E, 2, 2) xy segments [m] of the planner's roadmap or tree (OMPL PlannerData), and its
    number of vertices (an unconnected PRM milestone is in no segment)."""
    data = ob.PlannerData(si)
    planner.getPlannerData(data)
    xy = np.array(
        [
            [v.getState().getX(), v.getState().getY()]
            for v in (data.getVertex(i) for i in range(data.numVertices()))
        ]
    )
    segments = []
    targets = ou.vectorUint()
    for i in range(data.numVertices()):
        data.getEdges(i, targets)
        segments.extend((xy[i], xy[j]) for j in targets)
    return np.array(segments, dtype=np.float64).reshape(-1, 2, 2), len(xy)


def _solve_prm(si, planner, cfg: PlannerConfig, deadline: float) -> list | None:
    # The first solve call only inserts the start and goal milestones (its condition is
    # already true); then we grow and expand the roadmap 2:1 like PRM.solve, but in this thread
    # and in fixed batches, and query it after every batch.
    planner.solve(_fn_ptc(lambda: True))
    grown = 0
    while grown < cfg.max_iterations and time.perf_counter() < deadline:
        planner.growRoadmap(_budget_ptc(cfg.prm_batch, deadline))
        planner.expandRoadmap(_budget_ptc(max(1, cfg.prm_batch // 2), deadline))
        grown += cfg.prm_batch
        states = _roadmap_path(si, planner)
        if states is not None:
            return states
    return None


def waypoints_on_surface(hf: HeightField, xy: np.ndarray, spacing: float) -> np.ndarray:
    """Resample a polyline ((K, 2) [m]) every `spacing` metres, keeping its corners, with z on
    the terrain surface. Returns (M, 3)."""
    xy = np.asarray(xy, dtype=float)
    pts = [xy[0]]
    for a, b in zip(xy[:-1], xy[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / spacing)))
        pts.extend(a + (b - a) * (k / n) for k in range(1, n + 1))
    pts = np.array(pts)
    return np.column_stack([pts, hf.sample(pts)])
