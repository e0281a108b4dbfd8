"""Guarded against unguarded runs of the robot loop, side by side in one run: the same twin with
hidden parameters, the same plans' seeds, through the real command line (`roachplan twin`,
`roachplan robot --go --json`), 127.0.0.1 only. Unguarded: the loop alone (its safety stops).
Guarded: `--look-ahead --guard P --replans N`: the look-ahead holds the robot before a predicted
stop and the command re-plans from where it stands, steering clear of where the rollouts failed.

    .venv/bin/python benchmarks/bench_guard.py [--runs 20] [--guard 0.5] [--replans 6] [--fitted]
        [--friction 0.7] [--motor-mismatch 0.06] [--motor-gain 0.95] [--scene double_bridge_rough]
        [--look-ahead-engine mujoco]

--fitted adds a third setting, guarded+fit: guarded runs whose scene names a robot file with the
twin's hidden parameters (what `roachplan fit` recovers at best), so that the look-ahead
simulates the robot it drives rather than one drawn round the nominal robot.

Prints each run (outcome, legs, drive time, share of control periods late) and, per setting,
how many reached the goal with a 95 % interval, the falls (a pose of the body FALL_DROP below
its plan's surface, read from the legs' logs: off a bridge), and the stops by reason. The goal
(a hidden-parameter twin where unguarded runs stop or fall at least 1 time in 4): guarded runs
reach the goal at least 90 % of the time with no fall. A run is a whole crossing: a guarded run
that was held and re-planned and then reached the goal is a success.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

ROACHPLAN = [sys.executable, "-m", "roachplan"]
LATENCY = 0.04
"""The twin's motion capture's latency [s]: what Motive would show, so the guarded robot's
look-ahead is told it (--look-ahead-latency; not one of the hidden parameters)."""
MOCAP = ["--latency", str(LATENCY), "--noise", "0.002"]
"""The twin's motion capture: 40 ms late, 2 mm of noise (as bench_robot's)."""


SETTINGS = ("unguarded", "guarded", "look-ahead only", "guarded+fit")
"""The settings a run may be made in (main's --settings)."""


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of k successes in n."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def fitted_scene(args, tmp: Path) -> Path:
    """A copy of the scene (in tmp) that names a robot file holding the twin's hidden
    parameters: the best `roachplan fit` could recover from runs, so that the look-ahead
    simulates the robot it is driving. Files the scene names are made absolute."""
    import yaml

    from roachplan.robot import SimParams
    from roachplan.scenes import load_scene, write_robot_file

    scene = load_scene(args.scene)
    folder = Path(scene.path).parent
    data = yaml.safe_load(Path(scene.path).read_text())
    for item in data["terrain"]:
        for key, value in item.items():
            if isinstance(value, str) and (folder / value).is_file():
                item[key] = str(folder / value)
    robot_file = tmp / "hidden_roach.yaml"
    hidden = SimParams(
        friction=args.friction, motor_gain=args.motor_gain, motor_mismatch=args.motor_mismatch
    )
    write_robot_file(robot_file, hidden.robot_file())
    data["robot"]["file"] = str(robot_file)
    out = tmp / f"{scene.name}_fitted.yaml"
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


@contextlib.contextmanager
def twin(args, k: int, scene: str):
    """A fresh `roachplan twin` of scene with the hidden parameters (args.friction,
    args.motor_mismatch, args.motor_gain), its motion capture MOCAP with seed k; its ready
    line (its ports)."""
    hidden = [
        "--friction", str(args.friction),
        "--motor-mismatch", str(args.motor_mismatch),
        "--motor-gain", str(args.motor_gain),
    ]  # fmt: skip
    proc = subprocess.Popen(
        [*ROACHPLAN, "twin", "--scene", scene, *hidden, *MOCAP, "--seed", str(k)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout is not None
        yield json.loads(proc.stdout.readline())
    finally:
        proc.terminate()
        proc.wait()


def one_run(args, k: int, setting: str, tmp: Path, scene: str) -> dict:
    """Run k (the twin's noise seed and the plan's seed are k) of a setting ("unguarded", or
    guarded: "guarded", "guarded+fit"): the robot, on `scene`, against a fresh twin of
    args.scene with the hidden parameters; the command's JSON summary, with the wall time."""
    guarded = setting != "unguarded"
    drift = (
        ["--guard-drift", "none", "--guard-stuck", "none", "--no-trim"]
        if setting == "look-ahead only"
        else []
    )
    with twin(args, k, args.scene) as ready:
        flags = [
            "--look-ahead", "--guard", str(args.guard), "--replans", str(args.replans),
            "--look-ahead-engine", args.look_ahead_engine,
            "--look-ahead-latency", str(LATENCY), *drift,
        ]  # fmt: skip
        log = tmp / f"{setting}-{k}.mcap"
        t = time.monotonic()
        ran = subprocess.run(
            [
                *ROACHPLAN,
                "robot",
                "--scene",
                scene,
                "--go",
                "--json",
                "--no-predict",
                "--seed",
                str(k),
                "--natnet-port",
                str(ready["natnet_port"]),
                "--robot",
                f"127.0.0.1:{ready['command_port']}",
                "-o",
                str(log),
                *(flags if guarded else []),
            ],  # fmt: skip
            capture_output=True,
            text=True,
            timeout=600,
            check=False,
        )
        wall = time.monotonic() - t
    if not ran.stdout.strip():
        return {"reason": "error", "detail": ran.stderr.strip()[-300:], "wall": wall}
    return {**json.loads(ran.stdout), "wall": wall}


FALL_DROP = 0.05
"""A run fell when a pose of its robot's body lies this far below the surface of its plan's
nearest waypoint [m] (the body stands a few cm above it): off a bridge onto the floor below."""


def fell(tmp: Path, setting: str, k: int) -> bool:
    """Whether run k of a setting fell, from its legs' logs (RUN.mcap, RUN-2.mcap, ...): the
    robot loop stops on no fall of its own (a floor below a bridge is off the standable
    ground it can reach, as far as the loop's stop allows: a robot can be on it first)."""
    import numpy as np

    from roachplan.robot import read_run

    legs = [tmp / f"{setting}-{k}.mcap", *sorted(tmp.glob(f"{setting}-{k}-*.mcap"))]
    for log in legs:
        if not log.is_file():
            continue
        run = read_run(log)
        path = np.asarray(run.plan["path"], dtype=float)
        body = np.asarray(run.poses["world_p"], dtype=float).reshape(-1, 3)
        if not len(body) or not len(path):
            continue
        nearest = np.argmin(np.linalg.norm(body[:, None, :2] - path[None, :, :2], axis=2), axis=1)
        if (body[:, 2] < path[nearest, 2] - FALL_DROP).any():
            return True
    return False


def held_by(r: dict) -> str:
    """How the guard held a run's legs before its last, each (its reason and the radius of the
    next plan's arcs), e.g. "drift 0.13 m, lookahead 0.19 m"; "-" when none was held."""
    legs = r.get("held", [])
    if not legs:
        return "-"
    radii = [h.get("turning_radius") for h in legs[1:]] + [r.get("turning_radius")]
    return (
        ", ".join(
            f"{h.get('reason', '?')} -> {'-' if radius is None else f'{radius:.2f} m'}"
            for h, radius in zip(legs, radii, strict=True)
        )
        or "-"
    )


def calibration(tmp: Path, setting: str) -> dict | None:
    """The look-aheads of a setting's logs (every leg's) scored against what happened
    (robot.look_ahead_reliability), or None without any."""
    from roachplan.robot import look_ahead_reliability, read_run

    logs = [read_run(p) for p in sorted(tmp.glob(f"{setting}-*.mcap"))]
    logs = [log for log in logs if log.lookaheads]
    return look_ahead_reliability(logs) if logs else None


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=20, help="runs of each setting")
    ap.add_argument("--guard", type=float, default=0.5, help="the guard's threshold")
    ap.add_argument(
        "--replans",
        type=int,
        default=6,
        help="re-plans a guarded run may make (the command's default)",
    )
    ap.add_argument(
        "--look-ahead-engine",
        default="mujoco",
        help="the look-ahead's engine (its lockstep: faster)",
    )
    ap.add_argument("--scene", default="double_bridge_rough")
    ap.add_argument(
        "--keep", default=None, metavar="DIR", help="keep the runs' logs in DIR (default: none)"
    )
    ap.add_argument(
        "--fitted",
        action="store_true",
        help="also guarded runs whose scene names a robot file with the twin's hidden "
        "parameters (the best a fit could give): the look-ahead then simulates that robot",
    )
    ap.add_argument(
        "--settings",
        default="unguarded,guarded",
        help="the settings run, comma-separated, of unguarded, guarded, look-ahead only "
        "(guarded with --guard-drift none --guard-stuck none --no-trim: only the look-ahead's "
        "chance holds it, and the commands go untrimmed), guarded+fit (as --fitted adds)",
    )
    ap.add_argument("--friction", type=float, default=0.7, help="hidden: ground friction")
    ap.add_argument(
        "--motor-mismatch", type=float, default=0.06, help="hidden: L x (1+d), R x (1-d)"
    )
    ap.add_argument("--motor-gain", type=float, default=0.95, help="hidden: both motors x this")
    args = ap.parse_args()
    print(
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; {args.scene}, twin "
        f"friction {args.friction}, motor mismatch {args.motor_mismatch}, motor gain "
        f"{args.motor_gain}; guard {args.guard}, up to {args.replans} re-plans, look-ahead in "
        f"{args.look_ahead_engine}",
        flush=True,
    )
    names = tuple(n.strip() for n in args.settings.split(","))
    if args.fitted and "guarded+fit" not in names:
        names = (*names, "guarded+fit")
    unknown = set(names) - set(SETTINGS)
    if unknown:
        ap.error(
            f"--settings: {', '.join(sorted(unknown))}: expected some of {', '.join(SETTINGS)}"
        )
    results: dict[str, list[dict]] = {name: [] for name in names}
    with TemporaryDirectory() as scratch:
        tmp = args.keep or scratch
        Path(tmp).mkdir(parents=True, exist_ok=True)
        scenes = {name: args.scene for name in names}
        if "guarded+fit" in names:
            scenes["guarded+fit"] = str(fitted_scene(args, Path(tmp)))
        for k in range(args.runs):  # (the settings interleaved: the machine's load falls alike)
            for name, runs in results.items():
                r = one_run(args, k, name, Path(tmp), scenes[name])
                r["fell"] = fell(Path(tmp), name, k)
                runs.append(r)
                late = r.get("late", 0) / max(r.get("periods", 0) or 1, 1)
                print(
                    f"{name:11s} run {k:2d}: {r['reason']:10s}{' FELL' if r['fell'] else ''} "
                    f"legs {1 + len(r.get('held', []))} "
                    f"({held_by(r)}) "
                    f"drive {r.get('drive_time') or 0:5.1f} s, late {100 * late:4.1f} %, "
                    f"lowest P(hold) {r.get('lowest_p_hold')}, trim {r.get('trim')}; "
                    f"{r.get('detail', '')[:90]}"
                    + (
                        f"; not re-planned: {r['replan_error'][:90]}"
                        if r.get("replan_error")
                        else ""
                    ),
                    flush=True,
                )
        reliability = {name: calibration(Path(tmp), name) for name in names if name != "unguarded"}
    print()
    for name, runs in results.items():
        ok = sum(r.get("success", False) for r in runs)
        lo, hi = wilson(ok, len(runs))
        reasons = collections.Counter(r["reason"] for r in runs if not r.get("success"))
        falls = sum(r["fell"] for r in runs)
        held = sum(len(r.get("held", [])) for r in runs)
        late = sum(r.get("late", 0) for r in runs) / max(sum(r.get("periods", 0) for r in runs), 1)
        print(
            f"{name:11s}: reached the goal {ok}/{len(runs)} ({100 * ok / max(len(runs), 1):.0f} %, "
            f"95 % interval {100 * lo:.0f}-{100 * hi:.0f} %), falls {falls}, held and re-planned "
            f"{held} times, control periods late {100 * late:.1f} %; stops: "
            + (", ".join(f"{n} {c}" for c, n in reasons.items()) or "none")
        )
    for name, ahead in reliability.items():
        if ahead is None or not ahead["scored"]:
            print(f"{name}: no look-ahead could be scored")
            continue
        bins = "; ".join(
            f"{b['bin'][0]:g}-{b['bin'][1]:g}: {b['scored']} scored, predicted "
            f"{b['predicted']:.2f}, held {b['observed']:.2f}"
            + (" (goal: within 0.10)" if b["scored"] >= 20 else " (under 20: says little)")
            for b in ahead["bins"]
            if b["scored"]
        )
        print(f"{name} look-aheads: {ahead['scored']} scored, Brier {ahead['brier']:.3f}; {bins}")
    if "unguarded" not in results:
        return
    unguarded = results["unguarded"]
    stopped = sum(not r.get("success") for r in unguarded) / max(len(unguarded), 1)
    print(
        f"the setting: unguarded runs stopped or fell {100 * stopped:.0f} % of the time "
        f"({'at least' if stopped >= 0.25 else 'LESS than'} 1 in 4); goal for guarded: at least "
        "90 % reached with no fall"
    )


if __name__ == "__main__":
    main()
