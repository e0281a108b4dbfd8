"""One drive on the double bridge: real-time factor and our overhead over raw PyBullet stepping.

    make bench        (or: .venv/bin/python benchmarks/bench_trial.py [--seed N])

overhead = wall time of the drive / wall time of stepping the same world the same number of
steps with no controller, no energy meter and no logging.
"""

from __future__ import annotations

import argparse
import time

from app._trial import drive, plan
from scenes import build_world, load_scene
from sim import Simulation


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    world = build_world(load_scene("double_bridge"))
    planned = plan(world, seed=args.seed)
    t0 = time.perf_counter()
    result = drive(world, planned.path_xyz)
    drive_wall = time.perf_counter() - t0
    dt = world.scene.sim.timestep
    steps = round(result.drive_time / dt)

    with Simulation(
        world.mesh.vertices, world.mesh.faces, ground_height=world.scene.ground,
        robot=world.robot, cfg=world.scene.sim,
    ) as sim:  # fmt: skip
        sim.reset(*world.scene.start)
        step = sim._bc.stepSimulation  # raw stepping, no controller: the floor we compare to
        t0 = time.perf_counter()
        for _ in range(steps):
            step()
        raw_wall = time.perf_counter() - t0

    print(f"drive: {result.outcome}, {result.drive_time:.2f} s simulated, {steps} steps of {dt} s")
    print(f"plan time                 {planned.plan_time:8.3f} s")
    print(f"drive wall time           {drive_wall:8.3f} s (incl. world setup and settling)")
    print(f"raw stepping wall time    {raw_wall:8.3f} s")
    print(f"real-time factor          {result.drive_time / drive_wall:8.1f} x  (target >= 30)")
    print(f"overhead vs raw stepping  {drive_wall / raw_wall:8.2f} x  (target <= 1.25)")


if __name__ == "__main__":
    main()
