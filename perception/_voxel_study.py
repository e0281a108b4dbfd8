"""The voxelization study of Tong 2018, section 3.1 (table 3.1): how much does voxelizing a
capture of a flat wall or floor reduce its measurement error?

For each voxel size: voxelize; fit a plane by least squares; discard the points farther from it
than 5 standard errors; refit; repeat until no point is discarded. Report the points, the points
kept and the standard error of the residuals [mm].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._errors import CaptureError
from ._pipeline import voxel_downsample


@dataclass(frozen=True)
class VoxelStudyRow:
    voxel_cm: float | None
    """None for the raw points (the report's "N/A" row)."""
    points: int
    kept: int
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
        err = np.sqrt(np.sum(resid[keep] ** 2) / (keep.sum() - 3)) * 1e3
        rows.append(VoxelStudyRow(voxel_cm=size, points=len(p), kept=int(keep.sum()), error_mm=err))
    return rows


def square_region(points: np.ndarray, side: float) -> np.ndarray:
    """The points within a side x side square [m] around the optical axis (camera frame x, y),
    as the report sampled a 2 m x 2 m square of the wall in front of the camera."""
    half = side / 2
    return points[(np.abs(points[:, 0]) <= half) & (np.abs(points[:, 1]) <= half)]


def format_study(rows: list[VoxelStudyRow]) -> str:
    lines = [f"{'voxel size (cm)':>15} {'points':>8} {'points kept':>11} {'error (mm)':>10}"]
    for r in rows:
        size = "N/A" if r.voxel_cm is None else f"{r.voxel_cm:g}"
        lines.append(f"{size:>15} {r.points:8d} {r.kept:11d} {r.error_mm:10.3f}")
    return "\n".join(lines)


def study_csv(rows: list[VoxelStudyRow]) -> str:
    out = ["voxel_cm,points,points_kept,error_mm"]
    out += [f"{'' if r.voxel_cm is None else r.voxel_cm},{r.points},{r.kept},{r.error_mm:.4f}"
            for r in rows]  # fmt: skip
    return "\n".join(out) + "\n"
