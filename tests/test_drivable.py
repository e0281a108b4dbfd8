"""Drivable plans and the tracking driver (issue 18): Dubins curves as OMPL computes them,
paths no tighter than the turning radius and valid by the independent ray-cast check, and a
driver that follows a hairpin without circling."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from roachplan.experiments import plan
from roachplan.experiments._trial import drive
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
                st.setX(x), st.setY(y), st.setYaw(yaw)
            assert curve.length == pytest.approx(space.distance(a, b), abs=1e-9)
            samples = curve.sample(0.01)
            assert max_curvature(samples) <= 1 / 0.15 * 1.02
    finally:
        space.freeState(a)
        space.freeState(b)


@pytest.mark.parametrize("planner", ["prm", "rrtconnect", "stride"])
def test_drivable_paths_turn_no_tighter_than_the_radius_and_pass_the_ray_cast_check(
    world, planner
):
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
    from roachplan.sim import DriverConfig
    from roachplan.sim._driver import _Tracking

    path = np.column_stack([np.linspace(0, 1, 21), np.zeros(21), np.zeros(21)])
    t = _Tracking(path, DriverConfig())
    t.s = t.total
    assert t.update((1.0, 0.07, 0.0)) is None  # abreast, 7 cm off: not yet decided
    assert t.s == pytest.approx(t.total)
    assert t.update((1.2, 0.2, 0.0))[0] == "missed"
