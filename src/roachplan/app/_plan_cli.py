"""`roachplan trial`, `plan` and `benchmark`: planning, and driving, on one scene.

A planning budget (`--time-limit`, else the scene's planner time_limit) bounds one planning
request: `trial`'s plan, every seed and try of `plan --count K`, each run of a benchmark.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from roachplan.experiments import check_output_file
from roachplan.planning import PLANNER_NAMES
from roachplan.scenes import MAX_SEED

from ._flags import UsageError, clip, planner_of, pose, scene_options
from ._progress import bar
from ._scene_cli import scene_inputs


def _notes(world) -> None:
    for note in world.notes:
        print(f"roachplan: {note}", file=sys.stderr)


def cmd_trial(args: argparse.Namespace) -> int:
    from roachplan.experiments import run_trial
    from roachplan.scenes import build_world, load_scene

    if args.from_dir is not None or args.trial is not None:
        return _rerun_trial(args)
    scene = scene_options(load_scene(args.scene or "double_bridge"), args)
    world = build_world(scene)
    _notes(world)
    planner = planner_of(scene.planner, args)
    seed = scene.seed if args.seed is None else args.seed
    result = run_trial(world, seed=seed, planner=planner)
    # The notes (who rendered an OpenSCAD terrain, start and goal picked) go in the JSON too.
    print_trial({**result.to_json(), "notes": list(world.notes)}, args.json)
    return 0


def print_trial(r: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(r))
        return
    spins = len(r.get("spins") or ())
    print(
        f"scene {r['scene']}  seed {r['seed']}  planner {r['planner']}\n"
        f"outcome {r['outcome']} ({r['reason']})  route {r['route'] or '-'}"
        f"{f'  {spins} turn(s) on the spot' if spins else ''}\n"
        f"drive time {r['drive_time']:.2f} s  energy {r['energy']:.4f} J "
        f"(relative {r['relative_energy']:.3f})  "
        f"plan {r['plan_time']:.2f} s  simulate {r['drive_wall_time']:.2f} s wall"
    )


def _rerun_trial(args: argparse.Namespace) -> int:
    """`trial --from DIR --trial K`: re-run a stored trial and compare."""
    from roachplan.experiments import rerun_trial

    if args.from_dir is None or args.trial is None:
        raise UsageError("give both --from DIR and --trial K to re-run a stored trial")
    recorded = ("scene", "seed", "planner", "time_limit")
    if any(getattr(args, k) is not None for k in recorded):
        raise UsageError(
            "--from re-runs a trial with its recorded scene, seed and planner; "
            "drop --scene/--seed/--planner/--time-limit"
        )
    rec, stored, differ = rerun_trial(args.from_dir, args.trial)
    print_trial(rec, args.json)
    if stored is None:
        print(
            f"roachplan: trial {args.trial} is not in the store yet; nothing to compare",
            file=sys.stderr,
        )
        return 0
    if differ:
        print(
            f"roachplan: the re-run differs from the stored trial in: {', '.join(differ)}",
            file=sys.stderr,
        )
        return 1
    print(
        f"roachplan: identical to stored trial {args.trial} (apart from wall-clock times)",
        file=sys.stderr,
    )
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    import dataclasses
    import time

    from roachplan.experiments import path_settings, plan_many
    from roachplan.scenes import build_world, load_scene

    start, goal = pose(args.start, "--start"), pose(args.goal, "--goal")
    scene = scene_options(load_scene(args.scene), args)
    # --start/--goal replace the scene's own poses before the world is built, so a scene pose
    # they replace is not checked; plan_path checks the poses it plans between, by their flags.
    start_goal = (start or scene.start, goal or scene.goal)
    replaced = (start or goal) is not None and None not in start_goal
    if replaced:
        scene = dataclasses.replace(scene, start=start or scene.start, goal=goal or scene.goal)
    world = build_world(scene, check_poses=not replaced)
    _notes(world)
    scene = world.scene  # with the start and goal picked, if the scene file had none
    # One budget for the whole request: every seed and try (plan_many), each try at most
    # --try-limit of it.
    budget = scene.planner.time_limit if args.time_limit is None else args.time_limit
    planner = planner_of(scene.planner, args)
    seed = scene.seed if args.seed is None else args.seed
    tried = []
    t0 = time.monotonic()
    with bar(args.count, "paths", unit=" path", enabled=None if args.count > 1 else False) as b:

        def attempt(_seed, new) -> None:
            tried.append(_seed)
            b.update(new is not None)

        plans = plan_many(
            world,
            args.count,
            seed=seed,
            start=start,
            goal=goal,
            planner=planner,
            budget=budget,
            on_attempt=attempt,
        )
    rows = [
        {
            "route": lp.route,
            "seed": lp.plan.seed,
            "plan_time": round(lp.plan.plan_time, 4),
            "length_m": round(
                float(np.sum(np.linalg.norm(np.diff(lp.plan.path_xyz, axis=0), axis=1))), 4
            ),
            "states": lp.plan.states.round(5).tolist(),
            "path": lp.plan.path_xyz.round(5).tolist(),
            # Turns on the spot: [index into path, heading rad], the driver turns there.
            "spins": [[k, round(yaw, 5)] for k, yaw in lp.plan.spins],
            "message": lp.plan.message,
        }
        for lp in plans
    ]
    if args.json:
        out = {
            "scene": scene.name,
            "planner": planner.name,
            "seed": seed,
            **path_settings(planner.turning_radius),
            "notes": list(world.notes),
        }
        if args.count == 1 and rows:
            out.update(rows[0])
        out["paths"] = rows
        print(json.dumps(out))
    else:
        for r in rows:
            spins = f"  {len(r['spins'])} turn(s) on the spot" if r["spins"] else ""
            print(
                f"seed {r['seed']:4d}  route {r['route']:14s} {len(r['path']):4d} waypoints  "
                f"{r['length_m']:.2f} m  planned in {r['plan_time']:.3f} s{spins}"
            )
    if len(rows) < args.count:
        spent = time.monotonic() - t0 >= budget - 0.1
        why = f"its {budget:g} s budget spent" if spent else f"after {len(tried)} tries"
        print(
            f"roachplan: found {len(rows)} distinct path(s) of the {args.count} asked for "
            f"({planner.name}, seeds from {seed}; {why})",
            file=sys.stderr,
        )
        return 1
    return 0


def _planner_list(text: str) -> list[str]:
    """'prm,rrtconnect' -> ['prm', 'rrtconnect'], each a planner, none twice, else UsageError."""
    names = [n.strip() for n in text.split(",")]
    for n in names:
        if n not in PLANNER_NAMES:
            raise UsageError(
                f"--planners {clip(repr(text), 80)}: {clip(repr(n), 40)} is not a "
                f"planner; choose from {', '.join(PLANNER_NAMES)}"
            )
    if len(set(names)) < len(names):
        raise UsageError(f"--planners {clip(repr(text), 80)}: a planner is named twice")
    return names


def cmd_benchmark(args: argparse.Namespace) -> int:
    import dataclasses

    from roachplan.experiments import (
        atomic_write,
        benchmark_bar,
        benchmark_log,
        is_benchmark_db,
        run_benchmark,
        write_benchmark_db,
    )
    from roachplan.scenes import build_world, load_scene

    names = _planner_list(args.planners)
    scene = load_scene(args.scene)
    seed = scene.seed if args.seed is None else args.seed
    if seed + args.runs - 1 > MAX_SEED:  # run k plans with seed + k
        raise UsageError(
            f"--seed {seed} with --runs {args.runs}: the last run's seed "
            f"{seed + args.runs - 1} is above {MAX_SEED}; give a smaller --seed"
        )
    # Refused before the runs, not after them; the log and the database never replace each other.
    inputs = scene_inputs(scene)
    log_path = check_output_file(
        args.output,
        suffixes=(".log",),
        inputs=inputs,
        kind="a benchmark log roachplan wrote",
        force=args.force,
    )
    db_path = None
    if args.db is not None:
        db_path = check_output_file(
            args.db,
            flag="--db",
            suffixes=(".db", ".sqlite", ".sqlite3"),
            inputs=[*inputs, args.output],
            replaceable=is_benchmark_db,
            kind="a benchmark database roachplan wrote",
            force=args.force,
        )
    world = build_world(scene_options(scene, args))
    _notes(world)
    base = planner_of(world.scene.planner, args)  # each run: one plan of --time-limit
    planners = [dataclasses.replace(base, name=n) for n in names]
    with benchmark_bar(not args.quiet, len(names) * args.runs) as progress:
        result = run_benchmark(
            world,
            planners,
            runs=args.runs,
            seed=seed,
            simulate=args.simulate,
            on_run=lambda run: progress.update(),
        )
    atomic_write(log_path, benchmark_log(result))
    if db_path is not None:
        write_benchmark_db(result, db_path)
    for name in names:
        runs = result.runs_of(name)
        solved = [r for r in runs if r.solved]
        line = (
            f"{name:16s} solved {len(solved)}/{len(runs)}  median plan time "
            f"{float(np.median([r.time for r in runs])):.3f} s"
        )
        if args.simulate:
            ok = [r for r in runs if r.simulated_success]
            energy = f"{np.mean([r.energy for r in ok]):.3f} J" if ok else "-"
            line += f"  reached the goal {len(ok)}/{len(runs)}  mean energy (reached) {energy}"
        print(line)
    print(
        f"wrote {log_path}"
        + (f" and {db_path}" if db_path is not None else "")
        + f" ({result.total_time:.1f} s)"
    )
    return 0
