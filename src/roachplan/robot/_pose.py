"""Where the robot is: pose samples and the sources that give them.

A source is anything with latest() and close() (PoseSource); sources are made by name from
POSE_SOURCES ("natnet": OptiTrack Motive, robot/_natnet.py; "udp-json": the plain stream
below; register_pose_source adds another). Poses are in the source's own (mocap) frame; the
loop maps them to the scene's world frame with a FrameTransform (robot/_transform.py).

The UDP/JSON pose stream: one datagram per pose, a UTF-8 JSON object

    {"seq": 812, "t": 16.24, "p": [x, y, z], "q": [qx, qy, qz, qw]}

seq an integer that grows, t the sender's time [s] (any origin), p the position [m], q the
orientation (a unit quaternion, xyzw), z up. Optional "valid": false says the tracker lost the
body (the sample is then not a pose).
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from roachplan._settings import SettingError, check_settings
from roachplan._settings import setting as s

from . import _checks
from ._errors import RobotError


@dataclass(frozen=True, kw_only=True)
class PoseSample:
    """One pose of the robot as a source gave it."""

    t_receive: float
    """When it arrived, this computer's monotonic clock [s]."""
    t_source: float
    """The source's own time stamp [s] (its origin is the source's)."""
    seq: int
    """The source's frame number."""
    position: tuple[float, float, float]
    """[m], the source's frame, z up."""
    quat: tuple[float, float, float, float]
    """Orientation, xyzw."""


class PoseSource(Protocol):
    """Gives the robot's newest pose."""

    def latest(self) -> PoseSample | None:
        """The newest valid sample, None before the first."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True, kw_only=True)
class UdpJsonSettings:
    """A UDP/JSON pose stream (the module docstring)."""

    host: str = s("127.0.0.1", _checks.host())
    """The address to receive on."""
    port: int = s(9871, _checks.port(free=True))
    """The port to receive on (0: a free one; UdpJsonPoseSource.port says which)."""

    def __post_init__(self) -> None:
        check_settings(self)


def parse_pose_json(data: bytes) -> tuple[int, float, tuple, tuple] | None:
    """(seq, t, position, quat) of one UDP/JSON datagram, None for a sample marked invalid;
    RobotError naming what is wrong."""
    try:
        msg = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RobotError(f"udp-json pose: not a JSON object: {exc}") from None
    if not isinstance(msg, dict):
        raise RobotError(f"udp-json pose: expected an object, got {type(msg).__name__}")
    if msg.get("valid", True) is False:
        return None
    try:
        seq, t = int(msg["seq"]), float(msg["t"])
        p = tuple(float(v) for v in msg["p"])
        q = tuple(float(v) for v in msg["q"])
    except (KeyError, TypeError, ValueError) as exc:
        raise RobotError(
            f"udp-json pose: {exc!r}; expected seq (integer), t [s], p [x, y, z] [m], "
            f"q [qx, qy, qz, qw]"
        ) from None
    norm = math.sqrt(sum(c * c for c in q)) if len(q) == 4 else 0.0
    if len(p) != 3 or abs(norm - 1.0) > 1e-3 or not all(map(math.isfinite, p)):
        raise RobotError(
            f"udp-json pose seq {seq}: expected p of 3 finite numbers and q a unit quaternion, "
            f"got p={list(p)}, q={list(q)}"
        )
    return seq, t, p, tuple(c / norm for c in q)


def pose_json(seq: int, t: float, position, quat) -> bytes:
    """One UDP/JSON pose datagram."""
    return json.dumps(
        {
            "seq": int(seq),
            "t": float(t),
            "p": [float(v) for v in position],
            "q": [float(v) for v in quat],
        }
    ).encode("utf-8")


class UdpJsonPoseSource:
    """Receives the UDP/JSON pose stream in a thread of its own."""

    def __init__(self, settings: UdpJsonSettings) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((settings.host, settings.port))
        except OSError as exc:
            self._sock.close()
            raise RobotError(
                f"udp-json pose source: cannot receive on {settings.host}:{settings.port}: "
                f"{exc.strerror or exc}; give a free port of this computer"
            ) from None
        self._sock.settimeout(0.1)
        self.port = self._sock.getsockname()[1]
        self._lock = threading.Lock()
        self._latest: PoseSample | None = None
        self.bad = 0
        """Datagrams that were no pose."""
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="udp-json-pose", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop:
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            t = time.monotonic()
            try:
                parsed = parse_pose_json(data)
            except RobotError:
                self.bad += 1
                continue
            if parsed is None:
                continue
            seq, ts, p, q = parsed
            with self._lock:
                self._latest = PoseSample(t_receive=t, t_source=ts, seq=seq, position=p, quat=q)

    def latest(self) -> PoseSample | None:
        with self._lock:
            return self._latest

    def close(self) -> None:
        self._stop = True
        self._thread.join()
        self._sock.close()


def _natnet(**kw) -> PoseSource:
    from ._natnet import NatNetPoseSource, NatNetSettings

    return NatNetPoseSource(NatNetSettings(**kw))


POSE_SOURCES: dict[str, Callable[..., PoseSource]] = {
    "natnet": _natnet,
    "udp-json": lambda **kw: UdpJsonPoseSource(UdpJsonSettings(**kw)),
}
"""Pose sources by name: name -> factory taking the source's settings as keywords."""


def register_pose_source(name: str, factory: Callable[..., PoseSource]) -> None:
    """Make another pose source available by name (open_pose_source(name, ...))."""
    POSE_SOURCES[name] = factory


def open_pose_source(name: str, **settings) -> PoseSource:
    """The pose source `name` with its settings; RobotError naming the source and what is
    accepted."""
    if name not in POSE_SOURCES:
        raise RobotError(f"pose source {name!r}: choose from {', '.join(sorted(POSE_SOURCES))}")
    try:
        return POSE_SOURCES[name](**settings)
    except (TypeError, SettingError) as exc:
        raise RobotError(f"pose source {name!r}: {exc}") from None
