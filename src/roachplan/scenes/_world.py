"""Assemble a scene into what the planner and the simulator consume."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from roachplan.perception import CaptureError, CaptureSettings, Reconstruction, mesh_capture
from roachplan.planning import (
    VALID,
    Footprint,
    HeightField,
    PlannerConfig,
    PlanningError,
    StandableMap,
    check_states,
    describe_state,
    heightfield_from_mesh,
    homology_signature,
    signature_label,
    standable_map,
)
from roachplan.sim import (
    LEG_NAMES,
    DriverConfig,
    RobotConfig,
    SimConfig,
    SimError,
    Simulation,
    make_simulation,
    quat_to_matrix,
)

from ._autopose import auto_bounds, pick_start_goal
from ._errors import SceneError
from ._mesh import clean_terrain_mesh, read_mesh, scaled_mesh
from ._openscad import render_scad_result
from ._scene import Scene, TerrainObject
from ._sim_terrain import (
    SIM_MAX_MESH_TRIANGLES,
    SimTerrain,
    level_ground,
    sim_terrain,
    standable_points,
)

HEIGHTFIELD_RESOLUTION = 0.01
"""Grid spacing of the planner's height field [m]: the bridge edges are sharp to within this."""
MAX_DEPTH_BELOW_GROUND = 1.0
"""How deep the terrain may reach under the ground plane [m] before build_world warns: a model
sunk a little into the floor is common; metres down is most often a wrong position z, units or
orientation."""
VERTEX_VALUES = ("height_noise",)
"""Per-vertex values a terrain mesh may carry (a capture's, perception/_surface.py): the
standard deviation of the vertex's height [m]; 0 on models and mesh files."""
FACE_VALUES = ("filled",)
"""Per-face values a terrain mesh may carry: 1.0 where a capture's triangle fills a hole
from its rim; 0 elsewhere."""
OVERHEAD = 0.3
"""A surface more than this above a lower one at the same place is overhead, not ground [m]:
a table top or a chair's seat over the floor a camera saw under it. The robot (3.5 cm tall)
walks under it; a step that high it could not climb anyway. Levels closer than this (a
bridge 20 cm over the floor) stay the top surface, as a solid's top does (no upward
surface under it)."""
FAR_FROM_AREA = 10.0
"""Farthest a terrain object may lie from the planning area [m] (or, when the scene leaves the
area to be picked, from the rest of the terrain). The robot goes nowhere near it: the planner
keeps its centre inside the area (its feet 0.15 m past it), and the area picked for a scene
is at most 10 m across; so an object further off can only be a wrong position, a sign or a
unit slipped (`position: [1e6, 0, 0]`), which would otherwise leave the robot on bare ground,
or the planning area picked somewhere between the pieces. Scenery just outside the area (a
capture's far wall, a second model beyond the goal) stays within it."""
MAX_PLANNING_AREA = 400.0
"""Largest area the robot's centre may be planned over [m^2] (20 m x 20 m): the height field
and the maps made from it take about 1 kB a cell, so 4 M cells at 1 cm is a few GB."""


@dataclass(frozen=True, eq=False)
class World:
    """A scene with its terrain built: the mesh for physics and display, the height field for
    planning, and the robot."""

    scene: Scene
    mesh: trimesh.Trimesh
    """Terrain triangles, world frame [m] (without the ground plane)."""
    heightfield: HeightField
    robot: RobotConfig
    notes: tuple[str, ...] = ()
    """What was chosen for the user (who rendered each OpenSCAD model and why; bounds, start
    and goal picked automatically)."""
    renders: tuple[str, ...] = ()
    """Of the notes, one per OpenSCAD object: who rendered it, why, and what that may change
    (ScadRender.note), for the page's status line."""
    checked: tuple | None = dataclasses.field(default=None, repr=False)
    """(height field, bounds, validity config, StandableMap.yaw_valid): the standable map's
    checks as the start and goal's pick made them, for regions to reuse while the world has
    that same height field, bounds and validity (a capture's take seconds); None: none made."""

    @property
    def start(self) -> tuple[float, float, float]:
        """The robot's start pose: x [m], y [m], yaw [rad] (the scene's, or picked by
        build_world)."""
        start = self.scene.start
        assert start is not None  # build_world sets it
        return start

    @property
    def goal(self) -> tuple[float, float, float]:
        """The goal pose: x [m], y [m], yaw [rad] (the scene's, or picked by build_world)."""
        goal = self.scene.goal
        assert goal is not None  # build_world sets it
        return goal

    @property
    def bounds(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The planning area ((x0, y0), (x1, y1)) [m] (the scene's, or picked by
        build_world)."""
        bounds = self.scene.bounds
        assert bounds is not None  # build_world sets it
        return bounds

    @functools.cached_property
    def footprint(self) -> Footprint:
        return footprint_of(self.robot)

    @functools.cached_property
    def regions(self) -> StandableMap:
        """Where the robot can stand within the scene's bounds, and the holes between those
        places (computed once, ~50 ms): the terrain sampler's support and the route labels."""
        validity = self.scene.planner.validity
        reuse = None
        if self.checked is not None:
            hf, bounds, cfg, yaw_valid = self.checked
            if hf is self.heightfield and bounds == self.bounds and cfg == validity:
                reuse = yaw_valid
        # A hole smaller than the robot's own footprint is noise to go through or over, not
        # an obstacle to go round.
        return standable_map(
            self.heightfield,
            self.footprint,
            validity,
            self.bounds,
            self.start[:2],
            min_hole_area=self.robot.body_length * self.robot.body_width * 4,
            yaw_valid=reuse,
        )

    def route(self, path_xy: np.ndarray) -> str:
        """The route a path ((K, 2) [m]) takes: the first of the scene's named route regions it
        passes through; without named routes (or through none of them), its homology class
        round the terrain's holes (e.g. "h1:+1"; "direct" on terrain without holes)."""
        named = route_of(self.scene, path_xy)
        if named != "other":
            return named
        return signature_label(homology_signature(self.regions.holes, path_xy))

    @functools.cached_property
    def sim_terrain(self) -> SimTerrain:
        """The terrain the physics engine is given: the mesh itself, or, for a large capture,
        its part near the planning area or the planner's height field as triangles
        (scenes/_sim_terrain.py; computed once)."""
        return sim_terrain_of(self)

    def _replaced(self, kept: tuple[str, ...], **changes) -> World:
        """dataclasses.replace(self, **changes), with the cached properties named in `kept`
        (those it has computed that the changes leave as they are) carried over."""
        world = dataclasses.replace(self, **changes)
        world.__dict__.update({k: v for k, v in self.__dict__.items() if k in kept})
        return world

    def with_notes(self, notes: tuple[str, ...]) -> World:
        """This world with other notes; what it has computed (regions, sim_terrain) kept."""
        return self._replaced(("regions", "sim_terrain"), notes=notes)

    def with_sim(self, sim: SimConfig, driver: DriverConfig) -> World:
        """This world simulated with other physics and driver settings (another engine, its
        turning curve): what it has computed (regions, sim_terrain: neither depends on them)
        kept."""
        scene = dataclasses.replace(self.scene, sim=sim, driver=driver)
        return self._replaced(("regions", "sim_terrain"), scene=scene)

    def with_planner(self, planner: PlannerConfig) -> World:
        """This world planned with other planner settings (a re-plan's wider arcs): what it has
        computed kept (sim_terrain; regions too when the validity settings they are made by
        are the same)."""
        same = planner.validity == self.scene.planner.validity
        scene = dataclasses.replace(self.scene, planner=planner)
        return self._replaced(("regions", "sim_terrain") if same else ("sim_terrain",), scene=scene)

    def with_scene(self, scene: Scene) -> World:
        """This terrain, height field and robot with scene: the same scene with what was picked
        for it written down (start, goal, bounds as the page writes them). The simulator's
        terrain is kept (made from the same mesh and height field: a second or two)."""
        return self._replaced(("sim_terrain",), scene=scene)

    def simulation(
        self,
        *,
        vertices: np.ndarray | None = None,
        robot: RobotConfig | None = None,
        cfg: SimConfig | None = None,
    ) -> Simulation:
        """A fresh world of this terrain (sim_terrain), ground and robot in the engine cfg names
        (sim.engine; the caller closes it). vertices: the terrain's vertices moved ((V, 3) [m],
        as sim_terrain's: a rollout's drawn sensor error); robot, cfg: other than the scene's
        (a fitted robot, another engine)."""
        terrain = self.sim_terrain
        try:
            return make_simulation(
                terrain.vertices if vertices is None else vertices,
                terrain.faces,
                ground_height=self.scene.ground,
                robot=self.robot if robot is None else robot,
                cfg=self.scene.sim if cfg is None else cfg,
            )
        except SimError as exc:
            raise SceneError(f"{self.scene.path}: {exc}") from None


def sim_terrain_of(world: World) -> SimTerrain:
    """The terrain the physics engine is given for world (World.sim_terrain)."""
    hf, m = world.heightfield, world.mesh
    slope = world.scene.planner.validity.max_slope_deg
    ground = None
    if len(m.faces) > SIM_MAX_MESH_TRIANGLES:  # (it may become the height field's triangles)
        # Where the feet go: level ground, and every place the robot can stand (the regions,
        # which every trial's route label needs anyway).
        ground = level_ground(hf, slope) | standable_points(hf, world.regions)
    return sim_terrain(m.vertices, m.faces, hf, world.bounds, ground=ground)


def footprint_of(robot: RobotConfig) -> Footprint:
    """The planner's view of the robot: its feet when standing and the underside of its body."""
    return Footprint(
        feet_xy=robot.foot_points_xy,
        foot_names=LEG_NAMES,
        body_length=robot.body_length,
        body_width=robot.body_width,
        body_clearance=robot.standing_height - robot.body_height / 2,
        leg_reach=robot.leg_length + robot.leg_radius,
    )


OnCapture = Callable[[Path, CaptureSettings, Reconstruction], None]
"""Told of each capture object's reconstruction while a terrain is built: on_capture(its
source, its settings, what perception made of it: the mesh, the camera pose, the report), for
the app, which shows the camera and ground found without meshing the capture again."""


def load_terrain_object(
    obj: TerrainObject, scene_path, on_capture: OnCapture | None = None
) -> tuple[trimesh.Trimesh, str]:
    """One terrain object's mesh, cleaned and placed in the world frame [m], and for a .scad
    object the note of who rendered it (ScadRender.note, at the object's scale), else ""."""
    label = f"{scene_path}: {obj.key}.{obj.kind}"
    source, note = obj.source, ""
    if obj.kind == "scad":
        try:
            rendered = render_scad_result(
                source, dict(obj.params), timeout=obj.timeout, backend=obj.backend
            )
        except SceneError as exc:
            raise SceneError(f"{label}: {exc}") from None
        source, note = rendered.path, rendered.note(scale=max(obj.scale))
    if obj.kind == "capture":
        assert obj.capture is not None  # a capture object has its settings
        try:
            rec = mesh_capture(source, obj.capture)
        except CaptureError as exc:
            raise SceneError(f"{label}: {exc}") from None
        if on_capture is not None:
            on_capture(Path(source), obj.capture, rec)
        raw = rec.mesh
    else:
        raw = read_mesh(source, label)
    if obj.scale != (1.0, 1.0, 1.0):  # before the unit check: a model in mm passes once scaled
        raw = scaled_mesh(raw, obj.scale)
    # A capture's units were judged by perception from the sensor's range, and its facets
    # face the sensor (section 3.2): neither is redone here.
    capture = obj.kind == "capture"
    mesh = clean_terrain_mesh(raw, label, check_units=not capture, rewind=not capture)
    transform = np.eye(4)
    transform[:3, :3] = quat_to_matrix(np.asarray(obj.orientation))
    transform[:3, 3] = obj.position
    mesh.apply_transform(transform)
    return mesh, note


@dataclass(frozen=True, eq=False)
class Terrain:
    """A scene's terrain objects built into one mesh, with what the user is told about it."""

    mesh: trimesh.Trimesh
    """Every terrain object, world frame [m] (maybe empty)."""
    notes: tuple[str, ...] = ()
    """One line per OpenSCAD object: who rendered it, why, and what that may change."""


def build_terrain(scene: Scene, *, on_capture: OnCapture | None = None) -> Terrain:
    """All terrain objects of a scene merged into one mesh, world frame [m], with the notes of
    their OpenSCAD renders; on_capture: told of each capture's reconstruction (OnCapture)."""
    if not scene.terrain:
        return Terrain(trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)))
    built = [load_terrain_object(o, scene.path, on_capture) for o in scene.terrain]
    for obj, (placed, _) in zip(scene.terrain, built):
        problem = below_ground_problem(placed, scene.ground)
        if problem:
            raise SceneError(f"{scene.path}: {obj.key}: {problem}")
    pieces = [
        (obj.key, obj.source.name, placed.bounds[:, :2])
        for obj, (placed, _) in zip(scene.terrain, built)
        if len(placed.faces)
    ]
    if far := far_piece(pieces, scene.bounds):
        raise SceneError(f"{scene.path}: {far}")
    for m, _ in built:  # every piece carries the same values, or concatenate drops them
        for key in VERTEX_VALUES:
            if key not in m.vertex_attributes:
                m.vertex_attributes[key] = np.zeros(len(m.vertices))
        for key in FACE_VALUES:
            if key not in m.face_attributes:
                m.face_attributes[key] = np.zeros(len(m.faces))
    mesh = trimesh.util.concatenate([m for m, _ in built])
    assert isinstance(mesh, trimesh.Trimesh)  # (of Trimesh pieces, one Trimesh)
    mesh.merge_vertices()
    return Terrain(mesh, tuple(note for _, note in built if note))


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between two boxes ((xmin, ymin), (xmax, ymax)) [m]; 0 when they overlap."""
    d = np.maximum(np.maximum(a[0] - b[1], b[0] - a[1]), 0.0)
    return float(np.hypot(*d))


def _box_text(box) -> str:
    (x0, y0), (x1, y1) = box
    return f"x {x0:.2f} to {x1:.2f}, y {y0:.2f} to {y1:.2f}"


def far_piece(pieces: list[tuple[str, str, np.ndarray]], bounds) -> str:
    """ "key: why" for the first terrain piece (key, file name, placed (2, 2) xy box [m]) more
    than FAR_FROM_AREA from the planning area `bounds`, or, without bounds, from the terrain's
    largest group of pieces (each within FAR_FROM_AREA of another); else ""."""
    why = (
        f"more than {FAR_FROM_AREA:g} m off, where the robot never goes, so most likely a wrong "
        f"position (a sign or a unit slipped); place it within {FAR_FROM_AREA:g} m of"
    )
    if bounds is not None:
        area = np.asarray(bounds, dtype=float)
        for key, name, box in pieces:
            if (gap := _gap(box, area)) > FAR_FROM_AREA:
                return (
                    f"{key}: {name} lies {gap:.1f} m from the planning area ({_box_text(area)}), "
                    f"at {_box_text(box)}: {why} the planning area, or widen the area"
                )
        return ""
    groups = list(range(len(pieces)))  # single linkage: each piece's group, by union-find

    def root(i: int) -> int:
        while groups[i] != i:
            i = groups[i]
        return i

    for i, (_, _, a) in enumerate(pieces):
        for j in range(i):
            if _gap(a, pieces[j][2]) <= FAR_FROM_AREA:
                groups[root(i)] = root(j)
    sizes: dict[int, float] = {}
    for i, (_, _, box) in enumerate(pieces):
        sizes[root(i)] = sizes.get(root(i), 0.0) + float(np.prod(box[1] - box[0]))
    main = max(sizes, key=lambda g: (sizes[g], -g))
    members = [box for i, (_, _, box) in enumerate(pieces) if root(i) == main]
    rest = np.array(
        [np.min([b[0] for b in members], axis=0), np.max([b[1] for b in members], axis=0)]
    )
    for i, (key, name, box) in enumerate(pieces):
        if root(i) != main:
            return (
                f"{key}: {name} lies {_gap(box, rest):.1f} m from the rest of the terrain "
                f"({_box_text(rest)}, where the planning area is picked), at {_box_text(box)}: "
                f"{why} the other pieces"
            )
    return ""


def build_terrain_mesh(scene: Scene) -> trimesh.Trimesh:
    """All terrain objects of a scene merged into one mesh, world frame [m] (maybe empty)."""
    return build_terrain(scene).mesh


def seen_mesh(scene: Scene) -> trimesh.Trimesh:
    """What a camera sees of a scene, world frame [m]: its terrain objects and, where it has a
    ground plane, the ground as a 100 m square slab (synthetic captures)."""
    mesh = build_terrain_mesh(scene)
    if scene.ground is None:
        return mesh
    slab = trimesh.creation.box((100.0, 100.0, 0.01))
    slab.apply_translation((0, 0, scene.ground - 0.005))
    seen = trimesh.util.concatenate([m for m in (mesh, slab) if len(m.faces)])
    assert isinstance(seen, trimesh.Trimesh)  # (meshes concatenate to a mesh)
    return seen


_RAISE_IT = "raise it with `position: [x, y, z]`, or give `ground: null` if it has its own floor"


def below_ground_problem(mesh: trimesh.Trimesh, ground: float | None) -> str:
    """Why a placed terrain object (world frame [m]) cannot be part of a world with a ground
    plane at z = ground [m] (None: no plane): it lies entirely under the plane, more than 1 mm
    (a model flush with the plane is a patch of floor); else ""."""
    if ground is None or len(mesh.faces) == 0:
        return ""
    top = float(mesh.bounds[1][2])
    if top >= ground - 1e-3:  # up to flush with the plane (a floor patch) is fine
        return ""
    return (
        f"lies entirely under the ground plane: its top is at z = {top:.3g} m, "
        f"{ground - top:.3g} m under the ground at z = {ground:g} m, so nothing of it can be "
        f"stood on; {_RAISE_IT} in a scene file"
    )


def below_ground_note(mesh: trimesh.Trimesh, ground: float | None) -> str:
    """A warning when the terrain (world frame [m]) reaches more than MAX_DEPTH_BELOW_GROUND
    under the ground plane at z = ground [m], or "". Not refused: a height map or a model in
    other units may do so on purpose (its part under the plane is hidden, and walked over)."""
    if ground is None or len(mesh.faces) == 0:
        return ""
    low = float(mesh.bounds[0][2])
    if ground - low <= MAX_DEPTH_BELOW_GROUND:
        return ""
    return (
        f"warning: the terrain reaches {ground - low:.3g} m under the ground plane at "
        f"z = {ground:g} m (its lowest point is at z = {low:.3g} m): the plane hides that part; "
        f"if it is placed wrong, {_RAISE_IT} (or scale a model in other units)"
    )


def build_world(
    scene: Scene,
    robot: RobotConfig | None = None,
    *,
    check_poses: bool = True,
    terrain: Terrain | None = None,
    on_capture: OnCapture | None = None,
) -> World:
    """Render/load the terrain and rasterise the planner's height field around the bounds;
    SceneError when the start or goal is not a place the robot can stand (unless check_poses
    is False: the app shows such a scene and says what is wrong with its markers).
    terrain: the scene's terrain if already built (build_terrain), not to build it twice; its
    notes (who rendered each OpenSCAD model) come first in the world's. on_capture: told of
    each capture's reconstruction as the terrain is built (OnCapture)."""
    robot = robot or scene.robot
    terrain = build_terrain(scene, on_capture=on_capture) if terrain is None else terrain
    mesh = terrain.mesh
    notes = list(terrain.notes)
    notes += [note] if (note := below_ground_note(mesh, scene.ground)) else []
    if scene.bounds is None:
        if len(mesh.faces) == 0:
            raise SceneError(
                f"{scene.path}: give bounds: the scene has no terrain to take them from"
            )
        bounds, note = auto_bounds(mesh.bounds, ground=scene.ground is not None)
        if bounds[0][0] >= bounds[1][0] or bounds[0][1] >= bounds[1][1]:
            raise SceneError(
                f"{scene.path}: the terrain ({mesh.extents[0]:.2f} m x {mesh.extents[1]:.2f} m) "
                f"is too small for the robot"
            )
        scene = dataclasses.replace(scene, bounds=bounds)
        notes += [note] if note else []
    margin = 0.15  # the robot's feet reach this far past its centre's bounds [m]
    assert scene.bounds is not None  # given, or picked above
    (lo, hi) = scene.bounds
    area = (hi[0] - lo[0]) * (hi[1] - lo[1])
    if area > MAX_PLANNING_AREA:
        raise SceneError(
            f"{scene.path}: bounds: {hi[0] - lo[0]:.1f} m x {hi[1] - lo[1]:.1f} m is more than "
            f"{MAX_PLANNING_AREA:.0f} m^2 to plan over at {HEIGHTFIELD_RESOLUTION * 100:.0f} cm; "
            f"give bounds at most {MAX_PLANNING_AREA**0.5:.0f} m x {MAX_PLANNING_AREA**0.5:.0f} m "
            f"around the part the robot is to cross"
        )
    hf = heightfield_from_mesh(
        mesh.vertices,
        mesh.faces,
        xy_min=(lo[0] - margin, lo[1] - margin),
        xy_max=(hi[0] + margin, hi[1] + margin),
        resolution=HEIGHTFIELD_RESOLUTION,
        ground_height=scene.ground,
        vertex_noise=mesh.vertex_attributes.get("height_noise"),
        overhead=OVERHEAD,
    )
    world = World(scene=scene, mesh=mesh, heightfield=hf, robot=robot, renders=terrain.notes)
    if scene.start is None:
        picked_checks = None
        try:
            picked = pick_start_goal(world, seed=scene.seed)
            picked_checks = picked.yaw_valid
            notes.append(picked.note)
            start, goal = picked.start, picked.goal
        except PlanningError as exc:
            if check_poses:
                raise SceneError(f"{scene.path}: {exc}") from None
            # The app shows such a world and says why its markers are invalid.
            notes.append(str(exc))
            (xa, ya), (xb, yb) = lo, hi
            start = goal = ((xa + xb) / 2, (ya + yb) / 2, 0.0)
        scene = dataclasses.replace(scene, start=start, goal=goal)
        world = dataclasses.replace(world, scene=scene)
        if picked_checks is not None:
            checked = (hf, scene.bounds, scene.planner.validity, picked_checks)
            world = dataclasses.replace(world, checked=checked)
    if len(mesh.faces) > SIM_MAX_MESH_TRIANGLES:
        # Made now, once: every drive's child gets it with the world, and the user is told.
        notes.append(world.sim_terrain.note())
        world = world.with_notes(tuple(notes))
    elif notes:
        world = dataclasses.replace(world, notes=tuple(notes))
    for key, pose in (("robot.start", scene.start), ("goal", scene.goal)) if check_poses else ():
        assert pose is not None  # given, or picked above
        problem = pose_problem(world, pose)
        if problem:
            raise SceneError(f"{scene.path}: {key}: {problem}")
    return world


def pose_problem(world: World, pose: tuple[float, float, float]) -> str:
    """Why the robot cannot stand at pose (x [m], y [m], yaw [rad]), or "" if it can."""
    xy = np.asarray(pose[:2], dtype=np.float64)
    if not np.isfinite(world.heightfield.sample(xy)):
        hf = world.heightfield
        (x0, y0), (x1, y1) = hf.covered_bounds()
        if not np.isfinite(x0):
            return f"({xy[0]:g}, {xy[1]:g}) is off the terrain: there is no terrain in the bounds"
        if not (x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1):
            return (
                f"({xy[0]:g}, {xy[1]:g}) is off the terrain: nothing to stand on there; the "
                f"terrain covers x in [{x0:.2f}, {x1:.2f}], y in [{y0:.2f}, {y1:.2f}]"
            )
        # Inside the terrain's extent: a hole or a gap between pieces; say where ground is.
        j, i = np.nonzero(np.isfinite(hf.heights))
        cells = np.column_stack([hf.x0 + i * hf.resolution, hf.y0 + j * hf.resolution])
        near = cells[np.argmin(np.sum((cells - xy) ** 2, axis=1))]
        return (
            f"({xy[0]:g}, {xy[1]:g}) is over a hole or gap in the terrain: nothing to stand on "
            f"there; the nearest surface is {np.linalg.norm(near - xy):.2f} m away, at "
            f"({near[0]:.2f}, {near[1]:.2f})"
        )
    hf, fp, cfg = world.heightfield, world.footprint, world.scene.planner.validity
    state = np.asarray(pose, dtype=np.float64)
    if check_states(hf, fp, cfg, state[None]).code[0] == VALID:
        return ""
    return (
        f"the robot cannot stand at ({xy[0]:g}, {xy[1]:g}, {np.degrees(pose[2]):g} deg): "
        f"{describe_state(hf, fp, cfg, state)}"
    )


def route_of(scene: Scene, path_xy: np.ndarray) -> str:
    """The first of the scene's named route regions the path passes through, or "other"."""
    path_xy = np.asarray(path_xy)
    for name, (lo, hi) in scene.routes:
        inside = np.all((path_xy >= lo) & (path_xy <= hi), axis=1)
        if inside.any():
            return name
    return "other"
