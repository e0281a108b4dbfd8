"""The candidates of a race: K distinct paths from the scene's start to its goal, each route the
scene names getting candidates in turn (planned through a pose inside it), the rest plan_many's
distinct plans. Candidate k is planned with a seed from cfg.seed on."""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import replace as dataclass_replace

import numpy as np

from roachplan.planning import PlanResult

from ._choose_candidate import Candidate
from ._choose_config import ChooseConfig
from ._trial import MIN_ATTEMPT_TIME, _resample, plan_many, start_plan


def plan_candidates(world, cfg: ChooseConfig, *, budget: float | None = None) -> list[Candidate]:
    """K distinct candidate paths. Where the scene names routes, each route gets candidates in
    turn, planned through a via pose inside it (a planner left alone takes the easiest route
    every time: a wide bridge, never the narrow one beside it); the rest, or all of them on a
    scene without routes, are plan_many's distinct plans. budget: wall time [s] (None: none)."""
    deadline = None if budget is None else time.monotonic() + budget
    picked: list[tuple[str, PlanResult]] = []
    shapes: list[np.ndarray] = []

    def add(route: str, planned: PlanResult) -> None:
        shape = _resample(planned.path_xyz[:, :2], 50)
        if all(np.mean(np.linalg.norm(shape - s, axis=1)) >= 0.02 for s in shapes):
            shapes.append(shape)
            picked.append((route, planned))

    vias = {
        name: v
        for name, region in world.scene.routes
        if (v := _via_pose(world, region)) is not None
    }
    tries, misses = 0, Counter()
    while vias and len(picked) < cfg.candidates and tries < 3 * cfg.candidates:
        for name, via in list(vias.items()):
            if len(picked) >= cfg.candidates or (deadline and time.monotonic() > deadline):
                break
            planned = _plan_via(world, via, seed=cfg.seed + tries, deadline=deadline)
            before = len(picked)
            if planned is not None and world.route(planned.path_xyz[:, :2]) == name:
                add(name, planned)
            misses[name] = 0 if len(picked) > before else misses[name] + 1
            if misses[name] >= 3:  # three plans in a row gave nothing new on this route
                del vias[name]
        tries += 1
    if len(picked) < cfg.candidates:
        left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
        for lp in plan_many(world, 3 * cfg.candidates, seed=cfg.seed, budget=left):
            if len(picked) < cfg.candidates:
                add(lp.route, lp.plan)
    out = []
    for i, (route, planned) in enumerate(picked):
        xyz = planned.path_xyz
        length = float(np.sum(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1)))
        out.append(
            Candidate(
                index=i,
                route=route,
                seed=planned.seed,
                path_xyz=xyz,
                length=max(length, 1e-6),
                spins=planned.spins,
            )
        )
    return out


def _via_pose(world, region) -> tuple[float, float, float] | None:
    """A pose inside the route's region ((xmin, ymin), (xmax, ymax)) where the robot can
    stand, heading from start to goal: the standable cell nearest the region's centre."""
    from roachplan.scenes import pose_problem

    sc = world.scene
    heading = math.atan2(sc.goal[1] - sc.start[1], sc.goal[0] - sc.start[0])
    (x0, y0), (x1, y1) = region
    cells = world.regions.cell_centres(world.regions.standable)
    inside = cells[
        (cells[:, 0] >= x0) & (cells[:, 0] <= x1) & (cells[:, 1] >= y0) & (cells[:, 1] <= y1)
    ]
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    for xy in inside[np.argsort(np.linalg.norm(inside - centre, axis=1))][:20]:
        for yaw in (heading, heading + math.pi):
            pose = (float(xy[0]), float(xy[1]), yaw)
            if not pose_problem(world, pose):
                return pose
    return None


def _plan_via(world, via, *, seed: int, deadline: float | None = None) -> PlanResult | None:
    """start -> via -> goal as one path (each leg planned with this seed, within what is left
    of the planning budget at `deadline`, time.monotonic()), or None. The two legs plan at
    once, in two children, so the pair takes about the wall time of the longer (choose's
    workers wait for the candidates); each is the plan it is alone (a plan stops on its
    iteration budget), unless one hits its time limit, which two on a busy core reach sooner.
    Its plan_time is the sum of the legs'."""
    sc = world.scene
    legs = []
    try:
        for a, b in ((sc.start, via), (via, sc.goal)):
            legs.append(
                start_plan(world, seed=seed, start=a, goal=b, planner=_within(sc.planner, deadline))
            )
        first = legs[0].result()
        if not first.found:
            return None  # (the second leg is cancelled below)
        second = legs[1].result()
    finally:
        for leg in legs:  # (the second when the first found none; on an error, or Ctrl-C)
            leg.cancel()
    if not second.found:
        return None
    return dataclass_replace(
        first,
        states=np.vstack([first.states, second.states[1:]]),
        path_xyz=np.vstack([first.path_xyz, second.path_xyz[1:]]),
        # The second leg's waypoints follow the first's, which end on its first.
        spins=first.spins + tuple((k + len(first.path_xyz) - 1, yaw) for k, yaw in second.spins),
        plan_time=first.plan_time + second.plan_time,
        message=f"through ({via[0]:.2f}, {via[1]:.2f}): {first.message}; {second.message}",
    )


def _within(planner, deadline: float | None):
    """The planner with its time limit cut to what is left before deadline (time.monotonic())."""
    if deadline is None:
        return planner
    left = max(deadline - time.monotonic(), MIN_ATTEMPT_TIME)
    return dataclass_replace(planner, time_limit=min(planner.time_limit, left))
