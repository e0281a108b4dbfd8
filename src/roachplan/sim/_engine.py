"""The physics seam: what the rest of roachplan asks of a simulated world, and the one factory
that builds one for the engine a SimConfig names (issue 31).

Two engines stand behind it: PyBullet (`sim/_pybullet.py`, the default and the reference:
every table the project reproduces was measured with it) and MuJoCo (`sim/_mujoco.py`). Both
hold one static terrain, an optional ground plane and one roach generated from the same
RobotConfig, and advance exactly `cfg.timestep` per step without reading the clock.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Protocol

import numpy as np

from ._config import ENGINES, DriverConfig, SimConfig
from ._errors import SimError
from ._robot import RobotConfig
from ._turning import ENGINE_TURNING

if TYPE_CHECKING:
    from collections.abc import Callable


CALIBRATED_TIMESTEP = {"pybullet": 0.001, "mujoco": 0.002}
"""The timestep [s] each engine was calibrated and checked at. PyBullet: 1 ms (halving it moves
a 10 s floor walk by < 0.5 % in distance; 2 ms is 1.4-1.6x faster with outcomes unchanged, but
every table was measured at 1 ms). MuJoCo: 2 ms, where semi-implicit Euler keeps the leg servo
stable and a 10 s walk within 5 % in distance and 2 % in energy of 0.25 ms (sim/_mujoco.py)."""


def engine_named(sim: object) -> str | None:
    """The engine a `sim:` mapping (a scene file's, an experiment spec's) names, when it names
    one of ENGINES (anything else is left to its validator to refuse)."""
    engine = sim.get("engine") if isinstance(sim, dict) else None
    return engine if isinstance(engine, str) and engine in ENGINES else None


def engine_settings(cfg: SimConfig, engine: str) -> SimConfig:
    """cfg with engine as calibrated: its name and its timestep (CALIBRATED_TIMESTEP)."""
    return dataclasses.replace(cfg, engine=engine, timestep=CALIBRATED_TIMESTEP[engine])


def engine_driver(driver: DriverConfig, engine: str) -> DriverConfig:
    """driver asking engine's own turning curve for its arcs (ENGINE_TURNING), where it asks an
    engine's calibrated curve (a scene's own `driver.turning` is kept)."""
    if driver.turning not in ENGINE_TURNING.values():
        return driver
    return dataclasses.replace(driver, turning=ENGINE_TURNING[engine])


class Simulation(Protocol):
    """One static terrain and one roach in a physics engine (a thin stateful shell).

    Frames: world z up [m]; the body frame is RobotConfig's (x forward, y left, z up, origin at
    the body box's centre). Legs are commanded per side: the three legs of a side follow one
    motor phase, as the real robot's linkage makes them.
    """

    robot: RobotConfig
    cfg: SimConfig
    time: float
    """Simulated time since reset [s]."""
    energy_per_leg: np.ndarray
    """(6,) energy each leg's motor spent since reset [J], hip order L1 L2 L3 R1 R2 R3."""

    @property
    def energy(self) -> float:
        """Energy spent by all leg motors since reset [J]."""
        ...

    def surface_height(self, x: float, y: float, below: float = 50.0) -> float:
        """Height of the highest terrain or ground surface at (x, y) [m] under z = below [m],
        -inf if none."""
        ...

    def surface_heights(self, xy: np.ndarray, top: float = 50.0) -> tuple[np.ndarray, np.ndarray]:
        """For points xy (N, 2) [m]: the highest surface under z = top ((N,) [m], -inf where
        none) and whether that surface is the terrain rather than the ground plane ((N,) bool).
        The robot is not in the way (the state it is in is kept)."""
        ...

    def reset(
        self,
        x: float,
        y: float,
        yaw: float,
        surface: float | None = None,
        *,
        phase: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        """Drop the robot at (x, y) [m] heading yaw [rad] on the ground there (surface: the
        planner's height there [m]: a table's floor, not its top), legs at the motors' phase
        (left, right) [rad], settle for cfg.settle_time; time and energy zeroed."""
        ...

    def place(
        self,
        position: tuple[float, float, float],
        quat: tuple[float, float, float, float],
    ) -> None:
        """Put the body at position [m] with orientation quat (xyzw, world from body), at rest,
        legs as they are (a test's upturned robot, a live pose to look ahead from)."""
        ...

    def set_leg_speeds(self, left: float, right: float) -> None:
        """Command the left and right motors [rad/s] (clipped to the motor's limit)."""
        ...

    def set_joint_damping(self, damping: float) -> None:
        """Viscous damping at every hip [N m s / rad] (0 on the robot: the energy meter's test
        drives the legs against it, in either engine)."""
        ...

    def perturb(
        self, *, friction: float, mass_scale: float, motor_gain: tuple[float, float]
    ) -> None:
        """This world's physical uncertainty for the next drives: Coulomb friction [-], body
        mass as a multiple of the robot's [-], (left, right) motor speed gains [-]."""
        ...

    def step(self) -> None:
        """Advance one timestep, metering the motors' energy."""
        ...

    def advance(self, n: int) -> None:
        """Advance n timesteps at the current leg speeds, metering the motors' energy."""
        ...

    def pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """(p_world_body [m], quat_world_body xyzw) as plain tuples: the controller's fast read."""
        ...

    def body_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(p_world_body (3,) [m], quat_world_body (4,) xyzw)."""
        ...

    def joint_angles(self) -> np.ndarray:
        """(6,) leg angles [rad], hip order L1 L2 L3 R1 R2 R3."""
        ...

    def close(self) -> None:
        """Free the engine's world (once)."""
        ...

    def __enter__(self) -> Simulation: ...

    def __exit__(self, *exc: object) -> None: ...


def _engine_class(engine: str) -> Callable[..., Simulation]:
    """The class of the engine named (imported on first use: MuJoCo loads only if asked)."""
    if engine == "pybullet":
        from ._pybullet import PyBulletSimulation

        return PyBulletSimulation
    if engine == "mujoco":
        try:
            from ._mujoco import MujocoSimulation
        except ModuleNotFoundError as exc:  # (an install without the mujoco wheel)
            if exc.name != "mujoco":
                raise
            raise SimError(
                f"sim.engine mujoco: MuJoCo is not installed here ({exc}); "
                f"`pip install mujoco` or use engine pybullet"
            ) from None
        return MujocoSimulation
    raise SimError(f"sim.engine {engine!r}: expected one of {', '.join(ENGINES)}")


def make_simulation(
    terrain_vertices: np.ndarray,
    terrain_faces: np.ndarray,
    *,
    ground_height: float | None,
    robot: RobotConfig,
    cfg: SimConfig,
) -> Simulation:
    """A fresh world of cfg.engine holding the terrain (vertices (V, 3) [m] world frame, faces
    (F, 3) int), a ground plane at ground_height [m] (None: none) and the robot; the caller
    closes it."""
    return _engine_class(cfg.engine)(
        terrain_vertices, terrain_faces, ground_height=ground_height, robot=robot, cfg=cfg
    )


def open_floor(robot: RobotConfig, cfg: SimConfig) -> Simulation:
    """A world of cfg.engine with nothing but an endless floor at z = 0: the calibrations and
    the reference walks."""
    no_terrain = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
    return make_simulation(*no_terrain, ground_height=0.0, robot=robot, cfg=cfg)
