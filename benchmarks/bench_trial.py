"""One drive on the double bridge: real-time factor and our overhead over raw PyBullet stepping.

    make bench        (or: .venv/bin/python benchmarks/bench_trial.py [--seed N] [--repeat R])

real-time factor = simulated seconds of the drive / wall seconds of the drive loop
overhead         = wall time of the drive loop / wall time of stepping the same world the same
                   number of steps with nothing of ours per step (no controller, no energy
                   meter, no logging). Two baselines:
  - replay: the leg torques of the drive, recorded beforehand, applied open loop -- the same
            motion and contacts step for step, so the ratio is exactly our per-step cost;
  - bare:   stepSimulation alone, the robot left lying with its motors off.
Each number is the best of R repeats (one core, no other load assumed).
"""

from __future__ import annotations

import argparse
import math
import time

import pybullet as p

from roachplan.experiments import plan
from roachplan.scenes import build_world, load_scene
from roachplan.sim import PyBulletSimulation, drive_path


def record_torques(world, path_xyz) -> list[list[float]]:
    """The leg torques a drive applies at each step, for the replay baseline."""
    recorded = []
    original = p.setJointMotorControlArray

    def recording(*args, forces, **kw):
        recorded.append(forces)
        return original(*args, forces=forces, **kw)

    p.setJointMotorControlArray = recording
    try:
        with world.simulation() as sim:
            sim.reset(*world.scene.start)
            del recorded[:]  # settling
            drive_path(sim, path_xyz, world.scene.driver)
    finally:
        p.setJointMotorControlArray = original
    return recorded


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    world = build_world(load_scene("double_bridge"))
    start = world.scene.start
    assert start is not None  # given by the scene, or picked by build_world
    planned = plan(world, seed=args.seed)
    dt = world.scene.sim.timestep

    drive_wall, setup_wall = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        with world.simulation() as sim:
            sim.reset(*start)
            t1 = time.perf_counter()
            result = drive_path(sim, planned.path_xyz, world.scene.driver)
            drive_wall.append(time.perf_counter() - t1)
        setup_wall.append(t1 - t0)
    steps = round(result.drive_time / dt)

    recorded = record_torques(world, planned.path_xyz)
    assert len(recorded) == steps, (len(recorded), steps)

    raw = {}
    for name in ("replay", "bare"):
        best = []
        for _ in range(args.repeat):
            with world.simulation() as sim:
                # (PyBullet's own stepping, the engine this benchmark measures the loop against)
                assert isinstance(sim, PyBulletSimulation), "bench_trial measures PyBullet"
                sim.reset(*start)
                cid, rid, joints = sim._bc._client, sim.robot_id, list(range(6))
                t0 = time.perf_counter()
                if name == "replay":
                    for forces in recorded:
                        p.setJointMotorControlArray(
                            rid, joints, p.TORQUE_CONTROL, forces=forces, physicsClientId=cid
                        )
                        p.stepSimulation(physicsClientId=cid)
                else:
                    for _ in range(steps):
                        p.stepSimulation(physicsClientId=cid)
                best.append(time.perf_counter() - t0)
                if name == "replay":
                    (x, y, _), _ = sim.pose()
                    replay_end = (x, y)
        raw[name] = min(best)
    wall = min(drive_wall)
    print(f"drive: {result.outcome}, {result.drive_time:.2f} s simulated, {steps} steps of {dt} s")
    print(f"plan time                      {planned.plan_time:8.3f} s")
    print(f"world setup + settling         {min(setup_wall):8.3f} s")
    print(f"drive loop wall time           {wall:8.3f} s")
    print(
        f"replayed torques, open loop    {raw['replay']:8.3f} s  "
        f"(ends {math.dist(replay_end, result.trajectory[-1][1:3]) * 1000:.1f} mm from the drive)"
    )
    print(f"bare stepSimulation            {raw['bare']:8.3f} s")
    print(f"real-time factor               {result.drive_time / wall:8.1f} x  (target >= 30)")
    print(f"overhead vs replay baseline    {wall / raw['replay']:8.2f} x  (target <= 1.25)")
    print(f"overhead vs bare stepping      {wall / raw['bare']:8.2f} x")
    print(f"whole trial incl. setup, RTF   {result.drive_time / (wall + min(setup_wall)):8.1f} x")


if __name__ == "__main__":
    main()
