"""Assemble a scene into what the planner and the simulator consume."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from planning import Footprint, HeightField, heightfield_from_mesh
from sim import LEG_NAMES, RobotConfig, quat_to_matrix

from ._errors import SceneError
from ._openscad import render_scad
from ._scene import Scene, TerrainObject

HEIGHTFIELD_RESOLUTION = 0.01
"""Grid spacing of the planner's height field [m]: the bridge edges are sharp to within this."""
MAX_TERRAIN_EXTENT = 50.0
"""A terrain wider than this [m] is almost certainly in millimetres, not metres."""


@dataclass(frozen=True, eq=False)
class World:
    """A scene with its terrain built: the mesh for physics and display, the height field for
    planning, and the robot."""

    scene: Scene
    mesh: trimesh.Trimesh
    """Terrain triangles, world frame [m] (without the ground plane)."""
    heightfield: HeightField
    robot: RobotConfig

    @property
    def footprint(self) -> Footprint:
        return footprint_of(self.robot)


def footprint_of(robot: RobotConfig) -> Footprint:
    """The planner's view of the robot: its feet when standing and the underside of its body."""
    return Footprint(
        feet_xy=robot.foot_points_xy,
        foot_names=LEG_NAMES,
        body_length=robot.body_length,
        body_width=robot.body_width,
        body_clearance=robot.standing_height - robot.body_height / 2,
    )


def load_terrain_object(obj: TerrainObject) -> trimesh.Trimesh:
    """One terrain object's mesh, placed in the world frame."""
    source = obj.source
    if source.suffix.lower() == ".scad":
        source = render_scad(source, dict(obj.params))
    try:
        mesh = trimesh.load(source, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise SceneError(f"{obj.source}: cannot read as a mesh: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SceneError(f"{obj.source}: the mesh has no triangles")
    if not np.all(np.isfinite(mesh.vertices)):
        raise SceneError(f"{obj.source}: the mesh has non-finite vertex coordinates")
    transform = np.eye(4)
    transform[:3, :3] = quat_to_matrix(np.asarray(obj.orientation))
    transform[:3, 3] = obj.position
    mesh.apply_transform(transform)
    return mesh


def build_terrain_mesh(scene: Scene) -> trimesh.Trimesh:
    """All terrain objects of a scene merged into one cleaned mesh, world frame [m]."""
    mesh = trimesh.util.concatenate([load_terrain_object(o) for o in scene.terrain])
    mesh.merge_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    extent = float(np.max(mesh.extents))
    if extent > MAX_TERRAIN_EXTENT:
        raise SceneError(
            f"{scene.path}: the terrain is {extent:.0f} m across; scenes are in metres, so this "
            f"is most likely a model in millimetres (scale it by 0.001)"
        )
    return mesh


def build_world(scene: Scene, robot: RobotConfig | None = None) -> World:
    """Render/load the terrain and rasterise the planner's height field around the bounds."""
    robot = robot or RobotConfig()
    mesh = build_terrain_mesh(scene)
    margin = 0.15  # the robot's feet reach this far past its centre's bounds [m]
    (lo, hi) = scene.bounds
    hf = heightfield_from_mesh(
        mesh.vertices,
        mesh.faces,
        xy_min=(lo[0] - margin, lo[1] - margin),
        xy_max=(hi[0] + margin, hi[1] + margin),
        resolution=HEIGHTFIELD_RESOLUTION,
        ground_height=scene.ground,
    )
    return World(scene=scene, mesh=mesh, heightfield=hf, robot=robot)


def route_of(scene: Scene, path_xy: np.ndarray) -> str:
    """The first of the scene's named route regions the path passes through, or "other"."""
    path_xy = np.asarray(path_xy)
    for name, (lo, hi) in scene.routes:
        inside = np.all((path_xy >= lo) & (path_xy <= hi), axis=1)
        if inside.any():
            return name
    return "other"
