"""`roachplan trial --json` end to end: real OpenSCAD mesh, real OMPL, real PyBullet."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from conftest import roachplan

GAP_HALF_WIDTH = 0.5  # table C.1: bridges 1.0 m apart, centred on x = 0
BRIDGE_HALF_LENGTH = 0.5


def run_trial(seed: int, *extra: str) -> dict:
    out = roachplan("trial", "--scene", "double_bridge", "--seed", str(seed), "--json", *extra)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def densify(path: np.ndarray, step: float = 0.005) -> np.ndarray:
    pts = [path[0]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        pts.extend(a + (b - a) * k / n for k in range(1, n + 1))
    return np.array(pts)


@pytest.fixture(scope="module")
def trial_seed3() -> dict:
    return run_trial(3)


def test_trial_json_has_the_documented_fields(trial_seed3):
    d = trial_seed3
    for key in (
        "seed",
        "planner",
        "path_found",
        "outcome",
        "drive_time",
        "energy",
        "relative_energy",
        "path",
        "trajectory",
    ):
        assert key in d, key
    assert d["seed"] == 3 and d["planner"] == "prm"
    assert d["outcome"] in ("success", "fell", "flipped", "stuck", "timeout", "no_path")
    assert d["path_found"] is True
    path = np.array(d["path"])
    traj = np.array(d["trajectory"])
    assert path.shape[1] == 3 and traj.shape[1] == 4
    np.testing.assert_allclose(path[0, :2], [0.0, -1.6], atol=1e-9)
    np.testing.assert_allclose(path[-1, :2], [0.0, 1.6], atol=1e-9)
    assert np.all(np.diff(traj[:, 0]) > 0), "trajectory time must increase"
    assert d["drive_time"] == pytest.approx(traj[-1, 0], abs=0.05)
    assert d["energy"] > 0
    # Up ramps and over a bridge costs more than the straight floor walk of the same distance.
    assert 1.0 < d["relative_energy"] < 5.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_planned_path_never_crosses_the_gap(seed):
    d = run_trial(seed)
    assert d["path_found"]
    xy = densify(np.array(d["path"])[:, :2])
    in_gap = (np.abs(xy[:, 0]) < GAP_HALF_WIDTH) & (np.abs(xy[:, 1]) < BRIDGE_HALF_LENGTH)
    assert not in_gap.any(), f"path enters the gap at {xy[in_gap][:3]}"
    on_bridges = np.abs(xy[:, 1]) < BRIDGE_HALF_LENGTH
    # The robot's centre keeps its feet (3.5 cm to each side) over the bridge.
    assert np.all(np.abs(xy[on_bridges, 0]) >= GAP_HALF_WIDTH + 0.03)
    assert np.all(np.abs(xy[on_bridges, 0]) <= 1.0)
    # z is the terrain surface: 0.2 m on the bridges.
    z = np.array(d["path"])[:, 2]
    bridge_z = z[np.abs(np.array(d["path"])[:, 1]) < BRIDGE_HALF_LENGTH - 0.05]
    np.testing.assert_allclose(bridge_z, 0.2, atol=1e-3)


def test_same_seed_gives_the_same_trial(trial_seed3):
    again = run_trial(3)
    for timing in ("plan_time", "drive_wall_time"):
        trial_seed3.pop(timing, None)
        again.pop(timing)
    assert again == trial_seed3


def test_another_seed_gives_another_path(trial_seed3):
    other = run_trial(4)
    assert other["path"] != trial_seed3["path"]


def test_unknown_scene_is_a_clear_error():
    out = roachplan("trial", "--scene", "no_such_scene", "--seed", "1")
    assert out.returncode == 2
    assert "unknown scene 'no_such_scene'" in out.stderr and "double_bridge" in out.stderr
    assert "Traceback" not in out.stderr


# --reference and `reference: true` (issue 18): the report's raw paths and algorithms 1-2, and
# every JSON output says which planner space, smoothing and driver it used.


def test_reference_flag_gives_the_reports_raw_path_and_driver(trial_seed3, world):
    from roachplan.experiments import plan
    from roachplan.planning import PlannerConfig

    ref = run_trial(3, "--reference")
    assert (ref["driver"], ref["planner_space"], ref["smoothing"]) == ("reference", "se2", "none")
    assert ref["turning_radius"] is None
    d = trial_seed3  # the same seed without the flag: drivable plans and the tracking driver
    assert (d["driver"], d["planner_space"], d["smoothing"]) == (
        "tracking",
        "se2",
        "dubins_shortcuts",
    )
    assert d["turning_radius"] == PlannerConfig().turning_radius
    # The raw path is the planner's own, as the library plans it with turning_radius None;
    # the default one is another (arcs), from the same seed.
    raw = plan(world, seed=3, planner=dataclasses.replace(world.scene.planner, turning_radius=None))
    np.testing.assert_allclose(np.array(ref["path"]), raw.path_xyz, atol=1e-9)
    drivable = np.array(d["path"])
    assert drivable.shape != raw.path_xyz.shape or not np.allclose(drivable, raw.path_xyz)


def test_plan_json_names_the_space_and_the_smoothing():
    def plan_json(*extra: str) -> dict:
        out = roachplan("plan", "--scene", "double_bridge", "--seed", "2", "--json", *extra)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout)

    from roachplan.planning._drivable import max_curvature

    ref, default = plan_json("--reference"), plan_json()
    assert (ref["planner_space"], ref["smoothing"], ref["turning_radius"]) == ("se2", "none", None)
    assert (default["planner_space"], default["smoothing"]) == ("se2", "dubins_shortcuts")
    radius = default["turning_radius"]
    assert radius > 0 and max_curvature(np.array(default["states"])) <= 1.05 / radius
    # The raw path's corners (its waypoints every 5 cm) are sharper than any arc of that radius.
    assert max_curvature(np.array(ref["path"])) > 2 / radius


def _spec(tmp_path, reference: bool):
    path = tmp_path / f"spec_{reference}.yaml"
    path.write_text(
        "scene: double_bridge\n"
        f"reference: {str(reference).lower()}\n"
        "planner: {name: prm}\n"
        "routes: [left_bridge, right_bridge]\n"
        "trials_per_route: 1\n"
        "best_path: {repeats: 0}\n"
    )
    return path


@pytest.mark.slow
def test_a_spec_with_reference_true_runs_and_records_the_reports_setting(tmp_path):
    from roachplan.experiments import load_experiment

    default = load_experiment(_spec(tmp_path, False))
    assert default.driver.kind == "tracking" and default.planner.turning_radius is not None
    spec = load_experiment(_spec(tmp_path, True))
    assert spec.driver.kind == "reference" and spec.planner.turning_radius is None
    # Everything else of the driver is the scene's, the report's gain included.
    assert dataclasses.replace(spec.driver, kind="tracking") == default.driver
    out = tmp_path / "results"
    run = roachplan(
        "experiment",
        str(_spec(tmp_path, True)),
        "--trials",
        "2",
        "--workers",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert run.returncode == 0, run.stderr
    records = [json.loads(line) for line in (out / "trials.jsonl").read_text().splitlines()]
    trials = [r for r in records if r["kind"] == "trial"]
    assert len(trials) == 2
    for r in trials:
        assert (r["driver"], r["planner_space"], r["smoothing"], r["turning_radius"]) == (
            "reference",
            "se2",
            "none",
            None,
        )
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["spec"]["driver"]["kind"] == "reference"
    assert manifest["spec"]["planner"]["turning_radius"] is None


def test_a_spec_reference_that_is_not_a_boolean_is_a_clear_error(tmp_path):
    path = tmp_path / "bad.yaml"
    good = _spec(tmp_path, True).read_text()
    path.write_text(good.replace("reference: true", "reference: yes please"))
    out = roachplan("experiment", str(path), "--trials", "1", "--out", str(tmp_path / "r"))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "reference" in out.stderr and "expected true or false" in out.stderr
