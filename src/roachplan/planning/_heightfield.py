"""A 2.5D height field of the terrain's top surface: what the planner stands the robot on."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class HeightField:
    """Top-surface height on a regular grid, world frame.

    heights[j, i] is the surface height [m] at (x0 + i * resolution, y0 + j * resolution); NaN
    where there is no surface at all (off the map). Bilinear in between.
    """

    x0: float
    """x of column 0 [m]."""
    y0: float
    """y of row 0 [m]."""
    resolution: float
    """Grid spacing [m]."""
    heights: np.ndarray
    """(ny, nx) float64 [m], NaN = no surface."""
    noise: np.ndarray | None = None
    """(ny, nx) float64: standard deviation of each height [m] (a capture's sensor noise;
    None: exact, as a model's)."""

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the grid [m]."""
        ny, nx = self.heights.shape
        return (
            self.x0,
            self.x0 + (nx - 1) * self.resolution,
            self.y0,
            self.y0 + (ny - 1) * self.resolution,
        )

    def covered_bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((xmin, ymin), (xmax, ymax)) of the grid points that have a surface [m]."""
        j, i = np.nonzero(np.isfinite(self.heights))
        if len(i) == 0:
            return ((np.nan, np.nan), (np.nan, np.nan))
        r = self.resolution
        return (
            (self.x0 + i.min() * r, self.y0 + j.min() * r),
            (self.x0 + i.max() * r, self.y0 + j.max() * r),
        )

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear surface height at xy ((..., 2) [m]); NaN off the grid or next to a NaN cell."""
        return self._bilinear(xy, self.heights)[0]

    def sample_noise(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear height noise at xy ((..., 2) [m]) [m]; 0 where there is none (a model, or
        off the surface)."""
        if self.noise is None:
            return np.zeros(np.shape(xy)[:-1])
        return np.nan_to_num(self._bilinear(xy, self.noise)[0])

    def sample_with_noise(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sample(xy), sample_noise(xy)) at once: the cells and weights found once."""
        if self.noise is None:
            return self.sample(xy), np.zeros(np.shape(xy)[:-1])
        h, noise = self._bilinear(xy, self.heights, self.noise)
        return h, np.nan_to_num(noise)

    def _bilinear(self, xy: np.ndarray, *grids: np.ndarray) -> list[np.ndarray]:
        """Bilinear interpolation of (ny, nx) grids on this one's points at xy ((..., 2) [m]),
        one array per grid; NaN off the grid or next to a NaN cell."""
        xy = np.asarray(xy, dtype=np.float64)
        ny, nx = self.heights.shape
        u = (xy[..., 0] - self.x0) / self.resolution
        v = (xy[..., 1] - self.y0) / self.resolution
        inside = (u >= 0) & (u <= nx - 1) & (v >= 0) & (v <= ny - 1)
        i = np.clip(np.floor(u).astype(np.int64), 0, nx - 2)
        j = np.clip(np.floor(v).astype(np.int64), 0, ny - 2)
        fu = np.clip(u - i, 0.0, 1.0)
        fv = np.clip(v - j, 0.0, 1.0)
        gu, gv = 1 - fu, 1 - fv
        # One flat index for the four corners (np.take on it is several times faster than
        # indexing by (j, i) pairs: the standable map samples millions of points).
        k = j * nx + i
        out = []
        for h in grids:
            flat = h.ravel()
            z = (
                flat.take(k) * gu * gv
                + flat.take(k + 1) * fu * gv
                + flat.take(k + nx) * gu * fv
                + flat.take(k + nx + 1) * fu * fv
            )
            out.append(np.where(inside, z, np.nan))
        return out


def heightfield_from_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    xy_min: tuple[float, float],
    xy_max: tuple[float, float],
    resolution: float,
    ground_height: float | None,
    vertex_noise: np.ndarray | None = None,
    overhead: float | None = None,
) -> HeightField:
    """Rasterise the upward-facing triangles of a mesh into a top-surface height field.

    vertices: (V, 3) world frame [m]; faces: (F, 3) int. Each grid point takes the highest
    triangle above it; points no triangle covers take ground_height (or NaN without ground).
    Exact for the piecewise-planar surface, and cheaper than one ray per cell.
    vertex_noise: (V,) standard deviation of each vertex's height [m] (a capture's), or None;
    each grid point takes the largest noise of the triangles above it (interpolated).
    overhead [m]: a surface more than this above the lowest one at a grid point is overhead,
    not ground (a table top over the floor the camera saw under it): the point takes the
    highest surface within overhead of its lowest. None: the highest surface.
    (grid_cover then heightfield_from_cover: the same, in two halves.)
    """
    cover = grid_cover(vertices, faces, xy_min=xy_min, xy_max=xy_max, resolution=resolution)
    return heightfield_from_cover(
        cover,
        np.asarray(vertices, dtype=np.float64)[:, 2],
        ground_height=ground_height,
        vertex_noise=vertex_noise,
        overhead=overhead,
    )


@dataclass(frozen=True, eq=False)
class GridCover:
    """Which grid points each upward-facing triangle of a mesh covers, and where: everything
    of a rasterising that depends on the mesh's horizontal layout only. The same mesh with its
    vertices moved up or down (a capture's drawn sensor error) rasterises from it without
    searching again (heightfield_from_cover), to the same bits as from scratch."""

    x0: float
    """World x of grid column 0 [m]."""
    y0: float
    """World y of grid row 0 [m]."""
    resolution: float
    """Grid spacing [m]."""
    shape: tuple[int, int]
    """(ny, nx) grid points."""
    faces: np.ndarray
    """(F, 3) int: the mesh's faces."""
    at: np.ndarray
    """(H,) int: flat grid index (row * nx + column) of each hit."""
    face: np.ndarray
    """(H,) int: the face (row of faces) that covers it."""
    a: np.ndarray
    """(H,) the hit's barycentric coordinate along the face's edge from corner 0 to 1 [-]."""
    c: np.ndarray
    """(H,) the same along the edge from corner 0 to 2 [-]."""

    def at_corners(self, per_vertex: np.ndarray) -> np.ndarray:
        """(H,) a per-vertex quantity ((V,): height [m], noise [m]) interpolated to the hits."""
        c0, c1, c2 = self._corners
        v0 = per_vertex[c0]
        return v0 + self.a * (per_vertex[c1] - v0) + self.c * (per_vertex[c2] - v0)

    @functools.cached_property
    def _corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(H,) each: the vertex at corner 0, 1 and 2 of each hit's face, made once (a
        capture's rollouts interpolate a moved surface from the same cover again and again)."""
        corners = self.faces[self.face]
        return (corners[:, 0].copy(), corners[:, 1].copy(), corners[:, 2].copy())


def grid_cover(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    xy_min: tuple[float, float],
    xy_max: tuple[float, float],
    resolution: float,
) -> GridCover:
    """The GridCover of a mesh (vertices (V, 3) world frame [m], only x and y read; faces (F,
    3) int) on the grid from xy_min to xy_max [m] at resolution [m]."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    nx = int(np.floor((xy_max[0] - xy_min[0]) / resolution)) + 1
    ny = int(np.floor((xy_max[1] - xy_min[1]) / resolution)) + 1
    at, face, a, c = _grid_hits(
        vertices[faces][:, :, :2], xy0=np.asarray(xy_min, dtype=np.float64),
        resolution=resolution, shape=(ny, nx),
    )  # fmt: skip
    return GridCover(
        x0=float(xy_min[0]), y0=float(xy_min[1]), resolution=resolution, shape=(ny, nx),
        faces=faces, at=at, face=face, a=a, c=c,
    )  # fmt: skip


def heightfield_from_cover(
    cover: GridCover,
    heights: np.ndarray,
    *,
    ground_height: float | None,
    vertex_noise: np.ndarray | None = None,
    overhead: float | None = None,
) -> HeightField:
    """The top-surface HeightField of cover's mesh with its vertices at heights ((V,) [m]);
    ground_height, vertex_noise and overhead as heightfield_from_mesh's."""
    ny, nx = cover.shape
    at = cover.at
    z = cover.at_corners(np.asarray(heights, dtype=np.float64))
    noisy = vertex_noise is not None and bool(np.any(np.asarray(vertex_noise) > 0))
    sigma = cover.at_corners(np.asarray(vertex_noise, dtype=np.float64)) if noisy else None
    if overhead is not None and len(at):  # keep each point's surfaces within overhead of its lowest
        lowest = np.full(ny * nx, np.inf)
        np.minimum.at(lowest, at, z)
        keep = z <= lowest[at] + overhead
        at, z, sigma = at[keep], z[keep], None if sigma is None else sigma[keep]
    top = np.full(ny * nx, -np.inf)
    np.maximum.at(top, at, z)
    noise = None
    if sigma is not None:
        noise = np.zeros(ny * nx)
        np.maximum.at(noise, at, sigma)
        noise = noise.reshape(ny, nx)
    top = top.reshape(ny, nx)
    if ground_height is not None:
        top = np.maximum(top, ground_height)
    top[~np.isfinite(top)] = np.nan
    return HeightField(
        x0=cover.x0, y0=cover.y0, resolution=cover.resolution, heights=top, noise=noise
    )


def _grid_hits(
    tri: np.ndarray,
    *,
    xy0: np.ndarray,
    resolution: float,
    shape: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(flat grid indices (H,), face (H,), barycentric a and c (H,) each): every grid point
    ((ny, nx) = shape, spacing resolution [m] from xy0 (2,)) an upward-facing triangle of tri
    ((F, 3, 2) its corners' x and y [m]) covers, the triangle's index in tri, and where in
    it (along its edges from corner 0 to 1 and to 2)."""
    ny, nx = shape
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # twice the signed xy area
    # Only triangles facing up (counter-clockwise seen from above) can be the top surface:
    # vertical faces cover no area from above, tiny ones are sliver noise, and downward faces
    # are undersides (of a closed mesh, or of a surface wound outward/upward as the scene
    # loader leaves every mesh) -- skipping them also skips a closed mesh's large bottom.
    kept = np.flatnonzero(det > 1e-12)
    tri, det = tri[kept], det[kept]
    lo = np.maximum(np.ceil((tri.min(1) - xy0) / resolution - 1e-9), 0).astype(np.int64)
    hi = np.minimum(np.floor((tri.max(1) - xy0) / resolution + 1e-9), (nx - 1, ny - 1)).astype(
        np.int64
    )
    on_grid = np.all(hi >= lo, axis=1)
    # Vectorised over triangles of similar size: each bucket tests a bx x by block of grid
    # points per triangle, bx and by the next powers of two of its triangles' bounding boxes'
    # sides (not a square of the longer: a far floor's triangles are long and thin).
    side = 1 << np.ceil(np.log2(np.maximum(hi - lo + 1, 1))).astype(np.int64)  # (F, 2)
    ats, fs = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    as_, cs = [np.zeros(0)], [np.zeros(0)]
    for bx, by in np.unique(side[on_grid], axis=0):
        idx = np.flatnonzero(on_grid & (side[:, 0] == bx) & (side[:, 1] == by))
        off = np.stack(np.meshgrid(np.arange(bx), np.arange(by)), axis=-1).reshape(-1, 2)
        chunk = max(1, 2_000_000 // (bx * by))  # bound the temporaries to ~2M grid points
        for k in range(0, len(idx), chunk):
            sel = idx[k : k + chunk]
            t, d = tri[sel], det[sel]
            cell = lo[sel, None, :] + off[None]  # (n, bx*by, 2) grid indices (i, j)
            o = t[:, None, 0]  # (n, 1, 2) first corner; e1, e2 the edges from it
            e1, e2 = (t[:, None, 1] - o), (t[:, None, 2] - o)
            px = xy0[0] + cell[..., 0] * resolution - o[..., 0]
            py = xy0[1] + cell[..., 1] * resolution - o[..., 1]
            a = (px * e2[..., 1] - py * e2[..., 0]) / d[:, None]  # barycentric along e1
            c = (py * e1[..., 0] - px * e1[..., 1]) / d[:, None]  # barycentric along e2
            eps = 1e-9
            inside = (a >= -eps) & (c >= -eps) & (a + c <= 1 + eps)
            inside &= np.all(cell <= hi[sel, None, :], axis=-1)
            ats.append((cell[..., 1] * nx + cell[..., 0])[inside])
            fs.append(np.broadcast_to(kept[sel][:, None], inside.shape)[inside])
            as_.append(a[inside])
            cs.append(c[inside])
    return np.concatenate(ats), np.concatenate(fs), np.concatenate(as_), np.concatenate(cs)
