"""Settings of the physics world and of the path-following driver."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from roachplan._settings import check_settings, integer, one_of, positive
from roachplan._settings import setting as s

from ._turning import CALIBRATED_SPIN, CALIBRATED_TURNING, TurningCurve

ENGINES: tuple[str, ...] = ("pybullet", "mujoco")
"""The physics engines behind the seam (sim/_engine.py): PyBullet, the default and the
reference every table was measured with, and MuJoCo, the fast one."""


@dataclass(frozen=True, kw_only=True)
class SimConfig:
    """Physics settings of one simulated world."""

    engine: Literal["pybullet", "mujoco"] = s("pybullet", one_of(ENGINES))
    """Physics engine: pybullet (the reference: the project's tables were measured with it) or
    mujoco (faster). What each was calibrated to (timestep, turning curve, spins) is data in
    sim/_engine.py (CALIBRATED_TIMESTEP) and sim/_turning.py (ENGINE_TURNING, ENGINE_SPINS)."""
    timestep: float = s(1.0 / 1000.0, positive("s"))
    """Fixed physics step [s]. Halving it changes a 10 s floor walk by < 0.5 % in distance and
    < 2.5 % in energy (README, timestep study)."""
    solver_iterations: int = s(30, integer(1))
    """Constraint-solver iterations per step."""
    friction: float = s(0.9, positive("-"))
    """Coulomb friction coefficient of feet, body and terrain [-]."""
    settle_time: float = s(0.3, positive("s"))
    """Time the robot stands still after being dropped at its start pose [s]."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class DriverConfig:
    """How the roach follows a path: `tracking` (pure pursuit along the path's arc length, the
    default) or `reference` (Tong 2018's algorithm 1, waypoint by waypoint, with the
    differential-drive P-controller of algorithm 2)."""

    kind: Literal["tracking", "reference"] = s("tracking", one_of(("tracking", "reference")))
    """tracking: steer onto the point `lookahead` metres further along the path than the
    robot's progress, which only grows, so a passed waypoint is never chased back;
    reference: algorithms 1 and 2 exactly as the report gives them (tables 7.1-7.3)."""
    lookahead: float = s(0.14, positive("m"))
    """tracking: distance along the path from the robot's progress to the point it steers to
    [m]. Shorter tracks tighter and oscillates: at 0.1 m relative energy rose by about 20 % on
    kinect_bridge and double_bridge_rough; at 0.2 m the robot drifted 2-3 cm outside a tight
    first turn on a real floor capture (region_growing) and flipped on the obstacle the path
    passes, every seed. 0.14 m (1.4 body lengths) succeeded on all three."""
    turning: TurningCurve = CALIBRATED_TURNING
    """tracking: the robot's motor ratio -> curvature curve on flat ground, fitted by the turning
    calibration (`roachplan calibrate-turning`, sim/_turning.py): the driver asks for the arc it
    wants with the ratio `turning.ratio_for(curvature)`, so its steering gain follows from the
    calibration rather than from tuning."""

    omega0: float = s(20.0, positive("rad/s"))
    """Base leg speed of both sides [rad/s]."""
    gain: float = s(2.7, positive("1/rad"))
    """P gain p: the faster side turns at omega0 * exp(|p * theta|) [1/rad]. Derived from the
    turning calibration (`roachplan calibrate-turning`, appendix A): curvature = 7.46 ln(ratio)
    on flat ground, and p = 2 / (7.46 * r_path) makes the controller drive the pure-pursuit arc
    onto a waypoint r_path ahead (see sim/_calibration.py, TurningModel.gain_for)."""
    max_ratio: float = s(3.0, positive("-"))
    """Cap on the fast side's speed relative to omega0 [-]: the exponential of algorithm 2 grows
    without bound, a real motor does not."""
    r_path: float = s(0.1, positive("m"))
    """Radius within which an intermediate waypoint counts as reached [m]."""
    r_end: float = s(0.05, positive("m"))
    """Radius within which the goal counts as reached [m] (Tong 2018, chapter 7: 5 cm)."""
    time_limit: float = s(60.0, positive("s"))
    """Simulated time allowed to reach the goal [s] (Tong 2018, chapter 7: 60 s)."""
    control_period: float = s(0.02, positive("s"))
    """Time between two controller updates [s]."""
    fall_drop: float = s(0.08, positive("m"))
    """A body this far below the planned surface under it has fallen off that surface [m]."""
    stuck_time: float = s(10.0, positive("s"))
    """A drive that makes no progress for this long is stuck [s]."""
    stuck_distance: float = s(0.02, positive("m"))
    """Progress: the next waypoint reached, or this much closer to it [m]."""
    spin_speed: float = s(CALIBRATED_SPIN.omega, positive("rad/s"))
    """tracking: speed of each side's motor while the robot turns on the spot at a plan's spin,
    one side backwards [rad/s]. 10 rad/s turns at 1.44 rad/s for 0.0123 J/rad (the spin
    calibration, sim/_turning.py CALIBRATED_SPIN; 20 rad/s: twice the rate, a third more energy
    per radian, more wander). The reference driver makes no spins."""
    spin_tolerance: float = s(0.05, positive("rad"))
    """tracking: a spin ends when the heading is within this of the spin's [rad]; pure pursuit
    corrects what is left. The gait sways the heading by up to 0.12 rad about its mean within a
    spin (measured at 10 and 20 rad/s), so a tighter tolerance mostly turns back and forth
    longer."""
    stuck_angle: float = s(0.1, positive("rad"))
    """Progress during a spin: this much closer to the spin's heading [rad] (a spin making
    angular progress is never stuck)."""
    frame_period: float = s(1.0 / 30.0, positive("s"))
    """Simulated time between two recorded trajectory samples [s]."""

    def __post_init__(self) -> None:
        check_settings(self)
