"""`roachplan scene list`, `scene check` and `scene build`, and writing a terrain mesh as
`scene build -o` and `mesh -o` do (marked as roachplan's, so a later -o may replace it)."""

from __future__ import annotations

import argparse
import os
import sys

from roachplan.experiments import WRITTEN_BY, check_output_file
from roachplan.scenes import SceneError, list_scenes

from ._flags import scene_options

MESH_WRITTEN = "a mesh roachplan wrote (it says so in its header)"
"""What `mesh -o` and `scene build -o` replace without --force: their own earlier output."""


def cmd_scene_list(args: argparse.Namespace) -> int:
    from roachplan.perception import load_yaml
    from roachplan.scenes import LIBRARY

    # The description as written (read, not built: listing answers at once; `scene check`
    # and the tests validate the library's files).
    for name in list_scenes():
        path = LIBRARY / f"{name}.yaml"
        raw = load_yaml(path.read_bytes(), path.name)
        print(f"{name:24s} {raw.get('description', '') if isinstance(raw, dict) else ''}")
    return 0


def cmd_scene_check(args: argparse.Namespace) -> int:
    from roachplan.scenes import build_world, load_scene

    failed = 0
    for name in args.files:
        try:
            world = build_world(scene_options(load_scene(name), args))
        except SceneError as exc:
            print(f"FAIL {name}: {exc}")
            failed += 1
            continue
        for note in world.notes:
            print(f"roachplan: {name}: {note}", file=sys.stderr)
        m, sc = world.mesh, world.scene
        size = "x".join(f"{v:.2f}" for v in m.extents) if len(m.faces) else "-"
        print(
            f"ok   {name}: {len(sc.terrain)} terrain object(s), {len(m.faces)} triangles, "
            f"{size} m, ground {'none' if sc.ground is None else f'{sc.ground:g} m'}; "
            f"start and goal stand on the terrain"
        )
    if failed:
        print(f"{failed} of {len(args.files)} scene file(s) failed", file=sys.stderr)
    return 1 if failed else 0


def export_mesh(mesh, out) -> None:
    """Write the mesh in the format out's suffix names, atomically (a failure leaves no
    half-written file), marked WRITTEN_BY where the format has room, so that a later -o may
    replace it without --force."""
    from roachplan.experiments import atomic_write

    fmt = out.suffix.lower().lstrip(".")
    if fmt == "obj":
        data = mesh.export(file_type="obj", header=WRITTEN_BY).encode()
    elif fmt == "glb":
        data = mesh.export(
            file_type="glb",
            tree_postprocessor=lambda tree: tree["asset"].update(
                generator=f"{WRITTEN_BY} (trimesh)"
            ),
        )
    else:
        data = mesh.export(file_type=fmt)
        if fmt == "stl":  # binary STL: 80 free bytes of header
            data = WRITTEN_BY.encode().ljust(80, b" ") + data[80:]
        elif fmt == "ply":  # a comment line after "ply" and "format ..."
            first, second, rest = data.split(b"\n", 2)
            data = b"\n".join((first, second, b"comment " + WRITTEN_BY.encode(), rest))
    atomic_write(out, data)


def scene_inputs(scene) -> list:
    """The files a scene is read from: never an output's target."""
    files = [scene.path]
    for o in scene.terrain:
        files.append(o.source)
        intrinsics = getattr(o.capture, "intrinsics", None)
        if isinstance(intrinsics, str | os.PathLike):
            files.append(intrinsics)
    return files


def cmd_scene_build(args: argparse.Namespace) -> int:
    from roachplan.scenes import build_terrain, load_scene

    scene = load_scene(args.scene)
    out = check_output_file(
        args.output,
        suffixes=(".stl", ".obj", ".ply", ".glb"),
        inputs=scene_inputs(scene),
        kind=MESH_WRITTEN,
        force=args.force,
    )
    terrain = build_terrain(scene_options(scene, args))
    for note in terrain.notes:
        print(f"roachplan: {note}", file=sys.stderr)
    mesh = terrain.mesh
    if len(mesh.faces) == 0:
        raise SceneError(f"scene {args.scene!r} has no terrain objects, only a ground plane")
    export_mesh(mesh, out)
    print(f"wrote {out}: {len(mesh.faces)} triangles, bounds {mesh.bounds.round(4).tolist()} m")
    return 0
