"""The physics seam (issue 31): one engine setting that reaches every simulation, from a scene
file, the command line and the API, each engine as it was calibrated; PyBullet the default."""

from __future__ import annotations

import json

import pytest

import roachplan
from conftest import roachplan as cli
from roachplan.scenes import SceneError, build_world, load_scene, with_engine
from roachplan.sim import (
    CALIBRATED_TIMESTEP,
    CALIBRATED_TURNING,
    MUJOCO_TURNING,
    MujocoSimulation,
    PyBulletSimulation,
    SimConfig,
)

FLAT = (
    "terrain: []\nground: 0.0\nrobot: {start: [0.0, 0.0, 0]}\ngoal: [0.6, 0.0, 0]\n"
    "bounds: [[-0.4, -0.4], [1.0, 0.4]]\nplanner: {name: rrtconnect}\n"
)


def test_pybullet_is_the_default_and_a_scene_file_names_the_other_as_calibrated(tmp_path):
    assert SimConfig().engine == "pybullet" and load_scene("double_bridge").sim.engine == "pybullet"
    (tmp_path / "mj.yaml").write_text(FLAT + "sim: {engine: mujoco}\n")
    scene = load_scene(str(tmp_path / "mj.yaml"))
    assert scene.sim.engine == "mujoco"
    assert scene.sim.timestep == CALIBRATED_TIMESTEP["mujoco"] != SimConfig().timestep
    assert scene.driver.turning == MUJOCO_TURNING != CALIBRATED_TURNING
    # What the file sets itself stays.
    (tmp_path / "mj1.yaml").write_text(FLAT + "sim: {engine: mujoco, timestep: 0.001}\n")
    assert load_scene(str(tmp_path / "mj1.yaml")).sim.timestep == 0.001
    (tmp_path / "bad.yaml").write_text(FLAT + "sim: {engine: bullet3}\n")
    with pytest.raises(SceneError, match=r"sim\.engine.*one of pybullet, mujoco"):
        load_scene(str(tmp_path / "bad.yaml"))


def test_the_world_builds_the_engine_its_scene_names_and_both_drive_a_plan(tmp_path):
    (tmp_path / "flat.yaml").write_text(FLAT)
    base = load_scene(str(tmp_path / "flat.yaml"))
    outcomes = {}
    for engine, cls in (("pybullet", PyBulletSimulation), ("mujoco", MujocoSimulation)):
        world = build_world(with_engine(base, engine))
        with world.simulation() as sim:
            assert isinstance(sim, cls) and sim.cfg.timestep == CALIBRATED_TIMESTEP[engine]
        trial = roachplan.trial(world, seed=1)
        outcomes[engine] = (trial.outcome, trial.energy)
    assert all(o == "success" for o, _ in outcomes.values()), outcomes
    assert outcomes["pybullet"][1] != outcomes["mujoco"][1]  # (two engines, not one twice)


def test_engine_on_the_command_line_and_a_refused_one_names_the_choices():
    ran = cli("trial", "--scene", "double_bridge", "--engine", "mujoco", "--seed", "3", "--json")
    assert ran.returncode == 0, ran.stderr
    assert json.loads(ran.stdout)["outcome"] in ("success", "fell", "flipped", "stuck", "missed")
    refused = cli("trial", "--scene", "double_bridge", "--engine", "ode")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "--engine" in refused.stderr and "mujoco" in refused.stderr


def test_rollouts_in_lockstep_are_the_rollouts_driven_one_at_a_time(tmp_path):
    """A worker's MuJoCo rollouts stepped together give, bit for bit, the records each gives
    alone (outcome, time, energy, where it ended), each world drawn from its own seed."""
    from roachplan.experiments import ExperimentSpec
    from roachplan.experiments._workers import TrialWorker

    (tmp_path / "flat.yaml").write_text(FLAT + "sim: {engine: mujoco}\n")
    scene = load_scene(str(tmp_path / "flat.yaml"))
    worker = TrialWorker(ExperimentSpec.of_scene(scene, name="lockstep"))
    path = [[0.0, 0.0, 0.0], [0.3, 0.05, 0.0], [0.6, 0.0, 0.0]]
    calls = [(k % 2, path, seed, ()) for k, seed in enumerate((11, 12, 13))]
    together = worker.rollouts(calls, scene.uncertainty)
    alone = [worker.rollout(c, p, seed, scene.uncertainty, s) for c, p, seed, s in calls]
    strip = [{k: v for k, v in r.items() if k != "wall_time"} for r in (*together, *alone)]
    assert strip[:3] == strip[3:]
    assert len({r["energy"] for r in together}) == 3  # (three worlds, not one thrice)


def test_a_choice_is_cross_checked_under_the_other_engine(tmp_path):
    """choose --cross-check: every rollout driven again under the other engine, the same paths
    in the same drawn worlds; per path both tallies, and a sentence on whether they agree."""
    (tmp_path / "flat.yaml").write_text(FLAT)
    world = roachplan.load(str(tmp_path / "flat.yaml"), engine="mujoco")
    choice = roachplan.choose(
        world, candidates=2, rollouts=8, budget_s=None, workers=2, seed=2, cross_check=True
    )
    x = choice.cross_check
    assert x is not None and (x["engine"], x["other"]) == ("mujoco", "pybullet")
    driven = {
        c.index: len(c.rollouts) + len(choice.fresh.get(c.index, [])) for c in choice.candidates
    }
    for row in x["candidates"]:
        assert row["mujoco"]["rollouts"] == row["pybullet"]["rollouts"] == driven[row["candidate"]]
        assert row["mujoco"]["successes"] <= row["mujoco"]["rollouts"]
    # On a flat floor both engines walk every path: they agree, and the sentence says so.
    assert x["agree"] and x["sentence"].startswith("mujoco and pybullet agree")


def test_the_page_says_a_cross_check_with_its_path_numbers():
    """The page numbers paths from 1 (candidate k is path k + 1), in the cross-check too."""
    from roachplan.app._choose_panel import RaceView, _pathed, follow_race
    from roachplan.experiments import CrossChecked

    said = _pathed(
        "model uncertainty: mujoco chose candidate 0, pybullet favours candidate 2; the "
        "engines' success rates differ beyond their 95% intervals on candidates 1, 3"
    )
    assert "chose path 1, pybullet favours path 3" in said and said.endswith("on paths 2, 4")
    view = follow_race(RaceView(message=""), CrossChecked(result={"sentence": "x"}))
    assert view.checked == {"sentence": "x"}


def test_an_experiment_spec_names_the_engine_as_calibrated(tmp_path):
    """An experiment spec's `sim: {engine: mujoco}` over a PyBullet scene: MuJoCo's timestep
    and turning curve, as a scene file's gives them; the spec's own keys read over those."""
    from roachplan.experiments import load_experiment

    (tmp_path / "flat.yaml").write_text(FLAT)
    (tmp_path / "spec.yaml").write_text("scene: flat.yaml\nsim: {engine: mujoco}\n")
    spec = load_experiment(str(tmp_path / "spec.yaml"))
    assert spec.sim.engine == "mujoco" and spec.sim.timestep == CALIBRATED_TIMESTEP["mujoco"]
    assert spec.driver.turning == MUJOCO_TURNING
    (tmp_path / "own.yaml").write_text("scene: flat.yaml\nsim: {engine: mujoco, timestep: 0.001}\n")
    assert load_experiment(str(tmp_path / "own.yaml")).sim.timestep == 0.001


def test_an_experiment_is_cross_checked_per_route_under_the_other_engine(tmp_path):
    """experiment --cross-check: every trial's stored path driven again under the other
    engine from its start; per route both tallies, in cross_check.json and the table. Driving
    a trial's path again under its own engine is the trial, bit for bit (what makes the other
    engine's drive the same trial)."""
    from roachplan.experiments import ExperimentSpec, load_experiment
    from roachplan.experiments._workers import TrialWorker

    (tmp_path / "flat.yaml").write_text(FLAT)
    (tmp_path / "spec.yaml").write_text("scene: flat.yaml\n")
    out = tmp_path / "out"
    report = roachplan.experiment(
        tmp_path / "spec.yaml", trials=3, out=out, workers=2, cross_check=True
    )
    x = report.cross_check
    assert x is not None and (x["engine"], x["other"]) == ("pybullet", "mujoco")
    trials = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    trials = [t for t in trials if t["kind"] == "trial" and t["path_found"]]
    assert x["trials"] == len(trials) == sum(r["pybullet"]["rollouts"] for r in x["routes"])
    assert sum(r["mujoco"]["rollouts"] for r in x["routes"]) == len(trials)
    assert json.loads((out / "cross_check.json").read_text()) == json.loads(json.dumps(x))
    assert report.table.splitlines()[-len(x["routes"]) - 1].startswith("cross-check: ")
    # A flat floor: both engines walk every path, at energies of their own.
    assert x["agree"] and x["same_outcome"] == len(trials), x["sentence"]
    for row in x["routes"]:
        assert row["pybullet"]["relative_energy"] != row["mujoco"]["relative_energy"]
    spec = load_experiment(str(tmp_path / "spec.yaml"))
    assert isinstance(spec, ExperimentSpec)
    t = trials[0]
    again = TrialWorker(spec).redrive(0, t["index"], t["path"], t["start"], t.get("spins", []))
    assert (again["outcome"], again["energy"]) == (t["outcome"], t["energy"])
