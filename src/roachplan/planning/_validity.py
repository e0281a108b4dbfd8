"""Which (x, y, yaw) states the robot may occupy on a terrain (Tong 2018, section 4.4).

A state is projected onto the terrain: a plane is fitted to the surface under the six feet, and
the body rests on that plane. The state is valid when
  (1) the body does not collide with the terrain,
  (2) the body is close to the ground (no pit under it),
  (3) every foot has ground within a tolerance below it (no leg over a pit or off an edge),
  (4) the support plane is no steeper than a limit,
and all sample points lie on the planner's height field (the scene's bounds plus a margin).
Where the terrain has no surface at all (no ground plane), a foot finds no ground (3).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ._config import ValidityConfig
from ._heightfield import HeightField

VALID, COLLISION, BODY_HEIGHT, FOOT, SLOPE, OFF_MAP = range(6)
CONDITION_NAMES = {
    VALID: "valid",
    COLLISION: "body collides with the terrain",
    BODY_HEIGHT: "body too far above the ground",
    FOOT: "a foot has no ground under it",
    SLOPE: "ground too steep",
    OFF_MAP: "outside the planning area",
}


@dataclass(frozen=True, kw_only=True, eq=False)
class Footprint:
    """The robot as the planner sees it: feet and the underside of its body, body frame [m]."""

    feet_xy: np.ndarray
    """(F, 2) foot positions, body frame [m]."""
    foot_names: tuple[str, ...]
    """(F,) names of the feet, for error messages."""
    body_length: float
    """Body extent along x [m]."""
    body_width: float
    """Body extent along y [m]."""
    body_clearance: float
    """Height of the body's underside above the support plane [m]."""
    leg_reach: float = 0.0
    """How far a foot's tip reaches from its hip [m]: the legs sweep the ground this far in
    front of and behind the hips, beside the body (0: the legs are not checked)."""

    @property
    def radius(self) -> float:
        """Distance from the body centre to the farthest point the checks sample [m]: how far
        a turn moves the footprint's outermost point."""
        local = _footprint_terms(self)[0]
        return float(np.max(np.hypot(local[:, 0], local[:, 1])))


@dataclass(frozen=True, kw_only=True)
class StateCheck:
    """Result of checking a batch of states."""

    code: np.ndarray
    """(N,) int: VALID or the first failed condition (COLLISION, BODY_HEIGHT, FOOT, SLOPE, OFF_MAP)."""
    worst_foot: np.ndarray
    """(N,) int: index of the foot with the least ground under it."""
    z_surface: np.ndarray
    """(N,) support-plane height under the body centre [m]."""

    @property
    def valid(self) -> np.ndarray:
        return self.code == VALID


@functools.lru_cache(maxsize=16)
def _footprint_terms(
    fp: Footprint,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What check_states needs of a footprint, computed once per footprint: sample points
    ((P, 2) feet, then body, then the legs' sweep, body frame [m]), the support-plane fit
    ((3, F) pseudo-inverse), and the plane's design matrices at the feet (F, 3), the body
    samples (B, 3) and the legs' sweep samples (L, 3; L = 0 without leg_reach)."""
    u = np.linspace(-fp.body_length / 2, fp.body_length / 2, 5)
    v = np.linspace(-fp.body_width / 2, fp.body_width / 2, 3)
    body = np.stack(np.meshgrid(u, v), axis=-1).reshape(-1, 2)
    legs = np.zeros((0, 2))
    if fp.leg_reach > 0:  # each side's line of hips, from the front foot's reach to the rear's
        xs = fp.feet_xy[:, 0]
        along = np.linspace(xs.min() - fp.leg_reach, xs.max() + fp.leg_reach, 7)
        sides = np.unique(np.round(fp.feet_xy[:, 1], 9))
        legs = np.array([(x, y) for y in sides for x in along])
    local = np.concatenate([fp.feet_xy, body, legs])
    design = np.column_stack([np.ones(len(fp.feet_xy)), fp.feet_xy])
    body_design = np.column_stack([np.ones(len(body)), body])
    leg_design = np.column_stack([np.ones(len(legs)), legs])
    return local, np.linalg.pinv(design), design, body_design, leg_design


CHUNK = 2048
"""States checked at once [-] (check_states)."""


def check_states(
    hf: HeightField, fp: Footprint, cfg: ValidityConfig, states: np.ndarray
) -> StateCheck:
    """Check states ((N, 3) x [m], y [m], yaw [rad]) against the four conditions, vectorised."""
    states = np.atleast_2d(np.asarray(states, dtype=np.float64))
    if states.shape[-1] != 3:
        raise ValueError(f"states must be (N, 3) x, y, yaw; got {states.shape}")
    if len(states) <= CHUNK:
        return _check_chunk(hf, fp, cfg, states)
    # States are checked each on its own, so in chunks whose temporaries stay in the caches
    # (a standable map checks 300,000 states at 35 points each: at once, about twice as slow).
    parts = [_check_chunk(hf, fp, cfg, states[k : k + CHUNK]) for k in range(0, len(states), CHUNK)]
    return StateCheck(
        code=np.concatenate([p.code for p in parts]),
        worst_foot=np.concatenate([p.worst_foot for p in parts]),
        z_surface=np.concatenate([p.z_surface for p in parts]),
    )


def _check_chunk(
    hf: HeightField, fp: Footprint, cfg: ValidityConfig, states: np.ndarray
) -> StateCheck:
    """check_states of states ((N, 3), float64)."""
    local, fit, design, body_design, leg_design = _footprint_terms(fp)
    c, s = np.cos(states[:, 2]), np.sin(states[:, 2])
    wx = states[:, None, 0] + c[:, None] * local[None, :, 0] - s[:, None] * local[None, :, 1]
    wy = states[:, None, 1] + s[:, None] * local[None, :, 0] + c[:, None] * local[None, :, 1]
    xy = np.stack([wx, wy], axis=-1)
    h, noise = hf.sample_with_noise(xy)  # (N, P), h NaN where there is no surface
    slack = np.minimum(cfg.noise_sigmas * noise, cfg.max_noise_slack)  # (N, P) [m]
    x0, x1, y0, y1 = hf.extent
    off_map = ((wx < x0) | (wx > x1) | (wy < y0) | (wy > y1)).any(axis=1)
    n_feet, n_body = len(fp.feet_xy), len(body_design)
    h_feet, h_body = h[:, :n_feet], h[:, n_feet : n_feet + n_body]
    h_legs = h[:, n_feet + n_body :]
    # Support plane z = a + b u + c v in body coordinates (u, v): a least-squares fit through
    # the ground under the feet; its pseudo-inverse is the same for every state.
    coef = np.nan_to_num(h_feet) @ fit.T  # (N, 3)
    plane_feet = coef @ design.T
    plane_body = coef @ body_design.T
    plane_legs = coef @ leg_design.T
    residual = h_feet - plane_feet  # < 0: ground below where the foot would be
    residual = np.nan_to_num(residual, nan=-np.inf)
    unsupported = residual < -(cfg.foot_tolerance + slack[:, :n_feet])
    # A plane fit cannot tell "front too high" from "rear too low"; among the feet that fail,
    # the one over the lowest ground is the one over the pit.
    worst_foot = np.where(
        unsupported.any(axis=1),
        np.argmin(np.where(unsupported, np.nan_to_num(h_feet, nan=-np.inf), np.inf), axis=1),
        np.argmin(residual, axis=1),
    )

    code = np.full(len(states), VALID)
    slope = np.degrees(np.arctan(np.hypot(coef[:, 1], coef[:, 2])))
    centre = len(body_design) // 2  # the middle body sample is the body centre
    checks = (
        (OFF_MAP, off_map),
        (FOOT, unsupported.any(axis=1)),
        (
            COLLISION,
            (
                h_body - plane_body
                > fp.body_clearance + cfg.collision_margin + slack[:, n_feet : n_feet + n_body]
            ).any(axis=1),
        ),
        (SLOPE, slope > cfg.max_slope_deg),
        # After the slope: on a steep curved ramp the legs' sweep uphill rises above the plane
        # through the feet, and "too steep" is the better explanation.
        (
            COLLISION,
            (h_legs - plane_legs > cfg.leg_clearance + slack[:, n_feet + n_body :]).any(axis=1),
        ),
        (
            BODY_HEIGHT,
            plane_body[:, centre] - np.nan_to_num(h_body[:, centre], nan=-np.inf)
            > cfg.body_band + slack[:, n_feet + centre],
        ),
    )
    # Later conditions only fill states no earlier condition has claimed: a foot over a pit
    # also tilts the support plane into the body, and the foot is the better explanation.
    for cond, failed in checks:
        code = np.where((code == VALID) & failed, cond, code)
    return StateCheck(code=code, worst_foot=worst_foot, z_surface=coef[:, 0])


def describe_state(hf: HeightField, fp: Footprint, cfg: ValidityConfig, state: np.ndarray) -> str:
    """Human-readable verdict for one state, naming the failed condition and foot."""
    r = check_states(hf, fp, cfg, np.asarray(state, dtype=float)[None])
    code = int(r.code[0])
    text = CONDITION_NAMES[code]
    if code == FOOT:
        text += f" (leg {fp.foot_names[int(r.worst_foot[0])]})"
    return text
