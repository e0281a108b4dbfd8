"""The simulator's terrain, sized to the work: what a physics engine is given to stand the robot
on, derived from the world's mesh and the planner's height field.

A library model or a small capture is given to the engine as it is (every triangle, overhangs
and all). A capture of ordinary size is not: a 640x480 depth frame meshes into ~450k
triangles, and PyBullet's concave triangle mesh refuses anything over ~175k ("createCollisionShape
failed"; measured: 130k triangles taken, 179k refused). Such a terrain is first cropped to the
planning area and a margin; if it is still large, the engine gets the planner's own height
field as triangles, merged into larger flat pieces wherever that keeps every height within the
sensor's noise: so the robot walks on what the planner checked it can stand on, and a
capture's flat floor costs a few thousand triangles, not a few hundred thousand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roachplan.planning import HeightField

SIM_MAX_MESH_TRIANGLES = 60_000
"""A terrain mesh of at most this many triangles goes to the engine as it is (every library
scene: the largest, kinect_bridge, has 38k); over it, it is cropped, then made from the height
field. Well under PyBullet's limit (~175k triangles), and a BVH this size steps as fast as a
small one."""
SIM_MAX_TRIANGLES = 100_000
"""Cap on the height field's terrain [triangles]: its tolerance grows until it fits (a rough
lidar patch, every cell of which differs from its neighbours by more than the noise)."""
SIM_CROP_MARGIN = 0.5
"""The cropped mesh reaches this far past the planning area [m]: the robot's feet reach
0.15 m past its centre's bounds, and a drive that strays further has left the plan anyway."""
SIM_MIN_TOLERANCE = 0.002
"""Smallest height error allowed where a flat piece replaces the height field's cells [m]: a
model's terrain has no sensor noise, and 2 mm is under a foot's radius."""
SIM_MAX_TOLERANCE = 0.01
"""Largest height error allowed where the sensor's noise is larger [m] (a Kinect at 4 m)."""
NOISE_TOLERANCE = 3.0
"""A grid point's height error allowed where a flat piece replaces the height field's cells,
in multiples of its height noise (the sensor's standard deviation there) [-]."""
OFF_GROUND_TOLERANCE = 0.03
"""Height error allowed where the robot cannot stand (a wall, a steep slope, a bridge's side)
[m]: the robot only bumps into such places, and a capture's ragged walls would otherwise
cost most of the triangles."""
MAX_BLOCK_LEVEL = 5
"""Largest flat piece: 2^5 = 32 height-field cells a side (32 cm at 1 cm)."""


@dataclass(frozen=True, eq=False)
class SimTerrain:
    """The triangles a physics engine is given for a world's terrain, and how they were made."""

    vertices: np.ndarray
    """(V, 3) float64, world frame [m]."""
    faces: np.ndarray
    """(F, 3) int64 indices into vertices."""
    kind: str
    """"mesh" (the world's mesh as it is), "cropped" (its triangles near the planning area) or
    "heightfield" (the planner's height field as triangles)."""
    source_triangles: int
    """How many triangles the world's mesh has."""
    max_error: float
    """Largest height difference from the planner's height field at its grid points where the
    ground is level enough to stand on (level_ground) [m], for kind "heightfield" (0 otherwise: the engine then has the
    very mesh the field came from)."""

    def note(self) -> str:
        """One line for the user when the engine's terrain is not the mesh as it is; else ""."""
        if self.kind == "mesh":
            return ""
        if self.kind == "cropped":
            return (
                f"the simulator's terrain: the {len(self.faces):,} of {self.source_triangles:,} "
                f"triangles within {SIM_CROP_MARGIN:g} m of the planning area"
            )
        return (
            f"the simulator's terrain: the planner's height field as {len(self.faces):,} "
            f"triangles (the mesh has {self.source_triangles:,}), flat pieces merged; where the "
            f"ground is level enough to stand on, heights within {self.max_error * 1000:.1f} mm of the planner's"
        )


def sim_terrain(
    vertices: np.ndarray,
    faces: np.ndarray,
    heightfield: HeightField,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    *,
    ground: np.ndarray | None = None,
    max_mesh_triangles: int = SIM_MAX_MESH_TRIANGLES,
    max_triangles: int = SIM_MAX_TRIANGLES,
) -> SimTerrain:
    """The terrain a physics engine is given for a world whose mesh is (vertices (V, 3) [m],
    faces (F, 3)), whose planner stands the robot on heightfield, within bounds ((xmin, ymin),
    (xmax, ymax)) [m]: the mesh as it is when it has at most max_mesh_triangles, else its
    triangles within SIM_CROP_MARGIN of bounds when those are few enough, else the height field
    as at most max_triangles triangles (simplified_heightfield_mesh; ground: where the feet
    may go, (ny, nx) bool on its grid, level_ground)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    n = len(faces)
    if n <= max_mesh_triangles:
        return SimTerrain(vertices, faces, "mesh", n, 0.0)
    cropped = crop_mesh(vertices, faces, bounds, SIM_CROP_MARGIN)
    if len(cropped[1]) <= max_mesh_triangles:
        return SimTerrain(*cropped, "cropped", n, 0.0)
    v, f, err = simplified_heightfield_mesh(heightfield, ground=ground, max_triangles=max_triangles)
    return SimTerrain(v, f, "heightfield", n, err)


def crop_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of the triangles with a corner within margin [m] of bounds ((xmin,
    ymin), (xmax, ymax)) [m] in x and y, the unused vertices dropped."""
    (x0, y0), (x1, y1) = bounds
    xy = vertices[:, :2]
    near = (
        (xy[:, 0] >= x0 - margin)
        & (xy[:, 0] <= x1 + margin)
        & (xy[:, 1] >= y0 - margin)
        & (xy[:, 1] <= y1 + margin)
    )
    kept = faces[near[faces].any(axis=1)]
    used, inverse = np.unique(kept, return_inverse=True)
    return vertices[used], inverse.reshape(-1, 3).astype(np.int64)


def simplified_heightfield_mesh(
    hf: HeightField,
    *,
    ground: np.ndarray | None = None,
    max_triangles: int = SIM_MAX_TRIANGLES,
    min_tolerance: float = SIM_MIN_TOLERANCE,
    max_tolerance: float = SIM_MAX_TOLERANCE,
) -> tuple[np.ndarray, np.ndarray, float]:
    """(vertices (V, 3) [m], faces (F, 3), largest height error [m]): the height field's grid
    points joined into triangles, two per square block of cells, the blocks as large as keeps
    every grid point inside within the tolerance of the two triangles (a quadtree, blocks of
    1 to 2^MAX_BLOCK_LEVEL cells a side). Where the robot may stand or put a foot (ground:
    (ny, nx) bool on the field's grid, level_ground; None: everywhere) a grid point's tolerance is
    NOISE_TOLERANCE times its height noise (the sensor's), clipped to min_tolerance to
    max_tolerance [m]; elsewhere (walls, steep ground) OFF_GROUND_TOLERANCE. All tolerances
    are raised together while the triangles are more than max_triangles. Cells with a corner
    off the surface (NaN) are left out. The error returned is the largest over the ground's
    grid points: each is within it of the triangles above it.

    Neighbouring blocks of different sizes meet at T-junctions, so the surface may step by up
    to twice the tolerance along a block's edge; the steps have no width (the triangles' xy
    projections tile the plane), so nothing falls through them.
    """
    h = np.asarray(hf.heights, dtype=np.float64)
    noise = np.zeros_like(h) if hf.noise is None else np.nan_to_num(hf.noise)
    ground = np.ones(h.shape, dtype=bool) if ground is None else np.asarray(ground)
    tolerance = np.where(
        ground, np.clip(NOISE_TOLERANCE * noise, min_tolerance, max_tolerance), OFF_GROUND_TOLERANCE
    )
    levels = _block_errors(h, tolerance, ground)
    scale = 1.0
    while True:
        blocks, error = _quadtree_blocks(levels, scale)
        if 2 * len(blocks) <= max_triangles or scale > 1e4:
            break
        scale *= 1.25
    return (*_blocks_mesh(hf, blocks), error)


def level_ground(hf: HeightField, max_slope_deg: float, span: float = 0.04) -> np.ndarray:
    """(ny, nx) bool on hf's grid: the points where the surface is level enough to stand on,
    its slope over span [m] (wider than a capture's noise: 3 mm over 1 cm is 17 deg) at most
    max_slope_deg [deg] in x and in y; False off the surface. Where the feet of a robot that
    stands go: the walls, a bridge's sides and steep ground are what it only bumps into."""
    h = hf.heights
    k = max(int(round(span / hf.resolution / 2)), 1)
    limit = np.tan(np.radians(max_slope_deg)) * 2 * k * hf.resolution
    level = np.isfinite(h)
    with np.errstate(invalid="ignore"):
        dx = np.abs(h[:, 2 * k :] - h[:, : -2 * k]) <= limit
        dy = np.abs(h[2 * k :, :] - h[: -2 * k, :]) <= limit
    level[:, k:-k] &= dx
    level[k:-k, :] &= dy
    return level


def standable_points(hf: HeightField, regions) -> np.ndarray:
    """(ny, nx) bool on hf's grid: the points within half a cell of a standable cell's centre
    of regions (a StandableMap: where the robot's centre can stand at some heading)."""
    ny, nx = hf.heights.shape
    i = np.round((hf.x0 + np.arange(nx) * hf.resolution - regions.x0) / regions.cell)
    j = np.round((hf.y0 + np.arange(ny) * hf.resolution - regions.y0) / regions.cell)
    i, j = i.astype(np.int64), j.astype(np.int64)
    my, mx = regions.standable.shape
    inside = ((j >= 0) & (j < my))[:, None] & ((i >= 0) & (i < mx))[None, :]
    return regions.standable[np.clip(j, 0, my - 1)][:, np.clip(i, 0, mx - 1)] & inside


def _block_errors(
    h: np.ndarray, tol: np.ndarray, ground: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray]]:
    """For each block side s = 2^k, k = 0..MAX_BLOCK_LEVEL: ((By, Bx) the largest |height -
    triangles| / tolerance over each aligned s x s block's grid points, inf where a point is
    off the surface; (By, Bx) the largest |height - triangles| [m] over its points where ground
    ((ny, nx) bool) is set, 0 where none is), of grid h ((ny, nx) [m], NaN off the surface)
    padded with NaN to whole blocks of the largest side."""
    ny, nx = h.shape
    top = 2**MAX_BLOCK_LEVEL
    py = -(-(ny - 1) // top) * top + 1
    px = -(-(nx - 1) // top) * top + 1
    hp = np.full((py, px), np.nan)
    hp[:ny, :nx] = h
    tp = np.ones((py, px))
    tp[:ny, :nx] = tol
    gp = np.zeros((py, px), dtype=bool)
    gp[:ny, :nx] = ground
    levels = []
    for level in range(MAX_BLOCK_LEVEL + 1):
        dev = _block_deviation(hp, 2**level)
        ratio = np.nan_to_num(dev / _windows(tp, 2**level), nan=np.inf)
        on_ground = np.where(_windows(gp, 2**level), np.nan_to_num(dev, nan=0.0), 0.0)
        levels.append((ratio.max(axis=(-1, -2)), on_ground.max(axis=(-1, -2))))
    return levels


def _windows(a: np.ndarray, s: int) -> np.ndarray:
    """(By, Bx, s+1, s+1) view: the grid points of each aligned s x s block of a."""
    return np.lib.stride_tricks.sliding_window_view(a, (s + 1, s + 1))[::s, ::s]


def _block_deviation(h: np.ndarray, s: int) -> np.ndarray:
    """(By, Bx, s+1, s+1) |height - triangles| [m] at each aligned s x s block's grid points
    (edges included), of grid h ((By*s+1, Bx*s+1) [m]), the block split into two triangles
    along the diagonal from its (0, 0) corner to its (s, s) corner; NaN where h is."""
    z = _windows(h, s)
    c00 = z[..., :1, :1]
    c01 = z[..., :1, -1:]  # the next column (x)
    c10 = z[..., -1:, :1]  # the next row (y)
    c11 = z[..., -1:, -1:]
    w = np.arange(s + 1)[:, None] / s  # along the rows (y), 0..1
    u = np.arange(s + 1)[None, :] / s  # along the columns (x), 0..1
    above = c00 + (c01 - c00) * u + (c11 - c01) * w  # the triangle (0,0) (0,s) (s,s): u >= w
    below = c00 + (c10 - c00) * w + (c11 - c10) * u  # the triangle (0,0) (s,0) (s,s): w >= u
    return np.abs(z - np.where(u >= w, above, below))


def _quadtree_blocks(
    levels: list[tuple[np.ndarray, np.ndarray]], scale: float
) -> tuple[np.ndarray, float]:
    """((B, 3) int blocks (row j, column i, side s in cells), the largest |height - triangles|
    over their ground points [m]): tiling every cell whose four corners are on the surface, each the largest
    aligned block whose points are within scale x their tolerance (_block_errors' levels),
    unless a larger block holding it is."""
    top = len(levels) - 1
    covered = np.zeros_like(levels[top][0], dtype=bool)
    out, worst = [], 0.0
    for level in range(top, -1, -1):
        ratio, dev = levels[level]
        if level < top:  # each parent block's cover passes to its 4 children
            covered = np.repeat(np.repeat(covered, 2, axis=0), 2, axis=1)
        leaf = ((ratio <= scale) | (level == 0) & np.isfinite(ratio)) & ~covered
        j, i = np.nonzero(leaf)
        s = 2**level
        out.append(np.column_stack([j * s, i * s, np.full(len(j), s)]))
        if len(j):
            worst = max(worst, float(dev[leaf].max()))
        covered |= leaf
    return np.concatenate(out).astype(np.int64), worst


def _blocks_mesh(hf: HeightField, blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) [m], faces (2B, 3)) of the blocks ((B, 3): row, column, side), each
    two triangles over its corner grid points, wound to face up."""
    h = hf.heights
    ny, nx = h.shape
    if len(blocks) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    j, i, s = blocks.T
    c00, c01 = j * nx + i, j * nx + i + s
    c10, c11 = (j + s) * nx + i, (j + s) * nx + i + s
    # Counter-clockwise seen from above (x right, y up): (0,0) (0,s) (s,s) and (0,0) (s,s) (s,0).
    corners = np.concatenate([np.column_stack([c00, c01, c11]), np.column_stack([c00, c11, c10])])
    used, inverse = np.unique(corners, return_inverse=True)
    jj, ii = np.divmod(used, nx)
    vertices = np.column_stack([hf.x0 + ii * hf.resolution, hf.y0 + jj * hf.resolution, h[jj, ii]])
    return vertices, inverse.reshape(-1, 3).astype(np.int64)
