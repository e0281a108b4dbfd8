"""Start and goal picked on a terrain nobody placed them on (scenes/_autopose.py):
in the largest region where the robot can stand *and* move, as far apart as it allows, joined
by a plan, within seconds; and where nothing can be joined, a message that says why and how
far apart two places of the region are."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import trimesh

from conftest import roachplan, synth_capture
from roachplan.planning import HeightField, PlanResult, check_states, standable_map
from roachplan.scenes import World, load_scene, pose_problem
from roachplan.scenes import _autopose as autopose
from roachplan.scenes._autopose import MIN_AUTO_DISTANCE, _largest_region, pick_start_goal


def capture_like_floor(
    size: tuple[float, float] = (8.0, 6.0), *, seed: int = 0, crate: bool = True
) -> World:
    """A world like a depth capture of a room's floor, made straight as a height field (no
    meshing: a second to make): heights with 1.5 mm of sensor noise, 3 cm dropouts (no
    surface), ten times as many on the far floor (y > a quarter of the depth) as near the
    camera (about 97 % and 70 % of random poses valid there, as on the library's captures),
    a crate 1 m x 0.6 m in the middle; no ground plane, start and goal left to pick."""
    rng = np.random.default_rng(seed)
    res, margin = 0.01, 0.15
    width, depth = size
    x0, y0 = -width / 2 - margin, -depth / 2 - margin
    nx = round((width + 2 * margin) / res) + 1
    ny = round((depth + 2 * margin) / res) + 1
    xs, ys = x0 + np.arange(nx) * res, y0 + np.arange(ny) * res
    z = rng.normal(0.0, 0.0015, (ny, nx))
    rate = np.where(ys[:, None] > depth / 4, 0.004, 0.0003)
    speck = rng.random((ny, nx)) < rate
    dropout = np.zeros_like(speck)
    for dj in range(3):
        for di in range(3):
            dropout |= np.roll(np.roll(speck, dj, axis=0), di, axis=1)
    z[dropout] = np.nan
    if crate:
        z[np.ix_(np.abs(ys) < 0.3, np.abs(xs) < 0.5)] = 0.3
    hf = HeightField(x0=x0, y0=y0, resolution=res, heights=z, noise=np.full_like(z, 0.0015))
    return _world_of(hf, ((-width / 2, -depth / 2), (width / 2, depth / 2)), seed)


def _world_of(hf: HeightField, bounds, seed: int = 0) -> World:
    """A world of a height field alone (no ground plane, no mesh), start and goal to pick."""
    flat = load_scene("flat")
    scene = dataclasses.replace(
        flat, terrain=(), ground=None, start=None, goal=None, bounds=bounds, seed=seed
    )
    return World(scene=scene, mesh=trimesh.Trimesh(), heightfield=hf, robot=scene.robot)


def with_poses(world: World, start, goal) -> World:
    return dataclasses.replace(
        world, scene=dataclasses.replace(world.scene, start=start, goal=goal)
    )


def test_the_standable_map_checks_every_cell_it_could_stand_on():
    """Cells with no surface under the body's centre are skipped: the map is the same as
    checking every cell at every yaw."""
    w = capture_like_floor((2.0, 1.6), crate=False)
    hf, fp, cfg = w.heightfield, w.footprint, w.scene.planner.validity
    sm = standable_map(hf, fp, cfg, w.bounds, (0.0, 0.0))
    (xa, ya), (xb, yb) = w.bounds
    gx, gy = np.meshgrid(np.arange(xa, xb + 1e-9, sm.cell), np.arange(ya, yb + 1e-9, sm.cell))
    yaws = np.arange(8) * np.pi / 4
    states = np.column_stack(
        [np.repeat(gx.ravel(), 8), np.repeat(gy.ravel(), 8), np.tile(yaws, gx.size)]
    )
    every = check_states(hf, fp, cfg, states).valid.reshape(*gx.shape, 8)
    assert (sm.yaw_valid == every).all()
    assert (sm.standable == every.any(axis=-1)).all()
    assert 0 < sm.standable.mean() < 1  # dropouts made some cells unstandable


def _l_shape(corner_yaws) -> np.ndarray:
    """(20, 20, 8) valid yaws: an arm along x (row 2) the robot stands on facing along it (0
    and 180 deg), an arm along y (column 2) likewise (90 and 270 deg), meeting at a corner
    cell valid at corner_yaws (indices of 45 deg steps)."""
    valid = np.zeros((20, 20, 8), dtype=bool)
    valid[2, 2:15, [0, 4]] = True
    valid[2:15, 2, [2, 6]] = True
    valid[2, 2, :] = False
    valid[2, 2, corner_yaws] = True
    return valid


@pytest.mark.parametrize("along_heading", [True, False])
def test_the_region_is_where_the_robot_can_move_not_only_stand(along_heading):
    """A corner joins the two arms only where the robot can turn on it (every heading between,
    the last heading next to the first); a strip the robot stands across but not along joins
    nothing for a robot that walks where it faces."""
    assert _largest_region(_l_shape(list(range(8))), along_heading=along_heading).sum() == 25
    assert _largest_region(_l_shape([0, 2]), along_heading=along_heading).sum() == 13
    assert _largest_region(_l_shape([6, 7, 0]), along_heading=along_heading).sum() == 25
    across = np.zeros((5, 30, 8), dtype=bool)
    across[2, :, 2] = True  # a strip along x, the robot valid on it only facing +y
    assert _largest_region(across, along_heading=along_heading).sum() == (
        1 if along_heading else 30
    )


def test_a_large_capture_like_floor_gets_start_and_goal_far_apart_that_a_plan_joins():
    """An 8 m x 6 m floor with a capture's noise and dropouts (the picker's plans used to
    spend their 5 s remaking the standable map of the whole area, and sample all of it: "no
    path within its time limit" at 1.7 m, then 1.15 m): start and goal the 4 m cap apart,
    joined by a plan of the scene's planner (the pick's own; `plan` on a capture checks the
    plan over the whole area, test_a_kinect2_qhd_capture_of_a_library_scene_gets_a_joined_pick)."""
    w = capture_like_floor()
    picked = pick_start_goal(w, seed=w.scene.seed)
    assert picked.distance == pytest.approx(autopose.MAX_AUTO_DISTANCE, abs=0.05), picked.note
    assert "picked automatically" in picked.note and "no pair further" not in picked.note
    w = with_poses(w, picked.start, picked.goal)
    assert pose_problem(w, w.start) == "" and pose_problem(w, w.goal) == ""


def test_the_pick_is_the_same_every_time():
    """Workers rebuild the world and pick again: they must get the same start and goal."""
    w = capture_like_floor((4.0, 3.0), seed=2)
    a, b = pick_start_goal(w, seed=2), pick_start_goal(w, seed=2)
    assert (a.start, a.goal) == (b.start, b.goal)
    assert a.distance >= 2.0


def test_a_narrow_floor_keeps_its_length():
    """A strip of floor 1.8 m x 0.2 m (as in front of a row of desks) with a pad 0.5 m square
    in its middle: start and goal go along the strip, not on the pad, where the robot has room
    at every heading (0.5 m apart at most there); the robot's legs reach 6.5 cm from its
    centre."""
    res = 0.01
    x0, y0 = -1.2, -0.5
    xs, ys = x0 + np.arange(241) * res, y0 + np.arange(101) * res
    floor = (np.abs(xs)[None, :] <= 0.9) & (np.abs(ys)[:, None] <= 0.1)
    floor |= (np.abs(xs)[None, :] <= 0.25) & (np.abs(ys)[:, None] <= 0.25)
    z = np.where(floor, 0.0, np.nan)
    w = _world_of(
        HeightField(x0=x0, y0=y0, resolution=res, heights=z), ((-1.05, -0.35), (1.05, 0.35))
    )
    picked = pick_start_goal(w, seed=0)
    assert picked.distance >= 1.5, picked.note


def _not_joined(why: str):
    def plan(hf, fp, start, goal, *, bounds, cfg, seed, regions=None, **_):
        return PlanResult(
            found=False,
            planner=cfg.name,
            seed=seed,
            states=np.zeros((0, 3)),
            path_xyz=np.zeros((0, 3)),
            plan_time=0.0,
            message=why,
        )

    return plan


def test_no_joinable_pair_says_why_and_how_far_apart_places_are(monkeypatch):
    w = capture_like_floor((3.0, 2.0), crate=False)
    monkeypatch.setattr(autopose, "plan_path", _not_joined("prm found no path, as a test"))
    with pytest.raises(autopose.PlanningError) as err:
        pick_start_goal(w, seed=0)
    text = str(err.value)
    assert "could not pick a start and goal the planner joins" in text
    assert "prm found no path, as a test" in text
    assert "give start and goal" in text
    # How far apart two places of the region are at most: about the floor's diagonal.
    extent = float(text.split("at most ")[1].split(" m", maxsplit=1)[0])
    assert 3.0 < extent <= math.hypot(3.0, 2.0) + 0.01
    # The pairs tried: nearly that far first (inside the region's rim), then shorter ones.
    tried = text.split("): ")[1].split(" m apart", maxsplit=1)[0]
    tried = [float(d) for d in tried.split(", ")]
    assert tried == sorted(tried, reverse=True)
    assert 0.8 * extent <= tried[0] <= extent and tried[-1] < 0.5 * tried[0]


def test_when_only_shorter_pairs_are_joined_the_longest_joined_is_picked_and_said(monkeypatch):
    w = capture_like_floor((3.0, 2.0), crate=False)
    real, refused = autopose.plan_path, _not_joined("prm found no path, as a test")

    def plan(hf, fp, start, goal, **kw):
        far = math.dist(start[:2], goal[:2]) > 1.5
        return (refused if far else real)(hf, fp, start, goal, **kw)

    monkeypatch.setattr(autopose, "plan_path", plan)
    picked = pick_start_goal(w, seed=0)
    assert MIN_AUTO_DISTANCE <= picked.distance <= 1.5
    assert "the planner joined no pair further apart" in picked.note
    assert "prm found no path, as a test" in picked.note


@pytest.mark.slow
def test_a_kinect2_qhd_capture_of_a_library_scene_gets_a_joined_pick(tmp_path):
    """The capture a user made: the double bridge seen by a Kinect v2 in QHD from
    3.2 m behind and 1.8 m up, used directly as a scene: `plan` picks start and goal at least
    1 m apart and plans between them (it said "could not pick a start and goal the planner
    joins ... (31.74 m^2): 1.45 m apart: prm found no path within its time limit")."""
    png = synth_capture(tmp_path / "qhd.png", "double_bridge", "kinect2-qhd")
    done = roachplan("plan", "--scene", str(png), "--json", timeout=600)
    assert done.returncode == 0, done.stderr
    r = json.loads(done.stdout)
    assert "picked automatically" in done.stderr
    assert len(r["path"]) >= 2
    assert math.dist(r["states"][0][:2], r["states"][-1][:2]) >= MIN_AUTO_DISTANCE


def test_the_worlds_regions_reuse_the_picks_checks_and_equal_a_fresh_map():
    """The standable map the pick made is not made a second time for World.regions (seconds
    on a capture), and what it gives is the map made afresh."""
    from roachplan.scenes import build_world
    from test_perception import REAL

    world = build_world(load_scene(str(REAL / "office_desk_160x120.pcd")))
    assert world.checked is not None
    fresh = standable_map(
        world.heightfield,
        world.footprint,
        world.scene.planner.validity,
        world.bounds,
        world.start[:2],
        min_hole_area=world.robot.body_length * world.robot.body_width * 4,
    )
    np.testing.assert_array_equal(world.regions.yaw_valid, fresh.yaw_valid)
    np.testing.assert_array_equal(world.regions.reachable, fresh.reachable)
    np.testing.assert_array_equal(world.regions.holes, fresh.holes)
    moved = dataclasses.replace(
        world, scene=dataclasses.replace(world.scene, bounds=((0, 0), (1, 1)))
    )
    assert moved.regions.yaw_valid.shape != world.regions.yaw_valid.shape  # (not reused)
