"""The simulator's terrain sized to the work (scenes/_sim_terrain.py): a capture of any size is a
terrain the engine takes, whose heights agree with the planner's where the robot stands."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import roachplan, synth_capture
from roachplan.planning import HeightField, heightfield_from_mesh
from roachplan.scenes import (
    SIM_MAX_TOLERANCE,
    SIM_MAX_TRIANGLES,
    build_world,
    crop_mesh,
    level_ground,
    load_scene,
    sim_terrain,
    simplified_heightfield_mesh,
)
from roachplan.sim import RobotConfig, SimConfig, SimError, make_simulation


def grid_mesh(n: int, spacing: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n grid of vertices at z = 0, two triangles a cell."""
    xs, ys = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing)
    v = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(n * n)])
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[:-1, 1:].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel()
    return v, np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])


def rasterised(v: np.ndarray, f: np.ndarray, hf: HeightField) -> np.ndarray:
    """The triangles' heights at hf's grid points [m] (NaN where none covers one)."""
    ny, nx = hf.heights.shape
    r = hf.resolution
    return heightfield_from_mesh(
        v,
        f,
        xy_min=(hf.x0, hf.y0),
        xy_max=(hf.x0 + (nx - 1) * r + 1e-9, hf.y0 + (ny - 1) * r + 1e-9),
        resolution=r,
        ground_height=None,
    ).heights


def terrain_field(seed: int = 0, noise: float = 0.0) -> HeightField:
    """A 3 m x 2 m field at 1 cm: a floor, a 5 cm step, a 10 deg ramp, a hole, and (noise > 0)
    a patch of sensor noise of that standard deviation [m] (with its noise map)."""
    rng = np.random.default_rng(seed)
    ny, nx = 201, 301
    x = np.arange(nx) * 0.01
    y = np.arange(ny) * 0.01
    h = np.zeros((ny, nx))
    h[:, x > 1.0] = 0.05  # a step
    ramp = (x > 2.0) & (x < 2.6)
    h[:, ramp] = 0.05 + np.tan(np.radians(10)) * (x[ramp] - 2.0)
    h[(y > 0.8) & (y < 1.0), :][:, (x > 0.3) & (x < 0.5)] = np.nan
    h[80:100, 30:50] = np.nan  # a dropout
    sigma = np.zeros((ny, nx))
    if noise > 0:
        patch = (slice(120, 200), slice(110, 190))
        h[patch] += rng.normal(0.0, noise, h[patch].shape)
        sigma[patch] = noise
    return HeightField(0.0, 0.0, 0.01, h, sigma if noise > 0 else None)


def test_a_mesh_moved_up_and_down_rasterises_from_its_cover_as_from_scratch():
    """A rollout's capture is the same mesh with each vertex moved up or down by the drawn
    sensor error: its height field from the kept grid cover is, bit for bit, the one a fresh
    rasterising gives (the overhead rule and the noise map too)."""
    from roachplan.planning import grid_cover, heightfield_from_cover

    v, f = grid_mesh(40, 0.013)
    v[:, 2] = 0.02 * np.sin(v[:, 0] * 9) * np.cos(v[:, 1] * 7)
    box = {"xy_min": (0.0, 0.0), "xy_max": (0.5, 0.5), "resolution": 0.004}
    cover = grid_cover(v, f, **box)
    rng = np.random.default_rng(3)
    for _ in range(3):
        moved = v.copy()
        moved[:, 2] += rng.normal(0.0, 0.004, len(v))
        sigma = rng.uniform(0.0, 0.003, len(v))
        for overhead in (None, 0.005):
            fresh = heightfield_from_mesh(
                moved, f, **box, ground_height=0.0, vertex_noise=sigma, overhead=overhead
            )
            kept = heightfield_from_cover(
                cover, moved[:, 2], ground_height=0.0, vertex_noise=sigma, overhead=overhead
            )
            assert np.array_equal(fresh.heights, kept.heights, equal_nan=True)
            assert fresh.noise is not None and kept.noise is not None
            assert np.array_equal(fresh.noise, kept.noise)
        unmoved = heightfield_from_cover(cover, v[:, 2], ground_height=0.0)
        assert np.any(fresh.heights != unmoved.heights)  # (the heights did move)


def test_flat_ground_becomes_few_triangles_within_the_tolerance():
    hf = terrain_field()
    v, f, err = simplified_heightfield_mesh(hf)
    cells = np.isfinite(hf.heights).sum()
    assert len(f) < 0.1 * 2 * cells  # a 1 cm grid would be two triangles a cell
    back = rasterised(v, f, hf)
    on = np.isfinite(hf.heights)
    diff = np.abs(back - hf.heights)[on]
    # Every grid point with a surface is covered, except where a hole leaves a lone point.
    assert np.isnan(diff).mean() < 0.01
    assert np.nanmax(diff) <= 0.002 + 1e-9  # SIM_MIN_TOLERANCE: no sensor noise on this field
    assert err == pytest.approx(np.nanmax(diff), abs=1e-6)
    assert np.all(np.isnan(back[~on]))  # no surface made up over the holes


def test_noisy_ground_is_kept_within_its_noise():
    sigma = 0.003
    hf = terrain_field(noise=sigma)
    v, f, err = simplified_heightfield_mesh(hf)
    diff = np.abs(rasterised(v, f, hf) - hf.heights)
    assert np.nanmax(diff) <= min(3 * sigma, SIM_MAX_TOLERANCE) + 1e-9
    assert np.nanmax(diff) <= err + 1e-9  # the reported error is never an understatement


def test_the_cap_raises_the_tolerance_rather_than_the_count():
    hf = terrain_field(noise=0.01)
    free = simplified_heightfield_mesh(hf, max_triangles=10**9)[1]
    v, f, err = simplified_heightfield_mesh(hf, max_triangles=len(free) // 2)
    assert len(f) <= len(free) // 2
    diff = np.abs(rasterised(v, f, hf) - hf.heights)
    assert np.nanmax(diff) <= err + 1e-9
    assert err > SIM_MAX_TOLERANCE  # the bound was loosened, and says so


def test_walls_are_coarser_than_where_the_robot_stands():
    hf = terrain_field(noise=0.004)
    ny, nx = hf.heights.shape
    stand = np.zeros((ny, nx), dtype=bool)
    stand[:, :100] = True  # only the left floor is walked on
    v, f, err = simplified_heightfield_mesh(hf, ground=stand)
    v_all, f_all, _ = simplified_heightfield_mesh(hf)
    assert len(f) < len(f_all)
    diff = np.abs(rasterised(v, f, hf) - hf.heights)
    assert np.nanmax(diff[stand]) <= err + 1e-9


def test_crop_keeps_the_triangles_near_the_area():
    v, f = grid_mesh(101, 0.05)  # 5 m x 5 m
    cv, cf = crop_mesh(v, f, ((1.0, 1.0), (2.0, 2.0)), 0.5)
    assert 0 < len(cf) < len(f)
    assert cv[:, :2].min() >= 0.5 - 0.05 - 1e-9 and cv[:, :2].max() <= 2.5 + 0.05 + 1e-9
    assert cf.max() < len(cv)


def test_a_library_scene_is_simulated_on_its_own_mesh():
    """PyBullet's results on the library scenes stay what they were: same triangles."""
    world = build_world(load_scene("double_bridge_rough"))
    terrain = world.sim_terrain
    assert terrain.kind == "mesh" and terrain.note() == ""
    np.testing.assert_array_equal(terrain.faces, world.mesh.faces)
    np.testing.assert_array_equal(terrain.vertices, world.mesh.vertices)


def test_a_large_mesh_is_given_to_the_engine_in_a_size_it_takes():
    v, f = grid_mesh(401)  # 318k triangles: PyBullet refuses this mesh itself
    hf = HeightField(0.0, 0.0, 0.01, np.zeros((401, 401)))
    terrain = sim_terrain(v, f, hf, ((0.5, 0.5), (3.5, 3.5)))
    assert terrain.kind == "heightfield" and len(terrain.faces) <= SIM_MAX_TRIANGLES
    assert terrain.max_error == 0.0
    assert "height field" in terrain.note()
    with make_simulation(
        terrain.vertices, terrain.faces, ground_height=None, robot=RobotConfig(), cfg=SimConfig()
    ) as sim:
        sim.reset(2.0, 2.0, 0.0)
        sim.advance(100)
        assert abs(sim.body_pose()[0][2] - RobotConfig().standing_height) < 0.02


def test_a_mesh_the_engine_refuses_is_a_clear_error_and_nothing_on_stdout(capfd):
    v, f = grid_mesh(401)
    with pytest.raises(SimError, match="PyBullet refused the terrain mesh .* smaller bounds"):
        make_simulation(v, f, ground_height=None, robot=RobotConfig(), cfg=SimConfig())
    assert capfd.readouterr().out == ""


def test_level_ground_is_the_floor_and_the_ramp_not_the_step():
    hf = terrain_field(noise=0.003)
    level = level_ground(hf, max_slope_deg=25.0)
    x = hf.x0 + np.arange(hf.heights.shape[1]) * hf.resolution
    assert level[150, (x > 0.1) & (x < 0.9)].all()  # the floor, and its noisy patch
    assert level[50, (x > 2.05) & (x < 2.55)].all()  # the 10 deg ramp
    assert not level[50, np.argmin(np.abs(x - 1.0))]  # the 5 cm step's edge
    assert not level[90, 40]  # the dropout


@pytest.mark.slow
def test_a_wide_kinect_capture_is_planned_and_driven_with_json_alone_on_stdout(tmp_path):
    """The report's setting (a Kinect 2 looking down at the double bridge from 3.2 m) at the
    sensor's own 512 x 424: its mesh (~300k triangles) was refused by PyBullet as "internal
    error", and PyBullet's warnings broke --json."""
    cap = synth_capture(tmp_path / "cap.png", "double_bridge", "kinect2-sd")
    done = roachplan("trial", "--scene", str(cap), "--seed", "1", "--json")
    assert done.returncode == 0, done.stderr
    trial = json.loads(done.stdout)  # nothing but the JSON on stdout
    assert trial["path_found"], trial["reason"]
    assert trial["outcome"] in {"success", "fell", "flipped", "stuck", "timeout", "missed"}
    start, goal = np.asarray(trial["start"][:2]), np.asarray(trial["goal"][:2])
    assert np.linalg.norm(goal - start) >= 1.0

    world = build_world(load_scene(str(cap)))
    terrain = world.sim_terrain
    assert len(world.mesh.faces) > SIM_MAX_TRIANGLES  # (the case this is about)
    assert terrain.kind == "heightfield" and len(terrain.faces) <= SIM_MAX_TRIANGLES
    # Where the robot can stand, the engine's heights are the planner's, within the error the
    # note states, and that within the sensor's noise at this range (SIM_MAX_TOLERANCE, raised
    # at most 2.5x by the cap).
    hf, regions = world.heightfield, world.regions
    # The grid points where the robot's centre can stand (the standable map's 4 cm cells fall
    # on the height field's 1 cm grid), and where the ground is level enough to stand on.
    centres = regions.cell_centres(regions.standable)
    i = np.round((centres[:, 0] - hf.x0) / hf.resolution).astype(int)
    j = np.round((centres[:, 1] - hf.y0) / hf.resolution).astype(int)
    feet = level_ground(hf, world.scene.planner.validity.max_slope_deg)
    feet[j, i] = True
    diff = np.abs(rasterised(terrain.vertices, terrain.faces, hf) - hf.heights)[feet]
    assert np.nanmax(diff) <= terrain.max_error + 1e-9
    assert terrain.max_error <= 2.5 * SIM_MAX_TOLERANCE
    assert np.isnan(diff).mean() < 0.01
