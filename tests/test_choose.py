"""Choose by simulation (issue 17): intervals, racing, the safe route over the risky one, the
same seed the same ranking, and --validate, through the real planner and PyBullet."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh
from conftest import roachplan

from roachplan.experiments._choose import Candidate, ChooseConfig, rank, wilson
from roachplan.experiments._uncertainty import UncertaintyConfig, draw, rollout_seed


def test_wilson_intervals_hold_their_coverage():
    rng = np.random.default_rng(3)
    for p in (0.1, 0.5, 0.9):
        hits = sum(
            lo <= p <= hi
            for lo, hi in (wilson(int(rng.binomial(30, p)), 30, 0.9) for _ in range(2000))
        )
        assert hits / 2000 > 0.86  # nominal 0.9; Wilson is close to it at n = 30
    assert wilson(0, 0, 0.95) == (0.0, 1.0)
    lo, hi = wilson(10, 10, 0.95)
    assert hi == pytest.approx(1.0) and 0.6 < lo < 0.8


def test_draws_are_a_pure_function_of_the_seed_and_stay_in_their_ranges():
    cfg = UncertaintyConfig()
    seeds = [rollout_seed(0, c, k) for c in range(3) for k in range(50)]
    assert len(set(seeds)) == len(seeds)
    for s in seeds:
        a, b = draw(cfg, s), draw(cfg, s)
        assert a == b
        assert math.hypot(*a.start_offset[:2]) <= cfg.start_xy + 1e-12
        assert abs(a.start_offset[2]) <= math.radians(cfg.start_yaw) + 1e-12
        assert abs(a.friction_scale - 1) <= cfg.friction and abs(a.mass_scale - 1) <= cfg.body_mass
    off = draw(UncertaintyConfig(friction=0.0), seeds[0])
    assert off.friction_scale == 1.0 and off.start_offset == draw(cfg, seeds[0]).start_offset


def _cand(i: int, outcomes: str, energy: float) -> Candidate:
    c = Candidate(index=i, route="r", seed=i, path_xyz=np.zeros((2, 3)), length=1.0)
    c.rollouts = [{"outcome": "success" if o == "1" else "fell", "relative_energy": energy,
                   "energy": energy, "drive_time": 1.0, "end": [0, 0], "seed": k}
                  for k, o in enumerate(outcomes)]  # fmt: skip
    return c


def test_ranking_never_puts_a_candidate_above_one_wholly_more_likely_to_succeed():
    safe_costly = _cand(0, "1" * 20, 3.0)
    risky_cheap = _cand(1, "1" * 4 + "0" * 16, 1.0)
    ordered = rank([risky_cheap, safe_costly], 0.95, None)
    assert ordered[0] is safe_costly
    # With min_success 0.5 the risky one does not qualify either.
    assert rank([risky_cheap, safe_costly], 0.95, 0.5)[0] is safe_costly
    # Two safe ones: the cheaper first.
    cheap_safe = _cand(2, "1" * 20, 1.5)
    assert rank([safe_costly, cheap_safe], 0.95, None)[0] is cheap_safe


@pytest.fixture(scope="module")
def two_bridges(tmp_path_factory):
    """Start and goal platforms joined by a wide bridge (safe) and a narrow one (risky: 12 cm
    for feet 7 cm apart), over a void."""
    d = tmp_path_factory.mktemp("two_bridges")
    boxes = [((0.9, 1.2, 0.1), (-0.75, 0.0)), ((0.9, 1.2, 0.1), (0.75, 0.0)),
             ((0.62, 0.3, 0.1), (0.0, 0.3)), ((0.62, 0.12, 0.1), (0.0, -0.2))]  # fmt: skip
    parts = []
    for size, (x, y) in boxes:
        b = trimesh.creation.box(size)
        b.apply_translation((x, y, 0.05))
        parts.append(b)
    trimesh.util.concatenate(parts).export(d / "bridges.stl")
    (d / "two_bridges.yaml").write_text(
        "terrain: [{mesh: bridges.stl}]\nground: null\nrobot: {start: [-1.0, 0.0, 0]}\n"
        "goal: [1.0, 0.0, 0]\nbounds: [[-1.15, -0.55], [1.15, 0.55]]\n"
        "routes: {wide: [[-0.3, 0.15], [0.3, 0.45]], narrow: [[-0.3, -0.3], [0.3, -0.1]]}\n"
        "planner: {name: rrtconnect}\n"
    )
    return d / "two_bridges.yaml"


def _choose(scene, *extra):
    proc = roachplan("choose", "--scene", str(scene), "--candidates", "4", "--rollouts", "32",
                     "--workers", "2", "--seed", "1", "--json", *extra, timeout=900)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    return json.loads(proc.stdout)


def test_the_safe_route_wins_and_the_same_seed_gives_the_same_ranking(two_bridges):
    first = _choose(two_bridges)
    routes = {r["route"] for r in first["ranking"]}
    assert routes == {"wide", "narrow"}, "both routes are candidates"
    by_index = {r["candidate"]: r for r in first["ranking"]}
    chosen = by_index[first["chosen"]]
    assert chosen["route"] == "wide", first["ranking"]
    # Nothing ranked above a candidate whose interval lies wholly above its own.
    for i, a in enumerate(first["ranking"]):
        for b in first["ranking"][i + 1 :]:
            assert not a["p_high"] < b["p_low"]
    assert first["rollouts"] <= 32 and first["stopped"]
    again = _choose(two_bridges)
    def key(result):  # every rollout the same: counts and the energies' means
        return [(r["candidate"], r["successes"], r["rollouts"], r["relative_energy"])
                for r in result["ranking"]]  # fmt: skip

    assert key(again) == key(first)


def test_validate_agrees_with_the_prediction_within_its_intervals(two_bridges, tmp_path):
    out = tmp_path / "choice"
    result = _choose(two_bridges, "--validate", "8", "--out", str(out))
    checked = result["validation"]
    assert checked["repeats"] == 8 and 0 <= checked["brier"] <= 1
    inside = [r["inside"] for r in checked["candidates"]]
    assert sum(inside) >= len(inside) - 1, checked["candidates"]
    saved = json.loads((out / "choice.json").read_text())
    assert saved["chosen"] == result["chosen"]
    assert len((out / "rollouts.jsonl").read_text().splitlines()) == result["rollouts"]
    # A folder holding other files is refused, the files left alone.
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    proc = roachplan("choose", "--scene", str(two_bridges), "--out", str(tmp_path / "mine"))
    assert proc.returncode == 2 and "--out" in proc.stderr
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"
