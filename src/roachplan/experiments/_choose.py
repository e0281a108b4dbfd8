"""Choose by simulation: which of K candidate paths the robot should take, with how much
confidence, by racing rollouts under an uncertainty model (`roachplan choose`, the page's
Choose path).

choose() plans K distinct candidates (experiments/_choose_planning.py: each route the scene
names gets candidates in turn), then screens them and certifies the one it picks on fresh
rollouts, with a guarantee valid at every look (experiments/_choose_certify.py, the default),
or, with procedure="race", races them without a certificate (experiments/_choose_race.py):
each round gives `batch` more rollouts (experiments/_uncertainty.py: each its own seed) on the worker pool to
the candidates whose intervals stand between the race and a decision, and after each round a
candidate leaves the race when it is clearly beaten (experiments/_choose_policy.py).

Bounds are Clopper-Pearson intervals for P(success) and t intervals for the mean energy over
successes (experiments/_choose_stats.py), each at confidence 1 - (1 - c) / K (Bonferroni over
the candidates). The race stops when one candidate is left (separated at the requested
confidence), when the first-ranked is within the indifference zone, when the rollout cap or
the time budget is spent, or, with min_success, when the cheapest candidate whose lower bound
clears it is separated from the other such ones. Which of these stopped it is reported.

What happens is told as it happens through on_event (experiments/_choose_events.py): the
candidates planned, each round, each candidate that leaves the race and why, the decision.

Everything drawn flows from `seed`: the candidates are planned with seeds seed, seed + 1, ...,
and rollout k of every candidate drives the world of seed world_seed(seed, k) (common random
numbers: the candidates are compared in the same worlds). Rounds end only when all their
rollouts are in, so with a rollout cap (not a time budget) the same seed gives the same choice.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace as dataclass_replace
from typing import TYPE_CHECKING

import numpy as np

from ._choose_certify import certify_race
from ._choose_config import ChooseConfig
from ._choose_events import CandidatesPlanned, ChooseEvent, CrossChecked
from ._choose_planning import plan_candidates
from ._choose_race import Choice, race
from ._cross_check import OTHER_ENGINE
from ._cross_check import cross_check as check_engines
from ._errors import ChooseError
from ._uncertainty import rollout_seed

if TYPE_CHECKING:
    from ._runner import Backend


def choose(
    world,
    cfg: ChooseConfig,
    *,
    workers: int | None = 1,
    backend: Backend = "local",
    address: str | None = None,
    validate_repeats: int = 0,
    cross_check: bool = False,
    on_event: Callable[[ChooseEvent], None] | None = None,
    cancelled: Callable[[], bool] = lambda: False,
) -> tuple[Choice, dict | None]:
    """Plan the candidates on `world` (a built World whose scene has a start and a goal; the
    rollout workers rebuild it from the scene's file), race them on a pool of `workers` (local
    processes, or Ray), and with validate_repeats > 0 validate the prediction. on_event
    receives the race's events (experiments/_choose_events.py) in the calling thread as they
    happen. cross_check: drive every rollout again under the other physics engine
    (experiments/_cross_check.py; choice.cross_check). Returns (choice, validation or None)."""
    from roachplan.scenes import with_engine

    from ._runner import _make_pool
    from ._spec import ExperimentSpec

    scene = world.scene
    uncertainty = scene.uncertainty if cfg.uncertainty is None else cfg.uncertainty
    cfg = dataclass_replace(cfg, uncertainty=uncertainty)
    t0 = time.monotonic()
    candidates = plan_candidates(world, cfg, budget=cfg.budget_s)
    if not candidates:
        raise ChooseError(f"{scene.name}: the planner found no path to choose from")
    if on_event is not None:
        on_event(CandidatesPlanned(candidates=tuple(c.plan for c in candidates)))

    def spec_of(physics) -> ExperimentSpec:  # (physics: the scene, or it under another engine)
        return ExperimentSpec.of_scene(
            physics, name=f"choose-{scene.name}", uncertainty=uncertainty
        )

    pool = _make_pool(spec_of(scene), workers, backend, address)
    spins = {c.index: c.spins for c in candidates}

    def runner(on, engine: str) -> Callable[[list[tuple]], list[dict]]:
        def run_rollouts(calls: list[tuple]) -> list[dict]:
            if engine != "mujoco":
                return list(
                    on.run(("rollout", (*c, uncertainty), {"spins": spins[c[0]]}) for c in calls)
                )
            # MuJoCo steps a worker's share of the round in lockstep (sim/_lockstep.py): one
            # batch per worker, the calls dealt round-robin (each batch a mix of candidates).
            dealt = [calls[k :: on.workers] for k in range(on.workers)]
            batches = [
                ("rollouts", ([(*c, spins[c[0]]) for c in part], uncertainty))
                for part in dealt
                if part
            ]
            return [rec for records in on.run(batches) for rec in records]

        return run_rollouts

    run_rollouts = runner(pool, scene.sim.engine)

    try:
        left = None if cfg.budget_s is None else max(cfg.budget_s - (time.monotonic() - t0), 0.0)
        choice = (race if cfg.procedure == "race" else certify_race)(
            candidates,
            dataclass_replace(cfg, budget_s=left),
            run_rollouts,
            mass=world.robot.mass,
            on_event=on_event,
            cancelled=cancelled,
        )
        checked = (
            validate(choice, validate_repeats, run_rollouts, seed=cfg.seed)
            if (validate_repeats > 0 and choice.stop != "cancelled")
            else None
        )
    finally:
        pool.close()
    if cross_check and choice.stop != "cancelled":
        other = with_engine(scene, OTHER_ENGINE[scene.sim.engine])
        pool = _make_pool(spec_of(other), workers, backend, address)
        try:
            checked_by = check_engines(choice, scene.sim.engine, runner(pool, other.sim.engine))
        finally:
            pool.close()
        choice = dataclass_replace(choice, cross_check=checked_by)
        if on_event is not None:
            on_event(CrossChecked(result=checked_by))
    return dataclass_replace(choice, wall_time=time.monotonic() - t0), checked


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
    predicted = {s.candidate: s for s in choice.standings}
    pairs = [(predicted[i].p_success, o) for i, obs in observed.items() for o in obs]
    brier = float(np.mean([(p - o) ** 2 for p, o in pairs])) if pairs else math.nan
    rows = []
    for i, obs in observed.items():
        s = predicted[i]
        rate = float(np.mean(obs)) if obs else math.nan
        rows.append(
            {
                "candidate": i,
                "predicted": s.p_success,
                "low": s.p_low,
                "high": s.p_high,
                "observed": rate,
                "rollouts": len(obs),
                "inside": bool(s.p_low - 1e-12 <= rate <= s.p_high + 1e-12),
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
