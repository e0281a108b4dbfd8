"""How to plan: the planner's settings and the validity conditions' tolerances, each with its
validator (roachplan/_settings.py). Importable without OMPL or numpy: the command line checks
`--time-limit` against them before it loads anything."""

from __future__ import annotations

from dataclasses import dataclass, field

from roachplan._settings import boolean, check_settings, integer, one_of, optional, positive
from roachplan._settings import setting as s

from ._names import PLANNER_NAMES, PlannerName

MAX_TIME_LIMIT = 3600.0
"""Largest planning budget [s]: an hour; no plan of a 10 m window is meant to take longer (the
page's Time budget box stops there too)."""


@dataclass(frozen=True, kw_only=True)
class ValidityConfig:
    """Tolerances of the four validity conditions."""

    foot_tolerance: float = s(0.02, positive("m"))
    """Condition 3: the ground under a foot may lie at most this far below the support plane [m]."""
    body_band: float = s(0.03, positive("m"))
    """Condition 2: the ground under the body centre may lie at most this far below the
    support plane [m]."""
    collision_margin: float = s(0.002, positive("m"))
    """Condition 1: the terrain may rise this far into the body's underside before it counts
    as a collision [m] (absorbs interpolation error)."""
    leg_clearance: float = s(0.02, positive("m"))
    """Condition 1, the legs: the terrain where they sweep may rise at most this far above the
    support plane [m]. A leg steps onto a bump lower than its hip (2.5 cm up) and strikes a
    higher one (a chair's foot beside the body flipped the robot in a real room capture)."""
    max_slope_deg: float = s(25.0, positive("deg"))
    """Condition 4: steepest allowed support plane [deg]."""
    noise_sigmas: float = s(2.5, positive())
    """On a capture, conditions 1-3 allow this many standard deviations of the terrain's
    height noise at each sample on top of their tolerances [-]: a floor that is flat within
    the sensor's noise is flat; a step or an object higher than that still counts."""
    max_noise_slack: float = s(0.02, positive("m"))
    """...but at most this much [m]: terrain known worse than that (an airborne survey's 6 cm)
    is not made more walkable by its noise."""

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True, kw_only=True)
class PlannerConfig:
    """How to plan."""

    name: PlannerName = s("prm", one_of(PLANNER_NAMES))
    """OMPL planner, by its class name in lower case."""
    time_limit: float = s(20.0, positive("s", MAX_TIME_LIMIT))
    """Wall-clock budget of one planning request [s]: everything it does to find its path (for
    a drivable plan, every route it searches) stops by then. `roachplan plan` and `trial`, the
    page's Plan and `choose`'s candidates spend one budget on every seed and try they make
    (experiments.plan_many); plans that hit it are not reproducible."""
    max_iterations: int = s(20000, integer(1))
    """Iteration budget (PRM: milestones) after which planning gives up [-]."""
    prm_batch: int = s(25, integer(1))
    """PRM: milestones added between two checks for a start-goal connection [-]."""
    check_resolution: float = s(0.01, positive("m"))
    """Spacing of validity checks along a motion [m]."""
    simplify: bool = s(False, boolean())
    """Shortcut the path: drop needless vertices, then try shortcuts between random pairs of
    points (the report drove raw PRM paths, so off by default)."""
    smooth: bool = s(False, boolean())
    """Round the path's corners with B-spline smoothing, keeping it valid."""
    optimize: bool = s(False, boolean())
    """Optimizing planners (RRT*, PRM*, BIT*, ...) refine path length until the iteration
    budget instead of stopping at their first solution."""
    waypoint_spacing: float = s(0.05, positive("m"))
    """Spacing of the waypoints handed to the driver [m]."""
    turning_radius: float | None = s(0.13, optional(positive("m")))
    """Drivable plans (issue 18): turn the planner's route into arcs of this radius [m] and
    straight lines, every state checked (planning/_drivable.py). From the turning calibration
    (`roachplan calibrate-turning`, sim/_turning.py): the roach turns at most 10.3 /m on flat
    ground, at the driver's largest motor ratio of 3; plans use 3/4 of that (PLAN_HEADROOM),
    1 / (0.75 * 10.3) = 0.129 m, so the tracking driver keeps a third more to correct with
    (tests/test_robot.py re-derives it). None: the planner's raw path, as the report drove it
    (`reference: true`)."""
    spin_margin: float | None = s(0.03, optional(positive("m")))
    """Drivable plans: where no arc of turning_radius goes on, the robot may turn on the spot
    (its sides in opposite directions), every heading of the turn checked at the spin's point
    and round it within this distance [m]: how far the body centre wanders in a spin, 2.1 cm in
    the spin calibration (sim/_turning.py CALIBRATED_SPIN, half turns entered from a walk) plus
    1 cm for where the tracking driver begins it (measured on the floor: up to 2.4 cm in all).
    None: arcs only, no turns on the spot."""
    goal_radius: float = s(0.05, positive("m"))
    """Start and goal closer than this [m] coincide: the plan is trivial (the robot stands where
    the driver counts the goal as reached; a drivable plan turns on the spot to the goal's
    heading when it differs and the turn is valid). The tracking and reference drivers' goal
    radius r_end, 5 cm (Tong 2018, chapter 7)."""
    keep_roadmap: bool = s(False, boolean())
    """Return the planner's graph (roadmap or tree) with the plan, for display."""
    validity: ValidityConfig = field(default_factory=ValidityConfig)
    """Tolerances of the validity conditions."""

    def __post_init__(self) -> None:
        check_settings(self)
