"""One drive on the double bridge: real-time factor and our overhead over raw PyBullet stepping.

    make bench        (or: .venv/bin/python benchmarks/bench_trial.py [--seed N] [--repeat R])

real-time factor = simulated seconds of the drive / wall seconds of the drive loop
overhead         = wall time of the drive loop / wall time of stepping the same world the same
                   number of steps with nothing of ours per step (no controller, no energy
                   meter, no logging). Two baselines:
  - walking:  the legs spin under PyBullet's own velocity motors, set once -- the same contact
              load as a drive, so the ratio is exactly our per-step Python cost;
  - standing: the robot stands still -- cheaper for Bullet itself (fewer contact changes).
Each number is the best of R repeats (one core, no other load assumed).
"""

from __future__ import annotations

import argparse
import time

import pybullet as p

from app._trial import plan
from scenes import build_world, load_scene
from sim import drive_path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    world = build_world(load_scene("double_bridge"))
    planned = plan(world, seed=args.seed)
    dt = world.scene.sim.timestep

    drive_wall, setup_wall = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        with world.simulation() as sim:
            sim.reset(*world.scene.start)
            t1 = time.perf_counter()
            result = drive_path(sim, planned.path_xyz, world.scene.driver)
            drive_wall.append(time.perf_counter() - t1)
        setup_wall.append(t1 - t0)
    steps = round(result.drive_time / dt)

    raw = {}
    for name in ("walking", "standing"):
        best = []
        for _ in range(args.repeat):
            with world.simulation() as sim:
                sim.reset(*world.scene.start)
                cid = sim._bc._client  # raw stepping: the floor we compare to
                if name == "walking":
                    speed = world.scene.driver.omega0 * 0.6  # the Buehler clock's mean leg speed
                    p.setJointMotorControlArray(
                        sim.robot_id, list(range(6)), p.VELOCITY_CONTROL,
                        targetVelocities=[speed] * 6, forces=[world.robot.max_motor_torque] * 6,
                        physicsClientId=cid,
                    )  # fmt: skip
                t0 = time.perf_counter()
                for _ in range(steps):
                    p.stepSimulation(physicsClientId=cid)
                best.append(time.perf_counter() - t0)
        raw[name] = min(best)

    wall = min(drive_wall)
    print(f"drive: {result.outcome}, {result.drive_time:.2f} s simulated, {steps} steps of {dt} s")
    print(f"plan time                      {planned.plan_time:8.3f} s")
    print(f"world setup + settling         {min(setup_wall):8.3f} s")
    print(f"drive loop wall time           {wall:8.3f} s")
    print(f"raw stepping, walking          {raw['walking']:8.3f} s")
    print(f"raw stepping, standing         {raw['standing']:8.3f} s")
    print(f"real-time factor               {result.drive_time / wall:8.1f} x  (target >= 30)")
    print(f"overhead vs walking baseline   {wall / raw['walking']:8.2f} x  (target <= 1.25)")
    print(f"overhead vs standing baseline  {wall / raw['standing']:8.2f} x")
    print(f"whole trial incl. setup, RTF   {result.drive_time / (wall + min(setup_wall)):8.1f} x")


if __name__ == "__main__":
    main()
