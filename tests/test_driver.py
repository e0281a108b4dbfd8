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
    heading_error,
    motor_speeds,
    next_waypoint,
    open_floor,
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
    path = [(0.0, 0.0), (0.0, 0.1), (0.0, 0.2), (0.0, 0.3)]  # as the driver passes them
    assert next_waypoint(path, 1, np.array([0.0, 0.0]), 0.05, 0.02) == (1, False)
    assert next_waypoint(path, 1, np.array([0.0, 0.12]), 0.05, 0.02) == (2, False)
    assert next_waypoint(path, 2, np.array([0.0, 0.17]), 0.05, 0.02) == (3, False)
    # The last point needs r_end, not r_path.
    assert next_waypoint(path, 3, np.array([0.0, 0.27]), 0.05, 0.02) == (3, False)
    assert next_waypoint(path, 3, np.array([0.0, 0.29]), 0.05, 0.02) == (3, True)


def test_roach_walks_forward_on_flat_ground_and_turns_toward_the_faster_side():
    results = {}
    for name, (left, right) in {"straight": (20.0, 20.0), "left": (20.0, 40.0)}.items():
        with open_floor(RobotConfig(), SimConfig()) as sim:
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

    from roachplan.experiments import drive
    from roachplan.scenes import build_world, load_scene, with_scad_backend

    rec = json.loads(REFERENCE_DRIVES.read_text())["drives"][k]
    world = build_world(with_scad_backend(load_scene(rec["scene"]), "cgal"))
    scene = world.scene
    world = dataclasses.replace(
        world,
        scene=dataclasses.replace(
            scene, driver=dataclasses.replace(scene.driver, kind="reference")
        ),
    )
    result = drive(world, np.array(rec["path"]))
    assert (result.outcome, result.reason) == (rec["outcome"], rec["reason"])
    assert result.drive_time == rec["drive_time"] and result.energy == rec["energy"]
    assert [list(p) for p in result.trajectory[-3:]] == rec["trajectory_tail"]


# -- turns on the spot (spins) ----------------------------------------------------------------


def _line(a, b, step: float = 0.05) -> np.ndarray:
    n = max(1, int(np.ceil(np.linalg.norm(np.subtract(b, a)) / step)))
    return np.array([np.add(a, np.subtract(b, a) * k / n) for k in range(n + 1)])


def _floor_drive(path_xy: np.ndarray, start_yaw: float, cfg: DriverConfig, spins=(), frames=None):
    from roachplan.sim import drive_path

    path = np.column_stack([path_xy, np.zeros(len(path_xy))])
    with open_floor(RobotConfig(), SimConfig()) as sim:
        sim.reset(float(path_xy[0, 0]), float(path_xy[0, 1]), start_yaw)
        return drive_path(sim, path, cfg, on_frame=frames, spins=spins)


def _yaw(quat) -> float:
    x, y, z, w = quat
    return float(np.arctan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z)))


# Out 0.5 m along +x, then back up and left at 143 degrees: a corner no arc turns on the spot.
OUT, BACK = _line((0.0, 0.0), (0.5, 0.0)), _line((0.5, 0.0), (0.1, 0.3))
CORNER_PATH = np.vstack([OUT, BACK[1:]])
CORNER = len(OUT) - 1
CORNER_SPIN = ((CORNER, float(np.arctan2(0.3, -0.4))),)


def _off_path(trajectory, path_xy: np.ndarray) -> float:
    """The largest distance of a driven track ((t, x, y, z) rows) from the polyline [m]."""
    a, d = path_xy[:-1], np.diff(path_xy, axis=0)
    worst = 0.0
    for p in np.array([q[1:3] for q in trajectory]):
        u = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum((d**2).sum(1), 1e-18), 0, 1)
        worst = max(worst, float(np.min(np.linalg.norm(a + d * u[:, None] - p, axis=1))))
    return worst


def test_the_tracking_driver_turns_on_the_spot_at_a_spin_and_goes_on():
    frames = []
    result = _floor_drive(CORNER_PATH, 0.0, DriverConfig(), CORNER_SPIN, frames.append)
    assert result.outcome == "success", result.reason
    # It walked up to the corner, turned there and came back along the path (measured: never
    # 2 cm off it), turning most of the 2.5 rad within 3 cm of the corner.
    assert _off_path(result.trajectory, CORNER_PATH) < 0.03
    track = np.array([f.p_world_body[:2] for f in frames])
    near = np.linalg.norm(track - CORNER_PATH[CORNER], axis=1) < 0.03
    turned = [_yaw(f.quat_world_body) for f, n in zip(frames, near, strict=True) if n]
    assert max(turned) - min(turned) > 2.0
    # Without the spin the same path is driven on arcs, which cut the corner (measured 17 cm).
    arcs = _floor_drive(CORNER_PATH, 0.0, DriverConfig())
    assert _off_path(arcs.trajectory, CORNER_PATH) > 0.1


def test_a_spin_that_turns_is_never_stuck_and_one_that_does_not_is():
    path = _line((0.0, 0.0), (0.6, 0.0))
    # Facing away from the path: half a turn on the spot first (about 2.2 s at 10 rad/s),
    # longer than stuck_time, in which the robot does not move along the path.
    cfg = DriverConfig(stuck_time=1.0)
    result = _floor_drive(path, np.pi, cfg, ((0, 0.0),))
    assert result.outcome == "success", result.reason
    assert result.drive_time > 2.0
    creeping = _floor_drive(path, np.pi, DriverConfig(stuck_time=1.0, spin_speed=0.05), ((0, 0.0),))
    assert creeping.outcome == "stuck"
    assert "turning on the spot" in creeping.reason


def test_a_path_of_one_waypoint_is_reached_where_the_robot_stands():
    result = _floor_drive(np.zeros((1, 2)), 0.3, DriverConfig())
    assert result.outcome == "success" and result.drive_time == 0.0 and result.energy == 0.0
    frames = []
    turned = _floor_drive(np.zeros((1, 2)), 0.3, DriverConfig(), ((0, 1.8),), frames.append)
    assert turned.outcome == "success" and turned.drive_time > 0.5
    end_yaw = _yaw(frames[-1].quat_world_body)
    # Within the spin tolerance when the driver stopped, plus the gait's sway after.
    assert abs(np.remainder(end_yaw - 1.8 + np.pi, 2 * np.pi) - np.pi) < 0.2


def test_spins_that_name_no_waypoint_are_refused():
    from roachplan.sim import drive_path

    with open_floor(RobotConfig(), SimConfig()) as sim:
        sim.reset(0.0, 0.0, 0.0)
        for bad in [((5, 0.0),), ((-1, 0.0),), ((0.5, 0.0),), ((0, float("nan")),), ((0,),)]:
            with pytest.raises(ValueError, match="waypoint index from 0 to 1"):
                drive_path(sim, np.zeros((2, 3)), DriverConfig(), spins=bad)


def test_the_reference_driver_ignores_spins():
    ref = DriverConfig(kind="reference")
    plain = _floor_drive(CORNER_PATH, 0.0, ref)
    with_spins = _floor_drive(CORNER_PATH, 0.0, ref, CORNER_SPIN)
    assert plain == with_spins
