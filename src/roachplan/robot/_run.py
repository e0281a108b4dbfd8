"""What `roachplan robot` does without a page: plan (or take a plan), Go, drive to the goal,
stop, and record it all (drive_robot); and the simulation's prediction of the same plan from
the robot's actual start (predict)."""

from __future__ import annotations

import collections
import dataclasses
import itertools
import logging
import math
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._config import RobotSettings
from ._edges import EDGE_OFF, EDGE_ROOM, at_edge, edge_margin, stands_on, step_in
from ._errors import RobotError
from ._estimate import pooled_mismatch
from ._links import CommandLink, open_link
from ._lookahead import LookAhead, LookAheadConfig, LookAheadRunner, remaining_path
from ._loop import LoopEvent, RobotLoop, RunResult
from ._pose import PoseSample, PoseSource, open_pose_source
from ._record import RunRecorder, scene_record
from ._safety import SafetyMap, distance_to_path, nearest_on_path
from ._transform import FrameTransform, measure_transform, yaw_of

if TYPE_CHECKING:
    from roachplan.planning import PlanResult
    from roachplan.scenes import World

_log = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True, eq=False)
class RobotRun:
    """What drive_robot did."""

    result: RunResult
    transform: FrameTransform
    path_xyz: np.ndarray
    spins: tuple[tuple[int, float], ...]
    log: Path | None
    prediction: dict | None
    lookaheads: tuple[LookAhead, ...] = ()
    """The look-aheads made while it drove (RobotSettings.look_ahead), in order."""
    plan_seed: int | None = None
    """The seed of the plan it drove (None: a plan given)."""
    clearance: float | None = None
    """How far its path kept from the points it was to avoid [m] (None: none given)."""
    turning_radius: float | None = None
    """The radius of the arcs its plan was made with [m] (None: a plan given, or the planner
    makes no arcs)."""
    estimates: tuple[tuple[float, float], ...] = ()
    """(mismatch, walked [m]) of each window the look-ahead estimated the motors' mismatch
    from, this leg's and the legs' before it (pooled_mismatch; a re-planned leg goes on
    from them)."""
    trim: float = 0.0
    """The mismatch the loop divided out of its commands at the end (RobotLoop.trim)."""


def wait_first_pose(source: PoseSource, timeout: float) -> PoseSample:
    deadline = time.monotonic() + timeout
    while (sample := source.latest()) is None:
        if time.monotonic() > deadline:
            raise RobotError(
                f"no pose of the robot within {timeout:g} s: is it tracked (Motive: the rigid "
                f"body visible and streamed), and are the source's settings right?"
            )
        time.sleep(0.01)
    return sample


AVOID_RADIUS = 0.05
"""How far a re-plan keeps its path from where the look-ahead's rollouts failed [m]: the
body's half length, about the spread of its feet."""
AVOID_TRIES = 4
"""Plans (seeds) a plan from the robot tries: for one that keeps clear of the points to avoid, or
for one at all."""
EDGE_TRIES = 12
"""...and for one that keeps RobotSettings.edge_keep from the drop-offs besides (a plan takes
0.1-0.2 s on the double bridge, and 3 of its first 12 seeds keep 4 cm at every waypoint)."""


def plan_keeps(clear: float, margin: float, radius: float, keep: float | None) -> float:
    """How well a plan keeps clear [-]: the smaller of its clearance of the points to avoid
    over `radius` and its edge_margin over `keep` (None: drop-offs not kept from), at most 1:
    1 keeps clear of both, the plan from the robot's rule takes the first that does, else the
    one highest on this."""
    edge = 1.0 if keep is None or keep <= 0 else margin / keep
    return min(clear / radius, edge, 1.0)


def clearance(path_xy, avoid: Sequence[tuple[float, float]], radius: float = AVOID_RADIUS) -> float:
    """How far a path ((N, 2) [m]) keeps from the points of avoid ((x, y) [m]) that lie
    `radius` [m] or more from its start (no path from there can keep clear of nearer ones):
    the least distance [m]; inf with none."""
    xy = np.asarray(path_xy, dtype=float)[:, :2]
    points = [p for p in avoid if math.dist(p[:2], xy[0]) >= radius]
    return min((distance_to_path(p, xy) for p in points), default=math.inf)


START_REACH = 0.05
"""How far a plan's start may lie from where the robot stands [m] when the planner refuses that
pose: a robot the guard held with a foot over a bridge's edge ("a foot has no ground under
it") is re-planned from the nearest pose the planner takes within this (its body's half
length), and the driver walks it the rest."""
_START_TURNS = np.radians([0.0, 10.0, -10.0, 20.0, -20.0])
"""Headings a moved start may turn by, in the order tried at each distance [rad]."""


def plan_start(
    world: World, here: tuple[float, float, float], reach: float = START_REACH
) -> tuple[tuple[float, float, float], float]:
    """(the pose nearest `here` (x, y [m], yaw [rad], world frame) that the planner takes as a
    start, how far it lies from here [m]): here itself when the planner takes it; else the
    first valid pose of rings every 5 mm out to `reach` (24 directions each), the heading
    kept or turned by up to 20 deg, the nearest ring first and the least turn, on the surface
    the robot stands on (its support plane within the planner's body_band of the ground under
    the robot: not the floor below a bridge it is on). RobotError, saying what is wrong where
    the robot stands, when none within reach is valid."""
    from roachplan.planning import check_states, describe_state

    hf, fp, validity = world.heightfield, world.footprint, world.scene.planner.validity
    (xa, ya), (xb, yb) = world.bounds
    x, y, yaw = here
    inside = xa <= x <= xb and ya <= y <= yb
    if inside and check_states(hf, fp, validity, np.array([here], dtype=float)).valid[0]:
        return here, 0.0
    ground = float(hf.sample(np.array([x, y]))) if inside else math.nan
    # Every candidate in the order tried (ring, then turn, then direction), checked at once.
    r, turn, angle = (
        a.ravel()
        for a in np.meshgrid(
            np.arange(0.005, reach + 1e-9, 0.005),
            _START_TURNS,
            np.linspace(0.0, 2 * math.pi, 24, endpoint=False),
            indexing="ij",
        )
    )
    poses = np.column_stack([x + r * np.cos(angle), y + r * np.sin(angle), yaw + turn])
    ok = stands_on(world, poses, ground)  # (the same surface: not a floor 5 cm below the edge)
    if ok.any():
        first = int(np.argmax(ok))
        px, py, pyaw = poses[first].tolist()
        return (px, py, pyaw), float(r[first])
    why = describe_state(hf, fp, validity, np.array(here)) if inside else "outside the area"
    raise RobotError(
        f"no plan from where the robot stands ({x:.3f}, {y:.3f}, {math.degrees(yaw):.0f} deg): "
        f"the planner refuses it ({why}), and every pose within {reach * 100:g} cm as well"
    )


def plan_clear_of(
    world: World,
    start: tuple[float, float, float],
    seed: int,
    avoid: Sequence[tuple[float, float]] = (),
    *,
    radius: float = AVOID_RADIUS,
    tries: int | None = None,
    deadline: float | None = None,
    keep: float | None = None,
) -> tuple[PlanResult, float]:
    """A plan from start (x, y [m], yaw [rad], world frame) to the scene's goal that keeps
    `radius` from every point of avoid ((x, y) [m]: where a look-ahead's rollouts failed),
    and its clearance (the least distance of its path to those points [m]; inf with none):
    the plans of seeds seed, seed + 1, ... up to `tries`, the first that keeps clear, else
    the one that keeps clearest (of those found). Points within radius of start are not
    avoided (no path from there can be). No points to avoid: the first of those seeds whose
    planner finds a path (from a pose at a bridge's edge, the sampling planner's iteration
    budget ran out once for a seed whose path the next seed would have found). deadline: a
    time.monotonic() [s] by which every try has ended (each gets what is left, at most the
    planner's time_limit; none starts with under MIN_TRY left; the first always does): a
    robot held for a re-plan that finds nothing waits that long, not tries x time_limit.
    keep [m]: the plan keeps clear of the drop-offs too, its edge_margin at least this (None:
    not asked; tries then default to EDGE_TRIES, else AVOID_TRIES), the clearest by
    plan_keeps where none does."""
    from roachplan.experiments import plan as plan_trial

    points = [p for p in avoid if math.dist(p[:2], start[:2]) >= radius]
    if tries is None:
        tries = AVOID_TRIES if keep is None else EDGE_TRIES
    best: tuple[PlanResult, float] | None = None
    score = -math.inf  # (best's plan_keeps)
    cfg = world.scene.planner
    for k in range(tries):
        left = math.inf if deadline is None else deadline - time.monotonic()
        if best is not None and left < MIN_TRY:
            break
        limit = max(min(cfg.time_limit, left), MIN_TRY)
        planner = cfg if limit >= cfg.time_limit else dataclasses.replace(cfg, time_limit=limit)
        planned = plan_trial(world, seed=seed + k, start=start, planner=planner)
        if not planned.found:
            best = best or (planned, math.inf)
            continue
        clear = clearance(planned.path_xyz, points, radius)
        margin = math.inf if keep is None else edge_margin(world, planned.path_xyz, keep)
        keeps = plan_keeps(clear, margin, radius, keep)
        if best is None or not best[0].found or keeps > score:
            best, score = (planned, clear), keeps
        if keeps >= 1.0:
            break
    assert best is not None  # (tries >= 1)
    return best


MIN_TRY = 0.5
"""plan_clear_of starts no try after its first with under this much of its time left [s]:
setting up a plan takes a good part of it."""


REJOIN_MIN = 0.10
"""rejoin_path meets the old path at least this far along it past the point nearest the robot
[m] (about a body length and a half)."""


def rejoin_path(
    path_xyz, spins, here_xy, *, ahead: float = REJOIN_MIN
) -> tuple[np.ndarray, tuple[tuple[int, float], ...]]:
    """The rest of a plan (path_xyz (N, 3) world frame [m], spins (waypoint index, heading
    [rad]) each) for a robot standing off it at here_xy [m]: a turn on the spot to face the
    old path where it meets it, a straight line there, then the old path's waypoints on
    (remaining_path), spins re-indexed. It meets the old path at the first waypoint `ahead`
    [m] or twice the robot's distance from it (whichever is more) past its nearest point; at a
    spin instead where one comes first, so no turn on the spot is skipped; at the old path's
    end where that comes first. The new path is (M, 3), M >= 2: its first rows here_xy at the
    height of the old path's nearest point (twice, the spin's, unless the meeting point is
    under a centimetre away). A robot the guard held for drifting, whose re-plan found no
    path, drives on along it: the path starts where the robot stands, and the robot turns
    before it walks (it was held heading off its path: walking on while it turned, a rejoin
    drifted off again within 0.5 s), so the drift hold does not fire again at once."""
    rest, kept = remaining_path(path_xyz, spins, here_xy)
    here = np.array([float(here_xy[0]), float(here_xy[1]), float(rest[0, 2])])
    off = float(np.linalg.norm(rest[0, :2] - here[:2]))
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(rest[:, :2], axis=0), axis=1))])
    join = int(np.searchsorted(along, max(ahead, 2.0 * off)))
    join = min([join, len(rest) - 1, *(i for i, _ in kept)])
    join = max(join, 1) if len(rest) > 1 else 0
    return lead_in(rest[join:], tuple((i - join, h) for i, h in kept if i >= join), here)


LEAD_MIN = 0.01
"""lead_in turns the robot on the spot to face a path's first waypoint only that far from it or
further [m] (nearer, there is no line to face)."""


def lead_in(path_xyz, spins, here_xyz) -> tuple[np.ndarray, tuple[tuple[int, float], ...]]:
    """A path ((N, 3) world frame [m]) and its spins ((waypoint index, heading [rad]) each)
    driven from here_xyz [m] instead of its start: a turn on the spot at here to face its first
    waypoint, a straight line there, then the path, spins re-indexed ((M, 3): here twice, a
    spin's next waypoint repeating its place; once, with no turn, where the first waypoint is
    under LEAD_MIN away). rejoin_path's way back to an old path, and a re-plan's walk away from
    an edge (step_in) to where the plan starts."""
    path = np.asarray(path_xyz, dtype=float)
    here = np.asarray(here_xyz, dtype=float)[:3]
    dx, dy = path[0, :2] - here[:2]
    # (the tolerance: step_in's nearest ring lies LEAD_MIN away, give or take a rounding)
    turn = ((0, math.atan2(dy, dx)),) if math.hypot(dx, dy) >= LEAD_MIN - 1e-9 else ()
    lead = 1 + len(turn)  # (here once, or twice: a spin's next waypoint repeats its place)
    return np.vstack([here] * lead + [path]), (*turn, *((i + lead, h) for i, h in spins))


def rejoin_plan(
    path_xyz, spins, here_xy, *, seed: int = 0, turning_radius: float | None = None
) -> PlanResult:
    """rejoin_path's path and spins from here_xy [m] as a plan to drive (the planner "rejoin"):
    what a robot the guard held for drifting drives on along when no re-plan is found, on the
    command line and in the page alike. seed and turning_radius [m]: the old plan's; each
    state's heading faces the next waypoint (a spin's next waypoint: the spin's heading)."""
    from roachplan.planning import PlanResult

    path, kept = rejoin_path(path_xyz, spins, here_xy)
    step = np.diff(path[:, :2], axis=0)
    yaw = np.append(np.arctan2(step[:, 1], step[:, 0]), 0.0)  # (toward the next waypoint)
    yaw[-1] = yaw[-2]
    for k, heading in kept:  # (a spin's next waypoint repeats its place, turned)
        yaw[k + 1] = heading
    return PlanResult(
        found=True,
        planner="rejoin",
        seed=seed,
        states=np.column_stack([path[:, :2], yaw]),
        path_xyz=path,
        plan_time=0.0,
        message="the rest of the path the robot drifted off, from where it stands",
        turning_radius=turning_radius,
        spins=kept,
    )


def stepped_plan(world: World, plan: PlanResult, stands) -> PlanResult:
    """A plan found from step_in's pose, driven from where the robot stands (stands: x, y [m],
    yaw [rad], world frame; the path's first waypoint on the terrain's surface there):
    lead_in's turn on the spot and straight line to the plan's start first. Its first state
    is the robot's pose; with a turn, the second faces the plan's start."""
    x, y, yaw = (float(v) for v in stands)
    ground = float(world.heightfield.sample(np.array([x, y])))
    path, spins = lead_in(plan.path_xyz, plan.spins, (x, y, ground))
    lead = len(path) - len(plan.path_xyz)
    head = [[x, y, yaw]] + ([[x, y, spins[0][1]]] if lead == 2 else [])
    return dataclasses.replace(
        plan,
        states=np.vstack([head, plan.states]),
        path_xyz=path,
        spins=spins,
        message=f"{plan.message} (first {math.dist(path[0, :2], path[lead, :2]):.2f} m in "
        "from the edge it stood at)",
    )


RETURN_SLACK = 0.01
"""After a spin that left the robot further off its path than the guard's drift limit, the
guard holds it once it is this much further off than the nearest it has come back to [m]
(watch_ahead: the motion capture's noise, 2 mm, and the gait's sway sideways)."""
GUARD_HOLDS = ("lookahead", "drift", "stall")
"""How a run ends when the guard held the robot (a look-ahead's chance, a drift, no progress):
the command re-plans from where it stands."""
MAX_WIDENING = 2.0
"""replan_radius widens a plan's arcs at most this many times [-]: a robot that drifted off arcs
that wide too is re-planned along lines and turns on the spot (SPIN_ONLY_RADIUS)."""
SPIN_ONLY_RADIUS = 100.0
"""The radius of a re-plan's arcs after the widening [m]: wider than any scene's area, so the
drivable planner fits no arc and turns the robot on the spot at every corner (its spin_margin;
where the scene allows no spin, no such plan is found and the scene's own arcs are planned).
A twin on a slippery floor (friction 0.6) whose one motor ran 12 % slow turned the other way
when driven at the largest motor ratio towards its slow side: after two drift holds it was
held again on arcs 4 times the scene's, leg after leg (bench_guard, the mismatch -0.12)."""


def drift_allowance(
    allowed: float, off: float, *, spinning: bool, limit: float, spin_limit: float
) -> float:
    """How far off its path [m] the guard lets the robot be at a pose `off` [m] from it, given
    what it allowed at the pose before (`allowed` [m]; `limit` at a leg's first): the guard's
    drift limit [m]; while the robot turns on the spot at a spin (`spinning`), as far as it
    has wandered plus RETURN_SLACK, up to `spin_limit` [m] (watch_ahead: halfway to the loop's
    stop); after the spin, RETURN_SLACK further than the nearest it has come back to since,
    never under `limit`. The guard holds the robot where off is more than that, or, with a
    lead, than drift_hold_at's distance (past this allowance, in a spin too).

    A spin wanders from its point: up to 7.4 cm in a 55 deg spin of bench_guard's mirrored
    twin on its slippery rough bridge, 15 cm in 110 deg (to the loop's stop), where the same
    spins on a flat floor moved under 2 cm. Pure pursuit takes a few cm back once the spin is
    made; held for them at `limit`, 7 of 53 legs there ended in a spin and used up the run's
    re-plans."""
    if spinning:
        return max(allowed, min(off + RETURN_SLACK, spin_limit))
    return max(limit, min(allowed, off + RETURN_SLACK))


DRIFT_MARGIN = 0.01
"""About how much further a robot the guard holds for drifting drifts on after the hold, at
any rate [m] (drift_hold_at: bench_guard's drift holds, 193 on three twins, took it a median
0.7 cm and a 90th percentile 1.3 cm further off its path; the lead covers what grows with the
rate)."""
RATE_WINDOW = 0.5
"""drift_rate's poses: those of the last this many seconds [s] (long enough to average the
motion capture's noise and the gait's sway, short enough to follow a drift that sets in; the
stop distances drift_hold_at's lead comes from were read at this window)."""


def drift_rate(times, offs) -> float:
    """How fast the robot is drifting off its path [m/s]: the least-squares slope of its
    distances off it, `offs` [m], over `times` [s] (a few poses': RATE_WINDOW); 0 with under 3
    poses or no time between them."""
    t, d = np.asarray(times, dtype=float), np.asarray(offs, dtype=float)
    if len(t) < 3:
        return 0.0
    t = t - t.mean()
    spread = float(np.dot(t, t))
    return float(np.dot(t, d - d.mean()) / spread) if spread > 0 else 0.0


def drift_hold_at(allowed: float, rate: float, *, lead: float | None, stop: float) -> float:
    """How far off its path [m] the guard lets a robot drifting at `rate` [m/s] (off it: > 0)
    be, given the drift limit it allows (`allowed` [m]: drift_allowance's): where the drift,
    going on `lead` seconds more at that rate, plus DRIFT_MARGIN, would reach the loop's stop
    (`stop` [m]: max_deviation), but never nearer than `allowed`; lead None: `allowed`.

    A drift hold ends the leg; many robots come back on their own. On bench_guard's twin with
    friction 0.58 and mismatch -0.08, 18 of 20 unguarded runs went past a fixed hold's 7.5 cm
    and 15 of them reached the goal, the furthest 14.4 cm off; those of the first ten were each
    still drifting away at 7.5 cm (0.9-6.9 cm/s), so only how soon a robot would reach the stop
    tells them apart.
    A robot held drifts on for a while (the stop frames' way to its motors, the gait's step
    under way): a median 0.13 s, a 90th percentile 0.34 s of its drift rate over the last
    half second, on 193 drift holds of three twins. Held by a lead of 0.4 s, that twin's
    unguarded runs would have been held in 4 of the 15 that came back; with the main twin's
    and a harsher one's, in 7 of 21 that came back and in all 18 that reached the stop, each
    0.27 s or more before it and 10.7-13.2 cm off."""
    if lead is None:
        return allowed
    return max(allowed, stop - DRIFT_MARGIN - lead * max(rate, 0.0))


def replan_radius(radius: float, drifts: int, *, stalled: bool = False) -> float:
    """The radius of a re-plan's arcs [m]: the scene's `radius` [m] doubled for each time the
    guard held the robot for drifting off its path so far (`drifts`), up to MAX_WIDENING
    times; past that, or after the guard held it for making no progress (`stalled`: "stall"),
    SPIN_ONLY_RADIUS (lines and turns on the spot). A robot that drifted off arcs of one radius
    is asked for wider ones, and the drivable planner turns it on the spot where they do not
    fit. A robot that walked in place at a ramp's foot, its driver asking for a hard turn
    towards its slow motor, is asked for none: in PyBullet with that twin's hidden parameters,
    the arc of its plan there stuck 4 times in 6, a turn on the spot to the same heading and a
    line to the same point 1 time in 6. (An estimate of how tightly
    the robot turns, from its heading against its commands in hard turns, read 0.0-0.3 of the
    turning curve on legs that reached the goal as well as on legs that drifted: the tracking
    driver's hard turns are mostly short corrections, which say little of the tightest turn.)"""
    wider = 2.0**drifts
    return radius * wider if wider <= MAX_WIDENING and not stalled else SPIN_ONLY_RADIUS


def start_height(world: World, xy) -> float:
    """Height of the robot's body centre standing at xy [m] (the planner's surface there plus
    the robot's standing height) [m]."""
    return float(world.heightfield.sample(np.asarray(xy[:2]))) + world.robot.standing_height


def predict(world: World, path_xyz: np.ndarray, spins, start: tuple[float, float, float]) -> dict:
    """The simulation of the plan from start (x, y [m], yaw [rad]) with the world's own
    parameters: outcome, reason, drive_time [s], trajectory [[t, x, y, z, yaw]...]."""
    from roachplan.experiments import drive

    frames: list[list[float]] = []

    def on_frame(f) -> None:
        frames.append([f.t, *f.p_world_body, yaw_of(f.quat_world_body)])

    driven = drive(world, path_xyz, start=start, on_frame=on_frame, spins=spins)
    return {
        "start": list(start),
        "outcome": driven.outcome,
        "reason": driven.reason,
        "drive_time": driven.drive_time,
        "trajectory": frames,
    }


def drive_robot(  # noqa: PLR0912, PLR0915 - the run's steps in order; to split
    world: World,
    settings: RobotSettings,
    *,
    plan: PlanResult | None = None,
    source: PoseSource | None = None,
    link: CommandLink | None = None,
    listeners: Sequence[Callable[[LoopEvent], None]] = (),
    on_loop: Callable[[RobotLoop], None] | None = None,
    ready: Callable[[RobotLoop], bool] | None = None,
    avoid: Sequence[tuple[float, float]] = (),
    turning_radius: float | None = None,
    estimates: Sequence[tuple[float, float]] = (),
) -> RobotRun:
    """Plan from where the robot stands (or take `plan`), Go, drive until the goal or a stop,
    and record it. source/link: already open ones (default: opened from the settings and
    closed at the end). on_loop(loop) is called once the loop runs (a caller's Stop button).
    ready(loop): the user's Go - called once the loop runs (sending stop frames: nothing
    moves) with the plan made (loop.path), it returns True to drive, False not to (the run
    then ends as "cancel"); None: go at once. Ctrl-C and SIGTERM stop the robot, while it
    waits for Go too (when called from the main thread). avoid: points (x, y) [m] the plan
    keeps clear of (plan_clear_of: where a look-ahead's rollouts failed, re-planning after the
    guard held the robot). turning_radius: the radius of the plan's arcs [m] (replan_radius: a
    re-plan's, widened after the robot drifted off its path); None: the scene's. estimates: the
    motors' mismatch estimated on the legs before (RobotRun.estimates): with the look-ahead and
    settings.trim, the loop starts with their pool divided out of its commands."""
    own_source = source is None
    own_link = link is None
    source = source or open_pose_source(settings.source, **settings.source_settings)
    recorder: RunRecorder | None = None
    watcher: LookAheadRunner | None = None
    try:
        link = link or open_link(settings.link, **settings.link_settings)
        scene = world.scene
        assert scene.start is not None and scene.goal is not None  # build_world sets them
        sample = wait_first_pose(source, settings.first_pose_timeout)
        transform = settings.transform or measure_transform(
            sample.position, sample.quat, scene.start, start_height(world, scene.start)
        )
        p, q = transform.apply(sample.position, sample.quat)
        stands = (p[0], p[1], yaw_of(q))  # (where the robot stands: world frame)
        here = stands  # (the plan's start: where it stands, or the nearest pose planned from)
        kept = None  # (how far the path keeps from avoid's points [m]; None: none to keep from)
        radius = None if plan is None else plan.turning_radius  # (its arcs' [m]; None: none)
        moved = 0.0  # (how far the plan's start lies from where the robot stands [m])
        inner = None  # (where it steps in to from an edge before the plan: step_in; None: no)
        measured = None if plan is None else plan.path_xyz  # (the path edge_margin measures)
        keep = settings.edge_keep  # (how far its path keeps from the drop-offs [m]; None: any)
        if plan is None:
            seed = scene.seed if settings.seed is None else settings.seed
            here, moved = plan_start(world, stands)
            # (within edge_keep of an edge: planned from where it steps in to, walked there)
            if keep is not None:
                inner = step_in(world, here, keep)
            if moved > 0:
                _log.warning(
                    "the planner refuses the robot's pose as a start: planning from "
                    "(%.3f, %.3f), %.1f cm from it",
                    here[0],
                    here[1],
                    moved * 100,
                )
            planner = scene.planner
            if turning_radius is not None and planner.turning_radius is not None:
                planner = dataclasses.replace(planner, turning_radius=turning_radius)
            # (every try of this leg's plan within the planner's budget: a held robot waits
            # for a re-plan that finds nothing that long, not 8 tries of it)
            deadline = time.monotonic() + scene.planner.time_limit
            # (from the step's pose, else, none found from it, from here: the wider arcs
            # first, then the scene's)
            tried: tuple[PlanResult, float] | None = None
            start, chosen = here, scene.planner
            starts = (inner, here) if inner is not None else (here,)
            for start, chosen in itertools.product(starts, dict.fromkeys((planner, scene.planner))):
                tried = plan_clear_of(
                    world.with_planner(chosen), start, seed, avoid, deadline=deadline, keep=keep
                )
                if tried[0].found:
                    break
            assert tried is not None  # (one try at least)
            plan, clear = tried
            planner = chosen
            inner = inner if plan.found and start == inner else None
            measured = plan.path_xyz  # (edge_margin's: the plan as chosen, before the step)
            if inner is not None:
                assert keep is not None  # (step_in ran)
                plan = stepped_plan(world, plan, stands)
                _log.warning(
                    "the robot stands within %.0f cm of an edge: it turns on the spot and "
                    "walks %.1f cm in a line to (%.3f, %.3f) first, and the plan starts there",
                    keep * 100,
                    math.dist(stands[:2], inner[:2]) * 100,
                    inner[0],
                    inner[1],
                )
            radius = planner.turning_radius
            kept = None if math.isinf(clear) else clear
            if not plan.found:
                raise RobotError(
                    f"no plan from where the robot stands ({stands[0]:.3f}, {stands[1]:.3f}, "
                    f"{math.degrees(stands[2]):.0f} deg): {plan.message}"
                )
        path, spins = np.asarray(plan.path_xyz, dtype=float), tuple(plan.spins)
        margin = None if keep is None else edge_margin(world, measured, keep)
        if settings.log is not None:
            recorder = RunRecorder(settings.log)
            t = time.monotonic()
            recorder.write("/scene", t, scene_record(_scene_file(scene), scene.name))
            recorder.write("/settings", t, _settings_record(world, settings, transform))
            recorder.write(
                "/plan",
                t,
                {
                    "path": path.tolist(),
                    "spins": [list(s) for s in spins],
                    "planner": plan.planner,
                    "seed": plan.seed,
                    "start": list(here),
                    # (how far that start lies from where the robot stood [m]: plan_start)
                    "start_moved": moved,
                    # (the pose (x, y [m], heading [rad]) it walked to from an edge it stood
                    # at, turning on the spot and in a line, before the plan: step_in; null:
                    # none)
                    "step_in": None if inner is None else list(inner),
                    "robot_pose": list(stands),
                    "goal": list(scene.goal),
                    # (a re-plan's: where the look-ahead's rollouts failed, and how far its
                    # path keeps from them [m]; null: none to keep clear of)
                    "avoid": [list(p[:2]) for p in avoid],
                    "clearance": kept,
                    # (the radius its arcs were planned with [m]: a re-plan's may be wider than
                    # the scene's, after drift holds; null: a plan given, or no arcs)
                    "turning_radius": radius,
                    # (how far it keeps from the drop-offs, up to edge_keep [m]: edge_margin;
                    # null: not asked)
                    "edge_margin": margin,
                    "edge_keep": keep,
                },
            )
        loop = RobotLoop(
            path_xyz=path,
            spins=spins,
            source=source,
            link=link,
            transform=transform,
            safety_map=SafetyMap.from_world(world),
            driver=scene.driver,
            max_motor_speed=world.robot.max_motor_speed,
            cfg=settings.loop,
            recorder=recorder,
            listeners=listeners,
        )
        if settings.look_ahead is not None or settings.guard is not None:
            watcher = watch_ahead(
                world,
                path,
                spins,
                loop,
                cfg=settings.look_ahead or LookAheadConfig(),
                guard=settings.guard,
                drift=settings.guard_drift,
                lead=settings.guard_drift_lead,
                stuck=settings.guard_stuck,
                trim=settings.trim,
                estimates=tuple(estimates),
                period=settings.look_ahead_period,
                seed=scene.seed if settings.seed is None else settings.seed,
                safety=settings.loop.safety,
                recorder=recorder,
            )
        restore = _stop_on_signals(loop)
        try:
            loop.start()
            if on_loop is not None:
                on_loop(loop)
            if ready is None or ready(loop):
                loop.go()
                if watcher is not None:  # (looks ahead of a robot that drives)
                    watcher.start()
            else:
                loop.stop("cancel", "not started: Go was not given")
            while (result := loop.wait(0.1)) is None:
                pass
        finally:
            restore()
            if watcher is not None:
                watcher.close()
        prediction = None
        if settings.predict and result.start is not None:
            prediction = predict(world, path, spins, result.start)
        if recorder is not None:
            t = time.monotonic()
            if prediction is not None:
                recorder.write("/prediction", t, prediction)
            recorder.write("/result", t, result.to_json())
            log = recorder.close()
            recorder = None
        else:
            log = None
        return RobotRun(
            result=result,
            transform=transform,
            path_xyz=path,
            spins=spins,
            log=log,
            prediction=prediction,
            lookaheads=tuple(watcher.results) if watcher is not None else (),
            plan_seed=plan.seed,
            clearance=kept,
            turning_radius=radius,
            estimates=watcher.estimates if watcher is not None else tuple(estimates),
            trim=loop.trim,
        )
    finally:
        if recorder is not None:
            recorder.abandon()
        if own_link and link is not None:
            link.close()
        if own_source:
            source.close()


def watch_ahead(
    world: World,
    path,
    spins,
    loop: RobotLoop,
    *,
    cfg: LookAheadConfig,
    guard: float | None,
    period: float,
    seed: int,
    safety,
    recorder: RunRecorder | None,
    also: Callable[[float, LookAhead], None] | None = None,
    drift: float | None = None,
    lead: float | None = None,
    stuck: float | None = None,
    trim: bool = False,
    estimates: tuple[tuple[float, float], ...] = (),
) -> LookAheadRunner:
    """A LookAheadRunner beside `loop` (its listener added; the caller starts it at Go and
    closes it), each result recorded on /lookahead (recorder: None, none) and given to also(t,
    result); under `guard` [0, 1] (None: none), the robot held: the loop stopped as
    "lookahead", the chance and the rollouts' ends in its detail; and, with the guard, once the
    robot drives further than `drift` times safety.max_deviation from the path (None: never;
    RobotSettings.guard_drift), or, EDGE_OFF off it, its footprint EDGE_ROOM further from the
    path would not stand (at_edge: the edge of a bridge on the side it drifted to), held as
    "drift" (a robot turning on the spot at a spin: halfway from that limit to the
    loop's stop; RETURN_SLACK); with a `lead` [s] (RobotSettings.guard_drift_lead; None: at
    that limit), past that limit only once its drift would reach the stop within the lead
    (drift_hold_at); and, with the guard and `stuck` (RobotSettings.guard_stuck; None: never),
    once it has made no progress for that share of the driver's stuck_time
    (loop.stall_time), held as "stall".
    trim: the motors' mismatch each look-ahead estimates (pooled
    with `estimates`, the legs' before) is divided out of the loop's commands from then on
    (loop.trim), and from the start the pool of `estimates` is. The
    command line's robot (drive_robot) and the page's Robot folder both look ahead through
    it."""

    def record(t: float, ahead: LookAhead) -> None:
        if recorder is not None:
            recorder.write("/lookahead", t, {"t": t, **ahead.to_json()})
        if guard is not None and ahead.p_hold < guard and not loop.stopping:
            whys = sorted({why for *_, why in ahead.failures})
            x, y, _ = ahead.start
            loop.stop(
                "lookahead",
                f"the look-ahead from ({x:.3f}, {y:.3f}) gave a {ahead.p_hold:.2f} chance of "
                f"going on {ahead.horizon:g} s without a stop or a fall (guard {guard:g}; its "
                f"rollouts ended: {', '.join(whys)})",
            )
        if also is not None:
            also(t, ahead)

    smap = loop.safety_map  # (the loop's own: the look-ahead judges its rollouts as it does)
    runner = LookAheadRunner(
        world,
        path,
        spins,
        cfg,
        safety=safety,
        safety_map=smap,
        period=period,
        seed=seed,
        on_result=record,
        estimates=estimates,
        on_trim=(lambda m: setattr(loop, "trim", m)) if trim else None,
        pending=lambda: loop.pending_spins,
    )
    if trim:  # (a re-planned leg's, from the legs before: until its first look-ahead)
        loop.trim = runner.trim = pooled_mismatch(estimates) or 0.0
    loop.listeners.append(runner.listen)
    if guard is not None and drift is not None:
        path_xy = np.asarray(path, dtype=float)[:, :2]
        limit = drift * safety.max_deviation  # [m]
        allowed = [limit]  # (how far off it may be [m]: more after a spin, while it comes back)
        spin_limit = (limit + safety.max_deviation) / 2  # (a spin's wander: held before the stop)
        recent: collections.deque = collections.deque()  # ((t [s], off [m]): drift_rate's)

        def drifted(event) -> None:  # (a loop listener: in the loop's thread, at each pose)
            if getattr(event, "kind", None) != "pose" or not runner.started or loop.stopping:
                return
            x, y = float(event.position[0]), float(event.position[1])
            (nx, ny), off = nearest_on_path((x, y), path_xy)
            # (drift_allowance: a spinning robot held only halfway to the loop's stop, and
            # with a lead only past drift_hold_at's distance; the edge check below holds
            # throughout)
            allowed[0] = drift_allowance(
                allowed[0], off, spinning=loop.spinning, limit=limit, spin_limit=spin_limit
            )
            t = event.sample.t_receive
            recent.append((t, off))
            while recent[0][0] < t - RATE_WINDOW:
                recent.popleft()
            rate = drift_rate(*zip(*recent))
            held_at = drift_hold_at(allowed[0], rate, lead=lead, stop=safety.max_deviation)
            if off > held_at:
                loop.stop(
                    "drift",
                    f"the robot at ({x:.3f}, {y:.3f}) drifted {off:.3f} m off its path, "
                    f"{100 * rate:+.1f} cm/s (guard drift {allowed[0]:.3g} m"
                    + ("" if lead is None else f", held {held_at:.3g} m with a {lead:g} s lead")
                    + f", before the loop's stop at {safety.max_deviation:g} m)",
                )
            elif off > EDGE_OFF and at_edge(world, (x, y, yaw_of(event.quat)), (x - nx, y - ny)):
                # (The robot's own footprint, checked as the planner checks a pose: held while
                # EDGE_ROOM is left before the edge on the side it drifted to. The safety
                # map's 4 cm cells put that edge 2-6 cm from a bridge's rim, and robots held
                # there slid off during the stop.)
                loop.stop(
                    "drift",
                    f"the robot at ({x:.3f}, {y:.3f}) drifted {off:.3f} m off its path, to "
                    f"within {EDGE_ROOM:g} m of the edge of the ground it can stand on (guard "
                    f"edge hold, past {EDGE_OFF:g} m off its path, before the loop's stop "
                    f"{safety.standable_margin:g} m past the safety map's edge)",
                )

        loop.listeners.append(drifted)
    if guard is not None and stuck is not None:  # (the loop counts the progress)
        loop.stall_time = stuck * loop.driver.stuck_time
    return runner


def _scene_file(scene) -> Path | None:
    path = Path(scene.path)
    return path if path.is_file() else None


def _settings_record(world: World, settings: RobotSettings, transform: FrameTransform) -> dict:
    scene = world.scene
    return {
        "source": settings.source,
        "source_settings": {k: v for k, v in settings.source_settings.items()},
        "link": settings.link,
        "link_settings": {k: v for k, v in settings.link_settings.items()},
        "transform": transform.to_json(),
        "transform_measured": settings.transform is None,
        "loop": dataclasses.asdict(settings.loop),
        "driver": dataclasses.asdict(scene.driver),
        "sim": dataclasses.asdict(scene.sim),
        "robot": dataclasses.asdict(world.robot),
        "bounds": [list(b) for b in scene.bounds] if scene.bounds else None,
    }


def _stop_on_signals(loop: RobotLoop) -> Callable[[], None]:
    """Ctrl-C and SIGTERM stop the robot (as Stop does) while it drives; the handlers before
    are put back by the function returned. Outside the main thread signals cannot be
    handled: nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def handler(signum, _frame) -> None:
        loop.stop("signal", f"{signal.Signals(signum).name} received")

    before = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

    def restore() -> None:
        for signum, h in before.items():
            signal.signal(signum, h)

    return restore
