"""Dubins curves: the shortest forward-only path between two poses for a vehicle whose turns
are arcs of radius at least R (Dubins 1957; the six words LSL, RSR, LSR, RSL, RLR, LRL as in
Shkel & Lumelsky 2001). The roach drives like this while both sides walk forward: it turns on
arcs whose tightest radius is set by the largest motor ratio (sim/_calibration.py). It can also
turn on the spot, one side backwards, which drivable plans use only where no arc goes on
(planning/_drivable.py).

Pure numpy, scalar per pose pair: OMPL's DubinsStateSpace gives the same lengths (tested), but
its Python states must be freed by hand and each call crosses into C++ for one number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_TWO_PI = 2.0 * math.pi
_WORDS = ("LSL", "RSR", "LSR", "RSL", "RLR", "LRL")
_TURN = {"L": 1.0, "S": 0.0, "R": -1.0}


def _mod2pi(a: float) -> float:
    return a - _TWO_PI * math.floor(a / _TWO_PI)


@dataclass(frozen=True)
class DubinsPath:
    """One Dubins curve from `start` (x [m], y [m], heading [rad]) in the world frame."""

    start: tuple[float, float, float]
    word: str
    """The three segments' kinds: L (left arc), S (straight), R (right arc)."""
    lengths: tuple[float, float, float]
    """Each segment's length [m] (arcs: radius x angle)."""
    radius: float
    """Radius of the arcs [m]."""

    @property
    def length(self) -> float:
        """Total length [m]."""
        return sum(self.lengths)

    def sample(self, step: float) -> np.ndarray:
        """(N, 3) poses (x, y, heading) every `step` metres along the curve [m], from the start
        to the end inclusive."""
        n = max(1, math.ceil(self.length / step))
        return self.at(np.linspace(0.0, self.length, n + 1))

    def at(self, s: np.ndarray) -> np.ndarray:
        """(N, 3) poses at arc lengths s ((N,) in [0, length] [m])."""
        s = np.asarray(s, dtype=float)
        x, y, th = (np.full(s.shape, v) for v in self.start)
        r = self.radius
        done = np.zeros_like(s)
        for kind, seg in zip(self.word, self.lengths, strict=True):
            d = np.clip(s - done, 0.0, seg)  # distance travelled within this segment
            k = _TURN[kind]
            if k == 0.0:
                x, y = x + d * np.cos(th), y + d * np.sin(th)
            else:
                dth = k * d / r
                x = x + k * r * (np.sin(th + dth) - np.sin(th))
                y = y - k * r * (np.cos(th + dth) - np.cos(th))
                th = th + dth
            done = done + seg
        return np.stack([x, y, np.arctan2(np.sin(th), np.cos(th))], axis=-1)

    @property
    def end(self) -> tuple[float, float, float]:
        """The pose at the end of the curve."""
        return tuple(self.at(np.array([self.length]))[0].tolist())


def _word_params(word: str, a: float, b: float, d: float) -> tuple[float, float, float] | None:  # noqa: PLR0911 - one return per Dubins word and its no-solution case
    """(t, p, q), the three segments of `word` in units of the radius, for the normalised
    problem (from the origin at heading a to (d, 0) at heading b); None where it has none."""
    sa, sb, ca, cb = math.sin(a), math.sin(b), math.cos(a), math.cos(b)
    cab = math.cos(a - b)
    if word == "LSL":
        p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
        if p2 < 0:
            return None
        phi = math.atan2(cb - ca, d + sa - sb)
        return _mod2pi(phi - a), math.sqrt(p2), _mod2pi(b - phi)
    if word == "RSR":
        p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
        if p2 < 0:
            return None
        phi = math.atan2(ca - cb, d - sa + sb)
        return _mod2pi(a - phi), math.sqrt(p2), _mod2pi(phi - b)
    if word == "LSR":
        p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
        if p2 < 0:
            return None
        p = math.sqrt(p2)
        phi = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        return _mod2pi(phi - a), p, _mod2pi(phi - b)
    if word == "RSL":
        p2 = d * d - 2 + 2 * cab - 2 * d * (sa + sb)
        if p2 < 0:
            return None
        p = math.sqrt(p2)
        phi = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        return _mod2pi(a - phi), p, _mod2pi(b - phi)
    if word == "RLR":
        c = (6 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8
        if abs(c) > 1:
            return None
        p = _mod2pi(_TWO_PI - math.acos(c))
        t = _mod2pi(a - math.atan2(ca - cb, d - sa + sb) + p / 2)
        return t, p, _mod2pi(a - b - t + p)
    # LRL
    c = (6 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8
    if abs(c) > 1:
        return None
    p = _mod2pi(_TWO_PI - math.acos(c))
    t = _mod2pi(-a - math.atan2(ca - cb, d + sa - sb) + p / 2)
    return t, p, _mod2pi(b - a - t + p)


def dubins_path(start, goal, radius: float) -> DubinsPath:
    """The shortest Dubins curve from start to goal ((x [m], y [m], heading [rad]) each) with
    arcs of `radius` [m]."""
    if radius <= 0:
        raise ValueError(f"radius must be positive, got {radius}")
    dx, dy = goal[0] - start[0], goal[1] - start[1]
    d = math.hypot(dx, dy) / radius
    theta = math.atan2(dy, dx) if d > 0 else 0.0
    a, b = _mod2pi(start[2] - theta), _mod2pi(goal[2] - theta)
    best: tuple[float, str, tuple[float, float, float]] | None = None
    for word in _WORDS:
        tpq = _word_params(word, a, b, d)
        if tpq is not None and (best is None or sum(tpq) < best[0]):
            best = (sum(tpq), word, tpq)
    assert best is not None  # RSR and LSL always exist (p2 = (d + ...)^2-like, >= 0)
    _, word, tpq = best
    return DubinsPath(
        start=(float(start[0]), float(start[1]), float(start[2])),
        word=word,
        lengths=(tpq[0] * radius, tpq[1] * radius, tpq[2] * radius),
        radius=radius,
    )
