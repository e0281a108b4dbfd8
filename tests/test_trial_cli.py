"""`roachplan trial --json` end to end: real OpenSCAD mesh, real OMPL, real PyBullet."""

from __future__ import annotations

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
    for key in ("seed", "planner", "path_found", "outcome", "drive_time", "energy",
                "relative_energy", "path", "trajectory"):  # fmt: skip
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
