"""The MuJoCo engine (sim/_mujoco.py): its model is the RobotConfig's, it stands, walks, turns
and meters energy as a roach should, it stands the robot where the planner does, and the same
inputs step it the same way bit for bit. Real MuJoCo throughout."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from roachplan.planning import heightfield_from_mesh
from roachplan.sim import LEG_NAMES, PyBulletSimulation, RobotConfig, SimConfig
from roachplan.sim._mujoco import (
    GROUND_CLEARANCE,
    INTEGRATOR,
    OVERHEAD,
    MujocoSimulation,
    leg_inertia_about_hip,
    terrain_shape,
)
from roachplan.sim._pieces import MAX_PIECES, convex_prisms


def _box(size, centre) -> trimesh.Trimesh:
    box = trimesh.creation.box(size)
    box.apply_translation(centre)
    return box


def _mesh(*parts: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    mesh = trimesh.util.concatenate(list(parts))
    assert isinstance(mesh, trimesh.Trimesh)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _yaw(quat_xyzw) -> float:
    x, y, z, w = quat_xyzw
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def test_the_model_is_the_robot_config():
    """Every mass, size and gain of the MJCF comes from RobotConfig: one not the default's
    (so a number written into the model by hand could not pass)."""
    robot = RobotConfig(
        body_length=0.12, body_width=0.05, body_height=0.025, body_mass=0.03, leg_length=0.03,
        leg_radius=0.004, leg_mass=0.002, hip_spacing=0.05, motor_kp=0.03, motor_kd=4e-4,
        max_motor_torque=0.07, drive_inertia=2e-6,
    )  # fmt: skip
    cfg = SimConfig(timestep=0.002, friction=0.7)
    with MujocoSimulation.open_floor(robot, cfg) as sim:
        m = sim.model
        assert m.opt.timestep == 0.002
        body = m.body("body")
        assert body.mass[0] == pytest.approx(robot.body_mass)
        assert m.geom("body_box").size == pytest.approx(
            [robot.body_length / 2, robot.body_width / 2, robot.body_height / 2]
        )
        assert sum(m.body_mass) == pytest.approx(robot.mass)
        for name, hip in zip(LEG_NAMES, robot.hip_positions, strict=True):
            leg, joint = m.body(f"leg_{name}"), m.joint(f"hip_{name}")
            assert leg.mass[0] == pytest.approx(robot.leg_mass)
            np.testing.assert_allclose(leg.pos, hip)
            np.testing.assert_allclose(joint.axis, (0, 1, 0))
            capsule = m.geom(f"leg_{name}_capsule")
            # (MuJoCo's capsule: radius and half length, centred half a leg below the hip)
            assert capsule.size[:2] == pytest.approx([robot.leg_radius, robot.leg_length / 2])
            np.testing.assert_allclose(capsule.pos, (0, 0, -robot.leg_length / 2), atol=1e-12)
            # The hinge's whole inertia is drive_inertia: the leg's own plus the armature.
            total = joint.armature[0] + leg_inertia_about_hip(robot)
            assert total == pytest.approx(robot.drive_inertia)
            servo = m.actuator(f"servo_{name}")
            assert servo.biasprm[1:3] == pytest.approx([-robot.motor_kp, -robot.motor_kd])
            assert servo.forcerange == pytest.approx([-0.07, 0.07])
        assert np.all(m.geom_friction[:, 0] == 0.7)
        # The foot: the capsule's tip stands standing_height under the body's centre.
        sim.reset(0.0, 0.0, 0.0)
        (_, _, z), _ = sim.pose()
        assert z == pytest.approx(robot.standing_height, abs=5e-4)


def test_the_robot_stands_on_a_floor_and_on_a_box_step():
    """Reset stands the body standing_height above the surface under it, level: on the open
    floor, on a 5 cm box step (a convex prism) and on the floor beside it (the plane)."""
    robot = RobotConfig()
    with MujocoSimulation.open_floor(robot, SimConfig()) as sim:
        sim.reset(0.3, -0.2, 1.0)
        (x, y, z), quat = sim.pose()
        assert z == pytest.approx(robot.standing_height, abs=5e-4)
        assert (x, y) == pytest.approx((0.3, -0.2), abs=2e-3)
        assert _yaw(quat) == pytest.approx(1.0, abs=0.01)
    step = _box((0.4, 0.4, 0.05), (0.2, 0.0, 0.025))
    with MujocoSimulation(*_mesh(step), ground_height=0.0, robot=robot, cfg=SimConfig()) as sim:
        z, on_terrain = sim.surface_heights(np.array([[0.2, 0.0], [-0.3, 0.0], [0.45, 0.1]]))
        np.testing.assert_allclose(z, [0.05, 0.0, 0.0], atol=1e-6)
        assert on_terrain.tolist() == [True, False, False]
        for x, top in ((0.2, 0.05), (-0.3, 0.0)):
            sim.reset(x, 0.0, 0.0)
            (_, _, z), quat = sim.pose()
            assert z == pytest.approx(top + robot.standing_height, abs=5e-4)
            assert abs(quat[0]) < 0.01 and abs(quat[1]) < 0.01  # level


def _walk(left: float, right: float, seconds: float = 2.0) -> tuple[np.ndarray, float, float]:
    with MujocoSimulation.open_floor(RobotConfig(), SimConfig(timestep=0.002)) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(left, right)
        sim.advance(round(seconds / sim.cfg.timestep))
        pos, quat = sim.body_pose()
        return pos, _yaw(quat), sim.energy


def test_it_walks_forward_and_turns_toward_the_slower_side():
    pos, yaw, _ = _walk(20.0, 20.0)
    assert pos[0] > 0.25, "walks forward along +x (~0.19 m/s)"
    assert abs(pos[1]) < 0.05 and abs(yaw) < math.radians(10)
    pos, yaw, _ = _walk(20.0, 40.0)  # the left side slower
    assert yaw > math.radians(20), "turns left"
    pos, yaw, _ = _walk(40.0, 20.0)
    assert yaw < -math.radians(20), "turns right"
    pos, yaw, _ = _walk(-20.0, -20.0)
    assert pos[0] < -0.15, "backwards"


def test_energy_grows_and_is_zero_after_reset():
    with MujocoSimulation.open_floor(RobotConfig(), SimConfig(timestep=0.002)) as sim:
        sim.reset(0.0, 0.0, 0.0)
        assert sim.energy == 0.0 and sim.time == 0.0
        sim.set_leg_speeds(20.0, 20.0)
        readings = []
        for _ in range(5):
            sim.advance(50)
            readings.append(sim.energy)
        assert np.all(np.diff(readings) > 0)
        assert np.all(sim.energy_per_leg > 0)
        assert sim.time == pytest.approx(0.5)
        sim.reset(0.0, 0.0, 0.0)
        assert sim.energy == 0.0 and not sim.energy_per_leg.any() and sim.time == 0.0


def test_the_energy_meter_reads_a_leg_spinning_against_viscous_damping():
    """Base fixed in the air (mass 0, as on PyBullet), legs at a constant speed (a stance sweep
    of pi makes the Buehler clock uniform) against a joint damping c: the servo applies
    tau = c omega, so the meter must read E = 6 c omega^2 T."""
    robot = RobotConfig(body_mass=0.0, stance_sweep=math.pi)
    c, omega, seconds = 5e-4, 20.0, 1.0
    with MujocoSimulation.open_floor(robot, SimConfig(timestep=0.002)) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.place((0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0))
        sim.set_joint_damping(c)
        sim.set_leg_speeds(omega, omega)
        sim.advance(125)  # up to speed
        sim.energy_per_leg[:] = 0.0
        sim.advance(round(seconds / sim.cfg.timestep))
        np.testing.assert_allclose(sim.energy_per_leg, c * omega**2 * seconds, rtol=1e-3)
        assert sim.pose()[0] == (0.0, 0.0, 0.5)


def _trajectory(sim: MujocoSimulation, chunks) -> np.ndarray:
    sim.reset(0.1, 0.0, 0.3)
    out = []
    for left, right, n in chunks:
        sim.set_leg_speeds(left, right)
        if n == 1:
            sim.step()
        else:
            sim.advance(n)
        out.append(np.concatenate([sim.data.qpos, sim.data.qvel, sim.energy_per_leg]))
    return np.array(out)


def test_the_same_inputs_give_bit_identical_trajectories():
    """Two worlds, the same commands: the same states to the last bit; a used world reset
    steps as a fresh one; and advance(n) steps as n step()s do."""
    chunks = [(20.0, 20.0, 300), (20.0, 35.0, 1), (10.0, -10.0, 150), (30.0, 25.0, 100)] * 2
    step = _box((0.3, 0.3, 0.01), (0.3, 0.0, 0.005))
    worlds = [
        MujocoSimulation(*_mesh(step), ground_height=0.0, robot=RobotConfig(), cfg=SimConfig())
        for _ in range(2)
    ]
    a = _trajectory(worlds[0], chunks)
    assert np.array_equal(a, _trajectory(worlds[1], chunks))
    assert np.array_equal(a, _trajectory(worlds[0], chunks)), "a reset world steps afresh"
    assert math.dist(a[0, :2], a[-1, :2]) > 0.05  # it went somewhere
    one_by_one = [(left, right, 1) for left, right, n in chunks[:4] for _ in range(n)]
    b = _trajectory(worlds[1], one_by_one)
    ends = np.cumsum([n for _, _, n in chunks[:4]]) - 1
    # (To rounding: one call takes its targets at phase + k dt omega, n calls add dt omega n
    # times, as PyBullet's advance does.)
    np.testing.assert_allclose(a[:4], b[ends], rtol=0, atol=1e-9)
    for sim in worlds:
        sim.close()


def test_a_table_over_the_floor_stands_the_robot_where_the_planner_does():
    """A floor slab and a table (top 0.5 m up, four legs), no ground plane: the planner's
    height field has the floor under the table (OVERHEAD), and reset with its surface stands
    the robot on that floor, as PyBullet's does; beside the table too."""
    from roachplan.scenes._world import OVERHEAD as PLANNERS_OVERHEAD

    assert OVERHEAD == PLANNERS_OVERHEAD
    parts = [_box((2.0, 2.0, 0.02), (0.0, 0.0, -0.01)), _box((0.8, 0.6, 0.03), (0.0, 0.0, 0.515))]
    parts += [_box((0.04, 0.04, 0.5), (x, y, 0.25)) for x in (-0.35, 0.35) for y in (-0.25, 0.25)]
    v, f = _mesh(*parts)
    hf = heightfield_from_mesh(
        v, f, xy_min=(-1, -1), xy_max=(1, 1), resolution=0.01, ground_height=None,
        overhead=PLANNERS_OVERHEAD,
    )  # fmt: skip
    robot = RobotConfig()
    for x, y in ((0.0, 0.05), (0.6, -0.5)):
        surface = float(hf.sample(np.array([x, y])))
        assert surface == pytest.approx(0.0, abs=1e-9)
        heights = []
        for engine in (MujocoSimulation, PyBulletSimulation):
            with engine(v, f, ground_height=None, robot=robot, cfg=SimConfig()) as sim:
                sim.reset(x, y, 0.5, surface=surface)
                heights.append(sim.pose()[0][2])
        assert heights[0] == pytest.approx(surface + robot.standing_height, abs=5e-4)
        # (PyBullet's mesh contact holds the feet about 1 mm off a concave mesh.)
        assert heights[0] == pytest.approx(heights[1], abs=2e-3)


def test_a_hole_without_ground_is_no_surface_and_the_robot_falls_into_it():
    floor = _box((1.0, 1.0, 0.02), (0.0, 0.0, -0.01))
    far = _box((1.0, 1.0, 0.02), (1.3, 0.0, -0.01))  # beyond a 30 cm gap
    v, f = _mesh(floor, far)
    with MujocoSimulation(v, f, ground_height=None, robot=RobotConfig(), cfg=SimConfig()) as sim:
        assert sim.surface_height(0.65, 0.0) == -math.inf
        assert sim.surface_height(0.2, 0.0) == pytest.approx(0.0, abs=1e-6)
        assert sim.surface_height(9.0, 0.0) == -math.inf  # off the field altogether
        sim.reset(0.4, 0.0, 0.0)  # walking to the gap
        sim.set_leg_speeds(20.0, 20.0)
        sim.advance(1500)
        assert sim.pose()[0][2] < -0.08, "fell into the gap"


def test_importing_the_sim_package_does_not_load_mujoco():
    code = (
        "import sys, roachplan.sim as s; s.SimConfig; s.RobotConfig; s.drive_path; "
        "assert 'mujoco' not in sys.modules; s.MujocoSimulation; assert 'mujoco' in sys.modules"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr


def test_the_engine_steps_at_its_configured_timestep():
    with MujocoSimulation.open_floor(RobotConfig(), SimConfig(timestep=0.002)) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.advance(10)
        assert sim.data.time == pytest.approx(0.02) and sim.time == pytest.approx(0.02)
        assert sim.model.opt.integrator == INTEGRATOR


def test_a_diverged_world_is_at_no_finite_place_and_says_so_off_stdout(
    tmp_path, monkeypatch, capfd
):
    """A leg of next to no inertia under a stiff servo at a 10 ms step diverges: MuJoCo resets
    such a state and goes on; the engine reports the body at NaN (the driver's "fell: the
    simulation diverged"), with nothing on standard output and no MUJOCO_LOG.TXT written."""
    monkeypatch.chdir(tmp_path)
    robot = RobotConfig(drive_inertia=1e-12, leg_mass=1e-6, motor_kd=1.0, max_motor_torque=1e3)
    with MujocoSimulation.open_floor(robot, SimConfig(timestep=0.01)) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(60.0, 60.0)
        sim.advance(100)
        (x, _, _), _ = sim.pose()
        assert math.isnan(x)
    assert capfd.readouterr().out == ""
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_a_terrain_of_flat_convex_tops_is_built_of_prisms_and_any_other_of_a_height_field():
    """The double bridge (two ramps, two decks) is four convex prisms standing in the ground
    plane, each its top's corners and the same outline GROUND_CLEARANCE under the plane; the
    world has no height field, rays find each top, the floor between is the plane's. Tops
    that are no such solids are a field: an L-shaped deck, a table over the floor (a prism
    would fill the room under it), a top more than OVERHEAD over the plane, more than
    MAX_PIECES tops (a bumpy deck), a frustum with sides too steep for tops and not walls
    (they reach out past its top's prism)."""
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene("double_bridge"))
    v, f = np.asarray(world.sim_terrain.vertices), np.asarray(world.sim_terrain.faces)
    field, prisms = terrain_shape(v, f, 0.0)
    assert field is None and prisms is not None and len(prisms) == 4
    for corners in prisms:
        top, bottom = np.split(corners, 2)
        assert np.allclose(bottom[:, :2], top[:, :2]) and np.all(bottom[:, 2] == -GROUND_CLEARANCE)
        assert top[:, 2].max() == pytest.approx(0.2)  # (each ramp rises to the decks' 0.2 m)
    with MujocoSimulation(v, f, ground_height=0.0, robot=RobotConfig(), cfg=SimConfig()) as sim:
        assert sim.model.nhfield == 0 and sim.model.nmesh == 4
        probes = np.array([[-0.75, 0.0], [0.75, 0.0], [0.0, 0.0], [0.0, -1.0], [0.0, -1.6]])
        z, on_terrain = sim.surface_heights(probes)
        np.testing.assert_allclose(z, [0.2, 0.2, 0.0, 0.1, 0.0], atol=1e-6)
        assert on_terrain.tolist() == [True, True, False, True, False]
        sim.reset(-0.75, 0.0, math.pi / 2)
        assert sim.pose()[0][2] == pytest.approx(0.2 + RobotConfig().standing_height, abs=5e-4)

    def shape(*parts, ground=0.0):
        return convex_prisms(*_mesh(*parts), ground, base=-0.005, overhead=OVERHEAD)

    deck = _box((0.4, 0.4, 0.05), (0.0, 0.0, 0.025))
    one = shape(deck)
    assert one is not None and len(one) == 1
    assert shape(deck, _box((0.4, 0.4, 0.05), (0.5, 0.0, 0.025))) is not None  # (side by side)
    ell = trimesh.boolean.union(
        [deck, _box((0.4, 0.2, 0.05), (0.4, 0.1, 0.025))], engine="manifold"
    )
    assert shape(ell) is None
    table = _box((0.8, 0.6, 0.03), (0.0, 0.0, 0.2))
    assert shape(deck, table) is None
    assert shape(_box((0.4, 0.4, 0.5), (0.0, 0.0, 0.25))) is None  # (over OVERHEAD)

    def frustum(top_scale: float) -> trimesh.Trimesh:
        """A hexagonal frustum 10 cm tall on the floor, its top top_scale x its base."""
        solid = trimesh.creation.cylinder(radius=0.2, height=0.1, sections=6)
        solid.vertices[solid.vertices[:, 2] > 0, :2] *= top_scale
        solid.apply_translation((0.0, 0.0, 0.05))
        return solid

    sloped = shape(frustum(0.8))  # (sides 68 deg steep: each a top, the solid their prisms)
    assert sloped is not None and len(sloped) == 7
    assert shape(frustum(0.98)) is None  # (sides 88 deg steep, no tops, and no walls)
    bumps = [_box((0.02, 0.02, 0.01), (0.03 * k, 0.0, 0.005)) for k in range(MAX_PIECES + 1)]
    assert shape(*bumps) is None and shape(*bumps[:MAX_PIECES]) is not None
    rough = build_world(load_scene("double_bridge_rough")).sim_terrain
    field, prisms = terrain_shape(np.asarray(rough.vertices), np.asarray(rough.faces), 0.0)
    assert field is not None and prisms is None


def test_a_box_step_walks_the_same_built_of_prisms_as_of_a_height_field(monkeypatch):
    """The same walk up onto a 2 cm box step, the step a prism and then the height field (as
    it was built before prisms): both climb it and end within 2 cm and 5 % of energy of each
    other (the field rounds the step's edge into a 5 mm slope; the prism keeps it sharp)."""
    import roachplan.sim._mujoco as engine

    step = _mesh(_box((0.6, 0.6, 0.02), (0.45, 0.0, 0.01)))
    ends = []
    for shaped in (engine.terrain_shape, lambda v, f, g: (engine.terrain_field(v, f, g), None)):
        monkeypatch.setattr(engine, "_cached_shape", shaped)
        with MujocoSimulation(
            *step, ground_height=0.0, robot=RobotConfig(), cfg=SimConfig(timestep=0.002)
        ) as sim:
            assert (sim.model.nmesh, sim.model.nhfield) == ((1, 0) if not ends else (0, 1))
            sim.reset(0.0, 0.0, 0.0)
            sim.set_leg_speeds(20.0, 20.0)
            sim.advance(1500)
            pos, _ = sim.body_pose()
            ends.append((pos.copy(), sim.energy))
    (p_prism, e_prism), (p_field, e_field) = ends
    assert p_prism[0] > 0.3 and p_prism[2] > 0.02, "climbed onto the step"
    assert np.linalg.norm(p_prism[:2] - p_field[:2]) < 0.02
    assert abs(e_prism - e_field) < 0.05 * e_field
