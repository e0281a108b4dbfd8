"""Planning on terrain (issue 5): every planner, the terrain sampler, validity, routes, the CLI.

The path checks here do not use the planner's height field: they cast rays at the robot's feet
onto the physics mesh in PyBullet, and compare with the double bridge's known geometry
(bridges |x| in [0.5, 1.0], y in [-0.5, 0.5], 0.2 m high; the gap between them has no terrain).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from conftest import roachplan
from roachplan.experiments import plan, plan_many
from roachplan.planning import PLANNER_NAMES, homology_signature

BRIDGE_HALF_LENGTH = 0.5
GAP_HALF_WIDTH = 0.5


def dense_states(states: np.ndarray, step: float = 0.01) -> np.ndarray:
    """(N, 3) x, y, yaw every `step` metres along the straight motions between states."""
    out = [states[:1]]
    for a, b in zip(states[:-1], states[1:], strict=True):
        dyaw = (b[2] - a[2] + math.pi) % (2 * math.pi) - math.pi
        n = max(1, math.ceil(max(math.dist(a[:2], b[:2]), abs(dyaw) * 0.06) / step))
        f = np.arange(1, n + 1)[:, None] / n
        out.append(a + f * np.array([b[0] - a[0], b[1] - a[1], dyaw]))
    return np.concatenate(out)


def independent_check(world, states: np.ndarray) -> list[str]:
    """Problems of a path of (x, y, yaw) states, found by ray casts on the physics mesh."""
    dense = dense_states(states)
    feet = world.robot.foot_points_xy  # (6, 2) body frame
    c, s = np.cos(dense[:, 2:3]), np.sin(dense[:, 2:3])
    fx = dense[:, :1] + c * feet[:, 0] - s * feet[:, 1]
    fy = dense[:, 1:2] + s * feet[:, 0] + c * feet[:, 1]
    # A foot is a 3 mm sphere on a 1 cm height field: it stands if the terrain reaches within
    # 5 mm of its centre, so each foot casts five rays (centre and 5 mm to four sides) and
    # stands on the highest hit.
    centres = np.stack([fx, fy], axis=-1).reshape(-1, 1, 2)
    patch = np.array([[0, 0], [0.005, 0], [-0.005, 0], [0, 0.005], [0, -0.005]])
    pts = (centres + patch).reshape(-1, 2)
    with world.simulation() as sim:
        z, on_terrain = sim.surface_heights(pts, top=2.0)
    z = z.reshape(len(dense), 6, 5)
    on_terrain = on_terrain.reshape(len(dense), 6, 5)
    best = np.argmax(z, axis=2)[..., None]
    z = np.take_along_axis(z, best, axis=2)[..., 0]
    z[np.isinf(z)] = np.nan
    on_terrain = np.take_along_axis(on_terrain, best, axis=2)[..., 0]
    problems = []
    (xa, ya), (xb, yb) = world.scene.bounds
    if not np.all(
        (dense[:, 0] >= xa) & (dense[:, 0] <= xb) & (dense[:, 1] >= ya) & (dense[:, 1] <= yb)
    ):
        problems.append("leaves the planning bounds")
    if np.isnan(z).any():
        problems.append("a foot over nothing at all")
    in_gap = (np.abs(dense[:, 0]) < GAP_HALF_WIDTH) & (np.abs(dense[:, 1]) < BRIDGE_HALF_LENGTH)
    if in_gap.any():
        problems.append(f"centre in the gap at {dense[in_gap][0, :2]}")
    # Over the bridges' span every foot stands on a bridge, not on the floor of the gap.
    span = np.abs(fy) < BRIDGE_HALF_LENGTH - 0.01
    if not np.all(on_terrain[span] & (z[span] > 0.19)):
        problems.append("a foot over the gap")
    # Nowhere a foot over a drop: the feet's ground lies within 3 cm of the plane fitted
    # through it (on a ramp the plane tilts; over an edge one foot drops 0.2 m).
    design = np.stack([np.ones_like(fx), fx, fy], axis=-1)  # (N, 6, 3)
    zz = np.nan_to_num(z)
    coef = np.array([np.linalg.lstsq(d, h, rcond=None)[0] for d, h in zip(design, zz)])
    residual = np.abs(zz - np.einsum("nfk,nk->nf", design, coef))
    if np.any(residual > 0.03):
        problems.append(f"a foot {residual.max():.3f} m off the plane of the others")
    return problems


# Every test on `runs` is slow: the fixture plans 11 times with every planner (20-70 s).
@pytest.fixture(scope="module")
def runs(world):
    """Every planner, seeds 0-9 on the double bridge, then seed 0 again: the planners' own
    paths (turning_radius None; drivable plans are tested in test_drivable.py)."""
    out = {}
    for name in PLANNER_NAMES:
        cfg = dataclasses.replace(world.scene.planner, name=name, turning_radius=None)
        plans = [plan(world, seed=seed, planner=cfg) for seed in range(10)]
        again = plan(world, seed=0, planner=cfg)
        out[name] = (plans, again)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", PLANNER_NAMES)
def test_every_planner_finds_valid_paths_for_ten_seeds(world, runs, name):
    plans, _ = runs[name]
    assert all(pl.found for pl in plans), [pl.message for pl in plans if not pl.found]
    for pl in plans:
        assert independent_check(world, pl.states) == [], f"seed {pl.seed}"
        np.testing.assert_allclose(pl.states[0], world.scene.start, atol=1e-9)
        np.testing.assert_allclose(pl.states[-1], world.scene.goal, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("name", PLANNER_NAMES)
def test_every_planner_draws_from_the_terrain_sampler(runs, name):
    plans, _ = runs[name]
    assert all(pl.sampler_calls > 0 for pl in plans), [pl.sampler_calls for pl in plans]


@pytest.mark.slow
@pytest.mark.parametrize("name", PLANNER_NAMES)
def test_same_seed_same_path_after_other_plans_in_the_process(runs, name):
    plans, again = runs[name]
    np.testing.assert_array_equal(again.states, plans[0].states)
    # ... and the seeds matter: ten seeds give more than one path.
    assert len({pl.states.tobytes() for pl in plans}) > 1


@pytest.mark.slow
def test_both_bridges_are_found_and_labelled(world, runs):
    for pl in runs["prm"][0]:
        route = world.route(pl.path_xyz[:, :2])
        side = np.median(pl.path_xyz[np.abs(pl.path_xyz[:, 1]) < 0.4, 0])
        assert route == ("left_bridge" if side < 0 else "right_bridge")
        # The homology signature round the one hole (the gap) agrees with the named route.
        assert pl.signature == ((0,) if side < 0 else (1,))
    routes = {world.route(pl.path_xyz[:, :2]) for pl in runs["prm"][0]}
    assert routes == {"left_bridge", "right_bridge"}


def test_the_double_bridge_has_one_hole_the_gap(world):
    holes = world.regions.holes
    assert holes.shape == (1, 2)
    assert np.all(np.abs(holes[0]) < 0.45)


def test_homology_signature_counts_signed_crossings():
    holes = np.array([[0.0, 0.0]])
    right = np.array([[0.0, -1.0], [1.0, -0.5], [1.0, 0.5], [0.0, 1.0]])
    left = right * [-1, 1]
    loop = np.array(
        [[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 0.0], [0.0, 1.0]]
    )
    assert homology_signature(holes, right) == (1,)
    assert homology_signature(holes, left) == (0,)
    assert homology_signature(holes, right[::-1]) == (-1,)
    assert homology_signature(holes, loop) == (2,)  # round the hole once more


def test_plan_many_returns_distinct_labelled_paths(world):
    plans = plan_many(world, 6, seed=0)
    assert len(plans) == 6
    shapes = [lp.plan.path_xyz for lp in plans]
    for i in range(6):
        for j in range(i):
            assert not (len(shapes[i]) == len(shapes[j]) and np.allclose(shapes[i], shapes[j]))
    assert {lp.route for lp in plans} == {"left_bridge", "right_bridge"}
    assert len({lp.plan.seed for lp in plans}) == 6


def test_simplify_and_smooth_keep_the_path_valid(world):
    def length(pl):
        return float(np.sum(np.linalg.norm(np.diff(pl.states[:, :2], axis=0), axis=1)))

    # OMPL's own simplification and smoothing of the planner's path (not drivable plans).
    own = dataclasses.replace(world.scene.planner, turning_radius=None)
    shortened = []
    for seed in range(4):
        raw = plan(world, seed=seed, planner=own)
        short = plan(world, seed=seed, planner=dataclasses.replace(own, simplify=True))
        assert length(short) <= length(raw) + 1e-9
        assert independent_check(world, short.states) == []
        shortened.append(length(raw) - length(short))
    assert max(shortened) > 0.05
    smooth = plan(world, seed=2, planner=dataclasses.replace(own, simplify=True, smooth=True))
    assert len(smooth.states) > len(short.states)  # B-spline smoothing adds states
    assert independent_check(world, smooth.states) == []
    # Waypoints carry z on the terrain surface: 0.2 m on the bridges.
    on_bridge = np.abs(smooth.path_xyz[:, 1]) < BRIDGE_HALF_LENGTH - 0.05
    np.testing.assert_allclose(smooth.path_xyz[on_bridge, 2], 0.2, atol=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ("--start=-0.46,0,0",),
            "start (-0.460, 0.000, yaw 0 deg) is invalid: a foot has no ground under it (leg L",
        ),
        (
            ("--goal=5,5,90",),
            "goal (5.000, 5.000) is invalid: outside the planning area x in [-1, 1]",
        ),
        (
            ("--scene", "heightmap", "--start=-0.62,0,0"),
            "start (-0.620, 0.000, yaw 0 deg) is invalid: ground too steep",
        ),
        (("--start", "1,2"), "--start '1,2': expected x,y,yaw_deg"),
        (("--count", "0"), "--count 0: expected a whole number from 1 to 100"),
    ],
)
def test_invalid_requests_name_what_failed(args, message):
    out = roachplan("plan", *args)
    assert out.returncode == 2
    assert message in out.stderr, out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.slow
def test_plan_cli_json_single_and_many():
    one = roachplan(
        "plan", "--scene", "double_bridge", "--planner", "rrtconnect", "--seed", "4", "--json"
    )
    assert one.returncode == 0, one.stderr
    d = json.loads(one.stdout)
    path = np.array(d["path"])
    assert path.shape[1] == 3 and len(path) > 20
    np.testing.assert_allclose(path[[0, -1], :2], [[0.0, -1.6], [0.0, 1.6]], atol=1e-6)
    assert d["route"] in ("left_bridge", "right_bridge") and d["seed"] == 4

    many = roachplan("plan", "--count", "4", "--planner", "rrtconnect", "--seed", "4", "--json")
    assert many.returncode == 0, many.stderr
    paths = json.loads(many.stdout)["paths"]
    assert len(paths) == 4
    assert paths[0]["path"] == d["path"]  # the first of many is the single plan of that seed
    for entry in paths:
        side = np.median([x for x, y, _ in entry["path"] if abs(y) < 0.4])
        assert entry["route"] == ("left_bridge" if side < 0 else "right_bridge")


def test_plans_started_together_are_each_the_plan_it_is_alone(world):
    """Several planning children at once (choose's two legs of a via plan, plan_many's next
    attempt beside this one) each give the path the same seed gives planned alone, and
    plan_many's plans are its seeds' single plans, in order."""
    from roachplan.experiments._trial import start_plan

    seeds = (3, 4, 5)
    children = [start_plan(world, seed=s) for s in seeds]
    together = [c.result() for c in children]
    alone = [plan(world, seed=s) for s in seeds]
    for s, a, b in zip(seeds, together, alone, strict=True):
        assert a.found and a.seed == s and np.array_equal(a.path_xyz, b.path_xyz), s
    many = plan_many(world, 3, seed=3, min_separation=0.0)
    assert [lp.plan.seed for lp in many] == list(seeds)
    for lp, b in zip(many, alone, strict=True):
        assert np.array_equal(lp.plan.path_xyz, b.path_xyz)


def test_a_threaded_process_plans_through_the_fork_server_with_the_same_result(world, monkeypatch):
    """Forking a process with other threads is unsafe (Ray workers, the web server): there, a
    plan runs in a child of the clean fork server, and gives the very path a fork gives."""
    import functools
    import threading

    from roachplan.planning import _ompl, plan_path
    from roachplan.processes import _child

    sc = world.scene
    plan_with = functools.partial(
        plan_path,
        world.heightfield,
        world.footprint,
        sc.start,
        sc.goal,
        bounds=sc.bounds,
        cfg=sc.planner,
        seed=5,
        regions=world.regions,
    )
    forked = plan_with(isolation="fork")
    served = plan_with(isolation="forkserver")
    assert forked.found and np.array_equal(forked.path_xyz, served.path_xyz)

    used = []

    class Recorded(_child.Child):  # (records how each child started)
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            if self.how == "forkserver":
                used.append(1)

    monkeypatch.setattr(_ompl, "Child", Recorded)  # (the planner's children start there)
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        auto = plan(world, seed=5)
    finally:
        stop.set()
        other.join()
    assert used and np.array_equal(auto.path_xyz, forked.path_xyz)


@pytest.mark.parametrize("name", ["prm", "rrtconnect"])
def test_keep_roadmap_returns_the_planners_graph(world, name):
    """The graph the app can show: edges between states in the planning area, the start among
    them, and more edges than the path has."""
    # The planner's own path (a drivable one is sampled every 5 cm: more states than edges).
    cfg = dataclasses.replace(
        world.scene.planner, name=name, keep_roadmap=True, turning_radius=None
    )
    planned = plan(world, seed=2, planner=cfg)
    graph = planned.roadmap
    assert planned.found and graph.shape[1:] == (2, 2) and len(graph) >= len(planned.states) - 1
    (xa, ya), (xb, yb) = world.scene.bounds
    pts = graph.reshape(-1, 2)
    assert np.all((pts[:, 0] >= xa - 1e-9) & (pts[:, 0] <= xb + 1e-9))
    assert np.all((pts[:, 1] >= ya - 1e-9) & (pts[:, 1] <= yb + 1e-9))
    assert np.min(np.linalg.norm(pts - np.array(world.scene.start[:2]), axis=1)) < 1e-9
    assert len(plan(world, seed=2).roadmap) == 0  # only when asked


def test_a_heading_of_180_degrees_is_planned_for(world):
    # OMPL's SO(2) bounds are [-pi, pi): a goal at exactly pi used to be skipped as out of
    # bounds, and the planner searched until its time limit.
    x, y, _ = world.scene.goal
    planned = plan(world, seed=0, goal=(x, y, math.pi))
    assert planned.found, planned.message
