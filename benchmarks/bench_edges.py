"""The guard's edge hold and the step in from an edge, in scripted drives in PyBullet on the
double bridge (`double_bridge_rough`), each in a fresh world: what docs/robot.md cites for
`at_edge` (EDGE_OFF, EDGE_ROOM) and `step_in`.

    .venv/bin/python benchmarks/bench_edges.py [--workers 2] [--part holds|steps|both]

holds: a robot walks a straight path along each of the bridges' four edges, the path keeping
2 or 4 cm from it (edge_margin), heading 0-12 deg towards the edge, its motors' mismatch left
after trimming 0.03-0.09 veering it there (friction 0.58, gain 0.92). Each drive is held (1 s of
stopped motors) by one rule: the guard's edge hold (2 cm off the path, its footprint 1 cm
further out not standing), the one it replaced (3.75 cm off, its centre nearer a cell of the
4 cm safety map where it cannot stand), or none; a drift of 12 cm is held under every rule
(the drift hold, about). Prints per rule and path: falls, holds, and of the held those whose
drive with the drift hold only did not fall.

steps: a robot at each of the four edges (its footprint 1 cm further would not stand), heading
5-15 deg towards it, the mismatch 0.03 or 0.09 towards it, re-planned as drive_robot re-plans
(plan_start, plan_clear_of keeping 4 cm, with the scene's arcs) from where it stands (before),
or from step_in's pose with stepped_plan's turn and line first (now); driven 10 s or off the
bridges with the edge hold. Prints falls and holds again per re-plan.

A fall: the body's centre 5 cm past standable ground (the loop's off_standable stop) or 5 cm
below the bridges' top, 1 s after the hold or at the end.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing as mp
import time

import numpy as np

SCENE = "double_bridge_rough"
FRICTION, GAIN = 0.58, 0.92
BRIDGES = (-0.77, 0.77)
"""The bridges' centre lines, x [m]."""
DRIFT_HOLD = 0.12
"""About where the drift hold holds a drifting robot [m] (7.5 cm, and the lead's 0.4 s)."""
_W: dict = {}


def _world():
    if not _W:
        from roachplan.robot import SafetyMap
        from roachplan.scenes import build_world, load_scene

        world = build_world(load_scene(SCENE))
        _W.update(world=world, smap=SafetyMap.from_world(world))
    return _W["world"], _W["smap"]


def _stands(world, states) -> np.ndarray:
    from roachplan.planning import check_states

    hf, fp, cfg = world.heightfield, world.footprint, world.scene.planner.validity
    return check_states(hf, fp, cfg, np.asarray(states, dtype=float)).valid


def _line(world, x: float, y0: float = -0.35, y1: float = 0.45, n: int = 40) -> np.ndarray:
    ys = np.linspace(y0, y1, n)
    xy = np.column_stack([np.full(n, x), ys])
    return np.column_stack([xy, world.heightfield.sample(xy)])


def _path_x(world, centre: float, side: int, keep: float) -> float:
    """x [m] of the straight path along a bridge, nearest its edge on `side` (+1: +x), that
    keeps `keep` [m] from it (edge_margin)."""
    from roachplan.robot import edge_margin

    best = centre
    for x in np.arange(centre, centre + side * 0.27, side * 0.002):
        if edge_margin(world, _line(world, x), 0.08) < keep - 1e-9:
            break
        best = float(x)
    return best


def _edge_x(world, centre: float, side: int, y: float, yaw: float) -> float:
    """x [m] nearest the edge on `side` whose footprint 1 cm further would not stand."""
    for x in np.arange(centre, centre + side * 0.3, side * 0.002):
        if not _stands(world, [[x + side * 0.01, y, yaw]])[0]:
            return float(x)
    raise AssertionError("no edge")


def _drive(world, smap, sim, path, spins, *, hold, t_end: float, y_end: float = 0.45):
    """Drive the (reset) robot along path ((N, 3) [m], spins) until t_end [s], past y_end [m]
    or a hold (hold(pos, yaw, nearest point of the path, distance off it) -> bool); held: 1 s
    of stopped motors. (held at [s] or None, fell)"""
    from roachplan.robot import nearest_on_path
    from roachplan.sim import make_follower, omega_limit

    driver = world.scene.driver
    follower = make_follower(np.asarray(path, dtype=float), driver, spins)
    omega = omega_limit(world.robot.max_motor_speed, driver)
    n = max(1, round(driver.control_period / sim.cfg.timestep))
    path_xy = np.asarray(path, dtype=float)[:, :2]
    held = None
    while sim.time < t_end:
        pos, quat = sim.pose()
        if held is None and pos[1] > y_end:
            break
        qx, qy, qz, qw = quat
        yaw = math.atan2(2 * (qx * qy + qz * qw), 1 - 2 * (qy * qy + qz * qz))
        if held is None:
            near, off = nearest_on_path(pos[:2], path_xy)
            if off > DRIFT_HOLD or hold(pos, yaw, near, off):
                held = sim.time
        if held is not None:
            if sim.time > held + 1.0:
                break
            sim.set_leg_speeds(0.0, 0.0)
        else:
            if follower.update(pos, quat) is not None:
                break
            sim.set_leg_speeds(*follower.speeds(pos, quat, omega))
        sim.advance(n)
    pos, _ = sim.pose()
    top = float(np.max(np.asarray(path)[:, 2])) + world.robot.standing_height
    fell = smap.off_standable(pos[0], pos[1]) > 0.05 or pos[2] < top - 0.05
    return held, bool(fell)


def _rule(world, smap, name: str):
    from roachplan.robot import EDGE_OFF, at_edge

    def now(pos, yaw, near, off) -> bool:
        toward = (pos[0] - near[0], pos[1] - near[1])
        return off > EDGE_OFF and at_edge(world, (pos[0], pos[1], yaw), toward)

    def before(pos, yaw, near, off) -> bool:  # (EDGE_DRIFT 0.5 of the 7.5 cm drift limit)
        return off > 0.0375 and smap.off_standable(pos[0], pos[1]) > 0.0

    return {
        "drift hold only": lambda *_: False,
        "map's edge (before)": before,
        "at_edge (now)": now,
    }[name]


def _sim(world, side: int, resid: float):
    """A fresh world, its motors' mismatch veering the robot towards `side` by `resid`."""
    sim = world.simulation()
    d = -side * resid
    sim.perturb(friction=FRICTION, mass_scale=1.0, motor_gain=(GAIN * (1 + d), GAIN * (1 - d)))
    return sim


def hold_trial(job):
    centre, side, keep, err, resid, rule = job
    world, smap = _world()
    x = _path_x(world, centre, side, keep)
    path = _line(world, x)
    yaw = math.pi / 2 - side * math.radians(err)
    sim = _sim(world, side, resid)
    try:
        sim.reset(x, -0.35, yaw, surface=float(world.heightfield.sample(np.array([x, -0.35]))))
        held, fell = _drive(world, smap, sim, path, (), hold=_rule(world, smap, rule), t_end=8.0)
    finally:
        sim.close()
    return job, held, fell


def step_trial(job):
    centre, side, err, resid, how = job
    from roachplan.robot import plan_clear_of, plan_start, step_in, stepped_plan

    world, smap = _world()
    cfg = dataclasses.replace(world.scene.planner, time_limit=3.0)
    planning = world.with_planner(cfg)
    yaw = math.pi / 2 - side * math.radians(err)
    x = _edge_x(world, centre, side, -0.1, yaw)
    here, _ = plan_start(world, (x, -0.1, yaw))
    inner = step_in(world, here, 0.04) if how == "step_in (now)" else None
    plan, _ = plan_clear_of(planning, inner or here, 7, keep=0.04, deadline=time.monotonic() + 3)
    if not plan.found:
        return job, "no plan", False
    if inner is not None:
        plan = stepped_plan(world, plan, (x, -0.1, yaw))
    sim = _sim(world, side, resid)
    try:
        sim.reset(x, -0.1, yaw, surface=float(world.heightfield.sample(np.array([x, -0.1]))))
        rule = _rule(world, smap, "at_edge (now)")
        held, fell = _drive(world, smap, sim, plan.path_xyz, plan.spins, hold=rule, t_end=10.0)
    finally:
        sim.close()
    return job, held, fell


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--part", choices=("holds", "steps", "both"), default="both")
    args = ap.parse_args()
    edges = [(c, s) for c in BRIDGES for s in (1, -1)]
    with mp.Pool(args.workers) as pool:
        if args.part in ("holds", "both"):
            rules = ("drift hold only", "map's edge (before)", "at_edge (now)")
            jobs = [
                (c, s, keep, err, resid, rule)
                for c, s in edges
                for keep in (0.04, 0.02)
                for err in (0, 4, 8, 12)
                for resid in (0.03, 0.06, 0.09)
                for rule in rules
            ]
            t = time.monotonic()
            out = pool.map(hold_trial, jobs)
            unheld = {j[:5]: fell for j, _, fell in out if j[5] == "drift hold only"}
            print(f"holds: {len(jobs)} drives in {time.monotonic() - t:.0f} s")
            print(
                "| rule | path keeps | fell | held | held, of those the drift hold only would not fall |"
            )
            print("|---|---|---|---|---|")
            for rule in rules:
                for keep in (0.04, 0.02):
                    o = [(j, h, f) for j, h, f in out if j[5] == rule and j[2] == keep]
                    held = [j for j, h, _ in o if h is not None]
                    spared = sum(not unheld[j[:5]] for j in held)
                    fell = sum(f for *_, f in o)
                    print(f"| {rule} | {keep * 100:.0f} cm | {fell}/{len(o)} | {len(held)} | "
                          f"{spared} |")  # fmt: skip
        if args.part in ("steps", "both"):
            hows = ("from where it stands (before)", "step_in (now)")
            jobs = [
                (c, s, err, resid, how)
                for c, s in edges
                for err in (5, 10, 15)
                for resid in (0.03, 0.09)
                for how in hows
            ]
            t = time.monotonic()
            out = pool.map(step_trial, jobs)
            print(f"\nsteps: {len(jobs)} drives in {time.monotonic() - t:.0f} s")
            print("| re-plan | fell | held again | held and fell | no plan |")
            print("|---|---|---|---|---|")
            for how in hows:
                o = [(h, f) for j, h, f in out if j[4] == how]
                none = sum(h == "no plan" for h, _ in o)
                again = [f for h, f in o if h is not None and h != "no plan"]
                print(f"| {how} | {sum(f for _, f in o)}/{len(o)} | {len(again)} | {sum(again)} | "
                      f"{none} |")  # fmt: skip


if __name__ == "__main__":
    main()
