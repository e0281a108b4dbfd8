"""How good was the prediction: re-simulate a logged run and compare (compare), and fit the
simulation's parameters to logged runs (fit).

A run is re-simulated two ways from the robot's logged start (its pose at Go): open-loop, the
same motor commands at the same times; and closed-loop, the same plan driven by the
simulation's own driver (what the prediction was). Errors are taken at the times of the
logged poses, shifted back by the pose latency when it is known (a pose received at t shows
the robot at t - latency).

The fit searches friction, motor gain and motor mismatch (and the body's mass if asked) to
minimise the short-horizon open-loop error over the logs (replay_windows): Nelder-Mead (scipy, bounded,
derivative-free: each evaluation is a PyBullet re-simulation, no gradient) from a seeded
initial simplex round the nominal parameters. The open-loop replay is the one whose error is
the model's alone: closed-loop, the driver corrects the model's errors as it goes.
compare also reports the short-horizon error (the fit's measure).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

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
    from roachplan.sim import Simulation

    robot = params.robot_file().robot()
    cfg = dataclasses.replace(world.scene.sim, friction=params.friction)
    return Simulation(
        world.mesh.vertices,
        world.mesh.faces,
        ground_height=world.scene.ground,
        robot=robot,
        cfg=cfg,
    )


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


def replay_windows(
    world: World, log: RunLog, params: SimParams, robot: Track, horizon: float = 1.0
) -> np.ndarray:
    """Open loop over short windows (multiple shooting): from the robot's logged pose at the
    start of each `horizon`-second window [s], the logged commands of that window in a
    simulation with params; (W, 2): the position error [m] and heading error [rad] at each
    window's end. A whole run replayed open loop drifts from the first small heading error on
    (the robot's own driver corrected it; the replay cannot), so a fit on it chases that
    drift; windows measure what the parameters do - how fast, how it turns - from the robot's
    own state each time."""
    t_go = log.t_go
    assert t_go is not None
    c = log.commands
    after = c["t"] >= t_go - 1e-9
    ct = c["t"][after] - t_go
    left = np.where(c["stop"][after], 0.0, c["left"][after])
    right = np.where(c["stop"][after], 0.0, c["right"][after])
    starts = np.arange(robot.t[0], robot.t[-1] - horizon, horizon)
    out = np.zeros((len(starts), 2))
    sim = _simulation(world, params)
    try:
        dt = sim.cfg.timestep
        for w, ts in enumerate(starts):
            (xy0,), (yaw0,) = robot.at(np.array([ts]))
            sim.reset(xy0[0], xy0[1], float(yaw0), surface=float(world.heightfield.sample(xy0)))
            k0 = int(np.searchsorted(ct, ts, side="right")) - 1
            sim.set_leg_speeds(float(left[max(k0, 0)]), float(right[max(k0, 0)]))
            k = k0 + 1
            while k < len(ct) and ct[k] < ts + horizon:
                n = round((ct[k] - ts - sim.time) / dt)
                if n > 0:
                    sim.advance(n)
                sim.set_leg_speeds(float(left[k]), float(right[k]))
                k += 1
            n = round((horizon - sim.time) / dt)
            if n > 0:
                sim.advance(n)
            pos, quat = sim.pose()
            (xy1,), (yaw1,) = robot.at(np.array([ts + horizon]))
            out[w, 0] = math.dist(pos[:2], xy1)
            out[w, 1] = abs(math.remainder(yaw_of(quat) - float(yaw1), 2 * math.pi))
    finally:
        sim.close()
    return out


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
    """The logged commands replayed."""
    closed_loop: Errors
    """The plan driven by the simulation's driver (the prediction)."""
    windows: np.ndarray
    """(W, 2) short-horizon open-loop errors (replay_windows): position [m], heading [rad]."""
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
            "windows": {
                "position_rms_m": float(np.sqrt(np.mean(self.windows[:, 0] ** 2))),
                "heading_rms_rad": float(np.sqrt(np.mean(self.windows[:, 1] ** 2))),
            },
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
) -> Comparison:
    """Re-simulate a logged run on world (its scene) with params (default: the world's own)
    open- and closed-loop from the logged start, and measure position and heading error over
    time, the end error and whether the outcome agreed. latency: the pose stream's [s]."""
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
        windows=replay_windows(world, log, params, robot),
        robot_outcome=(log.result or {}).get("reason", "unknown"),
        sim_outcome=outcome,
    )


@dataclass(frozen=True, kw_only=True)
class FitResult:
    """What fit found."""

    params: SimParams
    before: SimParams
    error_before: float
    """Mean over the logs of the short-horizon open-loop error (replay_windows: position, and
    heading as 0.5 m per radian, RMS over the windows) with `before` [m]."""
    error_after: float
    """The same with `params` [m]."""
    evaluations: int
    fitted: tuple[str, ...]

    def to_json(self) -> dict:
        return {
            "params": dataclasses.asdict(self.params),
            "before": dataclasses.asdict(self.before),
            "error_before_m": self.error_before,
            "error_after_m": self.error_after,
            "evaluations": self.evaluations,
            "fitted": list(self.fitted),
        }


BOUNDS = {
    "friction": (0.2, 2.0),
    "motor_gain": (0.5, 1.5),
    "motor_mismatch": (-0.2, 0.2),
    "mass_scale": (0.5, 2.0),
}
"""Where the fit searches each parameter."""
STEPS = {"friction": 0.25, "motor_gain": 0.1, "motor_mismatch": 0.04, "mass_scale": 0.3}
"""The initial simplex's size in each parameter."""


def fit(
    logs: Sequence[RunLog | str | Path],
    world: World,
    *,
    parameters: Sequence[str] = ("friction", "motor_gain", "motor_mismatch"),
    seed: int = 0,
    max_evaluations: int = 80,
    latency: float = 0.0,
    horizon: float = 1.0,
    out: str | Path | None = None,
) -> FitResult:
    """Fit the simulation's parameters to the logged runs (the module docstring); write them
    as a robot file to `out` if given (scenes name it as `robot: {file: ...}`)."""
    from scipy.optimize import minimize

    unknown = [p for p in parameters if p not in PARAMETERS]
    if unknown or not parameters:
        raise RobotError(f"fit: parameters {list(parameters)}: choose from {', '.join(PARAMETERS)}")
    runs = [_as_log(lg) for lg in logs]
    if not runs:
        raise RobotError("fit: give at least one run log")
    tracks = [logged_track(r, latency) for r in runs]
    before = nominal_params(world)
    names = tuple(parameters)
    evaluations = 0

    def params_of(x: np.ndarray) -> SimParams:
        return dataclasses.replace(before, **{n: float(v) for n, v in zip(names, x, strict=True)})

    def cost(x: np.ndarray) -> float:
        nonlocal evaluations
        evaluations += 1
        p = params_of(x)
        errs = []
        for r, tr in zip(runs, tracks, strict=True):
            w = replay_windows(world, r, p, tr, horizon)
            # heading error weighted as the offset it makes 0.5 m on (1 rad ~ 0.5 m)
            errs.append(float(np.sqrt(np.mean(w[:, 0] ** 2 + (0.5 * w[:, 1]) ** 2))))
        return float(np.mean(errs))

    x0 = np.array([getattr(before, n) for n in names])
    rng = np.random.default_rng(seed)
    steps = np.array([STEPS[n] for n in names])
    # A seeded simplex: the nominal point and one vertex per parameter, each a step along its
    # own axis with a random sign and a little of the others (so no two fits share a path).
    simplex = [x0]
    for i in range(len(names)):
        v = x0 + steps * rng.uniform(-0.2, 0.2, len(names))
        v[i] = x0[i] + steps[i] * rng.choice([-1.0, 1.0])
        simplex.append(v)
    bounds = [BOUNDS[n] for n in names]
    simplex = np.array(
        [np.clip(v, [b[0] for b in bounds], [b[1] for b in bounds]) for v in simplex]
    )
    error_before = cost(x0)
    res = minimize(
        cost,
        x0,
        method="Nelder-Mead",
        bounds=bounds,
        options={
            "initial_simplex": simplex,
            "maxfev": max_evaluations,
            "xatol": 1e-3,
            "fatol": 1e-4,
        },
    )
    best = params_of(np.asarray(res.x))
    error_after = float(res.fun)
    if error_after > error_before:  # never worse than where it started
        best, error_after = before, error_before
    result = FitResult(
        params=best,
        before=before,
        error_before=error_before,
        error_after=error_after,
        evaluations=evaluations,
        fitted=names,
    )
    if out is not None:
        from roachplan.scenes import write_robot_file

        fitted = {
            "logs": [str(r.path) for r in runs],
            "scene": world.scene.name,
            "parameters": list(names),
            "error_before_m": round(error_before, 6),
            "error_after_m": round(error_after, 6),
            "evaluations": evaluations,
            "seed": seed,
        }
        write_robot_file(Path(out), best.robot_file(fitted))
    return result
