"""The statistics a race decides on, over plain numbers: Clopper-Pearson intervals for
P(success), Student t intervals for a mean, and the paired bound on an energy difference over
the worlds two candidates both succeeded in. The race's Bonferroni correction (each interval at
1 - (1 - c) / K) is the caller's: these take the confidence of one interval."""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping

import numpy as np
from scipy import stats


@functools.lru_cache(maxsize=65536)  # (ranking asks for the same few intervals many times)
def clopper_pearson(successes: int, n: int, confidence: float) -> tuple[float, float]:
    """Clopper-Pearson (exact) interval of a binomial proportion [-]; (0, 1) without trials.
    Its coverage is at least `confidence` for every p (Wilson's dips below it near 0 and 1),
    and where the race decides, at or near n successes in n, it is the narrower: the lower
    bound for n in n is ((1 - c) / 2)^(1/n), about 1 - 5.8 / n at c = 1 - 0.05 / 8, where
    Wilson's n / (n + z^2) is 1 - 7.5 / n."""
    if n == 0:
        return 0.0, 1.0
    a = (1 - confidence) / 2
    lo = 0.0 if successes == 0 else float(stats.beta.ppf(a, successes, n - successes + 1))
    hi = 1.0 if successes == n else float(stats.beta.ppf(1 - a, successes + 1, n - successes))
    return lo, hi


def mean_interval(values: list[float], confidence: float) -> tuple[float, float, float]:
    """(mean, low, high): Student t interval of the mean; infinite bounds with < 2 values."""
    if not values:
        return math.nan, -math.inf, math.inf
    m = float(np.mean(values))
    if len(values) < 2:
        return m, -math.inf, math.inf
    half = _t_quantile(1 - (1 - confidence) / 2, len(values) - 1) * (
        float(np.std(values, ddof=1)) / math.sqrt(len(values))
    )
    return m, m - half, m + half


@functools.lru_cache(maxsize=65536)
def _t_quantile(q: float, df: int) -> float:
    """Student t's q quantile with df degrees of freedom: a race asks the same few (its
    confidence, each candidate's count) at every look, and scipy's ppf took half of its time."""
    return float(stats.t.ppf(q, df))


def paired_excess_bound(
    mine: Mapping[int, float], theirs: Mapping[int, float], confidence: float, de: float
) -> float:
    """Upper confidence bound on the mean of mine[w] - (1 + de) theirs[w] over the keys w (the
    worlds) both have, in the order of `theirs`; +inf with fewer than 2 such worlds. Paired by
    world, so what a world does to both values cancels in each difference."""
    diffs = [mine[w] - (1 + de) * v for w, v in theirs.items() if w in mine]
    return mean_interval(diffs, confidence)[2] if len(diffs) >= 2 else math.inf
