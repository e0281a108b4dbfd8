"""Drivable paths: a planned polyline turned into arcs no tighter than the robot can walk and
straight lines, every state on it checked (issue 18).

The planners search (x, y, yaw) with straight motions; the roach instead drives forward on
arcs whose radius is at least its minimum turning radius. We keep the planner's route and make
it drivable by Dubins shortcutting: key poses sit on the route's vertices, heading along the
route (the start keeps the robot's real heading), and from each key pose we join the farthest
later key pose whose Dubins curve is valid at every `step` and not much longer than the route
it replaces. Where even the next key pose cannot be joined (a corner too sharp for the space
round it), the route between them is split at its middle, a few times at most. Then, if turns on
the spot are allowed (spin_margin), the robot turns on the spot at the key pose it stands on to
face the farthest later key pose a straight line reaches, walks that line and goes on from
there, preferring arcs again; else the route is given up as undrivable. A plan that needs no
spin is the same as without them. Every state of the result, and every heading a spin passes
through (round its point, within spin_margin), has been checked by the same validity checker as
the planner's, with the yaw of the curve, so the result is valid by construction.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ._dubins import dubins_path

DETOUR = 1.5
"""A shortcut may be at most this much longer than the route it replaces, plus one full turn
at the radius: longer ones loop round (a Dubins curve is the shortest forward-only path, but
between far-apart key poses it can circle) [-]."""
MAX_SPLITS = 4
"""Times a route segment that cannot be joined is halved before the route is given up (or,
with spins allowed, before the robot turns on the spot) [-]."""
EITHER_WAY = 0.3
"""A spin within this of half a turn is checked both ways round [rad]: the gait sways the
heading by up to 0.12 rad while the roach spins (sim/_turning.py), so the driver, which turns
the shorter way, may set off either way."""
MARGIN_RINGS = ((0.5, 6), (1.0, 12))
"""Where a spin is checked besides its point: rings at these fractions of spin_margin, with
this many points each (1.6 cm apart at a 3 cm margin) [-]."""


@dataclass(frozen=True, kw_only=True, eq=False)
class DrivablePath:
    """A drivable path: arcs, straight lines and turns on the spot."""

    states: np.ndarray
    """(N, 3) x [m], y [m], heading [rad], world frame, every <= step along the path; a spin
    is two states at the same (x, y), the heading before it and the heading after."""
    spins: tuple[int, ...] = ()
    """Indices k into states where a spin begins: states[k + 1] is states[k] turned on the
    spot [-]."""


def _key_poses(xy: np.ndarray, start_yaw: float) -> np.ndarray:
    """(K, 3) poses on the polyline's vertices: the start at start_yaw, the others heading
    along the route (the mean direction of the segments in and out, the last along its in)."""
    seg = np.diff(xy, axis=0)
    heading = np.arctan2(seg[:, 1], seg[:, 0])
    yaw = np.empty(len(xy))
    yaw[0] = start_yaw
    for k in range(1, len(xy) - 1):
        a, b = heading[k - 1], heading[k]
        yaw[k] = a + math.remainder(b - a, 2 * math.pi) / 2
    yaw[-1] = heading[-1]
    return np.column_stack([xy, yaw])


def _dedup(xy: np.ndarray, tol: float) -> np.ndarray:
    keep = [0]
    for k in range(1, len(xy)):
        if np.linalg.norm(xy[k] - xy[keep[-1]]) > tol:
            keep.append(k)
    if keep[-1] != len(xy) - 1:  # the goal itself stays
        keep[-1] = len(xy) - 1
    return xy[keep]


def drivable_path(
    xy: np.ndarray,
    start_yaw: float,
    radius: float,
    is_valid: Callable[[np.ndarray], np.ndarray],
    step: float,
    *,
    spin_margin: float | None = None,
    spin_step: float = 0.1,
) -> DrivablePath | None:
    """A path of arcs of radius `radius` [m] and straight lines, sampled every <= step [m],
    that follows the route xy ((K, 2) [m], world frame, from start to goal) and is valid at
    every state under is_valid ((N, 3) -> (N,) bool); None when no such path follows this
    route. spin_margin [m]: where no arc goes on, the robot may turn on the spot, every heading
    of the turn checked every spin_step [rad] at the spin's point and round it within
    spin_margin (how far the body centre wanders while it spins); None: arcs only."""
    xy = _dedup(np.asarray(xy, dtype=float)[:, :2], tol=step / 2)
    if len(xy) < 2:
        return None
    # Split each route segment that is long against the radius, so a blocked shortcut can fall
    # back to key poses close together.
    pts = [xy[0]]
    for a, b in zip(xy[:-1], xy[1:], strict=True):
        n = max(1, math.ceil(np.linalg.norm(b - a) / (4 * radius)))
        pts += [a + (b - a) * (k / n) for k in range(1, n + 1)]
    keys = list(_key_poses(np.array(pts), start_yaw))
    out = [keys[0][None, :]]
    n_out, spins = 1, []
    i, splits = 0, 0
    while i < len(keys) - 1:
        joined = _join_farthest(np.array(keys), i, radius, is_valid, step)
        if joined is not None:
            j, states = joined
            out.append(states[1:])
            n_out += len(states) - 1
            i, splits = j, 0
            continue
        if splits < MAX_SPLITS:
            # Nothing reaches even the next key pose: put one halfway along the route, retry.
            a, b = keys[i][:2], keys[i + 1][:2]
            keys.insert(i + 1, np.array([*(a + b) / 2, math.atan2(b[1] - a[1], b[0] - a[0])]))
            splits += 1
            continue
        if spin_margin is None:
            return None
        # The robot stands on the last state so far: key pose i, to the curve's rounding.
        here = out[-1][-1]
        turned = _spin_and_line(
            np.array(keys), i, here, is_valid, step=step, margin=spin_margin, yaw_step=spin_step
        )
        if turned is None:
            return None
        j, line = turned
        if abs(math.remainder(line[0, 2] - here[2], 2 * math.pi)) > 1e-9:
            spins.append(n_out - 1)
            out.append(line)  # its first state is the spin's end: key pose i turned on the spot
            n_out += len(line)
        else:  # already facing along the line
            out.append(line[1:])
            n_out += len(line) - 1
        keys[j] = line[-1]  # arrived along the line: go on from its heading
        i, splits = j, 0
    return DrivablePath(states=np.concatenate(out), spins=tuple(spins))


def spin_states(
    xy: np.ndarray, yaw_from: float, yaw_to: float, margin: float, yaw_step: float
) -> np.ndarray:
    """(M, 3) states a turn on the spot at xy ((2,) [m]) from heading yaw_from to yaw_to [rad]
    passes through, the shorter way round (both ways within EITHER_WAY of half a turn), every
    <= yaw_step [rad], at xy and on rings round it within `margin` [m] (MARGIN_RINGS)."""
    turn = math.remainder(yaw_to - yaw_from, 2 * math.pi)
    sweeps = [turn]
    if abs(turn) > math.pi - EITHER_WAY:
        sweeps.append(turn - math.copysign(2 * math.pi, turn))
    yaws = np.concatenate(
        [yaw_from + np.linspace(0.0, t, max(1, math.ceil(abs(t) / yaw_step)) + 1) for t in sweeps]
    )
    centres = [np.asarray(xy, dtype=float)]
    for fraction, count in MARGIN_RINGS:
        a = 2 * math.pi * np.arange(count) / count
        centres += list(xy + fraction * margin * np.column_stack([np.cos(a), np.sin(a)]))
    c = np.repeat(np.array(centres), len(yaws), axis=0)
    return np.column_stack([c, np.tile(yaws, len(centres))])


def _spin_and_line(
    keys: np.ndarray,
    i: int,
    here: np.ndarray,
    is_valid,
    *,
    step: float,
    margin: float,
    yaw_step: float,
):
    """(j, states) for the farthest key pose j > i that the robot, standing at `here` ((3,)
    pose on key pose i), reaches by turning on the spot to face it and walking the straight
    line there: states from the turned pose to key pose j's position, every <= step [m],
    heading along the line. None when no key pose is reached so (the turn or every line is
    invalid)."""
    for j in range(len(keys) - 1, i, -1):
        chord = keys[j, :2] - here[:2]
        length = float(np.hypot(*chord))
        if length < 1e-9:
            continue
        heading = math.atan2(chord[1], chord[0])
        f = np.linspace(0.0, 1.0, max(1, math.ceil(length / step)) + 1)[:, None]
        line = np.column_stack([here[:2] + f * chord, np.full(len(f), heading)])
        line[-1, :2] = keys[j, :2]  # exactly on the key pose, whatever the rounding
        if not bool(np.all(is_valid(line))):
            continue
        turn = spin_states(here[:2], float(here[2]), heading, margin, yaw_step)
        if bool(np.all(is_valid(turn))):
            return j, line
    return None


def _join_farthest(keys: np.ndarray, i: int, radius: float, is_valid, step: float):
    """(j, states) for the farthest key pose j > i that a valid, not-looping Dubins curve
    reaches from key pose i (trying the last, then halving the reach, then the rest); None
    when none does."""
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(keys[:, :2], axis=0), axis=1))])
    last = len(keys) - 1
    # The farthest first, then halving the reach: O(log K) curves a step, not O(K).
    # Then every other one, nearest first: a route into a corner is joined past the corner.
    reach = sorted({i + max(1, (last - i) >> k) for k in range(32)}, reverse=True)
    reach += [j for j in range(i + 1, last + 1) if j not in reach]
    for j in reach:
        ends = [keys[j]]
        if j == last:  # the goal's heading is free: also arrive straight from key pose i
            chord = keys[j, :2] - keys[i, :2]
            ends.append(np.array([*keys[j, :2], math.atan2(chord[1], chord[0])]))
        for end in ends:
            curve = dubins_path(keys[i], end, radius)
            if curve.length > DETOUR * float(cum[j] - cum[i]) + 2 * math.pi * radius:
                continue
            states = curve.sample(step)
            if bool(np.all(is_valid(states))):
                return j, states
    return None


def max_curvature(states: np.ndarray) -> float:
    """The largest |d heading / d s| along (N, 3) states (x, y, heading) [1/m], measured from
    the positions (the heading column is not trusted)."""
    d = np.diff(states[:, :2], axis=0)
    ds = np.linalg.norm(d, axis=1)
    ok = ds > 1e-9
    heading = np.arctan2(d[ok, 1], d[ok, 0])
    if len(heading) < 2:
        return 0.0
    dth = np.abs(np.remainder(np.diff(heading) + np.pi, 2 * np.pi) - np.pi)
    # A turn between two chords is spread over half of each.
    s_mid = (ds[ok][:-1] + ds[ok][1:]) / 2
    return float(np.max(dth / s_mid))
