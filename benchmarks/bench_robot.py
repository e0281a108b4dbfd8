"""The robot in the loop against the twin, on this machine: the control loop's rate, how fast
a pose dropout and Stop stop the robot, and how well fit recovers the twin's hidden
parameters. Prints shares and ratios; a busy machine shows in them (load average printed).

    .venv/bin/python benchmarks/bench_robot.py [--fit-evaluations 80] [--skip-fit]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from tempfile import TemporaryDirectory

import roachplan
from roachplan.robot import RobotSettings, SimParams, drive_robot

HIDDEN = {"friction": 0.7, "motor_mismatch": 0.03, "motor_gain": 0.96}
MOCAP = ["--latency", "0.04", "--noise", "0.002", "--seed", "5"]


class Twin:
    def __init__(self, *args: str) -> None:
        hidden = []
        for k, v in HIDDEN.items():
            hidden += [f"--{k.replace('_', '-')}", str(v)]
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "roachplan.robot.twin", *hidden, *MOCAP, *args],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None
        self.ready = json.loads(self.proc.stdout.readline())
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.settimeout(5)

    def control(self, op: str, **kw) -> dict:
        self.sock.sendto(
            json.dumps({"op": op, **kw}).encode(), ("127.0.0.1", self.ready["control_port"])
        )
        return json.loads(self.sock.recv(1 << 22))

    def settings(self, **kw) -> RobotSettings:
        return RobotSettings(
            source="natnet",
            source_settings={"command_port": self.ready["natnet_port"]},
            link="udp",
            link_settings={"port": self.ready["command_port"]},
            **kw,
        )

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait()
        self.sock.close()


def after(seconds, action):
    def on_loop(loop):
        threading.Timer(seconds, action, args=(loop,)).start()

    return on_loop


def main() -> None:  # noqa: PLR0915 - the benchmark's steps in order
    ap = argparse.ArgumentParser()
    ap.add_argument("--fit-evaluations", type=int, default=80)
    ap.add_argument("--skip-fit", action="store_true")
    args = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    world = roachplan.load("double_bridge")
    with TemporaryDirectory() as tmp:
        logs = []
        # 1. three full crossings: success, the control rate, the logs for the fit
        for k in range(3):
            twin = Twin()
            try:
                log = Path(tmp) / f"run{k}.mcap"
                t = time.monotonic()
                run = drive_robot(world, twin.settings(log=log, seed=k))
                r = run.result
                print(
                    f"run {k}: {r.reason} in {time.monotonic() - t:.1f} s wall; periods "
                    f"{r.periods}, late {r.late} ({100 * r.late / max(r.periods, 1):.1f} %, "
                    f"goal < 10 %); twin lag max {twin.control('state')['lag_max'] * 1000:.0f} ms"
                )
                logs.append(log)
            finally:
                twin.close()
        # 2. a 500 ms dropout: how long until the first stop frame
        twin = Twin()
        try:
            marks: dict = {}
            run = drive_robot(
                world,
                twin.settings(predict=False),
                on_loop=after(2.0, lambda loop: marks.update(twin.control("dropout", seconds=0.5))),
            )
            cmds = twin.control("commands")["commands"]
            first = min(c[0] for c in cmds if c[4] and c[0] >= marks["t_start"])
            print(
                f"dropout 500 ms: {run.result.reason}, first stop frame "
                f"{(first - marks['t_start']) * 1000:.0f} ms after the dropout began (goal 250 ms)"
            )
        finally:
            twin.close()
        # 3. Stop: how long from stop() to the first stop frame at the robot
        twin = Twin()
        try:
            marks = {}

            def stop(loop):
                marks["t"] = time.monotonic()
                loop.stop()

            run = drive_robot(world, twin.settings(predict=False), on_loop=after(2.0, stop))
            cmds = twin.control("commands")["commands"]
            first = min(c[0] for c in cmds if c[4] and c[0] >= marks["t"])
            print(
                f"Stop: {run.result.reason}, first stop frame at the robot "
                f"{(first - marks['t']) * 1000:.1f} ms after stop() (goal: one period + latency "
                f"= 60 ms)"
            )
        finally:
            twin.close()
        if args.skip_fit:
            return
        fit_and_compare(world, logs, args.fit_evaluations)


def fit_and_compare(world, logs, evaluations: int) -> None:
    """fit on the three logs; compare each before (the scene's nominal robot) and after."""
    from roachplan.robot import FitConfig, compare, fit

    t = time.monotonic()
    result = fit(logs, world, cfg=FitConfig(latency=0.04, max_evaluations=evaluations))
    p = result.params
    print(
        f"fit ({result.evaluations} evaluations, {time.monotonic() - t:.0f} s): friction "
        f"{p.friction:.3f} (twin {HIDDEN['friction']}, "
        f"{100 * abs(p.friction / HIDDEN['friction'] - 1):.1f} % off, goal 10 %), "
        f"mismatch {p.motor_mismatch:.4f} (twin {HIDDEN['motor_mismatch']}, off by "
        f"{abs(p.motor_mismatch - HIDDEN['motor_mismatch']):.4f}, goal 0.02), gain "
        f"{p.motor_gain:.3f} (twin {HIDDEN['motor_gain']}, "
        f"{100 * abs(p.motor_gain / HIDDEN['motor_gain'] - 1):.1f} % off); windows' error "
        f"{result.error_before:.4f} -> {result.error_after:.4f} m"
    )
    exact = SimParams(**HIDDEN)
    for log in logs:
        row = []
        for label, params in (("nominal", None), ("fitted", p), ("twin's own", exact)):
            c = compare(log, world, params=params, latency=0.04)
            row.append((label, c.open_loop.end, c.windows.error(), c.closed_loop.end))
        (_, o0, w0, c0) = row[0]
        print(
            f"compare {log.name}: "
            + "; ".join(
                f"{label}: open-loop end {o:.3f} m ({o / o0:.2f}), windows {w:.3f} m "
                f"({w / w0:.2f}), closed-loop end {c:.3f} m"
                for label, o, w, c in row
            )
        )


if __name__ == "__main__":
    main()
