"""The physical uncertainty of a simulated world (issue 17): how far one real run of the robot
may differ from the nominal simulation. A scene's or an experiment spec's `uncertainty:` key
is read into this; `roachplan choose` draws each rollout's world from it
(experiments/_uncertainty.py, where the defaults' reasons are given in full).

It lives in sim/ (not experiments/) because scene files carry it, and scenes/ may depend on
sim/ but not on experiments/.
"""

from __future__ import annotations

from dataclasses import dataclass

from roachplan._settings import Check, between, check_settings
from roachplan._settings import setting as s

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


def _spread(name: str) -> Check:
    """The validator of spread `name`: a number in its UNCERTAINTY_RANGES range."""
    lo, hi, closed, unit = UNCERTAINTY_RANGES[name]
    return between(lo, hi, unit, high_included=closed)


@dataclass(frozen=True, kw_only=True)
class UncertaintyConfig:
    """Spread of each uncertain quantity; 0 turns it off (reasons for the defaults:
    experiments/_uncertainty.py)."""

    start_xy: float = s(0.01, _spread("start_xy"))
    """The start is uniform in a disc of this radius round the start pose [m] (placed by
    hand: about 1 cm, as the report's best-path re-drives jitter it)."""
    start_yaw: float = s(3.0, _spread("start_yaw"))
    """The start heading is uniform within this many degrees of the start pose's [deg]."""
    friction: float = s(0.2, _spread("friction"))
    """Friction x U(1 - f, 1 + f) [-] (small plastic feet on plywood or carpet: +-20 %)."""
    motor_speed: float = s(0.05, _spread("motor_speed"))
    """Both motors' speed x U(1 - m, 1 + m) [-] (open-loop motors, battery voltage: +-5 %)."""
    motor_mismatch: float = s(0.03, _spread("motor_mismatch"))
    """Left x (1 + d), right x (1 - d), d ~ U(-m, m) [-] (two motors of one type: a few %)."""
    body_mass: float = s(0.1, _spread("body_mass"))
    """The body's mass (and inertia) x U(1 - m, 1 + m) [-] (a payload: +-10 %)."""
    terrain_height: float = s(0.0017, _spread("terrain_height"))
    """Captured terrain only: each vertex of the terrain mesh moves up or down by N(0, s^2)
    [m], a new draw each rollout (the real surface differs from the measured one by about the
    sensor's error). Default: the Kinect v2's axial noise at 2 m, 1.5 - 0.5 z + 0.3 z^2 mm
    (perception/_synthetic.py's noise model, Fankhauser et al. 2015), 1.7 mm. Modelled
    terrain (OpenSCAD, mesh files) is exact and never moved."""

    def __post_init__(self) -> None:
        check_settings(self)


def uncertainty_problem(name: str, value: float) -> str | None:
    """Why `value` is not accepted for field `name` (its allowed range), or None."""
    return _spread(name)(value)
