"""Synthetic depth captures: what a Kinect v2 would see of a mesh, for tests and experiments
without a sensor.

Ray casting (Open3D's RaycastingScene) gives exact depth; the noise model adds what the real
sensor does (after Fankhauser et al., "Kinect v2 for mobile robot navigation: evaluation and
modeling", ICAR 2015): axial noise growing with distance and with the angle of incidence, no
return at grazing angles or out of range, dropped pixels at depth discontinuities (the driver's
flying-pixel filter) and randomly missing pixels.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ._camera import Intrinsics
from ._errors import CaptureError


@dataclass(frozen=True, kw_only=True)
class NoiseModel:
    axial: bool = True
    """sigma_z = 1.5 - 0.5 z + 0.3 z^2 + 0.1 z^1.5 theta^2 / (pi/2 - theta)^2 [mm], z [m],
    theta the angle of incidence (Fankhauser et al. 2015, eq. 4)."""
    range: tuple[float, float] = (0.5, 8.0)
    """Measured depths [m] (the Kinect v2's rated range is 0.5-4.5 m; it returns up to ~8)."""
    max_incidence_deg: float = 80.0
    """No return from surfaces seen more obliquely than this."""
    edge_jump: float = 0.03
    """A pixel whose depth differs from a neighbour's by more than this fraction is at a
    discontinuity ..."""
    edge_dropout: float = 0.7
    """... and is dropped with this probability."""
    dropout: float = 0.005
    """Probability that any pixel is missing."""


NO_NOISE = NoiseModel(axial=False, edge_dropout=0.0, dropout=0.0, max_incidence_deg=90.0)


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(4, 4) world_from_camera of a camera at eye looking at target [m]; camera frame x right,
    y down, z forward."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    if np.linalg.norm(z) < 1e-9:
        raise CaptureError("camera eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise CaptureError("the camera looks straight along 'up'; give another up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    out = np.eye(4)
    out[:3, :3] = np.column_stack([x, y, z])
    out[:3, 3] = eye
    return out


def survey_views(mesh_bounds) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Three views of a terrain whose mesh has these (2, 3) bounds [m], as (eye, target) [m]
    in its frame, looking at the centre of its base (centre c, larger half-extent r):
    "low-near" (1.2 r + 0.6 m back, 0.6 m up), "high-far" (2 r + 1.5 m back, 1.8 m up) and
    "oblique" (r + 0.8 m away at 45 deg to the side and back, 1.2 m up): the kinds of view a
    person takes of the ground in front of them."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in mesh_bounds)
    c = (lo + hi) / 2
    r = float(max(hi[0] - lo[0], hi[1] - lo[1])) / 2
    target = np.array([c[0], c[1], lo[2]])
    return {
        "low-near": (target + [0.0, -(1.2 * r + 0.6), 0.6], target),
        "high-far": (target + [0.0, -(2.0 * r + 1.5), 1.8], target),
        "oblique": (target + [(r + 0.8) * 0.7, -(r + 0.8) * 0.7, 1.2], target),
    }


def render_depth(
    mesh: trimesh.Trimesh,
    intr: Intrinsics,
    world_from_camera: np.ndarray,
    noise: NoiseModel = NoiseModel(),
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """(H, W) depth along the optical axis [m] of the mesh (world frame) seen by the camera;
    0 where nothing is measured. rng: the noise's randomness (required with noise)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor.from_numpy(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor.from_numpy(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    rot, eye = world_from_camera[:3, :3], world_from_camera[:3, 3]
    dirs = intr.rays() @ rot.T  # z = 1 in the camera: the hit distance is the depth
    rays = np.concatenate([np.broadcast_to(eye, dirs.shape), dirs], axis=-1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor.from_numpy(rays))
    depth = hit["t_hit"].numpy().astype(np.float64)
    normals = hit["primitive_normals"].numpy().astype(np.float64)
    depth[~np.isfinite(depth)] = 0.0
    unit = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    cos_inc = np.abs(np.einsum("hwk,hwk->hw", unit, normals))
    theta = np.arccos(np.clip(cos_inc, 0.0, 1.0))
    if noise is NO_NOISE:
        return depth
    if rng is None:
        raise CaptureError("a noisy render needs an rng (numpy Generator)")
    seen = depth > 0
    if noise.axial:
        th = np.minimum(theta, np.radians(89.0))
        sigma_mm = (
            1.5 - 0.5 * depth + 0.3 * depth**2 + 0.1 * depth**1.5 * th**2 / (np.pi / 2 - th) ** 2
        )
        depth = depth + rng.normal(size=depth.shape) * np.maximum(sigma_mm, 0.5) * 1e-3
    lo, hi = noise.range
    keep = seen & (depth >= lo) & (depth <= hi) & (np.degrees(theta) <= noise.max_incidence_deg)
    jump = np.zeros_like(keep)
    for axis in (0, 1):
        d = np.abs(np.diff(depth, axis=axis)) > noise.edge_jump * np.minimum(
            np.delete(depth, -1, axis=axis), np.delete(depth, 0, axis=axis)
        )
        pad = [(0, 0), (0, 0)]
        pad[axis] = (0, 1)
        jump |= np.pad(d, pad)
        pad[axis] = (1, 0)
        jump |= np.pad(d, pad)
    keep &= ~(jump & (rng.uniform(size=depth.shape) < noise.edge_dropout))
    keep &= rng.uniform(size=depth.shape) >= noise.dropout
    return np.where(keep, depth, 0.0)


def save_depth(
    path: Path,
    depth_m: np.ndarray,
    intr: Intrinsics,
    *,
    depth_scale: float = 1000.0,
    world_from_camera: np.ndarray | None = None,
) -> list[Path]:
    """Write the depth image as a capture file: by suffix, a 16-bit PNG (units of
    1/depth_scale m, 0 = none) with its intrinsics in a sidecar .json; an organized binary
    .pcd; .ply; .npy ((H, W, 3) points). The sidecar also records the camera's true pose.
    Files are written beside their targets and renamed (nothing half-written)."""
    from ._capture import depth_to_points

    path = Path(path)
    suffix = path.suffix.lower()
    written = []
    tmp = path.with_name(f".{path.name}.part")
    if suffix == ".png":
        from PIL import Image

        units = np.round(depth_m * depth_scale)
        if units.max() > 65535:
            raise CaptureError(
                f"{path}: depths beyond {65535 / depth_scale:.1f} m do not fit 16 bits"
            )
        Image.fromarray(units.astype(np.uint16)).save(tmp, format="PNG")
        side = path.with_suffix(".json")
        meta = {**intr.to_json(), "depth_scale": depth_scale}
        if world_from_camera is not None:
            meta["world_from_camera"] = np.asarray(world_from_camera).round(9).tolist()
        side_tmp = side.with_name(f".{side.name}.part")
        side_tmp.write_text(json.dumps(meta, indent=1) + "\n")
        os.replace(side_tmp, side)
        written.append(side)
    else:
        pts = depth_to_points(depth_m, intr).astype(np.float32)
        if suffix == ".pcd":
            from pypcd4.pypcd4 import Encoding, PointCloud

            pc = PointCloud.from_xyz_points(pts)
            pc.metadata.width, pc.metadata.height = intr.width, intr.height
            pc.save(tmp, encoding=Encoding.BINARY)
        elif suffix == ".npy":
            with open(tmp, "wb") as f:
                np.save(f, pts.reshape(intr.height, intr.width, 3))
        elif suffix == ".ply":
            ok = pts[np.isfinite(pts).all(axis=1)]
            trimesh.PointCloud(ok).export(tmp, file_type="ply")
        else:
            raise CaptureError(f"{path}: write .png, .pcd, .ply or .npy")
    os.replace(tmp, path)
    return [path, *written]
