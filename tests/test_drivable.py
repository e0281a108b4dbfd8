"""Drivable plans and the tracking driver (issue 18): Dubins curves as OMPL computes them,
paths no tighter than the turning radius and valid by the independent ray-cast check, and a
driver that follows a hairpin without circling."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from roachplan.experiments import drive, plan
from roachplan.planning._drivable import max_curvature
from roachplan.planning._dubins import dubins_path
from roachplan.scenes import build_world, load_scene
from test_planning import independent_check


def test_dubins_curves_end_on_the_goal_and_are_as_long_as_ompls():
    from roachplan.planning._ompl_import import ob

    rng = np.random.default_rng(7)
    space = ob.DubinsStateSpace(0.15, False)
    a, b = space.allocState(), space.allocState()
    try:
        for _ in range(300):
            s, g = rng.uniform([-1, -1, -4], [1, 1, 4]), rng.uniform([-1, -1, -4], [1, 1, 4])
            curve = dubins_path(s, g, 0.15)
            end = np.array(curve.end)
            assert np.allclose(end[:2], g[:2], atol=1e-9)
            assert abs(math.remainder(end[2] - g[2], 2 * math.pi)) < 1e-9
            for st, (x, y, yaw) in ((a, s), (b, g)):
                st.setX(x)
                st.setY(y)
                st.setYaw(yaw)
            assert curve.length == pytest.approx(space.distance(a, b), abs=1e-9)
            samples = curve.sample(0.01)
            assert max_curvature(samples) <= 1 / 0.15 * 1.02
    finally:
        space.freeState(a)
        space.freeState(b)


@pytest.mark.parametrize("planner", ["prm", "rrtconnect", "stride"])
def test_drivable_paths_turn_no_tighter_than_the_radius_and_pass_the_ray_cast_check(world, planner):
    cfg = dataclasses.replace(world.scene.planner, name=planner)
    assert cfg.turning_radius is not None, "drivable plans are the default"
    for seed in range(5):
        pl = plan(world, seed=seed, planner=cfg)
        assert pl.found, pl.message
        assert max_curvature(pl.states) <= 1 / cfg.turning_radius * 1.05
        assert independent_check(world, pl.states) == [], f"{planner} seed {seed}"
        # It starts as the robot stands (its heading too) and ends on the goal.
        np.testing.assert_allclose(pl.states[0], world.scene.start, atol=1e-9)
        np.testing.assert_allclose(pl.states[-1, :2], world.scene.goal[:2], atol=1e-9)


def _flat_world(tmp_path):
    path = tmp_path / "flat.yaml"
    path.write_text(
        "terrain: []\nground: 0.0\nrobot: {start: [0.0, 0.0, 0]}\ngoal: [0.0, 0.6, 180]\n"
        "bounds: [[-1.0, -1.0], [2.0, 2.0]]\n"
    )
    return build_world(load_scene(path))


def _net_turn(trajectory, spacing: float = 0.05) -> float:
    """Net signed heading change of the body's track taken every `spacing` metres [rad]: a
    circle driven on the way adds 2 pi to it (the gait's sway left and right cancels)."""
    kept = [np.array(trajectory[0][1:3])]
    for p in trajectory:
        if np.linalg.norm(np.array(p[1:3]) - kept[-1]) >= spacing:
            kept.append(np.array(p[1:3]))
    d = np.diff(np.array(kept), axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    return float(np.sum(np.remainder(np.diff(h) + np.pi, 2 * np.pi) - np.pi))


def test_the_tracking_driver_follows_a_hairpin_without_circling(tmp_path):
    # Out 1 m along +x, a half circle of radius 0.3 m, back along -x: 180 degrees of turning.
    world = _flat_world(tmp_path)
    out = np.column_stack([np.linspace(0, 1, 21), np.zeros(21)])
    a = np.linspace(-np.pi / 2, np.pi / 2, 31)[1:]
    arc = np.column_stack([1 + 0.3 * np.cos(a), 0.3 + 0.3 * np.sin(a)])
    back = np.column_stack([np.linspace(1, 0, 21)[1:], np.full(20, 0.6)])
    xy = np.vstack([out, arc, back])
    path = np.column_stack([xy, np.zeros(len(xy))])
    result = drive(world, path)
    assert result.outcome == "success", result.reason
    # Half a turn to the left, not a full extra circle; and no longer a walk than the path.
    assert abs(_net_turn(result.trajectory) - math.pi) < math.pi / 2
    track = np.array([p[1:3] for p in result.trajectory])
    walked = float(np.sum(np.linalg.norm(np.diff(track, axis=0), axis=1)))
    assert walked < 1.2 * float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))


def test_a_goal_passed_too_wide_is_missed_not_circled(tmp_path):
    # A path whose end the robot cannot reach without turning on the spot: a 90 degree corner
    # 3 cm before the goal.
    world = _flat_world(tmp_path)
    xy = np.vstack([np.column_stack([np.linspace(0, 1, 21), np.zeros(21)]), [[1.0, 0.1]]])
    result = drive(world, np.column_stack([xy, np.zeros(len(xy))]))
    assert result.outcome in ("success", "missed"), result.reason
    if result.outcome == "missed":
        assert "passed the goal" in result.reason
    assert result.drive_time < 30, "ended without circling until the time limit"


def test_progress_at_the_very_end_of_the_path_still_projects():
    """The robot abreast of the goal but wider than r_end: its progress is the path's length,
    and the projection window must still hold the last segment (it was empty)."""
    from roachplan.sim import DriverConfig, TrackingFollower

    path = np.column_stack([np.linspace(0, 1, 21), np.zeros(21), np.zeros(21)])
    t = TrackingFollower(path, DriverConfig())
    t.s = t.total
    assert t.update((1.0, 0.07, 0.0)) is None  # abreast, 7 cm off: not yet decided
    assert t.s == pytest.approx(t.total)
    outcome = t.update((1.2, 0.2, 0.0))
    assert outcome is not None and outcome[0] == "missed"


# -- turns on the spot where arcs cannot go -----------------------------------------------------

DEAD_END_SCAD = """\
// A corridor 22 cm wide and 60 cm long between walls 5 cm high, closed at its +x end.
h = 0.05;
width = 0.22;
len = 0.6;
wall = 0.05;
translate([-len / 2, width / 2, 0]) cube([len + wall, wall, h]);
translate([-len / 2, -width / 2 - wall, 0]) cube([len + wall, wall, h]);
translate([len / 2, -width / 2, 0]) cube([wall, width, h]);
"""
# The robot stands in it facing the closed end; the goal is outside, behind it. Turning round
# on arcs of 0.13 m takes 2 x 0.13 m plus the feet's 7 cm, 0.33 m; on the spot it takes the
# feet's circle (0.11 m) and the spin margin round it (2 x 3 cm), 0.17 m.
DEAD_END_YAML = """\
terrain:
  - scad: dead_end.scad
ground: 0.0
robot: {start: [0.15, 0.0, 0]}
goal: [-0.6, 0.0, 180]
bounds: [[-0.8, -0.4], [0.4, 0.4]]
"""

SWITCHBACK_SCAD = """\
// Two corridors 20 cm wide cut into a block 5 cm high, joined where the second turns back
// 150 degrees from the first.
h = 0.05;
width = 0.2;
len = 0.9;
difference() {
    translate([-1.0, -0.4, 0]) cube([1.4, 1.2, h]);
    translate([-len, -width / 2, -0.01]) cube([len + width / 2, width, h + 0.02]);
    rotate([0, 0, 150]) translate([-width / 2, -width / 2, -0.01])
        cube([len + width / 2, width, h + 0.02]);
}
"""
SWITCHBACK_YAML = """\
terrain:
  - scad: switchback.scad
ground: 0.0
robot: {start: [-0.6, 0.0, 0]}
goal: [-0.52, 0.3, 150]
bounds: [[-0.8, -0.2], [0.2, 0.6]]
"""


def _scene_world(folder, name: str, scad: str, yaml_text: str):
    (folder / f"{name}.scad").write_text(scad)
    (folder / f"{name}.yaml").write_text(yaml_text)
    return build_world(load_scene(folder / f"{name}.yaml"))


@pytest.fixture(scope="module")
def dead_end(tmp_path_factory):
    return _scene_world(
        tmp_path_factory.mktemp("dead_end"), "dead_end", DEAD_END_SCAD, DEAD_END_YAML
    )


@pytest.fixture(scope="module")
def switchback(tmp_path_factory):
    return _scene_world(
        tmp_path_factory.mktemp("switchback"), "switchback", SWITCHBACK_SCAD, SWITCHBACK_YAML
    )


def _on_the_floor(world, states: np.ndarray) -> bool:
    """Every foot of every state, every 1 cm and every 0.17 rad of a spin (test_planning's
    dense_states), stands on the floor, not on a wall: ray casts on the physics mesh."""
    from test_planning import dense_states

    dense = dense_states(states)
    feet = world.robot.foot_points_xy
    c, s = np.cos(dense[:, 2:3]), np.sin(dense[:, 2:3])
    pts = np.stack(
        [
            dense[:, :1] + c * feet[:, 0] - s * feet[:, 1],
            dense[:, 1:2] + s * feet[:, 0] + c * feet[:, 1],
        ],
        axis=-1,
    ).reshape(-1, 2)
    with world.simulation() as sim:
        z, _ = sim.surface_heights(pts, top=2.0)
    return bool(np.all(z < 0.005))


def _spins_are_valid(world, planned) -> bool:
    """Every heading each spin of the plan passes through is valid at its point and round it
    within the spin margin, by the planner's checker (planning/_drivable.py spin_states)."""
    from roachplan.planning import check_states
    from roachplan.planning._drivable import spin_states

    cfg = world.scene.planner
    for k, yaw in planned.spins:
        before = planned.states[k]
        turn = spin_states(before[:2], before[2], yaw, cfg.spin_margin, 0.05)
        if not check_states(world.heightfield, world.footprint, cfg.validity, turn).valid.all():
            return False
    return True


def test_a_dead_end_too_narrow_for_arcs_is_left_by_a_turn_on_the_spot(dead_end):
    from roachplan.experiments import finish_trial
    from roachplan.planning import check_states

    scene = dead_end.scene
    arcs_only = plan(dead_end, seed=0, planner=dataclasses.replace(scene.planner, spin_margin=None))
    assert not arcs_only.found and "none the robot can follow" in arcs_only.message
    planned = plan(dead_end, seed=0)
    assert planned.found, planned.message
    assert "1 turn on the spot" in planned.message
    assert len(planned.spins) == 1
    k, yaw = planned.spins[0]
    assert k == 0 and abs(abs(yaw) - math.pi) < 0.3  # at the start, half a turn round
    # The spin is carried by the states: the same position twice, the heading turned.
    np.testing.assert_allclose(planned.states[0], scene.start, atol=1e-9)
    np.testing.assert_allclose(planned.states[1, :2], planned.states[0, :2], atol=1e-12)
    np.testing.assert_allclose(planned.path_xyz[1], planned.path_xyz[0], atol=1e-12)
    assert planned.states[1, 2] == yaw
    np.testing.assert_allclose(planned.states[-1, :2], scene.goal[:2], atol=1e-9)
    valid = check_states(
        dead_end.heightfield, dead_end.footprint, scene.planner.validity, planned.states
    ).valid
    assert valid.all() and _spins_are_valid(dead_end, planned)
    assert _on_the_floor(dead_end, planned.states)
    assert max_curvature(planned.states[1:]) <= 1 / scene.planner.turning_radius * 1.05

    result = finish_trial(dead_end, planned, start=scene.start, goal=scene.goal)
    assert result.outcome == "success", result.reason
    assert result.spins == planned.spins and result.to_json()["spins"] == [[k, yaw]]
    track = np.array([p[1:3] for p in result.trajectory])
    # It turned where it stood, in the corridor, and never walked into the closed end.
    assert track[:, 0].max() < scene.start[0] + 0.04
    assert np.abs(track[track[:, 0] > -0.3, 1]).max() < 0.11 - 0.035


def test_a_plan_with_spins_and_its_trial_are_the_same_for_the_same_seed(dead_end):
    from roachplan.experiments import run_trial

    a, b = (plan(dead_end, seed=3) for _ in range(2))
    assert a.spins == b.spins and np.array_equal(a.states, b.states)
    first, second = (run_trial(dead_end, seed=3) for _ in range(2))
    assert first.outcome == "success"
    assert first.trajectory == second.trajectory and first.energy == second.energy
    assert first.spins == second.spins == a.spins


def test_spins_mid_path_are_driven_where_the_route_turns_back(switchback):
    """Where the second corridor turns back 150 degrees, some routes' key poses leave no room
    for an arc (others do); those plans turn on the spot there and drive through."""
    from roachplan.experiments import finish_trial

    scene = switchback.scene
    mid = [
        p
        for p in (plan(switchback, seed=s) for s in range(6))
        if p.found and any(k > 0 for k, _ in p.spins)
    ]
    assert mid, "no plan of seeds 0-5 turned on the spot along the way"
    for planned in mid:
        for k, yaw in planned.spins:
            assert np.array_equal(planned.path_xyz[k], planned.path_xyz[k + 1])
            assert planned.states[k + 1, 2] == yaw
        assert _spins_are_valid(switchback, planned) and _on_the_floor(switchback, planned.states)
        result = finish_trial(switchback, planned, start=scene.start, goal=scene.goal)
        assert result.outcome == "success", (planned.seed, result.reason)


@pytest.mark.parametrize("planner", ["prm", "rrtconnect"])
def test_plans_that_need_no_spin_are_as_without_spins(world, planner):
    cfg = dataclasses.replace(world.scene.planner, name=planner)
    for seed in range(4):
        with_spins = plan(world, seed=seed, planner=cfg)
        arcs_only = plan(world, seed=seed, planner=dataclasses.replace(cfg, spin_margin=None))
        assert with_spins.found and with_spins.spins == ()
        assert np.array_equal(with_spins.states, arcs_only.states)
        assert np.array_equal(with_spins.path_xyz, arcs_only.path_xyz)
        assert with_spins.message == arcs_only.message


def test_start_and_goal_that_coincide_make_a_trivial_plan_and_a_trial_that_succeeds(world):
    from roachplan.experiments import run_trial

    start = world.scene.start
    same = plan(world, seed=0, start=start, goal=start)
    assert same.found and "start and goal coincide" in same.message
    assert same.states.shape == (1, 3) and same.spins == ()
    trial = run_trial(world, seed=0, start=start, goal=start)
    assert (trial.outcome, trial.drive_time, trial.energy) == ("success", 0.0, 0.0)
    # 3 cm away, within the driver's 5 cm goal radius: reached where the robot stands.
    near = (start[0] + 0.03, start[1], start[2])
    assert "coincide" in plan(world, seed=0, start=start, goal=near).message
    assert run_trial(world, seed=0, start=start, goal=near).drive_time == 0.0
    # Facing another way: a turn on the spot to the goal's heading, then success.
    turned = (start[0], start[1], start[2] + math.pi / 2)
    spin = plan(world, seed=0, start=start, goal=turned)
    assert spin.found and "turn on the spot of 90 deg" in spin.message
    assert spin.spins == ((0, turned[2]),) and spin.states.shape == (2, 3)
    frames = []
    trial = run_trial(world, seed=0, start=start, goal=turned, on_frame=frames.append)
    assert trial.outcome == "success" and 0.5 < trial.drive_time < 3.0
    x, y, z, w = frames[-1].quat_world_body
    yaw = math.atan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z))
    assert abs(math.remainder(yaw - turned[2], 2 * math.pi)) < 0.2
    assert trial.relative_energy < 5.0  # against a walk of the goal radius, not of 0 m
    # The report's raw plan: OMPL's two states, no spin.
    raw = plan(
        world,
        seed=0,
        start=start,
        goal=turned,
        planner=dataclasses.replace(world.scene.planner, turning_radius=None),
    )
    assert raw.found and raw.spins == () and raw.states.shape == (2, 3)


def test_plan_and_trial_json_carry_the_spins(tmp_path):
    from conftest import roachplan

    (tmp_path / "dead_end.scad").write_text(DEAD_END_SCAD)
    (tmp_path / "dead_end.yaml").write_text(DEAD_END_YAML)
    scene = str(tmp_path / "dead_end.yaml")
    out = roachplan("plan", "--scene", scene, "--json")
    assert out.returncode == 0, out.stderr
    planned = json.loads(out.stdout)
    assert len(planned["spins"]) == 1 and planned["spins"][0][0] == 0
    assert "1 turn on the spot" in planned["message"]
    k = planned["spins"][0][0]
    assert planned["path"][k] == planned["path"][k + 1]
    out = roachplan("trial", "--scene", scene, "--json")
    assert out.returncode == 0, out.stderr
    trial = json.loads(out.stdout)
    assert trial["outcome"] == "success"
    assert [k for k, _ in trial["spins"]] == [k for k, _ in planned["spins"]]
    # (plan --json rounds headings to 5 decimals, as its states)
    assert trial["spins"][0][1] == pytest.approx(planned["spins"][0][1], abs=1e-5)
