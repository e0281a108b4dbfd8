"""How good was the prediction: re-simulate a logged run and compare (compare), and fit the
simulation's parameters to logged runs (fit).

A run is re-simulated two ways from the robot's logged start (its pose at Go): open-loop, the
same motor commands at the same times; and closed-loop, the same plan driven by the
simulation's own driver (what the prediction was). Errors are taken at the times of the
logged poses, shifted back by the pose latency when it is known (a pose received at t shows
the robot at t - latency).

A whole run replayed open loop diverges chaotically (replay_windows says how much), so both
compare and fit also replay it in short windows, each from the robot's own logged pose and
the motor phase its commands give (replay_windows). fit matches each parameter to the
windows' statistic it moves most (fit): friction to the position error, motor mismatch to the
mean turn, motor gain to the mean forward travel; coordinate by coordinate, each search
derivative-free (each evaluation is a PyBullet re-simulation of every log).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from roachplan._settings import between, check_settings, integer
from roachplan._settings import setting as s

from ._errors import RobotError
from ._record import RunLog, read_run
from ._transform import yaw_of

if TYPE_CHECKING:
    from roachplan.scenes import RobotFile, World

PARAMETERS = ("friction", "motor_gain", "motor_mismatch", "mass_scale")


@dataclass(frozen=True, kw_only=True)
class SimParams:
    """The simulation's parameters of one robot (as a robot file holds them)."""

    friction: float
    motor_gain: float = 1.0
    motor_mismatch: float = 0.0
    mass_scale: float = 1.0

    def robot_file(self, fitted: dict | None = None) -> RobotFile:
        from roachplan.scenes import RobotFile

        return RobotFile(**dataclasses.asdict(self), fitted=fitted)


def nominal_params(world: World) -> SimParams:
    """The world's own parameters (its scene's friction; its robot's motors and mass)."""
    from roachplan.sim import RobotConfig

    g_left, g_right = world.robot.motor_gain
    gain = (g_left + g_right) / 2
    return SimParams(
        friction=world.scene.sim.friction,
        motor_gain=gain,
        motor_mismatch=(g_left - g_right) / (2 * gain),
        mass_scale=world.robot.body_mass / RobotConfig().body_mass,
    )


@dataclass(frozen=True, kw_only=True, eq=False)
class Track:
    """A trajectory: t (K,) [s since Go], xy (K, 2) [m], yaw (K,) [rad]."""

    t: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(xy, yaw) interpolated at times t (held at the ends)."""
        x = np.interp(t, self.t, self.xy[:, 0])
        y = np.interp(t, self.t, self.xy[:, 1])
        yaw = np.interp(t, self.t, np.unwrap(self.yaw))
        return np.column_stack([x, y]), yaw


def logged_track(log: RunLog, latency: float = 0.0) -> Track:
    """The robot's poses from Go to the stop, at the times they show [s since Go]."""
    t_go = log.t_go
    if t_go is None or log.start is None:
        raise RobotError(f"run log {log.path}: the robot never went (no go event)")
    t_stop = next((e["t"] for e in log.events if e["name"] == "stop"), math.inf)
    t = log.poses["t_receive"] - latency
    keep = (t >= t_go - 1e-9) & (log.poses["t_receive"] <= t_stop)
    if keep.sum() < 2:
        raise RobotError(f"run log {log.path}: fewer than two poses between Go and the stop")
    q = log.poses["world_q"][keep]
    return Track(
        t=t[keep] - t_go,
        xy=log.poses["world_p"][keep, :2],
        yaw=np.array([yaw_of(qq) for qq in q]),
    )


def _simulation(world: World, params: SimParams):
    robot = params.robot_file().robot()
    cfg = dataclasses.replace(world.scene.sim, friction=params.friction)
    return world.simulation(robot=robot, cfg=cfg)


def replay_commands(world: World, log: RunLog, params: SimParams, times: np.ndarray) -> Track:
    """Open loop: the logged commands from Go on, applied at their times [s since Go] from the
    logged start, in a simulation with params; the pose at each of times (sorted)."""
    t_go = log.t_go
    start = log.start
    assert t_go is not None and start is not None  # logged_track checked
    c = log.commands
    after = c["t"] >= t_go - 1e-9
    ct = c["t"][after] - t_go
    left = np.where(c["stop"][after], 0.0, c["left"][after])
    right = np.where(c["stop"][after], 0.0, c["right"][after])
    sim = _simulation(world, params)
    try:
        sim.reset(*start, surface=float(world.heightfield.sample(np.array(start[:2]))))
        dt = sim.cfg.timestep
        xy = np.zeros((len(times), 2))
        yaw = np.zeros(len(times))
        k = 0
        for j, tj in enumerate(times):
            while k < len(ct) and ct[k] <= tj:
                n = round((ct[k] - sim.time) / dt)
                if n > 0:
                    sim.advance(n)
                sim.set_leg_speeds(float(left[k]), float(right[k]))
                k += 1
            n = round((tj - sim.time) / dt)
            if n > 0:
                sim.advance(n)
            pos, quat = sim.pose()
            xy[j] = pos[:2]
            yaw[j] = yaw_of(quat)
        return Track(t=np.asarray(times, dtype=float), xy=xy, yaw=yaw)
    finally:
        sim.close()


def _commands_after_go(log: RunLog) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The commands sent from Go on: times [s since Go], left and right [rad/s] (0 when a
    stop frame)."""
    t_go = log.t_go
    assert t_go is not None  # logged_track checked
    c = log.commands
    after = c["t"] >= t_go - 1e-9
    stop = c["stop"][after]
    return (
        c["t"][after] - t_go,
        np.where(stop, 0.0, c["left"][after]),
        np.where(stop, 0.0, c["right"][after]),
    )


def motor_phase(
    ct: np.ndarray, left: np.ndarray, right: np.ndarray, gains: tuple[float, float], limit: float
):
    """The (left, right) motor phase [rad] at a time [s since Go] of a robot whose motors run
    at gain x their command (at most `limit` [rad/s]) and stood still before Go: the integral
    of the logged commands. (The simulation's motors track their phase exactly; a real
    robot's speed-controlled motors near enough over a few strides.)"""
    wl = np.clip(left * gains[0], -limit, limit)
    wr = np.clip(right * gains[1], -limit, limit)
    dts = np.diff(ct, append=ct[-1]) if len(ct) else ct
    pl = np.concatenate([[0.0], np.cumsum(wl * dts)])
    pr = np.concatenate([[0.0], np.cumsum(wr * dts)])

    def at(t: float) -> tuple[float, float]:
        k = int(np.searchsorted(ct, t, side="right")) - 1
        if k < 0:
            return (0.0, 0.0)
        return (
            float(pl[k] + wl[k] * (t - ct[k])) % (2 * math.pi),
            float(pr[k] + wr[k] * (t - ct[k])) % (2 * math.pi),
        )

    return at


def _body(v, yaw: float) -> tuple[float, float]:
    """A horizontal vector in the frame of a body heading yaw [rad]: (forward, left)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return (c * v[0] + s * v[1], -s * v[0] + c * v[1])


@dataclass(frozen=True, kw_only=True, eq=False)
class Windows:
    """A run re-simulated in short windows (replay_windows): how the robot and the simulation
    moved over each, in the body frame at the window's start."""

    t: np.ndarray
    """(W,) each window's start [s since Go]."""
    robot: np.ndarray
    """(W, 3) the robot's forward and leftward displacement [m] and turn [rad]."""
    sim: np.ndarray
    """(W, 3) the simulation's."""

    @property
    def position(self) -> np.ndarray:
        """(W,) |displacement difference| [m]."""
        return np.hypot(*(self.sim[:, :2] - self.robot[:, :2]).T)

    @property
    def heading(self) -> np.ndarray:
        """(W,) |turn difference| [rad]."""
        return np.abs(self.sim[:, 2] - self.robot[:, 2])

    def error(self) -> float:
        """RMS over the windows of the displacement difference and the turn difference as the
        offset it makes half a metre on (1 rad ~ 0.5 m) [m]."""
        if len(self.t) == 0:
            return 0.0
        return float(np.sqrt(np.mean(self.position**2 + (0.5 * self.heading) ** 2)))

    def to_json(self) -> dict:
        return {
            "t": self.t.tolist(),
            "position_rms_m": float(np.sqrt(np.mean(self.position**2))) if len(self.t) else 0.0,
            "heading_rms_rad": float(np.sqrt(np.mean(self.heading**2))) if len(self.t) else 0.0,
            "error_m": self.error(),
            "forward_bias_m": float(np.mean(self.sim[:, 0] - self.robot[:, 0]))
            if len(self.t)
            else 0.0,
            "turn_bias_rad": float(np.mean(self.sim[:, 2] - self.robot[:, 2]))
            if len(self.t)
            else 0.0,
        }


def replay_windows(
    world: World,
    log: RunLog,
    params: SimParams,
    robot: Track,
    horizon: float = 1.0,
    *,
    lead: float = 0.5,
) -> Windows:
    """Open loop over short windows (multiple shooting): from the robot's logged pose
    `lead` seconds before each `horizon`-second window, its legs at the motor phase the
    logged commands give (motor_phase), the logged commands in a simulation with params; how
    far and which way each moved over the window, in the body frame at its start.

    A whole run replayed open loop is chaotic here (shifting every command by 1 ms moves its
    end by half a metre: the gait's contacts decide the heading): it measures the first
    small difference, amplified, not the parameters. Windows measure what the parameters do
    - how fast, how it turns, how it slips - from the robot's own state each time: its pose
    (logged) and its legs' phase (the commands' integral: without it a window's turn is off
    by 0.2 rad RMS whatever the parameters). The lead lets the body take up its gait before
    the window counts."""
    ct, left, right = _commands_after_go(log)
    robot_gain = params.robot_file().robot().motor_gain
    phase = motor_phase(ct, left, right, robot_gain, world.robot.max_motor_speed)
    starts = np.arange(robot.t[0] + lead, robot.t[-1] - horizon, horizon)
    out_robot = np.zeros((len(starts), 3))
    out_sim = np.zeros((len(starts), 3))
    sim = _simulation(world, params)
    try:
        dt = sim.cfg.timestep
        for w, ts in enumerate(starts):
            t0 = ts - lead
            (xy0,), (yaw0,) = robot.at(np.array([t0]))
            sim.reset(
                xy0[0],
                xy0[1],
                float(yaw0),
                surface=float(world.heightfield.sample(xy0)),
                phase=phase(t0),
            )
            k = int(np.searchsorted(ct, t0, side="right")) - 1
            sim.set_leg_speeds(float(left[max(k, 0)]), float(right[max(k, 0)]))
            k += 1
            yaws: list[float] = []
            marks: list[tuple[np.ndarray, float]] = []
            for mark in (ts, ts + horizon):
                while k < len(ct) and ct[k] < mark:
                    n = round((ct[k] - t0 - sim.time) / dt)
                    if n > 0:
                        sim.advance(n)
                    yaws.append(yaw_of(sim.pose()[1]))  # (every 20 ms: a spin unwraps)
                    sim.set_leg_speeds(float(left[k]), float(right[k]))
                    k += 1
                n = round((mark - t0 - sim.time) / dt)
                if n > 0:
                    sim.advance(n)
                pos, quat = sim.pose()
                yaws.append(yaw_of(quat))
                marks.append((np.array(pos[:2]), float(np.unwrap(yaws)[-1])))
            (p0, y0), (p1, y1) = marks
            (r0, r1), (ry0, ry1) = robot.at(np.array([ts, ts + horizon]))
            out_sim[w] = (*_body(p1 - p0, y0), y1 - y0)
            out_robot[w] = (*_body(r1 - r0, float(ry0)), float(ry1 - ry0))
    finally:
        sim.close()
    return Windows(t=starts, robot=out_robot, sim=out_sim)


def drive_plan(world: World, log: RunLog, params: SimParams) -> tuple[Track, str, str]:
    """Closed loop: the logged plan driven by the simulation's driver from the logged start;
    (track, outcome, reason)."""
    from roachplan.sim import drive_path

    start = log.start
    assert start is not None
    path = np.asarray(log.plan["path"], dtype=float)
    spins = [tuple(s) for s in log.plan.get("spins", [])]
    frames: list[tuple[float, float, float, float]] = []

    def on_frame(f) -> None:
        frames.append((f.t, f.p_world_body[0], f.p_world_body[1], yaw_of(f.quat_world_body)))

    sim = _simulation(world, params)
    try:
        sim.reset(*start, surface=float(world.heightfield.sample(np.array(start[:2]))))
        driven = drive_path(sim, path, world.scene.driver, on_frame=on_frame, spins=spins)
        pos, quat = sim.pose()
        frames.append((sim.time, pos[0], pos[1], yaw_of(quat)))
    finally:
        sim.close()
    a = np.array(frames)
    return Track(t=a[:, 0], xy=a[:, 1:3], yaw=a[:, 3]), driven.outcome, driven.reason


@dataclass(frozen=True, kw_only=True, eq=False)
class Errors:
    """Simulation against robot at the robot's pose times."""

    t: np.ndarray
    """(K,) [s since Go]."""
    position: np.ndarray
    """(K,) horizontal distance [m]."""
    heading: np.ndarray
    """(K,) |heading difference| [rad]."""
    end: float
    """Distance between where the robot ended and where the simulation did [m]."""

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.position**2)))

    def to_json(self) -> dict:
        return {
            "end_m": self.end,
            "rms_m": self.rms,
            "max_m": float(self.position.max()),
            "heading_rms_rad": float(np.sqrt(np.mean(self.heading**2))),
            "t": self.t.tolist(),
            "position_m": self.position.tolist(),
            "heading_rad": self.heading.tolist(),
        }


def _errors(robot: Track, sim_xy: np.ndarray, sim_yaw: np.ndarray, sim_end_xy) -> Errors:
    d_yaw = np.abs(np.remainder(sim_yaw - robot.yaw + np.pi, 2 * np.pi) - np.pi)
    return Errors(
        t=robot.t,
        position=np.linalg.norm(sim_xy - robot.xy, axis=1),
        heading=d_yaw,
        end=float(np.linalg.norm(np.asarray(sim_end_xy) - robot.xy[-1])),
    )


@dataclass(frozen=True, kw_only=True, eq=False)
class Comparison:
    """How well the simulation predicted one run."""

    log: Path
    params: SimParams
    open_loop: Errors
    """The logged commands replayed over the whole run (chaotic: see replay_windows)."""
    closed_loop: Errors
    """The plan driven by the simulation's driver (the prediction)."""
    windows: Windows
    """The logged commands replayed in short windows from the robot's own state."""
    robot_outcome: str
    """How the robot's run ended (its stop reason)."""
    sim_outcome: str
    """How the simulated drive ended (the trial outcome)."""

    @property
    def outcome_agrees(self) -> bool:
        """Both reached the goal, or neither did."""
        return (self.robot_outcome == "goal") == (self.sim_outcome == "success")

    def to_json(self) -> dict:
        return {
            "log": str(self.log),
            "params": dataclasses.asdict(self.params),
            "open_loop": self.open_loop.to_json(),
            "closed_loop": self.closed_loop.to_json(),
            "windows": self.windows.to_json(),
            "robot_outcome": self.robot_outcome,
            "sim_outcome": self.sim_outcome,
            "outcome_agrees": self.outcome_agrees,
        }


def _as_log(log: RunLog | str | Path) -> RunLog:
    return log if isinstance(log, RunLog) else read_run(log)


def compare(
    log: RunLog | str | Path,
    world: World,
    *,
    params: SimParams | None = None,
    latency: float = 0.0,
    horizon: float = 1.0,
) -> Comparison:
    """Re-simulate a logged run on world (its scene) with params (default: the world's own)
    open- and closed-loop from the logged start, and in `horizon`-second windows from the
    robot's own state; position and heading error over time, the end error, and whether the
    outcome agreed. latency: the pose stream's [s] (a pose received at t shows the robot at
    t - latency)."""
    log = _as_log(log)
    params = params or nominal_params(world)
    robot = logged_track(log, latency)
    open_track = replay_commands(world, log, params, robot.t)
    open_err = _errors(robot, open_track.xy, open_track.yaw, open_track.xy[-1])
    closed, outcome, _ = drive_plan(world, log, params)
    xy, yaw = closed.at(robot.t)
    closed_err = _errors(robot, xy, yaw, closed.xy[-1])
    return Comparison(
        log=log.path,
        params=params,
        open_loop=open_err,
        closed_loop=closed_err,
        windows=replay_windows(world, log, params, robot, horizon),
        robot_outcome=(log.result or {}).get("reason", "unknown"),
        sim_outcome=outcome,
    )


def log_world(log: RunLog, scene: str | Path | None = None) -> World:
    """The world a run was made on: `scene` (a library name or a file) if given, else the
    scene file the log names - RobotError when it is gone or has changed since the run (its
    SHA-256 is in the log): then give the scene."""
    import hashlib

    from roachplan.scenes import build_world, load_scene

    if scene is not None:
        return build_world(load_scene(scene))
    recorded = log.scene or {}
    path = recorded.get("path")
    if not path:
        raise RobotError(f"{log.path}: the log names no scene file; give the scene (--scene)")
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise RobotError(
            f"{log.path}: its scene file {path} cannot be read ({exc.strerror}); give the "
            f"scene (--scene)"
        ) from None
    if recorded.get("sha256") and hashlib.sha256(data).hexdigest() != recorded["sha256"]:
        raise RobotError(
            f"{log.path}: its scene file {path} has changed since the run; give the scene "
            f"(--scene) to use it as it is now"
        )
    return build_world(load_scene(path))


def params_of_robot_file(path: str | Path) -> SimParams:
    """The parameters a robot file holds (scenes/_robot_file.py)."""
    from roachplan.scenes import load_robot_file

    f = load_robot_file(Path(path))
    return SimParams(
        friction=f.friction,
        motor_gain=f.motor_gain,
        motor_mismatch=f.motor_mismatch,
        mass_scale=f.mass_scale,
    )


BOUNDS = {
    "friction": (0.2, 2.0),
    "motor_gain": (0.5, 1.5),
    "motor_mismatch": (-0.2, 0.2),
    "mass_scale": (0.5, 2.0),
}
"""Where the fit searches each parameter."""


def _parameters_check(value) -> str | None:
    expected = f"expected one or more of {', '.join(PARAMETERS)}, each once"
    ok = (
        isinstance(value, tuple | list)
        and 0 < len(value) == len(set(value))
        and all(isinstance(v, str) and v in PARAMETERS for v in value)
    )
    return None if ok else expected


@dataclass(frozen=True, kw_only=True)
class FitConfig:
    """How fit searches (each value checked by its validator however the config is made)."""

    parameters: tuple[str, ...] = s(("friction", "motor_gain", "motor_mismatch"), _parameters_check)
    """What to fit (PARAMETERS); the others stay at the world's own values."""
    latency: float = s(0.0, between(0.0, 1.0, "s"))
    """The pose stream's latency [s]: a pose received at t shows the robot at t - latency."""
    horizon: float = s(1.0, between(0.2, 5.0, "s"))
    """The windows' length [s] (replay_windows)."""
    lead: float = s(0.5, between(0.0, 2.0, "s"))
    """How long each window's simulation runs before it counts [s]."""
    starts: int = s(5, integer(2, 50, noun="a number of starting points"))
    """Friction is searched from this many points across its range, then refined by Brent's
    method from the best (the position error is not convex over the whole range)."""
    rounds: int = s(2, integer(1, 10, noun="a number of rounds"))
    """Passes over the parameters, each fitted with the others held (coordinate descent)."""
    max_evaluations: int = s(80, integer(1, 100_000, noun="a number of simulations"))
    """At most this many re-simulations of every log (each a few seconds of CPU per log)."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class FitResult:
    """What fit found."""

    params: SimParams
    before: SimParams
    error_before: float
    """Mean over the logs of the windows' error (Windows.error) with `before` [m]."""
    error_after: float
    """The same with `params` [m]."""
    evaluations: int
    fitted: tuple[str, ...]
    statistics: dict
    """The statistics each parameter was fitted on, with params: position RMS [m], turn bias
    [rad per window], forward bias [share of the robot's own]."""

    def to_json(self) -> dict:
        return {
            "params": dataclasses.asdict(self.params),
            "before": dataclasses.asdict(self.before),
            "error_before_m": self.error_before,
            "error_after_m": self.error_after,
            "evaluations": self.evaluations,
            "fitted": list(self.fitted),
            "statistics": self.statistics,
        }


class _Budget(Exception):
    """The fit's evaluations are spent."""


class _Objective:
    """The logs re-simulated in windows with given parameters, each set of parameters once."""

    def __init__(self, world: World, runs: list[RunLog], tracks: list[Track], cfg: FitConfig):
        self.world, self.runs, self.tracks, self.cfg = world, runs, tracks, cfg
        self.cache: dict[tuple, list[Windows]] = {}
        self.evaluations = 0

    def windows(self, p: SimParams, *, budgeted: bool = True) -> list[Windows]:
        key = tuple(round(v, 9) for v in dataclasses.astuple(p))
        if key not in self.cache:
            if budgeted and self.evaluations >= self.cfg.max_evaluations:
                raise _Budget
            self.evaluations += 1
            self.cache[key] = [
                replay_windows(self.world, r, p, tr, self.cfg.horizon, lead=self.cfg.lead)
                for r, tr in zip(self.runs, self.tracks, strict=True)
            ]
        return self.cache[key]

    def stats(self, p: SimParams, *, budgeted: bool = True) -> dict[str, float]:
        ws = self.windows(p, budgeted=budgeted)
        sim = np.concatenate([w.sim for w in ws])
        robot = np.concatenate([w.robot for w in ws])
        if len(sim) == 0:
            raise RobotError(
                f"fit: the logs are too short for one {self.cfg.horizon:g} s window after "
                f"a {self.cfg.lead:g} s lead; drive longer runs"
            )
        moved = max(float(np.mean(robot[:, 0])), 1e-6)
        return {
            "error_m": float(np.mean([w.error() for w in ws])),
            "position_rms_m": float(np.sqrt(np.mean(np.sum((sim[:, :2] - robot[:, :2]) ** 2, 1)))),
            "turn_bias_rad": float(np.mean(sim[:, 2] - robot[:, 2])),
            "forward_bias": float(np.mean(sim[:, 0] - robot[:, 0])) / moved,
        }


def _minimise(f, lo: float, hi: float, points: int) -> float:
    """The x in [lo, hi] where f is least: the best of `points` spread over the range (in
    log space for a positive range), then Brent's method between its neighbours."""
    from scipy.optimize import minimize_scalar

    grid = np.geomspace(lo, hi, points) if lo > 0 else np.linspace(lo, hi, points)
    values = [f(float(x)) for x in grid]
    k = int(np.argmin(values))
    a, b = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, points - 1)])
    res = minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": 1e-3 * (hi - lo)})
    return float(res.x) if float(res.fun) <= values[k] else float(grid[k])


def _root(f, x0: float, lo: float, hi: float, step: float) -> float:
    """A zero of f (decreasing or increasing) near x0 within [lo, hi]: bracketed by steps
    outward from x0, then Brent's method; the end of the range nearest a zero when f keeps its
    sign."""
    from scipy.optimize import brentq

    a, fa = x0, f(x0)
    if fa == 0:
        return x0
    for direction in (1.0, -1.0):
        x, fx = a, fa
        while True:
            nxt = min(max(x + direction * step, lo), hi)
            if nxt == x:
                break
            fn = f(nxt)
            if (fn < 0) != (fx < 0):
                lo_, hi_ = sorted((x, nxt))
                root = brentq(f, lo_, hi_, xtol=1e-4 * (hi - lo), full_output=False)
                return float(root)  # pyright: ignore[reportArgumentType] - a float without full_output
            if abs(fn) >= abs(fx):  # going away from a zero: try the other way
                break
            x, fx = nxt, fn
    return a


def fit(
    logs: Sequence[RunLog | str | Path],
    world: World,
    *,
    cfg: FitConfig | None = None,
    out: str | Path | None = None,
) -> FitResult:
    """Fit the simulation's parameters to logged runs: each parameter on the statistic of the
    windowed re-simulations (replay_windows) it moves most and others least, the others held,
    in `cfg.rounds` passes:

    - friction: the position RMS of the windows (how far the robot slips and so moves: the
      least at the robot's friction, from a coarse search then Brent's method);
    - motor_mismatch: the mean turn per window, simulation minus robot (zero when the sides'
      speeds differ as the robot's do; the root by Brent's method);
    - motor_gain: the mean forward travel per window, simulation minus robot (zero at the
      robot's speed);
    - mass_scale: the windows' error (Windows.error).

    Whole-run trajectories are not matched: this simulation is chaotic over tens of seconds
    (replay_windows), and a least-squares fit of all parameters at once on the windows has a
    needle at the exact parameters of a twin and noise elsewhere (what docs/robot.md
    measured). Writes a robot file to `out` if given (scenes name it as
    `robot: {file: ...}`)."""
    cfg = cfg or FitConfig()
    runs = [_as_log(lg) for lg in logs]
    if not runs:
        raise RobotError("fit: give at least one run log")
    tracks = [logged_track(r, cfg.latency) for r in runs]
    objective = _Objective(world, runs, tracks, cfg)
    before = nominal_params(world)
    p = before
    error_before = objective.stats(before)["error_m"]

    def with_(name: str, value: float) -> SimParams:
        return dataclasses.replace(p, **{name: value})

    try:
        for _ in range(cfg.rounds):
            for name in PARAMETERS:  # (this order: friction first; it moves every statistic)
                if name not in cfg.parameters:
                    continue
                lo, hi = BOUNDS[name]
                if name == "friction":
                    x = _minimise(
                        lambda v: objective.stats(with_(name, v))["position_rms_m"],
                        lo,
                        hi,
                        cfg.starts,
                    )
                elif name == "motor_mismatch":
                    x = _root(
                        lambda v: objective.stats(with_(name, v))["turn_bias_rad"],
                        p.motor_mismatch,
                        lo,
                        hi,
                        0.03,
                    )
                elif name == "motor_gain":
                    x = _root(
                        lambda v: objective.stats(with_(name, v))["forward_bias"],
                        p.motor_gain,
                        lo,
                        hi,
                        0.05,
                    )
                else:
                    x = _minimise(
                        lambda v: objective.stats(with_(name, v))["error_m"], lo, hi, cfg.starts
                    )
                p = with_(name, x)
    except _Budget:
        pass
    stats = objective.stats(p, budgeted=False)  # (cached, or one more past the budget)
    result = FitResult(
        params=p,
        before=before,
        error_before=error_before,
        error_after=stats["error_m"],
        evaluations=objective.evaluations,
        fitted=tuple(n for n in PARAMETERS if n in cfg.parameters),
        statistics=stats,
    )
    if out is not None:
        from roachplan.scenes import write_robot_file

        fitted = {
            "logs": [str(r.path) for r in runs],
            "scene": world.scene.name,
            "parameters": list(result.fitted),
            "error_before_m": round(result.error_before, 6),
            "error_after_m": round(result.error_after, 6),
            "evaluations": result.evaluations,
            "latency_s": cfg.latency,
        }
        write_robot_file(Path(out), p.robot_file(fitted))
    return result
