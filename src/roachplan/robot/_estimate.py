"""What the robot's own poses and commands say about it (issue 32): how its motors differ from
the model's, and the commands that make such motors run as the driver asks.

Pure functions of recorded arrays: poses ((K, 4): t [s], x, y [m], yaw [rad], world frame) and
the commands sent meanwhile ((M, 3): t [s], left, right [rad/s]; a stop frame 0, 0). The
look-ahead drives its rollouts with the mismatch (robot/_lookahead.py), and the robot loop
divides it out of the commands it sends (trim_commands).
"""

from __future__ import annotations

import math

import numpy as np

MIN_WALK = 0.1
"""The least distance the robot must have walked in the window for a mismatch estimate [m]."""


def estimate_mismatch(
    poses: np.ndarray, commands: np.ndarray, curve, max_ratio: float
) -> float | None:
    """The motors' mismatch d (left x (1 + d), right x (1 - d)) that explains how the robot
    turned while it was told to: poses ((K, 4): t [s], x, y [m], yaw [rad], world frame) and
    the commands sent meanwhile ((M, 3): t [s], left, right [rad/s]; walking ones, both sides
    forward) over one window. Its mean curvature (the heading's change over the distance
    walked) is the turn the robot's actual speed ratio drives on `curve` (a TurningCurve: the
    robot's calibrated one); the commands' mean log ratio is the turn it was asked for; the
    difference is ln((1 - d) / (1 + d)). None when it walked under MIN_WALK or was not told to
    walk. Small turns, where the curve is near linear in the log ratio, estimate best (the
    tracking driver's: it holds a drifting robot on its path by a steady counter-turn)."""
    estimate = window_mismatch(poses, commands, curve, max_ratio)
    return None if estimate is None else estimate[0]


def window_mismatch(
    poses: np.ndarray, commands: np.ndarray, curve, max_ratio: float
) -> tuple[float, float] | None:
    """(estimate_mismatch's d, the distance the body centre walked over the window [m]), or
    None where estimate_mismatch is None: the pair pooled_mismatch weighs."""
    poses, commands = np.asarray(poses, dtype=float), np.asarray(commands, dtype=float)
    if len(poses) < 2 or not len(commands):
        return None
    walking = (commands[:, 1] > 0) & (commands[:, 2] > 0)
    if not walking.any():
        return None
    walked = float(np.sum(np.linalg.norm(np.diff(poses[:, 1:3], axis=0), axis=1)))
    if walked < MIN_WALK:
        return None
    turned = float(np.sum(np.remainder(np.diff(poses[:, 3]) + math.pi, 2 * math.pi) - math.pi))
    kappa = turned / walked  # [1/m], positive to the left (the right side faster)
    actual = math.copysign(math.log(curve.ratio_for(abs(kappa), max_ratio)), kappa)
    asked = float(np.mean(np.log(commands[walking, 2] / commands[walking, 1])))
    return float(np.clip(-math.tanh((actual - asked) / 2), -0.5, 0.5)), walked


MISMATCH_PIECE = 1.0
"""straight_mismatches' stretches [s]: a window cut so that its straight walks are kept apart
from its turns."""
STRAIGHT_RATIO = 1.5
"""A stretch is walked near straight when the driver's mean motor-speed ratio is under this,
either way [-] (where the turning curve is still near linear in the log ratio)."""


def straight_mismatches(
    poses: np.ndarray, commands: np.ndarray, curve, max_ratio: float, *, piece=MISMATCH_PIECE
) -> list[tuple[float, float]]:
    """window_mismatch's (d, walked [m]) of each `piece`-second stretch of one window in which
    the driver asked the robot to walk near straight: poses ((K, 4): t [s], x, y [m], yaw
    [rad]), commands ((M, 4): t [s], left, right [rad/s] as sent, and the trim they were sent
    with: RobotLoop.trim, the driver having asked left x (1 + trim), right x (1 - trim)). A
    stretch with a turn on the spot in it is left out (its poses turn with the spin, which
    read as a walk's turn gave 0.35 for a twin's -0.12), and so is one whose driver's mean
    speed ratio is STRAIGHT_RATIO or more either way:
    in a hard turn the curve bends, and a floor that turns the robot less than the curve says
    (a slippery one) would be read as a mismatch of the motors; on the rough bridge the
    estimates of whole 3 s windows so scattered from 0.05 to 0.47 for a twin's 0.12."""
    poses, commands = np.asarray(poses, dtype=float), np.asarray(commands, dtype=float)
    out: list[tuple[float, float]] = []
    if len(poses) < 2 or not len(commands):
        return out
    t0 = float(poses[0, 0])
    for k in range(math.floor((float(poses[-1, 0]) - t0) / piece)):  # (whole stretches)
        a = t0 + k * piece
        p = poses[(poses[:, 0] >= a) & (poses[:, 0] <= a + piece)]
        c = commands[(commands[:, 0] >= a) & (commands[:, 0] < a + piece)]
        if (c[:, 1] * c[:, 2] < 0).any():  # (a turn on the spot: its poses' turn is no walk's)
            continue
        c = c[(c[:, 1] > 0) & (c[:, 2] > 0)]
        if len(p) < 2 or not len(c):
            continue
        trim = c[:, 3]
        asked = np.log(c[:, 2] / c[:, 1]) + np.log((1 - trim) / (1 + trim))  # (the driver's)
        if abs(float(np.mean(asked))) >= math.log(STRAIGHT_RATIO):
            continue
        estimate = window_mismatch(p, c[:, :3], curve, max_ratio)
        if estimate is not None:
            out.append(estimate)
    return out


PRIOR_WALK = 0.3
"""pooled_mismatch counts a mismatch of 0 as though the robot had walked this far with it [m]:
motors match until the walk says otherwise (a prior)."""


def pooled_mismatch(estimates) -> float | None:
    """The motors' mismatch from every window estimated so far: estimates ((d, walked [m])
    each, a window's estimate_mismatch and the distance walked in it), their sum weighted by
    the distance, over the distance plus PRIOR_WALK (a mean drawn towards 0 while little has
    been walked); None without any. A motor's mismatch holds for the whole leg, and one
    stretch's estimate scatters: on bench_guard's four twins (1,813 stretches of 1 s), by 0.10
    (standard deviation) round the twin's, and 1 in 20 by more than 0.2; the same on the level
    and on the 11 deg ramp. The plain mean of the first stretches was 0.15 or more off the
    twin's 7.6 % of the time (one run's first estimate: -0.37 for a twin's -0.08; trimmed by
    it, the robot went nowhere); drawn towards 0 by 0.3 m, 4.0 %, and 0.25 or more off 0.3 %
    (1.8 %), with the mean error over whole runs 0.052 (0.050). (Windows overlap when
    look-aheads come faster than the window, so a stretch walked counts in several: a running
    mean, not independent samples.)"""
    weights = sum(w for _, w in estimates)
    if not estimates or weights <= 0:
        return None
    return float(sum(d * w for d, w in estimates) / (weights + PRIOR_WALK))


def trim_commands(left: float, right: float, mismatch: float, limit: float) -> tuple[float, float]:
    """The motor speeds (left, right) [rad/s] to send to a robot whose motors run at
    left x (1 + mismatch), right x (1 - mismatch), so that they run at (left, right): each
    divided by its side's factor, both then scaled down together where one would pass `limit`
    [rad/s] (the motors' top speed: the ratio between the sides, which steers, is kept; the
    robot walks slower through that turn). A turn on the spot (the sides opposite) is trimmed
    the same way."""
    a, b = left / (1.0 + mismatch), right / (1.0 - mismatch)
    top = max(abs(a), abs(b))
    if top > limit > 0:
        a, b = a * limit / top, b * limit / top
    return a, b
