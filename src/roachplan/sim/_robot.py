"""A VelociRoACH-like hexapod for PyBullet: a box body and six continuously rotating legs.

Dimensions and masses follow the real robot where published:
  - Haldane, Peterson, Garcia Bermudez, Fearing, "Animal-inspired design and aerodynamic
    stabilization of a hexapedal millirobot", ICRA 2013: the VelociRoACH is 10 cm long and
    weighs about 30 g; two motors, one per side, each drive the three legs of that side
    through a linkage, giving an alternating-tripod gait.
  - Body width, height and leg length are not tabulated in the paper; they are estimated from
    its photographs (about 4 cm wide, 2 cm tall body; legs reaching about 2.5 cm below the
    hips). Tong 2018, section 4.3, models the robot the same way: a box body and six identical
    legs.

Frames: body frame x forward, y left, z up, origin at the box centre. A leg's joint angle q is a
rotation about the body +y axis; q = 0 points the leg straight down, and q increasing swings the
foot backward while it is on the ground, so positive motor speed walks forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, kw_only=True)
class RobotConfig:
    """Geometry, masses and motor limits of the simulated roach."""

    body_length: float = 0.10
    """Body box length along x [m] (Haldane et al. 2013: 10 cm)."""
    body_width: float = 0.04
    """Body box width along y [m] (estimated from photographs)."""
    body_height: float = 0.02
    """Body box height along z [m] (estimated from photographs)."""
    body_mass: float = 0.024
    """Body mass [kg]; with the legs the robot weighs 30 g (Haldane et al. 2013)."""
    leg_length: float = 0.022
    """Hip-to-foot-centre distance [m]."""
    leg_radius: float = 0.003
    """Radius of the leg capsule and its foot [m]."""
    leg_mass: float = 0.001
    """Mass of one leg [kg]."""
    hip_spacing: float = 0.04
    """Distance along x between front, middle and rear hips [m]."""
    hip_offset_y: float = 0.012
    """How far outside the body side the legs rotate [m]. With it the feet stand about 7 cm
    apart; closer feet (5.6 cm) let the robot roll over in sharp turns on the ramps."""
    max_motor_torque: float = 0.05
    """Torque limit of one leg drive [N m]."""
    max_motor_speed: float = 60.0
    """Motor speed limit [rad/s] (about 10 strides per second)."""
    motor_kp: float = 0.02
    """Proportional gain of a leg's servo on its commanded angle [N m / rad]."""
    motor_kd: float = 3e-4
    """Derivative gain of a leg's servo on its commanded speed [N m s / rad]. Bullet integrates
    joint torques explicitly, so kd dt / I and kp dt^2 / I (I = drive_inertia) must stay well
    below 1: these gains are stable at timesteps up to 2 ms."""
    drive_inertia: float = 1e-6
    """Moment of inertia of a leg with its share of motor rotor and gearbox, about the hip
    [kg m^2]. A 1 g leg alone has ~2e-7; the geared motor's reflected inertia dominates (an
    estimate: not published for the VelociRoACH)."""
    motor_gain: tuple[float, float] = (1.0, 1.0)
    """(left, right) each motor's speed / its command [-]: 1 on the nominal robot; a robot
    file (scenes/_robot_file.py, fitted to a real robot's runs by roachplan.robot.fit) sets
    what that robot's motors do."""
    stance_sweep: float = 1.2
    """Angle a leg sweeps while its tripod is in stance [rad]. The motor phase maps to the leg
    angle through a Buehler clock: the stance arc takes half of every motor revolution and the
    swing the other half, so one tripod is always on the ground, as the real robot's linkage
    keeps it. (Constant-speed spinning legs would drop the body onto the ground twice per stride.)"""

    def leg_angle(self, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Leg angle q [rad] and dq/dphase [-] for motor phases `phase` [rad] (any shape).

        phase in [-pi/2, pi/2] (mod 2 pi) is stance: q sweeps [-s/2, s/2] slowly; the rest of
        the revolution is the swing back to the front, done faster.
        """
        phase = np.asarray(phase, dtype=float)
        turns = np.floor((phase + np.pi / 2) / (2 * np.pi))
        w = phase - 2 * np.pi * turns  # in [-pi/2, 3 pi/2)
        s = self.stance_sweep
        stance = w < np.pi / 2
        q = np.where(stance, w * s / np.pi, s / 2 + (w - np.pi / 2) * (2 * np.pi - s) / np.pi)
        slope = np.where(stance, s / np.pi, (2 * np.pi - s) / np.pi)
        return 2 * np.pi * turns + q, slope

    @property
    def mass(self) -> float:
        """Total mass [kg]."""
        return self.body_mass + 6 * self.leg_mass

    @property
    def hip_positions(self) -> np.ndarray:
        """(6, 3) hip positions in the body frame [m], ordered L1 L2 L3 R1 R2 R3 (front to rear)."""
        y = self.body_width / 2 + self.hip_offset_y + self.leg_radius
        xs = (self.hip_spacing, 0.0, -self.hip_spacing)
        return np.array([(x, y, 0.0) for x in xs] + [(x, -y, 0.0) for x in xs])

    @property
    def leg_sides(self) -> np.ndarray:
        """(6,) 0 for a left leg, 1 for a right leg, in hip order."""
        return np.array([0, 0, 0, 1, 1, 1])

    @property
    def leg_phase_offsets(self) -> np.ndarray:
        """(6,) phase of each leg relative to its side's motor [rad]: tripods L1-R2-L3 and R1-L2-R3."""
        return np.array([0.0, np.pi, 0.0, np.pi, 0.0, np.pi])

    @property
    def standing_height(self) -> float:
        """Height of the body centre above flat ground with a leg pointing straight down [m]."""
        return self.leg_length + self.leg_radius

    @property
    def foot_points_xy(self) -> np.ndarray:
        """(6, 2) horizontal foot positions in the body frame when the legs point down [m]."""
        return self.hip_positions[:, :2].copy()


LEG_NAMES = ("L1", "L2", "L3", "R1", "R2", "R3")
