"""Choose by simulation (issue 17): which of K candidate paths the robot should take, with how
much confidence, by racing rollouts under an uncertainty model.

The candidates are K distinct plans (plan_many), routes taken round-robin so that where the
terrain has several routes each gets a candidate. Each round gives `batch` more rollouts
(experiments/_uncertainty.py: each its own seed) on the worker pool to the candidates whose
intervals stand between the race and a decision (_to_sample: at first every one; then, in
each comparison that keeps the decision below from holding, the side with the wider
interval); after each round a candidate leaves the race when it is clearly beaten:

- on success: its upper confidence bound on P(success) is below another's lower bound;
- on energy: another candidate at least as likely to succeed (its P lower bound at or above
  this one's upper bound less DP, the indifference in P below) has an upper bound on mean
  relative energy below this one's lower bound.

Bounds are Clopper-Pearson intervals for P(success) and t intervals for the mean energy over
successes, each at confidence 1 - (1 - c) / K (Bonferroni over the candidates). The race stops
when one candidate is left (separated at the requested confidence), when the rollout cap or the
time budget is spent, or, with min_success, when the cheapest candidate whose lower bound clears
it is separated from the other such ones. Which of these stopped it is reported.

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
bound clears min_success.
(0, 0) turns the zone off: the race then stops only as described above.

Everything drawn flows from `seed`: the candidates are planned with seeds seed, seed + 1, ...,
and rollout k of every candidate drives the world of seed world_seed(seed, k) (common random
numbers: the candidates are compared in the same worlds). Rounds end only when all their
rollouts are in, so with a rollout cap (not a time budget) the same seed gives the same choice.
"""

from __future__ import annotations

import functools
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from dataclasses import replace as dataclass_replace

import numpy as np
from scipy import stats

from roachplan.planning import PlanResult

from ._choose_config import ChooseConfig
from ._errors import ExperimentError
from ._trial import MIN_ATTEMPT_TIME, _resample, plan, plan_many
from ._uncertainty import rollout_seed

GRAVITY = 9.81


@functools.lru_cache(maxsize=65536)  # (ranking asks for the same few intervals many times)
def clopper_pearson(successes: int, n: int, confidence: float) -> tuple[float, float]:
    """Clopper-Pearson (exact) interval of a binomial proportion [-]; (0, 1) without trials.
    Its coverage is at least `confidence` for every p (Wilson's dips below it near 0 and 1),
    and where the race decides, at or near n successes in n, it is the narrower: the lower
    bound for n in n is ((1 - c) / 2)^(1/n), about 1 - 5.8 / n at c = 1 - 0.05 / 8, where
    Wilson's n / (n + z^2) is 1 - 7.5 / n."""
    if n == 0:
        return 0.0, 1.0
    a = (1 - confidence) / 2
    lo = 0.0 if successes == 0 else float(stats.beta.ppf(a, successes, n - successes + 1))
    hi = 1.0 if successes == n else float(stats.beta.ppf(1 - a, successes + 1, n - successes))
    return lo, hi


def mean_interval(values: list[float], confidence: float) -> tuple[float, float, float]:
    """(mean, low, high): Student t interval of the mean; infinite bounds with < 2 values."""
    if not values:
        return math.nan, -math.inf, math.inf
    m = float(np.mean(values))
    if len(values) < 2:
        return m, -math.inf, math.inf
    half = stats.t.ppf(1 - (1 - confidence) / 2, len(values) - 1) * (
        float(np.std(values, ddof=1)) / math.sqrt(len(values))
    )
    return m, m - half, m + half


def energy_excess_bound(best: Candidate, other: Candidate, conf: float, de: float) -> float:
    """Upper confidence bound [relative energy] on the mean of e_best - (1 + de) e_other over
    the worlds both succeeded in (rollout k of every candidate drives the same world: common
    random numbers, so the draws' shared effect on energy cancels in each difference; on
    double_bridge_rough they explain a third to a half of its spread); +inf with fewer than 2
    such worlds. <= 0: at confidence conf, best needs at most (1 + de) times other's energy."""
    mine = {r["seed"]: r["relative_energy"] for r in best.successes}
    diffs = [
        mine[r["seed"]] - (1 + de) * r["relative_energy"]
        for r in other.successes
        if r["seed"] in mine
    ]
    return mean_interval(diffs, conf)[2] if len(diffs) >= 2 else math.inf


@dataclass
class Candidate:
    """One candidate path and what its rollouts showed."""

    index: int
    route: str
    seed: int
    """The planning seed of its path."""
    path_xyz: np.ndarray
    length: float
    """Path length [m]."""
    spins: tuple[tuple[int, float], ...] = ()
    """Its turns on the spot (PlanResult.spins)."""
    rollouts: list[dict] = field(default_factory=list)
    out: str = ""
    """Why it left the race ("" while in it)."""

    @property
    def n(self) -> int:
        return len(self.rollouts)

    @property
    def successes(self) -> list[dict]:
        return [r for r in self.rollouts if r["outcome"] == "success"]

    def p_interval(self, confidence: float) -> tuple[float, float, float]:
        k = len(self.successes)
        lo, hi = clopper_pearson(k, self.n, confidence)
        return (k / self.n if self.n else math.nan), lo, hi

    def energy_interval(self, confidence: float) -> tuple[float, float, float]:
        return mean_interval([r["relative_energy"] for r in self.successes], confidence)

    def summary(self, confidence: float, mass: float) -> dict:
        """The ranking row of this candidate."""
        p, p_lo, p_hi = self.p_interval(confidence)
        e, e_lo, e_hi = self.energy_interval(confidence)
        ok = self.successes
        joules = [r["energy"] for r in ok]
        fails = [r for r in self.rollouts if r["outcome"] != "success"]
        mean_j = float(np.mean(joules)) if joules else math.nan
        return {
            "candidate": self.index,
            "route": self.route,
            "plan_seed": self.seed,
            "length_m": round(self.length, 3),
            "rollouts": self.n,
            "successes": len(ok),
            "p_success": p,
            "p_low": p_lo,
            "p_high": p_hi,
            "relative_energy": e,
            "relative_energy_low": e_lo,
            "relative_energy_high": e_hi,
            "energy_j": mean_j,
            "energy_j_per_m": mean_j / self.length,
            "cost_of_transport": mean_j / (mass * GRAVITY * self.length),
            "drive_time_s": float(np.mean([r["drive_time"] for r in ok])) if ok else math.nan,
            "failures": dict(Counter(r["outcome"] for r in fails)),
            "failed_at": [[round(v, 3) for v in r["end"]] for r in fails[:10]],
            "out": self.out,
        }


@dataclass(frozen=True)
class Choice:
    """The outcome of a race."""

    chosen: int | None
    """Index of the chosen candidate (None: no candidate ever succeeded)."""
    ranking: list[dict]
    """Every candidate's summary, best first."""
    stopped: str
    """Why the race stopped."""
    rollouts: int
    wall_time: float
    """[s]"""
    candidates: list[Candidate]
    confidence_reached: float | None = None
    """When the race ended on its budget or cap short of a decision: the highest joint
    confidence (from 0.5) at which the ranking's first is within the indifference zone on the
    rollouts it had, to 0.01; None when it decided, or not even at 0.5."""


def plan_candidates(world, cfg: ChooseConfig, *, budget: float | None = None) -> list[Candidate]:
    """K distinct candidate paths. Where the scene names routes, each route gets candidates in
    turn, planned through a via pose inside it (a planner left alone takes the easiest route
    every time: a wide bridge, never the narrow one beside it); the rest, or all of them on a
    scene without routes, are plan_many's distinct plans."""
    deadline = None if budget is None else time.monotonic() + budget
    picked: list[tuple[str, PlanResult]] = []
    shapes: list[np.ndarray] = []

    def add(route: str, planned: PlanResult) -> None:
        shape = _resample(planned.path_xyz[:, :2], 50)
        if all(np.mean(np.linalg.norm(shape - s, axis=1)) >= 0.02 for s in shapes):
            shapes.append(shape)
            picked.append((route, planned))

    vias = {
        name: v
        for name, region in world.scene.routes
        if (v := _via_pose(world, region)) is not None
    }
    tries, misses = 0, Counter()
    while vias and len(picked) < cfg.candidates and tries < 3 * cfg.candidates:
        for name, via in list(vias.items()):
            if len(picked) >= cfg.candidates or (deadline and time.monotonic() > deadline):
                break
            planned = _plan_via(world, via, seed=cfg.seed + tries, deadline=deadline)
            before = len(picked)
            if planned is not None and world.route(planned.path_xyz[:, :2]) == name:
                add(name, planned)
            misses[name] = 0 if len(picked) > before else misses[name] + 1
            if misses[name] >= 3:  # three plans in a row gave nothing new on this route
                del vias[name]
        tries += 1
    if len(picked) < cfg.candidates:
        left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
        for lp in plan_many(world, 3 * cfg.candidates, seed=cfg.seed, budget=left):
            if len(picked) < cfg.candidates:
                add(lp.route, lp.plan)
    out = []
    for i, (route, planned) in enumerate(picked):
        xyz = planned.path_xyz
        length = float(np.sum(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1)))
        out.append(
            Candidate(
                index=i,
                route=route,
                seed=planned.seed,
                path_xyz=xyz,
                length=max(length, 1e-6),
                spins=planned.spins,
            )
        )
    return out


def _via_pose(world, region) -> tuple[float, float, float] | None:
    """A pose inside the route's region ((xmin, ymin), (xmax, ymax)) where the robot can
    stand, heading from start to goal: the standable cell nearest the region's centre."""
    from roachplan.scenes._world import pose_problem

    sc = world.scene
    heading = math.atan2(sc.goal[1] - sc.start[1], sc.goal[0] - sc.start[0])
    (x0, y0), (x1, y1) = region
    cells = world.regions.cell_centres(world.regions.standable)
    inside = cells[
        (cells[:, 0] >= x0) & (cells[:, 0] <= x1) & (cells[:, 1] >= y0) & (cells[:, 1] <= y1)
    ]
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    for xy in inside[np.argsort(np.linalg.norm(inside - centre, axis=1))][:20]:
        for yaw in (heading, heading + math.pi):
            pose = (float(xy[0]), float(xy[1]), yaw)
            if not pose_problem(world, pose):
                return pose
    return None


def _plan_via(world, via, *, seed: int, deadline: float | None = None) -> PlanResult | None:
    """start -> via -> goal as one path (each leg planned with this seed, within what is left
    of the planning budget at `deadline`, time.monotonic()), or None."""
    sc = world.scene
    first = plan(world, seed=seed, start=sc.start, goal=via, planner=_within(sc.planner, deadline))
    if not first.found:
        return None
    second = plan(world, seed=seed, start=via, goal=sc.goal, planner=_within(sc.planner, deadline))
    if not second.found:
        return None
    return dataclass_replace(
        first,
        states=np.vstack([first.states, second.states[1:]]),
        path_xyz=np.vstack([first.path_xyz, second.path_xyz[1:]]),
        # The second leg's waypoints follow the first's, which end on its first.
        spins=first.spins + tuple((k + len(first.path_xyz) - 1, yaw) for k, yaw in second.spins),
        plan_time=first.plan_time + second.plan_time,
        message=f"through ({via[0]:.2f}, {via[1]:.2f}): {first.message}; {second.message}",
    )


def _within(planner, deadline: float | None):
    """The planner with its time limit cut to what is left before deadline (time.monotonic())."""
    if deadline is None:
        return planner
    left = max(deadline - time.monotonic(), MIN_ATTEMPT_TIME)
    return dataclass_replace(planner, time_limit=min(planner.time_limit, left))


def _eliminate(
    alive: list[Candidate], conf: float, min_success: float | None, dp: float = 0.0
) -> None:
    """Mark the candidates that are clearly beaten (see the module docstring). On energy, only
    by a candidate that is at least as safe at confidence conf: its P lower bound clears
    min_success, or this one's P upper bound less dp (the indifference in P). A point estimate
    is not enough: a path that fails 6 times in 100 has succeeded in all of its first 24
    rollouts one time in five, and would then knock out a safer, costlier one for good."""
    p = {c.index: c.p_interval(conf) for c in alive}
    e = {c.index: c.energy_interval(conf) for c in alive}
    if min_success is None:
        best_low = max(p[c.index][1] for c in alive)
        for c in alive:
            if p[c.index][2] < best_low:
                c.out = "less likely to succeed than another (intervals apart)"
    else:
        for c in alive:
            if p[c.index][2] < min_success:
                c.out = f"P(success) upper bound below {min_success:g}"
    still = [c for c in alive if not c.out]
    for c in still:
        for d in still:
            if d is c or d.out:
                continue
            safe_enough = (
                p[d.index][1] >= min_success
                if min_success is not None
                else p[d.index][1] >= p[c.index][2] - dp
            )
            if safe_enough and e[d.index][2] < e[c.index][1]:
                c.out = f"costs more energy than candidate {d.index} (intervals apart)"
                break


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
        if min_success is not None:
            return (bool(c.out), lo < min_success, energy, -p)
        return (bool(c.out), -(p if math.isfinite(p) else -1), energy)

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


def _decided(alive: list[Candidate], conf: float, cfg: ChooseConfig) -> str:
    """Why the race can stop with a decision short of separation, or "": with min_success, one
    candidate alone clears it; or the first-ranked is within the indifference zone."""
    if cfg.min_success is not None:
        qualifying = [c for c in alive if c.p_interval(conf)[1] >= cfg.min_success]
        if len(qualifying) == 1 and all(
            c is qualifying[0] or c.p_interval(conf)[2] < cfg.min_success for c in alive
        ):
            return f"only one candidate clears P(success) >= {cfg.min_success:g}"
    if within_zone(alive, conf, cfg.min_success, cfg.indifference):
        dp, de = cfg.indifference
        return (
            f"within the indifference zone (P {dp:g}, energy {de:.0%}) at "
            f"{cfg.confidence:.0%} confidence"
        )
    return ""


def _to_sample(alive: list[Candidate], conf: float, cfg: ChooseConfig) -> list[Candidate]:
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
            if side.n >= cfg.max_per_candidate:  # (spent: only the other can move)
                side = d if side is best else best
            picked[side.index] = side
    return [c for c in open_ if c.index in picked] or open_


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
    progress: Callable[[str, float], None] | None = None,
    cancelled: Callable[[], bool] = lambda: False,
) -> Choice:
    """Race the candidates. run_rollouts(calls) runs [(candidate index, path, seed)] and returns
    their rollout records (any order). progress(message, fraction) after each round."""
    t0 = time.monotonic()
    k = max(len(candidates), 1)
    conf = 1 - (1 - cfg.confidence) / k
    used = 0
    stopped = ""
    per_rollout = 0.0  # wall time per rollout in the last round [s]
    cut_short = False  # stopped by the budget, the cap or max_per_candidate, not a decision
    while True:
        alive = [c for c in candidates if not c.out]
        # A lone candidate from the start is not a decision: it races on (alone) until the
        # budget or cap, so that its P(success) is measured, not left at "unknown".
        if len(alive) <= 1 and len(candidates) > 1:
            stopped = f"separated at {cfg.confidence:.0%} confidence"
            break
        stopped = _decided(alive, conf, cfg) if len(candidates) > 1 else ""
        if stopped:
            break
        if cancelled():
            stopped = "cancelled"
            break
        room = None if cfg.rollouts is None else cfg.rollouts - used
        if not alive:  # only when no candidate was planned
            stopped = "no candidate to race"
            break
        targets = _to_sample(alive, conf, cfg)
        if not targets:
            stopped = f"every candidate has its {cfg.max_per_candidate} rollouts"
            cut_short = True
            break
        if room is not None and room < len(targets):
            stopped, cut_short = f"rollout cap of {cfg.rollouts} reached", True
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
            stopped, cut_short = f"time budget of {cfg.budget_s:.1f} s spent", True
            break
        t_round = time.monotonic()
        for rec in run_rollouts(calls):
            candidates[rec["candidate"]].rollouts.append(rec)
        per_rollout = (time.monotonic() - t_round) / len(calls)
        for c in alive:  # the order rollouts came back in must not matter
            c.rollouts.sort(key=lambda r: r["seed"])
        used += len(calls)
        _eliminate(alive, conf, cfg.min_success, cfg.indifference[0])
        if progress is not None:
            frac = (
                used / cfg.rollouts
                if cfg.rollouts
                else (time.monotonic() - t0) / (cfg.budget_s or 1)
            )
            left = sum(not c.out for c in candidates)
            progress(
                f"{used} rollouts, {left} of {len(candidates)} candidates in the race",
                min(frac, 1.0),
            )
    ordered = rank(candidates, conf, cfg.min_success)
    chosen = next((c.index for c in ordered if c.successes), None)
    reached = None
    if cut_short and len(candidates) > 1:
        reached = _confidence_reached([c for c in candidates if not c.out], k, cfg)
        if reached is not None:
            stopped += (
                f"; the first-ranked is within the indifference zone at {reached:.0%} "
                f"confidence (not {cfg.confidence:.0%})"
            )
        elif cfg.indifference != (0.0, 0.0):
            stopped += (
                "; the first-ranked is not within the indifference zone even at 50% confidence"
            )
    return Choice(
        chosen=chosen,
        ranking=[c.summary(conf, mass) for c in ordered],
        stopped=stopped,
        rollouts=used,
        wall_time=time.monotonic() - t0,
        candidates=candidates,
        confidence_reached=reached,
    )


def _confidence_reached(alive: list[Candidate], k: int, cfg: ChooseConfig) -> float | None:
    """The highest joint confidence on the 0.01 grid in [0.5, cfg.confidence) at which
    within_zone holds for alive with the candidate it holds for at cfg.confidence's ranking
    first; None if at none."""
    conf = 1 - (1 - cfg.confidence) / k
    first = rank(alive, conf, cfg.min_success)[0] if alive else None
    top = math.ceil(cfg.confidence * 100 - 1e-9) - 1
    for c in (v / 100 for v in range(top, 49, -1)):
        if within_zone(alive, 1 - (1 - c) / k, cfg.min_success, cfg.indifference) is first:
            return c
    return None


def validate(
    choice: Choice,
    repeats: int,
    run_rollouts: Callable[[list[tuple]], list[dict]],
    *,
    seed: int,
) -> dict:
    """Drive every candidate `repeats` more times with fresh seeds (stream 1) and compare with
    the predicted P(success): Brier score and a reliability table."""
    calls = [
        (c.index, c.path_xyz.tolist(), rollout_seed(seed, c.index, k, stream=1))
        for c in choice.candidates
        for k in range(repeats)
    ]
    observed: dict[int, list[int]] = {c.index: [] for c in choice.candidates}
    for rec in run_rollouts(calls):
        observed[rec["candidate"]].append(int(rec["outcome"] == "success"))
    predicted = {row["candidate"]: row for row in choice.ranking}
    pairs = [(predicted[i]["p_success"], o) for i, obs in observed.items() for o in obs]
    brier = float(np.mean([(p - o) ** 2 for p, o in pairs])) if pairs else math.nan
    rows = []
    for i, obs in observed.items():
        row = predicted[i]
        rate = float(np.mean(obs)) if obs else math.nan
        rows.append(
            {
                "candidate": i,
                "predicted": row["p_success"],
                "low": row["p_low"],
                "high": row["p_high"],
                "observed": rate,
                "rollouts": len(obs),
                "inside": bool(row["p_low"] - 1e-12 <= rate <= row["p_high"] + 1e-12),
            }
        )
    bins = [(0.0, 0.5), (0.5, 0.8), (0.8, 0.95), (0.95, 1.0001)]
    table = []
    for lo, hi in bins:
        sel = [(p, o) for p, o in pairs if lo <= p < hi]
        if sel:
            table.append(
                {
                    "bin": f"[{lo:.2f}, {min(hi, 1):.2f}]",
                    "rollouts": len(sel),
                    "mean_predicted": float(np.mean([p for p, _ in sel])),
                    "observed": float(np.mean([o for _, o in sel])),
                }
            )
    return {"repeats": repeats, "brier": brier, "candidates": rows, "reliability": table}


def choose(
    scene,
    cfg: ChooseConfig,
    *,
    workers: int | None = 1,
    backend: str = "local",
    address: str | None = None,
    validate_repeats: int = 0,
    progress: Callable[[str, float], None] | None = None,
    cancelled: Callable[[], bool] = lambda: False,
) -> tuple[Choice, dict | None]:
    """Plan the candidates on `scene` (a loaded Scene with start and goal), race them on a pool
    of `workers` (local processes, or Ray), and with validate_repeats > 0 validate the
    prediction. Returns (choice, validation or None)."""
    from roachplan.scenes import build_world

    from ._runner import _make_pool
    from ._spec import ExperimentSpec

    if cfg.uncertainty is None:
        cfg = dataclass_replace(cfg, uncertainty=scene.uncertainty)
    world = build_world(scene)
    t0 = time.monotonic()
    if progress is not None:
        progress(f"planning {cfg.candidates} candidate paths", 0.0)
    candidates = plan_candidates(world, cfg, budget=cfg.budget_s)
    if not candidates:
        raise ChooseError(f"{scene.name}: the planner found no path to choose from")
    spec = ExperimentSpec(
        name=f"choose-{scene.name}",
        path=scene.path,
        scene=scene.path,
        planner=scene.planner,
        sim=scene.sim,
        driver=scene.driver,
        uncertainty=cfg.uncertainty,
    )
    pool = _make_pool(spec, workers, backend, address)

    spins = {c.index: c.spins for c in candidates}

    def run_rollouts(calls: list[tuple]) -> list[dict]:
        return list(
            pool.run(("rollout", (*c, cfg.uncertainty), {"spins": spins[c[0]]}) for c in calls)
        )

    try:
        left = None if cfg.budget_s is None else max(cfg.budget_s - (time.monotonic() - t0), 0.0)
        choice = race(
            candidates,
            dataclass_replace(cfg, budget_s=left),
            run_rollouts,
            mass=world.robot.mass,
            progress=progress,
            cancelled=cancelled,
        )
        checked = (
            validate(choice, validate_repeats, run_rollouts, seed=cfg.seed)
            if (validate_repeats > 0 and choice.stopped != "cancelled")
            else None
        )
    finally:
        pool.close()
    return dataclass_replace(choice, wall_time=time.monotonic() - t0), checked


class ChooseError(ExperimentError):
    """A choice that cannot be made as asked."""
