"""How `roachplan choose` chooses: the race's settings, each with its validator
(roachplan/_settings.py). Importable without numpy, scipy or OMPL: `roachplan choose` checks its
flags against them before it loads anything."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from roachplan._settings import (
    SettingError,
    between,
    check_settings,
    integer,
    is_number,
    non_negative,
    one_of,
    optional,
)
from roachplan._settings import seed as seed_number
from roachplan._settings import setting as s
from roachplan.sim import UncertaintyConfig

QUICK_MODE = (0.10, 0.10)
"""The quick mode's (eps_P, eps_E): a wider zone, decided in about a quarter of the rollouts."""
DEFAULT_MODE = (0.05, 0.05)
"""The default mode's (eps_P, eps_E)."""

MAX_CANDIDATES = 64
"""Most candidate paths a race takes [-]."""


def _probability(v: Any) -> str | None:
    """A probability strictly between 0 and 1."""
    ok = is_number(v) and 0 < v < 1
    return None if ok else "expected a probability above 0 and below 1, e.g. 0.9"


def _indifference(v: Any) -> str | None:
    """(DP, DE), each in [0, 1)."""
    if isinstance(v, tuple | list) and len(v) == 2 and all(is_number(x) and 0 <= x < 1 for x in v):
        return None
    return "give DP,DE: two numbers in [0, 1), e.g. 0.05,0.05 (0,0: no indifference zone)"


@dataclass(frozen=True, kw_only=True)
class ChooseConfig:
    """How to choose."""

    candidates: int = s(8, integer(1, MAX_CANDIDATES))
    """K, the number of candidate paths [-]."""
    rollouts: int | None = s(None, optional(integer(1)))
    """Cap on rollouts over all candidates [-] (None: only the time budget)."""
    budget_s: float | None = s(60.0, optional(non_negative("s")))
    """Wall-time budget of the race, candidates' planning included [s] (None: only the
    rollout cap; 0: none of it left)."""
    confidence: float = s(0.95, between(0.5, 1.0, high_included=False))
    """Joint confidence of the decision [-]."""
    min_success: float | None = s(None, optional(_probability))
    """Choose the lowest-energy candidate whose P(success) lower bound is at least this [-];
    None: the most likely to succeed, then the lowest energy."""
    batch: int = s(4, integer(1))
    """Rollouts per candidate per round [-]."""
    max_per_candidate: int = s(200, integer(1))
    """A candidate gets at most this many rollouts [-]."""
    seed: int = s(0, seed_number())
    indifference: tuple[float, float] = s(DEFAULT_MODE, _indifference)
    """(DP, DE): differences too small to matter, DP in P(success) [-] and DE in mean relative
    energy [fraction, 0.05 = 5 %]; the race stops once the first-ranked candidate is within
    them of the best (module docstring). (0, 0): off, stop only on separation."""
    uncertainty: UncertaintyConfig | None = None
    """What each rollout's world is drawn from; None: the scene's (its `uncertainty:` key,
    else the defaults of experiments/_uncertainty.py)."""
    procedure: Literal["certify", "race"] = s("certify", one_of(("certify", "race")))
    """"certify": screen, then certify the chosen path on fresh rollouts, with a guarantee
    valid at every look (experiments/_choose_certify.py; indifference is then (eps_P, eps_E):
    the chosen path succeeds at least 1 - eps_P of the time, or min_success, and is within
    eps_E of the lowest energy among the paths that safe); "race": the race without a certificate
    (experiments/_choose_race.py)."""

    def __post_init__(self) -> None:
        check_settings(self)
        if self.procedure == "certify" and self.min_success is None and self.indifference[0] <= 0:
            raise SettingError(
                "indifference",
                self.indifference,
                "DP above 0 (the chosen path is certified to succeed at least 1 - DP of the "
                "time), or a min_success",
            )
        if self.rollouts is not None and self.rollouts < self.candidates:
            expected = f"at least one rollout per candidate ({self.candidates})"
            raise SettingError("rollouts", self.rollouts, expected)
