"""Backend manifold: openscad-evaluator on the Manifold library (scenes/_manifold_main.py), run
in the same jail and under the same limits as the binary; what it renders differently from the
binary (refused or left to the binary), the checks of its meshes, its versions and its jail.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import re
import shutil
import sys
from collections.abc import Mapping
from pathlib import Path

from ._errors import SceneError
from ._scad_sandbox import (
    JAIL_MODEL,
    JAIL_OUT,
    RUNTIME_DATA,
    jail_layout_of,
    program_libraries,
    shared_libraries,
)
from ._scad_source import ScadValue, first_call, scad_literal

MANIFOLD_DIFFERS = {
    "surface": "its base is at z = 0, not 1 below the lowest height as in OpenSCAD",
}
"""Constructs whose mesh under backend manifold differs from the reference binary's, measured
by benchmarks/bench_openscad.py (construct -> how): a model calling one renders with the
binary under auto, and is refused under manifold."""
MANIFOLD_CHECKED = {
    "polyhedron": "a polyhedron that is open, or wound both ways, is no solid there, while "
    "the binary may still export it as it is",
}
"""Constructs that differ only sometimes: allowed, but a model calling one must come out
closed and outward (a polyhedron wound either way throughout agrees: _manifold_main.py turns
one wound the other way outward). Found by the scan, not evaluated: a model whose polyhedra
are all solid but that also makes open geometry (touching solids) fails the check too, and
renders with the binary (auto) or is refused (manifold)."""
TEXT_DEVIATION = 1.5e-3
"""How far a text() glyph drawn by backend manifold may sit from the binary's, per unit of
the size given to text() [model units per model unit]. Measured: benchmarks/bench_openscad.py
--text (2 strings of 15 and 54 glyphs, sizes 1 to 100, every halign and valign, DejaVu Sans -
fontconfig's answer to OpenSCAD's Liberation Sans here - and stand-ins for DejaVu Sans Mono
Bold, Futura Bold and Liberation Serif): at most 1.01e-3 x size (0.10 at size 100), not growing
with the string's length; a public tile's labels (size 3, spacing 1.1, a bold stand-in),
1.1e-3 x size; the limit leaves a third more. What is left is FreeType's hinting in the
binary, which the evaluator does not reproduce; before _manifold_main.py's text patch (the
evaluator's own Liberation Sans, HarfBuzz's positions unscaled) 14 glyphs at size 10 sat up to
2.5 apart, more the longer the string."""

FLAT_STAND_IN_HEIGHT = 1.0
"""How thick openscad-evaluator makes a model whose top level is 2-D [model units]: it exports
its preview, the shape extruded 1 unit up from where it lies, where the binary refuses the
model ("Current top level object is not a 3D object"). Seen: `square(1);` came out a 1 x 1 x 1
cube of 12 triangles."""


def flat_stand_in(mesh_path: Path) -> bool:
    """Whether backend manifold's mesh may be the evaluator's stand-in for a 2-D top level: a
    slab FLAT_STAND_IN_HEIGHT thick whose vertices all lie on its top or its bottom. A solid
    extruded by that much looks the same: the model is then asked for as a drawing
    (_openscad.py: the evaluator writes SVG of a 2-D model only) before it is refused."""
    import numpy as np
    import trimesh

    z = np.asarray(trimesh.load_mesh(mesh_path, process=False).vertices, dtype=np.float64)[:, 2]
    if len(z) == 0:
        return False
    lo, hi = float(z.min()), float(z.max())
    tol = 1e-6 * max(1.0, abs(lo), abs(hi))  # (the STL's float32 coordinates)
    on_faces = (np.abs(z - lo) <= tol) | (np.abs(z - hi) <= tol)
    return abs(hi - lo - FLAT_STAND_IN_HEIGHT) <= tol and bool(on_faces.all())


MANIFOLD_PACKAGES = ("openscad-evaluator", "manifold3d")
"""The distributions backend manifold runs (with what they require)."""
_MANIFOLD_MAIN = Path(__file__).with_name("_manifold_main.py")
"""The evaluator's entry point in the jail (standard library only until it imports it)."""


def manifold_differs(scad_file: Path) -> str:
    """What in the model (or a file it includes or uses) backend manifold renders differently
    from the binary (MANIFOLD_DIFFERS), where and how; "" if nothing."""
    found = first_call(scad_file, MANIFOLD_DIFFERS)
    if found is None:
        return ""
    path, line, name = found
    return (
        f"{name}() ({path.name}, line {line}) is rendered differently by manifold "
        f"({MANIFOLD_DIFFERS[name]})"
    )


def manifold_problem(scad_file: Path) -> str:
    """Why backend manifold must not render this model, or "" if it may: the model, or a file
    it includes or uses, calls a construct of MANIFOLD_DIFFERS."""
    found = first_call(scad_file, MANIFOLD_DIFFERS)
    if found is None:
        return ""
    path, line, name = found
    return (
        f"{path}, line {line}: {name}() is not rendered alike by backend manifold "
        f"({MANIFOLD_DIFFERS[name]}); render this model with `backend: cgal` "
        f"(--scad-backend cgal), the openscad binary, or `backend: auto`, which picks it"
    )


def manifold_mesh_problem(scad_file: Path, mesh: Path) -> str:
    """Why the evaluator's mesh of the model cannot stand for the binary's, or "" if it can:
    solids that touch face to face kept apart (Manifold treats touching as not overlapping,
    so two walls stay back to back inside the solid; the binary's CGAL merges them: on
    plywood_bridge, whose blocks, plank and ramps touch, 151 of 20,000 surface samples lay on
    such walls, up to 6.7 cm from the binary's surface); and, for a model calling a
    MANIFOLD_CHECKED construct, a mesh that is not closed and outward. Openness alone is not
    checked elsewhere: the binary's own mesh of solids touching along an edge is open too
    (voxel_wall)."""
    import trimesh

    m = trimesh.load_mesh(mesh)  # (what trimesh.load(mesh, force="mesh") does, typed)
    where = _touching_walls(m)
    if where is not None:
        x, y, z = (f"{c:.4g}" for c in where)
        return (
            f"{scad_file}: solids that touch face to face (near [{x}, {y}, {z}]) stay apart "
            f"in backend manifold, walls inside the solid, where the binary merges them; "
            f"render this model with `backend: cgal` (--scad-backend cgal), the openscad "
            f"binary, or `backend: auto`, which picks it"
        )
    found = first_call(scad_file, MANIFOLD_CHECKED)
    if found is None or (m.is_watertight and m.is_winding_consistent and m.volume > 0):
        return ""
    path, line, name = found
    return (
        f"{path}, line {line}: {name}(): backend manifold made an open or inside-out mesh "
        f"({MANIFOLD_CHECKED[name]}); render this model with `backend: cgal` "
        f"(--scad-backend cgal), the openscad binary, or `backend: auto`, which picks it"
    )


def _touching_walls(mesh) -> tuple[float, float, float] | None:
    """A point [model units] where faces of mesh lie on one another back to back over some
    area (solids touching face to face, kept apart), or None if none do.
    Faces are grouped by their plane (normal and offset, rounded); a plane met from both
    sides is checked for overlap in 2D. Faces merely meeting at an edge do not count."""
    import numpy as np

    if len(mesh.faces) == 0:
        return None
    size = float(max(mesh.extents)) or 1.0
    n, c = mesh.face_normals, mesh.triangles_center
    d = np.einsum("ij,ij->i", n, c)
    keys = np.column_stack([np.round(n * 1e4), np.round(d / (1e-6 * size))]).astype(np.int64)
    groups: dict[tuple, list[int]] = {}
    for k, key in enumerate(map(tuple, keys)):
        groups.setdefault(key, []).append(k)
    for key, faces in groups.items():
        other = groups.get(tuple(-v for v in key))
        if other is None or key < tuple(-v for v in key):
            continue
        where = _overlap(mesh, n[faces[0]], faces, other, min_area=1e-8 * size * size)
        if where is not None:
            return where
    return None


def _overlap(mesh, normal, faces: list[int], other: list[int], min_area: float):
    """Where two sets of coplanar faces overlap by more than min_area [model units^2], in 3D,
    or None."""
    import numpy as np
    from shapely import Polygon, unary_union

    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)

    def region(ids):
        tris = mesh.triangles[ids]
        return unary_union([Polygon(np.column_stack([t @ u, t @ w])).buffer(0) for t in tris])

    common = region(faces).intersection(region(other))
    if common.area <= min_area:
        return None
    p = common.representative_point()
    offset = float(mesh.triangles[faces[0]][0] @ normal)
    x, y, z = (float(v) for v in p.x * u + p.y * w + offset * np.asarray(normal))
    return (x, y, z)


def _manifold_distributions() -> list:
    """The installed distributions of MANIFOLD_PACKAGES and everything they require."""
    from importlib import metadata

    found, seen = [], set()
    todo: list[str] = list(MANIFOLD_PACKAGES)
    while todo:
        name = todo.pop()
        key = re.sub(r"[-_.]+", "-", name).lower()
        if key in seen:
            continue
        seen.add(key)
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            raise SceneError(
                f"backend manifold needs the Python package {name!r}, which is not installed "
                f"(pip install openscad-evaluator manifold3d, or reinstall roachplan); or use "
                f"`backend: cgal`, the openscad binary"
            ) from None
        found.append(dist)
        for req in dist.requires or []:
            if "extra ==" not in req:
                project = re.match(r"[A-Za-z0-9._-]+", req)
                assert project is not None  # (a requirement starts with the project's name)
                todo.append(project.group())
    return found


@functools.cache
def manifold_version() -> str:
    """The versions of the evaluator and of Manifold, for the cache key and messages."""
    dists = {
        re.sub(r"[-_.]+", "-", d.metadata["Name"]).lower(): d.version
        for d in _manifold_distributions()
    }
    return f"openscad-evaluator {dists['openscad-evaluator']}, manifold3d {dists['manifold3d']}"


@functools.cache
def _manifold_layout() -> tuple[str, list[str], dict[str, str], dict[str, str]]:
    """(interpreter, its sys.path in the jail, read-only binds, symlinks) that run the
    evaluator in the jail: the base Python program (not the venv's link to it) with its
    libraries and standard library, and, of site-packages, only the files of the evaluator's
    distributions (each package folder or module, read-only) and the system libraries their
    compiled modules load; and, for text(), fontconfig's `fc-match` with its libraries and
    the fonts and font settings the binary's jail shows (RUNTIME_DATA), so that the evaluator
    asks for a font where the binary does and gets the same one (_manifold_main.py)."""
    python = os.path.realpath(getattr(sys, "_base_executable", sys.executable))
    # The base interpreter's standard library (its lib-dynload inside), not a venv's folders.
    stdlib = os.path.realpath(os.path.dirname(os.__file__))
    shown: set[str] = set()
    for dist in _manifold_distributions():
        for f in dist.files or []:
            # Top-level entries of site-packages; `..` leads to scripts in bin/, not needed.
            if f.parts[0] not in ("..", "__pycache__"):
                shown.add(os.path.normpath(str(dist.locate_file(f.parts[0]))))
    paths = sorted({os.path.dirname(p) for p in shown})
    compiled = [
        os.path.join(root, f)
        for top in shown
        if os.path.isdir(top)
        for root, _, files in os.walk(top)
        for f in files
        if ".so" in f
    ] + [p for p in shown if p.endswith(".so")]
    libraries = set(program_libraries(python)) | shared_libraries(compiled)
    fc_match = shutil.which("fc-match")
    fonts = [fc_match, *program_libraries(fc_match), *RUNTIME_DATA] if fc_match else []
    ro, links = jail_layout_of(
        [
            python,
            *sorted(libraries),
            stdlib,
            *sorted(shown),
            str(_MANIFOLD_MAIN),
            "/dev/null",
            "/etc/ld.so.cache",
            *fonts,
        ]
    )
    return python, paths, ro, links


def manifold_argv(model: str, target: str) -> tuple[list[str], tuple[dict, dict]]:
    """The evaluator's command line rendering model (a path as the jail shows it) to the binary
    STL target, and the jail layout it needs."""
    python, paths, ro, links = _manifold_layout()
    # -I -S: no site, no .pth files, no user packages; only `paths` come on sys.path, and the
    # jail shows only the evaluator's own packages there.
    return [
        python,
        "-I",
        "-S",
        "-B",
        str(_MANIFOLD_MAIN),
        json.dumps(paths),
        model,
        "-o",
        target,
        "--export-format",
        "binstl",
    ], (ro, links)


def main_digest() -> str:
    """A digest of the evaluator's entry point, whose patches shape its meshes: a changed
    patch renders again rather than reuse a mesh the old one made."""
    return hashlib.sha256(_MANIFOLD_MAIN.read_bytes()).hexdigest()[:16]


def manifold_input(scad_file: Path, params: Mapping[str, ScadValue], work: Path, jail: bool) -> str:
    """The file the evaluator is given, as its process sees it: the model itself, or, with
    params, a wrapper in the output folder that includes the model and then assigns them. That
    is what `-D` does (the evaluator has no -D): an assignment after the model's own, the last
    one winning. The model's own relative paths still resolve from its folder."""
    model = f"{JAIL_MODEL}/{scad_file.name}" if jail else str(scad_file)
    if not params:
        return model
    wrapper = work / "out" / "_params.scad"
    wrapper.write_text(
        f"include <{model}>\n"
        + "".join(f"{k} = {scad_literal(v)};\n" for k, v in sorted(params.items()))
    )
    return f"{JAIL_OUT}/{wrapper.name}" if jail else str(wrapper)
