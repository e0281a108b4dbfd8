"""Rollouts in lockstep (issue 31, item 3): a worker's MuJoCo drives advanced together, one
batched MuJoCo call per control period (its n physics steps) for all of them, each stopped at
its outcome.

Each rollout is a MujocoSimulation the caller made, reset and perturbed as for a drive of its
own (its terrain, friction, masses and motor gains are its own: its model), and a Drive (the
driver's controller and bookkeeping, sim/_driver.py). Every control period each rollout still
running reads its pose and says its motor speeds; then `mujoco.batch.Batch` steps them all
(one call per control period, on its own threads with the GIL released), its state rows the
simulations' own, so that a rollout gives bit for bit what it gives driven alone (drive_path):
a rollout re-runs exactly from its seed, whoever ran it with what.

What it saves against driving them one after the other is Python's share of each step: the
servo inputs of all rollouts are computed at once, the energy metered at once, one call made.
"""

# pyright: reportAttributeAccessIssue=false
# (mujoco's names come from its compiled modules, which pyright cannot read: sim/_mujoco.py)

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from mujoco.batch import Batch

from ._config import DriverConfig
from ._driver import Drive, DriveResult
from ._engine import Simulation
from ._errors import SimError
from ._mujoco import MujocoSimulation

_STATE = mujoco.mjtState.mjSTATE_INTEGRATION.value
_CTRL = mujoco.mjtState.mjSTATE_CTRL.value
_DIVERGED = (
    mujoco.mjtWarning.mjWARN_BADQPOS.value,
    mujoco.mjtWarning.mjWARN_BADQVEL.value,
    mujoco.mjtWarning.mjWARN_BADQACC.value,
)


def drive_lockstep(
    engines: Sequence[Simulation],
    paths: Sequence[np.ndarray],
    cfg: DriverConfig,
    spins: Sequence = (),
    *,
    threads: int = 1,
) -> list[DriveResult]:
    """Drive engines[i] (MujocoSimulations, already reset and perturbed) along paths[i] ((N, 3) world frame [m])
    with its turns on the spot spins[i] (default none), all in lockstep; one DriveResult each,
    as drive_path gives it. threads: MuJoCo's threads for the batch (1: a worker of a pool
    already uses its core)."""
    sims = [s for s in engines if isinstance(s, MujocoSimulation)]
    if len(sims) != len(engines):
        raise SimError("rollouts in lockstep are MuJoCo's: give MujocoSimulations")
    if not sims:
        return []
    timestep = sims[0].cfg.timestep
    if any(s.cfg.timestep != timestep for s in sims):
        raise SimError("rollouts in lockstep share one timestep")
    if any(s.robot != sims[0].robot for s in sims):
        raise SimError("rollouts in lockstep share one robot description")
    spins = list(spins) or [()] * len(sims)
    drives = [
        Drive(path, cfg, spin, robot=sim.robot)
        for sim, path, spin in zip(sims, paths, spins, strict=True)
    ]
    n = max(1, round(cfg.control_period / timestep))
    batch = Batch(sims[0].model, nsim=len(sims), nthread=threads)
    batch.set_models([s.model for s in sims])
    results: list[DriveResult | None] = [None] * len(sims)
    running = list(range(len(sims)))
    while running:
        stepping = []
        for i in running:
            sim, drive = sims[i], drives[i]
            pos, quat = sim.pose()
            speeds = drive.control(sim.time, pos, quat)
            if speeds is None:
                results[i] = drive.result(sim.time, pos, sim.energy_per_leg)
                continue
            sim.set_leg_speeds(*speeds)
            stepping.append(i)
        running = stepping
        if not running:
            break
        ids = np.array(running)
        every = None if len(running) == len(sims) else ids  # (None: all, no ids to check)
        inputs = MujocoSimulation.servo_inputs_together([sims[i] for i in running], n)
        for i in running:  # (the batch's state rows: the simulations' own)
            mujoco.mj_getState(sims[i].model, sims[i].data, batch.state[i], _STATE)
        before = batch.warning[ids][:, _DIVERGED, 0].sum(axis=1)
        # The period's n steps in one call: each step's servo inputs set before it, the
        # sensors of its forward pass recorded after it (what ctrl and sensordata read round
        # n calls of batch.step gave, bit for bit, without n calls' Python).
        readings = batch.rollout(
            n,
            control=inputs.transpose(1, 0, 2),
            control_spec=_CTRL,
            record=("sensordata",),
            ids=every,
        )["sensordata"]
        diverged = batch.warning[ids][:, _DIVERGED, 0].sum(axis=1) != before
        energy = MujocoSimulation.metered(readings, timestep)  # (k, 6) [J]
        for j, i in enumerate(running):
            mujoco.mj_setState(sims[i].model, sims[i].data, batch.state[i], _STATE)
            sims[i].advanced(n, readings[j], diverged=bool(diverged[j]), energy=energy[j])
    return [r for r in results if r is not None]
