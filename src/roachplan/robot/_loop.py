"""The robot in the loop: the page-independent control loop (RobotLoop).

Every control period (default 50 Hz, the simulated driver's 20 ms) the loop reads the newest
pose from its source, maps it to the world frame, checks it (robot/_safety.py), lets the same
path follower the simulation uses (sim.make_follower) advance and set the motor speeds, and
sends them over its command link; everything is recorded (robot/_record.py) and told to its
listeners as events (PoseEvent, CommandEvent, StopEvent, FinishedEvent).

Nothing moves until go(): before it the loop sends stop frames at the control rate. A stop -
the goal reached, a safety check failed, stop() (Stop, Cancel, a signal) - sends stop frames
at the control rate for SafetyConfig.stop_hold seconds, then the loop ends. stop() wakes the
loop at once, so the stop frame leaves within milliseconds, not at the next tick.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from roachplan.sim import DriverConfig, make_follower, omega_limit

from ._config import LoopConfig
from ._estimate import trim_commands
from ._frames import CommandFrame
from ._links import CommandLink
from ._pose import PoseSample, PoseSource
from ._safety import SafetyMap, Stop, StopReason, check_pose
from ._transform import FrameTransform


@dataclass(frozen=True, kw_only=True)
class PoseEvent:
    kind: Literal["pose"] = "pose"
    sample: PoseSample
    position: tuple[float, float, float]
    """World frame [m]."""
    quat: tuple[float, float, float, float]
    """World frame, xyzw."""


@dataclass(frozen=True, kw_only=True)
class CommandEvent:
    kind: Literal["command"] = "command"
    t: float
    """When it was sent [s, monotonic]."""
    scheduled: float
    """The control instant it belongs to [s, monotonic]."""
    frame: CommandFrame


@dataclass(frozen=True, kw_only=True)
class StopEvent:
    kind: Literal["stop"] = "stop"
    t: float
    """When the first stop frame was sent [s, monotonic]."""
    stop: Stop


@dataclass(frozen=True, kw_only=True)
class RunResult:
    """How a drive went."""

    reason: StopReason
    detail: str
    t_go: float | None
    """go() [s, monotonic]; None: never went."""
    t_stop: float
    """The first stop frame [s, monotonic]."""
    t_end: float
    """The loop's end, after the stop hold [s, monotonic]."""
    start: tuple[float, float, float] | None
    """The robot's pose at go(): x, y [m], yaw [rad], world frame."""
    end: tuple[float, float, float] | None
    """Its last pose: x, y [m], yaw [rad]."""
    poses: int
    commands: int
    periods: int
    """Control periods while driving."""
    late: int
    """Of them, late (LoopConfig.late_tolerance)."""

    @property
    def success(self) -> bool:
        return self.reason == "goal"

    def to_json(self) -> dict:
        return {
            "reason": self.reason,
            "detail": self.detail,
            "t_go": self.t_go,
            "t_stop": self.t_stop,
            "t_end": self.t_end,
            "start": None if self.start is None else list(self.start),
            "end": None if self.end is None else list(self.end),
            "poses": self.poses,
            "commands": self.commands,
            "periods": self.periods,
            "late": self.late,
        }


@dataclass(frozen=True, kw_only=True)
class FinishedEvent:
    kind: Literal["finished"] = "finished"
    result: RunResult


LoopEvent = PoseEvent | CommandEvent | StopEvent | FinishedEvent


class Recorder(Protocol):
    """What the loop records (robot/_record.py RunRecorder)."""

    def pose(self, event: PoseEvent) -> None: ...

    def command(self, event: CommandEvent) -> None: ...

    def event(self, name: str, t: float, data: dict) -> None: ...


def _yaw(quat) -> float:
    x, y, z, w = quat
    return math.atan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z))


class RobotLoop:
    """Drives one robot along one path. start() runs the loop in a thread of its own; go(),
    stop() and cancel() may be called from any thread; listeners are called in the loop's
    thread and must return quickly (a page puts the event on its own queue)."""

    def __init__(
        self,
        *,
        path_xyz: np.ndarray,
        source: PoseSource,
        link: CommandLink,
        transform: FrameTransform,
        safety_map: SafetyMap,
        driver: DriverConfig,
        max_motor_speed: float,
        spins: Sequence[tuple[int, float]] = (),
        cfg: LoopConfig = LoopConfig(),
        recorder: Recorder | None = None,
        listeners: Sequence[Callable[[LoopEvent], None]] = (),
        clock: Callable[[], float] = time.monotonic,
        trim: float = 0.0,
    ) -> None:
        self.path = np.asarray(path_xyz, dtype=float)
        self.spins = tuple(spins)
        self._follower = make_follower(self.path, driver, self.spins)
        self._path_xy = self._follower.path[:, :2]
        self.source, self.link, self.transform = source, link, transform
        self.safety_map, self.driver, self.cfg = safety_map, driver, cfg
        self.omega_max = omega_limit(max_motor_speed, driver)
        self.max_motor_speed = max_motor_speed
        self.trim = trim
        """The motors' mismatch d divided out of every walking command sent (trim_commands:
        left / (1 + d), right / (1 - d)); 0: none. Any thread may set it (the look-ahead's
        estimate, robot.watch_ahead); the loop reads it once a period."""
        self.recorder = recorder
        self.listeners = list(listeners)
        self.clock = clock
        self.period = 1.0 / cfg.rate
        self._wake = threading.Event()
        self._lock = threading.Lock()
        self._go_at: float | None = None
        self._requested: Stop | None = None
        self._thread: threading.Thread | None = None
        self._result: RunResult | None = None
        self._done = threading.Event()
        self.latest_world: tuple[tuple[float, float, float], tuple] | None = None
        """The newest pose, world frame (position [m], quat xyzw)."""
        self.stall_time: float | None = None
        """The guard's stall hold (robot.watch_ahead, RobotSettings.guard_stuck): with no
        progress along the path for this long [s] (as the stuck stop counts progress: the
        follower advanced, came stuck_distance nearer its target, or stuck_angle nearer a
        spin's heading), the run ends as "stall", before the stuck stop at the driver's
        stuck_time; None: no such hold. Set before start()."""

    @property
    def pending_spins(self) -> tuple[tuple[int, float], ...]:
        """The plan's spins not yet made ((waypoint index, heading [rad]) each): the one under
        way first. Any thread may read it (the look-ahead's rollouts go on from the robot's
        progress: a spin at the waypoint where the robot stands is still to be made)."""
        # (a copy: the loop pops a spin once made; the reference follower makes none)
        return tuple(getattr(self._follower, "spins", ()))

    @property
    def spinning(self) -> bool:
        """The robot is turning on the spot at a spin of its plan (the follower's; any thread
        may read it)."""
        return bool(getattr(self._follower, "spinning", False))  # (the reference one: never)

    # -- control ---------------------------------------------------------------------------

    def start(self) -> None:
        """Start the loop (it sends stop frames until go())."""
        self._thread = threading.Thread(target=self._run, name="robot-loop", daemon=True)
        self._thread.start()

    def go(self) -> None:
        """Start driving."""
        with self._lock:
            if self._go_at is None and self._requested is None:
                self._go_at = self.clock()
        self._wake.set()

    def stop(self, reason: StopReason = "stop", detail: str = "") -> None:
        """Stop the robot now (Stop: "stop"; Cancel: "cancel"; a signal: "signal")."""
        with self._lock:
            if self._requested is None:
                self._requested = Stop(reason=reason, detail=detail or f"{reason} requested")
        self._wake.set()

    def cancel(self) -> None:
        self.stop("cancel")

    def wait(self, timeout: float | None = None) -> RunResult | None:
        """The result once the loop has ended (None if it has not within timeout [s])."""
        self._done.wait(timeout)
        return self._result

    @property
    def stopping(self) -> bool:
        """A stop was asked for (stop(), cancel(), a signal), or the loop has ended."""
        with self._lock:
            return self._requested is not None or self._done.is_set()

    @property
    def running(self) -> bool:
        return self._thread is not None and not self._done.is_set()

    def close(self, timeout: float = 5.0) -> None:
        """Stop (if driving) and wait for the loop to end."""
        if self.running:
            self.stop("cancel", "the loop was closed")
            self.wait(timeout)

    # -- the loop --------------------------------------------------------------------------

    def _emit(self, event: LoopEvent) -> None:
        for listener in self.listeners:
            listener(event)

    def _send(self, scheduled: float, left: float, right: float, stop: bool) -> None:
        frame = self.link.send(left, right, stop=stop)
        event = CommandEvent(t=self.clock(), scheduled=scheduled, frame=frame)
        if self.recorder is not None:
            self.recorder.command(event)
        self._emit(event)

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # a link gone: stop the robot with what is left
            t = self.clock()
            for _ in range(3):
                try:
                    self.link.send(0.0, 0.0, stop=True)
                except Exception:
                    break
            self._finish(Stop(reason="error", detail=f"{type(exc).__name__}: {exc}"), t, t)
            raise

    def _loop(self) -> None:  # noqa: PLR0912, PLR0915 - one period's state machine; to split into steps
        cfg, drv = self.cfg, self.driver
        follower = self._follower
        last_seq: int | None = None
        poses = commands = periods = late = 0
        start: tuple[float, float, float] | None = None
        stop: Stop | None = None
        t_stop = math.inf
        last_progress, best_gap = 0.0, math.inf
        stall = self.stall_time
        tick = self.clock()
        while True:
            now = self.clock()
            sample = self.source.latest()
            if sample is not None and sample.seq != last_seq:
                last_seq = sample.seq
                pos, quat = self.transform.apply(sample.position, sample.quat)
                self.latest_world = (pos, quat)
                event = PoseEvent(sample=sample, position=pos, quat=quat)
                poses += 1
                if self.recorder is not None:
                    self.recorder.pose(event)
                self._emit(event)
            with self._lock:
                go_at, requested = self._go_at, self._requested
            if stop is None and requested is not None:
                stop = requested
            driving = go_at is not None and stop is None
            if driving:
                assert go_at is not None
                periods += 1
                if now - tick > cfg.late_tolerance * self.period:
                    late += 1
                world = self.latest_world
                stop = check_pose(
                    cfg.safety,
                    self.safety_map,
                    self._path_xy,
                    now=now,
                    t_receive=None if sample is None else sample.t_receive,
                    position_world=None if world is None else world[0],
                )
                if stop is None and world is not None:
                    pos, quat = world
                    if start is None:
                        start = (pos[0], pos[1], _yaw(quat))
                        if self.recorder is not None:
                            self.recorder.event("go", go_at, {"start": list(start)})
                    ended = follower.update(pos, quat)
                    elapsed = now - go_at
                    if ended is not None:
                        outcome, why = ended
                        stop = Stop(reason="goal" if outcome == "success" else "missed", detail=why)
                    elif follower.advanced or follower.gap < best_gap - drv.stuck_distance:
                        last_progress, best_gap = elapsed, follower.gap
                    elif stall is not None and elapsed - last_progress >= stall:
                        stop = Stop(
                            reason="stall",
                            detail=f"the robot at ({pos[0]:.3f}, {pos[1]:.3f}) made no progress "
                            f"along its path for {elapsed - last_progress:.1f} s, "
                            f"{follower.where()} (guard stall {stall:g} s, before the loop's "
                            f"stuck stop at {drv.stuck_time:g} s)",
                        )
                    elif elapsed - last_progress >= drv.stuck_time:
                        stop = Stop(
                            reason="stuck",
                            detail=f"no progress for {drv.stuck_time:g} s, {follower.where()}",
                        )
                    if stop is None and elapsed >= drv.time_limit:
                        stop = Stop(
                            reason="timeout",
                            detail=f"did not reach the goal within {drv.time_limit:g} s",
                        )
                    if stop is None:
                        left, right = follower.speeds(pos, quat, self.omega_max)
                        if self.trim:
                            left, right = trim_commands(
                                left, right, self.trim, self.max_motor_speed
                            )
                        self._send(tick, left, right, False)
                        commands += 1
            if not driving or stop is not None:
                self._send(tick, 0.0, 0.0, True)
                commands += 1
                if stop is not None and t_stop == math.inf:
                    t_stop = self.clock()
                    if self.recorder is not None:
                        self.recorder.event(
                            "stop", t_stop, {"reason": stop.reason, "detail": stop.detail}
                        )
                    self._emit(StopEvent(t=t_stop, stop=stop))
                if stop is not None and self.clock() - t_stop >= cfg.safety.stop_hold:
                    break
            tick += self.period
            now = self.clock()
            if now - tick > self.period:  # far behind (a stall): start afresh from now
                tick = now
            self._wake.wait(max(tick - now, 0.0))
            if self._wake.is_set():
                self._wake.clear()
                with self._lock:
                    woke_by_stop = self._requested is not None and stop is None
                if woke_by_stop:
                    tick = self.clock()  # act on a stop at once, not at the next instant
        world = self.latest_world
        end = None if world is None else (world[0][0], world[0][1], _yaw(world[1]))
        assert stop is not None
        result = RunResult(
            reason=stop.reason,
            detail=stop.detail,
            t_go=self._go_at,
            t_stop=t_stop,
            t_end=self.clock(),
            start=start,
            end=end,
            poses=poses,
            commands=commands,
            periods=periods,
            late=late,
        )
        self._result = result
        if self.recorder is not None:
            self.recorder.event("finished", result.t_end, result.to_json())
        self._emit(FinishedEvent(result=result))
        self._done.set()

    def _finish(self, stop: Stop, t_stop: float, t_end: float) -> None:
        self._result = RunResult(
            reason=stop.reason,
            detail=stop.detail,
            t_go=self._go_at,
            t_stop=t_stop,
            t_end=t_end,
            start=None,
            end=None,
            poses=0,
            commands=0,
            periods=0,
            late=0,
        )
        self._emit(FinishedEvent(result=self._result))
        self._done.set()
