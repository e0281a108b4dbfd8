"""`roachplan`: the command line."""

from __future__ import annotations

import argparse
import errno
import json
import math
import os
import sys

import numpy as np

from roachplan.app._choose_cli import add_choose_parser
from roachplan.app._progress import bar, render_progress, stage_progress
from roachplan.experiments import WRITTEN_BY, ExperimentError, OutputError, check_output_file
from roachplan.perception import CaptureError
from roachplan.planning import PLANNER_NAMES, PlanningError
from roachplan.scenes import MAX_SEED, SceneError, list_scenes
from roachplan.sim import SimError


class UsageError(ValueError):
    """A command-line value out of its range; the message names the flag, the value and the
    range."""


USER_ERRORS = (
    SceneError,
    PlanningError,
    SimError,
    ExperimentError,
    CaptureError,
    OutputError,
    UsageError,
)
MESH_WRITTEN = "a mesh roachplan wrote (it says so in its header)"
"""What `mesh -o` and `scene build -o` replace without --force: their own earlier output."""
FORCE_HELP = (
    "replace an existing output file roachplan did not write (never an input of the command)"
)


def _cmd_serve(args: argparse.Namespace) -> int:
    from ._server import serve  # viser only when serving

    serve(scene=args.scene, host=args.host, port=args.port)
    return 0


def _cmd_trial(args: argparse.Namespace) -> int:
    from roachplan.experiments import run_trial
    from roachplan.scenes import build_world, load_scene

    if args.from_dir is not None or args.trial is not None:
        return _rerun_trial(args)
    scene = _scene_options(load_scene(args.scene or "double_bridge"), args)
    world = build_world(scene)
    for note in world.notes:
        print(f"roachplan: {note}", file=sys.stderr)
    planner = _planner_config(scene, args)
    seed = scene.seed if args.seed is None else args.seed
    result = run_trial(world, seed=seed, planner=planner)
    # The notes (who rendered an OpenSCAD terrain, start and goal picked) go in the JSON too.
    _print_trial({**result.to_json(), "notes": list(world.notes)}, args.json)
    return 0


def _print_trial(r: dict, as_json: bool) -> None:
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
        raise ExperimentError("give both --from DIR and --trial K to re-run a stored trial")
    if args.scene is not None or args.seed is not None or args.planner is not None:
        raise ExperimentError(
            "--from re-runs a trial with its recorded scene, seed and planner; "
            "drop --scene/--seed/--planner"
        )
    rec, stored, differ = rerun_trial(args.from_dir, args.trial)
    _print_trial(rec, args.json)
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


def _cmd_experiment(args: argparse.Namespace) -> int:
    import dataclasses
    from concurrent.futures.process import BrokenProcessPool
    from pathlib import Path

    from roachplan.experiments import (
        check_results_folder,
        describe_best,
        load_experiment,
        read_manifest,
        run_experiment,
    )

    cores = os.cpu_count() or 1
    cluster = args.backend == "ray" and args.address is not None
    if args.workers is not None and not cluster and args.workers > 4 * cores:
        raise UsageError(
            f"--workers {args.workers}: this machine has {cores} cores; give at "
            f"most {4 * cores} local workers (or a Ray cluster's --address)"
        )
    if args.out is not None:  # refused before the spec's work, not after it
        check_results_folder(Path(args.out), create=False)
    spec = load_experiment(args.spec)
    if args.reference:
        spec = _as_reference(spec)
    out = Path(args.out) if args.out else Path("results") / spec.name
    trials, repeats = args.trials, args.repeats
    if args.resume and (out / "manifest.json").is_file():  # continue as it was started
        manifest = read_manifest(out)
        trials = manifest["trials_total"] if trials is None else trials
        repeats = manifest["best_path"]["repeats"] if repeats is None else repeats
    if repeats is not None:
        if repeats < 0:
            raise ExperimentError(f"--repeats {repeats}: must be 0 or more")
        spec = dataclasses.replace(spec, best_path_repeats=repeats)
    trials = spec.default_trials if trials is None else trials
    # Ray with a cluster address: one worker per CPU of the cluster unless told.
    workers = args.workers if args.workers is not None else (None if cluster else cores)
    try:
        report = run_experiment(
            spec,
            trials=trials,
            out=out,
            workers=workers,
            resume=args.resume,
            backend=args.backend,
            address=args.address,
            progress=not args.quiet,
        )
    except (KeyboardInterrupt, BrokenProcessPool) as exc:
        why = "interrupted" if isinstance(exc, KeyboardInterrupt) else f"a worker died ({exc})"
        print(
            f"roachplan: {why}; every finished trial is stored in {out}; continue with --resume",
            file=sys.stderr,
        )
        return 130 if isinstance(exc, KeyboardInterrupt) else 1
    print(
        f"{spec.name}: {report.trials_stored} trials in {out} "
        f"({report.trials_run} run now, {report.trials_stored - report.trials_run} stored before)\n"
    )
    print(report.table)
    print()
    print(describe_best(report.best))
    print(f"\nwrote {out}/summary.csv, summary.md, paths.png, energy.png, best_path.json")
    return 0


def _pose(text: str | None, flag: str) -> tuple[float, float, float] | None:
    """'x,y,yaw_deg' -> (x [m], y [m], yaw [rad])."""
    if text is None:
        return None
    try:
        x, y, yaw = (float(v) for v in text.split(","))
    except ValueError:
        raise PlanningError(
            f"{flag} {_clip(repr(text), 80)}: expected x,y,yaw_deg, e.g. 0,-1.6,90"
        ) from None
    if not all(map(math.isfinite, (x, y, yaw))):
        raise PlanningError(f"{flag} {_clip(repr(text), 80)}: expected finite numbers x,y,yaw_deg")
    return (x, y, math.radians(yaw))


def _planner_config(scene, args: argparse.Namespace):
    import dataclasses

    changes = {"name": args.planner} if args.planner else {}
    # `trial` has only --planner; `plan` also the post-processing flags and the time limit.
    for flag in ("simplify", "smooth", "optimize"):
        if getattr(args, flag, None) is not None:
            changes[flag] = getattr(args, flag)
    if getattr(args, "time_limit", None) is not None:
        if args.time_limit <= 0:
            raise PlanningError(f"--time-limit {args.time_limit}: must be > 0 seconds")
        changes["time_limit"] = args.time_limit
    return dataclasses.replace(scene.planner, **changes)


def _cmd_plan(args: argparse.Namespace) -> int:
    import dataclasses

    from roachplan.experiments import path_settings, plan_many
    from roachplan.scenes import build_world, load_scene

    if args.count < 1:
        raise PlanningError(f"--count {args.count}: must be 1 or more")
    start, goal = _pose(args.start, "--start"), _pose(args.goal, "--goal")
    scene = _scene_options(load_scene(args.scene), args)
    # --start/--goal replace the scene's own poses before the world is built, so a scene pose
    # they replace is not checked; plan_path checks the poses it plans between, by their flags.
    start_goal = (start or scene.start, goal or scene.goal)
    replaced = (start or goal) is not None and None not in start_goal
    if replaced:
        scene = dataclasses.replace(scene, start=start or scene.start, goal=goal or scene.goal)
    world = build_world(scene, check_poses=not replaced)
    for note in world.notes:
        print(f"roachplan: {note}", file=sys.stderr)
    scene = world.scene  # with the start and goal picked, if the scene file had none
    planner = _planner_config(scene, args)
    seed = scene.seed if args.seed is None else args.seed
    with bar(args.count, "paths", unit=" path", enabled=None if args.count > 1 else False) as b:
        plans = plan_many(
            world,
            args.count,
            seed=seed,
            start=start,
            goal=goal,
            planner=planner,
            on_attempt=lambda _seed, new: b.update(new is not None),
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
        print(
            f"roachplan: found {len(rows)} distinct path(s) of the {args.count} asked for "
            f"({planner.name}, seeds from {seed})",
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
                f"--planners {_clip(repr(text), 80)}: {_clip(repr(n), 40)} is not a "
                f"planner; choose from {', '.join(PLANNER_NAMES)}"
            )
    if len(set(names)) < len(names):
        raise UsageError(f"--planners {_clip(repr(text), 80)}: a planner is named twice")
    return names


def _cmd_benchmark(args: argparse.Namespace) -> int:
    import dataclasses

    from roachplan.experiments import atomic_write
    from roachplan.experiments._benchmark import (
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
    inputs = _scene_inputs(scene)
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
    world = build_world(_scene_options(scene, args))
    for note in world.notes:
        print(f"roachplan: {note}", file=sys.stderr)
    base = world.scene.planner
    time_limit = base.time_limit if args.time_limit is None else args.time_limit
    planners = [dataclasses.replace(base, name=n, time_limit=time_limit) for n in names]
    with benchmark_bar(not args.quiet, len(names) * args.runs) as bar:
        result = run_benchmark(
            world,
            planners,
            runs=args.runs,
            seed=seed,
            simulate=args.simulate,
            on_run=lambda run: bar.update(),
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


def _cmd_scene_list(args: argparse.Namespace) -> int:
    from roachplan.perception import load_yaml
    from roachplan.scenes import LIBRARY

    # The description as written (read, not built: listing answers at once; `scene check`
    # and the tests validate the library's files).
    for name in list_scenes():
        path = LIBRARY / f"{name}.yaml"
        raw = load_yaml(path.read_bytes(), path.name)
        print(f"{name:24s} {raw.get('description', '') if isinstance(raw, dict) else ''}")
    return 0


def _scene_options(scene, args: argparse.Namespace):
    """The scene with the command line's --scale, --scad-timeout and --scad-backend applied,
    where given."""
    from roachplan.scenes import scaled_scene, with_scad_backend, with_scad_timeout

    if getattr(args, "scale", None) is not None:
        scene = scaled_scene(scene, args.scale)
    if getattr(args, "scad_timeout", None) is not None:
        scene = with_scad_timeout(scene, args.scad_timeout)
    if getattr(args, "scad_backend", None) is not None:
        scene = with_scad_backend(scene, args.scad_backend)
    if getattr(args, "reference", False):
        scene = _as_reference(scene)
    return scene


def _as_reference(scene_or_spec):
    """--reference: the report's raw paths and algorithms 1-2 (tables 7.1-7.3)."""
    import dataclasses

    from roachplan.experiments._spec import reference_settings

    planner, driver = reference_settings(scene_or_spec.planner, scene_or_spec.driver)
    return dataclasses.replace(scene_or_spec, planner=planner, driver=driver)


def _cmd_scene_check(args: argparse.Namespace) -> int:
    from roachplan.scenes import build_world, load_scene

    _scene_options(load_scene("flat"), args)  # a bad flag is refused once (exit 2), not per file
    failed = 0
    for name in args.files:
        try:
            world = build_world(_scene_options(load_scene(name), args))
        except SceneError as exc:
            print(f"FAIL {name}: {exc}")
            failed += 1
            continue
        for note in world.notes:
            print(f"roachplan: {name}: {note}", file=sys.stderr)
        m, sc = world.mesh, world.scene
        size = "x".join(f"{v:.2f}" for v in m.extents) if len(m.faces) else "-"
        print(
            f"ok   {name}: {len(sc.terrain)} terrain object(s), {len(m.faces)} triangles, "
            f"{size} m, ground {'none' if sc.ground is None else f'{sc.ground:g} m'}; "
            f"start and goal stand on the terrain"
        )
    if failed:
        print(f"{failed} of {len(args.files)} scene file(s) failed", file=sys.stderr)
    return 1 if failed else 0


def _export_mesh(mesh, out) -> None:
    """Write the mesh in the format out's suffix names, atomically (a failure leaves no
    half-written file), marked WRITTEN_BY where the format has room, so that a later -o may
    replace it without --force."""
    from roachplan.experiments import atomic_write

    fmt = out.suffix.lower().lstrip(".")
    if fmt == "obj":
        data = mesh.export(file_type="obj", header=WRITTEN_BY).encode()
    elif fmt == "glb":
        data = mesh.export(
            file_type="glb",
            tree_postprocessor=lambda tree: tree["asset"].update(
                generator=f"{WRITTEN_BY} (trimesh)"
            ),
        )
    else:
        data = mesh.export(file_type=fmt)
        if fmt == "stl":  # binary STL: 80 free bytes of header
            data = WRITTEN_BY.encode().ljust(80, b" ") + data[80:]
        elif fmt == "ply":  # a comment line after "ply" and "format ..."
            first, second, rest = data.split(b"\n", 2)
            data = b"\n".join((first, second, b"comment " + WRITTEN_BY.encode(), rest))
    atomic_write(out, data)


def _scene_inputs(scene) -> list:
    """The files a scene is read from: never an output's target."""
    files = [scene.path]
    for o in scene.terrain:
        files.append(o.source)
        intrinsics = getattr(o.capture, "intrinsics", None)
        if isinstance(intrinsics, str | os.PathLike):
            files.append(intrinsics)
    return files


def _cmd_scene_build(args: argparse.Namespace) -> int:
    from roachplan.scenes import build_terrain, load_scene

    scene = load_scene(args.scene)
    out = check_output_file(
        args.output,
        suffixes=(".stl", ".obj", ".ply", ".glb"),
        inputs=_scene_inputs(scene),
        kind=MESH_WRITTEN,
        force=args.force,
    )
    terrain = build_terrain(_scene_options(scene, args))
    for note in terrain.notes:
        print(f"roachplan: {note}", file=sys.stderr)
    mesh = terrain.mesh
    if len(mesh.faces) == 0:
        raise SceneError(f"scene {args.scene!r} has no terrain objects, only a ground plane")
    _export_mesh(mesh, out)
    print(f"wrote {out}: {len(mesh.faces)} triangles, bounds {mesh.bounds.round(4).tolist()} m")
    return 0


def _numbers(
    text: str | None, flag: str, n: tuple[int, ...], error: type[Exception] = CaptureError
) -> list[float] | None:
    """'a,b,c' -> [a, b, c], finite, with a count in n, or `error` naming the flag, the value
    and what is wrong with it."""
    if text is None:
        return None
    contiguous = len(n) > 2 and n == tuple(range(n[0], n[-1] + 1))
    counts = f"{n[0]} to {n[-1]}" if contiguous else " or ".join(map(str, n))
    expected = f"expected {counts} comma-separated numbers"
    parts = text.split(",")
    if len(parts) not in n:
        raise error(f"{flag} {_clip(repr(text), 80)}: {expected}, got {len(parts)}")
    values = []
    for part in parts:
        try:
            values.append(float(part))
        except ValueError:
            raise error(
                f"{flag} {_clip(repr(text), 80)}: {expected}; {_clip(repr(part), 40)} "
                f"is not a number"
            ) from None
        if not math.isfinite(values[-1]):
            raise error(
                f"{flag} {_clip(repr(text), 80)}: {expected}; {part.strip()} is not a finite number"
            )
    return values


def _intrinsics_flags(args: argparse.Namespace) -> str | dict | None:
    """--intrinsics, or --fx --fy --cx --cy (all four) as a mapping; CaptureError names the
    flag."""
    given = {k: getattr(args, k, None) for k in ("fx", "fy", "cx", "cy")}
    if all(v is None for v in given.values()):
        return args.intrinsics
    missing = [f"--{k}" for k, v in given.items() if v is None]
    if missing:
        raise CaptureError(
            f"--fx --fy --cx --cy go together (the pinhole's focal lengths and principal point "
            f"[px]); missing {' '.join(missing)}"
        )
    if args.intrinsics is not None:
        raise CaptureError("pass either --intrinsics or --fx --fy --cx --cy, not both")
    for k, v in given.items():
        if not (math.isfinite(v) and v > 0):
            raise CaptureError(f"--{k} {v:g}: expected a number of pixels > 0")
    return given


def _capture_settings(args: argparse.Namespace):
    from roachplan.perception import capture_settings

    voxel = _numbers(args.voxel, "--voxel", (1, 3))
    given = {
        "voxel": voxel[0] if voxel and len(voxel) == 1 else voxel,
        "method": getattr(args, "method", None),
        "camera_pose": _numbers(getattr(args, "camera_pose", None), "--camera-pose", (7,)),
        "intrinsics": _intrinsics_flags(args),
        "depth_scale": args.depth_scale,
        "depth_units": args.depth_units,
        "units": args.units,
        "topic": args.topic,
        "seed": getattr(args, "seed", None),
        "frame": getattr(args, "frame", None),
        "up": _numbers(getattr(args, "up", None), "--up", (3,)),
        "depth_range": _numbers(getattr(args, "depth_range", None), "--depth-range", (2,)),
        "ground_point": _numbers(getattr(args, "ground_point", None), "--ground-point", (3,)),
        "recentre": getattr(args, "recentre", None),
    }
    crop = _numbers(getattr(args, "crop", None), "--crop", (6,))
    if crop:
        swapped = [a for a, lo, hi in zip("xyz", crop[:3], crop[3:]) if not lo < hi]
        if swapped:
            raise CaptureError(
                f"--crop {_clip(args.crop, 80)}: expected xmin,ymin,zmin,xmax,ymax,zmax [m] with "
                f"each min below its max; not so for {', '.join(swapped)}"
            )
        given["crop"] = [crop[:3], crop[3:]]
    near_far = given["depth_range"]
    if near_far is not None and not 0 <= near_far[0] < near_far[1]:
        raise CaptureError(
            f"--depth-range {_clip(args.depth_range, 80)}: expected NEAR,FAR [m] "
            f"with 0 <= NEAR < FAR"
        )
    settings = {k: v for k, v in given.items() if v is not None}
    try:
        return capture_settings(settings)
    except CaptureError as exc:
        raise CaptureError(f"--{str(exc).replace('_', '-')}") from None


def _mesh_with_progress(path: str, settings):
    """mesh_capture with a bar over its stages (run in the meshing child)."""
    from roachplan.perception import mesh_capture
    from roachplan.perception._pipeline import STAGES

    meshing, on_stage = stage_progress(("read", *STAGES), "meshing")
    with meshing:
        return mesh_capture(path, settings, on_stage)


def _cmd_mesh(args: argparse.Namespace) -> int:
    settings = _capture_settings(args)
    out = check_output_file(
        args.output,
        suffixes=(".stl", ".ply", ".obj"),
        inputs=(args.input, args.intrinsics),
        kind=MESH_WRITTEN,
        force=args.force,
    )
    import open3d  # noqa: F401 - mapped here, not under the child's address-space limit
    import tqdm  # noqa: F401

    import roachplan.perception._pipeline  # noqa: F401
    from roachplan.planning._isolated import run_isolated

    # In a child under the memory limit (issue 15): a capture that needs more ends in a clear
    # error, not by taking the machine; its progress bar is drawn by the child, which inherits
    # the libraries loaded above (loading them under the limit would fail first).
    rec = run_isolated(_mesh_with_progress, args.input, settings, isolation="fork", task="meshing")
    _export_mesh(rec.mesh, out)
    report = {"input": args.input, "output": str(out), **rec.report()}
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"wrote {out}: {report['triangles']} triangles, bounds {report['bounds']} m")
    print("points: " + ", ".join(f"{k} {v}" for k, v in rec.counts.items()))
    print("seconds: " + ", ".join(f"{k} {v:.3f}" for k, v in rec.times.items()))
    print(f"frame: {report['frame']}; up: {report['up_source']}")
    if report["camera_pose"] is not None:
        g = report.get("ground") or {}
        print(
            f"camera: {report['camera_height_m']:.3f} m above the ground, pitched "
            f"{report['pitch_down_deg']:.1f} deg down, roll {report['roll_deg']:.1f} deg; ground "
            f"support {100 * g.get('support_fraction', 1.0):.0f} % of the points, "
            f"{g.get('area_m2', 0.0):.2f} m^2 seen"
        )
        print(
            "camera pose in the world (x,y,z,qx,qy,qz,qw): "
            + ",".join(f"{v:.5f}" for v in report["camera_pose"])
        )
    for note in report["notes"]:
        print(f"note: {note}")
    for warning in report["warnings"]:
        print(f"roachplan: warning: {warning}", file=sys.stderr)
    return 0


def _cmd_voxel_study(args: argparse.Namespace) -> int:
    from roachplan.experiments import atomic_write
    from roachplan.perception import load_capture
    from roachplan.perception._voxel_study import (
        format_study,
        planarity_warning,
        plane_region,
        rect_region,
        square_region,
        study_csv,
        study_json,
        voxel_study,
    )

    sizes = _numbers(args.sizes, "--sizes", tuple(range(1, 32)))
    if not all(math.isfinite(s) and s > 0 for s in sizes):
        raise CaptureError(f"--sizes {args.sizes!r}: voxel sizes must be numbers > 0 [cm]")
    if args.square is not None and not (math.isfinite(args.square) and args.square > 0):
        raise CaptureError(f"--square {args.square:g}: expected the square's side > 0 [m]")
    region = _numbers(args.region, "--region", (4,))
    if region is not None:
        x0, y0, x1, y1 = region
        if not (all(map(math.isfinite, region)) and x0 < x1 and y0 < y1):
            raise CaptureError(
                f"--region {args.region!r}: expected x0,y0,x1,y1 [m] in the "
                f"camera frame with x0 < x1 and y0 < y1"
            )
        if args.square is not None:
            raise CaptureError("pass either --square or --region, not both")
    settings = _capture_settings(args)
    if args.csv is not None:  # before the study's work, not after it
        header = study_csv([]).encode()  # a CSV that starts with the study's header: ours
        check_output_file(
            args.csv,
            flag="--csv",
            suffixes=(".csv",),
            inputs=(args.capture, args.intrinsics),
            kind="a voxel-study table",
            replaceable=lambda head: head.startswith(header),
            force=args.force,
        )
    cap = load_capture(
        args.capture,
        intrinsics=settings.intrinsics,
        depth_scale=settings.depth_scale,
        topic=settings.topic,
        units=settings.units,
        depth_units=settings.depth_units,
    )
    pts = cap.finite_points() - cap.sensor_origin
    total, where = len(pts), "the whole capture"
    if args.square is not None:
        pts, where = square_region(pts, args.square), f"the {args.square:g} m square"
    elif region is not None:
        pts, where = rect_region(pts, *region), f"the region {args.region}"
    if len(pts) < 4:
        raise CaptureError(f"{args.capture}: {len(pts)} points within {where}; 4 or more needed")
    if args.plane:
        pts = plane_region(pts, settings.meshing.seed)
        where = f"the dominant plane of {where} (seed {settings.meshing.seed})"
    rows = voxel_study(pts, sizes)
    warning = planarity_warning(rows[0], float(np.median(np.linalg.norm(pts, axis=1))))
    if args.json:
        print(
            json.dumps(
                {
                    "capture": args.capture,
                    "region": where,
                    "capture_points": total,
                    **study_json(rows, warning),
                }
            )
        )
    else:
        print(f"{len(pts)} of {total} points: {where}")
        print(format_study(rows))
    if warning is not None:
        print(f"roachplan: warning: {warning}", file=sys.stderr)
    if args.csv:
        atomic_write(args.csv, study_csv(rows))
        print(f"wrote {args.csv}", file=sys.stderr if args.json else sys.stdout)
    return 0


def _cmd_synth_capture(args: argparse.Namespace) -> int:
    import numpy as np
    import trimesh

    from roachplan.perception import (
        NO_NOISE,
        NoiseModel,
        load_intrinsics,
        look_at,
        render_depth,
        save_depth,
    )
    from roachplan.scenes import build_terrain_mesh, load_scene

    scene = load_scene(args.scene)
    eye = _numbers(args.eye, "--eye", (3,))
    target = _numbers(args.target, "--target", (3,))
    # A capture may be a real one, not ours to replace: an existing file needs --force.
    inputs = (*_scene_inputs(scene), args.intrinsics)
    out = check_output_file(
        args.output,
        suffixes=(".png", ".pcd", ".ply", ".npy"),
        inputs=inputs,
        replaceable=None,
        kind="a capture, perhaps a real one, is replaced only with --force",
        force=args.force,
    )
    if out.suffix.lower() == ".png":  # and its calibration beside it
        check_output_file(
            out.with_suffix(".json"),
            flag="-o (the .png's sidecar)",
            inputs=inputs,
            replaceable=None,
            kind="a capture's calibration is replaced only with --force",
            force=args.force,
        )
    mesh = build_terrain_mesh(scene)
    if scene.ground is not None:  # the endless floor, as a big square
        g = trimesh.creation.box((100.0, 100.0, 0.01))
        g.apply_translation((0, 0, scene.ground - 0.005))
        mesh = trimesh.util.concatenate([m for m in (mesh, g) if len(m.faces)])
    intr = load_intrinsics(args.intrinsics)
    pose = look_at(eye, target)
    noise = NO_NOISE if args.no_noise else NoiseModel()
    depth = render_depth(mesh, intr, pose, noise, np.random.default_rng(args.seed))
    written = save_depth(out, depth, intr, world_from_camera=pose)
    print(
        f"wrote {', '.join(map(str, written))}: {intr.width}x{intr.height}, "
        f"{np.mean(depth > 0) * 100:.1f} % of pixels measured, seed {args.seed}"
    )
    return 0


def _add_perception_parsers(sub) -> None:
    from roachplan.perception import DEPTH_UNITS, FRAMES, METHODS, PRESETS

    def capture_flags(p):
        p.add_argument(
            "--intrinsics",
            default=None,
            help=f"depth images: a calibration file (.json, PCL .xml, OpenCV or ROS "
            f".yaml) or a preset: {', '.join(PRESETS)}",
        )
        for k, what in (
            ("fx", "focal length x"),
            ("fy", "focal length y"),
            ("cx", "principal point x"),
            ("cy", "principal point y"),
        ):
            p.add_argument(
                f"--{k}",
                type=float,
                default=None,
                help=f"depth images: {what} [px] (with the other three of "
                f"--fx --fy --cx --cy, instead of --intrinsics)",
            )
        p.add_argument(
            "--depth-scale",
            type=float,
            default=None,
            help="depth images: units per metre (default: the calibration's or "
            "preset's, e.g. 5000 for tum-*, else 1000, i.e. mm)",
        )
        p.add_argument(
            "--depth-units",
            choices=DEPTH_UNITS,
            default=None,
            help="depth images: kinect-disparity for a Kinect v1's raw 11-bit "
            "disparity (NYU Depth v2's raw dumps), converted to metres with "
            "NYU's model (default: depth in units of --depth-scale; raw "
            "disparity is recognised when plain)",
        )
        p.add_argument("--units", choices=("m", "mm"), default=None, help="point cloud units")
        p.add_argument("--topic", default=None, help="bags: the topic to read")

    p = sub.add_parser("mesh", help="capture (point cloud, depth image, bag) -> terrain mesh")
    p.add_argument(
        "input", metavar="INPUT", help=".pcd .ply .xyz .pts .npy .png .pgm .ppm .bag .db3 .mcap"
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="mesh file: .stl, .ply or .obj, in an existing folder; an existing file "
        "is replaced only if roachplan wrote it (else --force), never the input",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--voxel", default=None, help="voxel size [m]: d or dx,dy,dz (default 0.01)")
    p.add_argument("--method", choices=METHODS, default=None, help="default: grid")
    p.add_argument(
        "--camera-pose",
        default=None,
        help="x,y,z,qx,qy,qz,qw of the camera in the world (default: from the ground)",
    )
    p.add_argument("--crop", default=None, help="world box xmin,ymin,zmin,xmax,ymax,zmax [m]")
    p.add_argument("--seed", type=int, default=None, help="RANSAC seed (default 0)")
    p.add_argument(
        "--frame",
        choices=FRAMES,
        default=None,
        help="camera: optical frame (x right, y down, z forward); world: z up (or "
        "--up), e.g. a lidar or a map; default auto: what the file says",
    )
    p.add_argument(
        "--up",
        default=None,
        metavar="X,Y,Z",
        help="up in the capture's frame (default: a calibration's pose, a bag's "
        "IMU, -y for a camera, +z for a world frame)",
    )
    p.add_argument(
        "--ground-point",
        default=None,
        metavar="X,Y,Z",
        help="a point on the intended ground, capture frame [m]: the plane through "
        "it is the ground",
    )
    p.add_argument(
        "--depth-range",
        default=None,
        metavar="NEAR,FAR",
        help="keep points this near/far [m] (default: 0.3,8 for a camera, all for a world frame)",
    )
    p.add_argument(
        "--recentre",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="put the cloud's centre at x = y = 0 (default: when georeferenced)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object: camera pose, ground, triangles, warnings",
    )
    capture_flags(p)
    p.set_defaults(func=_cmd_mesh)

    p = sub.add_parser(
        "voxel-study", help="table 3.1: voxel size vs plane-fit error of a flat capture"
    )
    p.add_argument("capture", metavar="CAPTURE")
    p.add_argument("--sizes", default="1,2,5,10,20", help="voxel sizes [cm]")
    p.add_argument(
        "--square",
        type=float,
        default=None,
        help="use the points within this square around the optical axis [m]",
    )
    p.add_argument(
        "--region",
        default=None,
        metavar="X0,Y0,X1,Y1",
        help="use the points with x0<=x<=x1, y0<=y<=y1 in the camera frame (x right, y down) [m]",
    )
    p.add_argument(
        "--plane",
        action="store_true",
        help="use only the dominant plane's points (RANSAC), e.g. a room's wall",
    )
    p.add_argument("--seed", type=int, default=None, help="RANSAC seed of --plane (default 0)")
    p.add_argument("--json", action="store_true", help="print the study as JSON")
    p.add_argument(
        "--csv",
        default=None,
        help="also write the table to this .csv file (an existing file is replaced "
        "only if it is a voxel-study table, else with --force)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--voxel", default=None, help=argparse.SUPPRESS)
    capture_flags(p)
    p.set_defaults(func=_cmd_voxel_study)

    p = sub.add_parser("synth-capture", help="render a scene as a noisy Kinect v2 depth capture")
    p.add_argument("scene", metavar="SCENE", help="library scene name or scene .yaml")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help=".png (+ .json sidecar), .pcd, .ply or .npy in an existing folder; an existing "
        "file is replaced only with --force",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--eye", required=True, help="camera position x,y,z [m]")
    p.add_argument("--target", required=True, help="point the camera looks at x,y,z [m]")
    p.add_argument("--intrinsics", default="kinect2-qhd", help=f"{', '.join(PRESETS)} or a file")
    p.add_argument("--seed", type=int, default=0, help="seed of the noise")
    p.add_argument("--no-noise", action="store_true", help="exact depth")
    p.set_defaults(func=_cmd_synth_capture)


CALIBRATION_FILES = ("turning.csv", "turning.png", "turning_model.json", "spin.csv", "spin.png")
"""What `calibrate-turning` writes in its --out folder."""


def _cmd_calibrate_turning(args: argparse.Namespace) -> int:
    from roachplan.experiments import is_partial, prepare_output_folder

    from ._calibrate import DEFAULT_RATIOS, calibrate_turning

    ratios = _numbers(args.ratios, "--ratios", tuple(range(2, 33)), SimError) or DEFAULT_RATIOS
    if any(r < 1.0 for r in ratios):
        raise SimError(
            f"--ratios {_clip(repr(args.ratios), 80)}: give two or more right/left ratios >= 1"
        )
    if len(set(ratios)) < 5:  # the turning curve has four parameters
        raise SimError(
            f"--ratios {_clip(repr(args.ratios), 80)}: the turning curve needs 5 or "
            f"more distinct right/left ratios >= 1"
        )

    # Its own earlier calibration may be replaced; a folder of anything else is refused.
    def earlier_calibration(folder) -> bool:
        return {n for n in os.listdir(folder) if not is_partial(n)} <= {*CALIBRATION_FILES}

    out = prepare_output_folder(
        args.out,
        flag="--out",
        owned=earlier_calibration,
        accepts=f"--out takes a new or empty folder, or one holding only an earlier "
        f"calibration ({', '.join(CALIBRATION_FILES)})",
    )
    samples, model, fit, spins = calibrate_turning(out, ratios=ratios, duration=args.duration)
    print(f"{'ratio':>6} {'distance m':>10} {'turns':>7} {'curvature 1/m':>13}")
    for s in samples:
        print(f"{s.ratio:6.2f} {s.distance:10.3f} {s.revolutions:7.3f} {s.curvature:13.3f}")
    c = fit.curve
    print(
        f"curve: curvature = {c.kappa_sat:.3f} (1 - r^-{c.rate:.3f}) + {c.lock:.4f} ln r / "
        f"(ln {c.lock_ratio:.4f} - ln r)  (R^2 {fit.r_squared:.3f}, rms residual "
        f"{fit.rms_residual:.3f} /m)\n"
        f"report's line: curvature = {model.slope:.3f} ln(ratio) {model.intercept:+.3f}  "
        f"(R^2 {model.r_squared:.3f})"
    )
    print(
        f"turning on the spot:\n{'omega rad/s':>11} {'rate rad/s':>10} {'drift mm/rad':>12} "
        f"{'wander mm':>9} {'J/rad':>7}"
    )
    for t in spins:
        print(
            f"{t.omega:11g} {t.yaw_rate:10.3f} {1000 * t.drift:12.2f} {1000 * t.wander:9.1f} "
            f"{t.energy_per_radian:7.4f}"
        )
    print(f"wrote {args.out}/{', '.join(CALIBRATION_FILES)}")
    return 0


def _add_experiment_parser(sub) -> None:
    from roachplan.experiments import list_experiments

    p = sub.add_parser(
        "experiment", help="a batch of trials in parallel: tables 7.1/7.2, figures, best path"
    )
    p.add_argument(
        "spec", metavar="SPEC", help=f"{', '.join(list_experiments())} or an experiment .yaml"
    )
    p.add_argument(
        "--trials",
        type=int,
        default=None,
        help="total trials, split evenly over the spec's routes (default: the spec's)",
    )
    p.add_argument(
        "--reference",
        action="store_true",
        help="the report's raw paths and algorithms 1-2 (default: drivable plans, "
        "arcs no tighter than the robot turns, and the tracking driver)",
    )
    p.add_argument(
        "--workers", type=int, default=None, help="parallel workers (default: all cores)"
    )
    p.add_argument(
        "--out",
        default=None,
        help="results folder, created if new (default: results/SPEC); an existing one "
        "must be empty or hold a roachplan experiment (to --resume)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the experiment in --out (its --trials and --repeats by default)",
    )
    p.add_argument("--repeats", type=int, default=None, help="re-drives of the best path")
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local worker processes, or a Ray cluster",
    )
    p.add_argument(
        "--address", default=None, help="Ray cluster address (default: start a local Ray instance)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_experiment)


def _cmd_replay(args: argparse.Namespace) -> int:
    from ._replay import SUFFIXES, load_replay, replay_inputs, replay_written, write_replay

    out = check_output_file(
        args.output,
        suffixes=SUFFIXES,
        inputs=replay_inputs(args.folder),
        replaceable=replay_written,
        kind="a replay roachplan wrote",
        force=args.force,
    )
    replay = load_replay(args.folder, trial=args.trial)
    size = write_replay(replay, out)
    shown = replay.trials[replay.shown]
    print(
        f"wrote {out} ({size / 1e6:.1f} MB): {replay.title}; {shown['label']} plays "
        f"({len(replay.frames)} frames, {shown['outcome']})"
    )
    if replay.note:
        print(f"roachplan: {replay.note}", file=sys.stderr)
    return 0


def _add_replay_parser(sub) -> None:
    p = sub.add_parser(
        "replay", help="a trial, experiment or choice as one HTML file that plays offline"
    )
    p.add_argument(
        "folder",
        metavar="DIR",
        help="an experiment's results folder (`experiment --out`) or a choice's (`choose --out`)",
    )
    p.add_argument(
        "--trial",
        type=int,
        default=None,
        metavar="K",
        help="only trial K of the experiment (default: every trial drawn, the best "
        "path's trial walking)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help=".html (standalone: viser's client and the recording in one file, opens "
        "offline) or .viser (viser's recording), in an existing folder; an "
        "existing file is replaced only if roachplan wrote it (else --force)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=_cmd_replay)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="roachplan",
        description="Plan a small hexapod's path across terrain with OMPL and test it in PyBullet.",
        epilog="Outputs are written atomically and never over an input; -o replaces an existing "
        "file only if roachplan wrote it (or with --force). Exit status: 0 done, 1 a run that "
        "failed, 2 bad input.",
    )
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the Python traceback of an error (for a bug report)",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("serve", help="start the browser app")
    p.add_argument(
        "--scene",
        default="double_bridge",
        help="library scene name, scene .yaml, or a terrain file (capture, mesh, .scad)",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default: loopback only)")
    p.add_argument("--port", type=int, default=8080)
    p.set_defaults(func=_cmd_serve)

    terrain_help = (
        "library scene name, scene .yaml, or a terrain file (capture, mesh, .scad) "
        "as a scene with start and goal picked"
    )
    p = sub.add_parser("trial", help="one headless plan-and-drive trial")
    p.add_argument("--scene", default=None, help=f"{terrain_help} (default: double_bridge)")
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="S",
        help="scale every terrain model by S (0.001: millimetres)",
    )
    p.add_argument("--seed", type=int, default=None, help="trial seed (default: the scene's)")
    p.add_argument("--planner", choices=PLANNER_NAMES, default=None)
    p.add_argument(
        "--from",
        dest="from_dir",
        default=None,
        metavar="DIR",
        help="re-run a trial of the experiment in DIR exactly (with --trial K)",
    )
    p.add_argument("--trial", type=int, default=None, metavar="K", help="trial number in DIR")
    p.add_argument(
        "--reference",
        action="store_true",
        help="the report's raw paths and algorithms 1-2 (default: drivable plans, "
        "arcs no tighter than the robot turns, and the tracking driver)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_trial)

    _add_experiment_parser(sub)
    add_choose_parser(sub, terrain_help)
    _add_replay_parser(sub)
    _add_perception_parsers(sub)

    p = sub.add_parser("plan", help="plan paths with OMPL over a scene's terrain (no driving)")
    p.add_argument("--scene", default="double_bridge", help=terrain_help)
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="S",
        help="scale every terrain model by S (0.001: millimetres)",
    )
    p.add_argument("--planner", choices=PLANNER_NAMES, default=None, help="default: the scene's")
    p.add_argument("--seed", type=int, default=None, help="first seed (default: the scene's)")
    p.add_argument("--count", type=int, default=1, help="number of distinct paths, by route")
    p.add_argument("--start", default=None, help="x,y,yaw_deg (default: the scene's)")
    p.add_argument("--goal", default=None, help="x,y,yaw_deg (default: the scene's)")
    p.add_argument("--time-limit", type=float, default=None, help="per plan [s]")
    for flag, what in (
        ("simplify", "shortcut the path"),
        ("smooth", "B-spline smooth the path"),
        ("optimize", "let optimizing planners refine to their budget"),
    ):
        p.add_argument(f"--{flag}", action=argparse.BooleanOptionalAction, default=None, help=what)
    p.add_argument(
        "--reference",
        action="store_true",
        help="the report's raw paths and algorithms 1-2 (default: drivable plans, "
        "arcs no tighter than the robot turns, and the tracking driver)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_plan)

    p = sub.add_parser(
        "benchmark", help="compare planners on a scene: an OMPL benchmark log (Planner Arena)"
    )
    p.add_argument("--scene", default="double_bridge", help=terrain_help)
    p.add_argument(
        "--planners",
        required=True,
        metavar="P,Q,...",
        help=f"comma-separated, from {', '.join(PLANNER_NAMES)}",
    )
    p.add_argument("--runs", type=int, required=True, help="plans per planner (run k: seed + k)")
    p.add_argument(
        "--time-limit", type=float, default=None, help="per plan [s] (default: the scene's)"
    )
    p.add_argument("--seed", type=int, default=None, help="first seed (default: the scene's)")
    p.add_argument(
        "--simulate",
        action="store_true",
        help="drive every plan in PyBullet: success, energy, drive time, failure mode",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="the OMPL benchmark log (.log), in an existing folder; an existing file is "
        "replaced only if roachplan wrote it (else --force), never an input",
    )
    p.add_argument(
        "--db",
        default=None,
        help="also the SQLite database Planner Arena opens (.db, .sqlite, .sqlite3)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_benchmark)

    p = sub.add_parser(
        "calibrate-turning", help="sweep motor-speed ratios on flat ground (appendix A, fig. 3.4)"
    )
    p.add_argument(
        "--out",
        required=True,
        help="folder for turning.csv/.png/_model.json and spin.csv/.png, created if "
        "new; an existing one must be empty or hold only an earlier "
        "calibration",
    )
    p.add_argument(
        "--ratios",
        default=None,
        help="right/left speed ratios (default: every 0.1 from 1 to 3 and 1.25, 1.75)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=10.0,
        help="simulated seconds per ratio and per steady spin",
    )
    p.set_defaults(func=_cmd_calibrate_turning)

    def _scad_flags(q) -> None:
        """The OpenSCAD render's time limit and backend, as every command that renders takes."""
        q.add_argument(
            "--scad-timeout",
            type=float,
            default=None,
            metavar="SECONDS",
            help="time limit of each OpenSCAD render (default: the scene's, else 600)",
        )
        q.add_argument(
            "--scad-backend",
            choices=("auto", "cgal", "manifold"),
            default=None,
            help="who renders each OpenSCAD model: auto (manifold unless the model "
            "uses something it renders differently, such as surface(), then "
            "the binary; a note says which and why), cgal (the openscad "
            "binary) or manifold (openscad-evaluator, faster on CSG-heavy "
            "models; refuses surface()) (default: the scene's, else auto)",
        )

    p = sub.add_parser("scene", help="the scene library")
    scene_sub = p.add_subparsers(dest="scene_command", required=True)
    q = scene_sub.add_parser("list", help="list library scenes")
    q.set_defaults(func=_cmd_scene_list)
    q = scene_sub.add_parser(
        "check", help="validate scene files: load, render, and check start and goal"
    )
    q.add_argument("files", nargs="+", metavar="FILE", help="scene .yaml files or library names")
    _scad_flags(q)
    q.set_defaults(func=_cmd_scene_check)
    q = scene_sub.add_parser("build", help="export a scene's assembled terrain mesh")
    q.add_argument("scene", metavar="NAME", help="library scene name or scene .yaml")
    q.add_argument(
        "-o",
        "--output",
        required=True,
        help="mesh file: .stl, .obj, .ply or .glb, in an existing folder; an existing "
        "file is replaced only if roachplan wrote it (else --force), never an "
        "input",
    )
    q.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="S",
        help="scale every terrain model by S before placing it (0.001: millimetres)",
    )
    _scad_flags(q)
    q.add_argument("--force", action="store_true", help=FORCE_HELP)
    q.set_defaults(func=_cmd_scene_build)
    # --debug after the command too (`roachplan plan --debug`); SUPPRESS keeps the top level's
    # value when it is not repeated there.
    for command in _all_parsers(parser)[1:]:
        command.add_argument(
            "--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
        )
    return parser


def _all_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """parser and every (sub)command's parser under it."""
    out = [parser]
    for action in parser._actions:  # argparse has no public walk of its subcommands
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                out += _all_parsers(child)
    return out


class _Parser(argparse.ArgumentParser):
    """argparse, with its error messages bounded (it echoes a refused value whole), and a value
    that starts with a negative number taken as a value: `--crop -1,-1,0,1,1,1`, not "expected
    one argument" (no roachplan option looks like a number)."""

    def __init__(self, *args, **kwargs) -> None:
        import re

        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d|\.\d)[\d.,eE+\-]*$")

    def error(self, message: str):
        super().error(_clip(message, 300))


def _clip(text: str, limit: int = 2000) -> str:
    """text, cut to at most about `limit` characters, saying how much was cut."""
    text = str(text)
    return (
        text if len(text) <= limit else f"{text[:limit]}... ({len(text) - limit} more characters)"
    )


MAX_PLAN_COUNT = 100
"""`plan --count` at most: each path costs up to 3 plans (plan_many), each up to --time-limit."""
MAX_BENCHMARK_RUNS = 10000
"""`benchmark --runs` at most: per planner, each run up to --time-limit."""
MAX_RUN_SECONDS = 3600.0
"""`plan --time-limit` and `calibrate-turning --duration` at most [s]."""
INT_FLAGS = {  # argparse dest: (flag, lowest, highest or None)
    "seed": ("--seed", 0, MAX_SEED),  # the scene files' range: what OMPL's generator takes
    "count": ("--count", 1, MAX_PLAN_COUNT),
    "runs": ("--runs", 1, MAX_BENCHMARK_RUNS),
    "trials": ("--trials", 1, None),
    "workers": ("--workers", 1, None),
    "repeats": ("--repeats", 0, None),
    "trial": ("--trial", 0, None),
    "port": ("--port", 1, 65535),
}
FLOAT_FLAGS = {  # argparse dest: (flag, above, at most or None, unit); --scale and
    # --scad-timeout are the scenes package's to check (_scene_options)
    "time_limit": ("--time-limit", 0.0, MAX_RUN_SECONDS, "s"),
    "duration": ("--duration", 0.0, MAX_RUN_SECONDS, "s"),
    "square": ("--square", 0.0, None, "m"),
    "depth_scale": ("--depth-scale", 0.0, None, "units per metre"),
}


def check_flags(args: argparse.Namespace) -> None:
    """Before any work: every numeric flag given is in its range, else UsageError naming the
    flag, the value and the range."""
    for dest, (flag, lo, hi) in INT_FLAGS.items():
        v = getattr(args, dest, None)
        if v is not None and not (lo <= v and (hi is None or v <= hi)):
            accepted = f"from {lo} to {hi}" if hi is not None else f"{lo} or more"
            raise UsageError(f"{flag} {_clip(str(v), 40)}: expected a whole number {accepted}")
    for dest, (flag, lo, hi, unit) in FLOAT_FLAGS.items():
        v = getattr(args, dest, None)
        if v is not None and not (math.isfinite(v) and lo < v and (hi is None or v <= hi)):
            accepted = f"above {lo:g}" + ("" if hi is None else f" and at most {hi:g}")
            raise UsageError(f"{flag} {v:g}: expected a number {accepted} {unit}".rstrip())


PATH_ERRNOS = {
    errno.ENOENT,
    errno.ENOTDIR,
    errno.EISDIR,
    errno.EACCES,
    errno.EPERM,
    errno.EROFS,
    errno.EEXIST,
    errno.ENAMETOOLONG,
    errno.ELOOP,
    errno.EINVAL,
    errno.EXDEV,
}
"""OSErrors about a path the user gave (exit 2); others (a full disk, an I/O error) are a run
that failed (exit 1)."""


def report_error(exc: BaseException, debug: bool) -> int:
    """Print exc as one bounded line (and its traceback with --debug); the exit status."""
    if debug:
        import traceback

        traceback.print_exception(exc)
    if isinstance(exc, USER_ERRORS):
        print(f"roachplan: error: {_clip(exc)}", file=sys.stderr)
        return 2
    if isinstance(exc, OSError):
        where = f"{_clip(os.fsdecode(exc.filename), 300)}: " if exc.filename is not None else ""
        print(f"roachplan: error: {where}{exc.strerror or _clip(exc, 300)}", file=sys.stderr)
        return 2 if exc.errno in PATH_ERRNOS else 1
    from roachplan.planning._isolated import IsolationError

    if isinstance(exc, IsolationError):  # a planning child hit its memory limit or crashed
        print(f"roachplan: error: {_clip(exc, 600)}", file=sys.stderr)
        return 1
    if isinstance(exc, MemoryError):
        print("roachplan: error: out of memory; try a smaller input or setting", file=sys.stderr)
        return 1
    # A bug of ours, not the user's input: say so in one line rather than hide it.
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    hint = "" if debug else "; re-run with --debug for the traceback"
    print(
        f"roachplan: internal error: {type(exc).__name__}: {_clip(first, 300)}{hint} (please "
        f"report it)",
        file=sys.stderr,
    )
    return 1


def main(argv: list[str] | None = None) -> int:
    """Exit status: 0 done, 1 a run that failed, 2 bad input (the message says which and what
    is accepted), 130 interrupted. No traceback unless --debug."""
    args = build_parser().parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        check_flags(args)
        with render_progress():  # a bar for every OpenSCAD render a command makes
            return args.func(args)
    except KeyboardInterrupt:
        print("roachplan: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # every error ends in one line and an exit status: see main's doc
        return report_error(exc, debug)


if __name__ == "__main__":
    sys.exit(main())
