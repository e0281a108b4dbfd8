"""The Python API: a few typed functions over the same code the command line runs, for notebooks
and scripts. Each call here is one `roachplan` command:

    world = roachplan.load("double_bridge")          # `--scene`: a name, a scene file, a terrain
    path = roachplan.plan(world, seed=3)              # `roachplan plan`
    trial = roachplan.drive(world, path)              # `roachplan trial` = plan + drive
    choice = roachplan.choose(world, candidates=4)    # `roachplan choose`
    report = roachplan.experiment("bridge_rough", trials=10, out="results/")

Frames and units are the library's: world frame z up, ground at z = 0, metres, poses
(x [m], y [m], yaw [rad]). Every random choice comes from the seed given (or the scene's).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the heavy modules load on first use, not on `import roachplan`
    from roachplan.experiments import Choice, ExperimentReport, TrialResult
    from roachplan.perception import Reconstruction
    from roachplan.planning import PlannerConfig, PlanResult
    from roachplan.scenes import World

Pose = tuple[float, float, float]
"""(x [m], y [m], yaw [rad]) in the world frame."""


def load(
    scene: str | os.PathLike,
    *,
    scale: float | None = None,
    scad_backend: str | None = None,
    engine: str | None = None,
) -> World:
    """A world ready to plan and drive on: a library scene's name ("double_bridge"), a scene
    .yaml, or any terrain file (a capture: .pcd .ply .xyz .npy, a 16-bit depth PNG, a ROS bag;
    a mesh; a .scad). A terrain file's start and goal are picked where the robot can stand
    (`world.notes` says how, and who rendered an OpenSCAD model). scale: multiplies the
    terrain (0.001 for a model in millimetres). scad_backend: who renders every OpenSCAD
    model, `--scad-backend` ("auto", "cgal" or "manifold"; default: each object's `backend:`,
    else "auto"). engine: the physics engine of its drives and choices, `--engine`
    ("pybullet", the reference, or "mujoco", the fast one; default: the scene's `sim.engine`)."""
    from roachplan.scenes import (
        build_world,
        load_scene,
        scaled_scene,
        with_engine,
        with_scad_backend,
    )

    loaded = load_scene(os.fspath(scene))
    if scale is not None:
        loaded = scaled_scene(loaded, scale)
    if scad_backend is not None:
        loaded = with_scad_backend(loaded, scad_backend)
    if engine is not None:
        loaded = with_engine(loaded, engine)
    return build_world(loaded)


def plan(
    world: World,
    *,
    seed: int | None = None,
    planner: str | PlannerConfig | None = None,
    time_limit: float | None = None,
    start: Pose | None = None,
    goal: Pose | None = None,
) -> PlanResult:
    """One OMPL plan from start to goal (default: the scene's) with the scene's planner, or the
    one named ("prm", "rrtconnect", ...; roachplan.planning.PLANNER_NAMES) or configured.
    `result.found`, `result.path_xyz` ((N, 3) world frame [m]), `result.spins` (turns on the
    spot: waypoint index, heading [rad]), `result.plan_time` [s]."""
    from roachplan.experiments import plan as plan_trial

    scene = world.scene
    return plan_trial(
        world,
        seed=scene.seed if seed is None else seed,
        start=start,
        goal=goal,
        planner=_planner(world, planner, time_limit),
    )


def drive(
    world: World, planned: PlanResult, *, start: Pose | None = None, goal: Pose | None = None
) -> TrialResult:
    """Drive a plan in a fresh world of the scene's engine and record the trial: `outcome` ("success",
    "fell", "flipped", "stuck", "timeout", "no_path"), `drive_time` [s], `energy` [J],
    `relative_energy` (1.0 = walking straight on a floor), `trajectory` (world frame [m])."""
    from roachplan.experiments import finish_trial

    return finish_trial(world, planned, start=start or world.start, goal=goal or world.goal)


def trial(
    world: World, *, seed: int | None = None, planner: str | PlannerConfig | None = None
) -> TrialResult:
    """Plan, then drive: `roachplan trial` (the same seed gives the same trial)."""
    from roachplan.experiments import run_trial

    return run_trial(
        world,
        seed=world.scene.seed if seed is None else seed,
        planner=_planner(world, planner, None),
    )


def choose(
    world: World,
    *,
    candidates: int = 8,
    budget_s: float | None = 60.0,
    rollouts: int | None = None,
    confidence: float = 0.95,
    min_success: float | None = None,
    seed: int = 0,
    workers: int = 1,
    quick: bool = False,
    cross_check: bool = False,
) -> Choice:
    """Which path should the robot take: K candidate paths screened by simulation under the
    scene's uncertainty model, the chosen one certified on fresh rollouts (`roachplan
    choose`). `choice.ranking` (best first: P(success) with its interval, energy, drive time,
    failures), `choice.chosen` (an index into `choice.candidates`, None when nothing
    succeeded), `choice.guarantee` (what the choice is shown to be, at `confidence`:
    `.sentence(choice.chosen)` says it in words), `choice.stopped` (why it ended). quick: the
    quick mode (succeeds at least 90 % of the time, within 10 % of the lowest energy; the
    default 95 % and 5 %). cross_check: every rollout driven again under the other physics
    engine (`choice.cross_check`: per path, success and energy under each, and whether they
    agree)."""
    from roachplan.experiments import DEFAULT_MODE, QUICK_MODE, ChooseConfig
    from roachplan.experiments import choose as race_candidates

    cfg = ChooseConfig(
        candidates=candidates,
        rollouts=rollouts,
        budget_s=budget_s,
        confidence=confidence,
        min_success=min_success,
        seed=seed,
        indifference=QUICK_MODE if quick else DEFAULT_MODE,
    )
    choice, _ = race_candidates(world, cfg, workers=workers, cross_check=cross_check)
    return choice


def experiment(
    spec: str | os.PathLike,
    *,
    trials: int,
    out: str | os.PathLike,
    workers: int = 2,
    resume: bool = False,
    progress: bool = False,
    engine: str | None = None,
    cross_check: bool = False,
    repeats: int | None = None,
) -> ExperimentReport:
    """A batch of trials in parallel with its tables and figures (`roachplan experiment`):
    a library spec's name ("bridge_rough") or a spec .yaml; results in `out` (new, empty, or
    an experiment's folder to resume). `report.table`, `report.summaries`, `report.best`.
    engine: `--engine` (default: the spec's `sim.engine`). cross_check: every trial's path
    driven again under the other engine (`report.cross_check`, per route). repeats: re-drives
    of the best path (`--repeats`; default: the spec's `best_path.repeats`)."""
    import dataclasses

    from roachplan.experiments import load_experiment, run_experiment
    from roachplan.scenes import with_engine

    loaded = load_experiment(os.fspath(spec))
    if repeats is not None:  # (the spec's setting checks it, as the spec file's)
        loaded = dataclasses.replace(loaded, best_path_repeats=repeats)
    return run_experiment(
        loaded if engine is None else with_engine(loaded, engine),
        trials=trials,
        out=Path(out),
        workers=workers,
        resume=resume,
        progress=progress,
        cross_check=cross_check,
    )


def mesh(capture: str | os.PathLike, **settings) -> Reconstruction:
    """A capture's terrain mesh (`roachplan mesh`): `settings` are the scene file's
    `perception:` keys (voxel, method, up, camera_pose, crop, depth_range, intrinsics, ...).
    `rec.mesh` (trimesh, world frame [m]), `rec.report()` (camera pose, ground, warnings)."""
    from roachplan.perception import capture_settings, mesh_capture

    path = Path(capture)
    return mesh_capture(path, capture_settings(settings, resolve=lambda p: path.parent / p))


def _planner(world: World, planner, time_limit: float | None):
    """The scene's planner config, with another planner's name or a whole config, and a time
    limit [s] (the budget of the plan, every try included); the config checks them
    (SettingError naming the setting and what it accepts)."""
    from roachplan.planning import PlannerConfig

    cfg = world.scene.planner
    if isinstance(planner, PlannerConfig):
        cfg = planner
    elif planner is not None:
        cfg = dataclasses.replace(cfg, name=planner)
    if time_limit is not None:
        cfg = dataclasses.replace(cfg, time_limit=time_limit)
    return cfg
