"""What a race tells as it runs (choose(..., on_event=...), race(..., on_event=...)): frozen
values, in this order:

1. CandidatesPlanned, once (from choose(): race() is handed its candidates);
2. for each round, a KnockedOut for every candidate that left the race after it (in index
   order), then RoundDone with every candidate's standing once they have left;
3. Decided, once, with the ranking and why the race stopped.

A candidate is racing from CandidatesPlanned on until its KnockedOut; each event's numbers are
the race's own (intervals at its per-candidate confidence, 1 - (1 - c) / K). Everything is
picklable: the page receives them through a pipe from the child that runs the race."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

from ._choose_candidate import CandidatePlan, Knockout, Standing

if TYPE_CHECKING:
    from ._choose_certify import Guarantee

StopReason = Literal[
    "separated",
    "one_qualifies",
    "indifference_zone",
    "rollout_cap",
    "time_budget",
    "max_per_candidate",
    "cancelled",
    "no_candidates",
    "certified",
    "chosen_unsafe",
    "rival_cheaper",
]
"""Why a race stopped: certified (screen then certify, experiments/_choose_certify.py: the
claim holds at the confidence) or ended short of it ("chosen_unsafe": the chosen path is shown
less safe than the level; "rival_cheaper": a rival is shown as safe and cheaper beyond the
margin); for the race, decided ("separated": one candidate left in the race; "one_qualifies":
with min_success, one alone clears it; "indifference_zone": the first-ranked is within the zone
at the requested confidence), cut short before a decision ("rollout_cap", "time_budget",
"max_per_candidate": every candidate in the race has its maximum), or neither ("cancelled",
"no_candidates")."""

CUT_SHORT: frozenset[StopReason] = frozenset({"rollout_cap", "time_budget", "max_per_candidate"})
"""The stops that end a race on its budget, cap or maximum, short of a decision."""


@dataclass(frozen=True, kw_only=True)
class CandidatesPlanned:
    """The candidates are planned: each one's path, route and planning seed; all are racing."""

    candidates: tuple[CandidatePlan, ...]
    """In index order."""

    @property
    def message(self) -> str:
        """One line of progress."""
        return f"{len(self.candidates)} candidates planned; racing them"


@dataclass(frozen=True, kw_only=True)
class KnockedOut:
    """A candidate left the race after a round: clearly beaten, by the bounds in `why`."""

    candidate: int
    round: int
    """The round after which it left (1: the first)."""
    why: Knockout


@dataclass(frozen=True, kw_only=True)
class RoundDone:
    """A round's rollouts are in and the clearly beaten have left the race."""

    round: int
    """1 for the first round."""
    rollouts: int
    """Rollouts so far, over all candidates [-]."""
    fraction: float
    """Of the rollout cap (with one) or else the time budget spent, 0 to 1 [-]."""
    driven: tuple[int, ...]
    """The candidates this round gave rollouts to, in index order."""
    standings: tuple[Standing, ...]
    """Every candidate's standing after the round, in index order (those out of the race
    too)."""
    phase: Literal["race", "screen", "certify"] = "race"
    """Which part of the choice the round belongs to: the race (procedure "race"), or the screening or
    the certifying of experiments/_choose_certify.py."""

    @property
    def racing(self) -> int:
        """Candidates still in the race [-]."""
        return sum(s.knocked_out is None for s in self.standings)

    @property
    def message(self) -> str:
        """One line of progress."""
        if self.phase == "screen":
            return f"screening: {self.rollouts} rollouts over {len(self.standings)} candidates"
        if self.phase == "certify":
            return (
                f"certifying on fresh worlds: {self.rollouts} rollouts, {len(self.driven)} "
                f"path{'s' * (len(self.driven) != 1)} driven"
            )
        return (
            f"{self.rollouts} rollouts, {self.racing} of {len(self.standings)} candidates in "
            f"the race"
        )


@dataclass(frozen=True, kw_only=True)
class Decided:
    """The race is over: what it chose, and why it stopped."""

    chosen: int | None
    """The chosen candidate (the first-ranked with a success); None: none ever succeeded."""
    stop: StopReason
    stopped: str
    """Why it stopped, in the words the command line and the page print (Choice.stopped)."""
    confidence: float
    """The joint confidence asked for [-]."""
    confidence_reached: float | None
    """When cut short: the highest joint confidence (from 0.5, to 0.01) at which the
    first-ranked is within the indifference zone; None when it decided, or not even at 0.5."""
    rollouts: int
    """Over all candidates [-]."""
    rounds: int
    standings: tuple[Standing, ...]
    """The ranking, best first."""
    wall_time_s: float
    """The race's wall time, planning not included [s]."""
    guarantee: Guarantee | None = None
    """What the choice is shown to be (screen then certify); None for the race (procedure "race")."""

    @property
    def cut_short(self) -> bool:
        """Stopped by the budget, the rollout cap or max_per_candidate, not by a decision."""
        return self.stop in CUT_SHORT


@dataclass(frozen=True, kw_only=True)
class CrossChecked:
    """After the race, its rollouts driven again under the other engine (choose's
    cross_check; experiments/_cross_check.py)."""

    result: dict
    """cross_check()'s: per path both engines' tallies, whether they agree, and the sentence."""


ChooseEvent = CandidatesPlanned | KnockedOut | RoundDone | Decided | CrossChecked
"""What on_event receives."""
