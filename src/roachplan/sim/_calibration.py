"""Turning calibration (Tong 2018, appendix A, figure 3.4), turning on the spot, and the
reference walk for energy.

All drive the roach on an open floor with fixed motor speeds and measure what it did, so the
controller gain, the spins of drivable plans and the energy unit come from the simulated robot
itself.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ._config import SimConfig
from ._engine import open_floor
from ._errors import SimError
from ._robot import RobotConfig
from ._turning import SpinTurn, TurningCurve


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
    """curvature = slope * ln(ratio) + intercept, the report's model (figure 3.4), fitted to a
    sweep. It fits our robot loosely (R^2 0.78; sim/_turning.py has the curve that fits); the
    reference driver's gain comes from it, so tables 7.1-7.3 stay comparable."""

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
    with open_floor(robot, cfg) as sim:
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
            ratio=right / left,
            distance=distance,
            revolutions=turned / (2 * math.pi),
            duration=sim.time,
        )


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


@dataclass(frozen=True, kw_only=True)
class TurningFit:
    """The turning curve fitted to a sweep, with how well it fits."""

    curve: TurningCurve
    """The fitted curve (sim/_turning.py)."""
    r_squared: float
    """Coefficient of determination over the sweep [-]."""
    rms_residual: float
    """Root mean square of measured minus fitted curvature [1/m]."""
    max_residual: float
    """Largest |measured - fitted| curvature [1/m]."""
    residuals: tuple[float, ...]
    """Measured minus fitted curvature, one per sample in sweep order [1/m]."""


CURVE_MIN_RATIOS = 5
"""Distinct ratios a turning-curve fit needs: it has four parameters [-]."""


def fit_turning_curve(samples: list[TurningSample]) -> TurningFit:
    """Least squares of the TurningCurve to the sweep's curvatures.

    For a fixed (rate, lock_ratio) the curve is linear in (kappa_sat, lock), so those two come
    from a non-negative linear solve on a grid of the other two (rate 0.1-30, lock_ratio from
    just above the largest swept ratio to 4 times it, both log-spaced); the best grid point is
    then refined by bounded least squares. Deterministic: no random starts.
    """
    from scipy.optimize import least_squares, nnls

    r = np.array([s.ratio for s in samples], dtype=float)
    k = np.array([s.curvature for s in samples], dtype=float)
    if len(np.unique(r)) < CURVE_MIN_RATIOS or r.min() < 1.0:
        raise SimError(
            f"a turning curve needs {CURVE_MIN_RATIOS} or more distinct ratios >= 1, "
            f"got {sorted(set(r.tolist()))}"
        )
    x, top = np.log(r), float(np.log(r.max()))

    def basis(rate: float, lock_ratio: float) -> np.ndarray:
        return np.column_stack([1.0 - np.exp(-rate * x), x / (np.log(lock_ratio) - x)])

    best = (math.inf, 0.0, 0.0, 1.0, 2.0)
    for rate in np.geomspace(0.1, 30.0, 60):
        for gap in np.geomspace(1e-3, np.log(4.0), 60):  # ln(lock_ratio) - ln(max ratio)
            lock_ratio = float(np.exp(top + gap))
            coef, norm = nnls(basis(rate, lock_ratio), k)
            if norm < best[0]:
                best = (norm, *coef, rate, lock_ratio)
    _, kappa_sat, lock, rate, lock_ratio = best

    def residual(p: np.ndarray) -> np.ndarray:
        return basis(p[2], np.exp(top + p[3])) @ p[:2] - k

    p0 = np.array([kappa_sat, lock, rate, np.log(lock_ratio) - top])
    lo, hi = np.array([0.0, 0.0, 0.05, 1e-4]), np.array([np.inf, np.inf, 50.0, 2.0])
    p = least_squares(residual, np.clip(p0, lo, hi), bounds=(lo, hi)).x
    curve = TurningCurve(
        kappa_sat=float(p[0]),
        lock=float(p[1]),
        rate=float(p[2]),
        lock_ratio=float(np.exp(top + p[3])),
    )
    res = k - np.array([curve.curvature(v) for v in r])
    total = float(np.sum((k - k.mean()) ** 2))
    return TurningFit(
        curve=curve,
        r_squared=1.0 - float(np.sum(res**2)) / total if total > 0 else 1.0,
        rms_residual=float(np.sqrt(np.mean(res**2))),
        max_residual=float(np.max(np.abs(res))),
        residuals=tuple(res.tolist()),
    )


@dataclass(frozen=True, kw_only=True)
class SpinSample:
    """One spin on the spot: the left motor at -omega, the right at +omega (a left turn),
    measured from the moment the motors were set so."""

    omega: float
    """Speed of each side's motor [rad/s]."""
    turned: float
    """Heading change, summed along the way [rad] (positive = to the left)."""
    displacement: float
    """Horizontal distance of the body centre from where the spin began to where it ended [m]."""
    wander: float
    """Largest horizontal distance of the body centre from where the spin began [m]."""
    energy: float
    """Energy the leg motors spent during the spin [J]."""
    duration: float
    """Simulated time of the spin [s]."""

    @property
    def yaw_rate(self) -> float:
        """Mean yaw rate [rad/s]."""
        return self.turned / self.duration

    @property
    def drift(self) -> float:
        """Displacement per radian turned [m/rad]."""
        return self.displacement / abs(self.turned)

    @property
    def energy_per_radian(self) -> float:
        """Energy per radian turned [J/rad]."""
        return self.energy / abs(self.turned)


def spin(
    robot: RobotConfig,
    cfg: SimConfig,
    omega: float,
    duration: float,
    *,
    lead_in: float = 0.0,
    walk_speed: float = 0.0,
    until: float = math.inf,
) -> SpinSample:
    """Spin on an open floor with the left motor at -omega and the right at +omega [rad/s] for
    `duration` [s], or until `until` [rad] is turned; first walk straight for `lead_in` [s]
    at `walk_speed` [rad/s] (0: the spin starts from rest, legs in tripod stance)."""
    with open_floor(robot, cfg) as sim:
        sim.reset(0.0, 0.0, 0.0)
        if lead_in > 0:
            sim.set_leg_speeds(walk_speed, walk_speed)
            sim.advance(max(1, round(lead_in / cfg.timestep)))
        sim.set_leg_speeds(-omega, omega)
        steps = max(1, round(0.005 / cfg.timestep))  # every 5 ms: the yaw moves < 0.1 rad
        (x0, y0, _), quat = sim.pose()
        yaw, t0, e0 = _yaw(quat), sim.time, sim.energy
        turned = wander = 0.0
        x, y = x0, y0
        while sim.time - t0 < duration - 1e-9 and abs(turned) < until:
            sim.advance(steps)
            (x, y, _), quat = sim.pose()
            new_yaw = _yaw(quat)
            turned += (new_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
            yaw = new_yaw
            wander = max(wander, math.hypot(x - x0, y - y0))
        return SpinSample(
            omega=omega,
            turned=turned,
            displacement=math.hypot(x - x0, y - y0),
            wander=wander,
            energy=sim.energy - e0,
            duration=sim.time - t0,
        )


SPIN_SPEEDS = (5.0, 10.0, 20.0, 30.0)
"""Motor speeds of the spin calibration [rad/s]: up to half the motor's limit; from 20 rad/s
on the feet slip and the yaw rate stops growing."""
SPIN_LEAD_INS = tuple(0.05 * k for k in range(1, 9))
"""Walks before the half-turn spins that measure the wander [s]: 0.05 to 0.4 s, so the spins
begin at phases spread over more than a stride (at 20 rad/s a motor revolution takes 0.31 s)
and with the walk's momentum, as the driver begins them."""


def spin_calibration(
    robot: RobotConfig,
    cfg: SimConfig,
    walk_speed: float,
    speeds=SPIN_SPEEDS,
    duration: float = 10.0,
) -> list[tuple[SpinTurn, SpinSample, list[SpinSample]]]:
    """Turning on the spot at each motor speed of `speeds` [rad/s]: a steady spin from rest for
    `duration` [s] (yaw rate, drift, energy per radian) and half turns (pi rad) entered from a
    straight walk at walk_speed [rad/s] after each of SPIN_LEAD_INS (wander: the largest
    distance of the body centre from where any of them began). Returns, per speed, the
    SpinTurn with the steady spin and the half turns it came from."""
    out = []
    for omega in speeds:
        steady = spin(robot, cfg, omega, duration)
        halves = [
            spin(robot, cfg, omega, duration, lead_in=t, walk_speed=walk_speed, until=math.pi)
            for t in SPIN_LEAD_INS
        ]
        if abs(steady.turned) < 1e-6:
            raise SimError(
                f"the robot did not turn on the spot at motor speeds -{omega:g} and "
                f"+{omega:g} rad/s (turned {steady.turned:.2g} rad in {duration:g} s)"
            )
        turn = SpinTurn(
            omega=omega,
            yaw_rate=steady.yaw_rate,
            drift=steady.drift,
            wander=max(h.wander for h in halves),
            energy_per_radian=steady.energy_per_radian,
        )
        out.append((turn, steady, halves))
    return out


@functools.cache
def reference_energy_per_metre(robot: RobotConfig, cfg: SimConfig, omega0: float) -> float:
    """Energy of walking straight on a flat floor at omega0, per metre travelled [J/m].

    The unit of relative energy: a trial's energy divided by this times its start-goal
    distance is ~1.0 when the trial cost as much as walking straight on the floor.
    Cached per configuration (10 simulated seconds, about 0.2 s of wall time).
    """
    with open_floor(robot, cfg) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(omega0, omega0)
        start, _ = sim.pose()
        sim.advance(round(10.0 / cfg.timestep))
        end, _ = sim.pose()
        return sim.energy / math.dist(start[:2], end[:2])
