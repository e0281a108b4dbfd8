"""The voxelization study of Tong 2018, section 3.1 (table 3.1): how much does voxelizing a
capture of a flat wall or floor reduce its measurement error?

For each voxel size: voxelize; fit a plane by least squares; discard the points farther from it
than 5 standard errors; refit; repeat until no point is discarded. Report the points, the points
kept and the standard error of the residuals [mm].

The report's "linear plane" is fitted here by orthogonal least squares (distances along the
plane's normal): for a wall facing the camera it is the same plane, and it also fits a floor,
which is edge-on to the optical axis and so no function z(x, y).

The report sampled a square of a wall and nothing else. In a room capture the user picks the
surface: a square or rectangle of the view, and/or the dominant plane (`plane_region`); and
`planarity_warning` says when the region is plainly not one flat surface, since the 5-sigma
rule cannot tell: over a whole room the standard error is hundreds of mm, so 5 of them cover
every point, nothing is discarded and the "error" is the room's depth, not the sensor's noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._errors import CaptureError
from ._pipeline import voxel_downsample

MAX_ERROR_MM = 20.0
"""A flat surface's error above this [mm] (and above MAX_ERROR_OF_RANGE) is not sensor noise."""
MAX_ERROR_OF_RANGE = 0.02
"""... nor above this fraction of the region's median range: stereo depth cameras are specified
to about 2 % RMS of the range, and Kinect-class noise and depth steps grow with the range."""
MIN_KEPT = 0.8
"""A flat surface keeps at least this fraction of its points through the 5-sigma rejection."""
PLANE_THRESHOLD = 0.02
"""RANSAC inlier distance that finds the dominant plane [m] (`plane_region`)."""
PLANE_BAND_SIGMAS = 3.0
"""`plane_region` keeps the points within this many standard errors of the refitted plane."""
CLI_HINT = (
    "study one surface: --plane (the dominant plane's points), or a smaller --square/--region"
)


@dataclass(frozen=True, kw_only=True)
class VoxelStudyRow:
    voxel_cm: float | None
    """Voxel edge [cm]; None for the raw points (the report's "N/A" row)."""
    points: int
    """Points fitted: the region's, voxelized at voxel_cm."""
    kept: int
    """Points left when the 5-sigma rejection loop stops discarding."""
    error_mm: float
    """Standard error of the plane fit's residuals over the kept points [mm]."""


def plane_fit_iterative(points: np.ndarray, k: float = 5.0, max_rounds: int = 100):
    """(kept mask, residuals [m]) of the least-squares plane after discarding, round by round,
    the points more than k standard errors from it until none is discarded."""
    keep = np.ones(len(points), dtype=bool)
    for _ in range(max_rounds):
        p = points[keep]
        if len(p) < 4:
            raise CaptureError("fewer than 4 points left for the plane fit")
        centre = p.mean(axis=0)
        normal = np.linalg.svd(p - centre, full_matrices=False)[2][2]
        resid = (points - centre) @ normal
        sigma = np.sqrt(np.sum(resid[keep] ** 2) / (keep.sum() - 3))  # 3 plane parameters
        new = keep & (np.abs(resid) <= k * sigma)
        if new.sum() == keep.sum():
            return keep, resid
        keep = new
    return keep, resid


def voxel_study(points: np.ndarray, sizes_cm: list[float]) -> list[VoxelStudyRow]:
    """points: (N, 3) finite, of one flat surface [m]; a row for the raw points and one per
    voxel size [cm]."""
    rows = []
    for size in [None, *sizes_cm]:
        p = points if size is None else voxel_downsample(points, (size / 100.0,) * 3)
        keep, resid = plane_fit_iterative(p)
        err = float(np.sqrt(np.sum(resid[keep] ** 2) / (keep.sum() - 3)) * 1e3)
        rows.append(VoxelStudyRow(voxel_cm=size, points=len(p), kept=int(keep.sum()), error_mm=err))
    return rows


def planarity_warning(raw: VoxelStudyRow, range_m: float, hint: str = CLI_HINT) -> str | None:
    """Why the region does not look like one flat surface, or None if it does. raw: the study's
    row of the raw points; range_m: the region's median distance from the camera [m]; hint:
    what to do instead, in the caller's terms (flags, or a page's controls)."""
    limit = max(MAX_ERROR_MM, MAX_ERROR_OF_RANGE * range_m * 1e3)
    kept = raw.kept / raw.points
    why = []
    if raw.error_mm > limit:
        why.append(
            f"the plane fit's error is {raw.error_mm:.0f} mm, more than a depth camera's noise "
            f"on a flat surface {range_m:.1f} m away (at most ~{limit:.0f} mm)"
        )
    if kept < MIN_KEPT:
        why.append(
            f"only {kept:.0%} of the points lie within 5 standard errors of the plane "
            f"(a flat surface keeps {MIN_KEPT:.0%} or more)"
        )
    if not why:
        return None
    return f"the region does not look like one flat surface: {'; '.join(why)}; {hint}"


def square_region(points: np.ndarray, side: float) -> np.ndarray:
    """The points within a side x side square [m] around the optical axis (camera frame x, y),
    as the report sampled a 2 m x 2 m square of the wall in front of the camera."""
    if not (np.isfinite(side) and side > 0):
        raise CaptureError(f"square side {side!r}: expected a length > 0 [m]")
    half = side / 2
    return points[(np.abs(points[:, 0]) <= half) & (np.abs(points[:, 1]) <= half)]


def rect_region(points: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """The points ((N, 3) camera frame [m]: x right, y down, z forward) with x0 <= x <= x1 and
    y0 <= y <= y1 [m]: square_region's window anywhere in the view, e.g. y beyond the camera's
    height above the floor for the floor. Metres, not pixels, so that it works on every capture,
    organized or not, in the same frame as the square."""
    bounds = np.array([x0, y0, x1, y1], dtype=np.float64)
    if not np.all(np.isfinite(bounds)) or not (x0 < x1 and y0 < y1):
        raise CaptureError(
            f"region {x0:g},{y0:g},{x1:g},{y1:g}: expected x0,y0,x1,y1 [m] with x0 < x1 and "
            f"y0 < y1 (the lower bounds first)"
        )
    x, y = points[:, 0], points[:, 1]
    return points[(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)]


def plane_region(
    points: np.ndarray, seed: int, threshold: float = PLANE_THRESHOLD, max_rounds: int = 100
) -> np.ndarray:
    """The points ((N, 3) [m]) of the dominant plane: Open3D's RANSAC (seeded) finds it with
    inliers within threshold [m]; then, refitting by least squares each round, the band widens
    or narrows to PLANE_BAND_SIGMAS standard errors of the points in it until it settles.

    Why not the RANSAC inliers as they are: a fixed band cuts the surface's own scatter when the
    sensor is noisier than the band (the error then measures the band, about threshold/sqrt(3)).
    Why 3 and not the report's 5 standard errors: a band that re-admits points at 5 of them
    grows round after round into the clutter in front of a wall and takes the whole room; 3
    keeps 99.7 % of a surface's Gaussian noise and settles."""
    import open3d as o3d

    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise CaptureError(f"{len(points)} points: too few to find a plane (4 or more needed)")
    o3d.utility.random.seed(seed)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, inliers = cloud.segment_plane(threshold, 3, 1000)
    keep = np.zeros(len(points), dtype=bool)
    keep[np.asarray(inliers, dtype=np.int64)] = True
    for _ in range(max_rounds):
        if keep.sum() < 4:
            raise CaptureError(f"the dominant plane has {keep.sum()} points: too few to fit")
        p = points[keep]
        centre = p.mean(axis=0)
        normal = np.linalg.svd(p - centre, full_matrices=False)[2][2]
        resid = (points - centre) @ normal
        sigma = np.sqrt(np.sum(resid[keep] ** 2) / (keep.sum() - 3))
        new = np.abs(resid) <= PLANE_BAND_SIGMAS * sigma
        if np.array_equal(new, keep):
            break
        keep = new
    return points[keep]


def format_study(rows: list[VoxelStudyRow]) -> str:
    lines = [f"{'voxel size (cm)':>15} {'points':>8} {'points kept':>11} {'error (mm)':>10}"]
    for r in rows:
        size = "N/A" if r.voxel_cm is None else f"{r.voxel_cm:g}"
        lines.append(f"{size:>15} {r.points:8d} {r.kept:11d} {r.error_mm:10.3f}")
    return "\n".join(lines)


def study_json(rows: list[VoxelStudyRow], warning: str | None) -> dict:
    """The study as plain data: rows as in the CSV, and the planarity warning (or None)."""
    return {
        "rows": [
            {
                "voxel_cm": r.voxel_cm,
                "points": r.points,
                "points_kept": r.kept,
                "error_mm": round(r.error_mm, 4),
            }
            for r in rows
        ],
        "warning": warning,
    }


def study_csv(rows: list[VoxelStudyRow]) -> str:
    out = ["voxel_cm,points,points_kept,error_mm"]
    out += [
        f"{'' if r.voxel_cm is None else r.voxel_cm},{r.points},{r.kept},{r.error_mm:.4f}"
        for r in rows
    ]
    return "\n".join(out) + "\n"
