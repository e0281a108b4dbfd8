"""Every call into OMPL lives here: state space, terrain sampler, validity checker, planners.

We use OMPL 1.7.0's Python bindings because they let a state-space sampler written in Python
reach every planner (`space.setStateSamplerAllocator`), and they expose STRIDE, LazyPRM, SPARS,
EST and SBL, which the 2.x wheels do not.

Determinism: our sampler draws from a numpy Generator seeded by the trial seed; OMPL's own
process-global RNG (used e.g. for RRT's goal bias and PRM's roadmap expansion) is seeded from the
same seed, which takes effect only before OMPL's first random draw in a process, so a plan is
reproducible when it runs in a fresh process (the CLI and the app's planning worker do).
Anytime planners stop on an iteration budget rather than on the clock, and PRM's roadmap is grown
in this thread in fixed batches (OMPL's PRM.solve grows it in a second thread and stops whenever
that thread notices a solution, which is timing-dependent).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from ._heightfield import HeightField
from ._ompl_import import ob, og, ou
from ._validity import Footprint, ValidityConfig, check_states, describe_state

PlannerName = Literal[
    "prm", "stride", "rrt", "rrtconnect", "rrtstar", "prmstar", "lazyprm", "bitstar",
    "est", "sbl", "kpiece1", "bkpiece1", "lbkpiece1", "fmt", "trrt", "informedrrtstar",
]  # fmt: skip
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
PLANNER_NAMES: tuple[str, ...] = get_args(PlannerName)
assert set(PLANNER_NAMES) == set(_OMPL_CLASS)

ou.setLogLevel(ou.LOG_WARN)


class PlanningError(ValueError):
    """A planning request that cannot be planned as asked (e.g. an invalid start)."""


@dataclass(frozen=True, kw_only=True)
class PlannerConfig:
    """How to plan."""

    name: PlannerName = "prm"
    """OMPL planner, by its class name in lower case."""
    time_limit: float = 20.0
    """Wall-clock cap on planning [s]; plans that hit it are not reproducible."""
    max_iterations: int = 20000
    """Iteration budget (PRM: milestones) after which planning gives up [-]."""
    prm_batch: int = 25
    """PRM: milestones added between two checks for a start-goal connection [-]."""
    check_resolution: float = 0.01
    """Spacing of validity checks along a motion [m]."""
    simplify: bool = False
    """Shortcut and smooth the path (the report drove raw PRM paths)."""
    waypoint_spacing: float = 0.05
    """Spacing of the waypoints handed to the driver [m]."""
    validity: ValidityConfig = field(default_factory=ValidityConfig)
    """Tolerances of the validity conditions."""


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
    """Wall time spent planning [s]."""
    message: str
    """Why planning failed, or a note on the solution."""


class _TerrainSampler(ob.StateSampler):
    """Samples (x, y, yaw) uniformly over the planning bounds; height, roll and pitch follow from
    projecting the robot onto the terrain in the validity checker (Tong 2018, section 4.4)."""

    def __init__(self, space: ob.StateSpace, rng: np.random.Generator, lo, hi) -> None:
        super().__init__(space)
        self._rng, self._lo, self._hi = rng, np.asarray(lo), np.asarray(hi)
        self.calls = 0

    def _set(self, state, x: float, y: float, yaw: float) -> None:
        state.setX(float(np.clip(x, self._lo[0], self._hi[0])))
        state.setY(float(np.clip(y, self._lo[1], self._hi[1])))
        state.setYaw(float((yaw + np.pi) % (2 * np.pi) - np.pi))

    def sampleUniform(self, state) -> None:
        self.calls += 1
        x, y = self._rng.uniform(self._lo, self._hi)
        self._set(state, x, y, self._rng.uniform(-np.pi, np.pi))

    def sampleUniformNear(self, state, near, distance: float) -> None:
        self.calls += 1
        d = self._rng.uniform(-distance, distance, size=3)
        self._set(state, near.getX() + d[0], near.getY() + d[1], near.getYaw() + d[2])

    def sampleGaussian(self, state, mean, std_dev: float) -> None:
        self.calls += 1
        d = self._rng.normal(0.0, std_dev, size=3)
        self._set(state, mean.getX() + d[0], mean.getY() + d[1], mean.getYaw() + d[2])


class _BatchMotionValidator(ob.MotionValidator):
    """Checks every state along a motion in one vectorised call instead of one Python callback
    per state: motions hold most of a planner's validity checks."""

    def __init__(self, si, hf: HeightField, fp: Footprint, vcfg: ValidityConfig, resolution: float):
        super().__init__(si)
        self._hf, self._fp, self._vcfg, self._res = hf, fp, vcfg, resolution
        # A yaw change moves the outermost body point by radius * dyaw.
        self._radius = float(np.max(np.hypot(fp.feet_xy[:, 0], fp.feet_xy[:, 1])))
        self.states_checked = 0

    def checkMotion(self, s1, s2, *_last_valid) -> bool:
        a = np.array([s1.getX(), s1.getY(), s1.getYaw()])
        b = np.array([s2.getX(), s2.getY(), s2.getYaw()])
        dyaw = (b[2] - a[2] + np.pi) % (2 * np.pi) - np.pi
        length = max(np.hypot(*(b[:2] - a[:2])), abs(dyaw) * self._radius)
        n = max(1, int(np.ceil(length / self._res)))
        f = np.arange(1, n + 1)[:, None] / n  # the motion's end state included, its start not
        states = a + f * np.array([b[0] - a[0], b[1] - a[1], dyaw])
        self.states_checked += n
        return bool(check_states(self._hf, self._fp, self._vcfg, states).valid.all())


def _se2_state(space: ob.SE2StateSpace, xyyaw) -> ob.State:
    s = ob.State(space)
    s().setX(float(xyyaw[0]))
    s().setY(float(xyyaw[1]))
    s().setYaw(float(xyyaw[2]))
    return s


def _fn_ptc(fn) -> ob.PlannerTerminationCondition:
    return ob.PlannerTerminationCondition(ob.PlannerTerminationConditionFn(fn))


def _budget_ptc(max_calls: int, deadline: float) -> ob.PlannerTerminationCondition:
    """Stops after max_calls evaluations (deterministic) or at the wall-clock deadline."""
    calls = [0]

    def done() -> bool:
        calls[0] += 1
        return calls[0] > max_calls or time.perf_counter() > deadline

    return _fn_ptc(done)


def _roadmap_path(si: ob.SpaceInformation, planner: og.PRM) -> list | None:
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


def plan_path(
    hf: HeightField,
    fp: Footprint,
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    *,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    cfg: PlannerConfig,
    seed: int,
) -> PlanResult:
    """Plan a path for the robot's (x, y, yaw) from start to goal over the height field.

    bounds: ((xmin, ymin), (xmax, ymax)) of the body centre [m]. Raises PlanningError when the
    start or goal is itself invalid (naming the failed condition); returns found=False when the
    planner gives up.
    """
    t0 = time.perf_counter()
    vcfg = cfg.validity
    for label, pose in (("start", start), ("goal", goal)):
        verdict = describe_state(hf, fp, vcfg, np.asarray(pose))
        if verdict != "valid":
            raise PlanningError(
                f"{label} ({pose[0]:.3f}, {pose[1]:.3f}, yaw {np.degrees(pose[2]):.0f} deg) "
                f"is invalid: {verdict}"
            )
    ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)  # OMPL rejects seed 0
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(bounds[0], dtype=float), np.asarray(bounds[1], dtype=float)

    space = ob.SE2StateSpace()
    rv = ob.RealVectorBounds(2)
    for k in range(2):
        rv.setLow(k, float(lo[k]))
        rv.setHigh(k, float(hi[k]))
    space.setBounds(rv)
    samplers: list[_TerrainSampler] = []

    def alloc(sp):
        sampler = _TerrainSampler(sp, rng, lo, hi)
        samplers.append(sampler)  # OMPL holds only a C++ reference: keep the Python object alive
        return sampler

    space.setStateSamplerAllocator(ob.StateSamplerAllocator(alloc))
    si = ob.SpaceInformation(space)

    def is_valid(s) -> bool:
        return bool(
            check_states(hf, fp, vcfg, np.array([[s.getX(), s.getY(), s.getYaw()]])).valid[0]
        )

    si.setStateValidityChecker(ob.StateValidityCheckerFn(is_valid))
    motion_validator = _BatchMotionValidator(si, hf, fp, vcfg, cfg.check_resolution)
    si.setMotionValidator(motion_validator)
    si.setup()
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(_se2_state(space, start), _se2_state(space, goal))
    planner = getattr(og, _OMPL_CLASS[cfg.name])(si)
    planner.setProblemDefinition(pdef)
    planner.setup()
    deadline = t0 + cfg.time_limit

    if cfg.name == "prm":
        states = _solve_prm(si, planner, cfg, deadline)
    else:
        planner.solve(_budget_ptc(cfg.max_iterations, deadline))
        states = pdef.getSolutionPath().getStates() if pdef.hasExactSolution() else None
    if states is None:
        why = "time limit" if time.perf_counter() > deadline else "iteration budget"
        return PlanResult(
            found=False, planner=cfg.name, seed=seed, states=np.zeros((0, 3)),
            path_xyz=np.zeros((0, 3)), plan_time=time.perf_counter() - t0,
            message=f"{cfg.name} found no path within its {why}",
        )  # fmt: skip
    path = og.PathGeometric(si)
    for s in states:
        path.append(s)
    if cfg.simplify:
        og.PathSimplifier(si).simplifyMax(path)
    xyyaw = np.array([[s.getX(), s.getY(), s.getYaw()] for s in path.getStates()])
    return PlanResult(
        found=True,
        planner=cfg.name,
        seed=seed,
        states=xyyaw,
        path_xyz=waypoints_on_surface(hf, xyyaw[:, :2], cfg.waypoint_spacing),
        plan_time=time.perf_counter() - t0,
        message=f"{len(xyyaw)} states",
    )


def _solve_prm(si, planner: og.PRM, cfg: PlannerConfig, deadline: float) -> list | None:
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
