"""Every robot run recorded, as an MCAP file (the `mcap` library; JSON messages with JSON
schemas), and read back as plain data.

Topics (one JSON object per message; log times are this computer's monotonic clock [ns]):
/scene (once: name, file, its SHA-256 and, for a text file up to 1 MB, its content),
/settings (once: loop, safety, driver, transform, source and link settings), /plan (once:
path [[x, y, z]...] [m], spins, planner, seed), /pose (each new pose: t_receive, t_source,
seq, mocap {p, q} and world {p, q}), /command (each frame sent: t, scheduled, seq, t_us,
left, right [rad/s], stop), /event (go, stop with its reason, finished), /prediction (the
simulation of the same plan from the robot's actual start: outcome, reason, trajectory
[[t, x, y, z, yaw]...]), /lookahead (each look-ahead while it drove, when asked for: t,
start, horizon, rollouts, holds, p_hold, failures [[x, y, why]...]) and /result (how the run
ended).

Crash-safe as the experiment results are: the run is written to a temporary file beside the
target (TARGET.partial), flushed as it goes (no chunks: each message is on disk once written),
and renamed to the target only when it is complete. A killed run leaves the readable
TARGET.partial (read_run reads it up to its last whole message) and never a corrupt target.
"""

from __future__ import annotations

import hashlib
import json
import os
import struct
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._errors import RobotError

TOPICS = (
    "/scene",
    "/settings",
    "/plan",
    "/pose",
    "/command",
    "/event",
    "/prediction",
    "/lookahead",
    "/result",
)
PROFILE = "roachplan.robot-run"
FORMAT_VERSION = 1


def _schema(topic: str) -> bytes:
    return json.dumps(
        {"title": f"roachplan {topic[1:]}", "type": "object", "$comment": "robot/_record.py"}
    ).encode()


def scene_record(scene_path: Path | None, name: str) -> dict:
    """The /scene message of a scene file (its content when it is text up to 1 MB)."""
    if scene_path is None:
        return {"name": name, "path": None, "sha256": None, "content": None}
    data = Path(scene_path).read_bytes()
    content = None
    if len(data) <= 1 << 20:
        try:
            content = data.decode("utf-8")
        except UnicodeDecodeError:
            content = None
    return {
        "name": name,
        "path": str(scene_path),
        "sha256": hashlib.sha256(data).hexdigest(),
        "content": content,
    }


class RunRecorder:
    """Writes one run (the loop's Recorder). close() completes it and renames it to the
    target; abandon() leaves the partial file."""

    def __init__(self, target: str | os.PathLike) -> None:
        from mcap.writer import CompressionType, Writer

        self.target = Path(target)
        if not self.target.parent.is_dir():
            raise RobotError(
                f"run log {self.target}: the folder {self.target.parent} does not exist"
            )
        self.partial = self.target.with_name(self.target.name + ".partial")
        self._file = open(self.partial, "wb")
        self._writer = Writer(self._file, compression=CompressionType.NONE, use_chunking=False)
        self._writer.start(profile=PROFILE, library="roachplan")
        self._channels: dict[str, int] = {}
        for topic in TOPICS:
            sid = self._writer.register_schema(topic[1:], "jsonschema", _schema(topic))
            self._channels[topic] = self._writer.register_channel(topic, "json", sid)
        self._seq = 0
        self._lock = threading.Lock()
        self._closed = False
        self.write("/event", 0.0, {"name": "opened", "t": 0.0, "format": FORMAT_VERSION})

    def write(self, topic: str, t: float, message: dict) -> None:
        """One message on topic at log time t [s, monotonic]."""
        data = json.dumps(message, allow_nan=True).encode()
        ns = max(int(t * 1e9), 0)
        with self._lock:
            if self._closed:
                return
            self._seq += 1
            self._writer.add_message(self._channels[topic], ns, data, ns, self._seq)
            self._file.flush()

    # the loop's Recorder
    def pose(self, event) -> None:
        s = event.sample
        self.write(
            "/pose",
            s.t_receive,
            {
                "t_receive": s.t_receive,
                "t_source": s.t_source,
                "seq": s.seq,
                "mocap": {"p": list(s.position), "q": list(s.quat)},
                "world": {"p": list(event.position), "q": list(event.quat)},
            },
        )

    def command(self, event) -> None:
        f = event.frame
        self.write(
            "/command",
            event.t,
            {
                "t": event.t,
                "scheduled": event.scheduled,
                "seq": f.seq,
                "t_us": f.t_us,
                "left": f.left,
                "right": f.right,
                "stop": f.stop,
            },
        )

    def event(self, name: str, t: float, data: dict) -> None:
        self.write("/event", t, {"name": name, "t": t, **data})

    def close(self) -> Path:
        """Finish the file and put it at the target (atomically); the target's path."""
        with self._lock:
            if self._closed:
                return self.target
            self._closed = True
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
        os.replace(self.partial, self.target)
        return self.target

    def abandon(self) -> Path:
        """Stop writing and leave the partial file (a run that failed to start); its path."""
        with self._lock:
            if not self._closed:
                self._closed = True
                self._file.close()
        return self.partial


@dataclass(frozen=True, kw_only=True)
class RunLog:
    """A run as plain data (read_run)."""

    path: Path
    complete: bool
    """The file was finished (not a partial one from a killed run)."""
    scene: dict
    settings: dict
    plan: dict
    poses: dict[str, np.ndarray]
    """t_receive (K,) [s], t_source (K,), seq (K,), mocap_p (K, 3), mocap_q (K, 4), world_p (K,
    3) [m], world_q (K, 4)."""
    commands: dict[str, np.ndarray]
    """t (M,) [s], scheduled (M,), seq (M,), left (M,), right (M,) [rad/s], stop (M,) bool."""
    events: list[dict]
    prediction: dict | None
    result: dict | None
    extra: dict[str, Any] = field(default_factory=dict)
    lookaheads: list[dict] = field(default_factory=list)
    """The look-aheads made while it drove (LookAhead.to_json() each, with "t" [s, monotonic]
    when it started), in order; none when it was not asked for."""

    @property
    def t_go(self) -> float | None:
        for e in self.events:
            if e["name"] == "go":
                return float(e["t"])
        return None

    @property
    def start(self) -> tuple[float, float, float] | None:
        """The robot's pose at Go (x, y [m], yaw [rad]), world frame."""
        for e in self.events:
            if e["name"] == "go":
                return tuple(e["start"])  # type: ignore[return-value]
        return None


def _messages(path: Path):
    """(topic, decoded JSON) of every whole message of the file, in order."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    channels: dict[int, str] = {}
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False)
        try:
            for record in reader.records:
                if isinstance(record, Channel):
                    channels[record.id] = record.topic
                elif isinstance(record, Message):
                    yield channels[record.channel_id], json.loads(record.data)
        except (McapError, EOFError, ValueError, struct.error):
            return  # a partial file ends mid-record: everything before it is whole


def read_run(path: str | os.PathLike) -> RunLog:
    """A run log (a finished one, or the .partial of a killed run) as plain data; RobotError
    when the file is no roachplan run log."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError as exc:
        raise RobotError(f"run log {path}: cannot read it: {exc.strerror or exc}") from None
    if head != b"\x89MCAP0\r\n":
        raise RobotError(f"run log {path}: not an MCAP file (it starts {head!r})")
    one: dict[str, dict] = {}
    poses: list[dict] = []
    commands: list[dict] = []
    events: list[dict] = []
    lookaheads: list[dict] = []
    for topic, msg in _messages(path):
        if topic == "/pose":
            poses.append(msg)
        elif topic == "/command":
            commands.append(msg)
        elif topic == "/event":
            events.append(msg)
        elif topic == "/lookahead":
            lookaheads.append(msg)
        else:
            one[topic] = msg
    if not events or events[0].get("name") != "opened":
        raise RobotError(f"run log {path}: an MCAP file, but no roachplan robot run")
    complete = not path.name.endswith(".partial") and _finished(path)

    def col(rows, key, sub=None, width: int = 1):
        if sub is None:
            return np.array([r[key] for r in rows], dtype=float)
        return np.array([r[key][sub] for r in rows], dtype=float).reshape(-1, width)

    return RunLog(
        path=path,
        complete=complete,
        scene=one.get("/scene", {}),
        settings=one.get("/settings", {}),
        plan=one.get("/plan", {}),
        poses={
            "t_receive": col(poses, "t_receive"),
            "t_source": col(poses, "t_source"),
            "seq": col(poses, "seq"),
            "mocap_p": col(poses, "mocap", "p", 3),
            "mocap_q": col(poses, "mocap", "q", 4),
            "world_p": col(poses, "world", "p", 3),
            "world_q": col(poses, "world", "q", 4),
        },
        commands={
            "t": col(commands, "t"),
            "scheduled": col(commands, "scheduled"),
            "seq": col(commands, "seq"),
            "left": col(commands, "left"),
            "right": col(commands, "right"),
            "stop": np.array([bool(c["stop"]) for c in commands], dtype=bool),
        },
        events=events,
        prediction=one.get("/prediction"),
        result=one.get("/result"),
        lookaheads=lookaheads,
    )


def _finished(path: Path) -> bool:
    """The file ends with MCAP's footer magic (it was finished)."""
    with open(path, "rb") as f:
        f.seek(0, os.SEEK_END)
        if f.tell() < 16:
            return False
        f.seek(-8, os.SEEK_END)
        return f.read(8) == b"\x89MCAP0\r\n"
