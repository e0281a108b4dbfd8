"""The handlers of the Plan and drive folder and of Results, run on the app's command loop: Plan
(up to K distinct paths within one time budget for every try, each drawn as it is found), Drive
and Best path (a drive in a child, played back as its frames come), Reset, Show trial and Export
CSV. A plan or a drive is followed by `app.loop.follow`: progress and elapsed time on the page,
Cancel at once.
"""

from __future__ import annotations

import time

import numpy as np

from roachplan.experiments import TrialResult
from roachplan.planning import PlanResult
from roachplan.processes import Returned
from roachplan.sim import Frame

from ._app import App
from ._commands import (
    BestPathCmd,
    Cmd,
    DriveCmd,
    EngineCmd,
    ExportCmd,
    PlanCmd,
    ResetCmd,
    ShowTrialCmd,
)
from ._draw import BLACK, BLUE, path_fraction
from ._jobs import Attempt, _drive_job, _plan_job, failure, with_page_engine
from ._panel import trials_csv

PLAN_GRACE = 0.8
"""How long past its budget a plan's child may run before it is killed [s]: it stops by itself
at the budget; this bounds what the wrap-up of its last attempt may add."""


def do_plan(app: App, cmd: PlanCmd) -> None:
    """Up to K distinct paths within one time budget for all tries (plan_many), each drawn
    as it is found; Cancel keeps those found so far."""
    start, goal = app.page.markers.valid_poses(app.world)
    settings = app.page.plan_settings()
    count, seed, planner = settings.count, app.next_seed, app.planner(settings)
    budget, deadline = planner.time_limit, time.monotonic() + planner.time_limit
    app.page.show_robot_at_start()
    # Only what this plan finds is shown: no earlier paths, roadmap or trajectories.
    app.set_plans([])
    app.page.view.clear("/trajectories")
    tried, plans, errors = [], [], []
    request = dict(seed=seed, start=start, goal=goal, planner=planner)
    job = app.world_job(_plan_job, count, request, deadline)

    def step(events: list[Attempt]) -> bool:
        for attempt in events:
            tried.append(attempt.seed)
            # A "path" of one waypoint (start and goal one point) is nothing to drive.
            if attempt.plan is not None and len(attempt.plan.plan.path_xyz) >= 2:
                plans.append(attempt.plan)
                app.page.view.add_path(attempt.plan.plan.path_xyz)
        if failure(job) and not errors:
            errors.append(failure(job))
        t = job.elapsed
        app.loop.progress(
            t / budget,
            f"Planning with {planner.name}: {len(plans)} of {count} "
            f"path(s), {len(tried)} tried (seeds from {seed}); {t:.1f} s of the "
            f"{budget:g} s budget",
        )
        return job.done

    end = app.loop.follow(job, "Plan", step, hard_stop=deadline + PLAN_GRACE)
    elapsed = job.elapsed
    app.next_seed = seed + len(tried) + (end != "done")
    if errors:
        app.page.view.hide_paths()  # (Drive stays off: no half-plan is left drawn as current)
        app.page.set_status(f"Planning failed: {errors[0]}")
        app.page.notify(cmd.client_id, "Planning failed", errors[0], error=True)
        return
    app.plan_endpoints = (start, goal)
    app.set_plans(plans, drawn=True)  # (drawn as they were found)
    seeds = f"seeds {seed}-{seed + len(tried) - 1}" if len(tried) > 1 else f"seed {seed}"
    tries = f"{len(tried)} {'try' if len(tried) == 1 else 'tries'}"
    routes = ", ".join(lp.route for lp in plans)
    spent = end == "stopped" or (
        end == "done" and len(plans) < count and len(tried) < 3 * count + 10
    )
    if end == "cancelled":
        kept = f"; {len(plans)} path(s) kept" if plans else ""
        text = f"Plan cancelled after {elapsed:.1f} s{kept}."
    elif not plans:
        why = f": the {budget:g} s budget is spent" if spent else ""
        text = f"No path found in {elapsed:.1f} s{why} ({planner.name}, {tries}, {seeds})."
    elif spent:
        text = (
            f"{len(plans)} of {count} paths found in {elapsed:.1f} s: the {budget:g} s "
            f"budget is spent ({seeds}; routes {routes}). **Drive** drives the marked one "
            f"(choose it in *Drive path*)."
        )
    elif count == 1:
        first = plans[0].plan
        text = f"Path found in {first.plan_time:.2f} s (seed {first.seed}). Press **Drive**."
        if len(tried) > 1:
            text += f" ({tries}, {elapsed:.1f} s in all)"
    else:
        text = (
            f"{len(plans)} paths found in {elapsed:.1f} s (seeds "
            f"{', '.join(str(lp.plan.seed) for lp in plans)}; routes {routes}). "
            f"**Drive** drives the marked one "
            f"(choose it in *Drive path*)."
        )
    app.page.set_status(text)


def do_drive(app: App, cmd: DriveCmd) -> None:
    """Drive the path marked for Drive; its trial joins the results."""
    if not app.plans or app.plan_endpoints is None:
        # (Drive is disabled then; a click sent before it was, or from a stale page, lands here)
        text = "There is no planned path to drive: press Plan and wait for a path first."
        app.page.set_status(text)
        app.page.notify(cmd.client_id, "Nothing to drive", text, error=True)
        return
    start, goal = app.plan_endpoints
    if not app.page.view.path_nodes:  # (hidden by Best path or Show trial: show what is driven)
        app.page.show_plans(app.plans, app.drive_path)
    result = drive(app, app.plans[app.drive_path].plan, start, goal, cmd)
    if result is not None:
        app.record(result.to_json(), "")


def drive(
    app: App, planned: PlanResult, start, goal, cmd: Cmd, *, name: str = "Drive"
) -> TrialResult | None:
    """Drive in a child and play its frames back at the playback speed x real time as they
    come (every frame the browser can take: at most 60 per second)."""
    app.page.view.clear("/trajectories")
    job = app.world_job(_drive_job, planned, start, goal)
    frames, results, errors = [], [], []
    path_xy = np.asarray(planned.path_xyz)[:, :2]
    play = {"t": 0.0, "wall": time.monotonic(), "k": -1, "drawn": 0.0}

    def step(events: list[Frame]) -> bool:
        frames.extend(events)
        if job.done and not (results or errors):
            if isinstance(job.outcome, Returned):
                results.append(job.outcome.value)
            else:
                errors.append(failure(job) or "the driving process ended without a result")
        now = time.monotonic()
        play["t"] += (now - play["wall"]) * max(app.page.playback_speed(), 1.0)
        play["wall"] = now
        k = play["k"]
        while k + 1 < len(frames) and frames[k + 1].t <= play["t"]:
            k += 1
        if k > play["k"]:
            play["k"], f = k, frames[k]
            app.page.show_frame(f)
            if now - play["drawn"] > 0.2:  # (the line and the words 5 times a second)
                app.page.view.draw(
                    "/trajectories/current", [g.p_world_body for g in frames[: k + 1]], BLUE
                )
                play["drawn"] = now
                done = path_fraction(path_xy, f.p_world_body)
                app.loop.progress(
                    done,
                    f"{name}: {100 * done:.0f} % of the path, {f.t:.1f} s "
                    f"simulated, {job.elapsed:.1f} s",
                )
        return job.done and (bool(errors) or play["k"] >= len(frames) - 1)

    end = app.loop.follow(job, name, step)
    app.page.view.draw(
        "/trajectories/current", [g.p_world_body for g in frames[: play["k"] + 1]], BLUE
    )
    if end != "done":
        app.page.set_status(f"{name} cancelled after {job.elapsed:.1f} s; no trial recorded.")
        return None
    if errors or not results:
        why = errors[0] if errors else "the driving process ended without a result"
        app.page.set_status(f"{name} failed: {why}")
        app.page.notify(cmd.client_id, f"{name} failed", why, error=True)
        return None
    return results[0]


def do_best_path(app: App, cmd: BestPathCmd) -> None:
    """The report's best_path: drive the lowest-energy successful path again."""
    ok = [(k, t) for k, t in enumerate(app.scene_trials) if t["outcome"] == "success" and t["path"]]
    if not ok:
        app.page.notify(
            cmd.client_id, "No best path yet", "Drive or run trials until one succeeds.", error=True
        )
        return
    k, best = min(ok, key=lambda kt: kt[1]["relative_energy"])
    planned = stub_plan(best)
    app.page.view.hide_paths()  # (the plan's paths and roadmap: Drive shows them again)
    app.page.view.draw("/plans/best", np.asarray(best["path"]) + [0, 0, 0.005], BLACK)
    result = drive(app, planned, tuple(best["start"]), tuple(best["goal"]), cmd, name="Best path")
    if result is not None:
        app.record(result.to_json(), f"best (trial {k + 1})")


def stub_plan(trial: dict):
    """The PlanResult of a stored trial's path (to drive it again)."""
    return PlanResult(
        found=True,
        planner=trial["planner"],
        seed=trial["seed"],
        states=np.zeros((0, 3)),
        path_xyz=np.asarray(trial["path"]),
        plan_time=0.0,
        message="stored path",
        spins=tuple(tuple(s) for s in trial.get("spins") or ()),
    )


def do_reset(app: App, cmd: ResetCmd) -> None:
    """The roach back at the start marker, no trajectory drawn."""
    app.page.show_robot_at_start()
    app.page.view.clear("/trajectories")
    app.page.set_status("Robot back at the start.")


def show_trial(app: App, cmd: ShowTrialCmd) -> None:
    """Draw the trial chosen in Show trial again: its path and trajectory."""
    k = app.page.shown_trial()
    if k is None:
        return
    t = app.scene_trials[k - 1]
    app.page.view.hide_paths()
    app.page.view.clear("/trajectories")
    app.page.view.draw("/plans/shown", np.asarray(t["path"]) + [0, 0, 0.005], BLACK)
    app.page.view.draw("/trajectories/shown", [p[1:] for p in t["trajectory"]], BLUE)
    app.page.set_status(f"Trial {k}: {t['outcome']} ({t['reason']}).")


def do_export(app: App, cmd: ExportCmd) -> None:
    """The scene's trials as CSV, a download to the browser that clicked."""
    app.page.send_file(
        cmd.client_id,
        f"{app.world.scene.name}-trials.csv",
        trials_csv(app.scene_trials).encode(),
    )


def do_engine(app: App, cmd: EngineCmd) -> None:
    """The Physics engine picker: this world, and every one loaded after it, simulated by the
    engine chosen (as it was calibrated); its host restarted with it, so that the next drive
    runs there. Plans, trials and markers stay: a plan does not depend on the engine."""
    if cmd.engine == app.world.scene.sim.engine:
        return  # (the picker set to show the world's engine calls back)
    app.engine = cmd.engine
    app.world = with_page_engine(app.world, cmd.engine)
    app.host_world()
    sim = app.world.scene.sim
    app.page.set_status(f"Drives now run in {cmd.engine} ({sim.timestep * 1000:g} ms steps).")
