"""PyBullet and MuJoCo side by side, in one run: what the same roach does under each engine,
and how fast each steps it. Prints numbers and ratios (MuJoCo / PyBullet); a busy machine shows
in the wall times (each the best of --repeat runs; the load average is printed), less in the
CPU times printed beside them.

    .venv/bin/python benchmarks/bench_engines.py [--quick] [--repeat 3] [--seed 3]

Open floor: a 10 s walk at 20 rad/s on both sides, and a turn with the right side at 1.5 times
the left (as the turning calibration walks them: the path summed every 20 ms), under PyBullet
at 1 ms and MuJoCo at 1 ms and 2 ms: distance, mean speed, curvature, energy per metre and wall
time per simulated second. Then one path the planner gives on the double bridge, driven by the
tracking driver under each: outcome, time and energy. Last, choose's rollouts per second on 2
workers (double_bridge, double_bridge_rough, kinect_bridge: its seed-0 plan in worlds drawn from
its uncertainty): PyBullet, MuJoCo one at a time and MuJoCo in lockstep (sim/_lockstep.py).
And the ceiling: the same scenes' rollouts in one process, PyBullet beside MuJoCo in lockstep
with MuJoCo's physics timed apart: how fast MuJoCo would be if its Python took no time.
--quick: 3 s walks, one repeat, 4 rollouts of double_bridge.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import time
from typing import Literal

from roachplan.sim import DriveResult, RobotConfig, SimConfig, drive_path, open_floor

Engine = Literal["pybullet", "mujoco"]
ENGINES: tuple[tuple[Engine, float], ...] = (
    ("pybullet", 0.001),
    ("mujoco", 0.001),
    ("mujoco", 0.002),
)
"""(engine, timestep [s]) compared; the first is the reference of every ratio."""
WALKS = (("straight", 1.0), ("turn 1.5", 1.5))
"""(name, right / left motor speed) of the floor walks, the left side at OMEGA."""
OMEGA = 20.0
"""The slow side's motor speed [rad/s] (the driver's omega0)."""


def _yaw(quat_xyzw) -> float:
    x, y, z, w = quat_xyzw
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def floor_walk(cfg: SimConfig, ratio: float, seconds: float) -> dict[str, float]:
    """A walk on the open floor at (OMEGA, ratio OMEGA): distance summed every 20 ms [m], mean
    speed [m/s], curvature 2 pi turns / distance [1/m], energy per metre [J/m], and the wall and
    CPU time of its stepping per simulated second [s/s]."""
    with open_floor(RobotConfig(), cfg) as sim:
        sim.reset(0.0, 0.0, 0.0)
        sim.set_leg_speeds(OMEGA, OMEGA * ratio)
        steps = max(1, round(0.02 / cfg.timestep))
        (x, y, _), quat = sim.pose()
        yaw, distance, turned = _yaw(quat), 0.0, 0.0
        wall = cpu = 0.0
        for _ in range(round(seconds / (steps * cfg.timestep))):
            t0, c0 = time.perf_counter(), time.process_time()
            sim.advance(steps)
            wall += time.perf_counter() - t0
            cpu += time.process_time() - c0
            (nx, ny, _), quat = sim.pose()
            new_yaw = _yaw(quat)
            distance += math.hypot(nx - x, ny - y)
            turned += (new_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
            x, y, yaw = nx, ny, new_yaw
        return {
            "distance": distance,
            "speed": distance / sim.time,
            "curvature": turned / distance,
            "energy_per_m": sim.energy / distance,
            "wall_per_s": wall / sim.time,
            "cpu_per_s": cpu / sim.time,
        }


def bridge_drive(world, planned, cfg: SimConfig) -> tuple[DriveResult, float, float]:
    """(DriveResult, wall time of the drive [s], its CPU time [s]) of the planned path on world
    under cfg."""
    x, y, yaw = world.start
    with world.simulation(cfg=cfg) as sim:
        sim.reset(x, y, yaw, surface=float(world.heightfield.sample([x, y])))
        t0, c0 = time.perf_counter(), time.process_time()
        result = drive_path(sim, planned.path_xyz, world.scene.driver, spins=planned.spins)
        return result, time.perf_counter() - t0, time.process_time() - c0


def _label(engine: str, dt: float) -> str:
    return f"{engine} {dt * 1000:g} ms"


def walks(seconds: float, repeat: int) -> None:
    """The floor walks' table (module docstring)."""
    print(f"\nopen floor, {seconds:g} s walks, left motor at {OMEGA:g} rad/s")
    units = ("[m]", "[m/s]", "[1/m]", "[J/m]", "[s/s]", "[s/s]")
    names = ("distance", "speed", "curv", "E/m", "wall/s", "cpu/s")
    print(f"{'walk':9s} {'engine':14s}" + "".join(f"{n:>9s}" for n in names))
    print(f"{'':24s}" + "".join(f"{u:>9s}" for u in units))
    ratios = []
    for name, ratio in WALKS:
        rows = []
        for engine, dt in ENGINES:
            cfg = SimConfig(engine=engine, timestep=dt)
            runs = [floor_walk(cfg, ratio, seconds) for _ in range(repeat)]
            row = dict(runs[0])  # (the physics is the same every run: deterministic)
            row["wall_per_s"] = min(r["wall_per_s"] for r in runs)
            row["cpu_per_s"] = min(r["cpu_per_s"] for r in runs)
            rows.append(row)
            keys = ("distance", "speed", "curvature", "energy_per_m", "wall_per_s", "cpu_per_s")
            print(f"{name:9s} {_label(engine, dt):14s}" + "".join(f"{row[k]:9.4f}" for k in keys))
        ref = rows[0]
        for (engine, dt), row in list(zip(ENGINES, rows, strict=True))[1:]:
            ratios.append(
                f"{name:9s} {_label(engine, dt):14s}"
                f"{row['distance'] / ref['distance']:9.3f}"
                f"{row['energy_per_m'] / ref['energy_per_m']:9.3f}"
                f"{row['curvature'] - ref['curvature']:+9.2f}"
                f"{ref['wall_per_s'] / row['wall_per_s']:8.2f}x"
                f"{ref['cpu_per_s'] / row['cpu_per_s']:8.2f}x"
            )
    print(f"\nratios to {_label(*ENGINES[0])} (curvature: the difference [1/m]; speed-up: its")
    print("time / this one's)")
    heads = ("distance", "E/m", "curv", "wall up", "cpu up")
    print(f"{'walk':9s} {'engine':14s}" + "".join(f"{h:>9s}" for h in heads))
    print("\n".join(ratios))


def bridge(seed: int, repeat: int) -> None:
    """The double bridge's drive under each engine (module docstring)."""
    from roachplan.experiments import plan
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene("double_bridge"))
    planned = plan(world, seed=seed)
    assert planned.found, planned.message
    route = world.route(planned.path_xyz[:, :2])
    print(f"\ndouble_bridge, the plan of seed {seed} ({route}), tracking driver")
    heads = ("outcome", "time [s]", "energy [J]", "wall [s]", "cpu [s]", "wall up", "cpu up")
    print(f"{'engine':14s}" + "".join(f"{h:>11s}" for h in heads))
    ref = None
    for engine, dt in ENGINES:
        cfg = dataclasses.replace(world.scene.sim, engine=engine, timestep=dt)
        runs = [bridge_drive(world, planned, cfg) for _ in range(repeat)]
        result = runs[0][0]
        wall, cpu = min(r[1] for r in runs), min(r[2] for r in runs)
        ref = (wall, cpu) if ref is None else ref
        print(
            f"{_label(engine, dt):14s}{result.outcome:>11s}{result.drive_time:11.2f}"
            f"{result.energy:11.3f}{wall:11.2f}{cpu:11.2f}"
            f"{ref[0] / wall:10.2f}x{ref[1] / cpu:10.2f}x"
        )


ROLLOUT_SCENES = ("double_bridge", "double_bridge_rough", "kinect_bridge")


def rollouts_per_second(scene: str, n: int, workers: int) -> None:
    """Choose's rollouts of one scene on `workers` cores: n rollouts of its seed-0 plan, each
    in its own world drawn from the scene's uncertainty, under PyBullet one at a time, MuJoCo
    one at a time, and MuJoCo in lockstep (the rounds choose deals: one batch per worker).
    Rollouts per second of wall time, the same calls in each, side by side."""
    from roachplan.experiments import ExperimentSpec, plan
    from roachplan.experiments._runner import _make_pool
    from roachplan.scenes import build_world, load_scene, with_engine

    base = load_scene(scene)
    world = build_world(base)
    planned = plan(world, seed=0)
    path = planned.path_xyz.tolist()
    calls = [(0, path, seed, planned.spins) for seed in range(1000, 1000 + n)]
    rows = {}
    for label, engine, lockstep in (
        ("pybullet", "pybullet", False),
        ("mujoco", "mujoco", False),
        ("mujoco lockstep", "mujoco", True),
    ):
        scene_e = with_engine(base, engine)
        spec = ExperimentSpec.of_scene(scene_e, name="bench")
        pool = _make_pool(spec, workers, "local", None)
        try:
            list(pool.run([("plan_route", (0,))] * workers))  # (the workers up, worlds built)
            t = time.perf_counter()
            if lockstep:
                dealt = [calls[k::workers] for k in range(workers)]
                batches = [("rollouts", (part, scene_e.uncertainty)) for part in dealt]
                recs = [r for records in pool.run(batches) for r in records]
            else:
                recs = list(
                    pool.run(
                        ("rollout", (c, p, sd, scene_e.uncertainty), {"spins": sp})
                        for c, p, sd, sp in calls
                    )
                )
            wall = time.perf_counter() - t
        finally:
            pool.close()
        ok = sum(r["outcome"] == "success" for r in recs)
        simulated = sum(r["drive_time"] for r in recs)
        rows[label] = (n / wall, simulated / wall, ok)
    ref, ref_sim = rows["pybullet"][:2]
    for label, (rate, sim_rate, ok) in rows.items():
        # (a failed rollout ends early: simulated seconds per second compare the engines'
        # speed where their outcomes differ)
        print(
            f"{scene:20s} {label:16s} {rate:7.2f} rollouts/s  {rate / ref:5.2f}x  "
            f"{sim_rate:6.1f} simulated s/s  {sim_rate / ref_sim:5.2f}x  successes {ok}/{n}"
        )


def ceiling(scene: str, n: int, repeat: int = 2) -> None:
    """How far MuJoCo's rollouts could go on one core: n rollouts of the scene's seed-0 plan
    (choose's worlds), PyBullet one at a time and MuJoCo in lockstep, interleaved `repeat`
    times in this process (no pool: its workers share caches), with the time inside MuJoCo's
    batch calls (its physics) timed apart. Per simulated second, so rollouts that end early
    weigh as they simulate: PyBullet's time, MuJoCo's, MuJoCo's physics, the speed-up now, and
    the speed-up if nothing but MuJoCo's physics took time (the most the Python could give)."""
    from mujoco.batch import Batch

    from roachplan.experiments import ExperimentSpec, plan
    from roachplan.experiments._workers import TrialWorker
    from roachplan.scenes import load_scene, with_engine

    inside = [0.0]
    stepping = Batch.rollout

    def timed(self, *args, **kwargs):  # (MuJoCo's batch call, its time counted)
        t = time.perf_counter()
        try:
            return stepping(self, *args, **kwargs)
        finally:
            inside[0] += time.perf_counter() - t

    scenes = {e: with_engine(load_scene(scene), e) for e in ("pybullet", "mujoco")}
    workers = {
        e: TrialWorker(ExperimentSpec.of_scene(sc, name="bench")) for e, sc in scenes.items()
    }
    planned = plan(workers["pybullet"].world, seed=0)
    calls = [(0, planned.path_xyz.tolist(), seed, planned.spins) for seed in range(1000, 1000 + n)]
    pb_u, mj_u = scenes["pybullet"].uncertainty, scenes["mujoco"].uncertainty
    workers["mujoco"].rollouts(calls[:2], mj_u)  # (worlds and caches made before the clock)
    wall = {"pybullet": 0.0, "mujoco": 0.0}
    simulated = dict.fromkeys(wall, 0.0)
    physics = 0.0
    Batch.rollout = timed
    try:
        for _ in range(repeat):
            t = time.perf_counter()
            recs = [workers["pybullet"].rollout(c, p, sd, pb_u, sp) for c, p, sd, sp in calls]
            wall["pybullet"] += time.perf_counter() - t
            simulated["pybullet"] += sum(r["drive_time"] for r in recs)
            inside[0] = 0.0
            t = time.perf_counter()
            recs = workers["mujoco"].rollouts(calls, mj_u)
            wall["mujoco"] += time.perf_counter() - t
            simulated["mujoco"] += sum(r["drive_time"] for r in recs)
            physics += inside[0]
    finally:
        Batch.rollout = stepping
        for w in workers.values():
            w.close()
    pb = wall["pybullet"] / simulated["pybullet"]
    mj, ph = wall["mujoco"] / simulated["mujoco"], physics / simulated["mujoco"]
    times = f"{pb * 1e3:9.1f} {mj * 1e3:9.1f} {ph * 1e3:9.1f}"  # [ms per simulated s]
    print(f"{scene:20s} {times} {pb / mj:8.2f}x {pb / ph:8.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 s walks, one repeat")
    ap.add_argument("--repeat", type=int, default=3, help="runs per time (the best)")
    ap.add_argument("--seed", type=int, default=3, help="the double bridge plan's seed")
    args = ap.parse_args()
    seconds, repeat = (3.0, 1) if args.quick else (10.0, args.repeat)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; best of {repeat}")
    walks(seconds, repeat)
    bridge(args.seed, repeat)
    n = 4 if args.quick else 16
    print(f"\nchoose's rollouts, {n} per scene on 2 workers (rollouts/s; ratio to PyBullet's)")
    for scene in ROLLOUT_SCENES[:1] if args.quick else ROLLOUT_SCENES:
        rollouts_per_second(scene, n, workers=2)
    k = 4 if args.quick else 8
    print(f"\nthe ceiling on one core: {k} rollouts, PyBullet and MuJoCo in lockstep interleaved")
    print("(ms of wall time per simulated second; 'ceiling': PyBullet's / MuJoCo's physics alone)")
    print(
        f"{'scene':20s} {'pybullet':>9s} {'mujoco':>9s} {'physics':>9s} {'now':>9s} {'ceiling':>9s}"
    )
    for scene in ROLLOUT_SCENES[:1] if args.quick else ROLLOUT_SCENES:
        ceiling(scene, k)


if __name__ == "__main__":
    main()
