"""The race loop: rounds of rollouts to the candidates the policy picks (experiments/
_choose_policy.py), the clearly beaten leaving after each round, until a decision, the rollout
cap or the time budget; what happens is told as events (experiments/_choose_events.py) and
returned as a Choice.

Rollout k of every candidate drives the world of seed world_seed(seed, k) (common random
numbers: the candidates are compared in the same worlds). Rounds end only when all their
rollouts are in, so with a rollout cap (not a time budget) the same seed gives the same choice.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ._choose_candidate import Candidate, Standing
from ._choose_config import ChooseConfig
from ._choose_events import (
    CUT_SHORT,
    ChooseEvent,
    Decided,
    KnockedOut,
    RoundDone,
    StopReason,
)
from ._choose_policy import confidence_reached, decision, eliminate, rank, to_sample
from ._uncertainty import rollout_seed

if TYPE_CHECKING:
    from ._choose_certify import Guarantee


@dataclass(frozen=True, kw_only=True)
class Choice:
    """The outcome of a race."""

    chosen: int | None
    """Index of the chosen candidate (None: no candidate ever succeeded)."""
    standings: tuple[Standing, ...]
    """Every candidate's standing, best first."""
    stop: StopReason
    """Why the race stopped (experiments/_choose_events.py)."""
    stopped: str
    """Why the race stopped, in words (with, when cut short, the confidence it reached)."""
    rollouts: int
    wall_time: float
    """[s]"""
    candidates: list[Candidate]
    confidence_reached: float | None = None
    """When the race ended on its budget or cap short of a decision: the highest joint
    confidence (from 0.5) at which the ranking's first is within the indifference zone on the
    rollouts it had, to 0.01; None when it decided, or not even at 0.5."""
    guarantee: Guarantee | None = None
    """What the choice is shown to be (screen then certify); None for the race (procedure "race")."""
    fresh: dict[int, list[dict]] = field(default_factory=dict)
    """The certifying rollouts' records by candidate (screen then certify)."""
    cross_check: dict | None = None
    """The same rollouts under the other physics engine, per path, and whether the engines
    agree (experiments/_cross_check.py; choose(cross_check=True)), else None."""

    @property
    def ranking(self) -> list[dict]:
        """Every candidate's ranking row (Standing.to_json), best first."""
        return [s.to_json() for s in self.standings]

    @property
    def cut_short(self) -> bool:
        """Stopped by the budget, the rollout cap or max_per_candidate, not by a decision."""
        return self.stop in CUT_SHORT


def world_seed(seed: int, k: int) -> int:
    """The seed of the world of every candidate's rollout k in a race seeded `seed` (common
    random numbers: candidates are compared in the same worlds)."""
    return rollout_seed(seed, 0, k)


def race(
    candidates: list[Candidate],
    cfg: ChooseConfig,
    run_rollouts: Callable[[list[tuple]], list[dict]],
    *,
    mass: float,
    on_event: Callable[[ChooseEvent], None] | None = None,
    cancelled: Callable[[], bool] = lambda: False,
) -> Choice:
    """Race the candidates (their tallies grow as it runs). run_rollouts(calls) runs
    [(candidate index, path, seed)] and returns their rollout records (any order); mass: the
    robot's [kg], for the cost of transport. on_event receives each KnockedOut, RoundDone and
    the Decided (experiments/_choose_events.py), in the calling thread; the events are built
    only when it is given."""
    t0 = time.monotonic()
    conf = 1 - (1 - cfg.confidence) / max(len(candidates), 1)  # (Bonferroni over the K)
    used = rounds = 0
    per_rollout = 0.0  # wall time per rollout in the last round [s]
    while True:
        alive = [c for c in candidates if c.knocked_out is None]
        # A lone candidate from the start is not a decision: it races on (alone) until the
        # budget or cap, so that its P(success) is measured, not left at "unknown".
        if len(alive) <= 1 and len(candidates) > 1:
            stop: StopReason = "separated"
            break
        verdict = decision(alive, conf, cfg) if len(candidates) > 1 else None
        if verdict is not None:
            stop = verdict
            break
        if cancelled():
            stop = "cancelled"
            break
        room = None if cfg.rollouts is None else cfg.rollouts - used
        if not alive:  # only when no candidate was planned
            stop = "no_candidates"
            break
        targets = to_sample(alive, conf, cfg)
        if not targets:
            stop = "max_per_candidate"
            break
        if room is not None and room < len(targets):
            stop = "rollout_cap"
            break
        per = cfg.batch if room is None else min(cfg.batch, room // len(targets))
        calls = [
            (c.index, c.path_xyz.tolist(), world_seed(cfg.seed, c.n + j))
            for c in targets
            for j in range(per)
        ]
        # Stop before a round that would overrun the budget (a rollout takes about as long as
        # one of the last round did).
        if cfg.budget_s is not None and (
            time.monotonic() - t0 + per_rollout * len(calls) >= cfg.budget_s
        ):
            stop = "time_budget"
            break
        t_round = time.monotonic()
        _add_rollouts(run_rollouts(calls), candidates)
        per_rollout = (time.monotonic() - t_round) / len(calls)
        used += len(calls)
        rounds += 1
        beaten = eliminate(alive, conf, cfg.min_success, cfg.indifference[0])
        if on_event is not None:
            spent = (
                used / cfg.rollouts
                if cfg.rollouts
                else (time.monotonic() - t0) / (cfg.budget_s or 1)
            )
            _tell_round(
                on_event,
                rounds,
                beaten,
                targets,
                candidates,
                used=used,
                fraction=spent,
                conf=conf,
                mass=mass,
            )
    ordered = rank(candidates, conf, cfg.min_success)
    chosen = next((c.index for c in ordered if c.successes), None)
    reached = None
    if stop in CUT_SHORT and len(candidates) > 1:
        reached = confidence_reached(alive, len(candidates), cfg)  # (alive: as it stopped)
    decided = Decided(
        chosen=chosen,
        stop=stop,
        stopped=_stopped(stop, cfg, reached, lone=len(candidates) <= 1),
        confidence=cfg.confidence,
        confidence_reached=reached,
        rollouts=used,
        rounds=rounds,
        standings=tuple(c.standing(conf, mass) for c in ordered),
        wall_time_s=time.monotonic() - t0,
    )
    if on_event is not None:
        on_event(decided)
    return Choice(
        chosen=decided.chosen,
        standings=decided.standings,
        stop=decided.stop,
        stopped=decided.stopped,
        rollouts=decided.rollouts,
        wall_time=decided.wall_time_s,
        candidates=candidates,
        confidence_reached=decided.confidence_reached,
    )


def _add_rollouts(records: list[dict], candidates: list[Candidate]) -> None:
    """Add a round's rollout records to their candidates' tallies, each tally in the order of
    its world seeds: the order the records came back in must not matter."""
    for rec in records:
        candidates[rec["candidate"]].rollouts.append(rec)
    for i in {rec["candidate"] for rec in records}:
        candidates[i].rollouts.sort(key=lambda r: r["seed"])


def _tell_round(
    on_event: Callable[[ChooseEvent], None],
    round_no: int,
    beaten: list[Candidate],
    driven: list[Candidate],
    candidates: list[Candidate],
    *,
    used: int,
    fraction: float,
    conf: float,
    mass: float,
) -> None:
    """A round's events: a KnockedOut for each candidate it beat, then its RoundDone."""
    for c in beaten:
        assert c.knocked_out is not None  # (beaten: eliminate() set why)
        on_event(KnockedOut(candidate=c.index, round=round_no, why=c.knocked_out))
    on_event(
        RoundDone(
            round=round_no,
            rollouts=used,
            fraction=min(fraction, 1.0),
            driven=tuple(c.index for c in driven),
            standings=tuple(c.standing(conf, mass) for c in candidates),
        )
    )


def _stopped(stop: StopReason, cfg: ChooseConfig, reached: float | None, *, lone: bool) -> str:
    """Why the race stopped, in words; when cut short with more than one candidate (not
    `lone`), with the confidence at which its first-ranked stood within the indifference
    zone."""
    dp, de = cfg.indifference
    match stop:
        case "separated":
            words = f"separated at {cfg.confidence:.0%} confidence"
        case "one_qualifies":
            words = f"only one candidate clears P(success) >= {cfg.min_success:g}"
        case "indifference_zone":
            words = (
                f"within the indifference zone (P {dp:g}, energy {de:.0%}) at "
                f"{cfg.confidence:.0%} confidence"
            )
        case "cancelled":
            words = "cancelled"
        case "no_candidates":
            words = "no candidate to race"
        case "max_per_candidate":
            words = f"every candidate has its {cfg.max_per_candidate} rollouts"
        case "rollout_cap":
            words = f"rollout cap of {cfg.rollouts} reached"
        case "time_budget":
            words = f"time budget of {cfg.budget_s:.1f} s spent"
        case _:  # (the certify procedure's own stops)
            words = stop
    if stop not in CUT_SHORT or lone:
        return words
    if reached is not None:
        return (
            f"{words}; the first-ranked is within the indifference zone at {reached:.0%} "
            f"confidence (not {cfg.confidence:.0%})"
        )
    if cfg.indifference != (0.0, 0.0):
        return (
            words + "; the first-ranked is not within the indifference zone even at 50% confidence"
        )
    return words
