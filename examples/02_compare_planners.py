"""Compare planners

Plan between the same start and goal with several OMPL planners and seeds, drive every path,
and print success, drive time and relative energy per planner (1.0 = as cheap as walking
straight on a floor).
"""

import statistics

import roachplan


def main() -> None:
    world = roachplan.load("double_bridge")
    for planner in ("prm", "rrtconnect"):
        trials = [roachplan.trial(world, seed=seed, planner=planner) for seed in range(3)]
        ok = [t for t in trials if t.outcome == "success"]
        energy = statistics.mean(t.relative_energy for t in ok) if ok else float("nan")
        routes = ", ".join(sorted({t.route or "-" for t in trials}))
        print(
            f"{planner:12s} {len(ok)}/{len(trials)} succeeded, mean relative energy "
            f"{energy:.2f}, routes: {routes}"
        )


if __name__ == "__main__":
    main()
