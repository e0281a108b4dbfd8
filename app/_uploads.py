"""Files a person loads into the app: each becomes a scene file in its own folder, so that every
part of roachplan (planning, driving, batch workers, `roachplan trial`) can rebuild it.

Safety: an upload is size-limited (checked when the transfer starts and as its parts arrive);
it is written into a fresh folder under the app's upload directory under a sanitised name; a
.scad runs confined to that folder with a time limit (scenes/_openscad.py); an uploaded scene
.yaml may use only the files beside it (a copy of the scene library is put there).
"""

from __future__ import annotations

import dataclasses
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np
import yaml

from perception import CAPTURE_SUFFIXES
from scenes import LIBRARY, MESH_SUFFIXES, SceneError

MAX_UPLOAD_BYTES = 64 * 1024 * 1024
"""Largest file the app accepts [bytes] (a 1920x1080 organized PCD is ~25 MB)."""
SCAD_TIMEOUT = 60.0
"""Time limit of an uploaded model's OpenSCAD render [s]."""
UPLOAD_SUFFIXES = tuple(sorted({".scad", ".yaml", ".yml", *MESH_SUFFIXES, *CAPTURE_SUFFIXES}))


def safe_name(name: str) -> str:
    """The file's base name with anything but letters, digits, '.', '-', '_' replaced."""
    base = Path(name.replace("\\", "/")).name or "upload"
    return re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip(".") or "upload"


def scene_from_upload(name: str, data: bytes, root: Path, capture: dict) -> Path:
    """Write an uploaded file into a fresh folder under root and return the scene .yaml that
    uses it. capture: perception settings for captures (method, voxel, intrinsics).

    A .yaml is the scene itself; a .scad or mesh becomes a terrain object on a ground plane; a
    capture becomes a capture object without a ground (the captured floor is the ground). The
    start and goal are placeholders until `with_poses` sets them.
    """
    if len(data) > MAX_UPLOAD_BYTES:
        raise SceneError(
            f"{name}: {len(data) / 1e6:.1f} MB is over the {MAX_UPLOAD_BYTES / 1e6:.0f} MB limit"
        )
    fname = safe_name(name)
    suffix = Path(fname).suffix.lower()
    if suffix not in UPLOAD_SUFFIXES:
        raise SceneError(f"{name}: cannot load {suffix or 'a file without extension'}; accepted: "
                         f"{', '.join(UPLOAD_SUFFIXES)}")  # fmt: skip
    folder = Path(tempfile.mkdtemp(prefix="upload-", dir=root))
    if suffix in (".yaml", ".yml"):
        for f in LIBRARY.iterdir():  # library files an uploaded scene may refer to
            if f.is_file() and f.suffix != ".yaml":
                shutil.copy(f, folder / f.name)
        path = folder / fname
        path.write_bytes(data)
        _check_sources_inside(path, folder)
        return path
    (folder / fname).write_bytes(data)
    if suffix == ".ply" and _ply_has_faces(data):
        obj = {"mesh": fname}
    elif suffix in CAPTURE_SUFFIXES:
        obj = {"capture": fname, "perception": capture}
    elif suffix == ".scad":
        obj = {"scad": fname, "timeout": SCAD_TIMEOUT}
    else:
        obj = {"mesh": fname}
    is_capture = "capture" in obj
    scene = {
        "description": f"Loaded from {name}",
        "terrain": [obj],
        "ground": None if is_capture else 0.0,
        "robot": {"start": [0.0, 0.0, 0.0]},
        "goal": [0.0, 0.0, 0.0],
        "bounds": [[-100.0, -100.0], [100.0, 100.0]],
        "seed": 0,
    }
    path = folder / f"{Path(fname).stem}.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    return path


def _ply_has_faces(data: bytes) -> bool:
    head = data[:4096].split(b"end_header", 1)[0]
    m = re.search(rb"element face (\d+)", head)
    return bool(m and int(m.group(1)) > 0)


def _check_sources_inside(path: Path, folder: Path) -> None:
    """An uploaded scene may not reach outside its folder (absolute paths, '..')."""
    try:
        raw = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path.name}: not valid YAML: {exc}") from None
    terrain = raw.get("terrain") if isinstance(raw, dict) else None
    for i, obj in enumerate(terrain if isinstance(terrain, list) else []):
        for kind in ("scad", "mesh", "capture"):
            ref = obj.get(kind) if isinstance(obj, dict) else None
            if isinstance(ref, str) and not (folder / ref).resolve().is_relative_to(
                folder.resolve()
            ):
                raise SceneError(
                    f"{path.name}: terrain[{i}].{kind}: {ref!r} is outside the upload; an uploaded "
                    f"scene may use only library files and files beside it"
                )


def prepare_upload_scene(scene_path: Path):
    """Build the world of a scene made by scene_from_upload: bounds from the terrain, a start
    and a goal where the robot can stand, 2/3 of the terrain apart along its longer side (left
    as the terrain's centre when none is found: the app then says why the markers are invalid).
    Rewrites the scene file; returns the World. An uploaded .yaml keeps its own poses."""
    from planning import VALID, check_states
    from scenes import build_terrain_mesh, build_world, load_scene

    raw = yaml.safe_load(scene_path.read_text())
    if not raw.get("description", "").startswith("Loaded from"):
        return build_world(load_scene(scene_path), check_poses=False)
    mesh = build_terrain_mesh(load_scene(scene_path))
    margin = 0.15
    lo, hi = mesh.bounds[0][:2] + margin, mesh.bounds[1][:2] - margin
    if np.any(hi <= lo):
        raise SceneError(
            f"{scene_path.name}: the terrain is too small for the robot ({mesh.extents.round(3).tolist()} m)"
        )
    centre = (lo + hi) / 2
    raw["bounds"] = [lo.round(3).tolist(), hi.round(3).tolist()]
    raw["robot"] = {"start": [*centre.round(3).tolist(), 0.0]}
    raw["goal"] = [*centre.round(3).tolist(), 0.0]
    scene_path.write_text(yaml.safe_dump(raw, sort_keys=False))
    world = build_world(load_scene(scene_path), check_poses=False, mesh=mesh)
    axis = 0 if (hi - lo)[0] >= (hi - lo)[1] else 1
    yaw = 0.0 if axis == 0 else np.pi / 2
    t = np.linspace(lo[axis], hi[axis], 80)
    states = np.column_stack([np.tile(centre, (len(t), 1)), np.full(len(t), yaw)])
    states[:, axis] = t
    ok = (
        check_states(world.heightfield, world.footprint, world.scene.planner.validity, states).code
        == VALID
    )
    span = (hi - lo)[axis]
    picks = np.flatnonzero(ok & (np.abs(t - centre[axis]) <= span / 3 + 1e-9))
    if len(picks) < 2:
        picks = np.flatnonzero(ok)
    if len(picks) < 2:
        return world
    a, b = states[picks[0]], states[picks[-1]]
    raw["robot"] = {"start": [round(float(a[0]), 3), round(float(a[1]), 3), float(np.degrees(yaw))]}
    raw["goal"] = [round(float(b[0]), 3), round(float(b[1]), 3), float(np.degrees(yaw))]
    scene_path.write_text(yaml.safe_dump(raw, sort_keys=False))
    # Only the poses changed: the same terrain and height field, with the scene as now written.
    return dataclasses.replace(world, scene=load_scene(scene_path))
