"""The planners' names and the planning error, without importing OMPL (the command line
builds its --planner choices from them, and `roachplan --help` must answer at once)."""

from __future__ import annotations

from typing import Literal, get_args

from roachplan._errors import InputError

PlannerName = Literal[
    "prm",
    "stride",
    "rrt",
    "rrtconnect",
    "rrtstar",
    "prmstar",
    "lazyprm",
    "bitstar",
    "est",
    "sbl",
    "kpiece1",
    "bkpiece1",
    "lbkpiece1",
    "fmt",
    "trrt",
    "informedrrtstar",
]
PLANNER_NAMES: tuple[str, ...] = get_args(PlannerName)


class PlanningError(InputError):
    """A planning request that cannot be planned as asked (e.g. an invalid start)."""
