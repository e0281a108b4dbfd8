"""Algorithms 1 and 2 of Tong 2018 (section 3.5), and a walk in the real PyBullet."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from roachplan.sim import (
    DriverConfig,
    RobotConfig,
    SimConfig,
    Simulation,
    heading_error,
    motor_speeds,
    next_waypoint,
    quat_to_matrix,
)


def yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2))


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.0, 3.0])
def test_heading_error_is_the_angle_to_the_target_left_positive(yaw):
    p = np.array([1.0, 2.0, 0.3])
    for rel in (0.0, 0.4, -1.2, 2.9):
        target = p + np.array([np.cos(yaw + rel), np.sin(yaw + rel), -0.3])
        assert heading_error(p, yaw_quat(yaw), target) == pytest.approx(rel, abs=1e-9)


def test_motor_speeds_follow_algorithm_2():
    # Target to the left (theta > 0): left at omega0, right faster by exp(|p theta|).
    assert motor_speeds(0.3, 10.0, 2.0, 100.0) == pytest.approx((10.0, 10.0 * np.exp(0.6)))
    assert motor_speeds(-0.3, 10.0, 2.0, 100.0) == pytest.approx((10.0 * np.exp(0.6), 10.0))
    assert motor_speeds(0.0, 10.0, 2.0, 100.0) == pytest.approx((10.0, 10.0))
    assert motor_speeds(3.0, 10.0, 2.0, 25.0) == pytest.approx((10.0, 25.0))


def test_next_waypoint_follows_algorithm_1():
    path = np.array([[0.0, 0.0], [0.0, 0.1], [0.0, 0.2], [0.0, 0.3]])
    assert next_waypoint(path, 1, np.array([0.0, 0.0]), 0.05, 0.02) == (1, False)
    assert next_waypoint(path, 1, np.array([0.0, 0.12]), 0.05, 0.02) == (2, False)
    assert next_waypoint(path, 2, np.array([0.0, 0.17]), 0.05, 0.02) == (3, False)
    # The last point needs r_end, not r_path.
    assert next_waypoint(path, 3, np.array([0.0, 0.27]), 0.05, 0.02) == (3, False)
    assert next_waypoint(path, 3, np.array([0.0, 0.29]), 0.05, 0.02) == (3, True)


def test_roach_walks_forward_on_flat_ground_and_turns_toward_the_faster_side():
    results = {}
    for name, (left, right) in {"straight": (20.0, 20.0), "left": (20.0, 40.0)}.items():
        with Simulation.open_floor(RobotConfig(), SimConfig()) as sim:
            sim.reset(0.0, 0.0, 0.0)
            sim.set_leg_speeds(left, right)
            while sim.time < 3.0:
                sim.step()
            p, q = sim.body_pose()
            R = quat_to_matrix(q)
            results[name] = (p, np.arctan2(R[1, 0], R[0, 0]), sim.energy, R[2, 2])
    p, yaw, energy, up = results["straight"]
    assert p[0] > 0.3, "walks forward along +x"
    assert abs(p[1]) < 0.1 and abs(yaw) < np.radians(15)
    assert energy > 0 and up > 0.9
    _, yaw_left, _, up_left = results["left"]
    assert yaw_left > np.radians(30) or yaw_left < -np.radians(150), "right side faster turns left"
    assert up_left > 0.5


def test_drive_config_defaults_are_the_reports():
    cfg = DriverConfig()
    assert cfg.r_end == 0.05 and cfg.time_limit == 60.0


REFERENCE_DRIVES = Path(__file__).parent / "data" / "reference_drives.json"


@pytest.mark.parametrize("k", [0, 1])
def test_the_reference_driver_reproduces_its_recorded_drives_bit_for_bit(k):
    """Two raw PRM paths on double_bridge_rough driven by algorithms 1-2, recorded with the
    code from before the tracking driver existed (a scad scene: its terrain does not move when
    perception changes, as a capture's does). Recorded on the openscad binary's mesh, so
    rendered by the binary: backend auto's manifold cuts the same surface into other
    triangles, and a bit-for-bit drive follows the triangles."""
    import dataclasses

    from roachplan.experiments._trial import drive
    from roachplan.scenes import build_world, load_scene, with_scad_backend

    rec = json.loads(REFERENCE_DRIVES.read_text())["drives"][k]
    world = build_world(with_scad_backend(load_scene(rec["scene"]), "cgal"))
    scene = world.scene
    world = dataclasses.replace(
        world, scene=dataclasses.replace(scene, driver=dataclasses.replace(scene.driver, kind="reference"))
    )
    result = drive(world, np.array(rec["path"]))
    assert (result.outcome, result.reason) == (rec["outcome"], rec["reason"])
    assert result.drive_time == rec["drive_time"] and result.energy == rec["energy"]
    assert [list(p) for p in result.trajectory[-3:]] == rec["trajectory_tail"]
