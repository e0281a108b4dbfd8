"""The race's policy, on the candidates' tallies at per-candidate confidence conf: who leaves
the race (eliminate), who gets the next round's rollouts (to_sample), how they rank (rank) and
when the race may stop with a decision (decision).

A candidate leaves the race when it is clearly beaten:

- on success: its upper confidence bound on P(success) is below another's lower bound (with
  min_success: below min_success);
- on energy: another candidate at least as likely to succeed (its P lower bound at or above
  this one's upper bound less DP, the indifference in P below; with min_success: its lower
  bound clears it) has an upper bound on mean relative energy below this one's lower bound.

Indifference zone (DP, DE) = cfg.indifference: candidates that are practically equal never
separate (two paths that succeed 199 and 200 times in 200 would need many thousands of
rollouts), so the race also stops, "within the indifference zone", when this holds for the
candidate the ranking puts first (c*), at the requested joint confidence (the same Bonferroni
intervals): every other candidate still in the race has P(success) upper bound at most c*'s
lower bound + DP [probability], and for each of them that is not clearly less safe (its P
upper bound at or above c*'s lower bound) the upper bound on the mean of c*'s relative energy
less (1 + DE) times its own, over the worlds both succeeded in, is at most 0 [DE a fraction
of the energy] (energy_excess_bound: paired, so the world's shared part cancels). That is: at
the requested confidence, the chosen candidate is within DP of the best P(success) and, among
those as safe, within DE of the lowest energy (the candidates that left the race were beaten
outright). With min_success only the energy part applies, among the candidates whose P upper
bound clears min_success. (0, 0) turns the zone off: the race then stops only on separation,
or with min_success when one candidate alone clears it.

A round gives rollouts to the candidates whose intervals stand between the race and a
decision (to_sample): at first every one; then, in each comparison that keeps the decision
above from holding, the side with the wider interval.
"""

from __future__ import annotations

import math

from ._choose_candidate import Candidate, Knockout
from ._choose_config import ChooseConfig
from ._choose_events import StopReason
from ._choose_stats import paired_excess_bound


def energy_excess_bound(best: Candidate, other: Candidate, conf: float, de: float) -> float:
    """Upper confidence bound [relative energy] on the mean of e_best - (1 + de) e_other over
    the worlds both succeeded in (rollout k of every candidate drives the same world: common
    random numbers, so the draws' shared effect on energy cancels in each difference; on
    double_bridge_rough they explain a third to a half of its spread); +inf with fewer than 2
    such worlds. <= 0: at confidence conf, best needs at most (1 + de) times other's energy."""
    return paired_excess_bound(
        {r["seed"]: r["relative_energy"] for r in best.successes},
        {r["seed"]: r["relative_energy"] for r in other.successes},
        conf,
        de,
    )


def eliminate(
    alive: list[Candidate], conf: float, min_success: float | None, dp: float = 0.0
) -> list[Candidate]:
    """Mark the candidates that are clearly beaten (module docstring: their `knocked_out`)
    and return them, in the order of `alive`. On energy, only by a candidate that is at least
    as safe at confidence conf: its P lower bound clears min_success, or this one's P upper
    bound less dp (the indifference in P). A point estimate is not enough: a path that fails
    6 times in 100 has succeeded in all of its first 24 rollouts one time in five, and would
    then knock out a safer, costlier one for good."""
    racing = {c.index for c in alive if c.knocked_out is None}
    p = {c.index: c.p_interval(conf) for c in alive}
    e = {c.index: c.energy_interval(conf) for c in alive}
    if min_success is None:
        leader = max(alive, key=lambda c: p[c.index][1])  # (the first of the highest lows)
        best_low = p[leader.index][1]
        for c in alive:
            if p[c.index][2] < best_low:
                c.knocked_out = Knockout(
                    reason="less_likely",
                    by=leader.index,
                    own_bound=float(p[c.index][2]),
                    rival_bound=float(best_low),
                )
    else:
        for c in alive:
            if p[c.index][2] < min_success:
                c.knocked_out = Knockout(
                    reason="below_min_success",
                    by=None,
                    own_bound=float(p[c.index][2]),
                    rival_bound=min_success,
                )
    still = [c for c in alive if c.knocked_out is None]
    for c in still:
        for d in still:
            if d is c or d.knocked_out is not None:
                continue
            safe_enough = (
                p[d.index][1] >= min_success
                if min_success is not None
                else p[d.index][1] >= p[c.index][2] - dp
            )
            if safe_enough and e[d.index][2] < e[c.index][1]:
                c.knocked_out = Knockout(
                    reason="costs_more",
                    by=d.index,
                    own_bound=float(e[c.index][1]),
                    rival_bound=float(e[d.index][2]),
                )
                break
    return [c for c in alive if c.index in racing and c.knocked_out is not None]


def zone_blockers(
    alive: list[Candidate],
    conf: float,
    min_success: float | None,
    indifference: tuple[float, float],
) -> tuple[Candidate | None, list[tuple[Candidate, str]]]:
    """(c*, blockers): the first-ranked of `alive`, and the candidates whose intervals keep the
    indifference-zone decision (module docstring) from holding for it at per-candidate
    confidence conf, each with why: "p" (it might be more than DP safer), "energy" (it might
    be more than DE cheaper, or its energy is not known), "own" (c* itself, first among them
    when any is). No blockers: the decision holds. With the zone off nothing but separation
    decides: every candidate blocks ("own")."""
    dp, de = indifference
    if (dp <= 0 and de <= 0) or not alive:
        return None, [(c, "own") for c in alive]
    best = rank(alive, conf, min_success)[0]
    _, b_lo, _ = best.p_interval(conf)
    blockers = []
    for d in alive:
        if d is best:
            continue
        _, d_lo, d_hi = d.p_interval(conf)
        if min_success is None and d_hi > b_lo + dp:
            blockers.append((d, "p"))
            continue
        # Only a candidate that might be as safe (or might qualify) counts for energy.
        if (d_hi < min_success) if min_success is not None else (d_hi < b_lo):
            continue
        if not energy_excess_bound(best, d, conf, de) <= 0:
            blockers.append((d, "energy"))
    # c*'s own bounds: fewer than 2 successes leave its energy unbounded; with min_success it
    # must clear it; and it is one side of every comparison above.
    if blockers or len(best.successes) < 2 or (min_success is not None and b_lo < min_success):
        blockers.insert(0, (best, "own"))
    return best, blockers


def within_zone(
    alive: list[Candidate],
    conf: float,
    min_success: float | None,
    indifference: tuple[float, float],
) -> Candidate | None:
    """The first-ranked of `alive` if the indifference-zone decision holds for it at per-
    candidate confidence conf (module docstring), else None. Never with the zone off, nor for
    a candidate with fewer than 2 successes (its energy interval is unbounded)."""
    best, blockers = zone_blockers(alive, conf, min_success, indifference)
    return best if best is not None and not blockers else None


def rank(candidates: list[Candidate], conf: float, min_success: float | None) -> list[Candidate]:
    """Best first: with min_success, the qualifying ones by energy; else by P(success), then
    energy. Those still in the race rank above those that left it (a candidate that left on
    energy after 12 rollouts, all successes, must not outrank the one that beat it at 199 in
    200). A candidate whose P(success) interval lies wholly below another's never ranks above
    it."""

    def key(c: Candidate):
        p, lo, _ = c.p_interval(conf)
        energy = c.energy_interval(conf)[0]
        energy = energy if math.isfinite(energy) else math.inf
        out = c.knocked_out is not None
        if min_success is not None:
            return (out, lo < min_success, energy, -p)
        return (out, -(p if math.isfinite(p) else -1), energy)

    ordered = sorted(candidates, key=key)
    # No candidate above one whose P interval lies wholly above its own.
    for _ in range(len(ordered)):
        moved = False
        for i in range(len(ordered) - 1):
            a, b = ordered[i], ordered[i + 1]
            if a.p_interval(conf)[2] < b.p_interval(conf)[1]:
                ordered[i], ordered[i + 1] = b, a
                moved = True
        if not moved:
            break
    return ordered


def decision(alive: list[Candidate], conf: float, cfg: ChooseConfig) -> StopReason | None:
    """Why the race can stop with a decision short of separation, or None: with min_success,
    one candidate alone clears it ("one_qualifies"); or the first-ranked is within the
    indifference zone ("indifference_zone")."""
    if cfg.min_success is not None:
        qualifying = [c for c in alive if c.p_interval(conf)[1] >= cfg.min_success]
        if len(qualifying) == 1 and all(
            c is qualifying[0] or c.p_interval(conf)[2] < cfg.min_success for c in alive
        ):
            return "one_qualifies"
    if within_zone(alive, conf, cfg.min_success, cfg.indifference):
        return "indifference_zone"
    return None


def to_sample(alive: list[Candidate], conf: float, cfg: ChooseConfig) -> list[Candidate]:
    """The candidates the next round gives rollouts to: every one until it has a round's
    worth; then, with the zone on, for each comparison that keeps the decision from holding
    (zone_blockers: c* against a blocker d), on P(success) the side whose interval is the wider
    where they meet, on energy the side with fewer rollouts (only worlds both have driven pair
    up). Sampling the other side cannot settle it: when d succeeds 40 times in 40 its upper
    bound stays 1 however often it is driven, and only c*'s lower bound can rise within DP of
    it. When c* is held back by its own bounds only (with min_success: below it), every
    candidate that might yet qualify is driven too. With the zone off, every candidate in the
    race (separation needs them all). Never a candidate that has its max_per_candidate; if the
    ones picked all have, every candidate in the race that has not."""
    open_ = [c for c in alive if c.n < cfg.max_per_candidate]
    new = [c for c in open_ if c.n < cfg.batch]
    if new:
        return new
    best, blockers = zone_blockers(alive, conf, cfg.min_success, cfg.indifference)
    if best is None:
        return open_
    picked: dict[int, Candidate] = {}
    p_b, b_lo, _ = best.p_interval(conf)
    if not blockers[1:]:  # c* alone: its own bounds (too few successes, or below min_success)
        picked[best.index] = best
        if cfg.min_success is not None:  # (another may be the one that qualifies)
            picked |= {c.index: c for c in alive if c.p_interval(conf)[2] >= cfg.min_success}
    for d, why in blockers[1:]:
        if why == "p":
            p_d, _, d_hi = d.p_interval(conf)
            sides = [best if p_b - b_lo >= d_hi - p_d else d]
        else:  # energy: only worlds both have driven pair up, so the one behind catches up
            sides = [c for c in (best, d) if c.n == min(best.n, d.n)]
        for side in sides:
            spent = side.n >= cfg.max_per_candidate  # (then only the other side can move)
            moving = (d if side is best else best) if spent else side
            picked[moving.index] = moving
    return [c for c in open_ if c.index in picked] or open_


def confidence_reached(alive: list[Candidate], k: int, cfg: ChooseConfig) -> float | None:
    """The highest joint confidence on the 0.01 grid in [0.5, cfg.confidence) at which
    within_zone holds for alive (k candidates in the race's Bonferroni correction) with the
    candidate it holds for at cfg.confidence's ranking first; None if at none."""
    conf = 1 - (1 - cfg.confidence) / k
    first = rank(alive, conf, cfg.min_success)[0] if alive else None
    top = math.ceil(cfg.confidence * 100 - 1e-9) - 1
    for c in (v / 100 for v in range(top, 49, -1)):
        if within_zone(alive, 1 - (1 - c) / k, cfg.min_success, cfg.indifference) is first:
            return c
    return None
