"""Headless PyBullet simulation of a VelociRoACH-like hexapod and its path-following driver."""

from ._calibration import TurningModel as TurningModel
from ._calibration import TurningSample as TurningSample
from ._calibration import fit_turning as fit_turning
from ._calibration import reference_energy_per_metre as reference_energy_per_metre
from ._calibration import turning_sweep as turning_sweep
from ._config import DriverConfig as DriverConfig
from ._config import SimConfig as SimConfig
from ._driver import DriveResult as DriveResult
from ._driver import Frame as Frame
from ._driver import Outcome as Outcome
from ._driver import drive_path as drive_path
from ._driver import heading_error as heading_error
from ._driver import motor_speeds as motor_speeds
from ._driver import next_waypoint as next_waypoint
from ._driver import quat_to_matrix as quat_to_matrix
from ._robot import LEG_NAMES as LEG_NAMES
from ._robot import RobotConfig as RobotConfig
from ._simulation import SimError as SimError
from ._simulation import Simulation as Simulation
