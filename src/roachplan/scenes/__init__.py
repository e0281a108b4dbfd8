"""Worlds to plan and drive in: scene files, OpenSCAD terrains, meshes and the scene library."""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

# Public names, imported on first use (roachplan._lazy): the command line answers at once.
_getattr, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "scaled_scene": "._adjust",
        "with_scad_timeout": "._adjust",
        "with_scad_backend": "._adjust",
        "with_engine": "._adjust",
        "SceneError": "._errors",
        "looks_like_millimetres": "._mesh",
        "BACKENDS": "._openscad",
        "DEFAULT_BACKEND": "._openscad",
        "DEFAULT_TIMEOUT": "._openscad",
        "MAX_TIMEOUT": "._scad_sandbox",
        "render_scad": "._openscad",
        "render_scad_result": "._openscad",
        "ScadRender": "._openscad",
        "LIBRARY": "._library",
        "RobotFile": "._robot_file",
        "ROBOT_FILE_HEADER": "._robot_file",
        "load_robot_file": "._robot_file",
        "write_robot_file": "._robot_file",
        "MAX_SEED": "roachplan._settings",
        "MESH_SUFFIXES": "._scene",
        "TERRAIN_SUFFIXES": "._scene",
        "terrain_file_scene": "._scene",
        "Scene": "._scene",
        "TerrainObject": "._scene",
        "YamlFields": "._scene",
        "library_names": "._library",
        "list_scenes": "._library",
        "load_scene": "._scene",
        "read_yaml": "._scene",
        "resolve_in_library": "._scene",
        "resolve_scene": "._scene",
        "SIM_MAX_MESH_TRIANGLES": "._sim_terrain",
        "SIM_MAX_TRIANGLES": "._sim_terrain",
        "SIM_MAX_TOLERANCE": "._sim_terrain",
        "SimTerrain": "._sim_terrain",
        "crop_mesh": "._sim_terrain",
        "sim_terrain": "._sim_terrain",
        "simplified_heightfield_mesh": "._sim_terrain",
        "level_ground": "._sim_terrain",
        "OnCapture": "._world",
        "World": "._world",
        "Terrain": "._world",
        "build_terrain": "._world",
        "build_terrain_mesh": "._world",
        "build_world": "._world",
        "footprint_of": "._world",
        "pose_problem": "._world",
        "route_of": "._world",
        "seen_mesh": "._world",
    },
)
if not TYPE_CHECKING:  # (a type checker sees the names imported below instead, and so
    # reports an import from here of a name that is not one of them)
    __getattr__ = _getattr
del _getattr

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from roachplan._settings import MAX_SEED as MAX_SEED

    from ._adjust import scaled_scene as scaled_scene
    from ._adjust import with_engine as with_engine
    from ._adjust import with_scad_backend as with_scad_backend
    from ._adjust import with_scad_timeout as with_scad_timeout
    from ._errors import SceneError as SceneError
    from ._library import LIBRARY as LIBRARY
    from ._library import library_names as library_names
    from ._library import list_scenes as list_scenes
    from ._mesh import looks_like_millimetres as looks_like_millimetres
    from ._openscad import BACKENDS as BACKENDS
    from ._openscad import DEFAULT_BACKEND as DEFAULT_BACKEND
    from ._openscad import DEFAULT_TIMEOUT as DEFAULT_TIMEOUT
    from ._openscad import ScadRender as ScadRender
    from ._openscad import render_scad as render_scad
    from ._openscad import render_scad_result as render_scad_result
    from ._robot_file import ROBOT_FILE_HEADER as ROBOT_FILE_HEADER
    from ._robot_file import RobotFile as RobotFile
    from ._robot_file import load_robot_file as load_robot_file
    from ._robot_file import write_robot_file as write_robot_file
    from ._scad_sandbox import MAX_TIMEOUT as MAX_TIMEOUT
    from ._scene import MESH_SUFFIXES as MESH_SUFFIXES
    from ._scene import TERRAIN_SUFFIXES as TERRAIN_SUFFIXES
    from ._scene import Scene as Scene
    from ._scene import TerrainObject as TerrainObject
    from ._scene import YamlFields as YamlFields
    from ._scene import load_scene as load_scene
    from ._scene import read_yaml as read_yaml
    from ._scene import resolve_in_library as resolve_in_library
    from ._scene import resolve_scene as resolve_scene
    from ._scene import terrain_file_scene as terrain_file_scene
    from ._sim_terrain import SIM_MAX_MESH_TRIANGLES as SIM_MAX_MESH_TRIANGLES
    from ._sim_terrain import SIM_MAX_TOLERANCE as SIM_MAX_TOLERANCE
    from ._sim_terrain import SIM_MAX_TRIANGLES as SIM_MAX_TRIANGLES
    from ._sim_terrain import SimTerrain as SimTerrain
    from ._sim_terrain import crop_mesh as crop_mesh
    from ._sim_terrain import level_ground as level_ground
    from ._sim_terrain import sim_terrain as sim_terrain
    from ._sim_terrain import simplified_heightfield_mesh as simplified_heightfield_mesh
    from ._world import OnCapture as OnCapture
    from ._world import Terrain as Terrain
    from ._world import World as World
    from ._world import build_terrain as build_terrain
    from ._world import build_terrain_mesh as build_terrain_mesh
    from ._world import build_world as build_world
    from ._world import footprint_of as footprint_of
    from ._world import pose_problem as pose_problem
    from ._world import route_of as route_of
    from ._world import seen_mesh as seen_mesh
