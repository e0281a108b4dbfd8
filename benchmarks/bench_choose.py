"""Choose by simulation (issue 17), measured side by side in one run.

    make bench        (or: .venv/bin/python benchmarks/bench_choose.py [--quick])

1. Decision time: `double_bridge_rough`, K = 8, 95 % confidence, 60 s budget, 2 workers; the wall
   time as a ratio to the report's minute per trial and to the robot's own traverse time.
2. Racing against brute force: every candidate driven N_full times once (the bank); then 20 races
   with different seeds replayed from the bank (each race draws its rollouts from a candidate's
   bank in its own seeded order): how often the race picks brute force's choice, and the share of
   the bank's rollouts it used. Goal: >= 95 % agreement with <= 50 % of the rollouts.
3. The chosen path against the first planned path on fresh rollouts (stream 1 seeds), on
   `double_bridge_rough` and `kinect_bridge`.
4. Scaling: the same rollouts on 1 and 2 local workers.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from roachplan.experiments._choose import ChooseConfig, choose, plan_candidates, race, rank
from roachplan.experiments._runner import _make_pool
from roachplan.experiments._spec import ExperimentSpec
from roachplan.experiments._uncertainty import rollout_seed
from roachplan.scenes import build_world, load_scene


def _pool(scene, workers: int):
    spec = ExperimentSpec(name="bench", path=scene.path, scene=scene.path,
                          planner=scene.planner, sim=scene.sim, driver=scene.driver)  # fmt: skip
    return _make_pool(spec, workers, "local", None)


def _drive_all(pool, cfg, candidates, n: int, stream: int) -> dict[int, list[dict]]:
    calls = [("rollout", (c.index, c.path_xyz.tolist(), rollout_seed(cfg.seed, c.index, k, stream),
                          cfg.uncertainty)) for c in candidates for k in range(n)]  # fmt: skip
    out: dict[int, list[dict]] = {c.index: [] for c in candidates}
    for rec in pool.run(calls):
        out[rec["candidate"]].append(rec)
    return out


def decision_time(quick: bool) -> None:
    scene = load_scene("double_bridge_rough")
    cfg = ChooseConfig(candidates=4 if quick else 8, budget_s=60.0, seed=0)
    choice, _ = choose(scene, cfg, workers=2)
    row = next(r for r in choice.ranking if r["candidate"] == choice.chosen)
    print(f"1. double_bridge_rough, K={cfg.candidates}: {choice.wall_time:.1f} s wall, "
          f"{choice.rollouts} rollouts, {choice.stopped}; chosen {choice.chosen} "
          f"({row['route']}, P {row['p_success']:.2f} [{row['p_low']:.2f}, {row['p_high']:.2f}])")
    print(f"   ratio to the report's minute per trial: {choice.wall_time / 60:.2f}; to the "
          f"robot's traverse ({row['drive_time_s']:.1f} s simulated): "
          f"{choice.wall_time / row['drive_time_s']:.2f}")


def racing_vs_bank(quick: bool) -> None:
    scene = load_scene("double_bridge_rough")
    world = build_world(scene)
    cfg = ChooseConfig(candidates=4 if quick else 8, budget_s=None, seed=0)
    candidates = plan_candidates(world, cfg)
    n_full = 12 if quick else 40
    pool = _pool(scene, 2)
    try:
        bank = _drive_all(pool, cfg, candidates, n_full, stream=2)
    finally:
        pool.close()
    full = [dataclasses.replace(c, rollouts=bank[c.index], out="") for c in candidates]
    truth = rank(full, 1 - (1 - cfg.confidence) / len(full), None)[0].index
    agree, used = 0, []
    runs = 5 if quick else 20
    for r in range(runs):
        order = {c.index: np.random.default_rng([r, c.index]).permutation(n_full) for c in candidates}
        taken = {c.index: 0 for c in candidates}

        def replay(calls, order=order, taken=taken):
            recs = []
            for index, _path, seed in calls:
                k = taken[index]
                taken[index] += 1
                recs.append({**bank[index][order[index][k]], "seed": seed})
            return recs

        racers = [dataclasses.replace(c, rollouts=[], out="") for c in candidates]
        choice = race(racers, dataclasses.replace(cfg, seed=100 + r, max_per_candidate=n_full),
                      replay, mass=world.robot.mass)  # fmt: skip
        agree += choice.chosen == truth
        used.append(choice.rollouts / (n_full * len(candidates)))
    print(f"2. racing vs all {n_full} rollouts of {len(candidates)} candidates: same choice in "
          f"{agree}/{runs} races, using {np.mean(used):.0%} of the rollouts (mean; max "
          f"{np.max(used):.0%})")


def chosen_vs_first(quick: bool) -> None:
    fresh = 20 if quick else 100
    for name in ("double_bridge_rough", "kinect_bridge"):
        scene = load_scene(name)
        cfg = ChooseConfig(candidates=4 if quick else 8, budget_s=60.0, seed=0)
        choice, _ = choose(scene, cfg, workers=2)
        first = next(c for c in choice.candidates if c.index == 0)
        chosen = next(c for c in choice.candidates if c.index == choice.chosen)
        pool = _pool(scene, 2)
        try:
            got = _drive_all(pool, cfg, [first, chosen] if chosen is not first else [first],
                             fresh, stream=1)  # fmt: skip
        finally:
            pool.close()
        rate = {i: np.mean([r["outcome"] == "success" for r in recs]) for i, recs in got.items()}
        print(f"3. {name}: chosen candidate {chosen.index} succeeds {rate[chosen.index]:.0%} of "
              f"{fresh} fresh rollouts; the first planned path {rate[first.index]:.0%}")


def scaling(quick: bool) -> None:
    scene = load_scene("double_bridge_rough")
    world = build_world(scene)
    cfg = ChooseConfig(candidates=2, seed=0)
    candidates = plan_candidates(world, cfg)
    n = 4 if quick else 12
    walls = {}
    for workers in (1, 2):
        pool = _pool(scene, workers)
        try:
            _drive_all(pool, cfg, candidates[:1], 1, stream=3)  # warm the workers
            t0 = time.perf_counter()
            _drive_all(pool, cfg, candidates, n, stream=3)
            walls[workers] = time.perf_counter() - t0
        finally:
            pool.close()
    print(f"4. {n * len(candidates)} rollouts: 1 worker {walls[1]:.1f} s, 2 workers {walls[2]:.1f} s,"
          f" speed-up {walls[1] / walls[2]:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer candidates and rollouts")
    args = ap.parse_args()
    decision_time(args.quick)
    racing_vs_bank(args.quick)
    chosen_vs_first(args.quick)
    scaling(args.quick)


if __name__ == "__main__":
    main()
