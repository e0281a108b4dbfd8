"""The look-ahead (issue 32, its first part): short rollouts of the rest of the plan from the
robot's live pose, judged by the loop's own safety checks. Real planner, both engines."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest

from conftest import bridge_edge_x
from roachplan.robot import (
    LookAheadConfig,
    SafetyConfig,
    SafetyMap,
    look_ahead,
    remaining_path,
)


def test_the_rest_of_a_plan_starts_at_the_point_nearest_the_robot_with_its_spins_reindexed():
    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
    spins = ((1, math.pi / 2), (2, 0.0))
    rest, kept = remaining_path(path, spins, (0.4, 0.1))
    assert np.allclose(rest, [[0.4, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
    assert kept == ((1, math.pi / 2), (2, 0.0))
    rest, kept = remaining_path(path, spins, (1.1, 0.5))  # past the first spin's waypoint
    assert np.allclose(rest, [[1.0, 0.5, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0]])
    assert kept == ((1, 0.0),)


def test_a_spin_the_robot_has_yet_to_make_is_not_behind_it_where_it_stands_at_it():
    """remaining_path(pending=True): the spins given are the loop's still to make, so one at
    the nearest point or just behind it (a plan that starts with a spin repeats its first
    waypoint; a robot turning through a spin wanders a few cm past it) is made first, at the
    rest's start. Without pending such a spin counts as made and is dropped."""
    path = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    spins = ((0, 0.0), (2, math.pi / 2))
    rest, kept = remaining_path(path, spins, (0.0, 0.01), pending=True)
    assert np.allclose(rest[0], [0.0, 0.0, 0.0]) and kept[0] == (0, 0.0)
    assert [rest[i, :2].tolist() for i, _ in kept] == [[0.0, 0.0], [1.0, 0.0]]
    assert remaining_path(path, spins, (0.0, 0.01))[1] == ((2, math.pi / 2),)  # (made, behind)
    # Wandered 3 cm past the second spin's waypoint while turning there: still to make.
    rest, kept = remaining_path(path, spins[1:], (1.0, 0.03), pending=True)
    assert kept == ((0, math.pi / 2),) and np.allclose(rest[0], [1.0, 0.03, 0.0])


@pytest.mark.slow
def test_a_look_ahead_from_a_robot_about_to_turn_on_the_spot_makes_that_turn_first(bridge):
    """A leg that starts with a spin (a rejoin's, a re-plan of lines and turns on the spot)
    and a robot standing at it facing back along its path: the rollouts turn on the spot and
    walk on (the spin is still to make: RobotLoop.pending_spins), rather than walk off the
    way the robot faces as if the spin were behind it."""
    from roachplan.robot import rejoin_path

    world, planned = bridge
    smap = SafetyMap.from_world(world)
    x, y, yaw = _pose_on_path(planned, 0.3)
    new, kept = rejoin_path(planned.path_xyz, planned.spins, (x, y))
    assert kept and kept[0][0] == 0 and np.allclose(new[0], new[1])  # (a spin where it stands)
    cfg = LookAheadConfig(draws=4, horizon=3.0, robot_draws=False)
    ahead = look_ahead(
        world, new, kept, (x, y, yaw + math.pi), cfg,
        safety=SafetyConfig(), safety_map=smap, seed=1,
    )  # fmt: skip
    assert (ahead.holds, ahead.failures) == (4, ()), ahead


def test_the_guard_lets_a_spin_wander_halfway_to_the_stop_and_the_robot_come_back_after():
    """drift_allowance, pose by pose: walking, the guard's limit; in a spin, what the robot has
    wandered plus RETURN_SLACK, held once past spin_limit; after it, held only where the robot
    goes RETURN_SLACK further off than the nearest it came back to, and never before the
    limit."""
    from roachplan.robot import RETURN_SLACK, drift_allowance

    limit, spin_limit = 0.075, 0.1125

    def held(poses) -> list[bool]:
        allowed, out = limit, []
        for off, spinning in poses:
            allowed = drift_allowance(
                allowed, off, spinning=spinning, limit=limit, spin_limit=spin_limit
            )
            out.append(off > allowed)
        return out

    assert held([(0.02, False), (0.07, False), (0.08, False)]) == [False, False, True]
    spin = [(0.04, True), (0.09, True), (0.10, True)]  # (wandered past the limit, turning)
    assert held(spin) == [False, False, False]
    assert held([*spin, (0.12, True)]) == [False, False, False, True]  # (past spin_limit)
    # Made at 0.10 off: coming back is not drifting; going further off than that is.
    assert held([*spin, (0.10 + 0.5 * RETURN_SLACK, False)])[-1] is False  # (the gait's sway)
    back = [(0.10, False), (0.095, False), (0.09, False)]
    assert held([*spin, *back]) == [False] * 6
    assert held([*spin, *back, (0.09 + 0.9 * RETURN_SLACK, False)])[-1] is False
    assert held([*spin, *back, (0.09 + 1.5 * RETURN_SLACK, False)])[-1] is True
    # Back within the limit, the limit again.
    assert held([*spin, (0.05, False), (0.07, False), (0.08, False)])[-2:] == [False, True]


def test_the_guard_holds_a_drifting_robot_by_how_soon_it_would_reach_the_stop():
    """drift_rate: the least-squares slope of the distance off over time, through the pose
    noise; drift_hold_at: past the allowed drift, held where the drift going on `lead` seconds
    would come within DRIFT_MARGIN of the stop; never nearer than the allowance; a robot
    coming back, or lead None, at the allowance."""
    from roachplan.robot import DRIFT_MARGIN, drift_hold_at, drift_rate

    t = np.arange(0.0, 0.5, 0.02)
    noise = np.random.default_rng(5).normal(0.0, 0.002, len(t))
    assert drift_rate(t, 0.08 + 0.05 * t + noise) == pytest.approx(0.05, abs=0.01)
    assert drift_rate(t, 0.10 - 0.03 * t) == pytest.approx(-0.03)
    assert drift_rate(t[:2], [0.0, 0.1]) == 0.0 and drift_rate([1.0] * 3, [0, 0.1, 0.2]) == 0.0
    stop, allowed = 0.15, 0.075
    slow = drift_hold_at(allowed, 0.02, lead=0.4, stop=stop)
    assert slow == pytest.approx(stop - DRIFT_MARGIN - 0.008)
    fast = drift_hold_at(allowed, 0.10, lead=0.4, stop=stop)
    assert allowed < fast < slow  # (a faster drift is held nearer)
    assert drift_hold_at(allowed, 0.5, lead=0.4, stop=stop) == allowed  # (never nearer)
    assert drift_hold_at(allowed, -0.05, lead=0.4, stop=stop) == stop - DRIFT_MARGIN
    assert drift_hold_at(allowed, 0.05, lead=None, stop=stop) == allowed
    assert drift_hold_at(0.14, 0.0, lead=0.4, stop=stop) == 0.14  # (a spin's allowance)


def test_a_drifted_robot_turns_to_rejoin_the_rest_of_its_path_ahead_without_skipping_a_spin():
    """rejoin_path: from where the robot stands, a turn on the spot to face the old path, a
    straight line to it, meeting it at the first waypoint REJOIN_MIN or twice its distance off
    past the nearest point (at a spin that comes first), then the old path on."""
    from roachplan.robot import REJOIN_MIN, distance_to_path, rejoin_path

    path = np.column_stack([np.arange(0.0, 1.001, 0.05), np.zeros(21), np.full(21, 0.1)])
    new, kept = rejoin_path(path, ((14, math.pi / 2),), (0.3, 0.04))
    assert np.allclose(new[:2], [[0.3, 0.04, 0.1]] * 2)  # (where it stands, at the path's height)
    met = new[2]
    assert met[0] == pytest.approx(0.3 + max(REJOIN_MIN, 0.08)) and met[1] == 0.0
    assert kept[0] == (0, pytest.approx(math.atan2(-0.04, met[0] - 0.3)))  # (faces it first)
    assert np.allclose(new[3:], path[path[:, 0] > met[0] + 1e-9])  # (the old path on)
    assert new[kept[1][0], 0] == pytest.approx(0.7) and kept[1][1] == math.pi / 2
    assert distance_to_path((0.3, 0.04), new[:, :2]) == 0.0  # (no drift at its start)
    far, _ = rejoin_path(path, (), (0.3, 0.09))  # (farther off: it meets the path farther on)
    assert 0.3 + 0.18 <= far[2, 0] < 0.3 + 0.18 + 0.05  # (the first waypoint that far on)
    new, kept = rejoin_path(path, ((7, 1.0),), (0.3, 0.04))  # (a spin 5 cm on: met there)
    assert new[2, 0] == pytest.approx(0.35) and kept[1:] == ((2, 1.0),)
    end, kept = rejoin_path(path, (), (0.98, 0.04))  # (near the end: met at the end)
    assert np.allclose(end[1:], [[0.98, 0.04, 0.1], [1.0, 0.0, 0.1]]) and len(kept) == 1
    on, kept = rejoin_path(path, (), (1.0, 0.005))  # (at the end: no line to face)
    assert len(on) == 2 and kept == ()


def test_a_rejoin_is_a_plan_to_drive_whose_states_face_along_it_and_turn_at_its_spins():
    """rejoin_plan: rejoin_path's path and spins as a plan (the planner "rejoin", the old
    plan's seed and arcs), each state's heading toward the next waypoint, a spin's next
    waypoint at the spin's heading; the tracking driver takes it."""
    from roachplan.robot import rejoin_path, rejoin_plan
    from roachplan.sim import DriverConfig, make_follower

    path = np.column_stack([np.arange(0.0, 1.001, 0.05), np.zeros(21), np.full(21, 0.1)])
    spins = ((14, math.pi / 2),)
    plan = rejoin_plan(path, spins, (0.3, 0.04), seed=7, turning_radius=0.26)
    new, kept = rejoin_path(path, spins, (0.3, 0.04))
    assert plan.found and plan.planner == "rejoin" and plan.seed == 7
    assert plan.turning_radius == 0.26 and plan.spins == kept
    assert np.array_equal(plan.path_xyz, new) and np.allclose(plan.states[:, :2], new[:, :2])
    for k, heading in kept:
        assert plan.states[k + 1, 2] == heading
    ahead = [i for i in range(len(new) - 1) if i not in {k + 1 for k, _ in kept}]
    step = np.diff(new[:, :2], axis=0)
    for i in ahead:
        if np.linalg.norm(step[i]) > 1e-9:  # (toward the next waypoint)
            assert plan.states[i, 2] == pytest.approx(math.atan2(step[i, 1], step[i, 0]))
    make_follower(plan.path_xyz, DriverConfig(), plan.spins)  # (a path the driver takes)


@pytest.fixture(scope="module")
def bridge():
    from roachplan.experiments import plan
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene("double_bridge"))
    planned = plan(world, seed=0)
    assert planned.found
    return world, planned


def _pose_on_path(planned, share: float) -> tuple[float, float, float]:
    p = planned.path_xyz
    k = int(share * (len(p) - 1))
    dx, dy = p[k + 1, :2] - p[k, :2]
    return float(p[k, 0]), float(p[k, 1]), math.atan2(dy, dx)


def _edge_pose(world, planned, safety_map) -> tuple[float, float, float]:
    """A pose on the bridge 2 cm inside its edge, facing out across it (the bridge's edge found
    from the standable map, walking sideways from the path's middle)."""
    x, y, yaw = _pose_on_path(planned, 0.5)
    out = yaw - math.pi / 2
    for side in (out, out + math.pi):
        for step in np.arange(0.0, 0.5, 0.005):
            px, py = x + step * math.cos(side), y + step * math.sin(side)
            if safety_map.off_standable(px, py) > 0.0:
                back = step - 0.02
                return x + back * math.cos(side), y + back * math.sin(side), side
    raise AssertionError("no edge found beside the path")


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_on_its_path_the_robot_holds_and_facing_off_the_bridge_edge_it_does_not(bridge, engine):
    world, planned = bridge
    world = world.with_sim(*_engine_settings(world, engine))
    smap = SafetyMap.from_world(world)
    cfg = LookAheadConfig(draws=4, horizon=2.0, robot_draws=False)  # (the pose's noise only)
    here = _pose_on_path(planned, 0.3)
    on = look_ahead(
        world, planned.path_xyz, planned.spins, here, cfg,
        safety=SafetyConfig(), safety_map=smap, seed=1,
    )  # fmt: skip
    assert (on.rollouts, on.holds, on.failures) == (4, 4, ())
    edge = _edge_pose(world, planned, smap)
    off = look_ahead(
        world, planned.path_xyz, planned.spins, edge, cfg,
        safety=SafetyConfig(), safety_map=smap, seed=1,
    )  # fmt: skip
    assert off.p_hold < 0.5, off
    assert all(why in ("off_standable", "fell", "flipped", "deviation") for *_, why in off.failures)
    # Where they failed: beside the edge, not back at the plan's start.
    for fx, fy, _ in off.failures:
        assert math.dist((fx, fy), edge[:2]) < 0.3
    again = look_ahead(
        world, planned.path_xyz, planned.spins, edge, cfg,
        safety=SafetyConfig(), safety_map=smap, seed=1,
    )  # fmt: skip
    assert again.failures == off.failures  # (one seed, one answer)
    # The robot drawn from the scene's uncertainty too (friction, mass, motor speeds): on the
    # path it mostly holds still, and one seed is one answer.
    drawn = [
        look_ahead(
            world, planned.path_xyz, planned.spins, here, dataclasses.replace(cfg, robot_draws=True),
            safety=SafetyConfig(), safety_map=smap, seed=1,
        )
        for _ in range(2)
    ]  # fmt: skip
    assert drawn[0] == dataclasses.replace(drawn[1], wall_time=drawn[0].wall_time)
    assert drawn[0].p_hold >= 0.5, drawn[0]


def _engine_settings(world, engine: str):
    from roachplan.scenes import with_engine

    scene = with_engine(world.scene, engine)
    return scene.sim, scene.driver


def test_the_runner_keeps_the_legs_phase_from_the_commands_sent(bridge):
    """The phase a look-ahead starts its legs at: the commands' integral (a stop frame stands
    still), as compare's windows take it from a log, at the moment the pose was the robot's
    (phase_at: between commands too, and before them); a look-ahead starts its rollouts
    that long before it began (LookAhead.lead: the pose's age and latency)."""
    from roachplan.robot import (
        CommandEvent,
        CommandFrame,
        LookAheadRunner,
        PoseEvent,
        PoseSample,
        phase_at,
    )

    world, planned = bridge
    assert world.robot.motor_gain == (1.0, 1.0)  # (the phase: the commands' integral)
    seen = []
    cfg = LookAheadConfig(draws=2, horizon=0.5, latency=0.05)
    runner = LookAheadRunner(
        world, planned.path_xyz, planned.spins, cfg,
        safety=SafetyConfig(), safety_map=SafetyMap.from_world(world), period=60.0, seed=0,
        on_result=lambda t, a: seen.append(a),
    )  # fmt: skip
    t0 = time.monotonic() - 1.0
    try:
        for t, left, right, stop in ((t0, 2.0, 3.0, False), (t0 + 0.5, 0.0, 0.0, True)):
            frame = CommandFrame(seq=0, t_us=0, left=left, right=right, stop=stop)
            runner.listen(CommandEvent(t=t, scheduled=t, frame=frame))
        with runner._lock:
            phases = list(runner._phases)
        assert phase_at(phases, t0 + 99.0) == pytest.approx((1.0, 1.5))  # (stopped since)
        assert phase_at(phases, t0 + 0.25) == pytest.approx((0.5, 0.75))  # (between them)
        assert phase_at(phases, t0 - 1.0) == (0.0, 0.0)  # (before the first: at rest)
        # A pose heard, the first look-ahead starts at once, from it.
        x, y, yaw = _pose_on_path(planned, 0.3)
        heard = time.monotonic()
        sample = PoseSample(
            t_receive=heard, t_source=0.0, seq=0, position=(x, y, 0.0), quat=(0.0, 0.0, 0.0, 1.0)
        )
        q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        runner.listen(PoseEvent(sample=sample, position=(x, y, 0.2), quat=q))
        runner.start()
        deadline = time.monotonic() + 60
        while not seen and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        runner.close()
    assert len(seen) == 1 and seen[0].start == pytest.approx((x, y, yaw))
    assert cfg.latency <= seen[0].lead <= cfg.latency + (time.monotonic() - heard)


def test_what_happened_over_each_horizon_scores_the_predictions():
    """observed_hold and look_ahead_reliability on recorded look-aheads: one that the run
    outlived holds; one whose horizon a deviation stop fell in did not; one cut short by the
    user's Stop is not scored. The Brier score is the mean squared miss."""
    from types import SimpleNamespace

    from roachplan.robot import look_ahead_reliability, observed_hold

    result = {"reason": "deviation", "t_stop": 10.0}
    early = {"t": 5.0, "horizon": 3.0, "p_hold": 0.9}
    late = {"t": 8.0, "horizon": 3.0, "p_hold": 0.3}
    assert observed_hold(early, result) == 1 and observed_hold(late, result) == 0
    assert observed_hold(late, {"reason": "stop", "t_stop": 10.0}) is None
    assert observed_hold(late, {"reason": "goal", "t_stop": 10.0}) == 1
    run = SimpleNamespace(result=result, lookaheads=[early, late])
    cut = SimpleNamespace(result={"reason": "stop", "t_stop": 10.0}, lookaheads=[late])
    out = look_ahead_reliability([run, cut])
    assert out["scored"] == 2
    assert out["brier"] == pytest.approx(((0.9 - 1) ** 2 + (0.3 - 0) ** 2) / 2)
    by_bin = {tuple(b["bin"]): b for b in out["bins"]}
    assert by_bin[(0.0, 0.5)]["scored"] == 1 and by_bin[(0.0, 0.5)]["observed"] == 0.0
    assert by_bin[(0.8, 0.95)]["scored"] == 1 and by_bin[(0.8, 0.95)]["observed"] == 1.0
    assert math.isnan(look_ahead_reliability([])["brier"])


@pytest.mark.slow
def test_a_plan_from_the_robot_keeps_clear_of_the_drop_offs(bridge):
    """edge_margin: seed 0's path on the double bridge passes a drop-off closer than 4 cm (a
    robot 4 cm sideways off it somewhere has a foot over the edge); with keep, plan_clear_of
    gives another seed's plan, every pose of which, past its first 10 cm, stays valid 4 cm to
    either side. Without keep it is seed 0's. The path carried a metre sideways, over the gap
    and off the area, keeps nothing."""
    from roachplan.planning import check_states
    from roachplan.robot import edge_margin, plan_clear_of

    world, planned = bridge
    keep = 0.04
    assert edge_margin(world, planned.path_xyz, keep) < keep
    chosen, clear = plan_clear_of(world, world.start, 0, keep=keep)
    assert chosen.found and chosen.seed != 0 and clear == math.inf
    assert edge_margin(world, chosen.path_xyz, keep) == keep
    xy = np.asarray(chosen.path_xyz)[:, :2]
    step = np.diff(xy, axis=0)
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(step, axis=1))])[:-1]
    yaw = np.arctan2(step[:, 1], step[:, 0])[along >= 0.1]
    left = np.column_stack([-np.sin(yaw), np.cos(yaw)])
    for side in (1.0, -1.0):
        poses = np.column_stack([xy[:-1][along >= 0.1] + side * keep * left, yaw])
        hf, fp, cfg = world.heightfield, world.footprint, world.scene.planner.validity
        assert check_states(hf, fp, cfg, poses).valid.all()
    same, _ = plan_clear_of(world, world.start, 0)
    assert same.seed == 0
    assert edge_margin(world, np.asarray(planned.path_xyz) + [1.0, 0.0, 0.0], keep) == 0.0


@pytest.mark.slow
def test_a_re_plan_keeps_clear_of_where_the_rollouts_failed(bridge):
    """plan_clear_of: a point on the seed's own path (on its bridge) is a place to keep clear
    of; the plan it gives keeps at least AVOID_RADIUS from it (another seed's plan), and says
    how far. A point within the radius of the start is not avoided (no path could). Past its
    deadline it tries once, with at most MIN_TRY to plan."""
    from roachplan.robot import AVOID_RADIUS, MIN_TRY, distance_to_path, plan_clear_of

    world, planned = bridge
    start = world.start
    spot = tuple(planned.path_xyz[len(planned.path_xyz) // 2, :2])
    chosen, clearance = plan_clear_of(world, start, 0, [spot])
    assert chosen.found and chosen.seed != 0
    xy = np.asarray(chosen.path_xyz)[:, :2]
    assert clearance == pytest.approx(distance_to_path(spot, xy)) and clearance >= AVOID_RADIUS
    near_start = [(start[0] + 0.01, start[1])]
    same, clear = plan_clear_of(world, start, 0, near_start)
    assert same.seed == 0 and clear == math.inf
    assert np.array_equal(same.path_xyz, planned.path_xyz)
    # Its deadline passed: one try only (the first always runs), within MIN_TRY of planning.
    once, kept = plan_clear_of(world, start, 0, [spot], deadline=time.monotonic())
    assert once.seed == 0 and kept < AVOID_RADIUS  # (the seed's own path: no other tried)
    assert once.plan_time <= MIN_TRY + 0.25


def test_a_re_plan_starts_from_the_nearest_pose_the_planner_takes(bridge):
    """plan_start: a robot held with a foot over a bridge's edge (a pose the planner refuses:
    "a foot has no ground under it") is re-planned from the nearest pose it takes, within
    START_REACH, and a plan from there is found; a pose it takes is kept as it is; a robot far
    from any such pose is refused in words that say what is wrong where it stands."""
    from roachplan.planning import FOOT, check_states
    from roachplan.robot import START_REACH, RobotError, plan_start

    world, planned = bridge
    hf, fp, validity = world.heightfield, world.footprint, world.scene.planner.validity
    xy = planned.path_xyz[len(planned.path_xyz) // 2, :2]  # on a bridge: walk off its side
    steps = np.arange(0.0, 0.3, 0.002)
    line = np.column_stack([xy[0] + steps, np.full_like(steps, xy[1]), np.full_like(steps, 1.5)])
    checked = check_states(hf, fp, validity, line)
    edge = int(np.argmax(~checked.valid))  # the first pose off the bridge
    assert not checked.valid[edge] and checked.code[edge] == FOOT
    here = tuple(line[edge].tolist())
    start, moved = plan_start(world, here)
    assert 0 < moved <= START_REACH and math.dist(start[:2], here[:2]) == pytest.approx(moved)
    moved_to = check_states(hf, fp, validity, np.array([start]))
    assert moved_to.valid[0]  # ... on the bridge it stood on, not the floor below its edge:
    ground = float(hf.sample(np.array(here[:2])))
    assert abs(float(moved_to.z_surface[0]) - ground) <= validity.body_band
    from roachplan.experiments import plan

    assert plan(world, seed=0, start=start).found
    kept, none = plan_start(world, world.start)
    assert kept == world.start and none == 0.0
    (xa, ya), _ = world.bounds
    with pytest.raises(RobotError, match=r"the planner refuses it \(outside the area\)"):
        plan_start(world, (xa - 1.0, ya - 1.0, 0.0))


def test_a_look_ahead_is_drawn_as_the_stretch_it_covered_in_its_risk_colour():
    """replay's (and the page's) drawing of a look-ahead: from the path's point nearest its
    start, horizon x RISK_SPEED along the path, green when every rollout held, red when none
    did; a red square round each failed rollout's end."""
    from roachplan.app._draw import FAILED, RISK_SPEED, look_ahead_lines, risk_colour

    path = np.array([[0.0, 0.0, 0.1], [0.3, 0.0, 0.1], [0.3, 1.0, 0.1]])
    ahead = {"start": [0.1, 0.02, 0.0], "horizon": 2.0, "p_hold": 0.25,
             "failures": [[0.35, 0.2, "deviation"]]}  # fmt: skip
    (name, stretch, colour), (fname, square, fcolour) = look_ahead_lines(ahead, path)
    assert name == "" and colour == risk_colour(0.25) and fname == "failed/0" and fcolour == FAILED
    assert np.allclose(stretch[0], [0.1, 0.0, 0.11]) and np.allclose(stretch[-1], [0.3, 0.2, 0.11])
    length = np.sum(np.linalg.norm(np.diff(stretch[:, :2], axis=0), axis=1))
    assert length == pytest.approx(2.0 * RISK_SPEED)
    assert np.allclose(square.mean(axis=0)[:2], [0.35, 0.2], atol=0.005) and np.ptp(
        square[:, 0]
    ) == pytest.approx(0.02)
    green, yellow, red = risk_colour(1.0), risk_colour(0.5), risk_colour(0.0)
    assert green[1] > 150 and green[0] == 0 and red[0] > 200 and red[1] == 0
    assert yellow[0] > 150 and yellow[1] > 150


def test_the_run_s_window_estimates_are_pooled_by_the_distance_walked_in_each():
    """pooled_mismatch: a motor's mismatch holds for the run, so each look-ahead drives with
    the mean of every window's estimate so far, weighted by how far the robot walked in it
    (a window that barely walked says little) and drawn towards 0 by PRIOR_WALK (one wild
    first window is not trimmed in full); none estimated: None."""
    from roachplan.robot import PRIOR_WALK, pooled_mismatch

    assert pooled_mismatch([]) is None
    assert pooled_mismatch([(0.1, 0.5)]) == pytest.approx(0.1 * 0.5 / (0.5 + PRIOR_WALK))
    first = pooled_mismatch([(0.4, 0.2)])
    assert first is not None and first < 0.4 / 2  # (a first stretch alone: under half)
    pooled = pooled_mismatch([(0.10, 0.6), (0.16, 0.2), (0.06, 0.2)])
    assert pooled == pytest.approx(0.104 / (1 + PRIOR_WALK))
    rng = np.random.default_rng(0)  # (windows scattered round 0.12: the pool is nearer it)
    windows = [(0.12 + rng.normal(0, 0.03), 0.5) for _ in range(40)]
    pooled = pooled_mismatch(windows)
    assert pooled is not None and abs(pooled - 0.12) < 0.03 / math.sqrt(40) * 3 + 0.12 * (
        PRIOR_WALK / 20
    )


def test_the_motors_mismatch_is_estimated_from_how_the_robot_turned_against_its_commands():
    """estimate_mismatch: on an arc the calibrated curve gives for the actual speed ratio, it
    recovers d exactly; the simulated roach told to walk straight with its motors at 1.06 and
    0.94 (d = 0.06) curves, and the estimate from 4 s of its poses comes within 0.02; too
    short a walk gives none."""
    from roachplan.robot import estimate_mismatch
    from roachplan.sim import DriverConfig, RobotConfig, SimConfig, open_floor

    driver = DriverConfig()
    curve, top = driver.turning, driver.max_ratio
    d, left, right = 0.05, 20.0, 24.0  # told to turn left at ratio 1.2
    actual = (right * (1 - d)) / (left * (1 + d))
    kappa = curve.curvature(actual)  # [1/m]
    s = np.linspace(0.0, 0.8, 41)  # along the arc [m]
    poses = np.column_stack(
        [s / 0.2, np.sin(kappa * s) / kappa, (1 - np.cos(kappa * s)) / kappa, kappa * s]
    )
    commands = np.column_stack([np.arange(0, 4, 0.02), np.full(200, left), np.full(200, right)])
    assert estimate_mismatch(poses, commands, curve, top) == pytest.approx(d, abs=1e-6)
    assert estimate_mismatch(poses[:3], commands, curve, top) is None  # (4 cm walked)

    track = []
    with open_floor(RobotConfig(), SimConfig()) as sim:
        sim.perturb(friction=SimConfig().friction, mass_scale=1.0, motor_gain=(1.06, 0.94))
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(20.0, 20.0)
        for _ in range(250):  # 5 s, the first second left out (from rest)
            sim.advance(20)
            (x, y, _), quat = sim.pose()
            track.append((sim.time, x, y, math.atan2(2 * (quat[3] * quat[2] + quat[0] * quat[1]),
                                                     1 - 2 * (quat[1] ** 2 + quat[2] ** 2))))  # fmt: skip
    poses = np.array(track[50:])
    commands = np.column_stack([poses[:, 0], np.full(len(poses), 20.0), np.full(len(poses), 20.0)])
    assert poses[-1, 3] - poses[0, 3] < -0.2  # (the faster left side turns it right)
    assert estimate_mismatch(poses, commands, curve, top) == pytest.approx(0.06, abs=0.02)


def _arc(kappa: float, speed: float, seconds: float, t0: float = 0.0, start=(0.0, 0.0, 0.0)):
    """Poses (t, x, y, yaw) every 10 ms of a walk at `speed` [m/s] on an arc of curvature kappa
    [1/m] (+: to the left) from start (x, y, yaw)."""
    t = np.arange(0.0, seconds, 0.01)
    s = speed * t
    x0, y0, yaw0 = start
    yaw = yaw0 + kappa * s
    if abs(kappa) < 1e-12:
        x, y = x0 + s * math.cos(yaw0), y0 + s * math.sin(yaw0)
    else:
        x = x0 + (np.sin(yaw) - math.sin(yaw0)) / kappa
        y = y0 - (np.cos(yaw) - math.cos(yaw0)) / kappa
    return np.column_stack([t0 + t, x, y, yaw])


def test_a_re_plan_after_drift_holds_asks_for_wider_arcs_then_turns_on_the_spot(bridge):
    """replan_radius: the scene's radius, doubled for each drift hold so far, up to
    MAX_WIDENING times; past that, or after a stall hold, SPIN_ONLY_RADIUS, with which the
    drivable planner's path is straight lines joined by turns on the spot (its heading changes
    only at its spins)."""
    from roachplan.experiments import plan
    from roachplan.robot import MAX_WIDENING, SPIN_ONLY_RADIUS, replan_radius

    assert replan_radius(0.13, 0) == 0.13
    assert replan_radius(0.13, 1) == pytest.approx(0.26)
    widened = max(k for k in range(8) if 2.0**k <= MAX_WIDENING)
    assert replan_radius(0.13, widened) == pytest.approx(0.13 * 2.0**widened)
    assert replan_radius(0.13, widened + 1) == replan_radius(0.13, 5) == SPIN_ONLY_RADIUS
    # (a robot the guard held for making no progress: lines and spins at once)
    assert replan_radius(0.13, 0, stalled=True) == SPIN_ONLY_RADIUS
    world, _ = bridge
    planner = dataclasses.replace(world.scene.planner, turning_radius=SPIN_ONLY_RADIUS)
    lines = plan(world.with_planner(planner), seed=0)
    assert lines.found and lines.spins
    xy = np.asarray(lines.path_xyz)[:, :2]
    step = np.diff(xy, axis=0)
    moving = np.linalg.norm(step, axis=1) > 1e-9
    heading = np.arctan2(step[moving, 1], step[moving, 0])
    turns = np.abs(np.remainder(np.diff(heading) + math.pi, 2 * math.pi) - math.pi)
    assert np.count_nonzero(turns > 1e-3) <= len(lines.spins)


class _Standing:
    """A pose source whose robot stands still at (x, y, z) [m] facing yaw [rad] (world frame
    = mocap frame), a fresh sample at every read."""

    def __init__(self, x: float, y: float, z: float, yaw: float) -> None:
        self.position, self.seq = (x, y, z), 0
        self.quat = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))

    def latest(self):
        from roachplan.robot import PoseSample

        self.seq += 1
        t = time.monotonic()
        return PoseSample(
            t_receive=t, t_source=t, seq=self.seq, position=self.position, quat=self.quat
        )

    def close(self) -> None:
        pass


class _Sent:
    """A command link that keeps nothing."""

    def send(self, left: float, right: float, *, stop: bool = False):
        from roachplan.robot import CommandFrame

        return CommandFrame(seq=0, t_us=0, left=left, right=right, stop=stop)

    def close(self) -> None:
        pass


@pytest.mark.parametrize("stall", [0.4, None])
def test_a_robot_that_makes_no_progress_is_held_as_stalled_before_the_stuck_stop(bridge, stall):
    """RobotLoop.stall_time (the guard's stall hold, RobotSettings.guard_stuck): a robot that
    stands still on its path is held as "stall" that long after Go, before the stuck stop at
    the driver's stuck_time (here 1 s); not before Go, however long it waits; with none, the
    stuck stop ends the run."""
    from roachplan.robot import FrameTransform, RobotLoop, SafetyMap

    world, planned = bridge
    x, y, z = (float(v) for v in planned.path_xyz[0])
    dx, dy = planned.path_xyz[1, :2] - planned.path_xyz[0, :2]
    loop = RobotLoop(
        path_xyz=planned.path_xyz,
        spins=planned.spins,
        source=_Standing(x, y, z, math.atan2(dy, dx)),
        link=_Sent(),
        transform=FrameTransform(),
        safety_map=SafetyMap.from_world(world),
        driver=dataclasses.replace(world.scene.driver, stuck_time=1.0),
        max_motor_speed=world.robot.max_motor_speed,
    )
    loop.stall_time = stall
    loop.start()
    try:
        assert loop.wait(1.2) is None  # (held, before Go: no stall, no stuck stop)
        loop.go()
        result = loop.wait(10)
    finally:
        loop.cancel()
    assert result is not None and result.t_go is not None
    waited = result.t_stop - result.t_go  # [s]
    if stall is None:
        assert result.reason == "stuck" and waited >= 1.0, result
    else:
        assert result.reason == "stall" and 0.4 <= waited < 1.0, (result, waited)
        assert "guard stall 0.4 s, before the loop's stuck stop at 1 s" in result.detail


def test_trimmed_commands_make_mismatched_motors_run_as_the_driver_asked():
    """trim_commands: a robot whose motors run at left x 1.12, right x 0.88 is sent left / 1.12,
    right / 0.88, so its motors run at what the driver asked; where that would pass the motors'
    top speed both sides are scaled down together (the ratio, which steers, kept); a turn on
    the spot the same; no mismatch, no change."""
    from roachplan.robot import trim_commands

    d, top = 0.12, 60.0
    left, right = trim_commands(20.0, 40.0, d, top)
    assert (left * (1 + d), right * (1 - d)) == pytest.approx((20.0, 40.0))
    left, right = trim_commands(20.0, 60.0, d, top)  # (60 / 0.88 would pass the top speed)
    assert max(abs(left), abs(right)) == pytest.approx(top)
    assert (right * (1 - d)) / (left * (1 + d)) == pytest.approx(3.0)
    left, right = trim_commands(-30.0, 30.0, d, top)
    assert (left * (1 + d), right * (1 - d)) == pytest.approx((-30.0, 30.0))
    assert trim_commands(20.0, 24.0, 0.0, top) == (20.0, 24.0)


def test_the_mismatch_is_estimated_on_the_stretches_the_driver_asked_to_walk_straight():
    """straight_mismatches: a robot whose motors run at left x 1.12, right x 0.88 walks
    straight when it is sent left / 1.12, right / 0.88 (the loop's trim of 0.12): each whole
    1 s stretch so walked estimates 0.12; a stretch where the driver asked for a hard turn is
    left out (there a floor that turns the robot less reads as a mismatch), and so is the
    part-second left at the end."""
    from roachplan.robot import straight_mismatches
    from roachplan.sim import DriverConfig

    driver = DriverConfig()
    curve, top = driver.turning, driver.max_ratio
    d = 0.12
    straight = _arc(0.0, 0.2, 3.5)
    t = np.arange(0.0, 3.5, 0.02)
    sent = np.column_stack([t, np.full(len(t), 20 / (1 + d)), np.full(len(t), 20 / (1 - d))])
    commands = np.column_stack([sent, np.full(len(t), d)])
    pieces = straight_mismatches(straight, commands, curve, top)
    assert len(pieces) == 3  # (0-1, 1-2, 2-3 s; 3-3.5 s is not whole)
    for estimate, walked in pieces:
        assert estimate == pytest.approx(d, abs=0.005) and walked == pytest.approx(0.2, abs=0.01)
    # Told to turn hard (ratio 2.5 as the driver asked) while it turned less: left out.
    turn = np.column_stack([t, np.full(len(t), 20.0), np.full(len(t), 50.0), np.zeros(len(t))])
    assert straight_mismatches(_arc(2.0, 0.2, 3.5), turn, curve, top) == []
    # A turn on the spot in the middle second (the spin's heading in its poses): that second
    # is left out, the others estimate as before.
    spun = straight.copy()
    during = (spun[:, 0] >= 1.2) & (spun[:, 0] < 1.6)
    spun[during, 1:3] = spun[np.argmax(during), 1:3]  # (on the spot)
    spun[during, 3] = np.linspace(0.0, 1.5, during.sum())
    spun[spun[:, 0] >= 1.6, 3] += 1.5
    spin = commands.copy()
    on_spot = (t >= 1.2) & (t < 1.6)
    spin[on_spot, 1:3] = (10.0, -10.0)
    kept = straight_mismatches(spun, spin, curve, top)
    assert len(kept) == 2 and all(e == pytest.approx(d, abs=0.005) for e, _ in kept)


def test_a_robot_at_a_bridge_edge_steps_in_before_its_re_plan(bridge):
    """step_in: a robot standing at the left bridge's edge, heading along it and 10 deg towards
    the gap, walks first to a pose within STEP_REACH whose footprint keeps 4 cm either side of
    its heading, by a straight line that stands, turning less than it would to face straight
    away from the edge; a robot in the bridge's middle needs no step. stepped_plan: the plan
    from that pose, driven from the robot: a turn on the spot there to face the pose, the line,
    then the plan (the tracking driver takes it). at_edge: 1 cm further towards the gap the
    robot at the edge would not stand; 1 cm the other way, and from the step's pose 4 cm
    either way, it would."""
    from roachplan.planning import check_states
    from roachplan.robot import STEP_REACH, at_edge, plan_clear_of, step_in, stepped_plan
    from roachplan.sim import DriverConfig, make_follower

    world, _ = bridge
    hf, fp, cfg = world.heightfield, world.footprint, world.scene.planner.validity
    yaw = math.radians(80.0)  # (along the bridge, 10 deg towards the gap at +x)
    x = bridge_edge_x(world, 0.0, yaw)
    here = (x, 0.0, yaw)
    assert at_edge(world, here, (1.0, 0.0)) and not at_edge(world, here, (-1.0, 0.0))
    stepped = step_in(world, here, 0.04)
    assert stepped is not None
    sx, sy, heading = stepped
    assert 0.0 < math.dist((sx, sy), here[:2]) <= STEP_REACH + 1e-9
    assert sx < x  # (away from the gap)
    assert heading == pytest.approx(math.atan2(sy, sx - x))  # (facing it from the robot)
    turn = abs((heading - yaw + math.pi) % (2 * math.pi) - math.pi)
    assert turn < math.radians(80.0)  # (less than facing straight away from the gap, 100 deg)
    left = np.array([-math.sin(heading), math.cos(heading)])
    for m in (0.01, 0.02, 0.03, 0.04):
        for side in (1.0, -1.0):
            px, py = np.array([sx, sy]) + side * m * left
            assert check_states(hf, fp, cfg, np.array([[px, py, heading]])).valid[0]
    assert not at_edge(world, (sx, sy, heading), (1.0, 0.0), room=0.04)
    # No direction of a smaller turn (every 10 deg) has a pose within reach that keeps 4 cm
    # either side with a line to it that stands (checked here apart from step_in).
    for a in np.radians(np.arange(-180.0, 180.0, 10.0)):
        if abs((a - yaw + math.pi) % (2 * math.pi) - math.pi) >= turn - 1e-6:
            continue
        u, n = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
        for r in np.arange(0.01, STEP_REACH + 1e-9, 0.01):
            p = np.array([x, 0.0]) + r * u
            poses = [p + m * n * side for m in (0.0, 0.01, 0.02, 0.03, 0.04) for side in (1, -1)]
            poses += [np.array([x, 0.0]) + f * r * u for f in (0.25, 0.5, 0.75)]
            states = np.column_stack([np.array(poses), np.full(len(poses), a)])
            assert not check_states(hf, fp, cfg, states).valid.all(), (math.degrees(a), r)
    assert step_in(world, (-0.75, 0.0, math.pi / 2), 0.04) is None  # (mid-bridge)
    planned, _ = plan_clear_of(world, (sx, sy, heading), 0, keep=0.04)
    assert planned.found
    z = float(hf.sample(np.array(here[:2])))
    driven = stepped_plan(world, planned, here)
    assert np.allclose(driven.path_xyz[:2], [[x, 0.0, z]] * 2)
    assert np.allclose(driven.states[:2], [[x, 0.0, yaw], [x, 0.0, heading]])  # (then turned)
    assert np.array_equal(driven.path_xyz[2:], planned.path_xyz)
    assert driven.spins[0] == (0, pytest.approx(heading))
    assert driven.spins[1:] == tuple((i + 2, h) for i, h in planned.spins)
    assert len(driven.states) == len(planned.states) + 2
    make_follower(driven.path_xyz, DriverConfig(), driven.spins)  # (a path the driver takes)


@pytest.mark.parametrize("toward_gap", [True, False])
def test_a_robot_drifted_to_within_a_centimetre_of_an_edge_is_held(bridge, toward_gap):
    """watch_ahead's edge hold (EDGE_OFF, EDGE_ROOM): a robot standing 2.5 cm off a path along
    the left bridge, at the bridge's edge on the gap's side of it (its footprint 1 cm further
    would not stand), is held as "drift" at once after Go; standing as far off on the other
    side, in the bridge, it is not held (the stuck stop, here after 1 s, ends the run). The
    drift limit (7.5 cm) is far; the look-ahead's guard never holds (0)."""
    from roachplan.robot import (
        EDGE_OFF,
        FrameTransform,
        LookAheadConfig,
        RobotLoop,
        SafetyConfig,
        SafetyMap,
        watch_ahead,
    )

    world, _ = bridge
    hf = world.heightfield
    edge = bridge_edge_x(world, 0.0, math.pi / 2)
    off = EDGE_OFF + 0.005
    line = edge - off  # (the path's x: 2.5 cm in from the edge)
    ys = np.linspace(-0.4, 0.45, 35)
    xy = np.column_stack([np.full(len(ys), line), ys])
    path = np.column_stack([xy, hf.sample(xy)])
    x = edge if toward_gap else line - off
    z = float(hf.sample(np.array([x, 0.0]))) + world.robot.standing_height
    loop = RobotLoop(
        path_xyz=path,
        spins=(),
        source=_Standing(x, 0.0, z, math.pi / 2),
        link=_Sent(),
        transform=FrameTransform(),
        safety_map=SafetyMap.from_world(world),
        driver=dataclasses.replace(world.scene.driver, stuck_time=1.0),
        max_motor_speed=world.robot.max_motor_speed,
    )
    watcher = watch_ahead(
        world, path, (), loop, cfg=LookAheadConfig(draws=2, horizon=0.5), guard=0.0,
        period=60.0, seed=0, safety=SafetyConfig(), recorder=None, drift=0.5,
    )  # fmt: skip
    loop.start()
    try:
        loop.go()
        watcher.start()
        result = loop.wait(10)
    finally:
        loop.cancel()
        watcher.close()
    assert result is not None
    if toward_gap:
        assert result.reason == "drift" and "edge" in result.detail, result
        assert result.t_go is not None and result.t_stop - result.t_go < 0.5, result
    else:
        assert result.reason == "stuck", result
