"""A 2.5D height field of the terrain's top surface: what the planner stands the robot on."""

from __future__ import annotations

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

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear surface height at xy ((..., 2) [m]); NaN off the grid or next to a NaN cell."""
        xy = np.asarray(xy, dtype=np.float64)
        ny, nx = self.heights.shape
        u = (xy[..., 0] - self.x0) / self.resolution
        v = (xy[..., 1] - self.y0) / self.resolution
        inside = (u >= 0) & (u <= nx - 1) & (v >= 0) & (v <= ny - 1)
        i = np.clip(np.floor(u).astype(np.int64), 0, nx - 2)
        j = np.clip(np.floor(v).astype(np.int64), 0, ny - 2)
        fu = np.clip(u - i, 0.0, 1.0)
        fv = np.clip(v - j, 0.0, 1.0)
        h = self.heights
        z = (
            h[j, i] * (1 - fu) * (1 - fv)
            + h[j, i + 1] * fu * (1 - fv)
            + h[j + 1, i] * (1 - fu) * fv
            + h[j + 1, i + 1] * fu * fv
        )
        return np.where(inside, z, np.nan)


def heightfield_from_mesh(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    xy_min: tuple[float, float],
    xy_max: tuple[float, float],
    resolution: float,
    ground_height: float | None,
) -> HeightField:
    """Rasterise the upward-facing triangles of a mesh into a top-surface height field.

    vertices: (V, 3) world frame [m]; faces: (F, 3) int. Each grid point takes the highest
    triangle above it; points no triangle covers take ground_height (or NaN without ground).
    Exact for the piecewise-planar surface, and cheaper than one ray per cell.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    nx = int(np.floor((xy_max[0] - xy_min[0]) / resolution)) + 1
    ny = int(np.floor((xy_max[1] - xy_min[1]) / resolution)) + 1
    top = np.full((ny, nx), -np.inf)
    tri = vertices[faces]  # (F, 3, 3)
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # twice the signed xy area
    # Vertical faces cover no area from above; tiny ones are sliver noise. Both orientations
    # count: the top surface is the highest one whatever the winding.
    keep = np.abs(det) > 1e-12
    for t, d in zip(tri[keep], det[keep], strict=True):
        lo = np.maximum(np.ceil((t[:, :2].min(0) - xy_min) / resolution - 1e-9), 0).astype(int)
        hi = np.minimum(
            np.floor((t[:, :2].max(0) - xy_min) / resolution + 1e-9), (nx - 1, ny - 1)
        ).astype(int)
        if np.any(hi < lo):
            continue
        gx = xy_min[0] + np.arange(lo[0], hi[0] + 1) * resolution
        gy = xy_min[1] + np.arange(lo[1], hi[1] + 1) * resolution
        px, py = np.meshgrid(gx - t[0, 0], gy - t[0, 1])
        a = (px * (t[2, 1] - t[0, 1]) - py * (t[2, 0] - t[0, 0])) / d
        b = (py * (t[1, 0] - t[0, 0]) - px * (t[1, 1] - t[0, 1])) / d
        eps = 1e-9
        inside = (a >= -eps) & (b >= -eps) & (a + b <= 1 + eps)
        if not inside.any():
            continue
        z = t[0, 2] + a * (t[1, 2] - t[0, 2]) + b * (t[2, 2] - t[0, 2])
        block = top[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]
        np.maximum(block, np.where(inside, z, -np.inf), out=block)
    if ground_height is not None:
        top = np.maximum(top, ground_height)
    top[~np.isfinite(top)] = np.nan
    return HeightField(x0=float(xy_min[0]), y0=float(xy_min[1]), resolution=resolution, heights=top)
