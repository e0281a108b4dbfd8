"""One candidate of a race: its path (CandidatePlan, a value), the tally of its rollouts
(Candidate, the race's record, appended to round by round), and what the tally shows at a
moment (Standing, a value: the row of the ranking) with, once it has left the race, why
(Knockout, a value)."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ._choose_stats import clopper_pearson, mean_interval

GRAVITY = 9.81
"""[m/s^2], for the cost of transport E / (m g d)."""

OutReason = Literal["less_likely", "below_min_success", "costs_more"]
"""Why a candidate left the race: its P(success) interval lies wholly below another's
("less_likely"), its P(success) upper bound is below the min_success asked for
("below_min_success"), or a candidate at least as safe is cheaper with their energy intervals
apart ("costs_more")."""


@dataclass(frozen=True, kw_only=True)
class Knockout:
    """Why a candidate left the race, as the bounds that decided it (at the race's per-candidate
    confidence): its own bound `own_bound` lies beyond `rival_bound`."""

    reason: OutReason
    by: int | None
    """The candidate that beat it: the one with the highest P(success) lower bound
    (less_likely) or the cheaper one (costs_more); None for below_min_success."""
    own_bound: float
    """Its P(success) upper bound [-] (less_likely, below_min_success), or the lower bound of
    its mean relative energy [-] (costs_more)."""
    rival_bound: float
    """What that bound fell short of: `by`'s P(success) lower bound [-] (less_likely),
    min_success [-] (below_min_success), or the upper bound of `by`'s mean relative energy
    [-] (costs_more)."""

    @property
    def sentence(self) -> str:
        """The words the ranking's "out" column has (choice.json, the command line's table)."""
        if self.reason == "less_likely":
            return "less likely to succeed than another (intervals apart)"
        if self.reason == "below_min_success":
            return f"P(success) upper bound below {self.rival_bound:g}"
        return f"costs more energy than candidate {self.by} (intervals apart)"


@dataclass(frozen=True, kw_only=True)
class CandidatePlan:
    """A candidate's path, as planned."""

    index: int
    """Its number in the race, 0 to K - 1."""
    route: str
    """The scene's route it takes ("" where the scene names none)."""
    seed: int
    """The planning seed of its path."""
    path_xyz: np.ndarray
    """(N, 3) float64 waypoints, world frame [m]."""
    length: float
    """Path length in the plane [m]."""
    spins: tuple[tuple[int, float], ...] = ()
    """Its turns on the spot (PlanResult.spins: waypoint index, heading [rad])."""


@dataclass(frozen=True, kw_only=True)
class Standing:
    """What one candidate's rollouts show at a moment: a row of the ranking. Intervals are at
    the race's per-candidate confidence; a bound that does not exist yet is infinite, a mean
    without values nan."""

    candidate: int
    route: str
    plan_seed: int
    length_m: float
    """Path length [m]."""
    rollouts: int
    successes: int
    p_success: float
    """Successes / rollouts [-] (nan without rollouts)."""
    p_low: float
    p_high: float
    relative_energy: float
    """Mean relative energy over the successes [-] (1.0: a straight walk on the floor)."""
    relative_energy_low: float
    relative_energy_high: float
    energy_j: float
    """Mean energy over the successes [J]."""
    cost_of_transport: float
    """energy_j / (m g length) [-]."""
    drive_time_s: float
    """Mean drive time over the successes [s]."""
    failures: tuple[tuple[str, int], ...]
    """(outcome, count) of the failed rollouts, in the order the outcomes first occur."""
    failed_at: tuple[tuple[float, ...], ...]
    """Where the first (at most 10) failed rollouts ended, world frame [m], to the mm."""
    knocked_out: Knockout | None
    """Why it left the race; None while it races."""
    fresh_rollouts: int = 0
    """Of `rollouts`, those in the certifying worlds (experiments/_choose_certify.py) [-]."""
    fresh_successes: int = 0

    @property
    def state(self) -> Literal["racing", "out"]:
        return "racing" if self.knocked_out is None else "out"

    @property
    def energy_j_per_m(self) -> float:
        """Mean energy over the successes per metre of path [J/m]."""
        return self.energy_j / self.length_m

    def to_json(self) -> dict:
        """The ranking row as choice.json, --json and ranking.csv have it."""
        return {
            "candidate": self.candidate,
            "route": self.route,
            "plan_seed": self.plan_seed,
            "length_m": round(self.length_m, 3),
            "rollouts": self.rollouts,
            "successes": self.successes,
            "p_success": self.p_success,
            "p_low": self.p_low,
            "p_high": self.p_high,
            "relative_energy": self.relative_energy,
            "relative_energy_low": self.relative_energy_low,
            "relative_energy_high": self.relative_energy_high,
            "energy_j": self.energy_j,
            "energy_j_per_m": self.energy_j_per_m,
            "cost_of_transport": self.cost_of_transport,
            "drive_time_s": self.drive_time_s,
            "failures": dict(self.failures),
            "failed_at": [list(end) for end in self.failed_at],
            "out": "" if self.knocked_out is None else self.knocked_out.sentence,
            "fresh_rollouts": self.fresh_rollouts,
            "fresh_successes": self.fresh_successes,
        }


@dataclass(eq=False)  # (a record that changes as the race runs: equal only to itself)
class Candidate:
    """One candidate path and the tally of its rollouts: the race's record, its rollouts
    appended round by round (kept in world order) and `knocked_out` set when it leaves."""

    index: int
    route: str
    seed: int
    """The planning seed of its path."""
    path_xyz: np.ndarray
    """(N, 3) float64 waypoints, world frame [m]."""
    length: float
    """Path length [m]."""
    spins: tuple[tuple[int, float], ...] = ()
    """Its turns on the spot (PlanResult.spins)."""
    rollouts: list[dict] = field(default_factory=list)
    """Its rollout records (experiments/_workers.py), in the order of their world seeds."""
    knocked_out: Knockout | None = None
    """Why it left the race (None while in it)."""

    @property
    def out(self) -> str:
        """Why it left the race, in words ("" while in it)."""
        return "" if self.knocked_out is None else self.knocked_out.sentence

    @property
    def n(self) -> int:
        return len(self.rollouts)

    @property
    def successes(self) -> list[dict]:
        return [r for r in self.rollouts if r["outcome"] == "success"]

    @property
    def plan(self) -> CandidatePlan:
        return CandidatePlan(
            index=self.index,
            route=self.route,
            seed=self.seed,
            path_xyz=self.path_xyz,
            length=self.length,
            spins=self.spins,
        )

    def p_interval(self, confidence: float) -> tuple[float, float, float]:
        """(successes / n, low, high) of P(success) [-]."""
        k = len(self.successes)
        lo, hi = clopper_pearson(k, self.n, confidence)
        return (k / self.n if self.n else math.nan), lo, hi

    def energy_interval(self, confidence: float) -> tuple[float, float, float]:
        """(mean, low, high) of the relative energy over the successes [-]."""
        return mean_interval([r["relative_energy"] for r in self.successes], confidence)

    def standing(self, confidence: float, mass: float) -> Standing:
        """What its rollouts show now, intervals at `confidence`; mass: the robot's [kg]."""
        p, p_lo, p_hi = self.p_interval(confidence)
        e, e_lo, e_hi = self.energy_interval(confidence)
        ok = self.successes
        fails = [r for r in self.rollouts if r["outcome"] != "success"]
        mean_j = float(np.mean([r["energy"] for r in ok])) if ok else math.nan
        return Standing(
            candidate=self.index,
            route=self.route,
            plan_seed=self.seed,
            length_m=self.length,
            rollouts=self.n,
            successes=len(ok),
            p_success=p,
            p_low=p_lo,
            p_high=p_hi,
            relative_energy=float(e),
            relative_energy_low=float(e_lo),
            relative_energy_high=float(e_hi),
            energy_j=mean_j,
            cost_of_transport=mean_j / (mass * GRAVITY * self.length),
            drive_time_s=float(np.mean([r["drive_time"] for r in ok])) if ok else math.nan,
            failures=tuple(Counter(r["outcome"] for r in fails).items()),
            failed_at=tuple(tuple(round(v, 3) for v in r["end"]) for r in fails[:10]),
            knocked_out=self.knocked_out,
        )
