"""Anytime-valid bounds for the certificate of a choice (experiments/_choose_certify.py): they
hold at every number of rollouts at once, so the race may look after every round and stop when
it likes without its stated confidence failing.

P(success), exact (no approximation): a test of "p <= p0" (for a lower bound; "p >= p0" for an
upper one) by a mixture of likelihood ratios against alternatives q beyond p0,

    M_n(p0) = sum_i w_i  int q^S (1 - q)^F pi_i(q | q beyond p0) dq  /  (p0^S (1 - p0)^F),

with S successes and F failures in n Bernoulli rollouts. Under "p <= p0" each ratio's factor
has expectation p q / p0 + (1 - p)(1 - q)/(1 - p0) <= 1 (q >= p0), so M_n is a nonnegative
supermartingale and, by Ville's inequality, P(M_n >= 1/delta for some n) <= delta: the test
rejects "p <= p0" at any n with error at most delta, and the lower bound is the p0 where it
stops rejecting. The mixture for lower bounds (LOWER_ALTERNATIVES) puts half its weight on
q = 1 (a path that never fails: M_n = p0^-n while every rollout succeeds, so 0.95 is cleared
after 80 straight successes at delta = 0.025, against 59 for a single look at 0.05) and the
rest on paths failing a fifth and two fifths as often as p0 allows (a path that fails now and
then still gets there: simulated, a true P of 0.99 clears 0.95 after 155 rollouts on average,
0.98 after 350; the price of epsilon = 0.05 near P = 1). For upper bounds (a rival shown to
fail too often) the mixture is uniform over q < p0 (Beta(1, 1)). These are the mixture
martingales of Robbins (1970) and Howard et al. (2021).

Mean energy: the asymptotic confidence sequence of Waudby-Smith, Arbour, Sinha, Kennedy and
Ramdas (2021), a normal mixture boundary with the running variance estimate,

    mean +- sd * sqrt(2 (n rho^2 + 1) / (n^2 rho^2) * log(sqrt(n rho^2 + 1) / alpha)),

valid at every n as the rollouts grow for any energy distribution with a finite variance (an
energy has no upper bound a test could lean on: without an assumption no number of rollouts
bounds its mean). rho is tuned to n = 100. No claim is made from fewer than MIN_PAIRS values:
simulated with looks every 4 values, the bound at 0.05 was wrong in 1.7 % of runs for normal
values and 3.5 % for right-skewed ones (lognormal, sigma 0.3; 5.7 % at sigma 0.5).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy import special, stats

LOWER_ALTERNATIVES = ((0.5, 0.0), (0.25, 0.2), (0.25, 0.4))
"""The lower bound's mixture: (weight, c), each the alternative q = 1 - c (1 - p0), a path
failing c times as often as p0 allows (c = 0: never) [-]."""
UPPER_BETA = (1.0, 1.0)
"""The upper bound's mixture over the alternatives: uniform [-]."""
MIN_PAIRS = 16
"""Fewest values an energy bound is made from [-]; below it the bound is infinite."""
RHO_TARGET_N = 100
"""The number of values the energy boundary is tightest at [-]."""


def _log_lr_null(s: int, f: int, p0: float) -> float:
    """log of p0^S (1 - p0)^F (0 * log 0 = 0)."""
    out = s * math.log(p0) if s else 0.0
    return out + (f * math.log1p(-p0) if f else 0.0)


def log_evidence_above(s: int, f: int, p0: float) -> float:
    """log M_n(p0): the evidence against "p <= p0" (module docstring) after S successes and F
    failures; 0 < p0 < 1."""
    parts = []
    for weight, c in LOWER_ALTERNATIVES:
        if c == 0.0:  # q = 1 explains only rollouts that all succeeded
            if f == 0:
                parts.append(math.log(weight) - s * math.log(p0))
        else:
            q = 1 - (1 - p0) * c
            parts.append(math.log(weight) + s * math.log(q / p0) + f * math.log(c))
    return float(np.logaddexp.reduce(parts))


def log_evidence_below(s: int, f: int, p0: float) -> float:
    """log of the evidence against "p >= p0" after S successes and F failures; 0 < p0 < 1."""
    a, b = UPPER_BETA
    mixed = special.betaln(a + s, b + f) - special.betaln(a, b)
    below = _log_beta_cdf(p0, a + s, b + f) - _log_beta_cdf(p0, a, b)
    return float(mixed + below) - _log_lr_null(s, f, p0)


def _log_beta_cdf(x: float, a: float, b: float) -> float:
    """log of the Beta(a, b) distribution function at x: the regularized incomplete beta
    function (fast, scalar), scipy's logcdf where it underflows."""
    cdf = float(special.betainc(a, b, x))
    return math.log(cdf) if cdf > 1e-300 else float(stats.beta.logcdf(x, a, b))


def shows_at_least(s: int, f: int, p0: float, delta: float) -> bool:
    """At error delta (anytime): P(success) > p0 is shown."""
    return log_evidence_above(s, f, p0) >= math.log(1 / delta)


def shows_below(s: int, f: int, p0: float, delta: float) -> bool:
    """At error delta (anytime): P(success) < p0 is shown."""
    return log_evidence_below(s, f, p0) >= math.log(1 / delta)


def p_lower(s: int, f: int, delta: float) -> float:
    """Anytime-valid lower confidence bound on P(success) [-] at error delta: the p0 below
    which "p <= p0" is rejected."""
    return 0.0 if s == 0 else _edge(lambda p0: shows_at_least(s, f, p0, delta))[0]


def p_upper(s: int, f: int, delta: float) -> float:
    """Anytime-valid upper confidence bound on P(success) [-] at error delta: the p0 above
    which "p >= p0" is rejected."""
    return 1.0 if f == 0 else _edge(lambda p0: not shows_below(s, f, p0, delta))[1]


def _edge(below: Callable[[float], bool]) -> tuple[float, float]:
    """(lo, hi): an interval of width 1e-4 in [0, 1] holding the p0 where below(p0) turns
    from True to False, by bisection (a lower bound takes lo, an upper one hi: never tighter
    than shown)."""
    lo, hi = 0.0, 1.0
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if below(mid) else (lo, mid)
    return lo, hi


def _radius(sd: float, n: int, alpha: float) -> float:
    """Half-width of the asymptotic confidence sequence (module docstring) [units of sd]."""
    la = math.log(1 / alpha)
    rho2 = (2 * la + math.log(2 * la + 1)) / RHO_TARGET_N
    x = n * rho2
    return sd * math.sqrt(2 * (x + 1) / (n * n * rho2) * (la + 0.5 * math.log(x + 1)))


def mean_upper(values: ArrayLike, alpha: float) -> float:
    """Anytime-valid (asymptotic) upper confidence bound on the mean of `values` at error
    alpha; +inf with fewer than MIN_PAIRS values."""
    v = np.asarray(values, dtype=np.float64)
    n = len(v)
    if n < MIN_PAIRS:
        return math.inf
    return float(v.mean()) + _radius(float(v.std(ddof=1)), n, alpha)


def mean_bounds(values: Sequence[float], alpha: float) -> tuple[float, float, float]:
    """(mean, low, high), each bound anytime-valid (asymptotic) at error alpha; infinite with
    fewer than MIN_PAIRS values, nan mean without any."""
    n = len(values)
    if n == 0:
        return math.nan, -math.inf, math.inf
    v = np.asarray(values, dtype=np.float64)
    m = float(v.mean())
    if n < MIN_PAIRS:
        return m, -math.inf, math.inf
    r = _radius(float(v.std(ddof=1)), n, alpha)
    return m, m - r, m + r


def excess_reached(mine: ArrayLike, theirs: ArrayLike, alpha: float) -> float:
    """The smallest e >= 0 (to 0.001) such that the upper bound on the mean of
    mine - (1 + e) theirs is <= 0 at error alpha: "mine costs at most e more than theirs";
    +inf when no e up to 10 does (or with fewer than MIN_PAIRS pairs). Paired by position."""
    a, b = np.asarray(mine, dtype=np.float64), np.asarray(theirs, dtype=np.float64)
    if len(a) < MIN_PAIRS:
        return math.inf

    def holds(e: float) -> bool:
        return mean_upper(a - (1 + e) * b, alpha) <= 0

    if holds(0.0):
        return 0.0
    if not holds(10.0):
        return math.inf
    lo, hi = 0.0, 10.0
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if holds(mid) else (mid, hi)
    return hi
