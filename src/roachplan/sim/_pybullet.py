"""The PyBullet engine behind the physics seam (sim/_engine.py): a static terrain and one roach
in one headless client. The reference engine: the project's tables were measured with it."""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
from collections.abc import Iterator

import numpy as np

from ._config import SimConfig
from ._errors import SimError
from ._motors import SideMotors
from ._placement import (
    DROP_CLEARANCE,
    ground_height,
    start_height,
    support_plane_pose,
    terrain_arrays,
)
from ._robot import RobotConfig


@contextlib.contextmanager
def _c_stdout_silenced(fds: tuple[int, ...] = (1,)) -> Iterator[None]:
    """PyBullet's C code prints "argv[0]=" to stdout on connect, which would corrupt JSON
    written to stdout; send the C-level output on fds to /dev/null meanwhile."""
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(fd) for fd in fds]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in fds:
            os.dup2(devnull, fd)
        yield
    finally:
        libc.fflush(None)
        for fd, s in zip(fds, saved, strict=True):
            os.dup2(s, fd)
            os.close(s)
        os.close(devnull)


# On import PyBullet prints "pybullet build time: ..." (to stdout, or to stderr once OMPL is
# loaded): noise on every command line.
with _c_stdout_silenced((1, 2)):
    import pybullet as p
    from pybullet_utils.bullet_client import BulletClient


class PyBulletSimulation:
    """Owns one headless PyBullet client holding a terrain and a roach (sim/_engine.py's
    Simulation).

    Never sleeps or reads the clock: `step()` advances exactly `cfg.timestep` seconds.
    Legs are commanded per side (differential drive); the three legs of a side follow one
    motor phase, as the real robot's linkage makes them.
    """

    def __init__(
        self,
        terrain_vertices: np.ndarray,
        terrain_faces: np.ndarray,
        *,
        ground_height: float | None,
        robot: RobotConfig,
        cfg: SimConfig,
    ) -> None:
        """terrain_vertices: (V, 3) float world frame [m]; terrain_faces: (F, 3) int."""
        terrain_vertices, terrain_faces = terrain_arrays(
            terrain_vertices, terrain_faces, ground_height
        )
        self.robot = robot
        self.cfg = cfg
        with _c_stdout_silenced():
            self._bc: BulletClient = BulletClient(connection_mode=p.DIRECT)
        self._open = True
        bc = self._bc
        bc.setGravity(0, 0, -9.81)
        bc.setPhysicsEngineParameter(
            fixedTimeStep=cfg.timestep, numSolverIterations=cfg.solver_iterations, numSubSteps=0
        )
        # Static terrain: one concave triangle mesh on a mass-0 body.
        self.terrain_id = None
        if len(terrain_faces):
            shape = self._terrain_shape(terrain_vertices, terrain_faces)
            self.terrain_id = bc.createMultiBody(baseMass=0, baseCollisionShapeIndex=shape)
            bc.changeDynamics(self.terrain_id, -1, lateralFriction=cfg.friction, restitution=0.0)
        self.ground_id = None
        if ground_height is not None:
            plane = bc.createCollisionShape(p.GEOM_PLANE)
            self.ground_id = bc.createMultiBody(
                baseMass=0, baseCollisionShapeIndex=plane, basePosition=(0, 0, ground_height)
            )
            bc.changeDynamics(self.ground_id, -1, lateralFriction=cfg.friction, restitution=0.0)
        self.robot_id = self._create_robot()
        self._cid = bc._client  # the hot loop calls pybullet directly, skipping the wrapper
        self._joints = list(range(6))
        self._motors = SideMotors(robot)
        self._base_inertia: tuple[float, float, float] | None = None  # nominal, for perturb
        self.time = 0.0
        self.energy_per_leg = np.zeros(6)

    @classmethod
    def open_floor(cls, robot: RobotConfig, cfg: SimConfig) -> PyBulletSimulation:
        """A world with nothing but an endless floor at z = 0: calibration and reference walks."""
        no_terrain = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        return cls(*no_terrain, ground_height=0.0, robot=robot, cfg=cfg)

    # -- construction -------------------------------------------------------------------------

    def _terrain_shape(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        """The terrain's concave triangle mesh (vertices (V, 3) [m], faces (F, 3)) as a
        collision shape; SimError saying what to change when PyBullet refuses it (it takes up
        to ~175k triangles), its own warnings (printed on standard output) kept off stdout."""
        try:
            with _c_stdout_silenced():
                return self._bc.createCollisionShape(
                    p.GEOM_MESH,
                    vertices=vertices.tolist(),
                    indices=faces.reshape(-1).tolist(),
                    flags=p.GEOM_FORCE_CONCAVE_TRIMESH,
                )
        except p.error:
            self.close()
            raise SimError(
                f"PyBullet refused the terrain mesh ({len(vertices):,} vertices, "
                f"{len(faces):,} triangles; it takes up to about 175,000 triangles): give "
                f"smaller bounds, or a coarser capture (a larger perception voxel)"
            ) from None

    def _create_robot(self) -> int:
        bc, r = self._bc, self.robot
        half = (r.body_length / 2, r.body_width / 2, r.body_height / 2)
        body = bc.createCollisionShape(p.GEOM_BOX, halfExtents=half)
        # Capsule along the link's z axis, centred half a leg below the hip: the leg points
        # down at q = 0 and its rounded tip is the foot.
        leg = bc.createCollisionShape(
            p.GEOM_CAPSULE,
            radius=r.leg_radius,
            height=r.leg_length,
            collisionFramePosition=(0, 0, -r.leg_length / 2),
        )
        hips = r.hip_positions
        robot_id = bc.createMultiBody(
            baseMass=r.body_mass,
            baseCollisionShapeIndex=body,
            basePosition=(0, 0, -1000.0),
            linkMasses=[r.leg_mass] * 6,
            linkCollisionShapeIndices=[leg] * 6,
            linkVisualShapeIndices=[-1] * 6,
            linkPositions=hips.tolist(),
            linkOrientations=[(0, 0, 0, 1)] * 6,
            linkInertialFramePositions=[(0, 0, -r.leg_length / 2)] * 6,
            linkInertialFrameOrientations=[(0, 0, 0, 1)] * 6,
            linkParentIndices=[0] * 6,
            linkJointTypes=[p.JOINT_REVOLUTE] * 6,
            linkJointAxis=[(0, 1, 0)] * 6,
        )
        for link in range(-1, 6):
            bc.changeDynamics(
                robot_id,
                link,
                lateralFriction=self.cfg.friction,
                restitution=0.0,
                linearDamping=0.0,
                angularDamping=0.0,
            )
        inertia = (r.drive_inertia,) * 3
        for j in range(6):
            # Continuous joints: no limits; the leg carries its motor's reflected inertia; the
            # default velocity motor is off, since our servo applies the torque itself.
            bc.changeDynamics(
                robot_id,
                j,
                jointLowerLimit=1.0,
                jointUpperLimit=-1.0,
                localInertiaDiagonal=inertia,
            )
            bc.setJointMotorControl2(robot_id, j, p.VELOCITY_CONTROL, force=0.0)
        return robot_id

    # -- state ----------------------------------------------------------------------------------

    def surface_height(self, x: float, y: float, below: float = 50.0) -> float:
        """Height of the highest terrain or ground surface at (x, y) [m] under z = below [m],
        -inf if none."""
        hit = self._bc.rayTest((x, y, below), (x, y, -50.0))[0]
        return hit[3][2] if hit[0] >= 0 else -np.inf

    def surface_heights(self, xy: np.ndarray, top: float = 50.0) -> tuple[np.ndarray, np.ndarray]:
        """For points xy (N, 2) [m]: the highest surface under z = top ((N,) [m], -inf where
        none) and whether it is the terrain rather than the ground plane ((N,) bool). The robot
        is parked out of the rays' way meanwhile and put back as it was."""
        bc, rid = self._bc, self.robot_id
        pos, quat = bc.getBasePositionAndOrientation(rid)
        vel = bc.getBaseVelocity(rid)
        bc.resetBasePositionAndOrientation(rid, (0, 0, -1000.0), (0, 0, 0, 1))
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        z = np.full(len(xy), -np.inf)
        on_terrain = np.zeros(len(xy), dtype=bool)
        for k in range(0, len(xy), 8000):  # (PyBullet's batch limit is about 16k rays)
            chunk = xy[k : k + 8000]
            hits = bc.rayTestBatch(
                [(x, y, top) for x, y in chunk], [(x, y, -50.0) for x, y in chunk]
            )
            for i, h in enumerate(hits):
                if h[0] >= 0:
                    z[k + i] = h[3][2]
                    on_terrain[k + i] = h[0] == self.terrain_id
        bc.resetBasePositionAndOrientation(rid, pos, quat)
        bc.resetBaseVelocity(rid, *vel)
        return z, on_terrain

    def reset(
        self,
        x: float,
        y: float,
        yaw: float,
        surface: float | None = None,
        *,
        phase: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        """Drop the robot at (x, y) [m] heading yaw [rad], legs in tripod stance, and settle.
        surface: the height the planner stands it on there [m]; the ground is then looked for
        just above it (under a table, the floor the plan is on, not the table top). phase: the
        (left, right) motors' phase to stand at [rad] (0: the tripod stance; a robot caught
        mid-stride, as a logged run's re-simulation from one of its poses starts it)."""
        bc, r = self._bc, self.robot
        # Park the robot out of the ray's way before looking for the ground under the start.
        bc.resetBasePositionAndOrientation(self.robot_id, (0, 0, -1000.0), (0, 0, 0, 1))

        def ground(gx: float, gy: float) -> float:
            return ground_height(self.surface_height, gx, gy, surface)

        z0 = start_height(ground, r, x, y, yaw)
        quat = bc.getQuaternionFromEuler((0.0, 0.0, yaw))
        position = (x, y, z0 + r.standing_height + DROP_CLEARANCE)
        tilted = support_plane_pose(ground, r, x, y, yaw)
        if tilted is not None:
            position, quat = tilted
        bc.resetBasePositionAndOrientation(self.robot_id, position, quat)
        bc.resetBaseVelocity(self.robot_id, (0, 0, 0), (0, 0, 0))
        q0 = self._motors.reset(phase)
        for j in self._joints:
            bc.resetJointState(self.robot_id, j, float(q0[j]), 0.0)
        self.advance(round(self.cfg.settle_time / self.cfg.timestep))  # legs held, speed 0
        self.time = 0.0
        self.energy_per_leg[:] = 0.0

    def place(
        self,
        position: tuple[float, float, float],
        quat: tuple[float, float, float, float],
    ) -> None:
        """Put the body at position [m] with orientation quat (xyzw, world from body), at rest,
        legs as they are."""
        self._bc.resetBasePositionAndOrientation(self.robot_id, position, quat)
        self._bc.resetBaseVelocity(self.robot_id, (0, 0, 0), (0, 0, 0))

    def set_joint_damping(self, damping: float) -> None:
        """Viscous damping at every hip [N m s / rad] (0 on the robot: a test of the energy
        meter drives the legs against it)."""
        for j in self._joints:
            self._bc.changeDynamics(self.robot_id, j, jointDamping=damping)

    def set_leg_speeds(self, left: float, right: float) -> None:
        """Command the left and right motors [rad/s], clipped to the motor's speed limit. With
        perturb()'s motor gains, each side then runs at gain x the command (a real motor's
        speed differs from what it is told)."""
        self._motors.command(left, right)

    def perturb(
        self, *, friction: float, mass_scale: float, motor_gain: tuple[float, float]
    ) -> None:
        """Set this world's physical uncertainty for the next drives (choose's rollouts):
        the Coulomb friction of terrain, ground and robot [-], the body's mass as a multiple
        of the robot's [-], and the (left, right) motors' speed gains [-] as multiples of the
        robot's own (RobotConfig.motor_gain, 1 on the nominal robot).
        perturb(friction=cfg.friction, mass_scale=1, motor_gain=(1, 1)) is the nominal world."""
        bc, r = self._bc, self.robot
        for body in (self.terrain_id, self.ground_id):
            if body is not None:
                bc.changeDynamics(body, -1, lateralFriction=friction)
        for link in range(-1, 6):
            bc.changeDynamics(self.robot_id, link, lateralFriction=friction)
        if self._base_inertia is None:
            self._base_inertia = tuple(bc.getDynamicsInfo(self.robot_id, -1)[2])
        # The body (a payload on it) only: the legs' inertia is their motors' reflected one.
        # PyBullet recomputes a link's inertia from its shape when its mass is set, so the
        # nominal inertia, scaled, is set back after.
        bc.changeDynamics(self.robot_id, -1, mass=r.body_mass * mass_scale)
        bc.changeDynamics(
            self.robot_id,
            -1,
            localInertiaDiagonal=tuple(v * mass_scale for v in self._base_inertia),
        )
        self._motors.set_gain(motor_gain)

    def step(self) -> None:
        """Advance one timestep and meter the energy the leg motors spend (Tong 2018, 3.4)."""
        self.advance(1)

    def advance(self, n: int) -> None:
        """Advance n timesteps at the current leg speeds, metering the motors' energy.

        The hot loop of every drive: the legs' targets for all n steps are computed at once,
        and each step costs three PyBullet calls (read joint states, apply torques, step).
        """
        dt, cid, rid, joints = self.cfg.timestep, self._cid, self.robot_id, self._joints
        r = self.robot
        kp, kd, limit = r.motor_kp, r.motor_kd, r.max_motor_torque
        q, dq = self._motors.targets(n, dt)  # (n, 6) each
        targets, speeds = q.tolist(), dq.tolist()
        energy = self.energy_per_leg.tolist()
        for k in range(n):
            # Each leg is a PD servo on its share of its side's motor phase: the legs of a
            # side stay in phase like the real linkage. We apply the torque ourselves (PyBullet
            # does not report it under torque control), so the meter integrates exactly the
            # torque the physics received: E += |tau * dq/dt| dt (Tong 2018, 3.4).
            states = p.getJointStates(rid, joints, physicsClientId=cid)
            target, speed = targets[k], speeds[k]
            torques = [0.0] * 6
            for j in range(6):
                q_j, dq_j = states[j][0], states[j][1]
                tau = kp * (target[j] - q_j) + kd * (speed[j] - dq_j)
                tau = limit if tau > limit else -limit if tau < -limit else tau
                torques[j] = tau
                energy[j] += abs(tau * dq_j) * dt
            p.setJointMotorControlArray(
                rid, joints, p.TORQUE_CONTROL, forces=torques, physicsClientId=cid
            )
            p.stepSimulation(physicsClientId=cid)
        self.energy_per_leg[:] = energy
        self._motors.advance(n, dt)
        self.time += n * dt

    def pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """(p_world_body [m], quat_world_body xyzw) as plain tuples: the controller's fast read."""
        return p.getBasePositionAndOrientation(self.robot_id, physicsClientId=self._cid)

    def body_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(p_world_body (3,) [m], quat_world_body (4,) xyzw)."""
        pos, quat = self.pose()
        return np.array(pos), np.array(quat)

    def joint_angles(self) -> np.ndarray:
        """(6,) leg angles [rad], hip order L1 L2 L3 R1 R2 R3."""
        return np.array([s[0] for s in self._bc.getJointStates(self.robot_id, self._joints)])

    @property
    def energy(self) -> float:
        """Energy spent by all leg motors since reset [J]."""
        return float(self.energy_per_leg.sum())

    def close(self) -> None:
        """Disconnect the PyBullet client (once)."""
        if self._open:
            self._bc.disconnect()
            self._open = False

    def __enter__(self) -> PyBulletSimulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
