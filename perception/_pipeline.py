"""From a capture to a simulation-ready terrain mesh (Tong 2018, sections 3.1-3.2).

crop (depth range) -> voxel grid (dx, dy, dz; centroid per voxel) -> statistical outliers ->
ground plane (RANSAC) and the camera-to-world transform (ground at z = 0, z up) or the user's
camera pose -> crop (world box) -> mesh -> every facet's normal toward the camera.

Frames: camera = x right, y down, z forward (the sensor's); world = z up, ground z = 0, x the
camera's x projected on the ground, origin where the optical axis meets the ground.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import trimesh

from ._capture import Capture
from ._errors import CaptureError

Method = Literal["grid", "poisson", "ball-pivot"]
METHODS: tuple[str, ...] = ("grid", "poisson", "ball-pivot")


@dataclass(frozen=True, kw_only=True)
class MeshingConfig:
    """Settings of the capture-to-mesh pipeline."""

    voxel: tuple[float, float, float] = (0.01, 0.01, 0.01)
    """Voxel size dx, dy, dz in the camera frame [m] (section 3.1)."""
    depth_range: tuple[float, float] = (0.3, 8.0)
    """Keep points this near/far along the optical axis [m] (Kinect v2: 0.5-4.5 m rated)."""
    crop: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    """World-frame box ((xmin, ymin, zmin), (xmax, ymax, zmax)) to keep [m]; None: all."""
    outlier_neighbours: int = 16
    outlier_std: float = 3.0
    """Statistical outlier removal: drop points whose mean distance to their neighbours is
    more than outlier_std standard deviations above the average."""
    ground_threshold: float = 0.015
    """RANSAC inlier distance of the ground plane [m]."""
    ground_iterations: int = 1000
    camera_pose: tuple[float, ...] | None = None
    """World pose of the camera x, y, z [m], qx, qy, qz, qw; None: from the ground plane."""
    method: Method = "grid"
    cell: float | None = None
    """Grid method: cell size of the height field [m] (default: dx)."""
    fill_holes: int = 2
    """Grid method: fill holes up to this many cells across from their neighbours."""
    poisson_depth: int = 9
    poisson_trim: float = 0.05
    """Poisson: drop the vertices of the lowest-density fraction (surface the data never saw)."""
    seed: int = 0
    """Seed of RANSAC."""


@dataclass(frozen=True, eq=False)
class Reconstruction:
    mesh: trimesh.Trimesh
    """Terrain in the world frame [m], every facet facing the camera."""
    world_from_camera: np.ndarray
    """(4, 4) transform of camera-frame points into the world frame."""
    counts: dict[str, int] = field(default_factory=dict)
    """Points after each stage, and triangles."""
    times: dict[str, float] = field(default_factory=dict)
    """Wall time of each stage [s]."""

    @property
    def camera_position(self) -> np.ndarray:
        return self.world_from_camera[:3, 3]


def voxel_downsample(points: np.ndarray, size: tuple[float, float, float]) -> np.ndarray:
    """Centroid of the points ((N, 3) [m], finite) in each voxel of size (dx, dy, dz) [m];
    (M, 3), one row per occupied voxel."""
    if len(points) == 0:
        return points.reshape(0, 3)
    d = np.asarray(size, dtype=np.float64)
    keys = np.floor(points / d).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    out = np.empty((len(counts), 3))
    for k in range(3):
        out[:, k] = np.bincount(inverse, weights=points[:, k]) / counts
    return out


def remove_outliers(points: np.ndarray, neighbours: int, std: float) -> np.ndarray:
    """(N, 3) -> the points Open3D's statistical outlier removal keeps."""
    import open3d as o3d

    if len(points) <= neighbours:
        return points
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, kept = cloud.remove_statistical_outlier(nb_neighbors=neighbours, std_ratio=std)
    return points[np.asarray(kept, dtype=np.int64)]


def fit_ground(points: np.ndarray, threshold: float, iterations: int, seed: int):
    """RANSAC plane of the points ((N, 3) camera frame [m]): (unit normal toward the camera,
    offset d with n.p + d = 0, inlier count)."""
    import open3d as o3d

    if len(points) < 3:
        raise CaptureError("too few points left to find the ground plane")
    o3d.utility.random.seed(seed)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    (a, b, c, d), inliers = cloud.segment_plane(threshold, 3, iterations)
    n = np.array([a, b, c])
    norm = np.linalg.norm(n)
    n, d = n / norm, d / norm
    if d < 0:  # the camera (the origin) is on the side the normal points to
        n, d = -n, -d
    return n, d, len(inliers)


def world_from_ground(normal: np.ndarray, d: float) -> np.ndarray:
    """(4, 4) camera -> world: z = the ground normal, ground at z = 0, x = the camera's x
    projected on the ground, origin where the optical axis meets the ground (or the foot of
    the camera when it looks away from the ground)."""
    z = normal
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:  # camera x along the normal: use camera z instead
        x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    axis = np.array([0.0, 0.0, 1.0])
    denom = normal @ axis
    t = -d / denom if denom < -1e-6 else None  # the optical axis hits the ground ahead
    origin = axis * t if t is not None and t > 0 else -d * normal
    rot = np.stack([x, y, z])  # rows: world axes in camera coordinates
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = -rot @ origin
    return out


def pose_matrix(pose: tuple[float, ...]) -> np.ndarray:
    """x, y, z, qx, qy, qz, qw -> (4, 4)."""
    if len(pose) != 7:
        raise CaptureError(f"camera pose {pose}: expected x,y,z,qx,qy,qz,qw")
    x, y, z, qx, qy, qz, qw = pose
    q = np.array([qx, qy, qz, qw], dtype=float)
    if not np.isfinite(q).all() or np.linalg.norm(q) < 1e-9:
        raise CaptureError(f"camera pose {pose}: the quaternion must be finite and non-zero")
    qx, qy, qz, qw = q / np.linalg.norm(q)
    out = np.eye(4)
    out[:3, :3] = [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]
    out[:3, 3] = (x, y, z)
    return out


def reconstruct(capture: Capture, cfg: MeshingConfig = MeshingConfig()) -> Reconstruction:
    """The terrain mesh of a capture, world frame; CaptureError when a stage has nothing left."""
    times: dict[str, float] = {}
    counts: dict[str, int] = {"points": int(capture.valid.sum())}
    t = time.perf_counter()

    def stage(name: str, n: int | None = None) -> None:
        nonlocal t
        now = time.perf_counter()
        times[name] = now - t
        t = now
        if n is not None:
            counts[name] = int(n)
            if n == 0:
                raise CaptureError(f"{capture.source}: no points left after the {name} stage")

    origin = np.asarray(capture.sensor_origin, dtype=np.float64)
    pts = capture.finite_points() - origin
    near, far = cfg.depth_range
    pts = pts[(pts[:, 2] >= near) & (pts[:, 2] <= far)]
    stage("depth range", len(pts))
    pts = voxel_downsample(pts, cfg.voxel)
    stage("voxel", len(pts))
    pts = remove_outliers(pts, cfg.outlier_neighbours, cfg.outlier_std)
    stage("outliers", len(pts))
    if cfg.camera_pose is not None:
        wfc = pose_matrix(cfg.camera_pose)
    else:
        normal, d, inliers = fit_ground(pts, cfg.ground_threshold, cfg.ground_iterations, cfg.seed)
        counts["ground inliers"] = inliers
        wfc = world_from_ground(normal, d)
    world = pts @ wfc[:3, :3].T + wfc[:3, 3]
    if cfg.crop is not None:
        lo, hi = np.asarray(cfg.crop[0]), np.asarray(cfg.crop[1])
        world = world[np.all((world >= lo) & (world <= hi), axis=1)]
    stage("ground", len(world))
    camera = wfc[:3, 3]
    if cfg.method == "grid":
        mesh = grid_mesh(world, cfg.cell or cfg.voxel[0], camera, cfg.fill_holes)
    else:
        mesh = surface_mesh(world, camera, cfg)
    stage("mesh")
    if len(mesh.faces) == 0:
        raise CaptureError(f"{capture.source}: meshing produced no triangles")
    counts["triangles"] = len(mesh.faces)
    return Reconstruction(mesh=mesh, world_from_camera=wfc, counts=counts, times=times)


def grid_mesh(
    points: np.ndarray, cell: float, camera: np.ndarray, fill_holes: int
) -> trimesh.Trimesh:
    """2.5D height field of world points ((N, 3) [m]) triangulated: each cell's highest point
    (the surface a robot stands on), two triangles per 2x2 block of occupied cells. Cells the
    camera never saw (behind an obstacle) stay empty, so no triangle spans an occlusion; small
    holes (sensor dropouts) are filled from their neighbours. Triangles facing away from the
    camera (surfaces it cannot have seen) are dropped: every facet faces the camera and up."""
    xy0 = points[:, :2].min(axis=0)
    ij = np.floor((points[:, :2] - xy0) / cell).astype(np.int64)
    nx, ny = ij.max(axis=0) + 1
    z = np.full((ny, nx), -np.inf)
    np.maximum.at(z, (ij[:, 1], ij[:, 0]), points[:, 2])
    z[~np.isfinite(z)] = np.nan
    z = _fill_small_holes(z, fill_holes)
    ys, xs = np.mgrid[0:ny, 0:nx]
    verts = np.column_stack([
        xy0[0] + (xs.ravel() + 0.5) * cell, xy0[1] + (ys.ravel() + 0.5) * cell, z.ravel()
    ])  # fmt: skip
    idx = np.arange(ny * nx).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]  # d is a's diagonal
    ok = np.isfinite(verts[:, 2])
    faces = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )  # fmt: skip  (counter-clockwise seen from +z: normals up)
    faces = faces[ok[faces].all(axis=1)]
    faces = faces[_faces_camera(verts, faces, camera)]
    mesh = trimesh.Trimesh(verts, faces, process=False)
    mesh.remove_unreferenced_vertices()
    return mesh


def _fill_small_holes(z: np.ndarray, rounds: int) -> np.ndarray:
    """Fill empty cells that have at least 5 of 8 occupied neighbours with their mean, `rounds`
    times: dropouts close, the shadows behind obstacles (wide) stay open."""
    z = z.copy()
    for _ in range(rounds):
        pad = np.pad(z, 1, constant_values=np.nan)
        h, w = z.shape
        stack = np.stack([pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
                          for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx])  # fmt: skip
        n = np.isfinite(stack).sum(axis=0)
        fill = np.isnan(z) & (n >= 5)
        if not fill.any():
            break
        z[fill] = np.nanmean(stack[:, fill], axis=0)
    return z


def _faces_camera(verts: np.ndarray, faces: np.ndarray, camera: np.ndarray) -> np.ndarray:
    """(F,) bool: <x_i, n_i> <= 0, with x_i the facet centre relative to the camera."""
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return np.einsum("ij,ij->i", tri.mean(axis=1) - camera, n) <= 0


def surface_mesh(points: np.ndarray, camera: np.ndarray, cfg: MeshingConfig) -> trimesh.Trimesh:
    """Open3D Poisson (density-trimmed) or ball pivoting over world points, with normals
    estimated and oriented toward the camera; then each facet turned to face the camera."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    radius = 3.0 * max(cfg.voxel)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
    cloud.orient_normals_towards_camera_location(camera)
    if cfg.method == "poisson":
        mesh, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            cloud, depth=cfg.poisson_depth
        )
        density = np.asarray(density)
        mesh.remove_vertices_by_mask(density < np.quantile(density, cfg.poisson_trim))
        mesh = mesh.crop(cloud.get_axis_aligned_bounding_box())
    else:
        radii = [1.5 * max(cfg.voxel), 3.0 * max(cfg.voxel), 6.0 * max(cfg.voxel)]
        mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_ball_pivoting(
            cloud, o3d.utility.DoubleVector(radii)
        )
    verts = np.asarray(mesh.vertices)
    faces = np.asarray(mesh.triangles, dtype=np.int64)
    away = ~_faces_camera(verts, faces, camera)
    faces[away] = faces[away][:, ::-1]  # section 3.2: <x_i, n_i> <= 0 for every facet
    out = trimesh.Trimesh(verts, faces, process=False)
    out.remove_unreferenced_vertices()
    return out


@dataclass(frozen=True, kw_only=True)
class CaptureSettings:
    """How to read and mesh one capture: a scene's `perception:` block or `roachplan mesh`'s
    flags."""

    meshing: MeshingConfig = MeshingConfig()
    intrinsics: str | None = None
    """Preset name or file path (depth images)."""
    depth_scale: float | None = None
    """Depth units per metre (depth images; default 1000 or the sidecar's)."""
    units: Literal["m", "mm"] = "m"
    topic: str | None = None
    """Bag topic."""


SETTING_KEYS = ("voxel", "method", "intrinsics", "depth_scale", "units", "topic", "camera_pose",
                "crop", "depth_range", "cell", "outlier_std", "ground_threshold", "seed")  # fmt: skip


def _num(k: str, v, lo: float = 0.0) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not v > lo:
        raise CaptureError(f"{k}: expected a number > {lo:g}, got {v!r}")
    return float(v)


def _vec(k: str, v, n: int, lo: float = -np.inf) -> tuple[float, ...]:
    if not isinstance(v, list | tuple) or len(v) != n:
        raise CaptureError(f"{k}: expected a list of {n} numbers, got {v!r}")
    return tuple(_num(k, x, lo) for x in v)


def _choice(k: str, v, options: tuple[str, ...]) -> str:
    if v not in options:
        raise CaptureError(f"{k}: {v!r} is not one of {', '.join(options)}")
    return v


def _crop(k: str, v):
    if not isinstance(v, list | tuple) or len(v) != 2:
        raise CaptureError(f"{k}: expected [[xmin, ymin, zmin], [xmax, ymax, zmax]], got {v!r}")
    return (_vec(f"{k}[0]", v[0], 3), _vec(f"{k}[1]", v[1], 3))


def _seed(k: str, v) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise CaptureError(f"{k}: expected a non-negative integer, got {v!r}")
    return v


_MESHING_PARSERS = {
    "voxel": lambda k, v: _vec(k, v, 3, 0.0) if isinstance(v, list | tuple) else (_num(k, v),) * 3,
    "method": lambda k, v: _choice(k, v, METHODS),
    "camera_pose": lambda k, v: _vec(k, v, 7),
    "crop": _crop,
    "depth_range": lambda k, v: _vec(k, v, 2, 0.0),
    "cell": _num,
    "outlier_std": _num,
    "ground_threshold": _num,
    "seed": _seed,
}


def capture_settings(data: dict, resolve=lambda p: p) -> CaptureSettings:
    """Validate a mapping of capture settings (keys SETTING_KEYS); CaptureError names the key.
    resolve: turns a relative intrinsics file name into a path (e.g. beside a scene file)."""
    from ._camera import PRESETS

    if not isinstance(data, dict):
        raise CaptureError(f"expected a mapping with keys {', '.join(SETTING_KEYS)}, got {data!r}")
    data = {k: v for k, v in data.items() if v is not None}  # null: the default
    for k in data:
        if k not in SETTING_KEYS:
            raise CaptureError(f"{k}: unknown key; accepted keys: {', '.join(SETTING_KEYS)}")
    meshing = {k: parse(k, data[k]) for k, parse in _MESHING_PARSERS.items() if k in data}
    intr = data.get("intrinsics")
    if intr is not None and not isinstance(intr, str):
        raise CaptureError(f"intrinsics: expected a preset name or a file name, got {intr!r}")
    topic = data.get("topic")
    if topic is not None and not isinstance(topic, str):
        raise CaptureError(f"topic: expected a topic name, got {topic!r}")
    return CaptureSettings(
        meshing=MeshingConfig(**meshing),
        intrinsics=None if intr is None else (intr if intr in PRESETS else str(resolve(intr))),
        depth_scale=_num("depth_scale", data["depth_scale"]) if "depth_scale" in data else None,
        units=_choice("units", data.get("units", "m"), ("m", "mm")),  # type: ignore[arg-type]
        topic=topic,
    )


def mesh_capture(path, settings: CaptureSettings = CaptureSettings()) -> Reconstruction:
    """Read a capture file and reconstruct its terrain."""
    from ._capture import load_capture

    cap = load_capture(path, intrinsics=settings.intrinsics, depth_scale=settings.depth_scale,
                       topic=settings.topic, units=settings.units)  # fmt: skip
    return reconstruct(cap, settings.meshing)
