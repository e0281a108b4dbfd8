"""How to choose a path by simulation: one frozen config for the planning of the candidates, the
race's policy and its budget."""

from __future__ import annotations

from dataclasses import dataclass

from ._uncertainty import UncertaintyConfig


@dataclass(frozen=True, kw_only=True)
class ChooseConfig:
    """How to choose."""

    candidates: int = 8
    """K, the number of candidate paths [-]."""
    rollouts: int | None = None
    """Cap on rollouts over all candidates [-] (None: only the time budget)."""
    budget_s: float | None = 60.0
    """Wall-time budget of the race [s] (None: only the rollout cap)."""
    confidence: float = 0.95
    """Joint confidence of the decision [-]."""
    min_success: float | None = None
    """Choose the lowest-energy candidate whose P(success) lower bound is at least this [-];
    None: the most likely to succeed, then the lowest energy."""
    batch: int = 4
    """Rollouts per candidate per round [-]."""
    max_per_candidate: int = 200
    """A candidate gets at most this many rollouts [-]."""
    seed: int = 0
    indifference: tuple[float, float] = (0.05, 0.05)
    """(DP, DE): differences too small to matter, DP in P(success) [-] and DE in mean relative
    energy [fraction, 0.05 = 5 %]; the race stops once the first-ranked candidate is within
    them of the best (experiments/_choose_policy.py). (0, 0): off, stop only on separation."""
    uncertainty: UncertaintyConfig | None = None
    """What each rollout's world is drawn from; None: the scene's (its `uncertainty:` key,
    else the defaults of experiments/_uncertainty.py)."""
