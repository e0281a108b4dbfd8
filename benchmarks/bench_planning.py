"""Every planner on the double bridges: success rate, time to first solution, validity checks/s.

    make bench        (or: .venv/bin/python benchmarks/bench_planning.py [--seeds N] [--scenes ...])

For each planner and scene, N seeds (default 20). "first solution" is the plan's wall time in
its planning process (optimizing planners stop at their first solution by default), without the
~8 ms fork that isolates each plan (reported separately). "checks/s" = states whose validity was
computed / wall time spent computing validity, summed over the seeds; most checks come in
batches (motions, and the sampler's blocks of 256); "single" is the rate of one-state checks.
Targets (issue 5): >= 50,000 checks/s; median first solution <= 0.2 s for PRM and RRTConnect
on double_bridge.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from roachplan.experiments import plan
from roachplan.planning import PLANNER_NAMES, check_states
from roachplan.scenes import build_world, load_scene


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--scenes", nargs="+", default=["double_bridge", "double_bridge_rough"])
    ap.add_argument("--planners", nargs="+", default=list(PLANNER_NAMES))
    args = ap.parse_args()
    for scene in args.scenes:
        world = build_world(load_scene(scene))
        _ = world.regions  # the standable map is computed once per world, not per plan
        one = np.array([world.scene.start])
        t0, n = time.perf_counter(), 0
        while time.perf_counter() - t0 < 0.5:
            check_states(world.heightfield, world.footprint, world.scene.planner.validity, one)
            n += 1
        single = n / (time.perf_counter() - t0)
        print(f"\n{scene}: {args.seeds} seeds per planner; one-state checks {single:,.0f}/s")
        print(
            f"{'planner':16s} {'success':>8s} {'median s':>9s} {'max s':>7s} {'checks/s':>10s}"
            f" {'fork ms':>8s}"
        )
        for name in args.planners:
            cfg = dataclasses.replace(world.scene.planner, name=name)
            times, walls, checks, check_time, found = [], [], 0, 0.0, 0
            for seed in range(args.seeds):
                t = time.perf_counter()
                r = plan(world, seed=seed, planner=cfg)
                walls.append(time.perf_counter() - t - r.plan_time)
                found += r.found
                if r.found:
                    times.append(r.plan_time)
                checks += r.validity_checks
                check_time += r.validity_time
            med = f"{np.median(times):9.3f}" if times else f"{'-':>9s}"
            mx = f"{np.max(times):7.3f}" if times else f"{'-':>7s}"
            print(
                f"{name:16s} {found:5d}/{args.seeds:<2d} {med} {mx} "
                f"{checks / max(check_time, 1e-9):10,.0f} {1000 * np.median(walls):8.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
