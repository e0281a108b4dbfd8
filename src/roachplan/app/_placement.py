"""Placing a loaded terrain again without uploading it: a model's position and ground plane, and
any loaded scene's planning area, typed in the page, become the scene file's `position:` (of its
one model), `ground:` and `bounds:`, and the scene is loaded again. A scene file the app did not
write (the library's, `serve --scene`'s) is never rewritten: a copy is (adopt_scene).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import yaml

from roachplan.perception import load_yaml
from roachplan.scenes import TERRAIN_SUFFIXES, Scene, SceneError, World, load_scene


@dataclass(frozen=True, kw_only=True)
class ModelView:
    """What the page keeps of a loaded terrain model (a scene of one mesh or .scad) to place
    it again."""

    scene_path: Path
    """Its scene file (or the model file itself, a scene of its own)."""
    model: str
    """The model file's name, for the panel."""
    position: tuple[float, float, float]
    """The model's `position` [m]."""
    ground: float | None
    """The ground plane's height [m]; None: no ground plane."""
    loaded: bool
    """False: the scene failed to load (placing it again may make it load)."""


def model_view(scene: Scene | str | Path, *, loaded: bool = True) -> ModelView | None:
    """The view of a scene (or scene file) of exactly one terrain model (mesh or .scad), else
    None (a capture, several objects, a file that does not read)."""
    if not isinstance(scene, Scene):
        try:
            scene = load_scene(scene)
        except (SceneError, OSError, ValueError):
            return None
    if len(scene.terrain) != 1 or scene.terrain[0].kind == "capture":
        return None
    obj = scene.terrain[0]
    x, y, z = obj.position
    return ModelView(
        scene_path=Path(scene.path),
        model=obj.source.name,
        position=(float(x), float(y), float(z)),
        ground=scene.ground,
        loaded=loaded,
    )


def planning_area(lo, hi) -> list[list[float]]:
    """The `bounds` of a typed planning area (min and max x, y [m]); ValueError naming the
    page's control when it is no area (one larger than the planner takes is refused by the
    load, in the page's words)."""
    (x0, y0), (x1, y1) = (tuple(float(v) for v in lo[:2]), tuple(float(v) for v in hi[:2]))
    if not all(map(math.isfinite, (x0, y0, x1, y1))) or not (x0 < x1 and y0 < y1):
        raise ValueError(
            f"Planning area: min ({x0:g}, {y0:g}) must be below max ({x1:g}, {y1:g}) in x and y [m]"
        )
    return [[round(x0, 4), round(y0, 4)], [round(x1, 4), round(y1, 4)]]


def adopt_scene(scene_path: str | Path, folder: Path) -> Path:
    """A copy in folder, which the app may rewrite, of a scene file from elsewhere (or of a
    terrain file as a scene of its own): its terrain files (and a capture's calibration file)
    by absolute path, its other keys kept."""
    scene = load_scene(scene_path)  # (resolves a library name; says what is wrong)
    path = Path(scene.path).resolve()
    if path.suffix.lower() in TERRAIN_SUFFIXES:
        obj = scene.terrain[0]
        raw = {
            "description": f"{path.name}, placed in the page",
            "terrain": [{obj.kind: str(path)}],
            "ground": scene.ground,
        }
    else:
        raw = load_yaml(path.read_bytes(), path.name, SceneError)
        for o in raw["terrain"]:
            kind = next(k for k in ("scad", "mesh", "capture") if k in o)
            o[kind] = str((path.parent / o[kind]).resolve())
            intrinsics = (o.get("perception") or {}).get("intrinsics")
            if isinstance(intrinsics, str) and (path.parent / intrinsics).is_file():
                o["perception"]["intrinsics"] = str((path.parent / intrinsics).resolve())
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{path.stem}.yaml"
    out.write_text(yaml.safe_dump(raw, sort_keys=False))
    return out


def rewrite_placement(
    scene_path: Path,
    *,
    position: Sequence[float] | None = None,
    ground: float | None | Literal["keep"] = "keep",
    bounds: list[list[float]] | None = None,
) -> None:
    """Set the scene file's model `position` ([x, y, z] [m]; None: kept), `ground` (a height
    [m], None for no ground plane, "keep") and `bounds` ([[x0, y0], [x1, y1]]; None: picked
    again); start and goal are dropped (picked again: the terrain or the area moved)."""
    raw = load_yaml(Path(scene_path).read_bytes(), Path(scene_path).name, SceneError)
    if position is not None:
        raw["terrain"][0]["position"] = [round(float(v), 4) for v in position]
    if ground != "keep":
        raw["ground"] = None if ground is None else round(float(ground), 4)
    raw.pop("bounds", None)
    if bounds is not None:
        raw["bounds"] = bounds
    for k in ("robot", "goal"):
        raw.pop(k, None)
    Path(scene_path).write_text(yaml.safe_dump(raw, sort_keys=False))


def area_of(world: World) -> tuple[tuple[float, float], tuple[float, float]]:
    """The loaded world's planning area ((x0, y0), (x1, y1)) [m], rounded for the page."""
    (x0, y0), (x1, y1) = world.bounds
    return (round(float(x0), 3), round(float(y0), 3)), (round(float(x1), 3), round(float(y1), 3))
