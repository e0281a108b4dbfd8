"""`python -m roachplan.robot.twin`: a simulated roach that speaks as a real one (robot/_twin.py).

    python -m roachplan.robot.twin --scene double_bridge --pose natnet --natnet-port 1510 \
        --command udp --command-port 9870 --friction 0.7 --motor-mismatch 0.03 \
        --latency 0.04 --noise 0.002 --seed 1

It prints one JSON line when it is ready ({"ready": true, "natnet_port": ..., "command_port":
..., "serial": "/dev/pts/N", "control_port": ...}) and runs until SIGTERM, Ctrl-C or the
control port's {"op": "quit"}. (`roachplan twin` will be the same command.)
"""

from __future__ import annotations

import argparse
import math
import sys

from ._errors import RobotError
from ._transform import FrameTransform
from ._twin import TwinConfig, run_twin


def _floats(text: str, n: int, flag: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != n or not all(map(math.isfinite, values)):
        raise RobotError(f"{flag} {text!r}: expected {n} comma-separated numbers")
    return values


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="python -m roachplan.robot.twin", description=(__doc__ or "").split("\n")[0]
    )
    ap.add_argument("--scene", default="double_bridge")
    ap.add_argument("--start", help="X,Y,YAW_DEG where the robot stands (default: the scene's)")
    ap.add_argument("--friction", type=float, help="ground friction (default: the scene's)")
    ap.add_argument("--motor-gain", type=float, default=1.0)
    ap.add_argument("--motor-mismatch", type=float, default=0.0)
    ap.add_argument("--mass-scale", type=float, default=1.0)
    ap.add_argument("--pose", choices=("natnet", "udp-json"), default="natnet")
    ap.add_argument("--natnet-port", type=int, default=0, help="NatNet command port (0: free)")
    ap.add_argument("--rigid-body", type=int, default=1, help="the rigid body's streaming id")
    ap.add_argument("--pose-target", help="udp-json: HOST:PORT to send poses to")
    ap.add_argument("--pose-rate", type=float, default=120.0, help="[Hz]")
    ap.add_argument("--latency", type=float, default=0.0, help="pose latency [s]")
    ap.add_argument("--noise", type=float, default=0.0, help="position noise sigma [m]")
    ap.add_argument("--noise-angle", type=float, default=0.0, help="orientation noise [rad]")
    ap.add_argument("--drop", type=float, default=0.0, help="probability a pose is lost")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mocap", help="X,Y,Z,YAW_DEG: T_world_mocap the poses are given in")
    ap.add_argument("--command", choices=("udp", "serial"), default="udp")
    ap.add_argument("--command-port", type=int, default=0)
    ap.add_argument("--serial", default="pty", help="pty (make one) or a device path")
    ap.add_argument("--command-timeout", type=float, default=0.25, help="[s]")
    return ap


def config_from_args(args: argparse.Namespace) -> TwinConfig:
    start = None
    if args.start:
        x, y, yaw = _floats(args.start, 3, "--start")
        start = (x, y, math.radians(yaw))
    mocap = FrameTransform()
    if args.mocap:
        x, y, z, yaw = _floats(args.mocap, 4, "--mocap")
        mocap = FrameTransform.from_xyz_yaw(x, y, z, math.radians(yaw))
    target = None
    if args.pose_target:
        host, _, port = args.pose_target.rpartition(":")
        if not host or not port.isdigit():
            raise RobotError(f"--pose-target {args.pose_target!r}: expected HOST:PORT")
        target = (host, int(port))
    for name in ("latency", "noise", "noise_angle", "drop"):
        if not getattr(args, name) >= 0:
            raise RobotError(f"--{name.replace('_', '-')} {getattr(args, name)}: must be >= 0")
    if args.drop >= 1:
        raise RobotError(f"--drop {args.drop}: a probability below 1")
    return TwinConfig(
        scene=args.scene,
        start=start,
        friction=args.friction,
        motor_gain=args.motor_gain,
        motor_mismatch=args.motor_mismatch,
        mass_scale=args.mass_scale,
        pose=args.pose,
        natnet_port=args.natnet_port,
        rigid_body=(args.rigid_body, "roach"),
        pose_target=target,
        pose_rate=args.pose_rate,
        latency=args.latency,
        noise=args.noise,
        noise_angle=args.noise_angle,
        drop=args.drop,
        seed=args.seed,
        mocap=mocap,
        command=args.command,
        command_port=args.command_port,
        serial=args.serial,
        command_timeout=args.command_timeout,
    )


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return run_twin(config_from_args(args))
    except (RobotError, ValueError) as exc:
        print(f"twin: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
