"""From a capture to a simulation-ready terrain mesh (Tong 2018, sections 3.1-3.2).

crop (depth range) -> (the sensor method, an organized capture: pixels averaged in blocks
about a voxel across) -> voxel grid (dx, dy, dz; centroid per voxel) -> statistical outliers ->
ground (perception/_ground.py: the lowest well-supported plane facing up under a gravity prior)
and the capture-to-world transform (ground at z = 0, z up) or the user's camera pose -> crop
(world box) -> mesh -> every facet's normal toward the camera.

Frames: camera = x right, y down, z forward (the sensor's optical frame); world = z up, ground
z = 0, x the camera's x projected on the ground, origin where the optical axis meets the ground.
A cloud already in a world frame (a lidar's or a map's, z up) keeps its axes: only its ground
is put at z = 0 and, when georeferenced (UTM), its centre at the origin.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import trimesh

from ._capture import Capture, depth_scale_advice, is_georeferenced
from ._errors import CaptureError
from ._ground import CAMERA_UP, Z_UP, GroundChoice, GroundConfig, choose_ground
from ._settings import CaptureSettings, MeshingConfig
from ._surface import (
    Blocks,
    Surface,
    block_image,
    organized_surface,
    projected_surface,
    range_noise_model,
    scattered_surface,
)

CAMERA_DEPTH_RANGE = (0.3, 8.0)
"""Default depth range of a camera-frame capture [m] (Kinect v2: 0.5-4.5 m rated)."""
MAX_GRID_CELLS = 40_000_000
"""Largest height field the grid method builds (~1 GB of arrays); beyond it, crop."""


@dataclass(frozen=True, eq=False)
class Reconstruction:
    mesh: trimesh.Trimesh
    """Terrain in the world frame [m], every facet facing the camera."""
    world_from_camera: np.ndarray
    """(4, 4) transform of capture-frame points into the world frame."""
    counts: dict[str, int] = field(default_factory=dict)
    """Points after each stage, and triangles."""
    times: dict[str, float] = field(default_factory=dict)
    """Wall time of each stage [s]."""
    frame: Literal["camera", "world"] = "camera"
    """The capture's frame as read."""
    up_source: str = ""
    """Where the gravity prior came from."""
    ground: GroundChoice | None = None
    """The ground plane found (None when a camera pose was given)."""
    warnings: tuple[str, ...] = ()
    """What the user should check."""
    notes: tuple[str, ...] = ()
    """What was assumed or adapted."""

    @property
    def camera_position(self) -> np.ndarray:
        return self.world_from_camera[:3, 3]

    @property
    def camera_pose(self) -> list[float] | None:
        """[x, y, z, qx, qy, qz, qw]: the camera in the world; None for a world-frame cloud."""
        if self.frame != "camera":
            return None
        from scipy.spatial.transform import Rotation

        quat = Rotation.from_matrix(self.world_from_camera[:3, :3]).as_quat()
        return [*map(float, self.world_from_camera[:3, 3]), *map(float, quat)]

    def to_capture_frame(self, p_world: np.ndarray) -> np.ndarray:
        """(..., 3) world points [m] -> the same points in the capture's frame [m]."""
        inv = np.linalg.inv(self.world_from_camera)
        return np.asarray(p_world) @ inv[:3, :3].T + inv[:3, 3]

    def report(self) -> dict:
        """What was found, as plain data (the `mesh --json` output)."""
        out: dict = {"frame": self.frame, "camera_pose": None, "up_source": self.up_source}
        pose = self.camera_pose
        if pose is not None:
            out["camera_pose"] = [round(v, 6) for v in pose]
            up = self.world_from_camera[2, :3]  # world z in camera coordinates
            out["camera_height_m"] = round(float(self.world_from_camera[2, 3]), 4)
            out["pitch_down_deg"] = round(float(np.degrees(np.arcsin(-np.clip(up[2], -1, 1)))), 2)
            out["roll_deg"] = round(float(np.degrees(np.arctan2(up[0], -up[1]))), 2)
        else:
            out["origin_in_capture_frame"] = [
                round(float(v), 4) for v in self.to_capture_frame(np.zeros(3))
            ]
        if self.ground is not None:
            g = self.ground
            out["ground"] = {
                "normal_in_capture_frame": [round(float(v), 5) for v in g.normal],
                "support_points": g.support,
                "support_fraction": round(g.fraction, 4),
                "area_m2": round(g.area, 3),
            }
        out["triangles"] = int(len(self.mesh.faces))
        out["bounds"] = self.mesh.bounds.round(4).tolist() if len(self.mesh.faces) else None
        out["counts"] = dict(self.counts)
        out["seconds"] = {k: round(v, 4) for k, v in self.times.items()}
        out["warnings"] = list(self.warnings)
        out["notes"] = list(self.notes)
        return out


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


def world_from_ground(normal: np.ndarray, d: float, reach: float = 8.0) -> np.ndarray:
    """(4, 4) camera -> world: z = the ground normal, ground at z = 0, x = the camera's x
    projected on the ground, origin where the optical axis meets the ground within reach [m]
    (else the foot of the camera: a level camera's axis meets the floor far beyond what it
    saw)."""
    z = normal
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:  # camera x along the normal: use camera z instead
        x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    axis = np.array([0.0, 0.0, 1.0])
    denom = normal @ axis
    t = -d / denom if denom < -1e-6 else None  # the optical axis hits the ground ahead
    origin = axis * t if t is not None and 0 < t <= reach else -d * normal
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
    if abs(np.linalg.norm(q) - 1.0) > 1e-3:
        raise CaptureError(
            f"camera pose {pose}: the quaternion (qx, qy, qz, qw) has norm "
            f"{np.linalg.norm(q):.4f}; give a unit quaternion"
        )
    qx, qy, qz, qw = q / np.linalg.norm(q)
    out = np.eye(4)
    out[:3, :3] = [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]
    out[:3, 3] = (x, y, z)
    return out


CAMERA_MAX_TAN = 2.0
"""No depth camera sees wider than this tangent off its optical axis (127 deg across; the
widest, a 120 deg wide-angle mode, reaches 1.73) [-]."""


def capture_frame(capture: Capture, points: np.ndarray, cfg: MeshingConfig) -> str:
    """ "camera" or "world": the config's, else the file's word, else from the points ((N, 3)
    finite, relative to the sensor): a georeferenced cloud, one with points behind the
    sensor (a lidar all round it; a camera sees only z > 0), or one spread wider than any
    camera's field of view (a lidar's patch of ground, its z up and small) is a world frame."""
    if cfg.frame != "auto":
        return cfg.frame
    if capture.frame is not None:
        return capture.frame
    if is_georeferenced(points) or np.mean(points[:, 2] <= 0.0) > 0.05:
        return "world"
    z = np.maximum(points[:, 2], 1e-12)
    off_axis = np.maximum(np.abs(points[:, 0]), np.abs(points[:, 1])) / z
    if np.mean(off_axis > CAMERA_MAX_TAN) > 0.05:
        return "world"
    return "camera"


def gravity_prior(capture: Capture, frame: str, cfg: MeshingConfig) -> tuple[np.ndarray, str]:
    """(up (3,) unit in the capture frame, where it came from)."""
    if cfg.up is not None:
        up, source = np.asarray(cfg.up, dtype=np.float64), "given (up)"
    elif capture.base_from_camera is not None:
        # The camera's pose in a z-up robot frame (a calibration file's local_transform).
        up, source = np.asarray(capture.base_from_camera)[2, :3], "the calibration's camera pose"
    elif capture.up is not None:
        up, source = np.asarray(capture.up, dtype=np.float64), "the IMU"
    elif frame == "camera":
        up, source = np.asarray(CAMERA_UP), "assumed: camera roughly level (up = -y)"
    else:
        up, source = np.asarray(Z_UP), "assumed: world frame, z up"
    norm = np.linalg.norm(up)
    if not np.isfinite(norm) or norm < 1e-9:
        raise CaptureError(f"up {up.tolist()}: expected a non-zero direction x,y,z")
    return up / norm, source


def _rotation_to_z(up: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking the unit vector up to +z (the smallest such rotation)."""
    z = np.array([0.0, 0.0, 1.0])
    v, c = np.cross(up, z), float(up @ z)
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


STAGES: tuple[str, ...] = ("depth range", "voxel", "outliers", "ground", "mesh")
"""The pipeline's stages after reading, in order (Reconstruction.times has one entry each)."""


class _Stages:
    """The pipeline's bookkeeping: each stage's wall time and points left, and progress."""

    def __init__(self, source: str, on_stage: Callable[[str], None] | None) -> None:
        self.source, self.on_stage = source, on_stage
        self.times: dict[str, float] = {}
        self.counts: dict[str, int] = {}
        self._t = time.perf_counter()

    def done(self, name: str, n: int | None = None) -> None:
        """Stage `name` ended with n points left (CaptureError when none is)."""
        now = time.perf_counter()
        self.times[name], self._t = now - self._t, now
        if self.on_stage is not None:
            self.on_stage(name)
        if n is not None:
            self.counts[name] = int(n)
            if n == 0:
                raise CaptureError(f"{self.source}: no points left after the {name} stage")


@dataclass(frozen=True, eq=False)
class _Placement:
    """Where a capture sits in the world."""

    world_from_file: np.ndarray
    """(4, 4) the file's own coordinates -> world."""
    world_from_centred: np.ndarray
    """(4, 4) points relative to the sensor (a camera frame) or as read (a world frame) ->
    world."""
    frame: Literal["camera", "world"]
    up_source: str
    ground: GroundChoice | None


def reconstruct(
    capture: Capture,
    cfg: MeshingConfig = MeshingConfig(),
    on_stage: Callable[[str], None] | None = None,
) -> Reconstruction:
    """The terrain mesh of a capture, world frame; CaptureError when a stage has nothing left.
    on_stage(name) is called as each of STAGES ends (progress)."""
    log = _Stages(capture.source, on_stage)
    log.counts["points"] = int(capture.valid.sum())
    warnings: list[str] = []
    notes: list[str] = list(capture.notes)
    raw = capture.finite_points()
    frame = capture_frame(capture, raw - np.asarray(capture.sensor_origin), cfg)
    origin = np.asarray(capture.sensor_origin, dtype=np.float64)
    pts = raw - origin if frame == "camera" else raw
    inside = _in_depth_range(capture, raw - origin, frame, cfg, warnings)
    pts = pts[inside]
    log.done("depth range", len(pts))
    kept = np.zeros(len(capture.points), dtype=bool)  # the file's points the stages keep
    kept[np.flatnonzero(capture.valid)[inside]] = True
    blocks = _blocks(capture, kept, frame, cfg, notes)
    if blocks is not None:  # the ground is found on a pixel of each block
        pts = blocks.samples[blocks.ok]
    pts = voxel_downsample(pts, cfg.voxel)
    log.done("voxel", len(pts))
    pts = remove_outliers(pts, cfg.outlier_neighbours, cfg.outlier_std)
    log.done("outliers", len(pts))
    placed = _place(capture, pts, frame, cfg, warnings=warnings, notes=notes)
    if placed.ground is not None:
        log.counts["ground inliers"] = placed.ground.support
    wfc = placed.world_from_file
    world = (pts + (origin if placed.frame == "camera" else 0.0)) @ wfc[:3, :3].T + wfc[:3, 3]
    in_crop = _crop_mask(world, cfg.crop)
    world = world[in_crop]
    log.done("ground", len(world))
    if cfg.method == "sensor":
        surface = _sensor_surface(
            capture, kept, blocks, pts=pts[in_crop], world=world, placed=placed, cfg=cfg
        )
        mesh = surface_to_mesh(surface)
        total = surface.observed_area + surface.filled_area
        notes.append(
            f"surface: {surface.observed_area:.2f} m^2 between measured samples; "
            f"{surface.filled_area:.2f} m^2 ({100 * surface.filled_area / max(total, 1e-12):.1f} %) "
            f"filled in from the rims of small holes; what the sensor did not see is left "
            f"open (not walkable)"
        )
        log.counts["filled vertices"] = int(surface.filled.sum())
    else:
        camera = wfc[:3, 3] if placed.frame == "camera" else _overhead(world)
        mesh = _other_mesh(world, camera, cfg, capture.source, notes)
    log.done("mesh")
    if len(mesh.faces) == 0:
        raise CaptureError(f"{capture.source}: meshing produced no triangles")
    log.counts["triangles"] = len(mesh.faces)
    below = float(np.percentile(world[:, 2], 1)) if placed.frame == "camera" else 0.0
    if below < -0.25:
        warnings.append(
            f"1 % of the terrain lies more than {-below:.2f} m below the ground chosen: the "
            f"ground may be a raised surface (a table), or the up direction wrong"
        )
    return Reconstruction(
        mesh=mesh,
        world_from_camera=wfc,
        counts=log.counts,
        times=log.times,
        frame=placed.frame,
        up_source=placed.up_source,
        ground=placed.ground,
        warnings=tuple(warnings),
        notes=tuple(notes),
    )


def _blocks(
    capture: Capture, kept: np.ndarray, frame: str, cfg: MeshingConfig, notes: list[str]
) -> Blocks | None:
    """An organized capture's pixels (kept (N,) bool: those the stages keep) in blocks about
    a voxel across (block_image), for the sensor method, which meshes the blocks and finds the
    ground on a pixel of each rather than on every pixel of a high-resolution image; None for
    another method or an unorganized cloud."""
    shape = capture.shape
    camera = frame == "camera" or cfg.camera_pose is not None
    if cfg.method != "sensor" or shape is None or not camera:
        return None
    origin = np.asarray(capture.sensor_origin, dtype=np.float64)
    grid = np.where(kept[:, None], capture.points - origin, np.nan)
    blocks = block_image(grid.reshape(*shape, 3), kept.reshape(shape), cfg.voxel[0])
    if blocks.stride > 1:
        notes.append(
            f"depth image averaged in blocks of {blocks.stride} x {blocks.stride} pixels "
            f"(about {cfg.voxel[0]:g} m across at the median range)"
        )
    return blocks


def _in_depth_range(
    capture: Capture, centred: np.ndarray, frame: str, cfg: MeshingConfig, warnings: list[str]
) -> np.ndarray:
    """(N,) bool: the finite points (centred: (N, 3) relative to the sensor [m]) inside the
    depth range: along the optical axis in a camera frame, from the sensor in a world frame
    (which keeps everything by default). CaptureError when most pixels of a depth image fall
    outside the default range (a wrong depth scale, with the one that fits); a warning when a
    range the user chose leaves out most."""
    if frame == "camera":
        near, far = cfg.depth_range or CAMERA_DEPTH_RANGE
        inside = (centred[:, 2] >= near) & (centred[:, 2] <= far)
    elif cfg.depth_range is not None:
        near, far = cfg.depth_range
        dist = np.linalg.norm(centred, axis=1)
        inside = (dist >= near) & (dist <= far)
    else:
        inside = np.ones(len(centred), dtype=bool)
    advice = depth_scale_advice(capture, cfg.depth_range or CAMERA_DEPTH_RANGE)
    if advice is not None and inside.mean() < 0.5:
        if cfg.depth_range is None:  # the default range: most likely a wrong scale
            raise CaptureError(f"{capture.source}: {advice}")
        # A range the user chose keeps what it keeps; the scale may still be wrong.
        warnings.append(
            f"{100 * (1 - inside.mean()):.0f} % of the points are outside the depth "
            f"range given; if that is not meant: {advice}"
        )
    return inside


def _place(
    capture: Capture,
    pts: np.ndarray,
    frame: str,
    cfg: MeshingConfig,
    *,
    warnings: list[str],
    notes: list[str],
) -> _Placement:
    """Where the capture's points (pts: (N, 3), relative to the sensor in a camera frame, as
    read in a world frame [m]) sit in the world: the camera pose given, or the ground found
    (a camera frame), or the world frame's ground at z = 0."""
    origin = np.asarray(capture.sensor_origin, dtype=np.float64)
    up, up_source = gravity_prior(capture, frame, cfg)
    gcfg = GroundConfig(
        threshold=cfg.ground_threshold, iterations=cfg.ground_iterations, seed=cfg.seed
    )
    near_point = None
    if cfg.ground_point is not None:
        near_point = np.asarray(cfg.ground_point) - (origin if frame == "camera" else 0.0)
    ground = None
    if cfg.camera_pose is not None:
        centred = pose_matrix(cfg.camera_pose)
        if frame != "camera":
            notes.append("a camera pose was given: the cloud is taken as in the camera's frame")
        frame, up_source = "camera", "the camera pose given"
    elif frame == "camera":
        ground = choose_ground(pts, up, gcfg, near=near_point)
        warnings.extend(ground.warnings)
        reach = (cfg.depth_range or CAMERA_DEPTH_RANGE)[1]
        centred = world_from_ground(ground.normal, ground.offset, reach)
    else:
        centred, ground = _world_frame_transform(
            pts, up, gcfg=gcfg, cfg=cfg, near=near_point, notes=notes
        )
    # A camera frame's transforms took points relative to the sensor; the file's own
    # coordinates have the sensor at its origin.
    from_file = centred @ _translation(-origin) if frame == "camera" else centred
    return _Placement(
        world_from_file=from_file,
        world_from_centred=centred,
        frame="camera" if frame == "camera" else "world",
        up_source=up_source,
        ground=ground,
    )


def _sensor_surface(
    capture: Capture,
    kept: np.ndarray,
    blocks: Blocks | None,
    *,
    pts: np.ndarray,
    world: np.ndarray,
    placed: _Placement,
    cfg: MeshingConfig,
) -> Surface:
    """The sensor method's surface (perception/_surface.py): an organized capture block to
    block (blocks: its pixels averaged, block_image; kept (N,) bool: the file's points the
    stages kept, whose spread gives the sensor's noise), within the crop box; an unorganized
    camera cloud by its directions (pts: the kept, cropped points relative to the sensor); a
    world-frame cloud by x, y (world: the same points in the world [m])."""
    if blocks is not None:
        origin = np.asarray(capture.sensor_origin, dtype=np.float64)
        to_world = placed.world_from_centred
        pick = np.flatnonzero(kept)
        if cfg.crop is not None:
            near = capture.points[pick] - origin
            pick = pick[_crop_mask(near @ to_world[:3, :3].T + to_world[:3, 3], cfg.crop)]
        # The noise model takes 20,000 of the pixels (range_noise_model), not the million of
        # a high-resolution image.
        raw = capture.points[pick[:: max(1, len(pick) // 20000)]] - origin
        ok = blocks.ok.copy()
        ok[ok] = _crop_mask(blocks.points[ok] @ to_world[:3, :3].T + to_world[:3, 3], cfg.crop)
        model = range_noise_model(raw, camera=True)
        return organized_surface(blocks, ok, to_world, cfg.max_fill, model)
    if placed.frame == "camera":
        return projected_surface(pts, placed.world_from_centred, cfg.max_fill)
    return scattered_surface(world, cfg.max_fill)


def _other_mesh(
    world: np.ndarray, camera: np.ndarray, cfg: MeshingConfig, source: str, notes: list[str]
) -> trimesh.Trimesh:
    """The grid, Poisson or ball-pivoting mesh of the world points ((N, 3) [m]) seen from
    camera ((3,) [m])."""
    if cfg.method != "grid":
        return surface_mesh(world, camera, cfg)
    cell = cfg.cell or cfg.voxel[0]
    if cfg.cell is None:
        spacing = _point_spacing(world)
        if spacing > 2.0 * cell:
            notes.append(
                f"points are {spacing:.3g} m apart: height field cells of "
                f"{spacing:.3g} m instead of {cell:g} m"
            )
            cell = spacing
    return grid_mesh(world, cell, camera, cfg.fill_holes, source=source)


def _crop_mask(world: np.ndarray, crop) -> np.ndarray:
    """(N,) bool: the world points ((N, 3) [m]) inside the crop box ((lo, hi) or None: all)."""
    if crop is None:
        return np.ones(len(world), dtype=bool)
    lo, hi = np.asarray(crop[0]), np.asarray(crop[1])
    return np.all((world >= lo) & (world <= hi), axis=1)


def surface_to_mesh(surface: Surface) -> trimesh.Trimesh:
    """A Surface as a trimesh mesh whose vertices carry "height_noise" [m] and whose faces
    carry "filled" (1.0 where a triangle fills a hole): the scene keeps them through placing
    and merging, the planner's height field takes the noise (scenes/_world.py), and the page
    draws filled triangles apart from measured ones."""
    return trimesh.Trimesh(
        surface.vertices,
        surface.faces,
        process=False,
        vertex_attributes={"height_noise": surface.height_noise},
        face_attributes={"filled": surface.filled_faces.astype(np.float64)},
    )


def _translation(t: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = t
    return out


def _overhead(world: np.ndarray) -> np.ndarray:
    """A viewpoint high above a world-frame cloud ((N, 3)): facets then face up."""
    centre = np.median(world, axis=0)
    return np.array([centre[0], centre[1], world[:, 2].max() + 1e4])


def _world_frame_transform(
    pts: np.ndarray,
    up: np.ndarray,
    *,
    gcfg: GroundConfig,
    cfg: MeshingConfig,
    near: np.ndarray | None,
    notes: list[str],
) -> tuple[np.ndarray, GroundChoice | None]:
    """A world-frame cloud ((N, 3)) keeps its axes (turned only when `up` is not +z); its
    ground goes to z = 0: the lowest well-supported level plane when there is one, else the
    cloud's 2nd percentile of height (hilly terrain); a georeferenced cloud's centre goes to
    x = y = 0 (the offset is in the notes and in world_from_camera)."""
    rot = _rotation_to_z(up)
    turned = pts @ rot.T
    ground = None
    try:
        choice = choose_ground(
            turned,
            np.array([0.0, 0.0, 1.0]),
            GroundConfig(**{**gcfg.__dict__, "prior_tolerance_deg": 15.0}),
            near=None if near is None else rot @ near,
            toward_sensor=False,
        )
    except CaptureError:
        choice = None
    centre = np.median(turned, axis=0)
    if choice is not None and (near is not None or not choice.warnings):
        n, d = choice.normal, choice.offset
        z0 = -(n[0] * centre[0] + n[1] * centre[1] + d) / n[2]
        ground = choice
    else:
        z0 = float(np.percentile(turned[:, 2], 2))
        notes.append("no level ground plane: the ground height is the terrain's 2nd percentile")
    recentre = is_georeferenced(pts) if cfg.recentre is None else cfg.recentre
    shift = np.array([-centre[0], -centre[1], -z0]) if recentre else np.array([0.0, 0.0, -z0])
    if recentre:
        notes.append(
            f"recentred: the capture-frame point ({centre[0]:.3f}, {centre[1]:.3f}, {z0:.3f}) "
            f"is the world origin"
        )
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = shift
    return out, ground


def _point_spacing(world: np.ndarray) -> float:
    """Median distance [m] from a point to its nearest neighbour in x, y (of up to 20,000
    evenly strided points of world, (N, 3))."""
    from scipy.spatial import KDTree

    xy = world[:: max(1, len(world) // 20000), :2]
    if len(xy) < 2:
        return 0.0
    dist, _ = KDTree(xy).query(xy, k=2)
    return float(np.median(dist[:, 1]))


def grid_mesh(
    points: np.ndarray, cell: float, camera: np.ndarray, fill_holes: int, source: str = "the cloud"
) -> trimesh.Trimesh:
    """2.5D height field of world points ((N, 3) [m]) triangulated: each cell's highest point
    (the surface a robot stands on), two triangles per 2x2 block of occupied cells. Cells the
    camera never saw (behind an obstacle) stay empty, so no triangle spans an occlusion; small
    holes (sensor dropouts) are filled from their neighbours. Triangles facing away from the
    camera (surfaces it cannot have seen) are dropped: every facet faces the camera and up."""
    xy0 = points[:, :2].min(axis=0)
    ij = np.floor((points[:, :2] - xy0) / cell).astype(np.int64)
    nx, ny = ij.max(axis=0) + 1
    if nx * ny > MAX_GRID_CELLS:
        w, h = points[:, :2].max(axis=0) - xy0
        raise CaptureError(
            f"{source}: the terrain spans {w:.1f} m x {h:.1f} m, {nx * ny / 1e6:.0f} million "
            f"cells of {cell:g} m (at most {MAX_GRID_CELLS / 1e6:.0f} million): crop it "
            f"(crop / --crop) or use a larger voxel (--voxel)"
        )
    z = np.full((ny, nx), -np.inf)
    np.maximum.at(z, (ij[:, 1], ij[:, 0]), points[:, 2])
    z[~np.isfinite(z)] = np.nan
    z = _fill_small_holes(z, fill_holes)
    ys, xs = np.mgrid[0:ny, 0:nx]
    verts = np.column_stack(
        [xy0[0] + (xs.ravel() + 0.5) * cell, xy0[1] + (ys.ravel() + 0.5) * cell, z.ravel()]
    )
    idx = np.arange(ny * nx).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]  # d is a's diagonal
    ok = np.isfinite(verts[:, 2])
    faces = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )  # counter-clockwise seen from +z: normals up
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
        stack = np.stack(
            [
                pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
                for dy in (-1, 0, 1)
                for dx in (-1, 0, 1)
                if dy or dx
            ]
        )
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


def mesh_capture(
    path,
    settings: CaptureSettings = CaptureSettings(),
    on_stage: Callable[[str], None] | None = None,
) -> Reconstruction:
    """Read a capture file and reconstruct its terrain; on_stage("read") once it is read, then
    as reconstruct calls it."""
    from ._inputs import load_capture

    cap = load_capture(
        path,
        intrinsics=settings.intrinsics,
        depth_scale=settings.depth_scale,
        topic=settings.topic,
        units=settings.units,
        depth_units=settings.depth_units,
    )
    if on_stage is not None:
        on_stage("read")
    return reconstruct(cap, settings.meshing, on_stage)
