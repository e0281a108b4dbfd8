"""Where a click lands: viser gives the click as a ray; we intersect it with the terrain."""

from __future__ import annotations

import numpy as np

from roachplan.planning import HeightField


def ray_hit_heightfield(
    hf: HeightField, origin, direction, *, max_distance: float = 100.0
) -> np.ndarray | None:
    """First point (x, y, z) [m] where the ray origin + t direction (t >= 0, world frame) meets
    the height field's surface, or None if it misses. Marches at half a cell, then bisects."""
    o = np.asarray(origin, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    step = hf.resolution / 2
    t = np.arange(0.0, max_distance, step)
    pts = o + t[:, None] * d
    z = hf.sample(pts[:, :2])
    below = np.isfinite(z) & (pts[:, 2] <= z)
    if not below.any():
        return None
    k = int(np.argmax(below))
    if k == 0:
        return np.array([o[0], o[1], float(z[0])])
    lo, hi = t[k - 1], t[k]
    for _ in range(30):  # bisect between the last point above and the first below
        mid = (lo + hi) / 2
        p = o + mid * d
        zm = hf.sample(p[None, :2])[0]
        if np.isfinite(zm) and p[2] <= zm:
            hi = mid
        else:
            lo = mid
    p = o + hi * d
    return np.array([p[0], p[1], float(hf.sample(p[None, :2])[0])])
