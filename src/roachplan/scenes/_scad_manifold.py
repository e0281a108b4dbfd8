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
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

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

if TYPE_CHECKING:
    from shapely.geometry.base import BaseGeometry

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
    solids that touch face to face kept apart, which merge_touching could not merge (two
    walls back to back inside the solid, where the binary's CGAL merges them: on
    plywood_bridge, before it was merged, 151 of 20,000 surface samples lay on such walls, up
    to 6.7 cm from the binary's surface); and, for a model calling a
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
    if found is None or _closed(m):
        return ""
    path, line, name = found
    return (
        f"{path}, line {line}: {name}(): backend manifold made an open or inside-out mesh "
        f"({MANIFOLD_CHECKED[name]}); render this model with `backend: cgal` "
        f"(--scad-backend cgal), the openscad binary, or `backend: auto`, which picks it"
    )


def _touching_walls(mesh) -> tuple[float, float, float] | None:
    """A point [model units] where faces of mesh lie on one another back to back over some
    area (solids touching face to face, kept apart), or None if none do."""
    for plane in _back_to_back(mesh):
        return plane.where
    return None


@dataclass(frozen=True)
class _Touching:
    """Faces of a mesh on one plane, seen from its two sides, that overlap: two solids touching
    face to face there."""

    faces: list[int]
    """The faces on one side and on the other (indices into the mesh's faces)."""
    normal: np.ndarray
    """(3,) the plane's unit normal, of the first side's faces."""
    u: np.ndarray
    """(3,) a unit vector in the plane: the first of its 2-D coordinates."""
    w: np.ndarray
    """(3,) normal x u: the second."""
    common: BaseGeometry
    """Where the two sides overlap (a shapely geometry, in (u, w) coordinates)."""
    where: tuple[float, float, float]
    """A point of the overlap [model units]."""


def _back_to_back(mesh) -> Iterator[_Touching]:
    """Each plane where faces of mesh lie on one another back to back over some area.
    Faces are grouped by their plane (normal and offset, rounded); a plane met from both
    sides is checked for overlap in 2D. Faces merely meeting at an edge do not count."""
    from shapely import Polygon, unary_union

    if len(mesh.faces) == 0:
        return
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
        normal = n[faces[0]]
        u, w = _plane_axes(normal)

        def region(ids):
            tris = mesh.triangles[ids]
            return unary_union([Polygon(np.column_stack([t @ u, t @ w])).buffer(0) for t in tris])

        common = region(faces).intersection(region(other))
        if common.area <= _MIN_AREA * size * size:
            continue
        p = common.representative_point()
        offset = float(mesh.triangles[faces[0]][0] @ normal)
        x, y, z = (float(v) for v in p.x * u + p.y * w + offset * np.asarray(normal))
        yield _Touching(faces + other, normal, u, w, common, (x, y, z))


_MIN_AREA = 1e-8
"""Least overlap of faces back to back that counts as touching [fraction of the mesh's
largest extent, squared]."""


_SLIVER = 1e-14
"""Area below which a piece of a face cut by merge_touching is float noise [fraction of the
mesh's largest extent, squared]."""


def _plane_axes(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, w): unit vectors spanning the plane of normal, u x w = normal. For a normal along
    an axis they are axes too, so a point's 2-D coordinates are two of its own, exactly."""
    k = int(np.argmax(np.abs(normal)))
    axis = np.zeros(3)
    if abs(abs(normal[k]) - 1.0) < 1e-12:  # along an axis: take the next two
        axis[(k + 1) % 3] = 1.0
        u = axis
    else:
        u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


MERGED = "merge_touching 1"
"""What backend manifold's meshes are made with after the evaluator (merge_touching), in the
render cache's key: a mesh cached, or a model refused, before it merged touching solids is
rendered again."""


def merge_touching(mesh_path: Path) -> int:
    """Merge solids that touch face to face in backend manifold's mesh (an STL, rewritten in
    place), as the binary's CGAL merges them; returns on how many planes (0: none touched,
    or the merge did not come out a closed solid of the same volume, and the mesh is left as
    it was).

    openscad-evaluator joins a module's or a loop's solids without a boolean
    (Manifold.compose), and Manifold keeps solids that only touch apart; so blocks side by
    side, a procedural terrain's usual make, leave both walls where they meet inside the
    solid (plywood_bridge: the plank's underside on its blocks' tops). Here the overlap of
    each such pair of faces is cut out of both (shapely, in the plane), what is left of a
    face is triangulated again, and faces are split where another face's corner lies on their
    edge, so that the mesh is closed again (and, unless solids touch along an edge only,
    watertight to trimesh). The STL's float32 coordinates put the two walls on exactly one
    plane (the evaluator's may differ in the last bit of a double: 0.7 + 0.1
    against 8 * 0.1). Then it is the binary's surface: the planner's height field sees no
    upward face inside the solid (a slab's top under a tower on it, 0.5 m below the tower's
    top, is ground under a shelf to its overhead rule), and the mesh cleaning of
    scenes/_mesh.py gets a closed mesh (walls inside put four faces on an edge: not watertight
    to trimesh, so the cleaning takes it for an open surface and turns it up by the sign of
    its upward area, 0 for a closed one: 16 x 16 blocks came out upside down).

    Written here because nothing at hand does it: Manifold's union, simplify() and
    set_tolerance() of the evaluator's mesh keep the faces (it sees them as touching, not
    overlapping), and trimesh has no boolean of coplanar faces nor a T-junction repair."""
    import trimesh

    mesh = trimesh.load_mesh(mesh_path)  # (vertices merged)
    planes = list(_back_to_back(mesh))
    if not planes:
        return 0
    merged = _merged(mesh, planes)
    if merged is None:
        return 0
    tmp = mesh_path.with_name(f".{mesh_path.name}.merged")
    merged.export(tmp, file_type="stl")
    tmp.replace(mesh_path)
    return len(planes)


def _merged(mesh, planes: list[_Touching]):
    """mesh (trimesh) with the overlap of each plane's faces cut out of them (_back_to_back),
    closed again; None unless it comes out closed and wound outward (_closed), touching
    nowhere and of the same volume (faces back to back add nothing to it)."""
    import shapely
    import trimesh
    from shapely import Polygon

    size = float(max(mesh.extents))
    # A face cut by less than this, or what is left of it, is no face [model units^2]: any
    # more, however small, must be cut or kept, or the mesh has a hole there.
    min_area = _SLIVER * size * size
    dropped: set[int] = set()
    added: list[np.ndarray] = []
    for plane in planes:
        for f in plane.faces:
            tri = mesh.triangles[f]
            flat = np.column_stack([tri @ plane.u, tri @ plane.w])
            face = Polygon(flat)
            if face.intersection(plane.common).area <= min_area:
                continue
            dropped.add(f)
            rest = face.difference(plane.common)
            if rest.area <= min_area:
                continue
            pieces = shapely.constrained_delaunay_triangles(rest)
            for piece in shapely.get_parts(pieces):
                corners = np.asarray(piece.exterior.coords)[:3]
                new = _lifted(corners, flat, tri)
                if np.cross(new[1] - new[0], new[2] - new[0]) @ mesh.face_normals[f] < 0:
                    new = new[::-1]
                added.append(new)
    keep = np.setdiff1d(np.arange(len(mesh.faces)), np.fromiter(dropped, dtype=np.int64))
    triangles = np.concatenate([mesh.triangles[keep], np.asarray(added).reshape(-1, 3, 3)])
    out = trimesh.Trimesh(**trimesh.triangles.to_kwargs(triangles))  # (vertices merged)
    out = _split_at_corners(out)
    out.update_faces(out.nondegenerate_faces())
    out.remove_unreferenced_vertices()
    if not _closed(out) or abs(out.volume - mesh.volume) > 1e-6 * abs(mesh.volume):
        return None
    if _touching_walls(out) is not None:
        return None
    return out


def _closed(mesh) -> bool:
    """Whether mesh bounds solids wound outward: each edge is crossed as often one way as the
    other (so each face has its neighbours and is wound as they are) and the volume is
    positive. Solids that touch along an edge only (voxel_wall's blocks corner to corner)
    put four faces on it, which trimesh's is_watertight refuses and the binary's mesh has too."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if len(faces) == 0:
        return False
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n = int(faces.max()) + 1
    forward = np.sort(edges[:, 0] * n + edges[:, 1])
    backward = np.sort(edges[:, 1] * n + edges[:, 0])
    return bool(np.array_equal(forward, backward)) and float(mesh.volume) > 0


def _lifted(corners: np.ndarray, flat: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(3, 3): the points of the plane of triangle tri ((3, 3), at (3, 2) flat in the plane's
    coordinates) at corners ((3, 2), in the same coordinates): a corner of tri itself exactly,
    any other by its barycentric coordinates."""
    out = np.empty((3, 3))
    m = np.column_stack([flat[1] - flat[0], flat[2] - flat[0]])
    for i, q in enumerate(corners):
        same = np.flatnonzero(np.all(flat == q, axis=1))
        if len(same):
            out[i] = tri[same[0]]
            continue
        b, c = np.linalg.solve(m, q - flat[0])
        out[i] = tri[0] + b * (tri[1] - tri[0]) + c * (tri[2] - tri[0])
    return out


def _split_at_corners(mesh, rounds: int = 4):
    """mesh with each face split where a corner of another face lies inside one of its edges
    (a T-junction: after the cut, a tall wall's edge runs past the corner of the short
    block beside it), so that every edge has a face on each side."""
    import trimesh
    from scipy.spatial import KDTree

    for _ in range(rounds):
        faces = np.asarray(mesh.faces)
        vertices = np.asarray(mesh.vertices)
        edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        _, index, counts = np.unique(
            np.sort(edges, axis=1), axis=0, return_inverse=True, return_counts=True
        )
        lone = np.flatnonzero(counts[index.reshape(-1)] == 1)  # edges of one face only
        if len(lone) == 0:
            return mesh
        ends = np.unique(edges[lone])
        tree = KDTree(vertices[ends])
        tol = 1e-9 * float(max(mesh.extents))
        splits: dict[int, list[tuple[int, list[int]]]] = {}
        for e in lone:
            a, b = edges[e]
            pa, pb = vertices[a], vertices[b]
            length = float(np.linalg.norm(pb - pa))
            found = []
            for j in tree.query_ball_point((pa + pb) / 2, length / 2 + tol):
                v = int(ends[j])
                if v in (a, b):
                    continue
                t = float((vertices[v] - pa) @ (pb - pa)) / (length * length)
                off = np.linalg.norm(pa + t * (pb - pa) - vertices[v])
                if 0 < t < 1 and off <= tol:
                    found.append((t, v))
            if found:
                splits.setdefault(int(e) // 3, []).append(
                    (int(e) % 3, [v for _, v in sorted(found)])
                )
        if not splits:
            return mesh
        new_faces = [np.delete(faces, list(splits), axis=0)]
        new_vertices = [vertices]
        count = len(vertices)
        for f, cuts in splits.items():
            ring: list[int] = []
            inner = dict(cuts)
            for k in range(3):  # the face's corners with the corners found on its edges
                ring += [int(faces[f][k]), *inner.get(k, [])]
            if len(cuts) == 1:  # a fan from the corner opposite the edge cut
                k = cuts[0][0]
                apex = int(faces[f][(k + 2) % 3])
                start = ring.index(apex)
                ring = ring[start:] + ring[:start]
                fan = [[apex, ring[i], ring[i + 1]] for i in range(1, len(ring) - 1)]
            else:  # a fan from the face's centre
                new_vertices.append(vertices[faces[f]].mean(axis=0)[None])
                fan = [[count, ring[i], ring[(i + 1) % len(ring)]] for i in range(len(ring))]
                count += 1
            new_faces.append(np.asarray(fan, dtype=np.int64))
        mesh = trimesh.Trimesh(np.concatenate(new_vertices), np.concatenate(new_faces))
    return mesh


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
