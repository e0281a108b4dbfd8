"""Turning calibration (Tong 2018, appendix A, figure 3.4) and the reference walk for energy.

Both drive the roach on an open floor with fixed motor speeds and measure what it did, so the
controller gain and the energy unit come from the simulated robot itself.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ._config import SimConfig
from ._robot import RobotConfig
from ._simulation import Simulation


@dataclass(frozen=True, kw_only=True)
class TurningSample:
    """One run of the sweep: the left motor at omega0, the right at ratio * omega0."""

    ratio: float
    """Right / left motor speed [-]."""
    distance: float
    """Horizontal distance travelled, summed along the way [m]."""
    revolutions: float
    """Heading change, summed along the way, in turns [-] (positive = to the left)."""
    duration: float
    """Simulated time of the run [s]."""

    @property
    def curvature(self) -> float:
        """2 pi n / d [1/m] (appendix A): the curvature of the circle the robot drove."""
        return 2 * math.pi * self.revolutions / self.distance


@dataclass(frozen=True, kw_only=True)
class TurningModel:
    """curvature = slope * ln(ratio) + intercept, fitted to a sweep (figure 3.4)."""

    slope: float
    """d curvature / d ln(ratio) [1/m]."""
    intercept: float
    """Curvature at equal motor speeds [1/m] (ideally 0)."""
    r_squared: float
    """Coefficient of determination of the fit [-]."""

    def gain_for(self, lookahead: float) -> float:
        """The P gain p of algorithm 2 that steers onto a waypoint `lookahead` metres ahead.

        The controller sets ln(ratio) = p |theta|, so the robot drives on a curvature of
        slope * p * |theta|. The arc that reaches a point at distance L and bearing theta has
        curvature 2 sin(theta) / L ~ 2 theta / L (pure pursuit). Equal for small theta when
        p = 2 / (slope * L).
        """
        return 2.0 / (self.slope * lookahead)


def walk(
    robot: RobotConfig, cfg: SimConfig, left: float, right: float, duration: float
) -> TurningSample:
    """Walk on an open floor at fixed motor speeds [rad/s]; measure distance and turning."""
    with Simulation.open_floor(robot, cfg) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(left, right)
        steps = max(1, round(0.02 / cfg.timestep))  # sample the pose every 20 ms
        (x, y, _), quat = sim.pose()
        yaw = _yaw(quat)
        distance = turned = 0.0
        for _ in range(round(duration / (steps * cfg.timestep))):
            sim.advance(steps)
            (nx, ny, _), quat = sim.pose()
            new_yaw = _yaw(quat)
            distance += math.hypot(nx - x, ny - y)
            turned += (new_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
            x, y, yaw = nx, ny, new_yaw
        return TurningSample(
            ratio=right / left, distance=distance, revolutions=turned / (2 * math.pi),
            duration=sim.time,
        )  # fmt: skip


def _yaw(quat_xyzw) -> float:
    x, y, z, w = quat_xyzw
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def turning_sweep(
    robot: RobotConfig, cfg: SimConfig, omega0: float, ratios, duration: float = 10.0
) -> list[TurningSample]:
    """Appendix A: one walk per motor-speed ratio (right / left >= 1, left at omega0)."""
    return [walk(robot, cfg, omega0, omega0 * r, duration) for r in ratios]


def fit_turning(samples: list[TurningSample]) -> TurningModel:
    """Least-squares line of curvature against ln(ratio)."""
    x = np.log([s.ratio for s in samples])
    k = np.array([s.curvature for s in samples])
    slope, intercept = np.polyfit(x, k, 1)
    residual = k - (slope * x + intercept)
    total = np.sum((k - k.mean()) ** 2)
    r2 = 1.0 - float(np.sum(residual**2) / total) if total > 0 else 1.0
    return TurningModel(slope=float(slope), intercept=float(intercept), r_squared=r2)


@functools.cache
def reference_energy_per_metre(robot: RobotConfig, cfg: SimConfig, omega0: float) -> float:
    """Energy of walking straight on a flat floor at omega0, per metre travelled [J/m].

    The unit of relative energy: a trial's energy divided by this times its start-goal
    distance is ~1.0 when the trial cost as much as walking straight on the floor.
    Cached per configuration (10 simulated seconds, about 0.2 s of wall time).
    """
    with Simulation.open_floor(robot, cfg) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(omega0, omega0)
        start, _ = sim.pose()
        sim.advance(round(10.0 / cfg.timestep))
        end, _ = sim.pose()
        return sim.energy / math.dist(start[:2], end[:2])
