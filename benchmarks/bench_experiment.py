"""Wall time of the bridge_rough experiment (50 trials) on 1 and 2 workers, and the speed-up.

    make bench        (or: .venv/bin/python benchmarks/bench_experiment.py [--trials 50])

Each run is the whole `roachplan experiment` pipeline from a cold start: worker start-up,
the census (plans until each bridge has its paths), the trials (plan + drive), the summary and
the figures; no best-path re-drives (--repeats 0), so that it times the 50 trials.
"Work" is the sum over trials of their planning and simulation wall times (in the workers);
efficiency = work / (wall x workers). Targets (issue 6): <= 60 s on 2 workers (Tong 2018: about
a minute per trial); speed-up 1 -> 2 workers >= 1.8.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from roachplan.experiments import load_experiment, run_experiment


def timed_run(spec, trials: int, workers: int) -> tuple[float, float, int]:
    """(wall [s], work [s], successes)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        report = run_experiment(spec, trials=trials, out=Path(tmp), workers=workers, progress=False)
        wall = time.perf_counter() - t0
        recs = [json.loads(line) for line in (Path(tmp) / "trials.jsonl").read_text().splitlines()]
    work = sum(r["plan_time"] + r["drive_wall_time"] for r in recs if r["kind"] == "trial")
    return wall, work, sum(s.successes for s in report.summaries)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--spec", default="bridge_rough")
    ap.add_argument("--trials", type=int, default=50)
    args = ap.parse_args()
    import dataclasses

    spec = dataclasses.replace(load_experiment(args.spec), best_path_repeats=0)
    print(f"{args.spec}: {args.trials} trials, {os.cpu_count()} cores")
    print(
        f"{'workers':>7} {'wall s':>7} {'s/trial':>7} {'work s':>7} {'efficiency':>10} {'successes':>9}"
    )
    walls = {}
    for workers in (1, 2):
        wall, work, ok = timed_run(spec, args.trials, workers)
        walls[workers] = wall
        print(
            f"{workers:7d} {wall:7.1f} {wall / args.trials:7.2f} {work:7.1f} "
            f"{work / (wall * workers):10.2f} {ok:9d}"
        )
    speedup = walls[1] / walls[2]
    print(f"2 workers: {walls[2]:.1f} s wall (target <= 60 s; the report: ~{args.trials} min)")
    print(f"speed-up 1 -> 2 workers: {speedup:.2f}x (target >= 1.8)")
    print(f"vs the report's ~60 s per trial: {60.0 * args.trials / walls[2]:.0f}x faster")


if __name__ == "__main__":
    main()
