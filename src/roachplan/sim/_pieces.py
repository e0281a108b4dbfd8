"""A terrain built of a few flat convex tops as convex solids (pure geometry; the MuJoCo engine's
choice of terrain shape, sim/_mujoco.py).

MuJoCo collides a mesh geom as its convex hull, so a terrain is a height field there unless it
comes apart into convex solids. A scene built of primitives (the double bridge: two ramps and
two bridge decks) does: its top surface is a few flat convex faces, none over another, and the
solid under each face down to a base level is a convex prism. Each prism is one mesh geom, its
hull exact; a foot meets one or two of them where it met dozens of the field's cells (and their
sharp edges are the mesh's, where the field rounds an edge into a slope a cell wide).

`convex_prisms` decides and builds. Frames: world, metres. A top is a connected set of
upward triangles on one plane; it is convex when its outline's area is its convex hull's.
"""

from __future__ import annotations

import numpy as np

MAX_PIECES = 64
"""Most convex tops a terrain may have to be built of prisms; over it (a bumpy or captured
surface: thousands of facets) it is a height field."""
GLANCE = 2048
"""Faces upward_tops looks at first, with `most` given: where these alone are on too many
planes (or one is steep), the terrain is no prisms, told without the rest (a capture's 38,000
faces: 7 ms a rollout world, each drawn anew)."""
UPWARD = 0.2
"""A triangle whose unit normal has z above this faces up: it is part of a top (one steeper
than 78 deg is no ground a robot stands on). A terrain with a triangle facing up less than
this, and not vertical, is a field: its solid reaches out past the tops' prisms (a 20 cm wall
at 80 deg, 3.5 cm)."""
VERTICAL = 1e-6
"""A triangle whose unit normal has |z| under this is a vertical wall."""
MIN_TOP_AREA = 1e-6
"""Smallest top a prism is made of [m^2] (1 mm^2); a terrain with a smaller one is a field (a
sliver's prism is no solid MuJoCo can weigh)."""
PLANE_TOLERANCE = 1e-6
"""Two triangles are on one plane when their unit normals and offsets [m] agree within this."""
AREA_TOLERANCE = 1e-6
"""A top is convex, and two tops do not overlap, to within this share of the top's area."""


def upward_tops(
    vertices: np.ndarray, faces: np.ndarray, most: int | None = None
) -> list[np.ndarray] | None:
    """The terrain's tops: for each connected set of upward triangles on one plane (sharing
    edges), its face indices ((k,) int). vertices (V, 3) [m], faces (F, 3) int. With `most`
    given, None when there are more than that (a capture's thousands of facets are told in
    one sort, before any are joined) or a face is steep but not vertical (UPWARD)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if most is not None and len(faces) > GLANCE:  # (a capture's thousands of facets)
        normal, _, _, d = _upward_planes(vertices, faces[:GLANCE])
        if _refused(normal, d, most):
            return None
    normal, up, n, d = _upward_planes(vertices, faces)
    if most is not None and _refused(normal, d, most):
        return None
    if len(up) == 0:
        return []
    # The edges of the upward triangles, each as its sorted vertex pair, and which triangle.
    tri = faces[up]
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(len(up)), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    same = np.all(edges[1:] == edges[:-1], axis=1)
    i, j = owner[:-1][same], owner[1:][same]  # two upward triangles sharing an edge
    coplanar = np.all(np.abs(n[i] - n[j]) <= PLANE_TOLERANCE, axis=1) & (
        np.abs(d[i] - d[j]) <= PLANE_TOLERANCE
    )
    i, j = i[coplanar], j[coplanar]
    joined = coo_matrix((np.ones(len(i)), (i, j)), shape=(len(up), len(up)))
    count, label = connected_components(joined, directed=False)
    if most is not None and count > most:
        return None
    order = np.argsort(label, kind="stable")
    return np.split(up[order], np.flatnonzero(np.diff(label[order])) + 1)


def _upward_planes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, ...]:
    """(normal (F, 3): each face's unit normal, zero where it has no area; up (U,) int: the
    faces facing up (UPWARD); their normals (U, 3); their planes' offsets along them (U,)
    [m])."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=1)
    good = length > 1e-15
    normal[good] /= length[good, None]
    normal[~good] = 0.0  # (no area: neither steep nor up)
    up = np.flatnonzero(normal[:, 2] > UPWARD)
    n = normal[up]
    return normal, up, n, np.einsum("ij,ij->i", n, a[up])


def _refused(normal: np.ndarray, d: np.ndarray, most: int) -> bool:
    """Whether faces with these unit normals ((F, 3)) and upward planes' offsets ((U,) [m])
    make a terrain no prisms whatever else it holds: one of them steep but not vertical
    (UPWARD: no top's prism holds it), or the upward ones on more than `most` planes (tops on
    one plane are at least as many as the planes; their offsets alone, a 1-D sort, tell a
    capture). Some of a terrain's faces have no more planes than all of them: True for some
    is True for all."""
    if np.any((normal[:, 2] > VERTICAL) & (normal[:, 2] <= UPWARD)):
        return True
    return len(np.unique(np.round(d / (10 * PLANE_TOLERANCE)))) > most


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of 2-D points ((N, 2)), counter-clockwise, without repeated or collinear
    points ((H, 2)); Andrew's monotone chain."""
    pts = np.unique(points, axis=0)
    if len(pts) < 3:
        return pts

    def chain(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2 and _cross(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = chain(pts), chain(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _area(polygon: np.ndarray) -> float:
    """Area of a simple polygon ((N, 2), either winding) [m^2]."""
    if len(polygon) < 3:
        return 0.0
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _clip(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """The part of convex polygon subject inside convex polygon clip (both counter-clockwise
    (N, 2)); Sutherland-Hodgman."""
    out = subject
    for k in range(len(clip)):
        if len(out) == 0:
            break
        a, b = clip[k], clip[(k + 1) % len(clip)]
        inside = [_cross(a, b, p) >= 0 for p in out]
        kept = []
        for m in range(len(out)):
            p, q = out[m], out[(m + 1) % len(out)]
            if inside[m]:
                kept.append(p)
            if inside[m] != inside[(m + 1) % len(out)]:
                dp, dq = _cross(a, b, p), _cross(a, b, q)
                kept.append(p + (q - p) * (dp / (dp - dq)))
        out = np.array(kept).reshape(-1, 2)
    return out


def convex_prisms(
    vertices: np.ndarray,
    faces: np.ndarray,
    ground_height: float | None,
    *,
    base: float,
    overhead: float,
) -> list[np.ndarray] | None:
    """The terrain (vertices (V, 3) [m] world frame, faces (F, 3)) as convex prisms, each its
    corner points ((2 k, 3) [m]: a top's outline and the same outline at z = base [m]); None
    when it is no such terrain, and a height field is the shape to use:

    - more than MAX_PIECES tops, or a top that is not convex (an L-shaped deck, a hole in it)
      or smaller than MIN_TOP_AREA;
    - a face steeper than a top but not a wall (a frustum's sides: UPWARD);
    - two tops over each other (a table over the floor: the field keeps the surface the planner
      stands the robot on, and a prism would fill the room under the table);
    - a top more than `overhead` [m] over the ground plane (the field takes the ground there).

    Tops at or under the ground plane (ground_height [m], None: none) are left out: the plane
    is that surface. [] for a terrain whose every top is so (or that has none)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    tops = upward_tops(vertices, faces, MAX_PIECES) if len(faces) else []
    if tops is None:
        return None
    outlines, heights = [], []
    for top in tops:
        corners = vertices[np.unique(faces[top].ravel())]
        if ground_height is not None and corners[:, 2].max() <= ground_height + 1e-9:
            continue
        if ground_height is not None and corners[:, 2].max() > ground_height + overhead:
            return None
        tri = vertices[faces[top]][:, :, :2]
        u, v = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        area = 0.5 * float(np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum())
        hull = _hull(corners[:, :2])
        if area < MIN_TOP_AREA or abs(_area(hull) - area) > AREA_TOLERANCE * area:
            return None
        outlines.append(hull)
        heights.append(corners)
    for k in range(len(outlines)):
        for m in range(k + 1, len(outlines)):
            shared = _area(_clip(outlines[k], outlines[m]))
            smaller = min(_area(outlines[k]), _area(outlines[m]))
            if shared > AREA_TOLERANCE * smaller:
                return None
    prisms = []
    for corners in heights:
        below = corners.copy()
        below[:, 2] = base
        prisms.append(np.concatenate([corners, below]))
    return prisms
