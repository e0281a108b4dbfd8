"""Where trials run: a pool of local worker processes, or Ray actors on a cluster.

Each worker builds the experiment's world (mesh, height field, standable map) once, and drives
every trial, re-drive and rollout in a fresh PyBullet world (0.02-0.1 s to build, against
seconds of driving): a reused client, reset, drove 5 of 8 kinect_bridge seeds differently
after a flip than a fresh one (what the solver keeps between steps is not all in its
saveState). Every plan runs in a clean child process seeded with the trial's seed
(planning/_isolated.py), so a trial's result does not depend on which worker ran it or what it
ran before.

Both backends take calls (method name, arguments) and yield each result as soon as it is ready.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterable, Iterator

import numpy as np

from roachplan.planning import PlanResult
from roachplan.processes import Pool
from roachplan.scenes import build_world
from roachplan.sim import drive_path

from ._spec import ExperimentSpec
from ._store import REDRIVE, TRIAL
from ._trial import drive, finish_trial, plan, reference_energy
from ._uncertainty import draw, terrain_noise

Call = tuple[str, tuple] | tuple[str, tuple, dict]
"""(TrialWorker method name, its arguments[, its keyword arguments])."""


class TrialWorker:
    """One process's world and PyBullet client; runs calls of the experiment."""

    def __init__(self, spec: ExperimentSpec) -> None:
        self.spec = spec
        self.world = build_world(spec.scene_with_settings())
        self.world.regions  # noqa: B018 - the standable map, computed once per worker

    def plan_route(self, seed: int) -> dict:
        """Plan with `seed` only, to learn which route its path takes (and keep the plan)."""
        planned = plan(self.world, seed=seed)
        route = self.world.route(planned.path_xyz[:, :2]) if planned.found else None
        return {"seed": seed, "route": route, "plan": planned}

    def trial(
        self,
        index: int,
        seed: int,
        target_route: str,
        planned: PlanResult | None,
        *,
        start: tuple[float, float, float] | None = None,
        goal: tuple[float, float, float] | None = None,
    ) -> dict:
        """Trial `index`: drive the plan of `seed` (planned now unless given: the census's
        plan of that seed is the same plan) from start to goal (default: the scene's); a store
        record."""
        start, goal = start or self.world.start, goal or self.world.goal
        if planned is None:
            planned = plan(self.world, seed=seed, start=start, goal=goal)
        result = finish_trial(self.world, planned, start=start, goal=goal)  # a fresh world
        return {"kind": TRIAL, "index": index, "target_route": target_route, **result.to_json()}

    def redrive(self, index: int, of_trial: int, path: list, start: list, spins=()) -> dict:
        """Repeat `index` of the best path: drive the stored path (and its turns on the spot)
        from a jittered start."""
        x, y, yaw = start
        driven = drive(self.world, np.asarray(path), start=(x, y, yaw), spins=spins)  # fresh
        return {
            "kind": REDRIVE,
            "index": index,
            "of_trial": of_trial,
            "start": list(start),
            "outcome": driven.outcome,
            "reason": driven.reason,
            "drive_time": driven.drive_time,
            "energy": driven.energy,
            "relative_energy": driven.energy
            / reference_energy(self.world, (x, y, yaw), self.world.goal),
            "trajectory": [list(p) for p in driven.trajectory],
        }

    def rollout(self, candidate: int, path: list, seed: int, uncertainty, spins=()) -> dict:
        """One of `choose`'s rollouts: drive candidate `candidate`'s path (and its turns on the
        spot, `spins`) in the world drawn from `uncertainty` with `seed`
        (experiments/_uncertainty.py); a rollout record."""
        t0 = time.perf_counter()
        with self._rollout_world(seed, uncertainty) as (sim, start, w, sigma):
            driven = drive_path(sim, np.asarray(path), self.world.scene.driver, spins=spins)
        return self._rollout_record(candidate, seed, (start, w, sigma), driven, t0)

    def rollouts(self, calls: list[tuple], uncertainty) -> list[dict]:
        """Several of `choose`'s rollouts, each call (candidate, path, seed, spins) as
        rollout's: with the MuJoCo engine stepped together in lockstep (sim/_lockstep.py:
        the same records, bit for bit, as one at a time), else one after the other."""
        if self.world.scene.sim.engine != "mujoco" or len(calls) < 2:
            return [self.rollout(c, p, seed, uncertainty, spins) for c, p, seed, spins in calls]
        from roachplan.sim import drive_lockstep

        t0 = time.perf_counter()
        with contextlib.ExitStack() as stack:
            made = [stack.enter_context(self._rollout_world(c[2], uncertainty)) for c in calls]
            driven = drive_lockstep(
                [sim for sim, *_ in made],
                [np.asarray(c[1]) for c in calls],
                self.world.scene.driver,
                [c[3] for c in calls],
            )
        now = time.perf_counter()
        share = now - (now - t0) / len(calls)  # (each its share of the wall time)
        return [
            self._rollout_record(c[0], c[2], tuple(drawn), d, share)
            for c, (_, *drawn), d in zip(calls, made, driven, strict=True)
        ]

    @contextlib.contextmanager
    def _rollout_world(self, seed: int, uncertainty):
        """The world of rollout `seed`: (a fresh simulation, reset at the drawn start and
        perturbed by the drawn friction, mass and motors; the start (x, y, yaw); the draw;
        the terrain's height error [m]), the simulation closed on leaving."""
        scene = self.world.scene
        w = draw(uncertainty, seed)
        x, y, yaw = (float(a + b) for a, b in zip(self.world.start, w.start_offset, strict=True))
        # A fresh world per rollout: after changed masses and friction a reused PyBullet one
        # drove the same seed differently depending on what it had driven before (measured:
        # 8 of 28 rollouts), and a rollout must re-run exactly from its seed alone.
        captured = any(obj.kind == "capture" for obj in scene.terrain)
        sigma = uncertainty.terrain_height if captured else 0.0
        if sigma > 0:  # a capture's surface, moved by the sensor's error (_uncertainty.py)
            vertices = np.array(self.world.sim_terrain.vertices, dtype=np.float64)
            vertices[:, 2] += terrain_noise(uncertainty, seed, len(vertices))
            world_sim = self.world.simulation(vertices=vertices)
        else:
            world_sim = self.world.simulation()
        with world_sim as sim:
            sim.perturb(
                friction=scene.sim.friction * w.friction_scale,
                mass_scale=w.mass_scale,
                motor_gain=w.motor_gain,
            )
            sim.reset(x, y, yaw, surface=float(self.world.heightfield.sample(np.array([x, y]))))
            yield sim, (x, y, yaw), w, sigma

    def _rollout_record(self, candidate: int, seed: int, drawn: tuple, driven, t0: float) -> dict:
        """A rollout record of the drive `driven` in the world drawn ((start, draw, terrain
        height error), as _rollout_world gives them), begun at t0 (time.perf_counter() [s])."""
        start, w, sigma = drawn
        return {
            "candidate": candidate,
            "seed": seed,
            "world": {**w.to_json(), "terrain_height": sigma},
            "outcome": driven.outcome,
            "reason": driven.reason,
            "drive_time": driven.drive_time,
            "energy": driven.energy,
            "relative_energy": driven.energy / reference_energy(self.world, start, self.world.goal),
            "end": list(driven.trajectory[-1][1:3]),
            "wall_time": time.perf_counter() - t0,  # (in this worker: world built, driven) [s]
        }

    def close(self) -> None:
        """Nothing held between calls (each drive's PyBullet world is closed with it)."""


# -- local processes ----------------------------------------------------------------------------


def _call_local(worker: TrialWorker, call: Call):
    name, args, kwargs = _unpack(call)
    return getattr(worker, name)(*args, **kwargs)


def _unpack(call: Call) -> tuple[str, tuple, dict]:
    name, args, *kwargs = call
    return name, args, kwargs[0] if kwargs else {}


class LocalPool:
    """`workers` processes on this machine (roachplan.processes.Pool): spawned, each builds the
    experiment's world once (TrialWorker) and runs calls under the child memory limit (a
    runaway trial ends in MemoryError, a clear failed run, not by taking the machine), ignoring
    Ctrl-C (the main process's to handle) and dying with the process that made the pool (a
    SIGKILLed experiment leaves no orphans running trials whose results nobody will store).
    """

    def __init__(self, spec: ExperimentSpec, workers: int) -> None:
        self.workers = workers
        self._pool = Pool(workers, TrialWorker, (spec,), handle=_call_local, task="trial worker")

    def run(self, calls: Iterable[Call]) -> Iterator:
        """Each call's result as it finishes (in any order). At most 2 calls per worker are
        queued, so an interrupted run leaves little in flight."""
        return self._pool.run(calls)

    def close(self) -> None:
        self._pool.close()

    def terminate(self) -> None:
        """Stop at once: the workers are killed (the calls in flight are lost). Safe from
        another thread than the one iterating `run`, which then ends with WorkerDied (a
        BrokenProcessPool)."""
        self._pool.terminate()


# -- Ray --------------------------------------------------------------------------------------


class RayPool:
    """One TrialWorker actor per worker slot of a Ray cluster (a local one when address is
    None). Every node must have roachplan installed and the scene's files at the same path."""

    def __init__(self, spec: ExperimentSpec, workers: int | None, address: str | None) -> None:
        if address is None and "ray" not in sys.modules:
            # A local instance on loopback, not on this machine's network address (Ray's
            # single-machine mode; it must be set before Ray is imported).
            os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
        import ray
        from ray.util import ActorPool

        self._ray = ray
        self._owns_ray = not ray.is_initialized()
        if self._owns_ray:
            ray.init(
                address=address,
                num_cpus=workers if address is None else None,
                include_dashboard=False,
                log_to_driver=False,
                # Ray annotates it int, but its own default is a name ("info"), as here.
                logging_level="WARNING",  # pyright: ignore[reportArgumentType]
            )
        n = workers or int(ray.cluster_resources().get("CPU", 1))
        actor = ray.remote(num_cpus=1)(TrialWorker)
        self._actors = [actor.remote(spec) for _ in range(n)]
        self._pool = ActorPool(self._actors)
        self.workers = n

    def run(self, calls: Iterable[Call]) -> Iterator:
        def submit(actor, call: Call):
            name, args, kwargs = _unpack(call)
            return getattr(actor, name).remote(*args, **kwargs)

        yield from self._pool.map_unordered(submit, list(calls))

    def close(self) -> None:
        for a in self._actors:
            # Ray types remote() as ActorHandle | the class (its ActorProxy); it is a handle.
            self._ray.kill(a)  # pyright: ignore[reportArgumentType]
        if self._owns_ray:
            self._ray.shutdown()
