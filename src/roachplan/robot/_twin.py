"""The twin: a stand-in robot on the other end of the real protocols.

A process (`python -m roachplan.robot.twin`) runs the project's Simulation of a scene in step
with the wall clock and speaks as a robot and its motion capture would: it serves the roach's
pose over NatNet (unicast, robot/_natnet.py) or the UDP/JSON stream (robot/_pose.py), and
obeys motor command frames (robot/_frames.py) over UDP or a serial line (a pseudo-terminal it
makes, or a device). Its hidden parameters make it another robot than the nominal simulation
(ground friction, motor gain and left/right mismatch, body mass), and its mocap adds latency,
seeded noise and dropped packets, so a loop, a comparison or a fit is tested against a robot
whose parameters it does not know.

A small JSON control port (UDP, loopback) lets a test read the twin's true state and the
commands it received, and start a pose dropout: {"op": "state"}, {"op": "commands", "since":
K}, {"op": "dropout", "seconds": S}, {"op": "quit"}.
"""

from __future__ import annotations

import json
import math
import os
import select
import signal
import socket
import sys
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from roachplan._settings import (
    between,
    check_settings,
    non_negative,
    numbers,
    one_of,
    optional,
    positive,
    seed,
)
from roachplan._settings import setting as s

from . import _checks
from ._errors import RobotError
from ._links import FdCommandReceiver, UdpCommandReceiver
from ._natnet import NatNetServer, RigidBodyFrame, RigidBodyModel, frame_packet
from ._pose import pose_json
from ._transform import FrameTransform, quat_multiply, quat_rotate


@dataclass(frozen=True, kw_only=True)
class TwinConfig:
    """One twin: its scene, its hidden parameters, its mocap and its links."""

    scene: str = "double_bridge"
    """A library scene's name, a scene file or a terrain file."""
    start: tuple[float, float, float] | None = s(
        None, optional(numbers(3, "x [m], y [m], yaw [rad]"))
    )
    """Where the robot stands at first (x [m], y [m], yaw [rad]); None: the scene's start."""
    friction: float | None = s(None, optional(between(0.05, 5.0, "-")))
    """Ground friction [-]; None: the scene's."""
    motor_gain: float = s(1.0, between(0.2, 5.0, "-"))
    """Both motors run at this times their command [-]."""
    motor_mismatch: float = s(0.0, between(-0.5, 0.5, "-"))
    """Left x (1 + d), right x (1 - d) [-], as the scenes' `uncertainty:` draws it."""
    mass_scale: float = s(1.0, between(0.2, 5.0, "-"))
    """The body's mass (and inertia) x this [-]."""
    pose: str = s("natnet", one_of(("natnet", "udp-json")))
    """How the pose is served: "natnet" or "udp-json"."""
    natnet_port: int = s(0, _checks.port(free=True))
    """NatNet command port (0: a free one; Motive's is 1510)."""
    rigid_body: tuple[int, str] = (1, "roach")
    """The rigid body's streaming id and name."""
    pose_target: tuple[str, int] | None = None
    """udp-json: where to send the poses."""
    pose_rate: float = s(120.0, between(1.0, 1000.0, "Hz"))
    """Poses per second [Hz] (Motive's default frame rate: 120)."""
    latency: float = s(0.0, between(0.0, 5.0, "s"))
    """How long after the simulation's instant a pose is sent [s]."""
    noise: float = s(0.0, non_negative("m"))
    """Standard deviation of each position coordinate's noise [m]."""
    noise_angle: float = s(0.0, non_negative("rad"))
    """Standard deviation of the orientation's noise, about each axis [rad]."""
    drop: float = s(0.0, between(0.0, 1.0, "-", high_included=False))
    """Probability that a pose is not sent [-]."""
    seed: int = s(0, seed())
    """Seed of the noise and the drops."""
    mocap: FrameTransform = FrameTransform()
    """T_world_mocap: the twin's poses are given in the mocap frame (its inverse applied)."""
    command: str = s("udp", one_of(("udp", "serial")))
    """How commands come: "udp" or "serial"."""
    command_port: int = s(0, _checks.port(free=True))
    """udp: the port commands come to (0: a free one)."""
    serial: str = "pty"
    """serial: "pty" (a pseudo-terminal the twin makes; its device is announced) or a device."""
    command_timeout: float = s(0.25, positive("s", 10.0))
    """With no valid command for this long the robot stops by itself [s]."""
    host: str = s("127.0.0.1", _checks.host())
    """The address every socket of the twin binds to."""

    def __post_init__(self) -> None:
        check_settings(self)


class _Announce:
    """The ports and device of a started twin, as the line it prints."""

    def __init__(self, **fields) -> None:
        self.fields = fields

    def line(self) -> str:
        return json.dumps({"ready": True, **self.fields})


def _inverse(tf: FrameTransform) -> FrameTransform:
    x, y, z, w = tf.quat
    q_inv = (-x, -y, -z, w)
    t = quat_rotate(q_inv, tf.translation)
    return FrameTransform(translation=(-t[0], -t[1], -t[2]), quat=q_inv)


def _small_rotation(rng: np.random.Generator, sigma: float) -> tuple[float, float, float, float]:
    if sigma <= 0:
        return (0.0, 0.0, 0.0, 1.0)
    v = rng.normal(0.0, sigma, size=3)
    angle = float(np.linalg.norm(v))
    if angle < 1e-12:
        return (0.0, 0.0, 0.0, 1.0)
    axis = v / angle
    s = math.sin(angle / 2)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))


def run_twin(cfg: TwinConfig, announce=print) -> int:  # noqa: PLR0912, PLR0915 - to split
    """Run a twin until it is told to quit or gets SIGTERM/SIGINT; announce(line) is called
    once with the JSON line of its ports when it is ready. Returns an exit status."""
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene(cfg.scene))
    scene = world.scene
    start = cfg.start or scene.start
    assert start is not None  # build_world picks one
    sim = world.simulation()
    g, d = cfg.motor_gain, cfg.motor_mismatch
    sim.perturb(
        friction=scene.sim.friction if cfg.friction is None else cfg.friction,
        mass_scale=cfg.mass_scale,
        motor_gain=(g * (1 + d), g * (1 - d)),
    )
    sim.reset(*start, surface=float(world.heightfield.sample(np.array(start[:2]))))
    rng = np.random.default_rng(cfg.seed)
    to_mocap = _inverse(cfg.mocap)

    stopping = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(True))
    signal.signal(signal.SIGINT, lambda *_: stopping.append(True))

    control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    control.bind((cfg.host, 0))
    control.setblocking(False)
    fields: dict = {"control_port": control.getsockname()[1], "pid": os.getpid()}
    natnet = None
    json_sock = None
    if cfg.pose == "natnet":
        rb_id, rb_name = cfg.rigid_body
        natnet = NatNetServer(
            [
                RigidBodyModel(
                    name=rb_name,
                    id=rb_id,
                    markers=((0.04, 0.0, 0.01), (-0.04, 0.02, 0.01), (-0.04, -0.02, 0.01)),
                )
            ],
            host=cfg.host,
            port=cfg.natnet_port,
        )
        fields["natnet_port"] = natnet.port
    elif cfg.pose == "udp-json":
        if cfg.pose_target is None:
            raise RobotError("twin: pose udp-json needs pose_target (host, port)")
        json_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    else:
        raise RobotError(f"twin: pose {cfg.pose!r}: choose natnet or udp-json")
    if cfg.command == "udp":
        receiver = UdpCommandReceiver(cfg.host, cfg.command_port)
        fields["command_port"] = receiver.port
    elif cfg.command == "serial":
        if cfg.serial == "pty":
            master, slave = os.openpty()
            import tty

            tty.setraw(slave)
            fields["serial"] = os.ttyname(slave)
            receiver = FdCommandReceiver(master)
        else:
            receiver = FdCommandReceiver(os.open(cfg.serial, os.O_RDWR | os.O_NOCTTY))
            fields["serial"] = cfg.serial
    else:
        raise RobotError(f"twin: command {cfg.command!r}: choose udp or serial")
    announce(_Announce(**fields).line())
    sys.stdout.flush()

    dt = sim.cfg.timestep
    pose_period = 1.0 / cfg.pose_rate
    t0 = time.monotonic()
    next_pose = 0.0
    frame_number = 0
    pending: deque[tuple[float, bytes]] = deque()  # (release time, packet)
    dropout_until = -math.inf
    last_command_at = -math.inf
    last_seq = -1
    speeds = (0.0, 0.0)
    commands: list[list] = []  # [t_monotonic, seq, left, right, stop]
    lag_max = 0.0
    quit_ = False
    while not quit_ and not stopping:
        now = time.monotonic()
        for frame in receiver.poll():
            commands.append([now, frame.seq, frame.left, frame.right, frame.stop])
            if frame.seq <= last_seq and last_seq - frame.seq < 2**31:
                continue  # an old datagram overtaken by a newer one
            last_seq, last_command_at = frame.seq, now
            speeds = (0.0, 0.0) if frame.stop else (frame.left, frame.right)
            sim.set_leg_speeds(*speeds)
        if now - last_command_at > cfg.command_timeout and speeds != (0.0, 0.0):
            speeds = (0.0, 0.0)  # the robot's own watchdog: its sender is gone
            sim.set_leg_speeds(0.0, 0.0)
        target = now - t0
        behind = target - sim.time
        lag_max = max(lag_max, behind)
        if behind > 0.1:  # a busy machine: drop time rather than spiral
            t0 += behind - 0.1
            target = now - t0
        while sim.time + dt / 2 < target:
            # up to the next pose instant, at most 5 ms of simulated time a call
            n = max(1, min(round((min(target, next_pose) - sim.time) / dt), 5))
            sim.advance(n)
            if sim.time + dt / 2 >= next_pose:
                pos, quat = sim.pose()
                p_m, q_m = to_mocap.apply(pos, quat)
                if cfg.noise > 0:
                    p_m = tuple(float(v) for v in np.asarray(p_m) + rng.normal(0.0, cfg.noise, 3))
                q_m = quat_multiply(q_m, _small_rotation(rng, cfg.noise_angle))
                dropped = cfg.drop > 0 and rng.uniform() < cfg.drop
                frame_number += 1
                if not dropped:
                    if natnet is not None:
                        packet = frame_packet(
                            frame_number,
                            [
                                RigidBodyFrame(
                                    id=cfg.rigid_body[0],
                                    position=(float(p_m[0]), float(p_m[1]), float(p_m[2])),
                                    quat=q_m,
                                )
                            ],
                            timestamp=sim.time,
                        )
                    else:
                        packet = pose_json(frame_number, sim.time, p_m, q_m)
                    pending.append((t0 + sim.time + cfg.latency, packet))
                next_pose += pose_period
        now = time.monotonic()
        while pending and pending[0][0] <= now:
            _, packet = pending.popleft()
            if now < dropout_until:
                continue
            if natnet is not None:
                natnet.publish(packet)
            elif json_sock is not None and cfg.pose_target is not None:
                try:
                    json_sock.sendto(packet, cfg.pose_target)
                except OSError:
                    pass
        if natnet is not None:
            natnet.serve(now)
        while True:
            try:
                data, addr = control.recvfrom(65536)
            except BlockingIOError:
                break
            try:
                msg = json.loads(data)
                op = msg["op"]
            except (ValueError, KeyError, TypeError):
                continue
            if op == "state":
                pos, quat = sim.pose()
                reply = {
                    "t": now,
                    "sim_time": sim.time,
                    "position": list(pos),
                    "quat": list(quat),
                    "speeds": list(speeds),
                    "lag_max": lag_max,
                    "commands": len(commands),
                    "bad_commands": receiver.bad,
                    "natnet_clients": natnet.clients if natnet is not None else 0,
                }
            elif op == "commands":
                reply = {"commands": commands[int(msg.get("since", 0)) :]}
            elif op == "dropout":
                dropout_until = now + float(msg["seconds"])
                reply = {"t_start": now, "t_end": dropout_until}
            elif op == "quit":
                reply, quit_ = {"quit": True}, True
            else:
                reply = {"error": f"unknown op {op!r}"}
            control.sendto(json.dumps(reply).encode(), addr)
        wake = [next_pose + t0 - time.monotonic()]
        if pending:
            wake.append(pending[0][0] - time.monotonic())
        timeout = min(max(min(wake), 0.0), 0.002)
        watch = [receiver, control] + ([natnet] if natnet is not None else [])
        select.select(watch, [], [], timeout)
    receiver.close()
    control.close()
    if natnet is not None:
        natnet.close()
    if json_sock is not None:
        json_sock.close()
    sim.close()
    return 0
