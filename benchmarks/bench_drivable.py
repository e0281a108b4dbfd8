"""Drivable plans + the tracking driver against the report's setting (raw paths, algorithms
1-2), side by side in one run (issue 18).

    make bench        (or: .venv/bin/python benchmarks/bench_drivable.py [--quick])

For each library spec it runs the experiment twice, `reference: true` (the report's) and
`reference: false` (the default), and prints successes and relative energy (mean, max over
successes). Goals: kinect_bridge (25 paths) mean <= 1.6, max <= 2.5, >= 24/25 successes;
bridge_rough (50 trials) >= 48/50; the rough bridge still costs more than the smooth one.
Then planning time of PRM and RRTConnect on double_bridge, raw vs drivable (goal: <= 2x).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from roachplan.experiments import load_experiment, plan, run_experiment
from roachplan.experiments._spec import reference_settings
from roachplan.scenes import build_world, load_scene


def run(spec, trials: int, workers: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run_experiment(spec, trials=trials, out=Path(tmp), workers=workers, progress=False)
        wall = time.perf_counter() - t0
        lines = (Path(tmp) / "trials.jsonl").read_text().splitlines()
    recs = [r for r in map(json.loads, lines) if r["kind"] == "trial"]
    rel = [r["relative_energy"] for r in recs if r["outcome"] == "success"]
    return dict(
        ok=len(rel),
        n=len(recs),
        mean=statistics.fmean(rel) if rel else float("nan"),
        max=max(rel) if rel else float("nan"),
        wall=wall,
    )


def settings(spec, reference: bool):
    """The spec as the report ran it (reference) or with this project's defaults."""
    if reference:
        planner, driver = reference_settings(spec.planner, spec.driver)
    else:
        scene = load_scene(spec.scene)  # the scene's (default) planner with the spec's choices
        planner = dataclasses.replace(spec.planner, turning_radius=scene.planner.turning_radius)
        driver = dataclasses.replace(spec.driver, kind=scene.driver.kind)
    return dataclasses.replace(spec, planner=planner, driver=driver, best_path_repeats=0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="a fifth of the trials")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    scale = 5 if args.quick else 1
    print(f"{'spec':<14} {'setting':<10} {'success':>9} {'rel. energy mean':>17} {'max':>6} "
          f"{'wall s':>7}")  # fmt: skip
    means = {}
    for name, trials in (("kinect_bridge", 25), ("bridge_rough", 50), ("bridge_smooth", 50)):
        spec = load_experiment(name)
        for label, reference in (("reference", True), ("drivable", False)):
            r = run(settings(spec, reference), max(2, trials // scale), args.workers)
            means[name, label] = r["mean"]
            print(f"{name:<14} {label:<10} {r['ok']:>4}/{r['n']:<4} {r['mean']:>17.2f} "
                  f"{r['max']:>6.2f} {r['wall']:>7.1f}", flush=True)  # fmt: skip
    for label in ("reference", "drivable"):
        rough, smooth = means["bridge_rough", label], means["bridge_smooth", label]
        print(f"{label}: rough / smooth relative energy = {rough / smooth:.2f} "
              f"({'rough costs more' if rough > smooth else 'rough does NOT cost more'})")

    world = build_world(load_scene("double_bridge"))
    print("\nplanning time on double_bridge, median of 10 seeds [s]")
    for planner in ("prm", "rrtconnect"):
        times = {}
        for label, radius in (("raw", None), ("drivable", world.scene.planner.turning_radius)):
            cfg = dataclasses.replace(world.scene.planner, name=planner, turning_radius=radius)
            times[label] = np.median([plan(world, seed=s, planner=cfg).plan_time for s in range(10)])
        print(f"  {planner:<11} raw {times['raw']:.3f}  drivable {times['drivable']:.3f}  "
              f"ratio {times['drivable'] / times['raw']:.2f} (goal <= 2)")


if __name__ == "__main__":
    main()
