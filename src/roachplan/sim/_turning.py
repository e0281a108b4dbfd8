"""The roach's turning curve: motor-speed ratio -> curvature on flat ground, and back (issue 18).

The report models curvature as a line in ln(ratio) (figure 3.4). Our robot does not turn like
that: a sweep of 23 ratios (`roachplan calibrate-turning`) rises about linearly in ln(ratio) up
to a ratio of 1.5, flattens between 1.5 and 2.5 (as a differential drive whose slow side slips
saturates), then climbs steeply to about 10 /m at a ratio of 3, where the fast side makes
exactly three strides per slow one and the two tripod gaits stay in step (phase locking). The line fits that with R^2 0.74-0.78; the curve here, a
saturating term plus a term that grows without bound towards a locking ratio, fits it with
R^2 0.99 (README, "Drivable plans").

Pure functions of plain numbers; no simulation here (the sweep is sim/_calibration.py).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from roachplan._settings import check_settings, is_number, non_negative, positive
from roachplan._settings import setting as s

PLAN_HEADROOM = 0.75
"""Part of the robot's tightest curvature a drivable plan may use [-]; the rest (a third of what
the plan uses) is left for the tracking driver's corrections. The margin the project chose with
the log-linear model (radius 0.16 m from 8.2 /m), kept for the fitted curve: 0.129 m. On
kinect_bridge (25 paths) and bridge_rough (50), plans of 0.13 m and 0.16 m both succeeded every
time, at about the same energy (README, "Drivable plans")."""


def _above_one(v) -> str | None:
    """A motor-speed ratio past equal speeds: above 1 (at 1 both sides walk straight)."""
    return None if is_number(v) and 1 < v < math.inf else "expected a number above 1 [-]"


@dataclass(frozen=True, kw_only=True)
class TurningCurve:
    """curvature(r) = kappa_sat (1 - r^-rate) + lock ln(r) / (ln(lock_ratio) - ln(r)) [1/m], for
    a motor-speed ratio r = fast side / slow side in [1, lock_ratio), on flat ground, slow side at
    the driver's omega0. Body frame: positive curvature turns towards the slow side.

    Both terms are 0 at r = 1 (equal speeds walk straight) and rise with r, so the curve is
    invertible: `ratio_for` gives the ratio that drives a curvature. The defaults are the
    simulated roach's curve (CALIBRATED_TURNING); a scene's `driver.turning` may change some.
    Ratios at or above lock_ratio have an infinite curvature."""

    kappa_sat: float = s(4.199, non_negative("1/m"))
    """Curvature the saturating (slipping differential drive) term tends to [1/m]."""
    rate: float = s(2.147, positive("-"))
    """How fast that term saturates: its part reached at ratio r is 1 - r^-rate [-]."""
    lock: float = s(0.1506, non_negative("1/m"))
    """Scale of the phase-locking term [1/m]."""
    lock_ratio: float = s(3.0772, _above_one)
    """Ratio at which the phase-locking term's curvature grows without bound [-]; above the
    calibrated range, so only ratios below it have a curvature."""

    def __post_init__(self) -> None:
        check_settings(self)

    def curvature(self, ratio: float) -> float:
        """Curvature driven at motor-speed ratio `ratio` (>= 1, < lock_ratio) [1/m]."""
        x = math.log(ratio)
        if x >= math.log(self.lock_ratio):  # at and past the pole: the tightest turn there is
            return math.inf
        return self.kappa_sat * (1.0 - math.exp(-self.rate * x)) + self.lock * x / (
            math.log(self.lock_ratio) - x
        )

    def ratio_for(self, curvature: float, max_ratio: float) -> float:
        """The motor-speed ratio in [1, max_ratio] that drives `curvature` [1/m] (its absolute
        value): the inverse of `curvature`, clipped to the driver's range. Bisection in ln(r):
        the curve has no closed-form inverse, and 40 halvings of ln 3 are exact to 1e-12."""
        k = abs(curvature)
        top, mids, below = _bisection_tree(self, max_ratio)
        if not k < top:  # also inf and nan: the tightest turn there is
            return max_ratio
        # The first _TREE_DEPTH halvings from the tree (their midpoints and curvatures are the
        # same every call), the rest as they come: the driver asks this every control period.
        lo, hi, node = 0.0, math.log(max_ratio), 0
        k_lo, k_hi = 0.0, top  # (the curvatures at lo and hi, for _bracket's first guess)
        for _ in range(_TREE_DEPTH):
            if below[node] < k:
                lo, k_lo, node = mids[node], below[node], 2 * node + 2
            else:
                hi, k_hi, node = mids[node], below[node], 2 * node + 1
        # The rest as they come, each decided by comparing mid with a bracket of the crossing
        # where that is shown to give the same turn, else by the curvature there.
        a, b = _bracket(self, k, (lo, k_lo), (hi, k_hi))
        for _ in range(_HALVINGS - _TREE_DEPTH):
            mid = 0.5 * (lo + hi)
            if mid <= a or (mid < b and self.curvature(math.exp(mid)) < k):
                lo = mid
            else:
                hi = mid
        return math.exp(0.5 * (lo + hi))

    def min_turning_radius(self, max_ratio: float, headroom: float = PLAN_HEADROOM) -> float:
        """Radius of the tightest arc a plan may ask for [m]: 1 / (headroom * curvature at the
        driver's largest ratio). headroom < 1 keeps part of the turning range for the driver's
        corrections, on top of the arc it follows."""
        return 1.0 / (headroom * self.curvature(max_ratio))


_HALVINGS = 40
"""ratio_for's bisection steps."""
_TREE_DEPTH = 14
"""Its first steps taken from a table (2^14 - 1 nodes, computed once per curve and range)."""


@functools.lru_cache(maxsize=32)
def _bisection_tree(curve: TurningCurve, max_ratio: float) -> tuple[float, list, list]:
    """(curvature at max_ratio, the midpoints [ln ratio], the curvature at each [1/m]) of
    ratio_for's first _TREE_DEPTH halvings of [0, ln max_ratio], as a heap: node i's lower
    half is node 2i+1, its upper 2i+2. Made by the very arithmetic ratio_for does, so a walk
    down it takes the same turns and reaches the same bits."""
    mids, below = [0.0] * (2**_TREE_DEPTH - 1), [0.0] * (2**_TREE_DEPTH - 1)
    bounds = [(0.0, math.log(max_ratio))]
    for node in range(len(mids)):
        lo, hi = bounds[node]
        mid = 0.5 * (lo + hi)
        mids[node] = mid
        below[node] = curve.curvature(math.exp(mid))  # (inf at and past the pole)
        bounds += [(lo, mid), (mid, hi)]
    return curve.curvature(max_ratio), mids, below


_SAFETY = 100.0
"""How many times its rounding error the curvature at a bracket's end must lie from the one
asked for [-]."""


def _bracket(
    curve: TurningCurve, k: float, low: tuple[float, float], high: tuple[float, float]
) -> tuple[float, float]:
    """(a, b) round the crossing in [lo, hi] (low = (lo, k_lo), high = (hi, k_hi): ln ratio
    and the curvature there [1/m]) of ratio_for's test `curvature(exp(mid)) < k`, such that
    the test is true at every mid <= a and false at every mid >= b; (-inf, inf) where that
    cannot be shown, and every halving then computes its test. Why: the driver asks
    ratio_for every control period, and each of its last 26 halvings computed three
    transcendental functions; with the crossing found first, all but the last two or three
    are a comparison.

    Shown, not assumed: the crossing is guessed between lo and hi and refined by a Newton
    step; the test is then computed at a and b themselves, as the halvings compute it, and
    each curvature must clear k by _SAFETY times its rounding error. The curve rises, so at any
    mid below a the computed curvature lies below a's plus twice that error: below k; the same
    above b. A curve too flat there, or too near its pole, gets no bracket."""
    (lo, k_lo), (hi, k_hi) = low, high
    ks, rate, lock, pole = curve.kappa_sat, curve.rate, curve.lock, math.log(curve.lock_ratio)
    rise = k_hi - k_lo
    if not (0.0 < rise < math.inf and hi < pole - 1e-3):
        return -math.inf, math.inf  # (near the pole the curvature loses its last digits)
    x = lo + (k - k_lo) / rise * (hi - lo)  # (within 1e-9 of the crossing: the span is 7e-5)
    e, gap = math.exp(-rate * x), pole - x
    slope = ks * rate * e + lock * pole / (gap * gap)  # d curvature / d ln ratio [1/m]
    if not slope > 0.0:
        return -math.inf, math.inf
    x -= (ks * (1.0 - e) + lock * x / gap - k) / slope
    # The computed curvature's rounding error: a few ulps of each term, the lock term's
    # cancellation in pole - x (an ulp of the pole over the gap), and ln(exp(mid))'s ulp
    # times the slope.
    lock_term = lock * abs(x) / gap
    margin = _SAFETY * (1e-15 * (ks + lock_term + slope) + lock_term * 2.3e-16 * pole / gap)
    delta = 4.0 * margin / slope
    a, b = x - delta, x + delta
    if not lo <= a < b <= hi:  # (a curve too flat here to gain anything; or no crossing)
        return -math.inf, math.inf
    # (the test's own computation at a and b: the curvature at exp(mid), as the halvings)
    if curve.curvature(math.exp(a)) - k < -margin and curve.curvature(math.exp(b)) - k > margin:
        return a, b
    return -math.inf, math.inf


CALIBRATED_TURNING = TurningCurve()
"""The turning curve of the simulated roach, as `roachplan calibrate-turning` fits it (default
sweep: 23 ratios from 1 to 3, 10 s each, slow side at 20 rad/s, flat floor, friction 0.9):
R^2 0.989, residuals rms 0.21 /m, at most 0.49 /m (at ratio 1.5); 10.3 /m at ratio 3.
tests/test_robot.py re-runs the calibration and checks these numbers."""


@dataclass(frozen=True, kw_only=True)
class SpinTurn:
    """Turning on the spot: the two sides' motors run at -omega and +omega (left -omega turns
    left, mirrored for a right turn), so the tripods push the body round its centre. Measured
    on flat ground by `spin_calibration` (sim/_calibration.py); body frame: positive yaw is to
    the left."""

    omega: float
    """Speed of each side's motor [rad/s], one side backwards."""
    yaw_rate: float
    """Mean yaw rate of a steady spin from rest [rad/s]."""
    drift: float
    """Net horizontal displacement of the body centre per radian turned over that steady spin
    [m/rad]: the spin's slow creep."""
    wander: float
    """Largest horizontal distance of the body centre from where a half-turn spin began, over
    half turns entered from a straight walk at the driver's omega0 (each from another phase of
    the gait) [m]: the walk's momentum and the gait's sway, what drivable plans leave room for
    round a spin (planner.spin_margin)."""
    energy_per_radian: float
    """Energy the leg motors spend per radian turned in that steady spin [J/rad]."""


CALIBRATED_SPINS = (
    SpinTurn(omega=5.0, yaw_rate=0.7378, drift=0.00037, wander=0.0209, energy_per_radian=0.01122),
    SpinTurn(omega=10.0, yaw_rate=1.441, drift=0.00045, wander=0.0209, energy_per_radian=0.01227),
    SpinTurn(omega=20.0, yaw_rate=2.828, drift=0.00097, wander=0.0289, energy_per_radian=0.01614),
    SpinTurn(omega=30.0, yaw_rate=2.804, drift=0.00069, wander=0.0682, energy_per_radian=0.03494),
)
"""Turning on the spot as `roachplan calibrate-turning` measures it (sim/_calibration.py,
`spin_calibration`; flat floor, friction 0.9): per motor speed, a 10 s spin from rest gives the
yaw rate, the drift and the energy per radian, and 8 half turns entered from a straight walk at
20 rad/s (after 0.05-0.4 s of walking) give the wander. The yaw rate grows in proportion to the
speed up to 20 rad/s (0.144 rad/s per rad/s) and stops there (at 30 rad/s the feet slip: twice
the energy per radian and 7 cm of wander). A right turn (left +omega, right -omega) is the exact
mirror. tests/test_robot.py re-runs the calibration and checks these numbers."""

CALIBRATED_SPIN = CALIBRATED_SPINS[1]
"""The spin the tracking driver makes (DriverConfig.spin_speed, 10 rad/s): 1.44 rad/s, within
4 % of the cheapest energy per radian (5 rad/s: 0.0112 J/rad) at twice its rate; 20 rad/s turns
twice as fast for a third more energy per radian and wanders 2.9 cm instead of 2.1 cm."""


MUJOCO_TURNING = TurningCurve(kappa_sat=3.077, rate=3.529, lock=0.3448, lock_ratio=4.3238)
"""The MuJoCo roach's turning curve (sim/_mujoco.py at its calibrated 2 ms step), as
`roachplan calibrate-turning --engine mujoco` fits it (the same sweep as CALIBRATED_TURNING's):
R^2 0.907, residuals rms 0.33 /m, at most 0.66 /m. It rises with PyBullet's up to a ratio of
1.5 (3.1 /m against 3.0 /m) and then stays near 3 /m: 4.05 /m at ratio 3, where PyBullet's
tripods phase-lock and reach 10.3 /m. Its softer contacts let the slow side slip sooner (a
contact time constant of 20 ms turned at 5.4-6.9 /m but walked 12 % less far). So the same
drivable plan (arcs down to 0.13 m radius, PyBullet's headroom) asks more of this robot than
it can turn: the driver asks the engine's own curve and saturates at max_ratio."""

MUJOCO_SPINS = (
    SpinTurn(omega=5.0, yaw_rate=0.7289, drift=0.00035, wander=0.0126, energy_per_radian=0.00955),
    SpinTurn(omega=10.0, yaw_rate=1.366, drift=0.00033, wander=0.0156, energy_per_radian=0.01075),
    SpinTurn(omega=20.0, yaw_rate=2.541, drift=0.00017, wander=0.0233, energy_per_radian=0.01677),
    SpinTurn(omega=30.0, yaw_rate=2.870, drift=0.00018, wander=0.0319, energy_per_radian=0.03576),
)
"""Turning on the spot under MuJoCo, measured as CALIBRATED_SPINS (`calibrate-turning --engine
mujoco`): within 5-12 % of PyBullet's yaw rates, a third less wander."""

ENGINE_TURNING = {"pybullet": CALIBRATED_TURNING, "mujoco": MUJOCO_TURNING}
"""Each engine's calibrated turning curve: what the driver asks it for an arc with."""
ENGINE_SPINS = {"pybullet": CALIBRATED_SPINS, "mujoco": MUJOCO_SPINS}
"""Each engine's calibrated spins."""
