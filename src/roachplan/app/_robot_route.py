"""Route from robot (the page's Robot folder): the plan from where the robot stands, as the
command line's re-plan makes it (robot.plan_start, robot.replan_radius, clear of where the
last look-ahead's rollouts failed, in from an edge it stands at first (robot.step_in), or on
along the old path after a drift hold), what a leg carries from the last one of the same
robot, the simulation's prediction of the plan, and the leg's log with its plan. Each runs on
the app's command loop (do_robot_plan calls them)."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roachplan.experiments import LabelledPlan, TrialResult
from roachplan.planning import PlanningError, PlanResult

if TYPE_CHECKING:
    from ._app import App
    from ._robot_panel import RobotForm, RobotSession


class RouteCancelled(PlanningError):
    """Route from robot's plan job was cancelled (Cancel): no second plan is tried after it."""


def held_text(stands, route: Route, waypoints: int, prediction) -> str:
    """What Route from robot says once the robot is held: where it stands (x, y [m], yaw
    [rad]), the route (how far its start was moved, its widened arcs, how far it keeps from
    where the last look-ahead's rollouts failed, or why it drives on along the old path), the
    plan, the simulation's prediction (a TrialResult, or None)."""
    from roachplan.robot import SPIN_ONLY_RADIUS

    said = (
        f"the simulation predicts **{prediction.outcome}** in {prediction.drive_time:.1f} s"
        if prediction is not None
        else "the simulation of the plan failed"
    )
    notes = ""
    if route.moved > 0:
        notes += (
            f" (planned from {100 * route.moved:.1f} cm away: the planner refuses where it stands)"
        )
    if route.step_in is not None:
        notes += (
            f" (first {100 * math.dist(stands[:2], route.step_in[:2]):.0f} cm in from the "
            "edge it stands at: a turn on the spot and a line)"
        )
    if route.drove_on is not None:
        what = f"no re-plan ({route.drove_on}): on along the rest of the path it drifted off"
    else:
        what = f"planned {waypoints} waypoints (black)"
        if route.wider == SPIN_ONLY_RADIUS:
            what += " of straight lines and turns on the spot (it " + (
                "made no progress along its path)" if route.stalled else "drifted off arcs)"
            )
        elif route.wider is not None:
            what += f" with arcs of {route.wider:.2f} m (it drifted off narrower ones)"
        if route.avoid:
            what += (
                f"; the {len(route.avoid)} places the look-ahead's rollouts failed are all "
                "next to the robot"
                if route.clearance is None
                else f"; it keeps {route.clearance:.2f} m from the {len(route.avoid)} places "
                "the look-ahead's rollouts failed"
            )
    return (
        f"Robot at ({stands[0]:.3f}, {stands[1]:.3f}) m, {math.degrees(stands[2]):.0f} deg"
        f"{notes}: {what}; {said} (blue). The robot is held: press **Go**."
    )


@dataclass(frozen=True, kw_only=True, eq=False)
class Carried:
    """What a Route from robot goes on from, of the last leg of the same robot (carried_from)."""

    estimates: tuple = ()
    """The motors' mismatch estimated so far ((mismatch, walked [m]) each)."""
    drifts: int = 0
    """The guard's drift holds in a row (robot.replan_radius widens the arcs)."""
    stalled: bool = False
    """The guard held the last leg, or one before it of the legs it held in a row, for making
    no progress (robot.replan_radius: lines and turns on the spot)."""
    avoid: tuple[tuple[float, float], ...] = ()
    """Where the last look-ahead's rollouts failed (x, y [m]), when the guard held the last
    leg: the re-plan keeps clear of them (robot.plan_clear_of's rule)."""
    drifted: Any = None
    """The last leg's RobotSession, when the guard held it for drifting: with no re-plan,
    the robot drives on along the rest of its path (robot.rejoin_plan)."""


@dataclass(frozen=True, kw_only=True, eq=False)
class Route:
    """What Route from robot planned (route_from)."""

    plan: PlanResult
    here: tuple[float, float, float]
    """The plan's start (x, y [m], yaw [rad])."""
    moved: float = 0.0
    """How far that start lies from where the robot stands [m] (robot.plan_start)."""
    wider: float | None = None
    """The radius of its arcs [m] when widened after drift holds or a stall hold (None: the
    scene's)."""
    stalled: bool = False
    """Lines and turns on the spot because the guard held the last leg, or one before it in a
    row, for making no progress (Carried.stalled)."""
    avoid: tuple[tuple[float, float], ...] = ()
    """The places it was to keep clear of (Carried.avoid)."""
    clearance: float | None = None
    """How far its path keeps from them [m] (robot.clearance; None: none to keep from)."""
    drove_on: str | None = None
    """Why no re-plan was found, when the robot drives on along the old path instead."""
    step_in: tuple[float, float, float] | None = None
    """The pose (x, y [m], heading [rad]) it walks to, in from an edge it stands at, before the
    plan (robot.step_in; None: it stands clear of every edge)."""


def route_from(app: App, stands, goal, carried: Carried) -> Route:
    """The plan from the robot standing at `stands` (x, y [m], yaw [rad]) to goal, as the
    command line's re-plan: from the nearest pose the planner takes (robot.plan_start: a
    robot the guard held with a foot over an edge), its arcs widened after drift holds in a
    row, lines and turns on the spot after a stall hold (robot.replan_radius), clear of where
    the last look-ahead's rollouts failed, walking in first from an edge it stands at
    (robot.step_in); after a drift hold with no plan found, the rest of the old path from
    where the robot stands (robot.rejoin_plan)."""
    from roachplan.processes import ChildError
    from roachplan.robot import (
        RobotError,
        RobotSettings,
        plan_start,
        rejoin_plan,
        replan_radius,
        step_in,
        stepped_plan,
    )

    radius = app.world.scene.planner.turning_radius
    wider = None
    if radius is not None and (carried.drifts or carried.stalled):  # (it drifted off arcs
        # this wide, or made no progress on them: wider ones, or lines and spins)
        wider = radius = replan_radius(radius, carried.drifts, stalled=carried.stalled)
    keep = RobotSettings().edge_keep  # (the command line's: the page has no box for it)
    try:
        here, moved = plan_start(app.world, stands)
        # (within edge_keep of an edge: planned from where it steps in to, walked there from
        # where it stands; none found from there, from here)
        inner = None if keep is None else step_in(app.world, here, keep)
        try:
            plan, keeps = plan_from(
                app, inner or here, goal, turning_radius=radius, avoid=carried.avoid
            )
        except PlanningError as exc:
            if inner is None or isinstance(exc, RouteCancelled):
                raise
            inner = None
            plan, keeps = plan_from(app, here, goal, turning_radius=radius, avoid=carried.avoid)
        if inner is not None:
            plan = stepped_plan(app.world, plan, stands)
            show_plan(app, plan, here, goal)  # (Drive's start: the robot's, not the step's)
    except (RobotError, PlanningError, ChildError) as exc:
        old = carried.drifted
        if old is None or old.plan is None:
            raise
        plan = rejoin_plan(
            old.path,
            old.spins,
            stands[:2],
            seed=old.plan.seed,
            turning_radius=old.plan.turning_radius,
        )
        show_plan(app, plan, stands, goal)
        return Route(plan=plan, here=tuple(stands), drove_on=str(exc))
    return Route(
        plan=plan,
        here=here,
        moved=moved,
        step_in=inner,
        wider=wider,
        stalled=carried.stalled,
        avoid=carried.avoid,
        clearance=None if math.isinf(keeps) else keeps,
    )


def carried_from(before: RobotSession | None, key: tuple) -> Carried:
    """What a Route from robot goes on from: the last leg's, when it drove the same robot
    (pose source and settings: `key`); nothing for another robot. The mismatch estimates;
    the drift holds in a row (a drift hold's leg adds one; a leg routed again before Go
    counts as that leg; any other end starts the count again); whether the guard held it, or
    a leg before it held in a row, for making no progress (a stall: lines and turns on the
    spot from then on); after a guard's hold, where its last look-ahead's rollouts
    failed, and after a drift hold, the leg itself."""
    from roachplan.robot import GUARD_HOLDS

    if before is None or before.source_key != key:
        return Carried()
    if not before.went:
        return Carried(estimates=before.estimates, drifts=before.drifts, stalled=before.stalled)
    reason = before.result.reason if before.result is not None else None
    held = reason in GUARD_HOLDS
    return Carried(
        estimates=before.estimates,
        drifts=before.drifts + 1 if reason == "drift" else 0,
        stalled=reason == "stall" or (held and before.stalled),
        avoid=tuple((x, y) for x, y, _ in before.lookaheads[-1].failures)
        if held and before.lookaheads
        else (),
        drifted=before if reason == "drift" else None,
    )


def show_plan(app: App, plan: PlanResult, start, goal) -> None:
    """A plan route_from made of a planned one (the walk in from an edge first, or the rest of
    the old path) as the app's only plan, drawn black, Drive's from start (x, y [m], yaw [rad])
    to goal."""
    app.plan_endpoints = (tuple(start), goal)
    app.set_plans([LabelledPlan(route=app.world.route(plan.path_xyz[:, :2]), plan=plan)])


def plan_from(
    app: App, here, goal, *, turning_radius: float | None = None, avoid=()
) -> tuple[PlanResult, float]:
    """(a plan from the robot's pose to the goal marker, its clearance [m]: robot.clearance,
    inf with none to keep from): a plan job, followed (Cancel stops it), drawn black as the
    app's plan; its arcs of turning_radius [m] (None: the scene's). avoid: points (x, y) [m]
    it keeps robot.AVOID_RADIUS from (those that far from here), and it keeps the command
    line's RobotSettings.edge_keep from the drop-offs (the page has no box for it): up to
    robot.EDGE_TRIES distinct plans (AVOID_TRIES without edge_keep), the first that keeps
    clear of both, else the clearest (robot.plan_clear_of's rule, robot.plan_keeps)."""
    from roachplan.robot import (
        AVOID_RADIUS,
        AVOID_TRIES,
        EDGE_TRIES,
        RobotSettings,
        clearance,
        edge_margin,
        plan_keeps,
    )

    from ._jobs import _plan_job, failure

    points = [p for p in avoid if math.dist(p[:2], here[:2]) >= AVOID_RADIUS]
    keep = RobotSettings().edge_keep
    tries = EDGE_TRIES if keep is not None else AVOID_TRIES if points else 1

    planner = app.planner(app.page.plan_settings())
    if turning_radius is not None and planner.turning_radius is not None:
        planner = dataclasses.replace(planner, turning_radius=turning_radius)
    deadline = time.monotonic() + planner.time_limit
    request = dict(seed=app.next_seed, start=here, goal=goal, planner=planner)
    app.page.view.clear("/trajectories")
    app.page.view.remove("/live")
    job = app.world_job(_plan_job, tries, request, deadline)
    found: list = []  # (LabelledPlan, its clearance [m], its plan_keeps) each

    def planning(events: list) -> bool:
        for a in events:
            if a.plan is not None:
                path = a.plan.plan.path_xyz
                clear = clearance(path, points)
                margin = math.inf if keep is None else edge_margin(app.world, path, keep)
                found.append((a.plan, clear, plan_keeps(clear, margin, AVOID_RADIUS, keep)))
        if found and found[-1][2] >= 1.0:  # (clear of both: no more tries)
            return True
        app.loop.progress(
            job.elapsed / planner.time_limit,
            f"Robot: planning from where it stands ({here[0]:.3f}, {here[1]:.3f}), "
            f"{job.elapsed:.1f} s",
        )
        return job.done

    end = app.loop.follow(job, "Route from robot", planning, hard_stop=deadline + 0.8)
    app.next_seed += 1
    if end == "cancelled" or not found:
        why = failure(job) or ("cancelled" if end == "cancelled" else "no path found")
        error = RouteCancelled if end == "cancelled" else PlanningError
        raise error(f"no plan from where the robot stands: {why}")
    app.plan_endpoints = (here, goal)
    best, keeps, _ = max(found, key=lambda f: f[2])  # (the first of equals: the first found)
    app.set_plans([best])  # (black; Drive simulates it too)
    return best.plan, keeps


def predict_from(app: App, plan: PlanResult, here, goal) -> TrialResult | None:
    """The simulation of the plan from the robot's pose (a drive job, followed), drawn blue."""
    from roachplan.processes import Returned

    from ._draw import BLUE
    from ._jobs import _drive_job

    drive = app.world_job(_drive_job, plan, here, goal)

    def predicting(events: list) -> bool:
        app.loop.progress(None, f"Robot: simulating the plan from the robot, {drive.elapsed:.1f} s")
        return drive.done

    app.loop.follow(drive, "Route from robot", predicting)
    outcome = drive.outcome
    if not isinstance(outcome, Returned) or not isinstance(outcome.value, TrialResult):
        return None
    prediction = outcome.value
    app.page.view.draw("/trajectories/prediction", [r[1:] for r in prediction.trajectory], BLUE)
    return prediction


def leg_recorder(
    app: App,
    form: RobotForm,
    *,
    transform,
    plan: PlanResult,
    here,
    stands,
    goal,
    prediction,
    route: Route | None = None,
):
    """(the log's path, its RunRecorder) with the scene, the settings, the plan (from `here`,
    the robot standing at `stands`: x, y [m], yaw [rad]) and the prediction written: beside
    the app's uploads, in robot-runs/."""
    from roachplan.robot import RunRecorder, scene_record

    log_dir = app.upload_dir / "robot-runs"
    log_dir.mkdir(exist_ok=True)
    stem = f"{app.world.scene.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    log, n = log_dir / f"{stem}.mcap", 1
    while log.exists() or log.with_name(log.name + ".partial").exists():  # (a leg this second)
        n += 1
        log = log_dir / f"{stem}-{n}.mcap"
    recorder = RunRecorder(log)
    t = time.monotonic()
    scene_path = Path(app.world.scene.path)
    scene_file = scene_path if scene_path.is_file() else None
    recorder.write("/scene", t, scene_record(scene_file, app.world.scene.name))
    settings = {
        "source": form.source,
        "source_settings": form.source_settings,
        "link": form.link,
        "link_settings": form.link_settings,
        "transform": transform.to_json(),
        "transform_measured": form.transform is None,
        "page": True,
    }
    recorder.write("/settings", t, settings)
    recorder.write(
        "/plan",
        t,
        {
            "path": np.asarray(plan.path_xyz).tolist(),
            "spins": [list(s) for s in plan.spins],
            "planner": plan.planner,
            "seed": plan.seed,
            "start": list(here),
            # (as the command line's: how far that start lies from where the robot stood [m],
            # where it stood, the radius of the plan's arcs [m]; null: no arcs)
            "start_moved": math.dist(here[:2], stands[:2]),
            "step_in": list(route.step_in) if route and route.step_in else None,
            "robot_pose": list(stands),
            "goal": list(goal),
            "turning_radius": plan.turning_radius,
            # (where the last look-ahead's rollouts failed, and how far the path keeps from
            # them [m]; null: none to keep clear of)
            "avoid": [list(p) for p in (route.avoid if route else ())],
            "clearance": route.clearance if route else None,
        },
    )
    if prediction is not None:
        frames = [[r[0], r[1], r[2], r[3], here[2]] for r in prediction.trajectory]
        recorder.write(
            "/prediction",
            t,
            {
                "start": list(here),
                "outcome": prediction.outcome,
                "reason": prediction.reason,
                "drive_time": prediction.drive_time,
                "trajectory": frames,
            },
        )
    return log, recorder
