"""Terrain meshes from files: read with trimesh, cleaned, and refused when absurd."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from ._errors import SceneError

MAX_TERRAIN_EXTENT = 50.0
"""A terrain piece wider than this [m] is almost certainly in millimetres, not metres."""


def read_mesh(path, label: str) -> trimesh.Trimesh:
    """Read a mesh file (STL/OBJ/PLY/GLB; a multi-mesh scene is flattened) without processing.

    label names the source in errors, e.g. "scene.yaml: terrain[0].mesh".
    """
    if Path(path).stat().st_size == 0:
        raise SceneError(f"{label}: {path} is an empty file")
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except KeyError as exc:
        if exc.args == ("z",):  # trimesh's PLY reader, on vertices of x and y alone
            raise SceneError(_flat_drawing(label, path)) from None
        raise SceneError(f"{label}: {path} cannot be read as a mesh: {exc}") from None
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise SceneError(f"{label}: {path} cannot be read as a mesh: {exc}") from None
    if isinstance(loaded, trimesh.Trimesh) and np.asarray(loaded.vertices).shape[1:] != (3,):
        raise SceneError(_flat_drawing(label, path))  # an OBJ of `v x y` lines
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        kind = Path(path).suffix.lstrip(".").upper()
        raise SceneError(
            f"{label}: {path} contains no triangles: it is not a valid {kind} file, or an empty one"
        )
    return loaded


def _flat_drawing(label: str, path) -> str:
    """The refusal of a mesh file whose vertices have no z: a 2-D drawing. (A mesh of x, y, z
    that is flat is a patch of floor, and is taken.)"""
    return (
        f"{label}: {path} is 2-D: its vertices have no z coordinate, so it has no height and "
        f"is no terrain; give it heights (a solid, or a surface of x, y, z) in the program "
        f"that made it"
    )


def terrain_extent(mesh: trimesh.Trimesh) -> float:
    """The largest side of the box round the mesh's finite vertices that faces use [m as read]."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    used = np.zeros(len(vertices), dtype=bool)
    used[np.asarray(mesh.faces, dtype=np.int64).ravel()] = True
    used &= np.all(np.isfinite(vertices), axis=1)
    if not used.any():
        return 0.0
    return float(np.max(np.ptp(vertices[used], axis=0)))


def looks_like_millimetres(mesh: trimesh.Trimesh) -> bool:
    """True if the mesh, read as metres, is too large to be a terrain piece: a model in
    millimetres (as most CAD and 3D-printing models are), to load with `scale: 0.001`."""
    return terrain_extent(mesh) > MAX_TERRAIN_EXTENT


def scaled_mesh(mesh: trimesh.Trimesh, scale: tuple[float, float, float]) -> trimesh.Trimesh:
    """A copy of mesh with its vertices scaled about its origin by (sx, sy, sz) (positive)."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64) * np.asarray(scale, dtype=np.float64)
    return trimesh.Trimesh(
        vertices,
        np.asarray(mesh.faces),
        process=False,
        vertex_attributes=dict(mesh.vertex_attributes),
        face_attributes=dict(mesh.face_attributes),
    )


def clean_terrain_mesh(
    mesh: trimesh.Trimesh, label: str, check_units: bool = True, rewind: bool = True
) -> trimesh.Trimesh:
    """A copy with non-finite vertices, duplicate vertices and degenerate faces removed and the
    faces wound consistently with normals outward (closed meshes) or upward (open surfaces);
    rewind False keeps each face's winding (a capture's facets already face its sensor).

    Raises SceneError naming `label` when nothing usable is left or the size is absurd.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    finite = np.all(np.isfinite(vertices), axis=1)
    keep = np.all(finite[faces], axis=1)
    faces = faces[keep]
    if len(faces) == 0:
        raise SceneError(f"{label}: the mesh has no triangles with finite coordinates")
    # Per-vertex and per-face values (a capture's height noise, its filled triangles) stay
    # with their vertices and faces through cleaning.
    out = trimesh.Trimesh(
        vertices,
        faces,
        process=False,
        vertex_attributes=dict(mesh.vertex_attributes),
        face_attributes={k: np.asarray(v)[keep] for k, v in mesh.face_attributes.items()},
    )
    out.remove_unreferenced_vertices()  # drops the non-finite ones before they are compared
    out.merge_vertices()
    out.update_faces(out.nondegenerate_faces())
    out.update_faces(out.unique_faces())
    out.remove_unreferenced_vertices()
    if len(out.faces) == 0:
        raise SceneError(f"{label}: every triangle of the mesh is degenerate (zero area)")
    # A capture's units were judged by perception from the sensor's range (a 300 m lidar
    # survey in metres is real); a model's only by its size.
    if check_units and looks_like_millimetres(out):
        raise SceneError(
            f"{label}: the mesh is {terrain_extent(out):.0f} m across; scenes are in metres, so "
            f"this is most likely a model in millimetres: add `scale: 0.001` to this terrain "
            f"object (or --scale 0.001)"
        )
    if not rewind:
        return out
    if out.is_watertight:
        trimesh.repair.fix_normals(out)  # consistent winding, outward (may flip all)
    else:
        # An open surface (a capture, a height map patch): wind it consistently, then turn it
        # so its normals face up on the whole, as the top of a terrain does.
        trimesh.repair.fix_winding(out)
        up = float((out.face_normals[:, 2] * out.area_faces).sum())
        if abs(up) <= 1e-9 * float(out.area_faces.sum()):
            # Closed after all (solids meeting along an edge, which trimesh does not call
            # watertight): its up and down faces cancel, and the sign of that rounding noise
            # would decide. Outward is where its volume is positive.
            if float(out.volume) < 0:
                out.invert()
        elif up < 0:
            out.invert()
    return out


def surface_distances(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int = 20_000) -> np.ndarray:
    """(n,) distances [model units] of n points sampled on a's surface (seed 0) to b's surface:
    for comparing two renders of one model (the OpenSCAD backends).

    Open3D's distance query finds them fast but not always right: on voxel_wall's 7 m x 2 cm
    slab faces it reported 5 mm for points lying on the other mesh's face (1e-11 exactly). So
    every point it puts further than 1e-5 of the diagonal away, the only ones that can decide
    a tolerance below, is measured again exactly against every triangle of b (float64)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(b.vertices.astype(np.float32)),
        o3d.core.Tensor.from_numpy(b.faces.astype(np.uint32)),
    )
    points = trimesh.sample.sample_surface(a, n, seed=0)[0]
    d = (
        scene.compute_distance(o3d.core.Tensor.from_numpy(points.astype(np.float32)))
        .numpy()
        .astype(float)
    )
    for i in np.flatnonzero(d > 1e-5 * np.linalg.norm(a.extents)):
        nearest = trimesh.triangles.closest_point(
            b.triangles, np.tile(points[i], (len(b.faces), 1))
        )
        d[i] = np.linalg.norm(nearest - points[i], axis=1).min()
    return d


def disagreement(a: trimesh.Trimesh, b: trimesh.Trimesh) -> dict[str, float]:
    """How far two meshes of one model are apart, each as a fraction of a's bounding-box
    diagonal: "bounds" (largest bounds difference), "p99" and "hausdorff" (99th percentile and
    max of the symmetric surface distance, surface_distances both ways)."""
    diag = float(np.linalg.norm(a.extents))
    d = np.concatenate([surface_distances(a, b), surface_distances(b, a)])
    return {
        "bounds": float(np.abs(a.bounds - b.bounds).max()) / diag,
        "p99": float(np.quantile(d, 0.99)) / diag,
        "hausdorff": float(d.max()) / diag,
    }
