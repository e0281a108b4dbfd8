"""Choose by simulation (issue 17): intervals, racing, the safe route over the risky one, the
same seed the same ranking, and --validate, through the real planner and PyBullet."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import re

import numpy as np
import pytest
import trimesh

from conftest import roachplan
from roachplan.experiments import (
    CandidatesPlanned,
    ChooseConfig,
    Decided,
    KnockedOut,
    RoundDone,
)
from roachplan.experiments._choose_candidate import Candidate, Knockout
from roachplan.experiments._choose_policy import eliminate, rank, to_sample, within_zone
from roachplan.experiments._choose_race import race, world_seed
from roachplan.experiments._choose_stats import clopper_pearson
from roachplan.experiments._uncertainty import UncertaintyConfig, draw, rollout_seed


def test_clopper_pearson_intervals_hold_their_coverage():
    rng = np.random.default_rng(3)
    for p in (0.1, 0.5, 0.9, 0.98):
        hits = sum(
            lo <= p <= hi
            for lo, hi in (clopper_pearson(int(rng.binomial(30, p)), 30, 0.9) for _ in range(2000))
        )
        assert hits / 2000 > 0.885  # at least the nominal 0.9 (exact), less sampling noise
    assert clopper_pearson(0, 0, 0.95) == (0.0, 1.0)
    lo, hi = clopper_pearson(10, 10, 0.95)
    assert hi == 1.0 and lo == pytest.approx(0.025 ** (1 / 10))
    lo, hi = clopper_pearson(0, 10, 0.95)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / 10))


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
    c.rollouts = [
        {
            "outcome": "success" if o == "1" else "fell",
            "relative_energy": energy,
            "energy": energy,
            "drive_time": 1.0,
            "end": [0, 0],
            "seed": k,
        }
        for k, o in enumerate(outcomes)
    ]
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


def _drawn(i: int, n: int, p: float, energy: float, sd: float, *, seed: int = 0) -> Candidate:
    """A candidate with n rollouts drawn (seeded) from P(success) p and relative energy
    N(energy, sd^2) over the successes, rollout k in the race's world k."""
    c = Candidate(index=i, route="r", seed=i, path_xyz=np.zeros((2, 3)), length=1.0)
    c.rollouts = [_rollout(i, world_seed(seed, k), p, energy, sd) for k in range(n)]
    return c


def _rollout(i: int, seed: int, p: float, energy: float, sd: float) -> dict:
    """Candidate i in world `seed`: nothing shared with another candidate in the same world
    (no help from pairing here)."""
    rng = np.random.default_rng([seed, i])
    ok = rng.random() < p
    e = float(rng.normal(energy, sd))
    return {
        "candidate": i,
        "seed": seed,
        "outcome": "success" if ok else "fell",
        "relative_energy": e,
        "energy": e,
        "drive_time": 1.0,
        "end": [0, 0],
    }


def _race(truths, on_event=None, **cfg):
    """Race hand-made candidates whose rollouts come from truths[i] = (p, energy, sd): the
    race's own logic on seeded draws, no simulation."""
    racers = [
        Candidate(index=i, route="r", seed=i, path_xyz=np.zeros((2, 3)), length=1.0)
        for i in range(len(truths))
    ]

    def run(calls):
        return [_rollout(i, seed, *truths[i]) for i, _path, seed in calls]

    return race(
        racers,
        ChooseConfig(candidates=len(truths), budget_s=None, **{"procedure": "race", **cfg}),
        run,
        mass=1.0,
        on_event=on_event,
    )


def test_practically_equal_candidates_stop_within_the_indifference_zone():
    conf = 1 - 0.05 / 2
    # 200/200 and 199/200 with energies 1 % apart: not separable, but equal within (0.05, 5 %).
    a, b = _drawn(0, 200, 1.0, 1.84, 0.08), _drawn(1, 200, 0.995, 1.86, 0.08)
    assert a.p_interval(conf)[2] >= b.p_interval(conf)[1], "the intervals overlap"
    best = within_zone([a, b], conf, None, (0.05, 0.05))
    assert best is rank([a, b], conf, None)[0]
    assert within_zone([a, b], conf, None, (0.0, 0.0)) is None
    # Too few rollouts to bound P(success) within 0.05: no decision yet.
    assert (
        within_zone(
            [_drawn(0, 40, 1.0, 1.84, 0.08), _drawn(1, 40, 1.0, 1.86, 0.08)],
            conf,
            None,
            (0.05, 0.05),
        )
        is None
    )
    # A rival that may be more than 5 % cheaper (energy 10 % lower) is no decision either.
    cheap = _drawn(1, 200, 1.0, 1.66, 0.08)
    assert within_zone([a, cheap], conf, None, (0.05, 0.05)) in (None, cheap)

    # The race: stops in the zone, well before the cap, and says so.
    truths = [(1.0, 1.84, 0.08), (0.995, 1.86, 0.08)]
    zoned = _race(truths, rollouts=800, max_per_candidate=400, seed=3)
    assert zoned.stopped == "within the indifference zone (P 0.05, energy 5%) at 95% confidence"
    assert zoned.rollouts < 800 and zoned.chosen in (0, 1)
    # With the zone off the same two never separate: the race runs to its cap.
    plain = _race(truths, rollouts=800, max_per_candidate=400, seed=3, indifference=(0.0, 0.0))
    assert "indifference" not in plain.stopped and "separated" not in plain.stopped
    assert plain.rollouts == 800


def test_rollouts_go_where_they_can_settle_the_decision():
    conf, cfg = 1 - 0.05 / 3, ChooseConfig(candidates=3, batch=4)
    # Two that never failed and a risky one: c* (the cheaper safe one) is within DP of the
    # other only once its own lower bound rises; driving the other, whose upper bound stays 1,
    # settles nothing. The risky one's wide upper bound is its own to narrow.
    leader = _drawn(0, 40, 1.0, 1.60, 0.05)
    rival = _drawn(1, 40, 1.0, 2.40, 0.05, seed=1)
    assert [c.index for c in to_sample([leader, rival], conf, cfg)] == [0]
    risky = _drawn(2, 4, 1.0, 1.0, 0.05, seed=2)  # 2 in 4: it might yet be as safe
    risky.rollouts = risky.rollouts[:2] + [{**r, "outcome": "fell"} for r in risky.rollouts[2:]]
    assert {c.index for c in to_sample([leader, rival, risky], conf, cfg)} >= {0, 2}
    # A newcomer first gets its first round; with the zone off every candidate is driven.
    fresh = _drawn(2, 0, 1.0, 1.0, 0.05)
    assert [c.index for c in to_sample([leader, rival, fresh], conf, cfg)] == [2]
    off = ChooseConfig(candidates=2, batch=4, indifference=(0.0, 0.0), procedure="race")
    assert len(to_sample([leader, rival], conf, off)) == 2

    # A race spends its rollouts where they decide: it stops in the zone, the first-ranked
    # driven most; the costly and the risky ones, beaten early, several times less.
    truths = [(1.0, 1.6, 0.05), (1.0, 2.4, 0.05), (0.995, 1.61, 0.05), (0.6, 1.2, 0.05)]
    choice = _race(truths, max_per_candidate=400, seed=4)
    assert choice.stopped.startswith("within the indifference zone"), choice.stopped
    n = {c.index: c.n for c in choice.candidates}
    assert choice.chosen in (0, 2) and n[choice.chosen] == max(n.values()), n
    assert max(n[1], n[3]) * 3 <= n[choice.chosen], n


@pytest.mark.parametrize(
    "truths",
    [
        # Three rivals 6 % costlier (just outside DE) and as safe.
        [(1.0, 1.80, 0.25), (1.0, 1.908, 0.25), (1.0, 1.908, 0.25), (1.0, 1.908, 0.25)],
        # Three rivals 17 % cheaper that fail 6 % of the time (just outside DP).
        [(1.0, 1.80, 0.25), (0.94, 1.5, 0.25), (0.94, 1.5, 0.25), (0.94, 1.5, 0.25)],
    ],
    ids=["energy-edge", "safety-edge"],
)
@pytest.mark.slow
def test_a_race_chooses_wrongly_no_more_often_than_its_confidence_allows(truths):
    # Candidate 0 is the only right choice; the others lie just outside the zone (0.05, 5 %),
    # where a decision at 95 % confidence may be wrong at most 5 % of the time. Measured: 4
    # and 3 wrong in 200 races (before energy eliminations needed a known-safe rival, 124 in
    # 200 picked a risky cheap path). The bound below leaves room for the sampling noise of
    # 100 races (at a true 5 %, more than 10 wrong happens 1 time in 90).
    wrong = sum(_race(truths, max_per_candidate=1000, seed=r).chosen != 0 for r in range(100))
    assert wrong <= 10, wrong


def test_a_race_cut_short_says_at_what_confidence_its_choice_stands():
    truths = [(1.0, 1.6, 0.05), (1.0, 2.4, 0.05), (0.995, 1.61, 0.05)]
    short = _race(truths, rollouts=120, max_per_candidate=400, seed=2)
    assert short.stopped.startswith("rollout cap of 120 reached"), short.stopped
    reached = short.confidence_reached
    assert reached is not None and 0.5 <= reached < 0.95, short.stopped
    assert f"at {reached:.0%} confidence (not 95%)" in short.stopped
    alive = [c for c in short.candidates if not c.out]
    at = within_zone(alive, 1 - (1 - reached) / 3, None, (0.05, 0.05))
    assert at is not None and at.index == short.chosen  # it holds there ...
    assert (
        within_zone(alive, 1 - (1 - reached - 0.01) / 3, None, (0.05, 0.05)) is not at
    )  # not above
    assert _race(truths, max_per_candidate=400, seed=2).confidence_reached is None  # decided


def test_with_min_success_the_one_that_may_qualify_is_driven_too():
    # The cheap path fails 15 % of the time and can never clear 0.9; the costly one never
    # fails. The race must drive the costly one, not spend every rollout on the cheap one.
    choice = _race(
        [(0.85, 1.2, 0.05), (1.0, 2.0, 0.05)], min_success=0.9, max_per_candidate=60, seed=1
    )
    n = {c.index: c.n for c in choice.candidates}
    assert choice.chosen == 1 and n[1] >= 40, (choice.stopped, n)


def test_a_clearly_worse_candidate_is_eliminated_and_the_better_is_chosen():
    conf = 1 - 0.05 / 3
    good = _drawn(0, 200, 1.0, 1.8, 0.05)
    risky = _drawn(1, 40, 0.5, 1.0, 0.05, seed=1)
    costly = _drawn(2, 200, 1.0, 2.6, 0.05, seed=2)
    alive = [good, risky, costly]
    eliminate(alive, conf, None, 0.05)
    assert not good.out
    assert risky.out.startswith("less likely to succeed"), risky.out
    assert costly.out.startswith("costs more energy than candidate 0"), costly.out
    # Energy knocks a candidate out only for one known to be as safe (within DP): a cheap
    # path that has not failed in its first 24 rollouts may still fail 6 times in 100.
    lucky = _drawn(3, 24, 1.0, 1.2, 0.05, seed=3)
    safe = _drawn(4, 200, 1.0, 1.8, 0.05, seed=4)
    eliminate([lucky, safe], conf, None, 0.05)
    assert not safe.out and not lucky.out
    # One that left the race, however good its few rollouts look, ranks below those in it.
    early = _drawn(3, 8, 1.0, 1.7, 0.05, seed=3)
    early.knocked_out = Knockout(reason="costs_more", by=0, own_bound=1.75, rival_bound=1.72)
    assert early.out == "costs more energy than candidate 0 (intervals apart)"
    ordered = rank([early, _drawn(0, 200, 0.99, 1.8, 0.05)], 1 - 0.05 / 2, None)
    assert ordered[0].index == 0
    # The race drops both and stops separated with the good one.
    choice = _race([(1.0, 1.8, 0.05), (0.5, 1.0, 0.05), (1.0, 2.6, 0.05)], rollouts=600, seed=5)
    assert choice.chosen == 0 and choice.stopped == "separated at 95% confidence"
    assert {c.index for c in choice.candidates if c.out} == {1, 2}


def _check_events(events: list, choice) -> dict[int, str | None]:
    """Assert that a race's events came in order (CandidatesPlanned first if at all, then
    each round's KnockedOut before its RoundDone, one Decided last), that each candidate's
    fate is told once, as values the round's standings agree with, and that the Decided
    agrees with the Choice returned. Returns each candidate's fate: its OutReason, or None
    (still racing when the race stopped)."""
    kinds = "".join(
        {CandidatesPlanned: "P", KnockedOut: "K", RoundDone: "R", Decided: "D"}[type(e)]
        for e in events
    )
    assert re.fullmatch(r"P?(K*R)*D", kinds), kinds
    rounds = [e for e in events if isinstance(e, RoundDone)]
    assert [r.round for r in rounds] == list(range(1, len(rounds) + 1))
    assert all(a.rollouts < b.rollouts for a, b in itertools.pairwise(rounds))
    k = len(choice.candidates)
    fate: dict[int, str | None] = dict.fromkeys(range(k))
    told: list[KnockedOut] = []
    for e in events:
        if isinstance(e, KnockedOut):
            assert fate[e.candidate] is None, f"candidate {e.candidate} left the race twice"
            fate[e.candidate] = e.why.reason
            told.append(e)
        elif isinstance(e, RoundDone):
            assert [s.candidate for s in e.standings] == list(range(k))  # index order
            assert all(s.knocked_out is None for s in e.standings if fate[s.candidate] is None)
            assert all(told_.round == e.round for told_ in told)  # (its own round's)
            for t in told:
                s, why = e.standings[t.candidate], t.why
                assert s.state == "out" and s.knocked_out == why
                if why.reason == "less_likely":  # its P interval wholly below the leader's
                    assert why.by is not None
                    assert why.own_bound == s.p_high < why.rival_bound
                    assert why.rival_bound == e.standings[why.by].p_low
                elif why.reason == "costs_more":  # its energy interval wholly above a rival's
                    assert why.by is not None
                    assert why.own_bound == s.relative_energy_low > why.rival_bound
                    assert why.rival_bound == e.standings[why.by].relative_energy_high
                    assert e.standings[why.by].state == "racing"
                else:
                    assert why.by is None and why.own_bound == s.p_high < why.rival_bound
            told = []
    decided = events[-1]
    assert decided.rollouts == (rounds[-1].rollouts if rounds else 0) == choice.rollouts
    assert decided.rounds == len(rounds)
    assert decided.chosen == choice.chosen and decided.stop == choice.stop
    assert decided.stopped == choice.stopped and decided.cut_short == choice.cut_short
    assert decided.confidence_reached == choice.confidence_reached
    assert decided.standings == choice.standings
    assert [s.to_json() for s in decided.standings] == choice.ranking
    assert sorted(s.candidate for s in decided.standings) == list(range(k))
    by_index = {s.candidate: s for s in decided.standings}
    for c in choice.candidates:  # every fate told is the one the result holds
        assert fate[c.index] == (c.knocked_out and c.knocked_out.reason)
        assert by_index[c.index].state == ("racing" if fate[c.index] is None else "out")
        assert by_index[c.index].to_json()["out"] == c.out
    return fate


def test_a_race_tells_its_rounds_and_every_candidate_s_fate_as_values():
    events: list = []
    truths = [(1.0, 1.8, 0.05), (0.5, 1.0, 0.05), (1.0, 2.6, 0.05)]
    choice = _race(truths, on_event=events.append, rollouts=600, seed=5)
    fate = _check_events(events, choice)
    assert fate == {0: None, 1: "less_likely", 2: "costs_more"}
    (costly,) = [e.why for e in events if isinstance(e, KnockedOut) and e.candidate == 2]
    assert costly.by == 0
    decided = events[-1]
    assert decided.stop == "separated" and not decided.cut_short and decided.chosen == 0
    assert decided.confidence_reached is None and decided.standings[0].candidate == 0
    # The first round drives every candidate; the words of choice.json come from the values.
    assert next(e for e in events if isinstance(e, RoundDone)).driven == (0, 1, 2)
    assert {c.index: c.out for c in choice.candidates} == {
        0: "",
        1: "less likely to succeed than another (intervals apart)",
        2: "costs more energy than candidate 0 (intervals apart)",
    }
    # The same seed, the same events (all but the wall time).
    again: list = []
    _race(truths, on_event=again.append, rollouts=600, seed=5)
    assert _without_time(again) == _without_time(events)

    # Cut short by the cap: told so, with the confidence it reached.
    short: list = []
    truths = [(1.0, 1.6, 0.05), (1.0, 2.4, 0.05), (0.995, 1.61, 0.05)]
    cut = _race(truths, on_event=short.append, rollouts=120, max_per_candidate=400, seed=2)
    _check_events(short, cut)
    assert short[-1].stop == "rollout_cap" and short[-1].cut_short
    assert short[-1].confidence_reached == cut.confidence_reached is not None
    # With min_success: the ones that cannot clear it leave, by a value, not a sentence.
    qualified: list = []
    truths = [(0.3, 1.2, 0.05), (1.0, 2.0, 0.05)]
    picked = _race(truths, on_event=qualified.append, min_success=0.9, max_per_candidate=60)
    assert _check_events(qualified, picked)[0] == "below_min_success"
    out = next(e.why for e in qualified if isinstance(e, KnockedOut))
    assert out.rival_bound == 0.9 and picked.candidates[0].out == "P(success) upper bound below 0.9"


def _without_time(events: list) -> list[str]:
    """The events as text, wall times left out (nan == nan there, as it is not in a float)."""
    return [
        repr(dataclasses.replace(e, wall_time_s=0.0) if isinstance(e, Decided) else e)
        for e in events
    ]


def test_the_chosen_is_never_wholly_below_another_with_or_without_the_zone():
    rng = np.random.default_rng(17)
    zoned = 0
    for trial in range(60):
        k = int(rng.integers(2, 6))
        truths = [
            (float(rng.choice([1.0, 0.98, 0.9, 0.6])), float(rng.uniform(1.5, 2.0)), 0.1)
            for _ in range(k)
        ]
        zone = (0.05, 0.05) if trial % 2 else (0.0, 0.0)
        choice = _race(
            truths,
            rollouts=int(rng.integers(40, 1000)),
            max_per_candidate=200,
            seed=trial,
            indifference=zone,
        )
        conf = 1 - 0.05 / k
        chosen = next(c for c in choice.candidates if c.index == choice.chosen)
        low = chosen.p_interval(conf)[1]
        for c in choice.candidates:
            assert not chosen.p_interval(conf)[2] < c.p_interval(conf)[1], (trial, choice.stopped)
        assert choice.ranking[0]["candidate"] == choice.chosen
        if choice.stopped.startswith("within the indifference zone"):
            # The decision's statement holds on the race's own intervals.
            rivals = [c for c in choice.candidates if not c.out and c is not chosen]
            assert all(c.p_interval(conf)[2] <= low + 0.05 + 1e-12 for c in rivals)
            zoned += 1
    assert zoned >= 3, "the zone stopped some of the races"


@pytest.fixture(scope="module")
def two_bridges(tmp_path_factory):
    """Start and goal platforms joined by a wide bridge (safe) and a narrow one (risky: 12 cm
    for feet 7 cm apart), over a void."""
    d = tmp_path_factory.mktemp("two_bridges")
    boxes = [
        ((0.9, 1.2, 0.1), (-0.75, 0.0)),
        ((0.9, 1.2, 0.1), (0.75, 0.0)),
        ((0.62, 0.3, 0.1), (0.0, 0.3)),
        ((0.62, 0.12, 0.1), (0.0, -0.2)),
    ]
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
    proc = roachplan(
        "choose",
        "--scene",
        str(scene),
        "--candidates",
        "4",
        "--rollouts",
        "32",
        "--workers",
        "2",
        "--seed",
        "1",
        "--json",
        *extra,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    return json.loads(proc.stdout)


@pytest.mark.slow
def test_the_safe_route_wins_the_same_seed_gives_the_same_ranking_and_validates(
    two_bridges, tmp_path
):
    from roachplan.experiments import ExperimentSpec
    from roachplan.experiments._workers import TrialWorker
    from roachplan.scenes import load_scene

    out = tmp_path / "choice"
    result = _choose(two_bridges, "--validate", "8", "--out", str(out))
    routes = {r["route"] for r in result["ranking"]}
    assert routes == {"wide", "narrow"}, "both routes are candidates"
    by_index = {r["candidate"]: r for r in result["ranking"]}
    chosen = by_index[result["chosen"]]
    assert chosen["route"] == "wide", result["ranking"]
    # Nothing ranked above a candidate whose interval lies wholly above its own.
    for i, a in enumerate(result["ranking"]):
        for b in result["ranking"][i + 1 :]:
            assert not a["p_high"] < b["p_low"]
    assert result["rollouts"] <= 32 and result["stopped"]
    # The same seed, the same ranking: each rollout is a function of its seed alone (not of
    # the worker, the order or what ran before), so the same race deals the same rollouts and
    # decides the same. The chosen path's first rollouts, driven again here, are the saved ones.
    saved = [json.loads(line) for line in (out / "rollouts.jsonl").read_text().splitlines()]
    mine = [r for r in saved if r["candidate"] == result["chosen"] and not r.get("fresh")][:3]
    scene = load_scene(str(two_bridges))
    worker = TrialWorker(ExperimentSpec.of_scene(scene, name="again"))
    for rec in mine:
        again = worker.rollout(
            rec["candidate"],
            result["chosen_path"],
            rec["seed"],
            scene.uncertainty,
            [tuple(s) for s in result["chosen_spins"]],
        )
        assert (again["outcome"], again["energy"]) == (rec["outcome"], rec["energy"])
    # Validation: the observed success of fresh rollouts within the predicted intervals.
    checked = result["validation"]
    assert checked["repeats"] == 8 and 0 <= checked["brier"] <= 1
    inside = [r["inside"] for r in checked["candidates"]]
    assert sum(inside) >= len(inside) - 1, checked["candidates"]
    assert json.loads((out / "choice.json").read_text())["chosen"] == result["chosen"]
    assert len((out / "rollouts.jsonl").read_text().splitlines()) == result["rollouts"]
    # A folder holding other files is refused, the files left alone.
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    proc = roachplan("choose", "--scene", str(two_bridges), "--out", str(tmp_path / "mine"))
    assert proc.returncode == 2 and "--out" in proc.stderr
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


@pytest.mark.slow
def test_choose_tells_the_candidates_it_planned_then_its_race(two_bridges):
    """choose() through the real planner and PyBullet: its events, in order, agree with the
    choice it returns, from the candidates' paths to the decision."""
    from roachplan.experiments import choose
    from roachplan.scenes import build_world, load_scene

    world = build_world(load_scene(str(two_bridges)))
    cfg = ChooseConfig(candidates=2, rollouts=8, budget_s=None, seed=1)
    events: list = []
    choice, _ = choose(world, cfg, workers=2, on_event=events.append)
    _check_events(events, choice)
    planned = events[0]
    assert isinstance(planned, CandidatesPlanned) and len(planned.candidates) == 2
    assert planned.message == "2 candidates planned; racing them"
    for p, c in zip(planned.candidates, choice.candidates, strict=True):
        assert (p.index, p.route, p.seed, p.spins) == (c.index, c.route, c.seed, c.spins)
        assert np.array_equal(p.path_xyz, c.path_xyz) and p.length == c.length
    assert {p.route for p in planned.candidates} == {"wide", "narrow"}
    assert events[-1].rollouts == choice.rollouts <= 8


# -- the uncertainty model from scene and spec YAML (`uncertainty:`) ------------------------------

FLAT = (
    "terrain: []\nground: 0.0\nrobot: {start: [0.0, 0.0, 0]}\ngoal: [0.6, 0.0, 0]\n"
    "bounds: [[-0.4, -0.4], [1.0, 0.4]]\nplanner: {name: rrtconnect}\n"
)


@pytest.mark.slow
def test_a_scene_s_uncertainty_changes_the_draws_of_its_rollouts(tmp_path):
    from roachplan.scenes import load_scene

    path = tmp_path / "wide.yaml"
    path.write_text(FLAT + "uncertainty: {friction: 0, start_xy: 0.05, motor_mismatch: 0.2}\n")
    cfg = load_scene(path).uncertainty
    assert (cfg.friction, cfg.start_xy, cfg.motor_mismatch) == (0.0, 0.05, 0.2)
    assert cfg.body_mass == UncertaintyConfig().body_mass  # keys not given keep their default
    seeds = [rollout_seed(1, 0, k) for k in range(200)]
    ours = [draw(cfg, s) for s in seeds]
    default = [draw(UncertaintyConfig(), s) for s in seeds]
    assert all(d.friction_scale == 1.0 for d in ours)
    assert any(abs(d.friction_scale - 1) > 0.05 for d in default)
    # Start offsets beyond the default 1 cm disc, and a mismatch beyond the default 3 %.
    assert max(math.hypot(*d.start_offset[:2]) for d in ours) > 0.03
    assert max(math.hypot(*d.start_offset[:2]) for d in default) <= 0.01 + 1e-12
    assert max(abs(d.motor_gain[0] / d.motor_gain[1] - 1) for d in ours) > 0.1

    # Through `roachplan choose`: the rollouts it drove were drawn from the scene's model.
    out = tmp_path / "choice"
    proc = roachplan(
        "choose",
        "--scene",
        str(path),
        "--candidates",
        "1",
        "--rollouts",
        "4",
        "--workers",
        "1",
        "--seed",
        "1",
        "--procedure",
        "race",  # (its worlds are the race's stream: issue 25's certify drives fresh ones)
        "--json",
        "--out",
        str(out),
        timeout=600,
    )
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    result = json.loads(proc.stdout)
    assert result["rollouts"] == 4, "a lone candidate still gets its rollouts"
    assert result["uncertainty"]["friction"] == 0.0 and result["uncertainty"]["start_xy"] == 0.05
    worlds = [
        json.loads(line)["world"] for line in (out / "rollouts.jsonl").read_text().splitlines()
    ]
    assert len(worlds) == 4 and all(w["friction_scale"] == 1.0 for w in worlds)
    assert sorted(w["seed"] for w in worlds) == sorted(rollout_seed(1, 0, k) for k in range(4))
    for w in worlds:  # each the pure draw of its recorded seed; no capture, no terrain noise
        assert w == {**draw(cfg, w["seed"]).to_json(), "terrain_height": 0.0}


def test_a_spec_s_uncertainty_overrides_its_scene_s_field_by_field(tmp_path):
    from roachplan.experiments import load_experiment

    (tmp_path / "s.yaml").write_text(FLAT + "uncertainty: {start_xy: 0.05, friction: 0.1}\n")
    (tmp_path / "e.yaml").write_text("scene: s.yaml\nuncertainty: {friction: 0.3}\n")
    u = load_experiment(tmp_path / "e.yaml").uncertainty
    assert (u.start_xy, u.friction, u.motor_speed) == (0.05, 0.3, UncertaintyConfig().motor_speed)
    assert load_experiment(tmp_path / "e.yaml").scene_with_settings().uncertainty == u


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (
            "uncertainty: {friction: 1.5}\n",
            "uncertainty.friction: expected a number from 0 to below 1 [-], got 1.5",
        ),
        (
            "uncertainty: {start_yaw: -3}\n",
            "uncertainty.start_yaw: expected a number from 0 to 180 [deg], got -3",
        ),
        (
            "uncertainty: {start_xy: 2}\n",
            "uncertainty.start_xy: expected a number from 0 to 0.5 [m], got 2",
        ),
        (
            "uncertainty: {frction: 0.1}\n",
            "uncertainty.frction: unknown key; accepted keys: start_xy, start_yaw, friction",
        ),
        ("uncertainty: {body_mass: lots}\n", "uncertainty.body_mass: expected a finite number"),
        ("uncertainty: 0.2\n", "uncertainty: expected a mapping with keys start_xy"),
    ],
)
@pytest.mark.slow
def test_a_bad_uncertainty_is_refused_naming_file_key_and_range(tmp_path, body, message):
    scene = tmp_path / "bad.yaml"
    scene.write_text(FLAT + body)
    proc = roachplan("choose", "--scene", str(scene), "--rollouts", "8", "--json")
    assert proc.returncode == 2 and proc.stdout == ""
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert str(scene) in proc.stderr and message in proc.stderr, proc.stderr
    # The same check on an experiment spec's `uncertainty:` (over a good scene).
    (tmp_path / "good.yaml").write_text(FLAT)
    spec = tmp_path / "spec.yaml"
    spec.write_text("scene: good.yaml\n" + body)
    done = roachplan("experiment", str(spec), "--out", str(tmp_path / "out"))
    assert done.returncode == 2 and str(spec) in done.stderr and message in done.stderr, done.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", ["0.05", "x,0.05", "1.5,0.05", "0.05,-0.1", "nan,0"])
def test_a_bad_indifference_is_refused_in_one_line(value):
    proc = roachplan("choose", "--scene", "flat", f"--indifference={value}")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert f"--indifference {value}: give DP,DE" in proc.stderr, proc.stderr


def test_address_is_for_the_ray_backend():
    proc = roachplan("choose", "--scene", "flat", "--address", "127.0.0.1:6379")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "--address 127.0.0.1:6379" in proc.stderr and "--backend ray" in proc.stderr
    helped = roachplan("choose", "--help")
    assert "--address RAY_ADDRESS" in helped.stdout


@pytest.mark.slow
def test_choose_on_a_ray_cluster_by_address_drives_the_same_rollouts(tmp_path, monkeypatch):
    """A Ray instance started by another process (as a cluster would be), reached with
    --address: the same seed and cap give the same ranking as local workers."""
    import os
    import subprocess
    import sys

    # Ray's single-machine mode, for the holder and for roachplan: every address on loopback,
    # not on the machine's network address (this test sends nothing off the machine).
    monkeypatch.setenv("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    scene = tmp_path / "flat.yaml"
    scene.write_text(FLAT)
    args = (
        "choose",
        "--scene",
        str(scene),
        "--candidates",
        "2",
        "--rollouts",
        "8",
        "--seed",
        "3",
        "--json",
    )
    local = roachplan(*args, "--workers", "2", timeout=600)
    assert local.returncode in (0, 1), local.stderr[-2000:]
    # The holder starts Ray and, when its stdin closes, shuts down what it started. Ray >= 2.59
    # turns token authentication on for a local cluster by default, and a client connecting by
    # address does not send the token (ray-project/ray#64755): off for this loopback test.
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, ray; ray.init(num_cpus=2, include_dashboard=False, "
            "logging_level='ERROR'); print(ray.get_runtime_context().gcs_address, flush=True); "
            "sys.stdin.read(); ray.shutdown()",
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "RAY_AUTH_MODE": "disabled"},
    )
    assert holder.stdin is not None and holder.stdout is not None  # both PIPE
    try:
        address = holder.stdout.readline().strip()
        assert address.startswith("127.0.0.1:"), (
            f"the Ray holder did not start on loopback: {address!r}"
        )
        on_ray = roachplan(*args, "--backend", "ray", "--address", address, timeout=300)
    finally:
        holder.stdin.close()
        holder.wait(timeout=120)
    assert on_ray.returncode == local.returncode, on_ray.stderr[-2000:]

    def key(result):
        return [
            (r["candidate"], r["successes"], r["rollouts"], r["relative_energy"])
            for r in result["ranking"]
        ]

    a, b = json.loads(local.stdout), json.loads(on_ray.stdout)
    assert key(b) == key(a) and b["chosen"] == a["chosen"]


def test_a_capture_s_terrain_height_noise_reaches_the_physics_and_reruns_exactly():
    """kinect_bridge (a synthetic Kinect capture): each rollout moves the mesh's vertices by
    the sensor's error, drawn from the rollout's seed."""
    import dataclasses

    from roachplan.experiments._spec import ExperimentSpec
    from roachplan.experiments._uncertainty import terrain_noise
    from roachplan.experiments._workers import TrialWorker
    from roachplan.scenes import load_scene

    cfg = UncertaintyConfig()
    dz = terrain_noise(cfg, 7, 20000)
    assert np.array_equal(dz, terrain_noise(cfg, 7, 20000))
    assert abs(np.std(dz) - cfg.terrain_height) < 0.05 * cfg.terrain_height
    assert not np.array_equal(dz, terrain_noise(cfg, 8, 20000))
    assert not terrain_noise(dataclasses.replace(cfg, terrain_height=0.0), 7, 5).any()

    scene = load_scene("kinect_bridge")
    spec = ExperimentSpec(
        name="t",
        path=scene.path,
        scene=scene.path,
        planner=scene.planner,
        sim=scene.sim,
        driver=scene.driver,
    )
    worker = TrialWorker(spec)
    try:
        from roachplan.experiments import plan

        planned = plan(worker.world, seed=scene.seed)
        assert planned.found
        path = planned.path_xyz.tolist()
        calm = dataclasses.replace(cfg, terrain_height=0.0)
        rough = dataclasses.replace(cfg, terrain_height=0.02)  # 2 cm: it must show
        a = worker.rollout(0, path, 11, rough)
        again = worker.rollout(0, path, 11, rough)
        assert again.pop("wall_time") > 0 and a.pop("wall_time") > 0
        assert again == a  # the same seed, the same rollout (but for its wall time)
        b = worker.rollout(0, path, 11, calm)
        assert a["world"]["terrain_height"] == 0.02 and b["world"]["terrain_height"] == 0.0
        assert (a["energy"], a["end"]) != (b["energy"], b["end"])
    finally:
        worker.close()


def test_a_manifest_from_before_uncertainty_still_resumes_and_a_changed_one_is_refused(tmp_path):
    import dataclasses
    from pathlib import Path

    from roachplan.experiments import ExperimentError, load_experiment
    from roachplan.experiments._manifest import check_same_spec, spec_from_manifest

    spec = load_experiment("bridge_rough")
    recorded = json.loads(json.dumps(spec.to_json()))
    del recorded["uncertainty"]  # as written before the key existed
    old = {"spec": recorded, "trials_total": 4}
    check_same_spec(old, spec, 4, Path("old"))
    assert spec_from_manifest(old, Path("old")).uncertainty == UncertaintyConfig()
    changed = dataclasses.replace(spec, uncertainty=UncertaintyConfig(friction=0.5))
    with pytest.raises(ExperimentError, match="was started with uncertainty"):
        check_same_spec(old, changed, 4, Path("old"))
