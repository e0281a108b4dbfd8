"""The robot loop's settings and a drive's (light: the command line checks its flags with
their validators before anything heavy loads)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from roachplan._settings import (
    between,
    boolean,
    check_settings,
    optional,
    positive,
    seed,
)
from roachplan._settings import setting as s

from ._lookahead import LookAheadConfig
from ._safety import SafetyConfig
from ._transform import FrameTransform


@dataclass(frozen=True, kw_only=True)
class LoopConfig:
    """How the loop runs."""

    rate: float = s(50.0, between(1.0, 1000.0, "Hz"))
    """Control rate [Hz]."""
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    late_tolerance: float = s(0.25, between(0.0, 1.0, "-"))
    """A period whose command leaves more than this share of a period after its instant is
    late (counted, and recorded) [-]."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class RobotSettings:
    """One drive of a real robot (the `roachplan robot` command's settings)."""

    source: str = "natnet"
    """The pose source's name (robot.POSE_SOURCES)."""
    source_settings: dict[str, Any] = field(default_factory=dict)
    """Its settings (e.g. natnet: server, local, command_port, rigid_body, up_axis)."""
    link: str = "udp"
    """The command link's name (robot.LINKS)."""
    link_settings: dict[str, Any] = field(default_factory=dict)
    """Its settings (udp: host, port; serial: port, baudrate)."""
    transform: FrameTransform | None = None
    """T_world_mocap; None: measured from the first pose, the robot placed at the start."""
    seed: int | None = s(None, optional(seed()))
    """The plan's seed (None: the scene's)."""
    loop: LoopConfig = field(default_factory=LoopConfig)
    log: Path | None = None
    """The run's MCAP file (None: not recorded)."""
    predict: bool = True
    """Record the simulation's prediction of the plan from the robot's actual start."""
    first_pose_timeout: float = s(5.0, positive("s", 600.0))
    """How long to wait for the robot's first pose [s]."""
    look_ahead: LookAheadConfig | None = None
    """Look ahead of the robot while it drives (robot/_lookahead.py: short rollouts from its
    live pose, in their own process, recorded on /lookahead); None: not."""
    guard: float | None = s(None, optional(between(0.0, 1.0, "-")))
    """Hold the robot (stop frames; the run ends as "lookahead") when a look-ahead's chance
    of going on without a stop or a fall is below this [-]; None: never. With it, the run
    looks ahead (look_ahead, or LookAheadConfig's defaults when that is None)."""
    guard_drift: float | None = s(0.5, optional(positive("-", 1.0)))
    """With the guard on: also hold the robot (the run ends as "drift") once it is this share of
    the loop's max_deviation from its path (0.5: 7.5 cm of the default 15 cm; past it, as
    guard_drift_lead says), before the
    loop's own stop there, so that it is re-planned from where it stands rather than stopped.
    A look-ahead's chance comes a second or more after the pose it started from, too late for
    a turn the robot cannot make; the drift is seen in the period it happens. None: not held
    for drifting."""
    guard_drift_lead: float | None = s(0.4, optional(positive("s", 5.0)))
    """With guard_drift: a robot past it is held only once its drift, going on this long at
    its rate over the last half second, would come within 1 cm of the loop's stop [s]
    (robot.drift_hold_at: a robot held drifts on a median 0.13 s, a 90th percentile 0.34 s of
    its rate; many drifting robots come back on their own); None: held at guard_drift."""
    guard_stuck: float | None = s(0.8, optional(between(0.1, 1.0, "-", high_included=False)))
    """With the guard on: also hold the robot (the run ends as "stall") once it has made no
    progress along its path for this share of the driver's stuck_time (0.8: 8 s of the
    default 10 s), before the loop's own stuck stop, as it counts progress; the re-plan is
    lines and turns on the spot (robot.replan_radius). A robot that walks in place at a
    ramp's foot, asked for a turn it cannot make, is re-planned rather than stopped (of 214
    legs of bench_guard's twins that reached the goal, 5 had gone 8 s or more without
    progress, none 9 s). None: not held for it (the stuck stop ends the run)."""
    edge_keep: float | None = s(0.04, optional(between(0.0, 0.2, "m")))
    """A plan from where the robot stands keeps this far from the drop-offs [m]: the robot may
    drift this far sideways off it anywhere (past its first 10 cm) and still stand where the
    planner lets it (robot.edge_margin); of up to EDGE_TRIES plans (seeds), the first that
    does, else the one that keeps farthest. A robot standing within this of an edge walks in
    first (robot.step_in). 4 cm: where the guard's first edge hold stopped a robot (half its
    7.5 cm drift limit); plans along a bridge's inner edge kept 0-3 cm, and a robot that
    drifted 4 cm fell off. None: any valid plan (the planner's first), and no step in."""
    trim: bool = s(True, boolean())
    """With the look-ahead: divide the motors' mismatch it estimates from the robot's own walk
    (pooled_mismatch) out of the commands sent, from each look-ahead on (RobotLoop.trim): a
    robot whose left motor runs 12 % fast and right 12 % slow is sent left / 1.12, right / 0.88,
    and turns both ways as the driver asks (within its motors' top speed). A re-planned leg
    starts with the last leg's estimate. False: the commands go as the driver gives them."""
    look_ahead_period: float = s(1.0, positive("s", 60.0))
    """How often to start a look-ahead [s] (the next starts when the last has ended, at the
    earliest this long after it began)."""

    def __post_init__(self) -> None:
        check_settings(self)
