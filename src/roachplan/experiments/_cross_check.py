"""Two engines as a cross-check (issue 31, item 4): a choice's rollouts driven again under the
other physics engine, the same paths in the same drawn worlds (each rollout's seed), and per
path its success and energy under each engine and whether they agree; an experiment's trials
likewise, per route (each trial's path driven again from its start).

Where both engines' success rates are within each other's 95 % intervals and the other engine
favours the same path, the choice is one both engines agree on; a disagreement is model
uncertainty: the simulators differ about this robot on this terrain (their contacts, their
turning), and the choice rests on the one that was used.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._choose_bounds import p_lower, p_upper
from ._choose_race import Choice

OTHER_ENGINE = {"pybullet": "mujoco", "mujoco": "pybullet"}
"""The engine a choice is checked under, by the engine it was made with."""
ALPHA = 0.05
"""Each engine's interval on a path's P(success): 95 %."""


@dataclass(frozen=True, kw_only=True)
class EngineTally:
    """One path's rollouts under one engine."""

    rollouts: int
    successes: int
    p_low: float
    """Lower end of the 95 % interval on P(success) [-]."""
    p_high: float
    relative_energy: float
    """Mean relative energy of its successes [-] (nan without one)."""

    @property
    def p_success(self) -> float:
        return self.successes / self.rollouts if self.rollouts else math.nan

    def to_json(self) -> dict:
        return {
            "rollouts": self.rollouts,
            "successes": self.successes,
            "p_success": self.p_success,
            "p_low": self.p_low,
            "p_high": self.p_high,
            "relative_energy": self.relative_energy,
        }


def tally(records: list[dict]) -> EngineTally:
    """The tally of one path's rollout records."""
    s = sum(r["outcome"] == "success" for r in records)
    f = len(records) - s
    energies = [r["relative_energy"] for r in records if r["outcome"] == "success"]
    return EngineTally(
        rollouts=len(records),
        successes=s,
        p_low=p_lower(s, f, ALPHA),  # (no rollouts: 0 and 1)
        p_high=p_upper(s, f, ALPHA),
        relative_energy=float(np.mean(energies)) if energies else math.nan,
    )


def favourite(tallies: dict) -> Any:
    """The group (a path's index, a route's name) one engine's rollouts favour: the highest
    success rate, then the lowest mean energy, then the first key in order."""

    def key(i):
        t = tallies[i]
        energy = t.relative_energy if math.isfinite(t.relative_energy) else math.inf
        return (-t.p_success, energy, i)

    return min(tallies, key=key)


def compare(
    mine: dict, theirs: dict, engine: str, other: str, *, key: str
) -> tuple[list[dict], Any]:
    """Per group (a candidate path, a route: the dicts' keys, records each), the two engines'
    tallies under `engine` and `other` and whether their 95 % intervals overlap (rows named by
    `key`, in key order); and the group the other engine's records favour (None without any)."""
    ours = {g: tally(recs) for g, recs in mine.items()}
    others = {g: tally(theirs.get(g, [])) for g in mine}
    rows = []
    for g in sorted(mine):
        a, b = ours[g], others[g]
        rows.append(
            {
                key: g,
                engine: a.to_json(),
                other: b.to_json(),
                "agree": bool(a.p_low <= b.p_high and b.p_low <= a.p_high),
            }
        )
    driven = {g: t for g, t in others.items() if t.rollouts}
    return rows, (favourite(driven) if driven else None)


def cross_check(
    choice: Choice, engine: str, run_other: Callable[[list[tuple]], list[dict]]
) -> dict:
    """Drive every rollout of `choice` (made under `engine`) again under the other engine by
    run_other(calls) (calls (candidate, path, seed) as choose's run_rollouts takes them); per
    path the two engines' tallies and whether their intervals overlap, and whether the other
    engine favours the path chosen."""
    other = OTHER_ENGINE[engine]
    mine: dict[int, list[dict]] = {}
    for c in choice.candidates:
        mine[c.index] = [*c.rollouts, *choice.fresh.get(c.index, [])]
    calls = [
        (c.index, c.path_xyz.tolist(), r["seed"]) for c in choice.candidates for r in mine[c.index]
    ]
    theirs: dict[int, list[dict]] = {i: [] for i in mine}
    for rec in run_other(calls):
        theirs[rec["candidate"]].append(rec)
    rows, favoured = compare(mine, theirs, engine, other, key="candidate")
    chosen = choice.chosen
    agree = chosen is not None and favoured == chosen and all(r["agree"] for r in rows)
    return {
        "engine": engine,
        "other": other,
        "candidates": rows,
        "other_favours": favoured,
        "agree": agree,
        "sentence": _sentence(engine, other, rows, chosen, favoured, agree=agree),
    }


def cross_check_routes(
    trials: list[dict], engine: str, drive_other: Callable[[list[dict]], Iterable[dict]]
) -> dict:
    """An experiment's trials (store records, made under `engine`) driven again under the other
    engine: drive_other(trials) drives each trial's stored path and turns on the spot from its
    start and yields {"index", "outcome", "relative_energy"} per trial, in any order. Per route
    (route_key), the two engines' tallies and whether their intervals overlap; whether both
    favour the same route (the highest success rate, then the lowest mean energy). Trials
    without a path are left out: there is nothing to drive."""
    from ._summary import route_key

    other = OTHER_ENGINE[engine]
    driven = [t for t in trials if t.get("path_found")]
    route_of = {t["index"]: route_key(t) for t in driven}
    mine: dict[str, list[dict]] = {}
    for t in driven:
        mine.setdefault(route_of[t["index"]], []).append(t)
    theirs: dict[str, list[dict]] = {r: [] for r in mine}
    agreeing = 0
    outcome = {t["index"]: t["outcome"] for t in driven}
    for rec in drive_other(driven):
        theirs[route_of[rec["index"]]].append(rec)
        agreeing += (rec["outcome"] == "success") == (outcome[rec["index"]] == "success")
    rows, favoured = compare(mine, theirs, engine, other, key="route")
    ours = favourite({r: tally(recs) for r, recs in mine.items()}) if mine else None
    agree = ours is not None and favoured == ours and all(r["agree"] for r in rows)
    if ours is None:
        sentence = f"no trial had a path for {other} to drive"
    elif agree:
        sentence = (
            f"{engine} and {other} agree: both favour {ours}, and every route's success rates "
            f"under the two are within each other's 95% intervals"
        )
    else:
        differ = [r["route"] for r in rows if not r["agree"]]
        sentence = f"model uncertainty: {engine} favours {ours}"
        if favoured != ours:
            sentence += f", {other} favours {favoured}"
        if differ:
            sentence += (
                f"; the engines' success rates differ beyond their 95% intervals on "
                f"{', '.join(differ)}"
            )
    return {
        "engine": engine,
        "other": other,
        "routes": rows,
        "favours": ours,
        "other_favours": favoured,
        "trials": len(driven),
        "same_outcome": agreeing,
        "agree": agree,
        "sentence": sentence,
    }


def _sentence(engine: str, other: str, rows: list[dict], chosen, favoured, *, agree: bool) -> str:
    """The cross-check in words (candidates by their index, as the command line numbers them)."""
    if chosen is None:
        return f"{other} drove the same rollouts; {engine} found no path that succeeds"
    if agree:
        return (
            f"{engine} and {other} agree: both favour candidate {chosen}, and every path's "
            f"success rates under the two are within each other's 95% intervals"
        )
    differ = [r["candidate"] for r in rows if not r["agree"]]
    words = [f"model uncertainty: {engine} chose candidate {chosen}"]
    if favoured != chosen:
        words.append(f", {other} favours candidate {favoured}")
    if differ:
        words.append(
            f"; the engines' success rates differ beyond their 95% intervals on candidate"
            f"{'s' * (len(differ) > 1)} {', '.join(map(str, differ))}"
        )
    return "".join(words)


def tally_lines(x: dict, key: str, name: Callable[[Any], str] = str) -> list[str]:
    """A cross-check's rows (x[key + "s"]: per candidate or route) in words, one line each:
    name(group), then its successes and mean relative energy under each engine, "differ" where
    their 95 % intervals do not overlap."""
    lines = []
    for row in x[key + "s"]:
        a, b = row[x["engine"]], row[x["other"]]
        lines.append(
            f"  {name(row[key])}: {x['engine']} {a['successes']}/{a['rollouts']} (relative "
            f"energy {a['relative_energy']:.2f}), {x['other']} {b['successes']}/{b['rollouts']} "
            f"({b['relative_energy']:.2f}){'' if row['agree'] else '  differ'}"
        )
    return lines
