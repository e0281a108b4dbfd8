"""Files a person loads into the app: each becomes a scene file in its own folder, so that every
part of roachplan (planning, driving, batch workers, `roachplan trial`) can rebuild it.

Safety: an upload is size-limited (checked when the transfer starts and as its parts arrive);
it is written into a fresh folder under the app's upload directory under a sanitised name; a
.scad runs confined to that folder with a time limit (scenes/_openscad.py); an uploaded scene
.yaml may use only the files beside it (a copy of the scene library is put there).
"""

from __future__ import annotations

import math
import re
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from roachplan.perception import CAPTURE_SUFFIXES, input_kind, load_yaml
from roachplan.scenes import DEFAULT_BACKEND, DEFAULT_TIMEOUT, LIBRARY, MESH_SUFFIXES, SceneError

if TYPE_CHECKING:
    from roachplan.scenes import OnCapture, World

MAX_UPLOAD_BYTES = 64 * 1024 * 1024
"""Largest file the app accepts [bytes] (a 1920x1080 organized PCD is ~25 MB)."""
SCAD_TIMEOUT = DEFAULT_TIMEOUT
"""Default time limit of an uploaded model's OpenSCAD render [s] (the command line's; the
page's load panel sets another)."""
UPLOAD_SUFFIXES = tuple(
    sorted({".scad", ".yaml", ".yml", ".zip", *MESH_SUFFIXES, *CAPTURE_SUFFIXES})
)
DEPTH_IMAGE_SUFFIXES = (".png", ".pgm", ".ppm")
"""Captures that need intrinsics (a pending calibration applies to them)."""


def safe_name(name: str) -> str:
    """The file's base name with anything but letters, digits, '.', '-', '_' replaced."""
    base = Path(name.replace("\\", "/")).name or "upload"
    return re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip(".") or "upload"


def scene_from_upload(
    name: str,
    data: bytes,
    root: Path,
    capture: dict,
    *,
    calibration: Path | None = None,
    scad_timeout: float = SCAD_TIMEOUT,
    scad_backend: str = DEFAULT_BACKEND,
) -> Path:
    """Write an uploaded file into a fresh folder under root and return the scene .yaml that
    uses it. capture: perception settings for captures (method, voxel, intrinsics, ...).
    calibration: a calibration file uploaded before a depth image (copied beside it and used as
    its intrinsics). scad_timeout: the OpenSCAD time limit of a .scad or .zip [s];
    scad_backend: who renders it (a scad object's `backend:`, written only when not the default,
    auto).

    A .yaml is the scene itself; a .scad or mesh becomes a terrain object on a ground plane; a
    .zip holds a .scad (at its top level) with its includes and data files, or a capture with
    its calibration file (loaded together); a capture becomes a
    capture object without a ground (the captured floor is the ground). Start, goal and bounds
    are left out: `prepare_upload_scene` picks them.
    """
    fname, suffix = _accepted(name, data)
    folder = Path(tempfile.mkdtemp(prefix="upload-", dir=root))
    if suffix in (".yaml", ".yml"):
        return _uploaded_scene(fname, data, folder)
    scad: dict[str, object] = {"timeout": scad_timeout}  # (a .scad object's keys)
    scad.update({"backend": scad_backend} if scad_backend != DEFAULT_BACKEND else {})
    if suffix == ".zip":
        obj = _zip_object(name, data, folder, capture=capture, scad=scad)
    else:
        (folder / fname).write_bytes(data)
        obj = _file_object(fname, folder, capture=capture, calibration=calibration, scad=scad)
    is_capture = "capture" in obj
    fname = obj["capture"] if is_capture else fname  # (a capture in a .zip names the scene)
    scene = {
        "description": f"Loaded from {name}",
        "terrain": [obj],
        "ground": None if is_capture else 0.0,
        "seed": 0,
    }
    path = folder / f"{Path(fname).stem}.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    return path


def _accepted(name: str, data: bytes) -> tuple[str, str]:
    """(the upload's safe file name, its suffix in lower case), or SceneError saying why it is
    not accepted (too large, a suffix the app does not load)."""
    if len(data) > MAX_UPLOAD_BYTES:
        raise SceneError(
            f"{name}: {len(data) / 1e6:.1f} MB is over the {MAX_UPLOAD_BYTES / 1e6:.0f} MB limit"
        )
    fname = safe_name(name)
    suffix = Path(fname).suffix.lower()
    if suffix not in UPLOAD_SUFFIXES:
        raise SceneError(
            f"{name}: cannot load {suffix or 'a file without extension'}; accepted: "
            f"{', '.join(UPLOAD_SUFFIXES)}"
        )
    return fname, suffix


def _uploaded_scene(fname: str, data: bytes, folder: Path) -> Path:
    """An uploaded scene .yaml, written into folder beside a copy of the library's files it
    may refer to; SceneError when it reaches outside the folder."""
    for f in LIBRARY.iterdir():  # library files an uploaded scene may refer to
        if f.is_file() and f.suffix != ".yaml":
            shutil.copy(f, folder / f.name)
    path = folder / fname
    path.write_bytes(data)
    _check_sources_inside(path, folder)
    return path


def _capture_object(fname: str, capture: dict) -> dict:
    """The terrain object of a capture file (its perception settings, unless none)."""
    return {"capture": fname, **({"perception": capture} if capture else {})}


def _zip_object(name: str, data: bytes, folder: Path, *, capture: dict, scad: dict) -> dict:
    """The terrain object of an uploaded .zip, extracted into folder: its .scad model (with
    the `scad` keys: timeout, backend) or, without one, its capture with its calibration."""
    from ._archive import capture_in_zip, extract_zip, scad_model

    paths = extract_zip(name, data, folder)
    has_scad = any(p.suffix.lower() == ".scad" for p in paths)
    found = None if has_scad else capture_in_zip(name, paths, CAPTURE_SUFFIXES)
    if found is None:
        return {"scad": scad_model(name, paths, folder), **scad}
    fname, calib = found  # a capture with its calibration, loaded together
    capture = dict(capture)
    if calib is not None:
        capture["intrinsics"] = calib
    return _capture_object(fname, capture)


def _file_object(
    fname: str,
    folder: Path,
    *,
    capture: dict,
    calibration: Path | None,
    scad: dict,
) -> dict:
    """The terrain object of an uploaded model, mesh or capture file (written into folder as
    fname), by what the file is (perception.input_kind, as the command line and the scene
    loader decide it): a .scad with the `scad` keys (timeout, backend); a capture with the
    calibration uploaded before it, when it is a depth image."""
    found = input_kind(folder / fname)
    assert found is not None  # (_accepted took only UPLOAD_SUFFIXES: .yaml and .zip go elsewhere)
    if found.kind == "capture":
        capture = dict(capture)
        if calibration is not None and found.is_depth_image:
            calib = safe_name(calibration.name)
            if calib == fname:
                calib = f"calibration-{calib}"
            shutil.copy(calibration, folder / calib)
            capture["intrinsics"] = calib
        return _capture_object(fname, capture)
    if found.kind == "model":
        return {"scad": fname, **scad}
    return {"mesh": fname}


def limit_uploads(server, max_bytes: int, refuse) -> None:
    """Make a viser server refuse an upload larger than max_bytes when it starts (before its
    parts are buffered), and drop one whose parts outgrow what it announced.
    refuse(client_id, name, size) says so."""
    from viser import _messages

    gui = server.gui
    ws = gui._websock_interface  # viser has no upload limit of its own (1.1)
    start, part = gui._handle_file_transfer_start, gui._handle_file_transfer_part

    def on_start(client_id, message) -> None:
        if message.size_bytes > max_bytes:
            refuse(client_id, message.filename, message.size_bytes)
            return
        start(client_id, message)

    def on_part(client_id, message) -> None:
        state = gui._current_file_upload_states.get(message.transfer_uuid)
        if state is not None and state["transferred_bytes"] + len(message.content) > max_bytes:
            gui._current_file_upload_states.pop(message.transfer_uuid, None)
            refuse(client_id, state["filename"], state["transferred_bytes"] + len(message.content))
            return
        part(client_id, message)

    ws.unregister_handler(_messages.FileTransferStartUpload, start)
    ws.unregister_handler(_messages.FileTransferPart, part)
    ws.register_handler(_messages.FileTransferStartUpload, on_start)
    ws.register_handler(_messages.FileTransferPart, on_part)


def _check_sources_inside(path: Path, folder: Path) -> None:
    """An uploaded scene may not reach outside its folder (absolute paths, '..')."""
    raw = load_yaml(path.read_bytes(), path.name, SceneError)
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


def prepare_upload_scene(scene_path: Path, *, on_capture: OnCapture | None = None) -> World:
    """Build the world of an uploaded scene. What the file leaves out (bounds, start, goal) is
    picked by build_world (scenes/_autopose.py: inside the largest standable region, joined by a
    plan; both at the centre, with the reason in world.notes, when none is found) and written
    back into the file, so batch workers and `roachplan trial` rebuild the same world without
    picking again. Returns the World (its notes say what was picked). on_capture: told of each
    capture's reconstruction as the terrain is built (roachplan.scenes.OnCapture)."""
    from roachplan.scenes import build_terrain, build_world, load_scene

    raw = load_yaml(scene_path.read_bytes(), scene_path.name, SceneError)
    scene = load_scene(scene_path)
    # The same picking as the command line's: a model on a ground plane gets the ground round
    # it and start and goal at either end of it (scenes/_autopose.py).
    world = build_world(
        scene, check_poses=False, terrain=build_terrain(scene, on_capture=on_capture)
    )
    filled = {}
    if not isinstance(raw.get("robot"), dict) or raw["robot"].get("start") is None:
        filled["robot"] = {**(raw.get("robot") or {}), "start": _pose_yaml(world.start)}
        filled["goal"] = _pose_yaml(world.goal)
    if raw.get("bounds") is None:
        filled["bounds"] = [[round(float(v), 4) for v in corner] for corner in world.bounds]
    if filled:
        scene_path.write_text(yaml.safe_dump({**raw, **filled}, sort_keys=False))
        # Only what was picked was written: the same terrain, with the scene as now written.
        world = world.with_scene(load_scene(scene_path))
    return world


RENDERERS = {
    "cgal": "OpenSCAD",
    "manifold": "Manifold",
    "auto": "Manifold or, where it must, OpenSCAD",
}
"""Who renders a model, by its `backend:`, as the page names it."""


def load_announcement(label: str, ref: str | Path) -> str:
    """What the page says while a scene (a file or a library name) loads: what is really done
    to each of its terrain files - a capture read and meshed, a model rendered (by whom, under
    which limit), a mesh read - not what an uploaded file's suffix suggests (a .zip may hold a
    capture or a model). label: the upload's or the picker's name; "Loading label" when the
    scene does not read (its load will say why)."""
    from roachplan.scenes import load_scene

    try:
        scene = load_scene(ref)
    except (SceneError, OSError, ValueError):
        return f"Loading {label}"
    said = []
    for obj in scene.terrain:
        if obj.kind == "capture":
            said.append(f"reading and meshing the capture {obj.source.name}")
        elif obj.kind == "scad":
            who = RENDERERS.get(obj.backend, f"OpenSCAD (backend {obj.backend})")
            said.append(f"rendering {obj.source.name} with {who} (limit {obj.timeout:g} s)")
        else:
            said.append(f"reading the mesh {obj.source.name}")
    if not said:
        return f"Loading {label}"
    text = "; ".join(dict.fromkeys(said))  # (each once, in order)
    if Path(label.split(": ", 1)[-1]).name in text:  # the label's file is named already
        return text[0].upper() + text[1:]
    return f"{label}: {text}"


def _pose_yaml(pose) -> list[float]:
    """(x [m], y [m], yaw [rad]) as a scene file writes it: [x, y, yaw_deg]."""
    return [round(float(pose[0]), 4), round(float(pose[1]), 4), round(math.degrees(pose[2]), 3)]


PLACE_THEM = (
    "place them yourself: set Start and goal → Click places to start and click the terrain "
    "where the robot is to start, then to goal and click where it is to go; View → Show where "
    "it can stand shows the places the robot can stand"
)
"""What the page offers where the command line says "give start and goal"."""
PAGE_ADVICE = (
    # perception: units, depth scale, disparity, intrinsics, size
    (
        r"pass units mm \(--units mm\), or units m \(--units m\) if it really is in metres",
        "set Meshing (captures) → Cloud units to mm and load the file again (or to m if it "
        "really is in metres)",
    ),
    (
        r"pass --depth-scale ([0-9.eE+-]+) \(depth_scale: [0-9.eE+-]+ in a scene\)",
        r"set Camera (next capture) → Depth scale [units/m] to \1 and load the file again",
    ),
    (
        r"check the depth scale(?: \(--depth-scale\))?",
        "check Camera (next capture) → Depth scale [units/m] and Depth units, and load the file "
        "again",
    ),
    (
        r"pass --depth-units kinect-disparity \(depth_units: kinect-disparity in a scene\)",
        "set Camera (next capture) → Depth units to kinect-disparity and load the file again",
    ),
    (
        r"pass its depth scale \(--depth-scale N; 1000 for millimetres\)",
        "set Camera (next capture) → Depth scale [units/m] (1000 for millimetres) and load the "
        "file again",
    ),
    (
        r"both a depth scale \(([0-9.eE+-]+)\) and depth units \(([\w-]+)\) were given: (.*?); "
        r"give one of them",
        r"both Depth scale [units/m] (\1) and Depth units (\2) were set: \3; set Camera (next "
        r"capture) → Depth scale [units/m] to 0 or Camera (next capture) → Depth units to auto",
    ),
    (
        r"pass --intrinsics with a preset \(([^)]*)\) or a calibration file, or the numbers "
        r"--fx --fy --cx --cy .*? beside it",
        r"choose its camera in Camera (next capture) → Camera (\1, or numbers below: fx, fy, cx, "
        r"cy), or load its calibration file first, then the depth image again",
    ),
    (
        r"crop it \(crop / --crop\) or use a larger voxel \(--voxel\)",
        "tick Meshing (captures) → Crop and set its box, or set a larger Meshing (captures) → "
        "Voxel [m], then press Re-mesh loaded capture (or load the file again)",
    ),
    (
        r"a topic \(([^;]*); --topic, `topic:` in a scene\) was given, but only a bag \(([^)]*)\) "
        r"has topics",
        r"the scene file gives a topic (\1), but only a bag (\2) has topics: take it out and load "
        r"the scene again (Scene → Load file)",
    ),
    (
        r"depth units \(([^;]*); --depth-units, `depth_units:` in a scene\) were given, but only a "
        r"depth image \(([^)]*)\) has them",
        r"the scene file gives depth units (\1), but only a depth image (\2) has them: take them "
        r"out and load the scene again (Scene → Load file)",
    ),
    # perception: the ground
    (
        r"give the up direction \(--up\) or the camera pose, or click the ground in the page",
        "set Loaded capture → Up direction and press Re-mesh with this up direction, or tick "
        "Loaded capture → Pick ground and click the ground, or type the camera's height, pitch "
        "and roll in Loaded capture and press Re-mesh with this camera pose",
    ),
    (
        r"check the result, or give --up or the camera pose",
        "check the result; if it is wrong, set Loaded capture → Up direction and press Re-mesh "
        "with this up direction, or tick Loaded capture → Pick ground and click the ground",
    ),
    (
        r"check the up direction",
        "check Loaded capture → Up direction (then press Re-mesh with this up direction)",
    ),
    (
        r"click it in the page or give the camera pose",
        "tick Loaded capture → Pick ground and click it, or type the camera's height, pitch and "
        "roll in Loaded capture and press Re-mesh with this camera pose",
    ),
    (
        r"study one surface: --plane \(the dominant plane's points\), or a smaller "
        r"--square/--region",
        "study one surface: set Voxel study → Region to Ground plane, or a smaller Voxel study → "
        "Square side [m]",
    ),
    # scenes: models
    (
        r"add `scale: 0\.001` to this terrain object \(or --scale 0\.001\)",
        "press Scene → Scale x0.001 to load it in metres",
    ),
    (
        r"give this terrain object `timeout: SECONDS` \(or --scad-timeout SECONDS\), "
        r"at most ([0-9.]+)",
        r"raise Scene → OpenSCAD limit [s] (at most \1) and load it again",
    ),
    (
        r"render this model with `backend: cgal` \(--scad-backend cgal\), the openscad binary, or "
        r"`backend: auto`, which picks it",
        "set Scene → OpenSCAD backend to auto (or cgal) and load it again",
    ),
    (
        r"(?:render this model with|use) `backend: cgal`(?: \(--scad-backend cgal\))?"
        r"(?:, the openscad binary)?",
        "set Scene → OpenSCAD backend to cgal (the openscad binary) and load it again",
    ),
    (
        r"raise it with `position: \[x, y, z\]`, or give `ground: null` if it has its own floor"
        r"(?: in a scene file)?",
        "raise it with Loaded model → Position [m], or untick Loaded model → Ground plane if it "
        "has its own floor, and press Loaded model → Reload model with these",
    ),
    # scenes: the planning area, start and goal
    (
        r"\(set bounds, or crop\)",
        "(to plan elsewhere: set Planning area → Min x, y [m] and Max x, y [m] and press "
        "Planning area → Reload with this area; for a capture, also Meshing (captures) → Crop)",
    ),
    (
        r"give bounds: the scene has no terrain to take them from",
        "the scene has no terrain to plan on: load a capture, a model or a scene with terrain "
        "(Scene → Load file)",
    ),
    (r"\bbounds: ([0-9.]+ m x [0-9.]+ m) is more than", r"the planning area, \1, is more than"),
    (
        r"give bounds at most ([0-9.]+ m x [0-9.]+ m) around the part the robot is to cross",
        r"set Planning area → Min x, y [m] and Max x, y [m] at most \1 apart, around the part "
        r"the robot is to cross, and press Reload with this area",
    ),
    (
        r"check the ground found, or give start and goal",
        f"check the ground found (for a capture, with Loaded capture → Pick ground), or "
        f"{PLACE_THEM}",
    ),
    (r"give start and goal", PLACE_THEM),
)
"""Advice written for the command line and scene files (perception, scenes and planning
messages) -> the same advice in the page's own controls (folder → control). Every piece of
advice that code can give has its entry here (tests/test_page_advice.py walks them)."""
_PATH = re.compile(r"(?<![\w.~-])(?:/[^\s/:'\"`,;()\[\]]+)+/([^\s/:'\"`,;()\[\]]+)")
"""An absolute path of two or more parts (the server's folders mean nothing in a browser)."""


def public_message(message: str, root: Path) -> str:
    """A message as a page shows it: a file is named by its own name, without the app's
    internal folders (upload folders, temporary and library paths), and command-line advice
    (`--depth-scale 1000`, `--crop`, `--scale 0.001`, ...) is given in terms of the page's
    controls. Idempotent (the app applies it to every notification)."""
    text = str(message)
    root = Path(root)
    for base in {str(root), str(root.resolve())}:
        text = re.sub(re.escape(base) + r"/upload-[^/\s]+/", "", text)
        text = text.replace(base + "/", "")
    text = _PATH.sub(r"\1", text)
    # "x.yaml: terrain[0].capture: x.pcd: ..." -> "x.pcd: ...": the file's own message names
    # it; the scene file around an upload is the app's.
    text = re.sub(
        r"^[\w.-]+\.ya?ml: terrain\[\d+\]\.(?:capture|mesh|scad): (?=[\w.-]+: )", "", text
    )
    text = re.sub(r"^([\w.-]+: )\1+", r"\1", text)  # (a file named twice over, once)
    for pattern, page in PAGE_ADVICE:
        text = re.sub(pattern, page, text)
    # Anything else written for the command line: an aside naming only a flag goes, and a flag
    # elsewhere is named as its setting (`--near 0.3` -> `near 0.3`).
    text = re.sub(r" ?\((?:or )?--[a-z][\w-]*(?: [^()]*)?\)", "", text)
    return re.sub(r"(?<![\w-])--([a-z][\w-]*)", r"\1", text)
