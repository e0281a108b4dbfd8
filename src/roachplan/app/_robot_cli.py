"""`roachplan twin`, `robot`, `compare` and `fit`: a real robot (or its stand-in) in the loop.

Every flag that sets a setting is checked by that setting's validator before any work
(app/_flags.py FLAGS); the addresses (HOST:PORT) and the transform are read here, each refused
in one line naming the flag.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import select
import sys
import time
from pathlib import Path

from roachplan.experiments import check_output_file

from ._flags import UsageError, clip, numbers, pose, refused, setting_flag


def _address(text: str | None, flag: str):
    """'HOST:PORT' (or 'PORT') -> (host, port), each checked by the robot's validators."""
    if text is None:
        return None
    from roachplan.robot import parse_address

    try:
        return parse_address(text)
    except ValueError as exc:
        shown = repr(text) if str(exc).startswith("expected HOST") else text
        raise UsageError(f"{flag} {clip(shown, 80)}: {exc}") from None


def _transform(text: str | None, flag: str):
    """'X,Y,Z,YAW_DEG' -> a FrameTransform (None: none given)."""
    values = numbers(text, flag, (4,))
    if values is None:
        return None
    from roachplan.robot import FrameTransform

    x, y, z, yaw = values
    return FrameTransform.from_xyz_yaw(x, y, z, math.radians(yaw))


# -- twin -----------------------------------------------------------------------------------------


def twin_config(args: argparse.Namespace):
    """The TwinConfig of `roachplan twin`'s flags (each checked by check_flags before)."""
    from roachplan.robot import FrameTransform, TwinConfig

    if args.pose == "udp-json" and args.pose_target is None:
        raise UsageError("--pose udp-json sends the poses to --pose-target HOST:PORT; give it")
    if args.pose != "udp-json" and args.pose_target is not None:
        raise UsageError("--pose-target is where --pose udp-json sends poses; add --pose udp-json")
    return TwinConfig(
        scene=args.scene,
        start=pose(args.start, "--start"),
        friction=args.twin_friction,
        motor_gain=args.twin_motor_gain,
        motor_mismatch=args.twin_motor_mismatch,
        mass_scale=args.twin_mass_scale,
        pose=args.pose,
        natnet_port=args.twin_natnet_port,
        rigid_body=(args.twin_rigid_body, "roach"),
        pose_target=_address(args.pose_target, "--pose-target"),
        pose_rate=args.twin_pose_rate,
        latency=args.twin_latency,
        noise=args.twin_noise,
        noise_angle=args.twin_noise_angle,
        drop=args.twin_drop,
        seed=0 if args.seed is None else args.seed,
        mocap=_transform(args.mocap, "--mocap") or FrameTransform(),
        command=args.command,
        command_port=args.twin_command_port,
        serial=args.serial,
        command_timeout=args.twin_command_timeout,
        host=args.twin_host,
    )


def cmd_twin(args: argparse.Namespace) -> int:
    from roachplan.robot import run_twin

    return run_twin(twin_config(args))


# -- robot ----------------------------------------------------------------------------------------

RUN_LOG_MARK = b"roachplan.robot-run"
"""In the head of every run log roachplan writes (its MCAP profile): `robot -o` replaces such a
file without --force."""


def _run_log_written(head: bytes) -> bool:
    return head.startswith(b"\x89MCAP0\r\n") and RUN_LOG_MARK in head


def robot_settings(args: argparse.Namespace, log: Path | None):
    """The RobotSettings of `roachplan robot`'s flags."""
    from roachplan import SettingError, setting_problem
    from roachplan.robot import LookAheadConfig, LoopConfig, RobotSettings, SafetyConfig

    if args.source == "natnet":
        from roachplan.robot import NatNetSettings

        rigid = int(args.rigid_body) if args.rigid_body.isdigit() else args.rigid_body
        if (expected := setting_problem(NatNetSettings, "rigid_body", rigid)) is not None:
            raise refused("--rigid-body", args.rigid_body, expected)
        source_settings: dict = {
            "server": args.natnet_server,
            "local": args.natnet_local,
            "command_port": args.robot_natnet_port,
            "rigid_body": rigid,
            "up_axis": args.up_axis,
        }
        stray = [f for f, v in (("--pose-port", args.robot_pose_port),) if v is not None]
    else:
        source_settings = {"host": args.pose_host, "port": args.robot_pose_port or 9871}
        stray = [
            f
            for f, v in (
                ("--natnet-server", args.natnet_server != "127.0.0.1"),
                ("--natnet-port", args.robot_natnet_port != 1510),
            )
            if v
        ]
    if stray:
        raise UsageError(f"{stray[0]} is a setting of another --source than {args.source}")
    if args.link == "udp":
        if args.serial_device is not None:
            raise UsageError("--serial is the device of --link serial; add --link serial")
        host, port = _address(args.robot_address, "--robot") or ("127.0.0.1", 9870)
        link_settings: dict = {"host": host, "port": port}
    else:
        if args.serial_device is None:
            raise UsageError("--link serial needs --serial DEVICE (e.g. /dev/ttyUSB0)")
        if args.robot_address is not None:
            raise UsageError(
                "--robot HOST:PORT is where --link udp sends; drop it with --link serial"
            )
        link_settings = {"port": args.serial_device, "baudrate": args.robot_baudrate}
    safety = {
        k: getattr(args, f"robot_{k}")
        for k in ("max_pose_age", "max_deviation", "area_margin", "standable_margin", "stop_hold")
        if getattr(args, f"robot_{k}") is not None
    }
    loop = LoopConfig(rate=args.robot_rate, safety=SafetyConfig(**safety))
    ahead = _look_ahead_flags(args)
    try:
        return RobotSettings(
            source=args.source,
            source_settings=source_settings,
            link=args.link,
            link_settings=link_settings,
            transform=_transform(args.transform, "--transform"),
            seed=args.seed,
            loop=loop,
            log=log,
            predict=not args.no_predict,
            first_pose_timeout=args.robot_first_pose_timeout,
            look_ahead=LookAheadConfig(**ahead) if args.look_ahead else None,
            guard=args.guard,
            trim=not args.no_trim,
            **_guard_flags(args),
            **_edge_keep(args),
            **(
                {}
                if args.look_ahead_period is None
                else {"look_ahead_period": args.look_ahead_period}
            ),
        )
    except SettingError as exc:
        if exc.key in ("guard_drift", "guard_drift_lead", "guard_stuck", "edge_keep"):
            flag = "--" + exc.key.replace("_", "-")
            raise refused(flag, getattr(args, exc.key), exc.expected) from None
        raise


def _look_ahead_flags(args: argparse.Namespace) -> dict:
    """LookAheadConfig's settings from the --look-ahead-* flags (those given); UsageError for
    one of them, or --guard, without --look-ahead."""
    names = {
        "draws": "draws",
        "horizon": "horizon",
        "noise": "position_sd",
        "engine": "engine",
        "latency": "latency",
    }
    ahead = {
        field: getattr(args, f"look_ahead_{k}")
        for k, field in names.items()
        if getattr(args, f"look_ahead_{k}") is not None
    }
    given = [
        f"--look-ahead-{k}"
        for k in (*names, "period")
        if getattr(args, f"look_ahead_{k}") is not None
    ]
    if given and not args.look_ahead:
        raise UsageError(f"{given[0]} is a setting of the look-ahead; add --look-ahead")
    if args.guard is not None and not args.look_ahead:
        raise UsageError("--guard holds the robot on what the look-ahead says; add --look-ahead")
    if args.no_trim and not args.look_ahead:
        raise UsageError("--no-trim: only the look-ahead trims the commands; add --look-ahead")
    return ahead


def _guard_flags(args: argparse.Namespace) -> dict:
    """RobotSettings' guard_drift from --guard-drift (a share of --max-deviation, or 'none'),
    guard_drift_lead from --guard-drift-lead (seconds, or 'none') and guard_stuck from
    --guard-stuck (a share of the scene's stuck time, or 'none'), as keywords; none for a flag
    absent (the setting's default)."""
    for flag, value in (
        ("--guard-drift", args.guard_drift),
        ("--guard-drift-lead", args.guard_drift_lead),
        ("--guard-stuck", args.guard_stuck),
    ):
        if value is not None and args.guard is None:
            raise UsageError(f"{flag} is a setting of the guard; add --guard P")
    return {
        **_number_or_none(
            "guard_drift", "--guard-drift", args.guard_drift, "a share of --max-deviation"
        ),
        **_number_or_none(
            "guard_drift_lead", "--guard-drift-lead", args.guard_drift_lead, "a time [s]"
        ),
        **_number_or_none(
            "guard_stuck", "--guard-stuck", args.guard_stuck, "a share of the stuck time"
        ),
    }


def _edge_keep(args: argparse.Namespace) -> dict:
    """RobotSettings' edge_keep from --edge-keep (metres, or 'none'), as a keyword; none when
    the flag is absent (the setting's default)."""
    return _number_or_none("edge_keep", "--edge-keep", args.edge_keep, "a distance [m]")


def _number_or_none(key: str, flag: str, text: str | None, number: str) -> dict:
    """{key: the number `text` gives, or None for 'none'} for a flag that may turn its setting
    off; {} when the flag is absent; the flag refused (expected `number` or 'none') else. The
    setting's own validator checks the number's range (robot_settings)."""
    if text is None:
        return {}
    word = text.strip().lower()
    try:
        return {key: None if word == "none" else float(word)}
    except ValueError:
        raise refused(flag, text, f"expected {number} or 'none'") from None


def _ask_go(loop) -> bool:
    """The CLI's Go: Enter on stdin; Ctrl-C, SIGTERM or the end of stdin: no Go."""
    print(
        "roachplan: the robot is held (stop frames); press Enter to Go, Ctrl-C to stop",
        file=sys.stderr,
        flush=True,
    )
    while not loop.stopping:
        try:
            readable, _, _ = select.select([sys.stdin], [], [], 0.1)
        except (OSError, ValueError):  # no stdin to read
            return False
        if readable:
            return sys.stdin.readline() != ""
    return False


def cmd_robot(args: argparse.Namespace) -> int:
    robot_settings(args, None)  # (every flag refused before the scene loads)

    from roachplan.planning import PlanningError
    from roachplan.processes import ChildError
    from roachplan.robot import (
        GUARD_HOLDS,
        RobotError,
        clearance,
        drive_robot,
        open_link,
        open_pose_source,
        rejoin_plan,
    )
    from roachplan.scenes import build_world, load_scene

    from ._scene_cli import scene_inputs

    scene = load_scene(args.scene)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    out = check_output_file(
        args.output or f"{scene.name}-robot-{stamp}.mcap",
        suffixes=(".mcap",),
        inputs=scene_inputs(scene),
        replaceable=_run_log_written,
        kind="a robot run log roachplan wrote",
        force=args.force,
    )
    settings = robot_settings(args, out)
    world = build_world(scene)
    for note in world.notes:
        print(f"roachplan: {note}", file=sys.stderr)

    avoid: list[tuple[float, float]] = []  # (a re-plan's: where the rollouts failed)

    def ready(loop) -> bool:
        path = loop.path
        length = float(sum(math.dist(a[:2], b[:2]) for a, b in zip(path, path[1:], strict=False)))
        x, y, yaw = _here(loop)
        clear = ""
        if avoid:  # (what the leg's /plan record says: robot.clearance)
            keeps = clearance(path, avoid)
            clear = (
                f"; the {len(avoid)} places its rollouts failed are all next to the robot"
                if math.isinf(keeps)
                else f"; it keeps {keeps:.2f} m from the {len(avoid)} places its rollouts failed"
            )
        print(
            f"roachplan: the robot stands at ({x:.3f}, {y:.3f}) m, {math.degrees(yaw):.0f} deg; "
            f"planned {len(path)} waypoints, {length:.2f} m to the goal{clear}",
            file=sys.stderr,
            flush=True,
        )
        return True if args.go else _ask_go(loop)

    # One pose source and one command link for every leg: the commands' sequence numbers run
    # on across a re-plan. (A robot takes a frame only if it is numbered after the last it
    # took: a new link's frames, from 0 again, were dropped and the re-planned leg stood still.)
    with contextlib.ExitStack() as stack:
        source = open_pose_source(settings.source, **settings.source_settings)
        stack.callback(source.close)
        link = open_link(settings.link, **settings.link_settings)
        stack.callback(link.close)
        run = drive_robot(world, settings, ready=ready, source=source, link=link)
        held = []  # the legs the guard ended: re-planned from where the robot stood
        replan_error = None  # (why the re-plan after the last hold failed: it stays held)
        drove_on: dict[int, str] = {}  # (held leg k's re-plan failed: why; it drove on)
        while run.result.reason in GUARD_HOLDS and len(held) < args.replans:
            held.append(run)
            radius, wider = _replan_arcs(world.scene.planner.turning_radius, held)
            print(
                f"roachplan: held by the guard: {run.result.detail}; re-planning from where "
                f"the robot stands (re-plan {len(held)} of at most {args.replans}){wider}",
                file=sys.stderr,
                flush=True,
            )
            log = _leg_log(args, scene, out, len(held) + 1) if settings.log is not None else None
            settings = dataclasses.replace(settings, transform=run.transform, log=log)
            # Steer clear of where the rollouts that held it failed (the guard's look-ahead: the
            # last one made); ready() says how far the new path keeps from them.
            avoid[:] = [(x, y) for x, y, _ in run.lookaheads[-1].failures] if run.lookaheads else []
            try:
                run = drive_robot(
                    world,
                    settings,
                    ready=ready,
                    avoid=avoid,
                    source=source,
                    link=link,
                    turning_radius=radius,
                    estimates=run.estimates,
                )
            except (RobotError, PlanningError, ChildError) as exc:  # (no plan from there)
                if run.result.reason != "drift" or run.result.end is None:
                    held.pop()  # (the held leg is the run's last: `run`)
                    replan_error = str(exc)
                    print(
                        f"roachplan: the re-plan failed: {exc}; the robot stays held",
                        file=sys.stderr,
                        flush=True,
                    )
                    break
                drove_on[len(held) - 1] = str(exc)
                # A drift hold's robot is on standable ground a few cm off a path the planner
                # made: with no new plan, it drives on along the rest of that one, as an
                # unguarded robot would (a look-ahead hold's robot is predicted to fail on it).
                print(
                    f"roachplan: the re-plan failed: {exc}; driving on along the rest of the "
                    f"path it drifted off",
                    file=sys.stderr,
                    flush=True,
                )
                run = drive_robot(
                    world,
                    settings,
                    plan=rejoin_plan(
                        run.path_xyz,
                        run.spins,
                        run.result.end[:2],
                        seed=run.plan_seed or 0,
                        turning_radius=run.turning_radius,
                    ),
                    ready=ready,
                    source=source,
                    link=link,
                    estimates=run.estimates,
                )
    return _report(args, scene.name, run, held, replan_error=replan_error, drove_on=drove_on)


def _replan_arcs(radius: float | None, held: list) -> tuple[float | None, str]:
    """(the radius of a re-plan's arcs [m], what to tell of it): the scene's `radius` (None: a
    planner without arcs) widened for each leg the guard held for drifting off its path, and
    once it held one for making no progress, lines and turns on the spot (replan_radius)."""
    from roachplan.robot import SPIN_ONLY_RADIUS, replan_radius

    drifts = sum(h.result.reason == "drift" for h in held)
    stalled = any(h.result.reason == "stall" for h in held)
    if radius is None or not (drifts or stalled):
        return radius, ""
    wider = replan_radius(radius, drifts, stalled=stalled)
    if stalled:
        return wider, "; straight lines and turns on the spot: it made no progress along its path"
    if wider == SPIN_ONLY_RADIUS:
        return wider, (
            f"; straight lines and turns on the spot: it drifted off arcs of {radius:.2f} m "
            "and wider"
        )
    return wider, f"; arcs of {wider:.2f} m: it drifted off arcs of {radius:.2f} m or wider"


def _leg_log(args: argparse.Namespace, scene, out: Path, leg: int) -> Path:
    """The log of a re-planned leg (leg >= 2), beside the first: RUN-2.mcap, ...; checked as
    the first was (never an input, nor a file roachplan did not write unless --force)."""
    from ._scene_cli import scene_inputs

    return check_output_file(
        out.with_name(f"{out.stem}-{leg}{out.suffix}"),
        suffixes=(".mcap",),
        inputs=scene_inputs(scene),
        replaceable=_run_log_written,
        kind="a robot run log roachplan wrote",
        force=args.force,
    )


def _report(
    args: argparse.Namespace,
    scene_name: str,
    run,
    held: list,
    *,
    replan_error: str | None = None,
    drove_on: dict[int, str] | None = None,
) -> int:
    """Print what a robot command did (its last leg `run`, the legs the guard ended before it:
    `held`, why re-planning after the last hold failed: replan_error, and after which held
    legs it drove on along the old path instead, why: drove_on), as JSON with --json; its exit
    status."""
    drove_on = drove_on or {}
    r = run.result
    summary = {
        "scene": scene_name,
        "reason": r.reason,
        "detail": r.detail,
        "replan_error": replan_error,
        "success": r.success,
        "drive_time": None if r.t_go is None else r.t_stop - r.t_go,
        "start": r.start,
        "end": r.end,
        "periods": r.periods,
        "late": r.late,
        "prediction": None
        if run.prediction is None
        else {k: run.prediction[k] for k in ("outcome", "reason", "drive_time")},
        "log": None if run.log is None else str(run.log),
        "held": [
            {
                "detail": h.result.detail,
                "log": None if h.log is None else str(h.log),
                "reason": h.result.reason,
                "failures": [list(f) for f in h.lookaheads[-1].failures] if h.lookaheads else [],
                "turning_radius": h.turning_radius,
                "trim": h.trim,
                # (why no re-plan was found after it, when it drove on along its path instead)
                "drove_on": drove_on.get(k),
            }
            for k, h in enumerate(held)
        ],
        "plan_seed": run.plan_seed,
        "clearance": run.clearance,
        "turning_radius": run.turning_radius,
        "trim": run.trim,
        "lookaheads": len(run.lookaheads),
        "lowest_p_hold": min((a.p_hold for a in run.lookaheads), default=None),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        drove = "" if summary["drive_time"] is None else f" after {summary['drive_time']:.2f} s"
        late = f"{r.late} of {r.periods} control periods late" if r.periods else "never drove"
        for k, h in enumerate(held):
            then = (
                "re-planned"
                if k not in drove_on
                else f"drove on along its path (no re-plan: {drove_on[k]})"
            )
            print(f"held by the guard, {then}: {h.result.detail} (wrote {h.log})")
        print(f"{r.reason}{drove}: {r.detail}\n{late}")
        if replan_error is not None:
            print(f"not re-planned: {replan_error}")
        if run.prediction is not None:
            p = run.prediction
            print(
                f"the simulation predicted: {p['outcome']} ({p['reason']}) in {p['drive_time']:.2f} s"
            )
        if run.lookaheads:
            low = min(run.lookaheads, key=lambda a: a.p_hold)
            print(
                f"looked ahead {len(run.lookaheads)} times; the lowest chance of going on "
                f"{low.horizon:g} s without a stop or a fall: {low.p_hold:.2f}, from "
                f"({low.start[0]:.2f}, {low.start[1]:.2f})"
            )
        print(f"wrote {run.log}")
    if r.success:
        return 0
    return 130 if r.reason == "signal" else 1


def _here(loop) -> tuple[float, float, float]:
    world = loop.latest_world
    if world is None:
        return (math.nan, math.nan, math.nan)
    from roachplan.robot import yaw_of

    (x, y, _), q = world
    return (x, y, yaw_of(q))


# -- compare and fit ------------------------------------------------------------------------------


def _fit_config(args: argparse.Namespace):
    """The FitConfig of `fit`'s flags (the numbers checked by check_flags; --parameters here,
    by the same validator)."""
    from roachplan import SettingError
    from roachplan.robot import FitConfig

    names = tuple(p.strip() for p in args.parameters.split(",")) if args.parameters else None
    values = {
        "parameters": names,
        "latency": args.latency,
        "max_evaluations": args.evaluations,
        "rounds": args.rounds,
        "starts": args.starts,
        "horizon": args.horizon,
    }
    try:
        return FitConfig(**{k: v for k, v in values.items() if v is not None})
    except SettingError as exc:
        raise setting_flag(exc, {"parameters": ("--parameters", args.parameters)}) from None


def cmd_compare(args: argparse.Namespace) -> int:
    from roachplan.robot import look_ahead_reliability, params_of_robot_file, read_run

    logs = [read_run(path) for path in args.logs]  # (every log read before any is simulated)
    params = params_of_robot_file(args.robot_file) if args.robot_file else None
    compared = [] if args.look_ahead_only else [_compare_one(log, args, params) for log in logs]
    with_ahead = [log for log in logs if log.lookaheads]
    ahead = look_ahead_reliability(with_ahead) if with_ahead else None
    if args.json:
        if len(logs) == 1 and compared:  # (one log: its comparison's fields at the top)
            print(json.dumps({**compared[0], "look_ahead": _json_safe(ahead)}))
        else:
            each = compared or [{}] * len(logs)  # (--look-ahead-only: no comparison)
            runs = [{"log": str(log.path), **c} for log, c in zip(logs, each, strict=True)]
            print(json.dumps({"runs": runs, "logs": len(logs), "look_ahead": _json_safe(ahead)}))
        return 0
    if ahead is None:
        print("look-ahead: none recorded in " + ("this log" if len(logs) == 1 else "these logs"))
        return 0
    made = sum(len(log.lookaheads) for log in logs)
    over = "" if len(logs) == 1 else f" over {len(with_ahead)} of {len(logs)} runs"
    brier = f"Brier score {ahead['brier']:.3f}" if ahead["scored"] else "no Brier score"
    print(
        f"look-ahead{over}: {made} made, {ahead['scored']} scored against what happened over "
        f"their horizon (a run the guard, Stop or a signal ended scores none), {brier}"
    )
    for b in ahead["bins"]:
        if b["scored"]:
            few = " (fewer than 20: says little)" if b["scored"] < 20 else ""
            print(
                f"  predicted {b['bin'][0]:g}-{b['bin'][1]:g}: {b['scored']} scored, mean "
                f"predicted {b['predicted']:.2f}, held {b['observed']:.2f}{few}"
            )
    return 0


def _json_safe(ahead: dict | None) -> dict | None:
    """The reliability's JSON: a Brier score of nothing scored is null, not NaN."""
    if ahead is None or ahead["scored"]:
        return ahead
    return {**ahead, "brier": None}


def _compare_one(log, args: argparse.Namespace, params) -> dict:
    """compare() of one run log, printed (without --json); its JSON."""
    import numpy as np

    from roachplan.robot import compare, log_world

    world = log_world(log, args.scene)
    c = compare(log, world, params=params, latency=args.latency or 0.0)
    if args.json:
        return c.to_json()
    p = c.params
    print(
        f"{log.path.name}: scene {world.scene.name}; simulated with friction {p.friction:.3f}, "
        f"motor gain {p.motor_gain:.3f}, mismatch {p.motor_mismatch:+.3f}, mass x{p.mass_scale:.2f}"
    )
    print(
        f"{'t [s]':>6} {'open-loop [m]':>14} {'heading [deg]':>13} {'closed-loop [m]':>16} {'heading [deg]':>13}"
    )
    t = c.open_loop.t
    for k in _every(t, 1.0):
        print(
            f"{t[k]:6.1f} {c.open_loop.position[k]:14.3f} {math.degrees(c.open_loop.heading[k]):13.1f} "
            f"{c.closed_loop.position[k]:16.3f} {math.degrees(c.closed_loop.heading[k]):13.1f}"
        )
    print(
        f"end error: open loop {c.open_loop.end:.3f} m, closed loop {c.closed_loop.end:.3f} m; "
        f"rms: open loop {c.open_loop.rms:.3f} m, closed loop {c.closed_loop.rms:.3f} m\n"
        f"windows ({len(c.windows.t)} of 1 s, each from the robot's own pose and leg phase): "
        f"error {c.windows.error():.3f} m (position rms "
        f"{float(np.sqrt(np.mean(c.windows.position**2))):.3f} m, turn rms "
        f"{math.degrees(float(np.sqrt(np.mean(c.windows.heading**2)))):.1f} deg)\n"
        f"outcome: the robot {c.robot_outcome}, the simulation {c.sim_outcome}: "
        f"{'they agree' if c.outcome_agrees else 'they DISAGREE'}\n"
    )
    return c.to_json()


def _every(t, step: float) -> list[int]:
    """Indices of t about `step` apart [s], and the last."""
    out, next_t = [], -math.inf
    for k, tk in enumerate(t):
        if tk >= next_t:
            out.append(k)
            next_t = tk + step
    if out and out[-1] != len(t) - 1:
        out.append(len(t) - 1)
    return out


def _robot_file_written(head: bytes) -> bool:
    from roachplan.scenes import ROBOT_FILE_HEADER

    return head.startswith(ROBOT_FILE_HEADER.encode())


def cmd_fit(args: argparse.Namespace) -> int:
    from roachplan.robot import fit, log_world, read_run

    out = check_output_file(
        args.output,
        suffixes=(".yaml", ".yml"),
        inputs=args.logs,
        replaceable=_robot_file_written,
        kind="a robot file roachplan wrote",
        force=args.force,
    )
    cfg = _fit_config(args)
    logs = [read_run(p) for p in args.logs]
    world = log_world(logs[0], args.scene)
    result = fit(logs, world, cfg=cfg, out=out)
    if args.json:
        print(json.dumps({**result.to_json(), "output": str(out)}))
        return 0
    p, b = result.params, result.before
    print(
        f"fitted {', '.join(result.fitted)} to {len(logs)} run(s) ({result.evaluations} simulations)"
    )
    for name in result.fitted:
        print(f"  {name:15s} {getattr(b, name):8.4f} -> {getattr(p, name):8.4f}")
    print(
        f"open-loop error (whole runs, mean over the logs): {result.error_before:.4f} m before, "
        f"{result.error_after:.4f} m after\nwrote {out} (a scene names it: robot: {{file: "
        f"{out.name}}})"
    )
    return 0
