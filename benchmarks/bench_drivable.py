"""Drivable plans + the tracking driver against the report's setting (raw paths, algorithms
1-2), side by side in one run (issue 18).

    make bench        (or: .venv/bin/python benchmarks/bench_drivable.py [--quick])

For each library spec it runs the experiment twice, `reference: true` (the report's) and
`reference: false` (the default), and prints successes and relative energy (mean, max over
successes), and how many trials' plans turned on the spot (spins: drivable plans use them only
where no arc goes on). Goals: kinect_bridge (25 paths) mean <= 1.6, max <= 2.5, >= 24/25 successes;
bridge_rough (50 trials) >= 48/50; the rough bridge still costs more than the smooth one.
Then planning time of PRM and RRTConnect on double_bridge, raw vs drivable (goal: <= 2x), and
the two ways to a drivable plan on double_bridge: searching OMPL's (x, y, yaw) space and
Dubins-shortcutting the route (the default), against searching OMPL's DubinsStateSpace itself
(RRT and KPIECE1: Dubins distance is not a metric, which PRM's undirected roadmap and
RRTConnect's backward tree assume; OMPL gives a non-metric space a nearest-neighbour structure
that does not assume one). Each Dubins-space path is checked independently: every state at
1 cm along its curves valid, its curvature within 1 / radius.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from roachplan.experiments import load_experiment, plan, run_experiment
from roachplan.experiments._spec import reference_settings
from roachplan.planning import check_states
from roachplan.planning._drivable import max_curvature
from roachplan.planning._dubins import dubins_path
from roachplan.planning._ompl import _budget_ptc, _se2_state, _seed_ompl, _TerrainSampler
from roachplan.planning._ompl_import import ob, og
from roachplan.processes import call
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
        spun=sum(1 for r in recs if r.get("spins")),
        spins=sum(len(r.get("spins") or ()) for r in recs),
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


class _DubinsMotions(ob.MotionValidator):
    """A motion in the Dubins space is the shortest Dubins curve between its ends: all its
    states every `step` checked in one vectorised call (our curve, the same as OMPL's)."""

    def __init__(self, si, radius: float, check, step: float) -> None:
        super().__init__(si)
        self._radius, self._check, self._step = radius, check, step

    def checkMotion(self, s1, s2, *_last_valid) -> bool:
        a, b = ((s.getX(), s.getY(), s.getYaw()) for s in (s1, s2))
        return bool(self._check(dubins_path(a, b, self._radius).sample(self._step)).all())


def _plan_in_dubins_space(
    hf,
    fp,
    *,
    world_bounds,
    start,
    goal,
    cells,
    cell,
    planner: str,
    radius: float,
    seed: int,
    vcfg,
    time_limit: float,
    max_iterations: int,
    step: float,
    shortcut: bool,
) -> dict:
    """In a child process (OMPL's seed): plan with `planner` in OMPL's DubinsStateSpace with
    the terrain sampler and validity checker the default planner uses."""
    t0 = time.perf_counter()
    _seed_ompl(seed)
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(v, dtype=float) for v in world_bounds)

    def check(st: np.ndarray) -> np.ndarray:
        inside = np.all((st[:, :2] >= lo) & (st[:, :2] <= hi), axis=1)
        return inside & check_states(hf, fp, vcfg, st).valid if inside.all() else inside

    known: dict = {}
    keep: list = []

    def alloc(sp):
        keep.append(
            _TerrainSampler(
                sp, rng=rng, cells=cells, cell=cell, lo=lo, hi=hi, check=check, known=known
            )
        )
        return keep[-1]

    space = ob.DubinsStateSpace(radius, False)  # forward only: the roach does not reverse
    rv = ob.RealVectorBounds(2)
    for k in range(2):
        rv.setLow(k, float(lo[k]))
        rv.setHigh(k, float(hi[k]))
    space.setBounds(rv)
    space.setStateSamplerAllocator(ob.StateSamplerAllocator(alloc))
    si = ob.SpaceInformation(space)

    def is_valid(st) -> bool:
        key = (st.getX(), st.getY(), st.getYaw())
        v = known.get(key)
        return bool(check(np.array([key]))[0]) if v is None else v

    si.setStateValidityChecker(ob.StateValidityCheckerFn(is_valid))
    si.setMotionValidator(_DubinsMotions(si, radius, check, step))
    si.setup()
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(_se2_state(space, start), _se2_state(space, goal))
    pl = getattr(og, planner)(si)
    pl.setProblemDefinition(pdef)
    pl.setup()
    pl.solve(_budget_ptc(max_iterations, t0 + time_limit))
    found = bool(pdef.hasExactSolution())
    if found and shortcut:  # OMPL joins vertices directly where it can (motions checked)
        simplifier = og.PathSimplifier(si)
        path = pdef.getSolutionPath()
        simplifier.reduceVertices(path)
        simplifier.collapseCloseVertices(path)
    out: dict[str, Any] = dict(
        found=found, plan_time=time.perf_counter() - t0, metric=bool(space.isMetricSpace())
    )
    if found:
        poses = [(s.getX(), s.getY(), s.getYaw()) for s in pdef.getSolutionPath().getStates()]
        curves = [dubins_path(a, b, radius) for a, b in zip(poses, poses[1:])]
        dense = np.concatenate([c.sample(step) for c in curves])
        out.update(
            length=sum(c.length for c in curves),
            states=dense,
            all_valid=bool(check_states(hf, fp, vcfg, dense).valid.all()),
        )
    return out


def dubins_space_plan(world, planner: str, radius: float, seed: int, shortcut: bool) -> dict:
    """One plan in OMPL's DubinsStateSpace between the scene's start and goal poses:
    found, plan_time [s], and when found length [m], states ((N, 3) every cm), all_valid."""
    sc, cfg, regions = world.scene, world.scene.planner, world.regions
    from scipy import ndimage

    cells = regions.cell_centres(ndimage.binary_dilation(regions.reachable))
    return call(
        _plan_in_dubins_space,
        (world.heightfield, world.footprint),
        dict(
            world_bounds=sc.bounds,
            start=sc.start,
            goal=sc.goal,
            cells=cells,
            cell=regions.cell,
            planner=planner,
            radius=radius,
            seed=seed,
            vcfg=cfg.validity,
            time_limit=cfg.time_limit,
            max_iterations=cfg.max_iterations,
            step=cfg.check_resolution,
            shortcut=shortcut,
        ),
        start="fork",
        task="planning",
    )


def compare_spaces(seeds: int) -> None:
    """Dubins shortcutting of (x, y, yaw) routes against planning in the Dubins space, on
    double_bridge: successes, median plan time and path length, largest curvature."""
    world = build_world(load_scene("double_bridge"))
    radius = world.scene.planner.turning_radius
    assert radius is not None  # the default planner's: plans are drivable
    print(
        f"\ndrivable plans on double_bridge, {seeds} seeds, radius {radius:g} m "
        f"(curvature limit {1 / radius:.2f} /m)"
    )
    print(
        f"  {'method':<44} {'success':>8} {'time s':>7} {'length m':>9} {'max curv.':>9} "
        f"{'all valid':>9}"
    )
    rows = []
    for name in ("prm", "rrtconnect", "rrt", "kpiece1"):
        cfg = dataclasses.replace(world.scene.planner, name=name)
        res = [plan(world, seed=s, planner=cfg) for s in range(seeds)]
        ok = [r for r in res if r.found]
        # Re-sampled every cm along the waypoints the driver gets, checked independently.
        valid = all(
            check_states(world.heightfield, world.footprint, cfg.validity, r.states).valid.all()
            for r in ok
        )
        rows.append(
            (
                f"(x,y,yaw) {name} + Dubins shortcuts",
                res,
                ok,
                valid,
                [
                    float(np.sum(np.linalg.norm(np.diff(r.states[:, :2], axis=0), axis=1)))
                    for r in ok
                ],
                [max_curvature(r.states) for r in ok],
            )
        )
    for name, shortcut in (("RRT", False), ("RRT", True), ("KPIECE1", False), ("KPIECE1", True)):
        res = [dubins_space_plan(world, name, radius, s, shortcut) for s in range(seeds)]
        ok = [r for r in res if r["found"]]
        assert not any(r["metric"] for r in res), "OMPL calls the Dubins space a metric"
        label = f"DubinsStateSpace {name}" + (" + OMPL shortcuts" if shortcut else "")
        rows.append(
            (
                label,
                [argparse.Namespace(**r) for r in res],
                ok,
                all(r["all_valid"] for r in ok),
                [r["length"] for r in ok],
                [max_curvature(r["states"]) for r in ok],
            )
        )
    for label, res, ok, valid, lengths, curv in rows:
        t = statistics.median(r.plan_time for r in res)
        print(
            f"  {label:<44} {len(ok):>3}/{len(res):<4} {t:>7.3f} "
            f"{statistics.median(lengths) if lengths else float('nan'):>9.2f} "
            f"{max(curv) if curv else float('nan'):>9.2f} {str(valid):>9}",
            flush=True,
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="a fifth of the trials")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--spaces-only",
        action="store_true",
        help="only the planner-space comparison on double_bridge",
    )
    ap.add_argument("--space-seeds", type=int, default=10, help="seeds per planner there")
    args = ap.parse_args()
    if args.spaces_only:
        compare_spaces(args.space_seeds)
        return
    scale = 5 if args.quick else 1
    print(
        f"{'spec':<14} {'setting':<10} {'success':>9} {'rel. energy mean':>17} {'max':>6} "
        f"{'spun':>9} {'wall s':>7}"
    )
    means = {}
    for name, trials in (("kinect_bridge", 25), ("bridge_rough", 50), ("bridge_smooth", 50)):
        spec = load_experiment(name)
        for label, reference in (("reference", True), ("drivable", False)):
            r = run(settings(spec, reference), max(2, trials // scale), args.workers)
            means[name, label] = r["mean"]
            spun = f"{r['spun']}/{r['n']} ({r['spins']})"  # trials with spins (spins in all)
            print(
                f"{name:<14} {label:<10} {r['ok']:>4}/{r['n']:<4} {r['mean']:>17.2f} "
                f"{r['max']:>6.2f} {spun:>9} {r['wall']:>7.1f}",
                flush=True,
            )
    for label in ("reference", "drivable"):
        rough, smooth = means["bridge_rough", label], means["bridge_smooth", label]
        print(
            f"{label}: rough / smooth relative energy = {rough / smooth:.2f} "
            f"({'rough costs more' if rough > smooth else 'rough does NOT cost more'})"
        )

    world = build_world(load_scene("double_bridge"))
    print("\nplanning time on double_bridge, median of 10 seeds [s]")
    for planner in ("prm", "rrtconnect"):
        times = {}
        for label, radius in (("raw", None), ("drivable", world.scene.planner.turning_radius)):
            cfg = dataclasses.replace(world.scene.planner, name=planner, turning_radius=radius)
            times[label] = np.median(
                [plan(world, seed=s, planner=cfg).plan_time for s in range(10)]
            )
        print(
            f"  {planner:<11} raw {times['raw']:.3f}  drivable {times['drivable']:.3f}  "
            f"ratio {times['drivable'] / times['raw']:.2f} (goal <= 2)"
        )
    compare_spaces(args.space_seeds)


if __name__ == "__main__":
    main()
