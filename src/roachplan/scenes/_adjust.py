"""Scene-wide changes a command line asks for: scale every model, give renders more time, pick
who renders them, pick the physics engine."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

from roachplan._settings import SettingError, setting_problem
from roachplan.sim import SimConfig, engine_driver, engine_settings

from ._errors import SceneError
from ._scene import Scene, backend_check, scale_problem, timeout_check


def scaled_scene(scene: Scene, factor: float | tuple[float, float, float]) -> Scene:
    """The scene with every terrain object's model scaled by factor (on top of its own
    `scale:`), about the model's origin, before it is placed: `--scale 0.001` loads models in
    millimetres. Positions, bounds, start and goal stay in metres."""
    _refuse("--scale", factor, scale_problem(factor))
    factors = tuple(factor) if isinstance(factor, tuple | list) else (factor,) * 3
    return dataclasses.replace(
        scene,
        terrain=tuple(
            dataclasses.replace(o, scale=tuple(s * f for s, f in zip(o.scale, factors)))
            for o in scene.terrain
        ),
    )


def with_scad_timeout(scene: Scene, timeout: float) -> Scene:
    """The scene with every OpenSCAD object's render time limit set to timeout [s]."""
    _refuse("--scad-timeout", timeout, timeout_check(timeout))
    return _every_scad(scene, timeout=float(timeout))


def with_scad_backend(scene: Scene, backend: str) -> Scene:
    """The scene with every OpenSCAD object rendered by backend ("auto", "cgal" or
    "manifold")."""
    _refuse("--scad-backend", backend, backend_check(backend))
    return _every_scad(scene, backend=backend)


def _refuse(flag: str, value, expected: str | None) -> None:
    """SceneError naming the flag when its setting's validator refused value."""
    if expected is not None:
        raise SceneError(f"{flag}: {SettingError('', value, expected).problem}")


def _every_scad(scene: Scene, **change) -> Scene:
    """The scene with `change` made to every OpenSCAD object."""
    return dataclasses.replace(
        scene,
        terrain=tuple(
            dataclasses.replace(o, **change) if o.kind == "scad" else o for o in scene.terrain
        ),
    )


_Sims = TypeVar("_Sims")


def with_engine(scene_or_spec: _Sims, engine: str) -> _Sims:
    """The scene (or experiment spec: anything with `sim:` and `driver:` configs) simulated by
    engine ("pybullet" or "mujoco") as that engine was calibrated: its timestep, and its turning
    curve for the driver (sim/_engine.py engine_settings, engine_driver). A scene file's
    `sim: {engine: ..., timestep: ...}` sets other combinations."""
    _refuse("--engine", engine, setting_problem(SimConfig, "engine", engine))
    held: Any = scene_or_spec
    return dataclasses.replace(
        held, sim=engine_settings(held.sim, engine), driver=engine_driver(held.driver, engine)
    )
