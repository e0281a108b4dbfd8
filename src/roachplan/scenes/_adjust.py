"""Scene-wide changes a command line asks for: scale every model, give renders more time, pick
who renders them."""

from __future__ import annotations

import dataclasses
import math

from ._errors import SceneError
from ._openscad import backend_problem
from ._scad_sandbox import timeout_problem
from ._scene import Scene


def scaled_scene(scene: Scene, factor: float | tuple[float, float, float]) -> Scene:
    """The scene with every terrain object's model scaled by factor (on top of its own
    `scale:`), about the model's origin, before it is placed: `--scale 0.001` loads models in
    millimetres. Positions, bounds, start and goal stay in metres."""
    factors = tuple(factor) if isinstance(factor, tuple | list) else (factor,) * 3
    if len(factors) != 3 or not all(
        isinstance(f, int | float) and not isinstance(f, bool) and 0 < f < math.inf for f in factors
    ):
        raise SceneError(
            f"--scale: expected a positive number (0.001 for models in millimetres), got {factor!r}"
        )
    return dataclasses.replace(
        scene,
        terrain=tuple(
            dataclasses.replace(o, scale=tuple(s * f for s, f in zip(o.scale, factors)))
            for o in scene.terrain
        ),
    )


def with_scad_timeout(scene: Scene, timeout: float) -> Scene:
    """The scene with every OpenSCAD object's render time limit set to timeout [s]."""
    return _every_scad(scene, "--scad-timeout", timeout_problem(timeout), timeout=float(timeout))


def with_scad_backend(scene: Scene, backend: str) -> Scene:
    """The scene with every OpenSCAD object rendered by backend ("auto", "cgal" or
    "manifold")."""
    return _every_scad(scene, "--scad-backend", backend_problem(backend), backend=backend)


def _every_scad(scene: Scene, flag: str, problem: str | None, **change) -> Scene:
    """The scene with `change` made to every OpenSCAD object; SceneError naming the flag when
    its value has a problem."""
    if problem:
        raise SceneError(f"{flag}: {problem}")
    return dataclasses.replace(
        scene,
        terrain=tuple(
            dataclasses.replace(o, **change) if o.kind == "scad" else o for o in scene.terrain
        ),
    )
