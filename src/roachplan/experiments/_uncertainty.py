"""The uncertainty a path is judged under (issue 17): what differs between one real run of the
robot and the next, and between the simulated robot and the real one.

A deterministic simulation drives a path once and answers yes or no; `choose` instead drives
each candidate many times, each rollout drawing its world from this model with its own
recorded seed (draw(cfg, seed) is a pure function), so any rollout re-runs exactly.

Defaults, and why:
- start: within 1 cm and 3 degrees of the start pose: the report's best-path re-drives jitter
  the start by this much (section 7.3), about how well the robot is placed by hand.
- friction: x U(0.8, 1.2): Coulomb friction of plywood and carpet under small plastic feet is
  known to about +-20 %, and changes with dust and wear.
- motor speed: x U(0.95, 1.05) on both sides: the report's motors run open loop at a set duty
  cycle; battery voltage moves their speed by about 5 % over a run.
- motor mismatch: left/right x U(0.97, 1.03) in opposite senses: two DC motors of one type
  differ by a few per cent, which turns a straight command into a slow curve.
- body mass: x U(0.9, 1.1) on the body: a payload (battery, camera) changes it by 10 %.
- terrain height (captures only): each mesh vertex up or down by N(0, (1.7 mm)^2): the Kinect
  v2's axial noise at 2 m in the noise model of the synthetic captures (perception/_synthetic.py,
  after Fankhauser et al. 2015: 1.5 - 0.5 z + 0.3 z^2 mm at depth z [m]). The measured mesh
  is one draw of the sensor's error; the real surface is as far from it again. No re-meshing:
  the vertices of the mesh already built move (each rollout builds a fresh PyBullet world
  anyway). The planner still sees the measured mesh, as it would on the real robot. An upper
  bound: the grid mesher averages several points per cell, which shrinks their error.

A scene file (or an experiment spec, over its scene's) sets any of these under `uncertainty:`
(start_xy [m], start_yaw [deg], friction, motor_speed, motor_mismatch, body_mass [-],
terrain_height [m]); the ranges accepted are sim.UNCERTAINTY_RANGES, checked where the YAML
is read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# The config itself lives in sim/ so that scene files can carry it (scenes/ may not import
# experiments/); re-exported here beside the reasons for its defaults.
from roachplan.sim import UncertaintyConfig  # noqa: F401 - re-exported


@dataclass(frozen=True, kw_only=True)
class WorldDraw:
    """One rollout's world: the values drawn from an UncertaintyConfig with one seed."""

    seed: int
    start_offset: tuple[float, float, float]
    """(dx [m], dy [m], dyaw [rad]) added to the start pose."""
    friction_scale: float
    mass_scale: float
    motor_gain: tuple[float, float]
    """(left, right) speed / command [-]."""

    def to_json(self) -> dict:
        return {
            "seed": self.seed,
            "start_offset": list(self.start_offset),
            "friction_scale": self.friction_scale,
            "mass_scale": self.mass_scale,
            "motor_gain": list(self.motor_gain),
        }


def draw(cfg: UncertaintyConfig, seed: int) -> WorldDraw:
    """The world of the rollout with this seed (the same seed, the same world)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, size=6)  # always six draws: turning one off moves no other
    r = cfg.start_xy * math.sqrt((u[0] + 1) / 2)  # uniform in the disc
    a = math.pi * u[1]
    speed = 1 + cfg.motor_speed * u[3]
    d = cfg.motor_mismatch * u[4]
    # u[5]: friction; the mass is drawn after the six.
    return WorldDraw(
        seed=int(seed),
        start_offset=(r * math.cos(a), r * math.sin(a), math.radians(cfg.start_yaw) * u[2]),
        friction_scale=1 + cfg.friction * u[5],
        mass_scale=1 + cfg.body_mass * float(rng.uniform(-1.0, 1.0)),  # the seventh
        motor_gain=(speed * (1 + d), speed * (1 - d)),
    )


def terrain_noise(cfg: UncertaintyConfig, seed: int, n: int) -> np.ndarray:
    """(n,) height offsets [m] of the n terrain vertices in the rollout with this seed: its
    own stream of the seed, so the seven draws of draw() stay as they were."""
    if cfg.terrain_height == 0:
        return np.zeros(n)
    return np.random.default_rng([seed, 1]).normal(0.0, cfg.terrain_height, size=n)


def rollout_seed(seed: int, candidate: int, k: int, stream: int = 0) -> int:
    """The seed of rollout k of candidate `candidate` in a choice seeded `seed`; stream 1 is
    --validate's fresh rollouts. Independent of the order rollouts run in."""
    return int(np.random.SeedSequence([seed, stream, candidate, k]).generate_state(1)[0])
