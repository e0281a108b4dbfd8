"""Fidelity under MuJoCo (issue 31's goal): the same candidate paths in the same drawn worlds
under both engines, side by side in one run. Per path: successes, the 95 % interval on
P(success) and the mean relative energy of the successes under PyBullet and MuJoCo, and
whether the two intervals overlap; then how many paths agree (the goal: at least 7 of 8),
which path each engine favours (the goal: the same one), and each engine's rollouts per second
on the same workers (MuJoCo in lockstep batches, as choose deals them).

    .venv/bin/python benchmarks/bench_fidelity.py [--scene double_bridge_rough]
        [--candidates 8] [--draws 40] [--workers 2] [--seed 0]

The candidates are choose's (experiments/_choose_planning.py plan_candidates, planned once on
the scene as PyBullet's: a plan does not depend on the engine that drives it); draw k of path
c is the world choose's rollout k of candidate c draws (rollout_seed), from the scene's
uncertainty. About 8 x 40 rollouts per engine: 4-6 minutes on 2 shared cores.
"""

from __future__ import annotations

import argparse
import os
import time


def run_engine(scene, engine: str, calls: list[tuple], workers: int) -> tuple[list[dict], float]:
    """(rollout records, wall time [s]) of calls (candidate, path, seed, spins) under engine."""
    from roachplan.experiments import ExperimentSpec
    from roachplan.experiments._runner import _make_pool
    from roachplan.scenes import with_engine

    scene_e = with_engine(scene, engine)
    pool = _make_pool(ExperimentSpec.of_scene(scene_e, name="fidelity"), workers, "local", None)
    try:
        list(pool.run([("plan_route", (0,))] * workers))  # (the workers up, worlds built)
        t = time.perf_counter()
        if engine == "mujoco":  # lockstep: one batch per worker
            dealt = [calls[k::workers] for k in range(workers)]
            batches = [("rollouts", (part, scene_e.uncertainty)) for part in dealt if part]
            records = [r for part in pool.run(batches) for r in part]
        else:
            records = list(
                pool.run(
                    ("rollout", (c, p, sd, scene_e.uncertainty), {"spins": sp})
                    for c, p, sd, sp in calls
                )
            )
        return records, time.perf_counter() - t
    finally:
        pool.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--scene", default="double_bridge_rough")
    ap.add_argument("--candidates", type=int, default=8)
    ap.add_argument("--draws", type=int, default=40, help="world draws per path")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0, help="the candidates' and draws' seed")
    args = ap.parse_args()

    from roachplan.experiments import ChooseConfig
    from roachplan.experiments._choose_planning import plan_candidates
    from roachplan.experiments._cross_check import compare
    from roachplan.experiments._uncertainty import rollout_seed
    from roachplan.scenes import build_world, load_scene

    scene = load_scene(args.scene)
    world = build_world(scene)
    t = time.perf_counter()
    cfg = ChooseConfig(candidates=args.candidates, seed=args.seed, budget_s=None)
    candidates = plan_candidates(world, cfg)
    print(
        f"{args.scene}: {len(candidates)} candidate paths planned in "
        f"{time.perf_counter() - t:.1f} s; {args.draws} world draws each; {args.workers} "
        f"workers; load average {os.getloadavg()[0]:.1f}"
    )
    calls = [
        (c.index, c.path_xyz.tolist(), rollout_seed(args.seed, c.index, k), c.spins)
        for c in candidates
        for k in range(args.draws)
    ]
    by_engine, wall = {}, {}
    for engine in ("pybullet", "mujoco"):
        records, wall[engine] = run_engine(scene, engine, calls, args.workers)
        grouped: dict[int, list[dict]] = {c.index: [] for c in candidates}
        for rec in records:
            grouped[rec["candidate"]].append(rec)
        by_engine[engine] = grouped
    rows, mujoco_favours = compare(
        by_engine["pybullet"], by_engine["mujoco"], "pybullet", "mujoco", key="candidate"
    )
    _, pybullet_favours = compare(
        by_engine["mujoco"], by_engine["pybullet"], "mujoco", "pybullet", key="candidate"
    )
    print(f"\n{'path':>4s} {'route':>12s}  {'pybullet':>26s}  {'mujoco':>26s}  agree")
    route = {c.index: c.route for c in candidates}

    def cell(t: dict) -> str:
        return (
            f"{t['successes']:3d}/{t['rollouts']:<3d}[{t['p_low']:.2f},{t['p_high']:.2f}] "
            f"E {t['relative_energy']:.2f}"
        )

    for row in rows:
        i = row["candidate"]
        print(
            f"{i:4d} {route[i] or '-':>12s}  {cell(row['pybullet']):>26s}  "
            f"{cell(row['mujoco']):>26s}  {'yes' if row['agree'] else 'NO'}"
        )
    agreeing = sum(r["agree"] for r in rows)
    print(
        f"\npaths whose success rates agree (95% intervals overlap): {agreeing} of {len(rows)} "
        f"(goal: at least {len(rows) - 1})"
    )
    print(
        f"favoured path: pybullet {pybullet_favours}, mujoco {mujoco_favours} "
        f"({'the same' if pybullet_favours == mujoco_favours else 'DIFFERENT'})"
    )
    n = len(calls)
    rate = {e: n / wall[e] for e in wall}
    print(
        f"rollouts per second on {args.workers} workers: pybullet {rate['pybullet']:.2f}, "
        f"mujoco (lockstep) {rate['mujoco']:.2f}: {rate['mujoco'] / rate['pybullet']:.2f}x"
    )


if __name__ == "__main__":
    main()
