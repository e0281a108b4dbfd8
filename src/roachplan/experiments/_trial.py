"""One trial, as the report's performance evaluator runs it: plan with OMPL, drive in PyBullet."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from roachplan.planning import PlannerConfig, PlanResult
from roachplan.planning import start_plan as planning_start_plan
from roachplan.processes import Child
from roachplan.scenes import World
from roachplan.sim import DriveResult, Frame, Simulation, drive_path, reference_energy_per_metre

TrialOutcome = Literal["success", "fell", "flipped", "stuck", "timeout", "missed", "no_path"]
MIN_ATTEMPT_TIME = 0.05
"""plan_many starts no attempt with less of its budget left than this [s]: a plan's own set-up
takes about that long."""


def path_settings(turning_radius: float | None) -> dict:
    """How a plan became the driven path, as the JSON outputs name it: planner_space "se2"
    (OMPL's (x, y, yaw) with straight motions; drivable plans are made drivable afterwards, and
    the Dubins space measured no better, README "Drivable plans"), smoothing "dubins_shortcuts"
    (arcs of turning_radius [m] and lines) or "none" (the raw path, the report's)."""
    return {
        "planner_space": "se2",
        "smoothing": "none" if turning_radius is None else "dubins_shortcuts",
        "turning_radius": turning_radius,
    }


@dataclass(frozen=True, kw_only=True)
class TrialResult:
    """Everything recorded about one plan-and-drive trial."""

    scene: str
    seed: int
    """Seed of every random choice in the trial."""
    planner: str
    path_found: bool
    outcome: TrialOutcome
    reason: str
    """Why the trial ended as it did."""
    route: str
    """The route the path takes (World.route: the scene's named region it crosses, else its
    homology label round the terrain's holes; "" without a path)."""
    drive_time: float
    """Simulated time of the drive [s] (0 without a path)."""
    energy: float
    """Energy the leg motors spent [J] (Tong 2018, section 3.4)."""
    relative_energy: float
    """energy / (energy of walking straight on a flat floor for the start-goal distance) [-]:
    the report's "relative unit"; ~1.0 = as cheap as the floor (0 without a drive)."""
    plan_time: float
    """Wall time spent planning [s]."""
    drive_wall_time: float
    """Wall time spent simulating the drive [s]."""
    start: tuple[float, float, float]
    """x [m], y [m], yaw [rad]."""
    goal: tuple[float, float, float]
    path: tuple[tuple[float, float, float], ...]
    """Planned waypoints x, y, z [m] (z on the terrain surface)."""
    trajectory: tuple[tuple[float, float, float, float], ...]
    """Driven body positions t [s], x, y, z [m]."""
    turning_radius: float | None = None
    """The path was made drivable with arcs of this radius [m]; None: the planner's raw path
    (the report's)."""
    driver: str = "reference"
    """Path follower: "tracking" (pure pursuit) or "reference" (Tong 2018, algorithms 1-2).
    Records from before drivers could be chosen were all driven by the reference one."""
    spins: tuple[tuple[int, float], ...] = ()
    """The plan's turns on the spot: (index into path, heading [rad]) each (PlanResult.spins);
    records from before spins existed have none."""

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d.update(path_settings(self.turning_radius))
        d["path"] = [list(p) for p in self.path]
        d["trajectory"] = [list(p) for p in self.trajectory]
        d["spins"] = [list(p) for p in self.spins]
        return d


def plan(
    world: World,
    *,
    seed: int,
    start: tuple[float, float, float] | None = None,
    goal: tuple[float, float, float] | None = None,
    planner: PlannerConfig | None = None,
) -> PlanResult:
    """Plan from start to goal (default: the scene's) over the world's terrain."""
    return start_plan(world, seed=seed, start=start, goal=goal, planner=planner).result()


def start_plan(
    world: World,
    *,
    seed: int,
    start: tuple[float, float, float] | None = None,
    goal: tuple[float, float, float] | None = None,
    planner: PlannerConfig | None = None,
) -> Child[PlanResult]:
    """plan()'s planning child, started and not waited for (planning.start_plan): its result()
    is what plan() returns; plans started together plan on as many cores, each the plan it is
    alone unless it hits its time limit."""
    return planning_start_plan(
        world.heightfield,
        world.footprint,
        start or world.start,
        goal or world.goal,
        bounds=world.bounds,
        cfg=planner or world.scene.planner,
        seed=seed,
        # The scene's standable map is from the scene's start; another start may lie elsewhere.
        regions=world.regions if start is None or start == world.scene.start else None,
    )


@dataclass(frozen=True, kw_only=True, eq=False)
class LabelledPlan:
    """One of several distinct plans, with the route it takes."""

    route: str
    plan: PlanResult


def plan_many(
    world: World,
    count: int,
    *,
    seed: int,
    start: tuple[float, float, float] | None = None,
    goal: tuple[float, float, float] | None = None,
    planner: PlannerConfig | None = None,
    max_attempts: int | None = None,
    min_separation: float = 0.02,
    budget: float | None = None,
    on_attempt: Callable[[int, LabelledPlan | None], None] | None = None,
) -> list[LabelledPlan]:
    """Up to `count` distinct paths, planned with seeds seed, seed + 1, ... (each path's own
    seed re-plans it alone), each labelled with its route (World.route).

    Distinct: the mean distance between two paths, resampled at 50 points by arc length, is at
    least min_separation [m]. Stops after max_attempts plans (default 3 count + 10), or when
    `budget` [s wall] is spent: the budget covers every attempt (each gets what is left of it,
    at most the planner's time_limit), not each one. on_attempt(seed, new_plan_or_None) is
    called after each attempt (progress).
    """
    out: list[LabelledPlan] = []
    shapes: list[np.ndarray] = []
    attempts = max_attempts if max_attempts is not None else 3 * count + 10
    cfg = planner or world.scene.planner
    deadline = None if budget is None else time.monotonic() + budget
    # While more than one plan is wanted, attempt k + 1 plans beside attempt k, in a second
    # child: each is the plan it is alone (a plan stops on its iteration budget, unless it hits
    # its time limit), taken in order; one not needed (or left when the budget is spent) is
    # cancelled.
    children: dict[int, Child[PlanResult]] = {}
    try:
        for k in range(attempts):
            if len(out) == count:
                break
            if deadline is not None:
                left = deadline - time.monotonic()
                if left < MIN_ATTEMPT_TIME:
                    break
                cfg = dataclasses.replace(cfg, time_limit=min(cfg.time_limit, left))
            ahead = 2 if count - len(out) > 1 else 1
            for j in range(k, min(k + ahead, attempts)):
                if j not in children:
                    children[j] = start_plan(
                        world, seed=seed + j, start=start, goal=goal, planner=cfg
                    )
            planned = children.pop(k).result()
            shape = _resample(planned.path_xyz[:, :2], 50) if planned.found else None
            if shape is None or any(
                np.mean(np.linalg.norm(shape - s, axis=1)) < min_separation for s in shapes
            ):
                if on_attempt is not None:
                    on_attempt(seed + k, None)
                continue
            shapes.append(shape)
            out.append(LabelledPlan(route=world.route(planned.path_xyz[:, :2]), plan=planned))
            if on_attempt is not None:
                on_attempt(seed + k, out[-1])
    finally:
        for child in children.values():
            child.cancel()
    return out


def _resample(xy: np.ndarray, n: int) -> np.ndarray:
    """n points evenly spaced by arc length along the polyline xy ((K, 2)) [m]."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(t, s, xy[:, 0]), np.interp(t, s, xy[:, 1])])


def drive(
    world: World,
    path_xyz: np.ndarray,
    *,
    start: tuple[float, float, float] | None = None,
    on_frame: Callable[[Frame], None] | None = None,
    sim: Simulation | None = None,
    spins=(),
) -> DriveResult:
    """Drop the robot at start (default: the scene's) and drive it along path_xyz, turning on
    the spot at `spins` ((waypoint index, heading [rad]) each: PlanResult.spins).

    sim: a simulation of this world to drive in (it is reset first; the caller owns it);
    default: a fresh one, which is what a reproducible trial needs: a reused client, reset,
    can carry the solver's history of an earlier drive into this one (experiments/_workers.py).
    """
    scene = world.scene
    x, y, yaw = start or world.start
    if sim is None:
        with world.simulation() as fresh:
            return drive(world, path_xyz, start=start, on_frame=on_frame, sim=fresh, spins=spins)
    sim.reset(x, y, yaw, surface=float(world.heightfield.sample(np.array([x, y]))))
    return drive_path(sim, path_xyz, scene.driver, on_frame=on_frame, spins=spins)


def reference_energy(
    world: World, start: tuple[float, float, float], goal: tuple[float, float, float]
) -> float:
    """Energy [J] of walking straight on a flat floor over the start-goal distance, or over the
    driver's goal radius r_end when they are closer (they coincide: the trial at most turns on
    the spot, and its energy against a walk of ~0 m would mean nothing)."""
    scene = world.scene
    per_metre = reference_energy_per_metre(world.robot, scene.sim, scene.driver.omega0)
    return per_metre * max(math.dist(start[:2], goal[:2]), scene.driver.r_end)


def run_trial(
    world: World,
    *,
    seed: int,
    planner: PlannerConfig | None = None,
    start: tuple[float, float, float] | None = None,
    goal: tuple[float, float, float] | None = None,
    on_frame: Callable[[Frame], None] | None = None,
    sim: Simulation | None = None,
) -> TrialResult:
    """Plan, then drive the plan; 'no_path' when the planner gives up."""
    start, goal = start or world.start, goal or world.goal
    planned = plan(world, seed=seed, start=start, goal=goal, planner=planner)
    return finish_trial(world, planned, start=start, goal=goal, on_frame=on_frame, sim=sim)


def finish_trial(
    world: World,
    planned: PlanResult,
    *,
    start: tuple[float, float, float],
    goal: tuple[float, float, float],
    on_frame: Callable[[Frame], None] | None = None,
    sim: Simulation | None = None,
) -> TrialResult:
    """Drive an existing plan and record the trial."""

    def record(**how_it_went) -> TrialResult:
        """The trial's record: what every trial records, and how_it_went (the drive's)."""
        return TrialResult(
            scene=world.scene.name,
            seed=planned.seed,
            planner=planned.planner,
            path_found=planned.found,
            plan_time=planned.plan_time,
            start=(start[0], start[1], start[2]),  # (a tuple, whatever sequence came in)
            goal=(goal[0], goal[1], goal[2]),
            turning_radius=planned.turning_radius,
            driver=world.scene.driver.kind,
            spins=planned.spins,
            **how_it_went,
        )

    if not planned.found:
        return record(
            outcome="no_path",
            reason=planned.message,
            route="",
            drive_time=0.0,
            energy=0.0,
            relative_energy=0.0,
            drive_wall_time=0.0,
            path=(),
            trajectory=(),
        )
    t0 = time.perf_counter()
    driven = drive(
        world, planned.path_xyz, start=start, on_frame=on_frame, sim=sim, spins=planned.spins
    )
    return record(
        outcome=driven.outcome,
        reason=driven.reason,
        route=world.route(planned.path_xyz[:, :2]),
        drive_time=driven.drive_time,
        energy=driven.energy,
        relative_energy=driven.energy / reference_energy(world, start, goal),
        drive_wall_time=time.perf_counter() - t0,
        path=tuple(tuple(p) for p in planned.path_xyz.tolist()),
        trajectory=driven.trajectory,
    )
