"""Choose by simulation (issues 17 and 25), measured side by side in one run.

    make bench        (or: .venv/bin/python benchmarks/bench_choose.py [--quick] [--parts 1,3]
                       [--bank N] [--races N] [--fresh N] [--scenes A,B]: fewer counts on a
                       busy machine; [--indifference DP,DE]: parts 1-2's zone, default 0.05,0.05)

Parts 1-2 race with an indifference zone (experiments/_choose_policy.py): on double_bridge_rough
the best candidates succeed 194-200 times in 200 and never separate. Part 2's bank is therefore 200
rollouts per candidate (the race's own cap, max_per_candidate): the zone is out of reach below
about 120 (with every rollout a success the Clopper-Pearson lower bound at 1 - 0.05/8 reaches
0.95 at n = 113), and with a bank of 40 every race ran to the bank's end. The bank drives every
candidate in the same worlds, as the race does (common random numbers).
Measured (2-core VM, load 1-3, mostly its own workers): part 1 59.5 s, 176 rollouts, budget
spent, no decision (uncapped: decided in 88.8 s, 280 rollouts); part 2 10/20 the same choice,
20/20 within the zone of it, 21 % of the rollouts (max 38 %), every race stopped in the zone,
brute force's own choice firm in 133 of 200 resamples; part 2 took 509 s; part 3 97 % vs 81 %
(double_bridge_rough), 95 % vs 93 % (kinect_bridge).

1. Decision time: `double_bridge_rough`, K = 8, 95 % confidence, 60 s budget, 2 workers, by issue
   17's race and by screen-and-certify (issue 25) in its default and quick modes, in that order
   in one run: the wall time as a ratio to the report's minute per trial and to the robot's own
   traverse time, and rollouts per second as a ratio to the race's.
2. Racing against brute force: every candidate driven N_full times once (the bank); then 20 races
   with different seeds replayed from the bank (each race draws its rollouts from a candidate's
   bank in its own seeded order): how often the race picks brute force's choice (and how often
   one within the zone of it, on the bank's estimates), the share of the bank's rollouts it used,
   and why the races stopped. Goal: >= 95 % agreement with <= 50 % of the rollouts.
3. The chosen path against the first planned path on fresh rollouts, on `double_bridge_rough`
   and `kinect_bridge`. The first planned path is the planner's plain first plan (the scene's
   planner with the choice's seed, start to goal, as `roachplan trial` plans it), not candidate
   0 (which is planned through a route's via pose). Both drive the same fresh worlds (stream 4
   seeds, unused by the race (0), --validate (1), the bank (2) and scaling (3)): a paired
   comparison.
4. Scaling: the same rollouts on 1 and 2 local workers.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from collections import Counter
from typing import Literal

import numpy as np

from roachplan.experiments import DEFAULT_MODE, QUICK_MODE, ChooseConfig, choose
from roachplan.experiments._choose_candidate import Candidate
from roachplan.experiments._choose_planning import plan_candidates
from roachplan.experiments._choose_policy import rank
from roachplan.experiments._choose_race import race
from roachplan.experiments._runner import _make_pool
from roachplan.experiments._spec import ExperimentSpec
from roachplan.experiments._trial import plan
from roachplan.experiments._uncertainty import rollout_seed
from roachplan.scenes import build_world, load_scene


def _pool(scene, workers: int):
    spec = ExperimentSpec(
        name="bench",
        path=scene.path,
        scene=scene.path,
        planner=scene.planner,
        sim=scene.sim,
        driver=scene.driver,
        uncertainty=scene.uncertainty,
    )
    return _make_pool(spec, workers, "local", None)


def _drive_all(
    pool, cfg, candidates, n: int, stream: int, *, paired: bool = False, uncertainty=None
) -> dict[int, list[dict]]:
    """Drive each candidate n times; paired: rollout k of every candidate in the same world."""
    u = uncertainty or cfg.uncertainty

    def seed(c, k):
        return rollout_seed(cfg.seed, 0 if paired else c.index, k, stream)

    calls = [
        ("rollout", (c.index, c.path_xyz.tolist(), seed(c, k), u), {"spins": c.spins})
        for c in candidates
        for k in range(n)
    ]
    out: dict[int, list[dict]] = {c.index: [] for c in candidates}
    for rec in pool.run(calls):  # (in the order they finish)
        out[rec["candidate"]].append(rec)
    k_of = {seed(c, k): k for c in candidates for k in range(n)}
    for recs in out.values():  # rollout k at [k]: paired, [k] is world k for every candidate
        recs.sort(key=lambda r: k_of[r["seed"]])
    return out


def decision_time(quick: bool, args) -> None:
    """Issue 17's race, then screen-and-certify in the default and the quick mode, one after
    the other in this run (the same machine, the same load): wall time to a decision with its
    guarantee, rollouts, and rollouts per second against the race's."""
    scene = load_scene("double_bridge_rough")
    world = build_world(scene)
    runs: tuple[tuple[str, Literal["certify", "race"], tuple[float, float]], ...] = (
        ("race (issue 17)", "race", args.indifference),
        ("certify, default", "certify", DEFAULT_MODE),
        ("certify, --quick", "certify", QUICK_MODE),
    )
    rate17 = None
    for label, procedure, zone in runs:
        cfg = ChooseConfig(
            candidates=4 if quick else 8,
            budget_s=60.0,
            seed=0,
            indifference=zone,
            procedure=procedure,
        )
        choice, _ = choose(world, cfg, workers=2)
        row = next((r for r in choice.ranking if r["candidate"] == choice.chosen), None)
        drives = [r for c in choice.candidates for r in c.rollouts]
        drives += [r for recs in choice.fresh.values() for r in recs]
        rollout_s = sum(r.get("wall_time", math.nan) for r in drives) / max(len(drives), 1)
        rate = choice.rollouts / choice.wall_time
        rate17 = rate17 or rate
        print(
            f"1. {label}: double_bridge_rough, K={cfg.candidates}, zone {cfg.indifference}: "
            f"{choice.wall_time:.1f} s wall, {choice.rollouts} rollouts ({rate:.2f}/s, "
            f"{rate / rate17:.2f}x the race's; {rollout_s:.2f} s per rollout in a worker), "
            f"{choice.stopped}; chosen {choice.chosen}"
            + (f" ({row['route']}, P {row['p_success']:.2f})" if row else "")
        )
        if choice.guarantee is not None and choice.chosen is not None:
            print(f"   guarantee: {choice.guarantee.sentence(choice.chosen)}")
        if row:
            print(
                f"   ratio to the report's minute per trial: {choice.wall_time / 60:.2f}; to "
                f"the robot's traverse ({row['drive_time_s']:.1f} s simulated): "
                f"{choice.wall_time / row['drive_time_s']:.2f}"
            )


def racing_vs_bank(quick: bool, args) -> None:
    scene = load_scene("double_bridge_rough")
    world = build_world(scene)
    cfg = ChooseConfig(
        candidates=4 if quick else 8,
        budget_s=None,
        seed=0,
        uncertainty=scene.uncertainty,
        indifference=args.indifference,
    )
    candidates = plan_candidates(world, cfg)
    n_full = args.bank or (12 if quick else 200)
    pool = _pool(scene, 2)
    try:
        bank = _drive_all(pool, cfg, candidates, n_full, stream=2, paired=True)
    finally:
        pool.close()
    full = [dataclasses.replace(c, rollouts=bank[c.index], knocked_out=None) for c in candidates]
    truth = rank(full, 1 - (1 - cfg.confidence) / len(full), None)[0].index
    # How firm brute force's own choice is: its choice on 200 resamples of the bank's worlds
    # (with replacement, the same worlds for every candidate). Between near-equal candidates it
    # moves, and no race using part of the bank can agree with it more often than that.
    firm = Counter()
    for b in range(200):
        pick = np.random.default_rng([7, b]).integers(0, n_full, n_full)
        resampled = [
            dataclasses.replace(
                c,
                knocked_out=None,
                rollouts=[{**bank[c.index][i], "seed": j} for j, i in enumerate(pick)],
            )
            for c in candidates
        ]
        firm[rank(resampled, 1 - (1 - cfg.confidence) / len(full), None)[0].index] += 1
    # Brute force's choice and everything within the indifference zone of it on the bank's own
    # estimates (P within DP, mean relative energy within DE): a race that stops in the zone
    # may pick any of these, which is as good as brute force's choice by the zone's definition.
    dp, de = cfg.indifference
    est = {c.index: (c.p_interval(0.95)[0], c.energy_interval(0.95)[0]) for c in full}
    zone = {
        i for i, (p, e) in est.items() if p >= est[truth][0] - dp and e <= (1 + de) * est[truth][1]
    }
    agree, in_zone, used, stops = 0, 0, [], Counter()
    runs = args.races or (5 if quick else 20)
    for r in range(runs):
        # One order of the bank's worlds per race, the same for every candidate: the race
        # compares candidates in the same worlds (common random numbers), and so does the bank.
        shared = np.random.default_rng([r]).permutation(n_full)
        order = {c.index: shared for c in candidates}
        taken = {c.index: 0 for c in candidates}

        def replay(calls, order=order, taken=taken):
            recs = []
            for index, _path, seed in calls:
                k = taken[index]
                taken[index] += 1
                recs.append({**bank[index][order[index][k]], "seed": seed})
            return recs

        racers = [dataclasses.replace(c, rollouts=[], knocked_out=None) for c in candidates]
        choice = race(
            racers,
            dataclasses.replace(cfg, seed=100 + r, max_per_candidate=n_full),
            replay,
            mass=world.robot.mass,
        )
        agree += choice.chosen == truth
        in_zone += choice.chosen in zone
        stops[choice.stopped] += 1
        used.append(choice.rollouts / (n_full * len(candidates)))
    print(
        f"2. racing vs all {n_full} rollouts of {len(candidates)} candidates (indifference "
        f"{dp:g}, {de:.0%}): same choice in {agree}/{runs} races, within the zone of it "
        f"{in_zone}/{runs}, using {np.mean(used):.0%} of the rollouts (mean; max "
        f"{np.max(used):.0%})"
    )
    print(
        "   brute force's own choice on 200 resamples of its bank: "
        + ", ".join(f"{i} {k}x" for i, k in firm.most_common())
    )
    print(
        f"   brute force: candidate {truth}; zone {sorted(zone)}; bank estimates "
        + ", ".join(f"{i}: {p:.3f} {e:.3f}" for i, (p, e) in est.items())
    )
    print("   stopped: " + "; ".join(f"{n}x {why}" for why, n in stops.items()))


def chosen_vs_first(quick: bool, args) -> None:
    fresh = args.fresh or (20 if quick else 100)
    for name in args.scenes.split(","):
        scene = load_scene(name)
        cfg = ChooseConfig(
            candidates=4 if quick else 8,
            budget_s=60.0,
            seed=scene.seed,
            uncertainty=scene.uncertainty,
        )
        world = build_world(scene)
        choice, _ = choose(world, cfg, workers=2)
        if choice.chosen is None:
            print(f"3. {name}: no candidate succeeded in any rollout; nothing to compare")
            continue
        picked = next(c for c in choice.candidates if c.index == choice.chosen)
        # The planner's plain first plan: what a user gets without choose (`roachplan trial
        # --seed S` plans the same path).
        planned = plan(world, seed=cfg.seed)
        if not planned.found:
            print(f"3. {name}: the planner's first plan found no path ({planned.message})")
            continue
        xyz = planned.path_xyz
        length = float(np.sum(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1)))
        first = Candidate(
            index=0,
            route=world.route(xyz[:, :2]) or "-",
            seed=cfg.seed,
            path_xyz=xyz,
            length=length,
            spins=planned.spins,
        )
        chosen = dataclasses.replace(picked, index=1, rollouts=[])
        pool = _pool(scene, 2)
        try:
            got = _drive_all(pool, cfg, [first, chosen], fresh, stream=4, paired=True)
        finally:
            pool.close()
        rate = {i: np.mean([r["outcome"] == "success" for r in recs]) for i, recs in got.items()}
        print(
            f"3. {name}: chosen candidate {picked.index} ({picked.route}) succeeds "
            f"{rate[1]:.0%} of {fresh} fresh rollouts; the planner's first plan "
            f"({first.route}, seed {cfg.seed}) {rate[0]:.0%} of the same {fresh} worlds "
            f"(race: {choice.rollouts} rollouts, {choice.wall_time:.1f} s, {choice.stopped})"
        )


def scaling(quick: bool, args) -> None:
    scene = load_scene("double_bridge_rough")
    world = build_world(scene)
    cfg = ChooseConfig(candidates=2, seed=0, uncertainty=scene.uncertainty)
    candidates = plan_candidates(world, cfg)
    n = 4 if quick else 12
    walls = {}
    for workers in (1, 2):
        pool = _pool(scene, workers)
        try:
            # Warm every worker: the pool spawns its processes on demand, and a worker's first
            # call pays for its imports and world (seconds), which is not the rollouts' time.
            _drive_all(pool, cfg, candidates[:1], 2 * workers, stream=5)
            t0 = time.perf_counter()
            _drive_all(pool, cfg, candidates, n, stream=3)
            walls[workers] = time.perf_counter() - t0
        finally:
            pool.close()
    print(
        f"4. {n * len(candidates)} rollouts: 1 worker {walls[1]:.1f} s, 2 workers {walls[2]:.1f} s,"
        f" speed-up {walls[1] / walls[2]:.2f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer candidates and rollouts")
    ap.add_argument("--parts", default="1,2,3,4", help="which parts to run, e.g. 1,3")
    ap.add_argument("--bank", type=int, default=None, help="part 2: rollouts per candidate (200)")
    ap.add_argument("--races", type=int, default=None, help="part 2: races replayed (20)")
    ap.add_argument("--fresh", type=int, default=None, help="part 3: fresh rollouts each (100)")
    ap.add_argument("--scenes", default="double_bridge_rough,kinect_bridge", help="part 3's scenes")
    ap.add_argument(
        "--indifference",
        default="0.05,0.05",
        metavar="DP,DE",
        help="parts 1-2: the race's indifference zone (0,0: off)",
    )
    args = ap.parse_args()
    args.indifference = tuple(float(v) for v in args.indifference.split(","))
    parts = {int(p) for p in args.parts.split(",")}
    for number, part in enumerate((decision_time, racing_vs_bank, chosen_vs_first, scaling), 1):
        if number in parts:
            t0 = time.perf_counter()
            part(args.quick, args)
            print(f"   (part {number}: {time.perf_counter() - t0:.0f} s wall)", flush=True)


if __name__ == "__main__":
    main()
