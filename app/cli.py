"""`roachplan`: the command line."""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from planning import PLANNER_NAMES, PlanningError
from scenes import SceneError, list_scenes
from sim import SimError

USER_ERRORS = (SceneError, PlanningError, SimError)


def _cmd_serve(args: argparse.Namespace) -> int:
    from ._server import serve  # viser only when serving

    serve(scene=args.scene, host=args.host, port=args.port)
    return 0


def _cmd_trial(args: argparse.Namespace) -> int:
    from scenes import build_world, load_scene

    from ._trial import run_trial

    scene = load_scene(args.scene)
    world = build_world(scene)
    planner = _planner_config(scene, args)
    seed = scene.seed if args.seed is None else args.seed
    result = run_trial(world, seed=seed, planner=planner)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        print(
            f"scene {result.scene}  seed {result.seed}  planner {result.planner}\n"
            f"outcome {result.outcome} ({result.reason})  route {result.route or '-'}\n"
            f"drive time {result.drive_time:.2f} s  energy {result.energy:.4f} J "
            f"(relative {result.relative_energy:.3f})  "
            f"plan {result.plan_time:.2f} s  simulate {result.drive_wall_time:.2f} s wall"
        )
    return 0


def _pose(text: str | None, flag: str) -> tuple[float, float, float] | None:
    """'x,y,yaw_deg' -> (x [m], y [m], yaw [rad])."""
    if text is None:
        return None
    try:
        x, y, yaw = (float(v) for v in text.split(","))
    except ValueError:
        raise PlanningError(f"{flag} {text!r}: expected x,y,yaw_deg, e.g. 0,-1.6,90") from None
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
    from scenes import build_world, load_scene

    from ._trial import plan_many

    if args.count < 1:
        raise PlanningError(f"--count {args.count}: must be 1 or more")
    scene = load_scene(args.scene)
    world = build_world(scene)
    planner = _planner_config(scene, args)
    seed = scene.seed if args.seed is None else args.seed
    start, goal = _pose(args.start, "--start"), _pose(args.goal, "--goal")
    plans = plan_many(world, args.count, seed=seed, start=start, goal=goal, planner=planner)
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
        }
        for lp in plans
    ]
    if args.json:
        out = {"scene": scene.name, "planner": planner.name, "seed": seed}
        if args.count == 1 and rows:
            out.update(rows[0])
        out["paths"] = rows
        print(json.dumps(out))
    else:
        for r in rows:
            print(
                f"seed {r['seed']:4d}  route {r['route']:14s} {len(r['path']):4d} waypoints  "
                f"{r['length_m']:.2f} m  planned in {r['plan_time']:.3f} s"
            )
    if len(rows) < args.count:
        print(
            f"roachplan: found {len(rows)} distinct path(s) of the {args.count} asked for "
            f"({planner.name}, seeds from {seed})",
            file=sys.stderr,
        )
        return 1
    return 0


def _cmd_scene_list(args: argparse.Namespace) -> int:
    from scenes import load_scene

    for name in list_scenes():
        print(f"{name:24s} {load_scene(name).description}")
    return 0


def _cmd_scene_check(args: argparse.Namespace) -> int:
    from scenes import build_world, load_scene

    failed = 0
    for name in args.files:
        try:
            world = build_world(load_scene(name))
        except SceneError as exc:
            print(f"FAIL {name}: {exc}")
            failed += 1
            continue
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


def _cmd_scene_build(args: argparse.Namespace) -> int:
    import os
    from pathlib import Path

    from scenes import build_terrain_mesh, load_scene

    out = Path(args.output)
    formats = (".stl", ".obj", ".ply", ".glb")
    if out.suffix.lower() not in formats:
        raise SceneError(f"{out}: the output must end in one of {', '.join(formats)}")
    mesh = build_terrain_mesh(load_scene(args.scene))
    if len(mesh.faces) == 0:
        raise SceneError(f"scene {args.scene!r} has no terrain objects, only a ground plane")
    # Write beside the target and rename, so a failure leaves no half-written file.
    tmp = out.with_name(f".{out.name}.part")
    mesh.export(tmp, file_type=out.suffix.lower().lstrip("."))
    os.replace(tmp, out)
    print(f"wrote {out}: {len(mesh.faces)} triangles, bounds {mesh.bounds.round(4).tolist()} m")
    return 0


def _cmd_calibrate_turning(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ._calibrate import calibrate_turning

    ratios = [float(r) for r in args.ratios.split(",")]
    if any(r < 1.0 for r in ratios) or len(ratios) < 2:
        raise SimError(f"--ratios {args.ratios!r}: give two or more right/left ratios >= 1")
    samples, model = calibrate_turning(Path(args.out), ratios=ratios, duration=args.duration)
    print(f"{'ratio':>6} {'distance m':>10} {'turns':>7} {'curvature 1/m':>13}")
    for s in samples:
        print(f"{s.ratio:6.2f} {s.distance:10.3f} {s.revolutions:7.3f} {s.curvature:13.3f}")
    print(
        f"fit: curvature = {model.slope:.3f} ln(ratio) {model.intercept:+.3f}  "
        f"(R^2 {model.r_squared:.3f})\nwrote {args.out}/turning.csv, turning.png, turning_model.json"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="roachplan",
        description="Plan a small hexapod's path across terrain with OMPL and test it in PyBullet.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("serve", help="start the browser app")
    p.add_argument("--scene", default="double_bridge", help="library scene name or scene .yaml")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default: loopback only)")
    p.add_argument("--port", type=int, default=8080)
    p.set_defaults(func=_cmd_serve)

    p = sub.add_parser("trial", help="one headless plan-and-drive trial")
    p.add_argument("--scene", default="double_bridge", help="library scene name or scene .yaml")
    p.add_argument("--seed", type=int, default=None, help="trial seed (default: the scene's)")
    p.add_argument("--planner", choices=PLANNER_NAMES, default=None)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_trial)

    p = sub.add_parser("plan", help="plan paths with OMPL over a scene's terrain (no driving)")
    p.add_argument("--scene", default="double_bridge", help="library scene name or scene .yaml")
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
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_plan)

    p = sub.add_parser(
        "calibrate-turning", help="sweep motor-speed ratios on flat ground (appendix A, fig. 3.4)"
    )
    p.add_argument("--out", required=True, help="folder for turning.csv/.png/_model.json")
    p.add_argument("--ratios", default="1,1.25,1.5,1.75,2,2.5,3", help="right/left speed ratios")
    p.add_argument("--duration", type=float, default=10.0, help="simulated seconds per ratio")
    p.set_defaults(func=_cmd_calibrate_turning)

    p = sub.add_parser("scene", help="the scene library")
    scene_sub = p.add_subparsers(dest="scene_command", required=True)
    q = scene_sub.add_parser("list", help="list library scenes")
    q.set_defaults(func=_cmd_scene_list)
    q = scene_sub.add_parser(
        "check", help="validate scene files: load, render, and check start and goal"
    )
    q.add_argument("files", nargs="+", metavar="FILE", help="scene .yaml files or library names")
    q.set_defaults(func=_cmd_scene_check)
    q = scene_sub.add_parser("build", help="export a scene's assembled terrain mesh")
    q.add_argument("scene", metavar="NAME", help="library scene name or scene .yaml")
    q.add_argument("-o", "--output", required=True, help="mesh file: .stl, .obj, .ply or .glb")
    q.set_defaults(func=_cmd_scene_build)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except USER_ERRORS as exc:
        print(f"roachplan: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
