"""The roach's two motors as every engine drives them: each side's phase and commanded speed,
and the leg targets that follow from them through the gait (RobotConfig.leg_angle). Pure
bookkeeping, no physics: sim/_pybullet.py and sim/_mujoco.py each apply the targets as their
engine's PD servo."""

from __future__ import annotations

import numpy as np

from ._robot import RobotConfig


class SideMotors:
    """The left and right motors of one simulated robot: phase [rad] and speed [rad/s] each.
    The three legs of a side follow its motor's phase (with their tripod's offset), as the real
    robot's linkage makes them; a motor runs at its gain times what it is told."""

    def __init__(self, robot: RobotConfig) -> None:
        self.robot = robot
        self.sides = robot.leg_sides
        self.offsets = robot.leg_phase_offsets
        self.phase = np.zeros(2)
        """Motor phase of the left and right side [rad]."""
        self.omega = np.zeros(2)
        """Speed of the left and right side [rad/s] (the command times the gain, clipped)."""
        self.gain = robot.motor_gain
        """Each side's speed / its command [-]."""
        self._ahead: dict[tuple[int, float], np.ndarray] = {}

    def reset(self, phase: tuple[float, float]) -> np.ndarray:
        """Stand at phase (left, right) [rad], stopped; the (6,) leg angles there [rad]."""
        self.phase[:] = phase
        self.omega[:] = 0.0
        q0, _ = self.robot.leg_angle(self.phase[self.sides] + self.offsets)
        return q0

    def command(self, left: float, right: float) -> None:
        """Run the left and right motors at gain x left and right [rad/s], clipped to the
        motor's speed limit."""
        lim = self.robot.max_motor_speed
        self.omega[0] = min(max(left * self.gain[0], -lim), lim)
        self.omega[1] = min(max(right * self.gain[1], -lim), lim)

    def set_gain(self, motor_gain: tuple[float, float]) -> None:
        """The (left, right) motors' gains as multiples of the robot's own [-]."""
        own = self.robot.motor_gain
        self.gain = (float(motor_gain[0]) * own[0], float(motor_gain[1]) * own[1])

    def targets(self, n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Each leg's target angle [rad] and speed [rad/s] after each of the next n steps of dt
        [s] at the current speeds: two (n, 6) arrays."""
        ahead = self._ahead.get((n, dt))
        if ahead is None:
            ahead = self._ahead[(n, dt)] = np.arange(1, n + 1)[:, None] * dt
        omega = self.omega[self.sides]  # (6,) motor speed of each leg's side [rad/s]
        leg_phase = self.phase[self.sides] + self.offsets
        q, dq_dphase = self.robot.leg_angle(leg_phase[None] + ahead * omega[None])
        return q, dq_dphase * omega

    def advance(self, n: int, dt: float) -> None:
        """Move the phases on by n steps of dt [s] at the current speeds."""
        self.phase += self.omega * (n * dt)


def targets_together(motors: list[SideMotors], n: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """SideMotors.targets of several robots' motors (one robot description) at once: two (n,
    k, 6) arrays, [:, j] what motors[j].targets(n, dt) gives, bit for bit (the same
    element-wise operations, one call for all)."""
    robot = motors[0].robot
    sides, offsets = robot.leg_sides, robot.leg_phase_offsets
    phase = np.stack([m.phase for m in motors])[:, sides] + offsets  # (k, 6) [rad]
    omega = np.stack([m.omega for m in motors])[:, sides]  # (k, 6) [rad/s]
    ahead = np.arange(1, n + 1)[:, None] * dt  # (n, 1) [s], as targets makes it
    q, dq_dphase = robot.leg_angle(phase[None] + ahead[:, :, None] * omega[None])
    return q, dq_dphase * omega[None]
