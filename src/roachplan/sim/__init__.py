"""Headless physics simulation of a VelociRoACH-like hexapod (PyBullet, the reference, or
MuJoCo, behind one seam) and its path-following driver."""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

# Public names, imported on first use (roachplan._lazy): the command line answers at once.
_getattr, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "TurningFit": "._calibration",
        "TurningModel": "._calibration",
        "fit_turning_curve": "._calibration",
        "CALIBRATED_TURNING": "._turning",
        "PLAN_HEADROOM": "._turning",
        "TurningCurve": "._turning",
        "TurningSample": "._calibration",
        "SPIN_SPEEDS": "._calibration",
        "SpinSample": "._calibration",
        "spin_calibration": "._calibration",
        "CALIBRATED_SPIN": "._turning",
        "CALIBRATED_SPINS": "._turning",
        "SpinTurn": "._turning",
        "fit_turning": "._calibration",
        "reference_energy_per_metre": "._calibration",
        "turning_sweep": "._calibration",
        "DriverConfig": "._config",
        "SimConfig": "._config",
        "DriveResult": "._driver",
        "Follower": "._driver",
        "Frame": "._driver",
        "ReferenceFollower": "._driver",
        "TrackingFollower": "._driver",
        "make_follower": "._driver",
        "omega_limit": "._driver",
        "Outcome": "._driver",
        "drive_path": "._driver",
        "heading_error": "._driver",
        "motor_speeds": "._driver",
        "next_waypoint": "._driver",
        "quat_to_matrix": "._driver",
        "LEG_NAMES": "._robot",
        "RobotConfig": "._robot",
        "SimError": "._errors",
        "ENGINES": "._config",
        "Simulation": "._engine",
        "make_simulation": "._engine",
        "drive_lockstep": "._lockstep",
        "engine_settings": "._engine",
        "engine_named": "._engine",
        "engine_driver": "._engine",
        "ENGINE_TURNING": "._turning",
        "ENGINE_SPINS": "._turning",
        "MUJOCO_TURNING": "._turning",
        "MUJOCO_SPINS": "._turning",
        "CALIBRATED_TIMESTEP": "._engine",
        "open_floor": "._engine",
        "PyBulletSimulation": "._pybullet",
        "MujocoSimulation": "._mujoco",
        "UNCERTAINTY_RANGES": "._uncertainty",
        "UncertaintyConfig": "._uncertainty",
        "uncertainty_problem": "._uncertainty",
    },
)
if not TYPE_CHECKING:  # (a type checker sees the names imported below instead, and so
    # reports an import from here of a name that is not one of them)
    __getattr__ = _getattr
del _getattr

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from ._calibration import SPIN_SPEEDS as SPIN_SPEEDS
    from ._calibration import SpinSample as SpinSample
    from ._calibration import TurningFit as TurningFit
    from ._calibration import TurningModel as TurningModel
    from ._calibration import TurningSample as TurningSample
    from ._calibration import fit_turning as fit_turning
    from ._calibration import fit_turning_curve as fit_turning_curve
    from ._calibration import reference_energy_per_metre as reference_energy_per_metre
    from ._calibration import spin_calibration as spin_calibration
    from ._calibration import turning_sweep as turning_sweep
    from ._config import ENGINES as ENGINES
    from ._config import DriverConfig as DriverConfig
    from ._config import SimConfig as SimConfig
    from ._driver import DriveResult as DriveResult
    from ._driver import Follower as Follower
    from ._driver import Frame as Frame
    from ._driver import Outcome as Outcome
    from ._driver import ReferenceFollower as ReferenceFollower
    from ._driver import TrackingFollower as TrackingFollower
    from ._driver import drive_path as drive_path
    from ._driver import heading_error as heading_error
    from ._driver import make_follower as make_follower
    from ._driver import motor_speeds as motor_speeds
    from ._driver import next_waypoint as next_waypoint
    from ._driver import omega_limit as omega_limit
    from ._driver import quat_to_matrix as quat_to_matrix
    from ._engine import CALIBRATED_TIMESTEP as CALIBRATED_TIMESTEP
    from ._engine import Simulation as Simulation
    from ._engine import engine_driver as engine_driver
    from ._engine import engine_named as engine_named
    from ._engine import engine_settings as engine_settings
    from ._engine import make_simulation as make_simulation
    from ._engine import open_floor as open_floor
    from ._errors import SimError as SimError
    from ._lockstep import drive_lockstep as drive_lockstep
    from ._mujoco import MujocoSimulation as MujocoSimulation
    from ._pybullet import PyBulletSimulation as PyBulletSimulation
    from ._robot import LEG_NAMES as LEG_NAMES
    from ._robot import RobotConfig as RobotConfig
    from ._turning import CALIBRATED_SPIN as CALIBRATED_SPIN
    from ._turning import CALIBRATED_SPINS as CALIBRATED_SPINS
    from ._turning import CALIBRATED_TURNING as CALIBRATED_TURNING
    from ._turning import ENGINE_SPINS as ENGINE_SPINS
    from ._turning import ENGINE_TURNING as ENGINE_TURNING
    from ._turning import MUJOCO_SPINS as MUJOCO_SPINS
    from ._turning import MUJOCO_TURNING as MUJOCO_TURNING
    from ._turning import PLAN_HEADROOM as PLAN_HEADROOM
    from ._turning import SpinTurn as SpinTurn
    from ._turning import TurningCurve as TurningCurve
    from ._uncertainty import UNCERTAINTY_RANGES as UNCERTAINTY_RANGES
    from ._uncertainty import UncertaintyConfig as UncertaintyConfig
    from ._uncertainty import uncertainty_problem as uncertainty_problem
