"""The physical uncertainty of a simulated world (issue 17): how far one real run of the robot
may differ from the nominal simulation. A scene's or an experiment spec's `uncertainty:` key
is read into this; `roachplan choose` draws each rollout's world from it
(experiments/_uncertainty.py, where the defaults' reasons are given in full).

It lives in sim/ (not experiments/) because scene files carry it, and scenes/ may depend on
sim/ but not on experiments/.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class UncertaintyConfig:
    """Spread of each uncertain quantity; 0 turns it off (reasons for the defaults:
    experiments/_uncertainty.py)."""

    start_xy: float = 0.01
    """The start is uniform in a disc of this radius round the start pose [m] (placed by
    hand: about 1 cm, as the report's best-path re-drives jitter it)."""
    start_yaw: float = 3.0
    """The start heading is uniform within this many degrees of the start pose's [deg]."""
    friction: float = 0.2
    """Friction x U(1 - f, 1 + f) [-] (small plastic feet on plywood or carpet: +-20 %)."""
    motor_speed: float = 0.05
    """Both motors' speed x U(1 - m, 1 + m) [-] (open-loop motors, battery voltage: +-5 %)."""
    motor_mismatch: float = 0.03
    """Left x (1 + d), right x (1 - d), d ~ U(-m, m) [-] (two motors of one type: a few %)."""
    body_mass: float = 0.1
    """The body's mass (and inertia) x U(1 - m, 1 + m) [-] (a payload: +-10 %)."""
    terrain_height: float = 0.0017
    """Captured terrain only: each vertex of the terrain mesh moves up or down by N(0, s^2)
    [m], a new draw each rollout (the real surface differs from the measured one by about the
    sensor's error). Default: the Kinect v2's axial noise at 2 m, 1.5 - 0.5 z + 0.3 z^2 mm
    (perception/_synthetic.py's noise model, Fankhauser et al. 2015), 1.7 mm. Modelled
    terrain (OpenSCAD, mesh files) is exact and never moved."""


UNCERTAINTY_RANGES: dict[str, tuple[float, float, bool, str]] = {
    "start_xy": (0.0, 0.5, True, "m"),
    "start_yaw": (0.0, 180.0, True, "deg"),
    "friction": (0.0, 1.0, False, "-"),
    "motor_speed": (0.0, 1.0, False, "-"),
    "motor_mismatch": (0.0, 1.0, False, "-"),
    "body_mass": (0.0, 1.0, False, "-"),
    "terrain_height": (0.0, 0.05, True, "m"),
}
"""(low, high, high included, unit) of each field. A scale spread must stay below 1 so that
friction, speed and mass stay positive; a start further than 0.5 m off is another start, not
a placing error; 180 degrees is any heading; a height error above 5 cm is a wrong capture,
not sensor noise."""


def uncertainty_problem(name: str, value: float) -> str | None:
    """Why `value` is not accepted for field `name` (its allowed range), or None."""
    lo, hi, closed, unit = UNCERTAINTY_RANGES[name]
    if lo <= value <= hi if closed else lo <= value < hi:
        return None
    upper = f"{hi:g}" if closed else f"below {hi:g}"
    return f"expected a number from {lo:g} to {upper} [{unit}], got {value:g}"
