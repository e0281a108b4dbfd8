"""From command-line flags to configs: each flag's value is checked by the validator of the
setting it sets (roachplan/_settings.py: what a scene file, the page and a script are held to)
before any work, and a refused one is a UsageError naming the flag, the value as typed and what
the setting accepts. Flags that set no config (--count, --runs, --port, ...) have their
validators here, made the same way.

Light: importing this loads no numpy, OMPL, Open3D or trimesh; the validators of a flag's
config are looked up when that flag is given.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from typing import Any

from roachplan import InputError, SettingError, setting_problem
from roachplan._settings import Check, accepted, integer, positive, seed


class UsageError(InputError):
    """A command-line value out of its range; the message names the flag, the value and what
    is accepted."""


def clip(text: object, limit: int = 2000) -> str:
    """text, cut to at most about `limit` characters, saying how much was cut."""
    text = str(text)
    return (
        text if len(text) <= limit else f"{text[:limit]}... ({len(text) - limit} more characters)"
    )


def shown(value: Any) -> str:
    """A flag's value as the user typed it (near enough): numbers as %g, text as it is."""
    if isinstance(value, float):
        return f"{value:g}"
    return clip(value, 80) if isinstance(value, str) else clip(str(value), 40)


def refused(flag: str, value: Any, expected: str) -> UsageError:
    """The one message of a refused flag: `--flag VALUE: what is accepted`."""
    return UsageError(f"{flag} {shown(value)}: {accepted(expected)}")


# -- flags checked before any work -------------------------------------------------------------

MAX_PLAN_COUNT = 100
"""`plan --count` at most: each path costs up to 3 plans (plan_many), all within --time-limit."""
MAX_BENCHMARK_RUNS = 10000
"""`benchmark --runs` at most: per planner, each run up to --time-limit."""
MAX_DURATION = 3600.0
"""`calibrate-turning --duration` at most [s simulated per ratio]."""


def _of(package: str, config: str, name: str) -> Callable[[], Check]:
    """The validator of setting `name` of `package`'s config class, looked up when needed."""

    def lookup() -> Check:
        import importlib

        cls = getattr(importlib.import_module(package), config)
        return lambda v: setting_problem(cls, name, v)

    return lookup


def _whole(lo: int, hi: int | None = None) -> Callable[[], Check]:
    return lambda: integer(lo, hi, noun="a whole number")


FLAGS: dict[str, tuple[str, Callable[[], Check]]] = {
    # argparse dest: (flag, its validator). A setting's flag takes its config's validator.
    "seed": ("--seed", seed),  # every seed: a plan's, RANSAC's, a synthetic capture's noise
    "time_limit": ("--time-limit", _of("roachplan.planning", "PlannerConfig", "time_limit")),
    "try_limit": ("--try-limit", _of("roachplan.planning", "PlannerConfig", "time_limit")),
    "scale": ("--scale", _of("roachplan.scenes", "TerrainObject", "scale")),
    "scad_timeout": ("--scad-timeout", _of("roachplan.scenes", "TerrainObject", "timeout")),
    "repeats": ("--repeats", _of("roachplan.experiments", "ExperimentSpec", "best_path_repeats")),
    "depth_scale": ("--depth-scale", _of("roachplan.perception", "CaptureSettings", "depth_scale")),
    "candidates": ("--candidates", _of("roachplan.experiments", "ChooseConfig", "candidates")),
    "rollouts": ("--rollouts", _of("roachplan.experiments", "ChooseConfig", "rollouts")),
    "budget_s": ("--budget-s", _of("roachplan.experiments", "ChooseConfig", "budget_s")),
    "confidence": ("--confidence", _of("roachplan.experiments", "ChooseConfig", "confidence")),
    "min_success": ("--min-success", _of("roachplan.experiments", "ChooseConfig", "min_success")),
    # The robot in the loop (app/_robot_cli.py): each its setting's validator.
    "twin_friction": ("--friction", _of("roachplan.robot", "TwinConfig", "friction")),
    "twin_motor_gain": ("--motor-gain", _of("roachplan.robot", "TwinConfig", "motor_gain")),
    "twin_motor_mismatch": (
        "--motor-mismatch",
        _of("roachplan.robot", "TwinConfig", "motor_mismatch"),
    ),
    "twin_mass_scale": ("--mass-scale", _of("roachplan.robot", "TwinConfig", "mass_scale")),
    "twin_natnet_port": ("--natnet-port", _of("roachplan.robot", "TwinConfig", "natnet_port")),
    "twin_rigid_body": ("--rigid-body", _whole(1)),
    "twin_pose_rate": ("--pose-rate", _of("roachplan.robot", "TwinConfig", "pose_rate")),
    "twin_latency": ("--latency", _of("roachplan.robot", "TwinConfig", "latency")),
    "twin_noise": ("--noise", _of("roachplan.robot", "TwinConfig", "noise")),
    "twin_noise_angle": ("--noise-angle", _of("roachplan.robot", "TwinConfig", "noise_angle")),
    "twin_drop": ("--drop", _of("roachplan.robot", "TwinConfig", "drop")),
    "twin_command_port": (
        "--command-port",
        _of("roachplan.robot", "TwinConfig", "command_port"),
    ),
    "twin_command_timeout": (
        "--command-timeout",
        _of("roachplan.robot", "TwinConfig", "command_timeout"),
    ),
    "twin_host": ("--host", _of("roachplan.robot", "TwinConfig", "host")),
    "natnet_server": ("--natnet-server", _of("roachplan.robot", "NatNetSettings", "server")),
    "natnet_local": ("--natnet-local", _of("roachplan.robot", "NatNetSettings", "local")),
    "robot_natnet_port": (
        "--natnet-port",
        _of("roachplan.robot", "NatNetSettings", "command_port"),
    ),
    "pose_host": ("--pose-host", _of("roachplan.robot", "UdpJsonSettings", "host")),
    "robot_pose_port": ("--pose-port", _of("roachplan.robot", "UdpJsonSettings", "port")),
    "serial_device": ("--serial", _of("roachplan.robot", "SerialLinkSettings", "port")),
    "robot_baudrate": ("--baudrate", _of("roachplan.robot", "SerialLinkSettings", "baudrate")),
    "robot_rate": ("--rate", _of("roachplan.robot", "LoopConfig", "rate")),
    "robot_max_pose_age": (
        "--max-pose-age",
        _of("roachplan.robot", "SafetyConfig", "max_pose_age"),
    ),
    "robot_max_deviation": (
        "--max-deviation",
        _of("roachplan.robot", "SafetyConfig", "max_deviation"),
    ),
    "robot_area_margin": ("--area-margin", _of("roachplan.robot", "SafetyConfig", "area_margin")),
    "robot_standable_margin": (
        "--standable-margin",
        _of("roachplan.robot", "SafetyConfig", "standable_margin"),
    ),
    "robot_stop_hold": ("--stop-hold", _of("roachplan.robot", "SafetyConfig", "stop_hold")),
    "robot_first_pose_timeout": (
        "--first-pose-timeout",
        _of("roachplan.robot", "RobotSettings", "first_pose_timeout"),
    ),
    "look_ahead_draws": (
        "--look-ahead-draws",
        _of("roachplan.robot", "LookAheadConfig", "draws"),
    ),
    "look_ahead_horizon": (
        "--look-ahead-horizon",
        _of("roachplan.robot", "LookAheadConfig", "horizon"),
    ),
    "guard": ("--guard", _of("roachplan.robot", "RobotSettings", "guard")),
    "replans": ("--replans", _whole(0, 100)),
    "look_ahead_noise": (
        "--look-ahead-noise",
        _of("roachplan.robot", "LookAheadConfig", "position_sd"),
    ),
    "look_ahead_period": (
        "--look-ahead-period",
        _of("roachplan.robot", "RobotSettings", "look_ahead_period"),
    ),
    "look_ahead_engine": (
        "--look-ahead-engine",
        _of("roachplan.robot", "LookAheadConfig", "engine"),
    ),
    "look_ahead_latency": (
        "--look-ahead-latency",
        _of("roachplan.robot", "LookAheadConfig", "latency"),
    ),
    "latency": ("--latency", _of("roachplan.robot", "FitConfig", "latency")),
    "evaluations": ("--evaluations", _of("roachplan.robot", "FitConfig", "max_evaluations")),
    "rounds": ("--rounds", _of("roachplan.robot", "FitConfig", "rounds")),
    "starts": ("--starts", _of("roachplan.robot", "FitConfig", "starts")),
    "horizon": ("--horizon", _of("roachplan.robot", "FitConfig", "horizon")),
    # Flags of the command line alone.
    "count": ("--count", _whole(1, MAX_PLAN_COUNT)),
    "runs": ("--runs", _whole(1, MAX_BENCHMARK_RUNS)),
    "trials": ("--trials", _whole(1)),
    "workers": ("--workers", _whole(1)),
    "validate": ("--validate", _whole(0)),
    "trial": ("--trial", _whole(0)),
    "port": ("--port", _whole(1, 65535)),
    "duration": ("--duration", lambda: positive("s", MAX_DURATION)),
    "square": ("--square", lambda: positive("m")),
}


SCENE_WIDE = ("scale", "scad_timeout")
"""Flags applied to every terrain object of a scene (scenes/_adjust.py), refused in the words
those changes have always used: `--scale: expected ..., got -1.0`."""


def check_flags(args: argparse.Namespace) -> None:
    """Before any work: every flag of FLAGS given is accepted by its validator, else
    UsageError naming the flag, the value and what is accepted."""
    for dest, (flag, check) in FLAGS.items():
        value = getattr(args, dest, None)
        if value is None or (expected := check()(value)) is None:
            continue
        if dest in SCENE_WIDE:
            raise UsageError(f"{flag}: {SettingError('', value, expected).problem}")
        raise refused(flag, value, expected)


def setting_flag(exc: SettingError, flags: dict[str, tuple[str, Any]]) -> UsageError:
    """A config's SettingError as the flag that set the setting: flags maps the setting's key
    to (flag, value as typed)."""
    flag, value = flags.get(exc.key, (f"--{exc.key.replace('_', '-')}", exc.value))
    return refused(flag, value, exc.expected)


# -- values of several numbers -----------------------------------------------------------------


def numbers(text: str | None, flag: str, n: tuple[int, ...]) -> list[float] | None:
    """'a,b,c' -> [a, b, c], finite, with a count in n, or UsageError naming the flag, the value
    and what is wrong with it."""
    if text is None:
        return None
    if len(n) > 2 and n == tuple(range(n[0], n[-1] + 1)):
        counts = f"{n[0]} to {n[-1]}"
    else:
        counts = " or ".join(map(str, n))
    expected = f"expected {counts} comma-separated numbers"
    parts = text.split(",")
    if len(parts) not in n:
        raise UsageError(f"{flag} {clip(repr(text), 80)}: {expected}, got {len(parts)}")
    values = []
    for part in parts:
        try:
            values.append(float(part))
        except ValueError:
            raise UsageError(
                f"{flag} {clip(repr(text), 80)}: {expected}; {clip(repr(part), 40)} is not a number"
            ) from None
        if not math.isfinite(values[-1]):
            raise UsageError(
                f"{flag} {clip(repr(text), 80)}: {expected}; {part.strip()} is not a finite number"
            )
    return values


def pose(text: str | None, flag: str) -> tuple[float, float, float] | None:
    """'x,y,yaw_deg' -> (x [m], y [m], yaw [rad])."""
    if text is None:
        return None
    try:
        x, y, yaw = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(
            f"{flag} {clip(repr(text), 80)}: expected x,y,yaw_deg, e.g. 0,-1.6,90"
        ) from None
    if not all(map(math.isfinite, (x, y, yaw))):
        raise UsageError(f"{flag} {clip(repr(text), 80)}: expected finite numbers x,y,yaw_deg")
    return (x, y, math.radians(yaw))


# -- flags to configs ----------------------------------------------------------------------------


def planner_of(base, args: argparse.Namespace):
    """base (a PlannerConfig) with the command's --planner, --simplify/--smooth/--optimize and
    its planning budget: --try-limit for each try where the command takes it, else
    --time-limit (`plan` spends the budget over all its tries: plan_many's budget)."""
    changes = {"name": args.planner} if getattr(args, "planner", None) else {}
    for flag in ("simplify", "smooth", "optimize"):
        if getattr(args, flag, None) is not None:
            changes[flag] = getattr(args, flag)
    for dest in ("time_limit", "try_limit"):  # (the later wins: a try's own limit)
        if getattr(args, dest, None) is not None:
            changes["time_limit"] = getattr(args, dest)
    return dataclasses.replace(base, **changes)


def as_reference(scene_or_spec):
    """--reference: the report's raw paths and algorithms 1-2 (tables 7.1-7.3)."""
    from roachplan.experiments import reference_settings

    planner, driver = reference_settings(scene_or_spec.planner, scene_or_spec.driver)
    return dataclasses.replace(scene_or_spec, planner=planner, driver=driver)


def engine_flag(p: argparse.ArgumentParser) -> None:
    """--engine: every command that simulates takes it (applied by scene_options)."""
    from roachplan.sim import ENGINES

    p.add_argument(
        "--engine",
        choices=ENGINES,
        default=None,
        help="physics engine, as calibrated (its timestep with it): pybullet, the reference "
        "the report's tables were reproduced with, or mujoco, the fast one (default: the "
        "scene's sim.engine, else pybullet)",
    )


def scene_options(scene, args: argparse.Namespace):
    """The scene with the command line's --scale, --scad-timeout, --scad-backend, --engine and
    --reference applied, where given (their values checked by check_flags)."""
    from roachplan.scenes import scaled_scene, with_engine, with_scad_backend, with_scad_timeout

    if getattr(args, "scale", None) is not None:
        scene = scaled_scene(scene, args.scale)
    if getattr(args, "scad_timeout", None) is not None:
        scene = with_scad_timeout(scene, args.scad_timeout)
    if getattr(args, "scad_backend", None) is not None:
        scene = with_scad_backend(scene, args.scad_backend)
    if getattr(args, "engine", None) is not None:
        scene = with_engine(scene, args.engine)
    if getattr(args, "reference", False):
        scene = as_reference(scene)
    return scene


PINHOLE = ("fx", "fy", "cx", "cy")


def _intrinsics(args: argparse.Namespace) -> str | dict | None:
    """--intrinsics, or --fx --fy --cx --cy (all four) as a mapping."""
    given = {k: getattr(args, k, None) for k in PINHOLE}
    if all(v is None for v in given.values()):
        return args.intrinsics
    missing = [f"--{k}" for k, v in given.items() if v is None]
    if missing:
        raise UsageError(
            f"--fx --fy --cx --cy go together (the pinhole's focal lengths and principal point "
            f"[px]); missing {' '.join(missing)}"
        )
    if args.intrinsics is not None:
        raise UsageError("pass either --intrinsics or --fx --fy --cx --cy, not both")
    return given


def capture_settings_of(args: argparse.Namespace):
    """CaptureSettings from `mesh`'s or `voxel-study`'s flags, through the one reader of a
    scene's `perception:` block (CaptureSettings.from_mapping): a flag refused as the same key
    of a scene file is, with the same words."""
    from roachplan.perception import CaptureSettings

    crop = numbers(getattr(args, "crop", None), "--crop", (6,))
    voxel = numbers(args.voxel, "--voxel", (1, 3))
    typed = {  # key: (flag, its value as typed, as the setting takes it)
        "voxel": ("--voxel", args.voxel, voxel[0] if voxel and len(voxel) == 1 else voxel),
        "method": ("--method", getattr(args, "method", None), getattr(args, "method", None)),
        "camera_pose": (
            "--camera-pose",
            getattr(args, "camera_pose", None),
            numbers(getattr(args, "camera_pose", None), "--camera-pose", (7,)),
        ),
        "intrinsics": ("--intrinsics", args.intrinsics, _intrinsics(args)),
        "depth_scale": ("--depth-scale", args.depth_scale, args.depth_scale),
        "depth_units": ("--depth-units", args.depth_units, args.depth_units),
        "units": ("--units", args.units, args.units),
        "topic": ("--topic", args.topic, args.topic),
        "seed": ("--seed", getattr(args, "seed", None), getattr(args, "seed", None)),
        "frame": ("--frame", getattr(args, "frame", None), getattr(args, "frame", None)),
        "up": ("--up", getattr(args, "up", None), numbers(getattr(args, "up", None), "--up", (3,))),
        "depth_range": (
            "--depth-range",
            getattr(args, "depth_range", None),
            numbers(getattr(args, "depth_range", None), "--depth-range", (2,)),
        ),
        "ground_point": (
            "--ground-point",
            getattr(args, "ground_point", None),
            numbers(getattr(args, "ground_point", None), "--ground-point", (3,)),
        ),
        "recentre": (
            "--recentre",
            getattr(args, "recentre", None),
            getattr(args, "recentre", None),
        ),
        "crop": ("--crop", getattr(args, "crop", None), crop and [crop[:3], crop[3:]]),
    }
    flags = {key: (flag, text) for key, (flag, text, _) in typed.items()}
    flags |= {f"intrinsics.{k}": (f"--{k}", getattr(args, k, None)) for k in PINHOLE}
    try:
        return CaptureSettings.from_mapping(
            {key: value for key, (_, _, value) in typed.items() if value is not None}
        )
    except SettingError as exc:
        if exc.key in {f"intrinsics.{k}" for k in PINHOLE}:  # (the flags' own words for it)
            flag, value = flags[exc.key]
            raise UsageError(f"{flag} {shown(value)}: expected a number of pixels > 0") from None
        raise setting_flag(exc, flags) from None
