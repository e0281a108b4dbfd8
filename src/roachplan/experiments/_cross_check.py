"""Two engines as a cross-check (issue 31, item 4): a choice's rollouts driven again under the
other physics engine, the same paths in the same drawn worlds (each rollout's seed), and per
path its success and energy under each engine and whether they agree.

Where both engines' success rates are within each other's 95 % intervals and the other engine
favours the same path, the choice is one both engines agree on; a disagreement is model
uncertainty: the simulators differ about this robot on this terrain (their contacts, their
turning), and the choice rests on the one that was used.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

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


def favourite(tallies: dict[int, EngineTally]) -> int:
    """The path one engine's rollouts favour: the highest success rate, then the lowest mean
    energy, then the lower index."""

    def key(i: int):
        t = tallies[i]
        energy = t.relative_energy if math.isfinite(t.relative_energy) else math.inf
        return (-t.p_success, energy, i)

    return min(tallies, key=key)


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
    ours = {i: tally(recs) for i, recs in mine.items()}
    others = {i: tally(recs) for i, recs in theirs.items()}
    rows = []
    for i in sorted(mine):
        a, b = ours[i], others[i]
        rows.append(
            {
                "candidate": i,
                engine: a.to_json(),
                other: b.to_json(),
                "agree": bool(a.p_low <= b.p_high and b.p_low <= a.p_high),
            }
        )
    favoured = favourite(others) if others else None
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
