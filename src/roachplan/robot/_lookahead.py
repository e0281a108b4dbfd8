"""Look-ahead (issue 32, its first part): from the robot's live pose, a handful of short
simulated rollouts of the rest of its plan, and the chance that it goes on for the horizon
without a stop the loop would make or a fall.

Each rollout drops the simulated robot at the live pose (x, y, yaw in the world frame [m],
[rad]) moved by the pose's noise (a draw of position_sd and yaw_sd_deg), and drives it with the
scene's driver along the plan from the path's point nearest the pose on (its turns on the spot
re-indexed), for `horizon` seconds. It fails when the simulation ends it (fell, flipped,
missed) or when, at any frame of its trajectory, the robot loop's own safety checks
(robot/_safety.py check_pose: outside the planning area, off standable ground, too far off
the path) would stop the real robot there. Reaching the goal within the horizon, or still
going at its end, is a rollout that holds.

The legs start at `phase`, the (left, right) motor phase [rad] the commands sent give (their
integral: LookAheadRunner keeps it from the loop's commands, as compare's windows do from a
log; reset at phase 0, a window's turn was off by 0.24 rad RMS, at the commands' phase by 0.03).
Each rollout's robot is drawn from the scene's uncertainty (friction, body mass, the two motors'
speeds: experiments.draw, as choose's rollouts; robot_draws), round the scene's robot, so a
scene naming a fitted robot file looks ahead with the fit. Driven one at a time, a rollout ends
at its first failure; in lockstep (MuJoCo) the safety checks read its frames afterwards.
LookAheadRunner also estimates the robot's motor mismatch from its last few seconds (how it
turned against how it was told to, on the stretches it was told to walk near straight:
straight_mismatches), pools each estimate with those before it (pooled_mismatch: a motor's
mismatch holds for the robot; a re-planned leg goes on from the legs before), and its
rollouts drive with that, so a robot whose motors differ from the model's is simulated
drifting as it does; with the loop's trim (RobotSettings.trim) the loop divides the pool out
of its commands, and the rollouts are driven so trimmed.
The pose is late (LookAheadConfig.latency, the motion capture's, and the time since it
arrived): each rollout starts from it at the moment it was the robot's, a lag drawn between its
arrival and twice the latency before it, with the legs at the phase the commands gave then,
and walks on until the horizon after the look-ahead began (LookAhead.lead).

look_ahead is a pure function of its inputs and seed: rollout k draws from
np.random.default_rng((seed, k)). LookAheadRunner runs it beside the robot loop about once a
`period` (RobotSettings.look_ahead), each look-ahead in its own process, recorded on the run's
/lookahead topic.
"""

from __future__ import annotations

import bisect
import collections
import contextlib
import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from roachplan._settings import (
    between,
    boolean,
    check_settings,
    integer,
    non_negative,
    one_of,
    optional,
    positive,
)
from roachplan._settings import setting as s
from roachplan.sim import ENGINES

from ._estimate import MISMATCH_PIECE, pooled_mismatch, straight_mismatches
from ._safety import SafetyConfig, SafetyMap, check_pose
from ._transform import yaw_of

if TYPE_CHECKING:
    from roachplan.scenes import World

_log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True)
class LookAheadConfig:
    """How far and how often the simulation looks ahead of the robot."""

    horizon: float = s(3.0, positive("s", 60.0))
    """Simulated time each rollout walks [s]."""
    draws: int = s(8, integer(1, 256))
    """Rollouts per look-ahead."""
    position_sd: float = s(0.01, non_negative("m"))
    """Standard deviation of the pose's position error, each horizontal axis [m]."""
    yaw_sd_deg: float = s(3.0, non_negative("deg"))
    """Standard deviation of the pose's heading error [deg]."""
    engine: str | None = s(None, optional(one_of(ENGINES)))
    """The physics engine its rollouts run in ("pybullet", "mujoco"; None: the scene's). Under
    MuJoCo a look-ahead's rollouts step together in lockstep (sim/_lockstep.py): 3 to 4 times
    as fast on the rough double bridge, so its chance is newer when it comes; a look-ahead in
    an engine other than the scene's is less faithful to it (docs: the engines' fidelity)."""
    mismatch_window: float = s(3.0, non_negative("s"))
    """Seconds of the robot's latest poses and commands kept to estimate its motors' mismatch
    from: each look-ahead estimates it on the 1 s stretches of them that the robot was told to
    walk near straight and no look-ahead before it estimated on (straight_mismatches), pooled
    with the estimates before (pooled_mismatch, the legs' before too); its rollouts then drive
    with it, on top of their draws (a robot that drifts is simulated drifting), and with the
    loop's trim (RobotSettings.trim). 0: not estimated."""
    latency: float = s(0.0, between(0.0, 5.0, "s"))
    """How late a pose is when it arrives [s]: the motion capture's latency (Motive shows
    it; the twin's --latency), taken as uncertain: each rollout starts from the newest pose at
    a moment drawn evenly between its arrival and twice this before it, the legs at the phase
    the commands gave then (at 20 rad/s, 40 ms is 0.8 rad of the gait), and walks the time
    since then on top of the horizon. 0: the pose was the robot's when it arrived."""
    robot_draws: bool = s(True, boolean())
    """Each rollout's robot is also drawn from the scene's uncertainty (friction, body mass,
    each motor's speed: the robot it might be, as choose's rollouts draw it); False: the
    scene's robot (its fitted robot file, if it names one) as it is."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class LookAhead:
    """One look-ahead's rollouts from one pose."""

    start: tuple[float, float, float]
    """The live pose it looked ahead from: x, y [m], yaw [rad], world frame."""
    horizon: float
    """[s]"""
    rollouts: int
    holds: int
    """Rollouts that went on for the horizon (or reached the goal) with no stop or fall."""
    failures: tuple[tuple[float, float, str], ...]
    """Where each failed rollout ended (x, y [m]) and why (a stop reason or an outcome)."""
    wall_time: float
    """Wall time of the look-ahead [s]."""
    mismatch: float | None = None
    """The motors' mismatch d its rollouts drove with (left x (1 + d), right x (1 - d)), as
    estimated from the robot's last seconds; None: not estimated."""
    trim: float = 0.0
    """The mismatch the robot loop divided out of its commands meanwhile (RobotLoop.trim), and
    its rollouts' driver with it."""
    lead: float = 0.0
    """How long before the look-ahead began its rollouts start [s], at the most likely lag:
    the pose's age on arrival (LookAheadConfig.latency) and since; they walk horizon + lead."""

    @property
    def p_hold(self) -> float:
        """The predicted chance that the robot goes on for the horizon without a stop or a
        fall [-]."""
        return self.holds / self.rollouts

    def to_json(self) -> dict:
        return {
            "start": list(self.start),
            "horizon": self.horizon,
            "rollouts": self.rollouts,
            "holds": self.holds,
            "p_hold": self.p_hold,
            "failures": [list(f) for f in self.failures],
            "wall_time": self.wall_time,
            "mismatch": self.mismatch,
            "trim": self.trim,
            "lead": self.lead,
        }


def remaining_path(
    path_xyz: np.ndarray, spins, xy, *, pending: bool = False
) -> tuple[np.ndarray, tuple[tuple[int, float], ...]]:
    """The plan from the point of path_xyz ((N, 3) world frame [m]) nearest xy on: that point,
    then the waypoints after it; spins ((waypoint index, heading [rad]) each) re-indexed to it,
    those behind it dropped. pending: spins are those the robot has yet to make (a loop's
    RobotLoop.pending_spins), and one at or behind the nearest point is made first, at the
    rest's start: a robot standing at a spin (a plan that starts with one repeats its first
    waypoint, and the nearest point is that waypoint's) or turning through it, a few
    centimetres past it, has not made it yet."""
    path = np.asarray(path_xyz, dtype=float)
    if len(path) < 2:
        return path.copy(), tuple((0, float(h)) for _, h in spins)
    a, b = path[:-1], path[1:]
    d = b - a
    p = np.asarray(xy, dtype=float)[:2]
    length2 = np.maximum(np.einsum("ij,ij->i", d[:, :2], d[:, :2]), 1e-18)
    u = np.clip(np.einsum("ij,ij->i", p - a[:, :2], d[:, :2]) / length2, 0.0, 1.0)
    k = int(np.argmin(np.linalg.norm(a[:, :2] + d[:, :2] * u[:, None] - p, axis=1)))
    nearest = a[k] + d[k] * u[k]
    rest = np.vstack([nearest, path[k + 1 :]])
    # waypoint i > k is row i - k of rest; a spin at waypoint k or before is behind the robot
    # (made, unless pending: then it is made first, where the rest starts)
    kept = tuple((max(int(i) - k, 0), float(h)) for i, h in spins if i > k or pending)
    return rest, kept


def _drawn_worlds(
    world: World,
    ahead: World,
    cfg: LookAheadConfig,
    pose,
    *,
    seed: int,
    phase,
    mismatch: float,
    trim: float = 0.0,
):
    """A look-ahead's cfg.draws simulations of `ahead` (world under the look-ahead's engine and
    horizon), each fresh (a rollout is its seed's alone), reset at pose (x, y, yaw) moved by
    the pose's noise drawn from (seed, k), the legs at phase ((2,) [rad], or (draws, 2): each
    rollout's), its robot drawn from the scene's
    uncertainty (cfg.robot_draws) with its motors' speeds moved by mismatch (left x (1 + d),
    right x (1 - d)) and back by the loop's trim (left / (1 + trim), right / (1 - trim): the
    driver's speeds are divided so before they are sent). A generator: the caller closes
    each."""
    from roachplan.experiments import draw

    x0, y0, yaw0 = pose
    phases = np.broadcast_to(np.asarray(phase, dtype=float), (cfg.draws, 2))
    # The estimate is the robot's whole mismatch; perturb's gains multiply the robot's own (a
    # fitted robot file's), so its own is divided out.
    own_l, own_r = world.robot.motor_gain
    own = (own_l - own_r) / (own_l + own_r) if mismatch else 0.0
    moved = ((1 + mismatch) / (1 + own) / (1 + trim), (1 - mismatch) / (1 - own) / (1 - trim))
    for k in range(cfg.draws):
        rng = np.random.default_rng((seed, k))
        dx, dy = rng.normal(0.0, cfg.position_sd, 2)
        dyaw = math.radians(float(rng.normal(0.0, cfg.yaw_sd_deg)))
        start = (x0 + float(dx), y0 + float(dy), yaw0 + dyaw)
        sim = ahead.simulation()
        try:
            friction, mass, gain = ahead.scene.sim.friction, 1.0, (1.0, 1.0)
            if cfg.robot_draws:
                w = draw(world.scene.uncertainty, int(rng.integers(2**63)))
                friction, mass, gain = friction * w.friction_scale, w.mass_scale, w.motor_gain
            if cfg.robot_draws or mismatch or trim:
                sim.perturb(
                    friction=friction,
                    mass_scale=mass,
                    motor_gain=(gain[0] * moved[0], gain[1] * moved[1]),
                )
            surface = float(world.heightfield.sample(np.array(start[:2])))
            sim.reset(*start, surface=surface, phase=tuple(phases[k].tolist()))
        except BaseException:
            sim.close()
            raise
        yield sim


def look_ahead(
    world: World,
    path_xyz: np.ndarray,
    spins,
    pose: tuple[float, float, float],
    cfg: LookAheadConfig,
    *,
    safety: SafetyConfig,
    safety_map: SafetyMap,
    seed: int,
    phase=(0.0, 0.0),
    mismatch: float | None = None,
    trim: float = 0.0,
    lead: float = 0.0,
) -> LookAhead:
    """cfg.draws rollouts of the plan (path_xyz, and the spins the robot has yet to make:
    RobotLoop.pending_spins; from the plan's start, all of them) from the live pose for
    cfg.horizon + lead seconds (lead: how long before now the pose was the robot's [s]), the
    legs at `phase` ((2,) [rad], or (cfg.draws, 2): each rollout's; module docstring),
    checked by the loop's safety settings on safety_map; the motors' mismatch
    (estimate_mismatch; None: none) applied to each, and the trim the robot loop divides out
    of its commands (RobotLoop.trim: what the robot is sent differs from what the driver asks
    by as much)."""
    from roachplan.scenes import with_engine
    from roachplan.sim import drive_lockstep, drive_path

    t0 = time.perf_counter()
    x0, y0, yaw0 = (float(v) for v in pose)
    rest, rest_spins = remaining_path(path_xyz, spins, (x0, y0), pending=True)
    scene = world.scene if cfg.engine is None else with_engine(world.scene, cfg.engine)
    walk = cfg.horizon + lead
    ahead = world.with_sim(scene.sim, dataclasses.replace(scene.driver, time_limit=walk))
    path_xy = np.asarray(path_xyz, dtype=float)[:, :2]

    def stop_at(p_world_body) -> tuple[float, float, str] | None:
        """Where and why the loop's safety checks would stop the robot at this position."""
        stop = check_pose(
            safety, safety_map, path_xy, now=0.0, t_receive=0.0, position_world=p_world_body
        )
        return (
            None if stop is None else (float(p_world_body[0]), float(p_world_body[1]), stop.reason)
        )

    with contextlib.ExitStack() as stack:
        sims = [
            stack.enter_context(sim)
            for sim in _drawn_worlds(
                world,
                ahead,
                cfg,
                (x0, y0, yaw0),
                seed=seed,
                phase=phase,
                mismatch=mismatch or 0.0,
                trim=trim,
            )
        ]
        if ahead.scene.sim.engine == "mujoco" and len(sims) > 1:
            # In lockstep; the safety checks then read each trajectory's frames (the frames
            # drive_path's on_frame sees).
            driven = drive_lockstep(
                sims, [rest] * len(sims), ahead.scene.driver, [rest_spins] * len(sims)
            )
            stops = [
                next(filter(None, (stop_at(f[1:]) for f in d.trajectory)), None) for d in driven
            ]
        else:
            driven, stops = [], []
            for sim in sims:
                stopped: list[tuple[float, float, str]] = []

                def on_frame(f, stopped=stopped) -> None:
                    stop = stop_at(f.p_world_body)
                    if stop is not None:
                        stopped.append(stop)
                        raise _Stopped  # (the rollout has failed: no need to walk on)

                try:
                    driven.append(
                        drive_path(
                            sim, rest, ahead.scene.driver, on_frame=on_frame, spins=rest_spins
                        )
                    )
                except _Stopped:
                    driven.append(None)
                stops.append(stopped[0] if stopped else None)
    holds = 0
    failures: list[tuple[float, float, str]] = []
    for d, stop in zip(driven, stops, strict=True):
        if stop is not None:
            failures.append(stop)
        elif d is not None and d.outcome in ("success", "timeout"):
            holds += 1
        elif d is not None:
            _, x, y, _ = d.trajectory[-1]
            failures.append((float(x), float(y), d.outcome))
    return LookAhead(
        start=(x0, y0, yaw0),
        horizon=cfg.horizon,
        rollouts=cfg.draws,
        holds=holds,
        failures=tuple(failures),
        wall_time=time.perf_counter() - t0,
        mismatch=mismatch,
        trim=trim,
        lead=lead,
    )


class _Stopped(Exception):
    """A look-ahead's rollout met a stop of the loop's safety checks."""


def _look_in(world: World, path_xyz, spins, pose, cfg, **settings) -> LookAhead:
    """look_ahead in a fork of the look-ahead's Host (its value: the world)."""
    return look_ahead(world, path_xyz, spins, pose, cfg, **settings)


SETTLE = 1.0
"""The mismatch is not estimated on a leg's first second of walk [s]: from rest, on the rough
bridge, the first estimates of a twin's 0.12 came out at -0.01 and 0.035."""


PHASE_KEPT = 2.0
"""LookAheadRunner keeps the motors' phase of the commands of the last this many seconds [s]:
a rollout starts at the pose's moment (its latency and age), never that long ago."""


def phase_at(phases, t: float) -> tuple[float, float]:
    """The motors' (left, right) phase [rad, in [0, 2 pi)] at t [s, monotonic] from phases
    ((t_k, left, right phase then [rad], left, right speed since [rad/s]) at each command, in
    time order): the last command at or before t, run on at its speeds; before the first kept,
    the first's phase."""
    kept = list(phases)
    k = bisect.bisect_right([c[0] for c in kept], t) - 1
    if k < 0:
        return kept[0][1], kept[0][2]
    return _run_on(kept[k], t)


def _run_on(entry, t: float) -> tuple[float, float]:
    """The phase of one of phase_at's entries run on at its speeds to t [s] (none before the
    first command: its time is -inf)."""
    t0, left, right, wl, wr = entry
    dt = max(t - t0, 0.0) if math.isfinite(t0) else 0.0
    two_pi = 2 * math.pi
    return ((left + wl * dt) % two_pi, (right + wr * dt) % two_pi)


class LookAheadRunner:
    """The look-ahead beside the robot loop, never in it: a thread that, every `period`
    seconds, takes the newest world-frame pose the loop has seen (`listen`, a loop listener)
    and looks ahead from it in a fork of a process holding the world (processes.Host: the
    simulation runs in its own process, so the 50 Hz loop keeps its rate and the GIL). Each
    result goes to on_result(t [s, monotonic], LookAhead). Look-ahead n is seeded
    (seed, n). Before each, the motors' mismatch is estimated from the robot's last window and
    pooled with the windows before (estimates: those of the legs before this one); on_trim
    (None: none) is given the pool, for the loop to divide out of its commands
    (RobotLoop.trim), and the look-ahead then simulates the robot so trimmed. pending() gives
    the spins the robot has yet to make at each look-ahead (RobotLoop.pending_spins; None: the
    plan's `spins`, all of them, whatever the robot's progress)."""

    def __init__(
        self,
        world: World,
        path_xyz: np.ndarray,
        spins,
        cfg: LookAheadConfig,
        *,
        safety: SafetyConfig,
        safety_map: SafetyMap,
        period: float,
        seed: int,
        on_result: Callable[[float, LookAhead], None],
        estimates: tuple[tuple[float, float], ...] = (),
        on_trim: Callable[[float], None] | None = None,
        pending: Callable[[], tuple[tuple[int, float], ...]] | None = None,
    ) -> None:
        from roachplan.processes import Host

        self._pending = pending
        self._args = (np.asarray(path_xyz, dtype=float), tuple(spins), cfg, safety, safety_map)
        self.period = period
        self.seed = seed
        self.on_result = on_result
        self.results: list[LookAhead] = []
        self._pose: tuple[float, float, float] | None = None
        self._pose_t = 0.0
        """When the newest pose arrived [s, monotonic]."""
        self._gain = world.robot.motor_gain
        self._limit = world.robot.max_motor_speed
        self._phases: collections.deque = collections.deque([(-math.inf, 0.0, 0.0, 0.0, 0.0)])
        """(t [s, monotonic], left, right phase [rad] then, left, right speed [rad/s] from then
        on) at each command of the last PHASE_KEPT seconds, and the one before them: the
        motors' phase at any moment since (phase_at; a rollout starts at the pose's)."""
        self._poses: collections.deque = collections.deque()
        """(t [s, monotonic], x, y [m], yaw [rad]) of the poses within cfg.mismatch_window."""
        self._commands: collections.deque = collections.deque()
        """(t [s, monotonic], left, right [rad/s], trim) of the commands within it, as sent
        (stop: 0, 0), with the loop's trim they were sent under."""
        self._curve = (world.scene.driver.turning, world.scene.driver.max_ratio)
        self._estimates: list[tuple[float, float]] = list(estimates)
        """(mismatch, walked [m]) of each window estimated so far (pooled_mismatch), from the
        legs before this one (estimates) on: a motor's mismatch holds for the robot."""
        self._until = -math.inf
        """The estimated stretches end here [s, monotonic]: the next starts after it (and
        SETTLE after the leg's first walking command: from rest the gait is not yet steady)."""
        self._walking: float | None = None
        """When the leg's first walking command was sent [s, monotonic] (None: not yet)."""
        self.on_trim = on_trim
        self.trim = 0.0
        """The trim last given to on_trim (the loop's, which the look-ahead then drives with)."""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._host = Host(world, name="roachplan look-ahead")
        self._thread = threading.Thread(target=self._run, name="look-ahead", daemon=True)

    def listen(self, event) -> None:
        """A loop listener: keep the newest pose (x, y, yaw in the world frame) and the motors'
        phase, the integral of the commands sent (the robot's motor gain applied, clipped to
        its motors' limit; a stop frame stands still)."""
        kind = getattr(event, "kind", None)
        window = self._args[2].mismatch_window
        if kind == "pose":
            x, y, _ = event.position
            t = event.sample.t_receive
            with self._lock:
                self._pose, self._pose_t = (float(x), float(y), yaw_of(event.quat)), t
                if window > 0:
                    self._poses.append((t, *self._pose))
                    while self._poses and self._poses[0][0] < t - window:
                        self._poses.popleft()
        elif kind == "command":
            f = event.frame
            wl, wr = (0.0, 0.0) if f.stop else (f.left * self._gain[0], f.right * self._gain[1])
            sent = (
                (event.t, 0.0, 0.0, self.trim) if f.stop else (event.t, f.left, f.right, self.trim)
            )
            with self._lock:
                if not f.stop and self._walking is None:  # (the leg's first walking command)
                    self._walking = event.t
                if window > 0:
                    self._commands.append(sent)
                    while self._commands and self._commands[0][0] < event.t - window:
                        self._commands.popleft()
                phases = self._phases
                at = _run_on(phases[-1], event.t)  # (the last command's: O(1) in the loop)
                limit = self._limit
                phases.append(
                    (event.t, *at, min(max(wl, -limit), limit), min(max(wr, -limit), limit))
                )
                while len(phases) > 2 and phases[1][0] < event.t - PHASE_KEPT:
                    phases.popleft()

    @property
    def estimates(self) -> tuple[tuple[float, float], ...]:
        """(mismatch, walked [m]) of every window estimated so far, the legs' before this one's
        first (a re-planned leg's runner starts from them)."""
        return tuple(self._estimates)

    def start(self) -> None:
        self._thread.start()

    @property
    def started(self) -> bool:
        """start() was called: the robot was given Go."""
        return self._thread.ident is not None

    def close(self) -> None:
        """Stop looking ahead (a look-ahead under way is cancelled) and end the host."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10)
        self._host.close()

    def _run(self) -> None:
        from roachplan.processes import Child, Returned

        n = 0
        while not self._stop.wait(self.period if n else 0.0):
            path, spins, cfg, safety, smap = self._args
            if self._pending is not None:  # (a spin made is behind; one under way is not)
                spins = self._pending()
            # The pose's lag behind now, drawn per rollout (LookAheadConfig.latency), and the
            # motors' phase at each such moment.
            lags = 2.0 * cfg.latency * np.random.default_rng((self.seed, n, 1)).random(cfg.draws)
            with self._lock:
                pose, t_pose = self._pose, self._pose_t
                phase = [phase_at(self._phases, t_pose - lag) for lag in lags]
                poses, commands = np.array(self._poses), np.array(self._commands)
                walking = self._walking
            if pose is None:
                continue
            if cfg.mismatch_window and len(poses) and walking is not None:
                # The straight stretches of the window not estimated before, pooled with the
                # legs' before them.
                poses = poses[poses[:, 0] >= max(self._until, walking + SETTLE)]
                if len(poses) >= 2:
                    self._estimates += straight_mismatches(poses, commands, *self._curve)
                    whole = math.floor((poses[-1, 0] - poses[0, 0]) / MISMATCH_PIECE)
                    self._until = float(poses[0, 0]) + whole * MISMATCH_PIECE
            mismatch = pooled_mismatch(self._estimates)
            if self.on_trim is not None and mismatch is not None:
                self.trim = mismatch  # (what the loop divides out from now on)
                self.on_trim(mismatch)
            seed = int(np.random.SeedSequence([self.seed, n]).generate_state(1)[0])
            t = time.monotonic()
            # (at the lags' mean; a pose older than PHASE_KEPT is stale: the loop stops first)
            lead = min(max(t - t_pose, 0.0), PHASE_KEPT) + cfg.latency
            child = Child(
                _look_in,
                (path, spins, pose, cfg),
                {
                    "safety": safety,
                    "safety_map": smap,
                    "seed": seed,
                    "phase": phase,
                    "mismatch": mismatch,
                    "trim": self.trim,
                    "lead": lead,
                },
                start=self._host,
                task="look-ahead",
            )
            while not child.done:
                if self._stop.is_set():
                    child.cancel()
                    return
                child.poll(0.05)
            n += 1
            outcome = child.outcome
            if isinstance(outcome, Returned) and isinstance(outcome.value, LookAhead):
                self.results.append(outcome.value)
                self.on_result(t, outcome.value)
            else:  # (the robot drives on: a look-ahead is advice, never the loop's)
                _log.warning("look-ahead %d from %s did not finish: %s", n, pose, outcome)


FAILED_STOPS = frozenset({"outside_area", "off_standable", "deviation", "missed", "stuck"})
"""How a run ends that a look-ahead predicts: the stops its rollouts fail by (the loop's
safety checks; the driver's missed and stuck). A fall ends a real run as off_standable."""
RELIABILITY_BINS = ((0.0, 0.5), (0.5, 0.8), (0.8, 0.95), (0.95, 1.0))
"""Bins of predicted chance [-] that `look_ahead_reliability` compares with what happened."""


def observed_hold(lookahead: dict, result: dict) -> int | None:
    """What happened over one recorded look-ahead's horizon (its /lookahead message, with "t"
    [s, monotonic]), given the run's /result: 1 when the robot went on for the horizon (its
    first stop frame later than t + horizon) or reached the goal; 0 when a stop it predicts
    (FAILED_STOPS) ended the run within it; None when something else did (Stop, Cancel, a
    signal, a stale pose, the guard): nothing to score."""
    if result["t_stop"] > lookahead["t"] + lookahead["horizon"] or result["reason"] == "goal":
        return 1
    return 0 if result["reason"] in FAILED_STOPS else None


def look_ahead_reliability(runs) -> dict:
    """How well the look-aheads recorded in runs (RunLog each, read_run) predicted what
    happened: per RELIABILITY_BINS bin, how many were scored, their mean predicted chance and
    the share observed to hold (a bin of fewer than 20 says little); and the Brier score over
    all (mean squared difference of prediction and outcome, 0 best; nan with none scored)."""
    pairs = []
    for run in runs:
        if run.result is None:
            continue
        for ahead in run.lookaheads:
            seen = observed_hold(ahead, run.result)
            if seen is not None:
                pairs.append((float(ahead["p_hold"]), seen))
    bins = []
    for k, (lo, hi) in enumerate(RELIABILITY_BINS):
        last = k == len(RELIABILITY_BINS) - 1
        inside = [(p, o) for p, o in pairs if lo <= p < hi or (last and p == hi)]
        bins.append(
            {
                "bin": [lo, hi],
                "scored": len(inside),
                "predicted": float(np.mean([p for p, _ in inside])) if inside else math.nan,
                "observed": float(np.mean([o for _, o in inside])) if inside else math.nan,
            }
        )
    brier = float(np.mean([(p - o) ** 2 for p, o in pairs])) if pairs else math.nan
    return {"scored": len(pairs), "brier": brier, "bins": bins}
