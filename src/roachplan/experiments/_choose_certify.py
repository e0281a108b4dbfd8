"""Screen, then certify: choose a path with a guarantee that holds however often the race looks.

The claim, for the chosen candidate c at confidence 1 - delta, with the safety level
p* = 1 - eps_P (or min_success) and the energy margin eps_E (ChooseConfig.indifference):

    P_c >= p*, and E_c <= (1 + eps_E) E_j for every candidate j with P_j >= p*

(E: mean relative energy of a successful drive; compared in the worlds both succeeded in).
That is, in words: "path c succeeds at least 95 % of the time and is within 5 % of the lowest
energy among the paths that safe".

1. Screen (any rule may choose; it only decides what is certified): rounds of `batch`
   rollouts in common worlds (stream 0, as the race's), given to the candidates a
   Bayesian posterior (flat Beta priors on P, normal posteriors on the mean energy; draws from
   the race's seed) still calls contenders. Screening ends when the leader is plausibly safe
   (posterior P(P_c >= p*) >= 0.5) and, if safe, within eps_E of the cheapest safe candidate
   with posterior probability SCREEN_SURE, or when its share of the budget (SCREEN_SHARE) is
   spent. The leader (highest posterior probability of meeting the claim) is chosen.
2. Certify on fresh worlds (stream 5, unseen by the screening, so choosing c from the
   screening's numbers costs no multiplicity): each round drives c and every rival not yet
   settled, `batch` times, in the same new worlds. With error budgets (delta split, below)
   that hold at every look (experiments/_choose_bounds.py):
   - P_c >= p* is shown by c's fresh rollouts alone, at delta / 2;
   - a rival is settled when its P_j < p* is shown on all its rollouts (any of the K at
     delta / 4 / K, so whichever are rivals), or when the upper bound on the mean of
     E_c - (1 + eps_E) E_j over the fresh worlds both succeeded in is <= 0 (each of the K - 1
     at delta / 4 / (K - 1)).
   The union of these events has probability at most delta, so the claim, when stated, holds
   with probability at least 1 - delta. The race stops certified, or when the certificate can
   no longer come (c's P shown below p*, or a rival shown safe and cheaper by more than eps_E),
   or on its budget or rollout cap: it then states the guarantee it reached (c's P lower bound,
   and how close in energy it is shown to be to each rival), at the same confidence.

Rollout k of the screening drives the world of seed world_seed(seed, k); certify round k the
world of fresh_seed(seed, k); with a rollout cap (not a time budget) the same seed gives the
same choice.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from dataclasses import replace as dataclass_replace
from typing import Literal

import numpy as np

from ._choose_bounds import (
    excess_reached,
    mean_bounds,
    mean_upper,
    p_lower,
    p_upper,
    shows_at_least,
    shows_below,
)
from ._choose_candidate import Candidate, Standing
from ._choose_config import ChooseConfig
from ._choose_events import ChooseEvent, Decided, RoundDone, StopReason
from ._choose_race import Choice, world_seed
from ._uncertainty import rollout_seed

SCREEN_SHARE = 0.35
"""Most of the budget (time, or the rollout cap) the screening may spend [-]."""
SCREEN_SURE = 0.9
"""Posterior probability at which the screening's leader is taken [-]."""
FRESH_STREAM = 5
"""The seed stream of the certifying worlds (0: the screening, 1: --validate, 2-4: the
benchmark's)."""
POSTERIOR_DRAWS = 2000
"""Monte Carlo draws of the posterior per look [-]."""


def fresh_seed(seed: int, k: int) -> int:
    """The seed of certify world k of a choice seeded `seed` (every candidate driven there)."""
    return rollout_seed(seed, 0, k, stream=FRESH_STREAM)


@dataclass(frozen=True, kw_only=True)
class Guarantee:
    """What the choice is shown to be, at `confidence`, on fresh rollouts: the claim in the
    module docstring when `certified`, else what was reached of it."""

    certified: bool
    confidence: float
    """1 - delta [-]."""
    p_level: float
    """p*, the safety level claimed [-]."""
    energy_margin: float
    """eps_E, the energy margin claimed [fraction]."""
    p_lower: float
    """Lower bound on the chosen path's P(success) reached on its fresh rollouts [-]."""
    energy_reached: float
    """The smallest margin e shown for every rival not shown below p*: E_c <= (1 + e) E_j
    [fraction]; 0 when every rival is shown unsafe; inf when some rival is not bounded."""
    fresh_rollouts: int
    fresh_successes: int
    rollouts: int
    """The chosen path's rollouts in all, screening and fresh (what the evidence is)."""
    successes: int
    """Its successes among them."""
    unsafe: tuple[int, ...]
    """Rivals shown to succeed less often than p*."""
    compared: tuple[tuple[int, float], ...]
    """(rival, e): rivals compared in energy, each with the margin shown against it."""
    unsettled: tuple[int, ...]
    """Rivals neither shown unsafe nor within energy_margin (empty when certified)."""
    posterior: float
    """Bayesian posterior probability (flat priors) that the chosen path meets the claim [-]:
    not a confidence, shown beside it."""

    def sentence(self, chosen: int, *, noun: str = "candidate", first: int = 0) -> str:
        """The guarantee in plain words, paths named `noun` and their index + `first` (the
        command line's candidate 2 is the page's path 3)."""
        name = f"{noun} {chosen + first}"
        conf = f"at {self.confidence:.0%} confidence"
        if self.certified:
            energy = (
                f"is within {self.energy_margin:.0%} of the lowest energy among the paths that safe"
                if self.compared
                else f"every other {noun} is shown less safe"
                if self.unsafe
                else f"it is the only {noun}"
            )
            return (
                f"{name}: {conf} it succeeds at least {self.p_level:.0%} of the time and "
                f"{energy} ({self.fresh_rollouts} fresh rollouts, {self.fresh_successes} "
                f"successes)"
            )
        if not self.fresh_rollouts:  # (no bound to state: the budget ended first)
            return (
                f"{name} (not certified): it succeeded in {self.successes} of its "
                f"{self.rollouts} rollouts; the race stopped before the fresh rollouts that "
                f"would show, {conf}, that it succeeds at least {self.p_level:.0%} of the time"
            )
        words = [f"{name} (not certified): {conf} it succeeds at least "]
        words.append(f"{math.floor(self.p_lower * 1000) / 10:g}% of the time")
        if not self.compared:
            pass  # (no rival to compare with: the only one, or every other shown less safe)
        elif math.isfinite(self.energy_reached):
            words.append(
                f" and is within {math.ceil(self.energy_reached * 1000) / 10:g}% of the lowest "
                f"energy among the paths that succeed at least {self.p_level:.0%} of the time"
            )
        elif self.unsettled:
            words.append(
                f"; not yet compared in energy with {noun}{'s' * (len(self.unsettled) > 1)} "
                + ", ".join(str(j + first) for j in self.unsettled)
            )
        return "".join(words) + (
            f" ({self.fresh_successes} of {self.fresh_rollouts} fresh rollouts succeeded)"
        )

    def to_json(self) -> dict:
        return {
            "certified": self.certified,
            "confidence": self.confidence,
            "p_level": self.p_level,
            "energy_margin": self.energy_margin,
            "p_lower": self.p_lower,
            "energy_reached": self.energy_reached,
            "fresh_rollouts": self.fresh_rollouts,
            "fresh_successes": self.fresh_successes,
            "rollouts": self.rollouts,
            "successes": self.successes,
            "unsafe": list(self.unsafe),
            "compared": [[j, e] for j, e in self.compared],
            "unsettled": list(self.unsettled),
            "posterior_probability": self.posterior,
        }


ATTEMPTS = (0.75, 0.125, 0.0625, 0.0625)
"""Each certifying attempt's share of the chosen path's and the energy claims' error [-]: when
the certificate can no longer come (the chosen path shown unsafe, or a rival shown cheaper),
the posterior's new leader is certified on new fresh worlds, at most len(ATTEMPTS) times; the
shares sum to 1, so the claim finally stated keeps its confidence (a union over attempts)."""


@dataclass(frozen=True)
class _Errors:
    """One attempt's error budgets, split (module docstring)."""

    chosen: float
    unsafe: float
    energy: float

    @classmethod
    def of(cls, confidence: float, k: int, share: float) -> _Errors:
        delta = 1 - confidence
        return cls(
            chosen=delta / 2 * share,
            unsafe=delta / 4 / k,  # (over all of a candidate's rollouts: every attempt's)
            energy=delta / 4 / max(k - 1, 1) * share,
        )


@dataclass
class _Fresh:
    """The certifying rollouts: per candidate, its records by fresh world index."""

    records: dict[int, dict[int, dict]] = field(default_factory=dict)
    worlds: int = 0
    """Fresh worlds used so far [-]."""

    def of(self, i: int, since: int = 0) -> list[dict]:
        """Candidate i's records in fresh worlds since `since`, in world order."""
        recs = self.records.get(i, {})
        return [recs[w] for w in sorted(recs) if w >= since]

    def tally(self, i: int, since: int = 0) -> tuple[int, int]:
        """(successes, failures) of candidate i's fresh rollouts since world `since`."""
        return _count(self.of(i, since))

    def pairs(self, c: int, j: int, since: int) -> tuple[np.ndarray, np.ndarray]:
        """c's and j's relative energies in the fresh worlds since `since` both succeeded in."""
        mine, theirs = self.records.get(c, {}), self.records.get(j, {})
        both = sorted(
            w
            for w in mine.keys() & theirs.keys()
            if w >= since and mine[w]["outcome"] == "success" and theirs[w]["outcome"] == "success"
        )
        return (
            np.array([mine[w]["relative_energy"] for w in both]),
            np.array([theirs[w]["relative_energy"] for w in both]),
        )


def _all_rollouts(c: Candidate, fresh: _Fresh) -> list[dict]:
    """Every rollout of candidate c, screening and fresh."""
    return c.rollouts + fresh.of(c.index)


def _tally(c: Candidate, fresh: _Fresh) -> tuple[int, int]:
    """(successes, failures) over all of candidate c's rollouts, screening and fresh."""
    return _count(_all_rollouts(c, fresh))


def _count(recs: list[dict]) -> tuple[int, int]:
    """(successes, failures) of rollout records."""
    s = sum(r["outcome"] == "success" for r in recs)
    return s, len(recs) - s


def _energies(c: Candidate, fresh: _Fresh) -> list[float]:
    """The relative energies of all of candidate c's successes."""
    return [r["relative_energy"] for r in _all_rollouts(c, fresh) if r["outcome"] == "success"]


def posterior(
    candidates: list[Candidate],
    fresh: _Fresh,
    p_level: float,
    margin: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """(good, safe): per candidate, the posterior probability that it meets the claim (module
    docstring), and that its P(success) >= p_level, over all its rollouts; flat Beta(1, 1)
    priors on P, and for the mean relative energy a normal posterior around the successes'
    mean (sd at least 5 % of it; a candidate with fewer than 2 successes: sd 1)."""
    k = len(candidates)
    p = np.empty((POSTERIOR_DRAWS, k))
    e = np.empty((POSTERIOR_DRAWS, k))
    for col, c in enumerate(candidates):
        s, f = _tally(c, fresh)
        p[:, col] = rng.beta(1 + s, 1 + f, POSTERIOR_DRAWS)
        values = _energies(c, fresh)
        if len(values) >= 2:
            m = float(np.mean(values))
            sd = max(float(np.std(values, ddof=1)), 0.05 * abs(m)) / math.sqrt(len(values))
        else:
            m, sd = (values[0] if values else 2.0), 1.0
        e[:, col] = rng.normal(m, sd, POSTERIOR_DRAWS)
    safe = p >= p_level
    cheapest = np.where(safe, e, np.inf).min(axis=1, keepdims=True)
    good = safe & (e <= (1 + margin) * cheapest)
    return good.mean(axis=0), safe.mean(axis=0)


def favoured_order(
    candidates: list[Candidate], fresh: _Fresh, good: np.ndarray, safe: np.ndarray
) -> list[int]:
    """Candidate indices, the one the evidence favours first: the likeliest to meet the claim
    (good); where that does not tell them apart (every path may fall short of p*: good ~ 0
    for all), the likeliest to be safe (safe), then the highest posterior mean P(success)
    ((1 + s) / (2 + n)), then the lower index. good and safe are Monte Carlo estimates from
    POSTERIOR_DRAWS draws (sd <= 0.011): compared to 0.02, not to their noise."""
    mean_p = [(1 + s) / (2 + s + f) for s, f in (_tally(c, fresh) for c in candidates)]
    key = {
        c.index: (-round(float(g) / 0.02), -round(float(sf) / 0.02), -m, c.index)
        for c, g, sf, m in zip(candidates, good, safe, mean_p, strict=True)
    }
    return sorted(key, key=key.__getitem__)


def _mean_energy(c: Candidate) -> float:
    values = [r["relative_energy"] for r in c.successes]
    return float(np.mean(values)) if values else math.inf


def certify_race(
    candidates: list[Candidate],
    cfg: ChooseConfig,
    run_rollouts: Callable[[list[tuple]], list[dict]],
    *,
    mass: float,
    on_event: Callable[[ChooseEvent], None] | None = None,
    cancelled: Callable[[], bool] = lambda: False,
) -> Choice:
    """Screen, then certify (module docstring). run_rollouts(calls) runs [(candidate index,
    path, seed)] and returns their rollout records (any order); mass: the robot's [kg], for
    the cost of transport. on_event receives each RoundDone and the Decided, in the calling
    thread."""
    return _Certifier(candidates, cfg, run_rollouts, mass, on_event, cancelled).run()


class _Certifier:
    """One choice's state: the candidates' tallies, the fresh rollouts, the budget."""

    def __init__(  # noqa: PLR0917 - certify_race's arguments, as given
        self,
        candidates: list[Candidate],
        cfg: ChooseConfig,
        run_rollouts: Callable[[list[tuple]], list[dict]],
        mass: float,
        on_event: Callable[[ChooseEvent], None] | None,
        cancelled: Callable[[], bool],
    ) -> None:
        self.candidates, self.cfg, self.mass = candidates, cfg, mass
        self.run_rollouts, self.on_event, self.cancelled = run_rollouts, on_event, cancelled
        self.k = len(candidates)
        self.eps_e = cfg.indifference[1]
        self.p_level = cfg.min_success if cfg.min_success is not None else 1 - cfg.indifference[0]
        self.rng = np.random.default_rng([cfg.seed, 25])  # (the posterior's draws)
        self.fresh = _Fresh()
        self.t0 = time.monotonic()
        self.clock = _Clock(self.t0, cfg)
        self.rounds = 0
        self.unsafe: set[int] = set()
        """Candidates shown to succeed less often than p_level (on all their rollouts)."""
        self.settled: dict[int, float] = {}
        """This attempt's rivals shown within the energy margin."""
        self.errors = _Errors.of(cfg.confidence, self.k, ATTEMPTS[0])
        self.since = 0
        """The first fresh world of this attempt."""

    def run(self) -> Choice:
        stop = self.screen() if self.k > 1 else None
        chosen = self.favoured()[0]
        attempt = 0
        while stop is None:
            self.errors = _Errors.of(self.cfg.confidence, self.k, ATTEMPTS[attempt])
            self.since, self.settled = self.fresh.worlds, {}
            stop = self.certify(chosen)
            if stop in ("chosen_unsafe", "rival_cheaper") and attempt + 1 < len(ATTEMPTS):
                order = self.favoured()
                if stop == "chosen_unsafe":  # (shown below p*: the next in line)
                    order = [i for i in order if i != chosen] + [chosen]
                if order[0] != chosen:
                    chosen, attempt, stop = order[0], attempt + 1, None
        return self.finish(chosen, stop)

    def favoured(self) -> list[int]:
        """Candidate indices, the one the evidence favours first (favoured_order)."""
        good, safe = self.posterior()
        return favoured_order(self.candidates, self.fresh, good, safe)

    def posterior(self) -> tuple[np.ndarray, np.ndarray]:
        return posterior(self.candidates, self.fresh, self.p_level, self.eps_e, self.rng)

    def tell(self, phase: Literal["screen", "certify"], driven: list[int]) -> None:
        if self.on_event is None:
            return
        self.on_event(
            RoundDone(
                round=self.rounds,
                rollouts=self.clock.used,
                fraction=min(self.clock.fraction(), 1.0),
                driven=tuple(sorted(driven)),
                standings=tuple(self.standing(c) for c in self.candidates),
                phase=phase,
            )
        )

    def screen(self) -> StopReason | None:
        """Screening rounds until the leader is sure enough or the screening's share of the
        budget is spent; "cancelled" or None."""
        cfg = self.cfg
        while True:
            if self.cancelled():
                return "cancelled"
            good, safe = self.posterior()
            leader = int(np.argmax(good))
            sure = safe[leader] >= 0.5 and good[leader] >= SCREEN_SURE * safe[leader]
            if sure and all(c.n >= 2 * cfg.batch for c in self.candidates):
                return None
            targets = self.screen_targets(good, safe)
            # (a first round for every candidate, whatever the share: a choice needs it)
            share = 1.0 if any(c.n == 0 for c in targets) else SCREEN_SHARE
            each = self.clock.worlds(len(targets), share, cfg.batch)
            calls = [
                (c.index, c.path_xyz.tolist(), world_seed(cfg.seed, c.n + j))
                for c in targets
                for j in range(each)
            ]
            if not calls or not self.clock.room(len(calls), share):
                return None
            for rec in self.clock.run(self.run_rollouts, calls):
                self.candidates[rec["candidate"]].rollouts.append(rec)
            for c in targets:
                c.rollouts.sort(key=lambda r: r["seed"])
            self.rounds += 1
            self.tell("screen", [c.index for c in targets])

    def screen_targets(self, good: np.ndarray, safe: np.ndarray) -> list[Candidate]:
        """Who the next screening round drives: every candidate until it has two rounds'
        worth; then the contenders (posterior probability of meeting the claim >= 0.05) and
        those that might be safe (>= 0.05) and cheaper than the leader, never one at
        max_per_candidate."""
        cfg = self.cfg
        open_ = [c for c in self.candidates if c.n < cfg.max_per_candidate]
        new = [c for c in open_ if c.n < 2 * cfg.batch]
        if new:
            return new
        leader = self.candidates[int(np.argmax(good))]
        lead_e = _mean_energy(leader) * (1 + 2 * self.eps_e)
        return [
            c
            for c in open_
            if c is leader
            or good[c.index] >= 0.05
            or (safe[c.index] >= 0.05 and _mean_energy(c) < lead_e)
        ]

    def settle(self, chosen: int) -> list[int]:
        """Mark the rivals now shown unsafe or within the margin; the rivals still open."""
        for c in self.candidates:
            if c.index not in self.unsafe and shows_below(
                *_tally(c, self.fresh), self.p_level, self.errors.unsafe
            ):
                self.unsafe.add(c.index)
        open_ = []
        for j in range(self.k):
            if j == chosen or j in self.unsafe or j in self.settled:
                continue
            mine, theirs = self.fresh.pairs(chosen, j, self.since)
            if mean_upper(mine - (1 + self.eps_e) * theirs, self.errors.energy) <= 0:
                self.settled[j] = self.eps_e
            else:
                open_.append(j)
        return open_

    def certify(self, chosen: int) -> StopReason:
        """Certifying rounds on fresh worlds for `chosen` until certified, lost, cancelled or
        out of budget."""
        cfg = self.cfg
        while True:
            open_rivals = self.settle(chosen)
            s, f = self.fresh.tally(chosen, self.since)
            if shows_at_least(s, f, self.p_level, self.errors.chosen) and not open_rivals:
                return "certified"
            lost = self.lost(chosen, open_rivals)
            if lost is not None:
                return lost
            if self.cancelled():
                return "cancelled"
            todo = self.to_drive(
                chosen,
                open_rivals,
                shown=s + f > 0 and shows_at_least(s, f, self.p_level, self.errors.chosen),
            )
            first, worlds = self.fresh.worlds, self.clock.worlds(len(todo), 1.0, cfg.batch)
            calls = [
                (i, self.candidates[i].path_xyz.tolist(), fresh_seed(cfg.seed, first + w))
                for w in range(worlds)
                for i in todo
            ]
            if not calls or not self.clock.room(len(calls), 1.0):
                return self.clock.limit
            seeds = {fresh_seed(cfg.seed, first + w): first + w for w in range(worlds)}
            for rec in self.clock.run(self.run_rollouts, calls):
                self.fresh.records.setdefault(rec["candidate"], {})[seeds[rec["seed"]]] = rec
            self.fresh.worlds += worlds
            self.rounds += 1
            self.tell("certify", todo)

    def to_drive(self, chosen: int, open_rivals: list[int], *, shown: bool) -> list[int]:
        """Who the next certifying round drives: every open rival, and the chosen path unless
        its P(success) is `shown` and every open rival is most likely unsafe (posterior
        probability of P >= p_level under 0.05: its own rollouts will settle it, no pairs
        needed)."""
        _, safe = self.posterior()
        paired = not shown or any(safe[j] >= 0.05 for j in open_rivals)
        return ([chosen] if paired else []) + open_rivals

    def lost(self, chosen: int, open_rivals: list[int]) -> StopReason | None:
        """Why this attempt's certificate can no longer come, or None: the chosen path's
        P(success) shown below p_level on its fresh rollouts, or a rival shown safe and
        cheaper by more than eps_E."""
        if shows_below(*self.fresh.tally(chosen, self.since), self.p_level, self.errors.chosen):
            return "chosen_unsafe"
        for j in open_rivals:
            if not shows_at_least(
                *_tally(self.candidates[j], self.fresh), self.p_level, self.errors.unsafe
            ):
                continue
            mine, theirs = self.fresh.pairs(chosen, j, self.since)
            # (the lower bound of mine - (1 + eps) theirs above 0)
            if mean_upper((1 + self.eps_e) * theirs - mine, self.errors.energy) < 0:
                return "rival_cheaper"
        return None

    def guarantee(self, chosen: int, stop: StopReason, good: np.ndarray) -> Guarantee:
        """What this attempt showed of the claim for `chosen`."""
        s, f = self.fresh.tally(chosen, self.since)
        compared = []
        for j in range(self.k):
            if j == chosen or j in self.unsafe:
                continue
            mine, theirs = self.fresh.pairs(chosen, j, self.since)
            reached = excess_reached(mine, theirs, self.errors.energy)
            compared.append((j, min(self.settled.get(j, math.inf), reached)))
        all_of_chosen = _tally(self.candidates[chosen], self.fresh)  # (screening and fresh)
        return Guarantee(
            certified=stop == "certified",
            confidence=self.cfg.confidence,
            p_level=self.p_level,
            energy_margin=self.eps_e,
            p_lower=p_lower(s, f, self.errors.chosen),
            energy_reached=max((e for _, e in compared), default=0.0),
            fresh_rollouts=s + f,
            fresh_successes=s,
            rollouts=sum(all_of_chosen),
            successes=all_of_chosen[0],
            unsafe=tuple(sorted(self.unsafe - {chosen})),
            compared=tuple(compared),
            unsettled=tuple(j for j, e in compared if e > self.eps_e),
            posterior=float(good[chosen]),
        )

    def finish(self, chosen: int, stop: StopReason) -> Choice:
        """The choice: chosen, when certified; else the path all the evidence favours (the
        last one tried may have been shown unsafe), with what was reached for it."""
        good, safe = self.posterior()
        order = favoured_order(self.candidates, self.fresh, good, safe)
        if stop != "certified":
            chosen = order[0]
        g = self.guarantee(chosen, stop, good)
        rank = {i: (i != chosen, k) for k, i in enumerate(order)}
        standings = tuple(
            self.standing(c) for c in sorted(self.candidates, key=lambda c: rank[c.index])
        )
        some_success = any(s.successes for s in standings)
        decided = Decided(
            chosen=chosen if some_success else None,
            stop=stop,
            stopped=_stopped(stop, g, self.cfg),
            confidence=self.cfg.confidence,
            confidence_reached=None,
            rollouts=self.clock.used,
            rounds=self.rounds,
            standings=standings,
            wall_time_s=time.monotonic() - self.t0,
            guarantee=g,
        )
        if self.on_event is not None:
            self.on_event(decided)
        return Choice(
            chosen=decided.chosen,
            standings=standings,
            stop=stop,
            stopped=decided.stopped,
            rollouts=self.clock.used,
            wall_time=decided.wall_time_s,
            candidates=self.candidates,
            guarantee=g,
            fresh={i: self.fresh.of(i) for i in self.fresh.records},
        )

    def standing(self, c: Candidate) -> Standing:
        """c's standing over all its rollouts, with anytime-valid bounds at delta / 4 / K."""
        s, f = _tally(c, self.fresh)
        alpha = self.errors.unsafe
        e, e_lo, e_hi = mean_bounds(_energies(c, self.fresh), alpha)
        fs, ff = self.fresh.tally(c.index)
        return dataclass_replace(
            c.standing(self.cfg.confidence, self.mass),
            rollouts=s + f,
            successes=s,
            p_success=s / (s + f) if s + f else math.nan,
            p_low=p_lower(s, f, alpha),
            p_high=p_upper(s, f, alpha),
            relative_energy=e,
            relative_energy_low=e_lo,
            relative_energy_high=e_hi,
            fresh_rollouts=fs + ff,
            fresh_successes=fs,
        )


class _Clock:
    """The race's budget: wall time and the rollout cap, and the rollouts used."""

    def __init__(self, t0: float, cfg: ChooseConfig) -> None:
        self.t0, self.cfg = t0, cfg
        self.used = 0
        self.per_rollout = 0.0
        """Wall time per rollout in the last round [s]."""
        self.limit: StopReason = "time_budget"
        """Which limit the last refused round met."""

    def fraction(self) -> float:
        """Of the rollout cap (with one) or else the time budget spent [-]."""
        if self.cfg.rollouts:
            return self.used / self.cfg.rollouts
        return (time.monotonic() - self.t0) / (self.cfg.budget_s or 1)

    def worlds(self, per_world: int, share: float, most: int) -> int:
        """How many worlds of per_world rollouts each, up to `most`, the rollout cap's `share`
        still holds (a last round smaller than a batch; 0: none)."""
        cap = self.cfg.rollouts
        if cap is None:
            return most
        left = math.floor(share * cap) - self.used
        fit = max(min(most, left // max(per_world, 1)), 0)
        if fit == 0:
            self.limit = "rollout_cap"
        return fit

    def room(self, n: int, share: float) -> bool:
        """Whether n more rollouts fit in `share` of the cap and of the budget (a rollout
        takes about as long as one of the last round did)."""
        cap, budget = self.cfg.rollouts, self.cfg.budget_s
        if cap is not None and self.used + n > share * cap:
            self.limit = "rollout_cap"
            return False
        spent = time.monotonic() - self.t0 + self.per_rollout * n
        self.limit = "time_budget"
        return budget is None or spent < share * budget

    def run(self, run_rollouts: Callable[[list[tuple]], list[dict]], calls: list[tuple]):
        t = time.monotonic()
        out = run_rollouts(calls)
        self.per_rollout = (time.monotonic() - t) / max(len(calls), 1)
        self.used += len(calls)
        return out


def _stopped(stop: StopReason, g: Guarantee, cfg: ChooseConfig) -> str:
    """Why the race stopped, in words (the guarantee reached is Guarantee.sentence)."""
    match stop:
        case "certified":
            words = "certified"
        case "chosen_unsafe":
            words = f"the path certified last is shown to succeed less often than {g.p_level:.0%}"
        case "rival_cheaper":
            words = f"a rival is shown as safe and more than {g.energy_margin:.0%} cheaper"
        case "rollout_cap":
            words = f"rollout cap of {cfg.rollouts} reached"
        case "time_budget":
            words = f"time budget of {cfg.budget_s:.1f} s spent"
        case "cancelled":
            words = "cancelled"
        case _:
            words = stop
    return words
