"""The MuJoCo engine behind the physics seam (sim/_engine.py): the same terrain, ground and roach
as the PyBullet engine (sim/_pybullet.py), its MJCF model generated from RobotConfig.

The model (`build_world_model`):
  - world: the terrain as convex prisms (mesh geoms `terrain_0`...) where it is built of a few
    flat convex tops, else as a height field (`hfield` geom, below), and, when the world has
    one, the ground as an infinite plane at z = ground_height. All static, in geom group 0.
  - `body`: a free body, the box of RobotConfig's body (its frame RobotConfig's: x forward,
    y left, z up, origin at the box centre); its mass spread over the box (a body of mass 0
    is fixed in the world, as PyBullet fixes a base of mass 0). Against a height field the box
    collides as four massless pieces along its length (_add_robot says why), with the plane
    as itself.
  - `leg_L1` ... `leg_R3`: one body per leg at `robot.hip_positions`, a hinge `hip_*` about
    the body's +y there (q = 0: the leg points straight down; continuous, no limits), a capsule
    from the hip to leg_length below it, radius leg_radius: its rounded tip is the foot. The
    leg's mass over the capsule; the rest of `drive_inertia` (a leg with its share of motor
    and gearbox, about the hip) is the hinge's `armature`: a geared motor's reflected inertia
    acts on the joint's axis alone. Robot geoms are in group 1 and collide with the world's,
    not with each other (PyBullet's multibody has no self-collision either).
  - `servo_*`: a general actuator per hip, force = ctrl - kp q - kd dq clamped to
    +-max_motor_torque (forcerange); advance() sets ctrl = kp q_target + kd dq_target, so the
    force is RobotConfig's PD servo kp (q_target - q) + kd (dq_target - dq). Sensors read
    each servo's force and each hip's speed for the energy meter.

The terrain: MuJoCo collides a mesh as its convex hull, so a terrain (a bridge over a floor,
a hole) cannot be one mesh geom. Where its top surface is a few flat convex faces, none over
another (a scene built of boxes and ramps), each face and the solid under it is one convex
prism (sim/_pieces.py; terrain_shape decides). Any other terrain's top surface is rasterised
(planning's heightfield_from_mesh, the planner's rasteriser, with the planner's rule for
surfaces overhead) into an hfield of FIELD_RESOLUTION. Frames: grid point (i, j) of the HeightField is at world (x0 + i r,
y0 + j r); the hfield geom sits at the grid's centre, z at the field's lowest level, and its
elevation row j, column i (row-major, rows along +y) is that point's height over it; MuJoCo
joins the points into two triangles a cell and fills the solid under them down to FIELD_BASE
below the lowest level.
"""

# pyright: reportAttributeAccessIssue=false
# (mujoco's names come from its compiled modules, which pyright cannot read: every mujoco.* is
# unknown to it; the tests run each of them.)

from __future__ import annotations

import functools
import hashlib
import logging
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
from mujoco import rollout

from ._config import SimConfig
from ._motors import SideMotors, targets_together
from ._pieces import convex_prisms
from ._placement import (
    DROP_CLEARANCE,
    ground_height,
    start_height,
    support_plane_pose,
    terrain_arrays,
)
from ._robot import LEG_NAMES, RobotConfig

if TYPE_CHECKING:
    from roachplan.planning import GridCover, HeightField

FIELD_RESOLUTION = 0.005
"""Grid spacing of the terrain's height field [m]. MuJoCo joins the grid points into flat
triangles, so an edge (a bridge's side, a step) is a slope one cell wide, and a foot (radius
3 mm) feels it within a cell of where the mesh has it: at 5 mm, less than a foot's width. A
coarser grid rounds a bridge's edge into a ramp the feet climb down (at 1 cm, the planner's
grid, an edge is a 1 cm slope); a finer one costs collision time for nothing on a flat floor
(a 10 s walk on a flat field: 2.5 mm took twice the time of 5 mm and walked the same
distance within 0.1 %)."""
MAX_FIELD_POINTS = 4_000_000
"""Most grid points of the height field (16 MB in MuJoCo): over it (a capture's terrain more
than 10 m x 10 m at 5 mm), the spacing grows until it fits."""
OVERHEAD = 0.3
"""A surface more than this above the lowest one at the same place is overhead, not ground
[m]: the planner's rule (scenes/_world.py OVERHEAD, the same value: tests/test_mujoco_engine.py
checks that they agree). A height field has one surface per point, so the engine keeps the
one the planner stands the robot on: a floor seen under a table top, not the top (3.5 cm
tall, the robot walks under it)."""
GROUND_CLEARANCE = 0.005
"""Field points whose top surface is the ground plane are sunk this far under it [m], so that
a foot on the floor touches the plane alone: a plane and a field at the same height would
both push on it and make the floor twice as stiff inside the field as outside."""
HOLE_DEPTH = 0.3
"""Field points with no surface (a hole, no ground plane) lie this far under the lowest
surface [m]: deep enough for the driver to call a robot in one fallen (DriverConfig.fall_drop),
shallow enough to keep the field's height resolution. A ray finds no surface there."""
FIELD_BASE = 0.05
"""Thickness of the solid under the field's lowest level [m]."""
CONTACT_TIMECONST = 0.005
"""Time constant of every contact [s] (MuJoCo's solref; damping ratio 1). MuJoCo's default,
0.02 s, is soft for a 30 g robot: on it the robot stood 0.4 mm into the floor, rode 0.5 mm
lower while walking at 20 rad/s and walked 5 % less far than on 5 ms (the stiffer contact is
also the nearer to PyBullet's, which are close to rigid). MuJoCo needs at least two timesteps
(4 ms at the 2 ms step); 5 ms is the same contact at 1 and 2 ms."""
INTEGRATOR = mujoco.mjtIntegrator.mjINT_EULER
"""MuJoCo's semi-implicit Euler. The servo is stable with it at 2 ms (kd dt / I = 0.6 and
kp dt^2 / I = 0.08 with I = drive_inertia, the bounds RobotConfig.motor_kd gives for Bullet),
and it is the faithful one: a 10 s walk at 20 rad/s at 2 ms was within 5 % in distance and 2 %
in energy of the same walk at 0.25 ms, where implicitfast (which takes the servo's damping
implicitly, and so lags the Buehler clock's jumps in speed) spent 20 % more energy."""

_FIELD_FILE = "terrain.bin"
"""The name the height field's zeros are given to MuJoCo under (_add_terrain)."""

BODY_SLOPE_DEG = 30.0
"""Steepest slope [deg] under which the body's box, cut into pieces along its length for the
height field (build_world_model), clears the field's cells: over it a piece's lowest corner is above
every cell under it, and MuJoCo skips those cells without a collision test. (The planner
stands the robot on slopes up to 25 deg.)"""

_log = logging.getLogger(__name__)


def _warned(message: str) -> None:
    _log.warning("MuJoCo: %s", message)


if mujoco.get_mju_user_warning() is None:
    # MuJoCo prints its warnings on standard output (which `--json` keeps for JSON alone) and
    # appends them to a MUJOCO_LOG.TXT in the working directory: ours go to the logger. What a
    # warning means for a drive (a state that diverged) is read from the data's counters.
    mujoco.set_mju_user_warning(_warned)

_TERRAIN_GROUP, _ROBOT_GROUP = 0, 1
_PLANE_BIT, _FIELD_BIT = 1, 2  # contype/conaffinity: what collides with the plane, the field
_RAY_GROUPS = np.array([1, 0, 0, 0, 0, 0], dtype=np.uint8)  # rays see the terrain alone
_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
_DIVERGED = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)


@functools.cache
def leg_inertia_about_hip(robot: RobotConfig) -> float:
    """Moment of inertia of a leg's capsule alone (mass leg_mass) about its hinge axis [kg m^2],
    as MuJoCo computes it from the geom."""
    spec = mujoco.MjSpec()
    leg = spec.worldbody.add_body(name="leg")
    leg.add_joint(type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0])
    _leg_geom(leg, robot)
    m = spec.compile()
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, m.body_iquat[1])
    rot = rot.reshape(3, 3)
    inertia = rot @ np.diag(m.body_inertia[1]) @ rot.T  # about the centre of mass, leg frame
    cx, _, cz = m.body_ipos[1]
    return float(inertia[1, 1] + m.body_mass[1] * (cx * cx + cz * cz))


def _leg_geom(leg, robot: RobotConfig):
    return leg.add_geom(
        name=f"{leg.name}_capsule",
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=[0.0, 0.0, 0.0, 0.0, 0.0, -robot.leg_length],
        size=[robot.leg_radius, 0.0, 0.0],
        mass=robot.leg_mass,
    )


def terrain_field(
    vertices: np.ndarray,
    faces: np.ndarray,
    ground_height: float | None,
    *,
    resolution: float = FIELD_RESOLUTION,
    max_points: int = MAX_FIELD_POINTS,
) -> HeightField | None:
    """The terrain's top surface (vertices (V, 3) [m] world frame, faces (F, 3)) as a
    planning HeightField over its xy extent, at `resolution` [m] or coarser to keep within
    max_points: each point the highest surface within OVERHEAD of the lowest there, at least
    the ground's (ground_height [m], None: no plane), NaN where there is none. None when no
    upward face covers a grid point (no faces, or only walls)."""
    from roachplan.planning import heightfield_from_cover

    if len(faces) == 0:
        return None
    cover = _cached_cover(vertices, faces, resolution, max_points)
    field = heightfield_from_cover(
        cover, vertices[:, 2], ground_height=ground_height, overhead=OVERHEAD
    )
    if min(field.heights.shape) < 2 or not np.any(np.isfinite(field.heights)):
        return None
    return field


_COVERS: dict[tuple, GridCover] = {}
_COVERS_KEPT = 2


def _cached_cover(
    vertices: np.ndarray, faces: np.ndarray, resolution: float, max_points: int
) -> GridCover:
    """The grid cover (planning's grid_cover) of the terrain's top surface at `resolution`
    [m] or coarser to keep within max_points, kept for the last _COVERS_KEPT terrains by
    their horizontal layout: a capture's rollouts each move its vertices up or down by the
    drawn sensor error, and finding the grid points each triangle covers took most of
    building their worlds (0.37 of 0.44 s on kinect_bridge); the heights from the cover come
    to the same bits."""
    from roachplan.planning import grid_cover

    xy = np.ascontiguousarray(vertices[:, :2])
    key = (_content(xy, faces), vertices.shape, faces.shape, resolution, max_points)

    def cover() -> GridCover:
        corners = xy[faces].reshape(-1, 2)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        width, depth = hi - lo
        r = resolution
        while (width / r + 1) * (depth / r + 1) > max_points:
            r *= 1.25
        return grid_cover(
            vertices,
            faces,
            xy_min=(float(lo[0]), float(lo[1])),
            xy_max=(float(hi[0]), float(hi[1])),
            resolution=r,
        )

    return _kept(_COVERS, _COVERS_KEPT, key, cover)


def _content(*arrays: np.ndarray) -> str:
    """A digest of the arrays' bytes: a cache key of their content."""
    digest = hashlib.blake2b(digest_size=16)
    for a in arrays:
        digest.update(np.ascontiguousarray(a).tobytes())
    return digest.hexdigest()


def _kept(cache: dict, kept: int, key, make: Callable[[], Any]) -> Any:
    """cache[key], made by make() if it is not there, the oldest entries dropped so that at
    most `kept` stay."""
    if key not in cache:
        while len(cache) >= kept:
            cache.pop(next(iter(cache)))
        cache[key] = make()
    return cache[key]


_SHAPES: dict[tuple, tuple[HeightField | None, list[np.ndarray] | None]] = {}
_SHAPES_KEPT = 4


def terrain_shape(
    vertices: np.ndarray, faces: np.ndarray, ground_height: float | None
) -> tuple[HeightField | None, list[np.ndarray] | None]:
    """(the height field, None) or (None, the convex prisms) the engine builds the terrain of
    (vertices (V, 3) [m] world frame, faces (F, 3); ground_height [m], None: no plane): prisms
    where the terrain is a few flat convex tops none over another (sim/_pieces.py), standing
    in the ground plane GROUND_CLEARANCE deep, or FIELD_BASE under the lowest vertex without
    one; else the field (terrain_field). (None, None): no terrain but the plane."""
    if len(faces):
        base = (
            ground_height - GROUND_CLEARANCE
            if ground_height is not None
            else float(vertices[:, 2].min()) - FIELD_BASE
        )
        prisms = convex_prisms(vertices, faces, ground_height, base=base, overhead=OVERHEAD)
        if prisms is not None:
            return None, prisms or None
    return terrain_field(vertices, faces, ground_height), None


def _cached_shape(
    vertices: np.ndarray, faces: np.ndarray, ground_height: float | None
) -> tuple[HeightField | None, list[np.ndarray] | None]:
    """terrain_shape, kept for the last _SHAPES_KEPT terrains by their content: a drive makes a
    fresh simulation of the same world each time, and the rasterising takes most of building
    one (0.2-0.7 s on double_bridge at 5 mm; compiling the model about 20 ms)."""
    key = (_content(vertices, faces), vertices.shape, faces.shape, ground_height)
    return _kept(_SHAPES, _SHAPES_KEPT, key, lambda: terrain_shape(vertices, faces, ground_height))


def field_elevation(heights: np.ndarray, ground_height: float | None) -> tuple[np.ndarray, float]:
    """(the field's heights over its lowest level ((ny, nx) float [m]), that lowest level's
    height [m]): heights ((ny, nx) [m], NaN: no surface) with the points the ground plane tops
    sunk GROUND_CLEARANCE under it and those with no surface HOLE_DEPTH under the lowest."""
    h = np.array(heights, dtype=np.float64)
    if ground_height is not None:
        h[h <= ground_height + 1e-9] = ground_height - GROUND_CLEARANCE
    hole = ~np.isfinite(h)
    low = float(np.min(h[~hole]))
    if hole.any():
        low -= HOLE_DEPTH
        h[hole] = low
    return h - low, low


def build_world_model(
    robot: RobotConfig,
    cfg: SimConfig,
    *,
    field: HeightField | None = None,
    prisms: list[np.ndarray] | None = None,
    ground_height: float | None = None,
) -> tuple[mujoco.MjModel, float | None]:
    """(the compiled model of the world: the terrain's height field (a planning HeightField,
    or None) or its convex prisms (convex_prisms' corner points, each a mesh geom), a ground
    plane at ground_height [m] (None: none) and the roach, standing at the origin; the height
    of the field's hole level [m], None without holes)."""
    spec = mujoco.MjSpec()
    spec.modelname = "roach"
    opt = spec.option
    opt.timestep = cfg.timestep
    opt.integrator = INTEGRATOR
    opt.iterations = cfg.solver_iterations
    opt.gravity = [0.0, 0.0, -9.81]
    contact = {
        "friction": [cfg.friction, 0.005, 0.0001],  # (torsion, rolling: MuJoCo's, unused)
        "solref": [CONTACT_TIMECONST, 1.0],
    }
    hole_level, elevation = _add_terrain(spec, field, ground_height, contact)
    for k, corners in enumerate(prisms or ()):
        spec.add_mesh(name=f"terrain_{k}", uservert=corners.ravel().tolist())
        spec.worldbody.add_geom(
            name=f"terrain_{k}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"terrain_{k}",
            group=_TERRAIN_GROUP,
            contype=0,
            conaffinity=_FIELD_BIT,
            **contact,
        )
    _add_robot(spec, robot, contact, on_field=field is not None)
    model = spec.compile()
    if elevation is not None:
        model.hfield_data[:] = elevation.ravel()
    return model, hole_level


def _add_terrain(
    spec: mujoco.MjSpec, field: HeightField | None, ground_height: float | None, contact: dict
) -> tuple[float | None, np.ndarray | None]:
    """Add the field (a planning HeightField, or None) and the ground plane at ground_height
    [m] (None: none) to spec's world; (the field's hole level [m], None without holes; its
    elevation data ((ny, nx) float32 in [0, 1]) for the compiled model, None without one)."""
    world = spec.worldbody
    hole_level = data = None
    if field is not None:
        elevation, low = field_elevation(field.heights, ground_height)
        ny, nx = elevation.shape
        rise = float(elevation.max())
        if np.any(~np.isfinite(field.heights)):
            hole_level = low
        half = ((nx - 1) * field.resolution / 2, (ny - 1) * field.resolution / 2)
        # The spec is given a field of zeros, as MuJoCo's binary field file (rows, columns,
        # then float32 heights) from memory, and the elevation goes into the compiled model
        # (build_world_model): through the spec, numpy's array became a list first (20 ms of
        # a capture's 55 ms rollout world), and a list of zeros took 6 ms more than these
        # bytes. The compiled model is the same but for the file's name.
        spec.assets = {
            _FIELD_FILE: np.array([ny, nx], dtype=np.int32).tobytes() + bytes(4 * ny * nx)
        }
        spec.add_hfield(
            name="terrain",
            file=_FIELD_FILE,
            size=[half[0], half[1], max(rise, 1e-6), FIELD_BASE],
        )
        # MuJoCo scales the elevation to [0, 1] of size[2]; given so, it stays as it is.
        data = (elevation / rise if rise > 0 else elevation).astype(np.float32)
        world.add_geom(
            name="terrain",
            type=mujoco.mjtGeom.mjGEOM_HFIELD,
            hfieldname="terrain",
            pos=[field.x0 + half[0], field.y0 + half[1], low],
            group=_TERRAIN_GROUP,
            contype=0,
            conaffinity=_FIELD_BIT,
            **contact,
        )
    if ground_height is not None:
        world.add_geom(
            name="ground",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0.0, 0.0, 1.0],
            pos=[0.0, 0.0, ground_height],
            group=_TERRAIN_GROUP,
            contype=0,
            conaffinity=_PLANE_BIT,
            **contact,
        )
    return hole_level, data


def _add_robot(spec: mujoco.MjSpec, robot: RobotConfig, contact: dict, *, on_field: bool):
    """Add the roach (module docstring) to spec, standing at the origin; on_field: the world
    has a height field (the body's box then meets it in pieces)."""
    body = spec.worldbody.add_body(name="body", pos=[0.0, 0.0, robot.standing_height])
    if robot.body_mass > 0:  # (of mass 0 it is fixed in the world, as PyBullet fixes a base)
        body.add_freejoint(name="root")
    robot_geom = {"group": _ROBOT_GROUP, "conaffinity": 0, **contact}
    half = (robot.body_length / 2, robot.body_width / 2, robot.body_height / 2)
    box = body.add_geom(name="body_box", type=mujoco.mjtGeom.mjGEOM_BOX, size=half, **robot_geom)
    box.mass = robot.body_mass
    box.contype = _PLANE_BIT | (0 if on_field else _FIELD_BIT)
    if on_field:
        # The box against the field: MuJoCo tests each of the field's cells under the box's
        # bounding box that rises above the box's lowest corner, so on a ramp, where that
        # corner is the box's downhill end, it tests hundreds a step. The same box cut along
        # its length into pieces short enough that each clears the slope under it tests next
        # to none (the body's collisions on the double bridge's drive: 67 -> 19 us a step).
        # Massless: the whole box carries the mass, and meets the plane.
        clearance = robot.standing_height - robot.body_height / 2
        rise = robot.body_length * math.tan(math.radians(BODY_SLOPE_DEG))
        pieces = max(1, math.ceil(rise / clearance))
        length = robot.body_length / pieces
        for k in range(pieces):
            piece = body.add_geom(
                name=f"body_box_{k}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=[length / 2, half[1], half[2]],
                pos=[-half[0] + length * (k + 0.5), 0.0, 0.0],
                **robot_geom,
            )
            piece.mass = 0.0
            piece.density = 0.0
            piece.contype = _FIELD_BIT
    armature = max(robot.drive_inertia - leg_inertia_about_hip(robot), 0.0)
    for name, hip in zip(LEG_NAMES, robot.hip_positions.tolist(), strict=True):
        leg = body.add_body(name=f"leg_{name}", pos=hip)
        leg.add_joint(
            name=f"hip_{name}",
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[0.0, 1.0, 0.0],
            armature=armature,
        )
        geom = _leg_geom(leg, robot)
        for key, value in robot_geom.items():
            setattr(geom, key, value)
        geom.contype = _PLANE_BIT | _FIELD_BIT
        servo = spec.add_actuator(
            name=f"servo_{name}", target=f"hip_{name}", trntype=mujoco.mjtTrn.mjTRN_JOINT
        )
        servo.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        servo.gainprm[0] = 1.0
        servo.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        servo.biasprm[1] = -robot.motor_kp
        servo.biasprm[2] = -robot.motor_kd
        servo.forcelimited = True
        servo.forcerange = [-robot.max_motor_torque, robot.max_motor_torque]
    for kind, what, prefix, sensor in (
        ("torque", mujoco.mjtObj.mjOBJ_ACTUATOR, "servo", mujoco.mjtSensor.mjSENS_ACTUATORFRC),
        ("speed", mujoco.mjtObj.mjOBJ_JOINT, "hip", mujoco.mjtSensor.mjSENS_JOINTVEL),
    ):
        for name in LEG_NAMES:
            spec.add_sensor(
                name=f"{kind}_{name}", type=sensor, objtype=what, objname=f"{prefix}_{name}"
            )


class MujocoSimulation:
    """One MuJoCo model and data holding a terrain and a roach (sim/_engine.py's Simulation).

    Never sleeps or reads the clock: `step()` advances exactly `cfg.timestep` seconds. Legs
    are commanded per side (differential drive); the three legs of a side follow one motor
    phase, as the real robot's linkage makes them. `model` and `data` are MuJoCo's, for
    reading (a viewer, a test).
    """

    def __init__(
        self,
        terrain_vertices: np.ndarray,
        terrain_faces: np.ndarray,
        *,
        ground_height: float | None,
        robot: RobotConfig,
        cfg: SimConfig,
    ) -> None:
        """terrain_vertices: (V, 3) float world frame [m]; terrain_faces: (F, 3) int."""
        terrain_vertices, terrain_faces = terrain_arrays(
            terrain_vertices, terrain_faces, ground_height
        )
        self.robot = robot
        self.cfg = cfg
        field, prisms = _cached_shape(terrain_vertices, terrain_faces, ground_height)
        self.model, self._hole_level = build_world_model(
            robot, cfg, field=field, prisms=prisms, ground_height=ground_height
        )
        self.data: mujoco.MjData = mujoco.MjData(self.model)
        m = self.model
        self._terrain_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "terrain")
        self._ground_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "ground")
        self._body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "body")
        self._nominal = (float(m.body_mass[self._body]), m.body_inertia[self._body].copy())
        self._free = robot.body_mass > 0  # the body has its free joint (build_world_model)
        self._legs_q = slice(7, 13) if self._free else slice(0, 6)  # the hips' qpos
        self._legs_dq = slice(6, 12) if self._free else slice(0, 6)  # and qvel
        self._rollout: rollout.Rollout | None = rollout.Rollout(nthread=0)
        self._state = np.empty((1, mujoco.mj_stateSize(m, _STATE)))
        self._warmstart = np.empty((1, m.nv))  # the solver's warm start, for the rollout
        self._buffers: dict[int, np.ndarray] = {}  # advance()'s sensor readings, by n
        self._motors = SideMotors(robot)
        self._diverged = False
        self._hit = np.zeros(1, dtype=np.int32)
        self.time = 0.0
        self.energy_per_leg = np.zeros(6)
        mujoco.mj_forward(m, self.data)  # (places the static geoms for the rays)

    @classmethod
    def open_floor(cls, robot: RobotConfig, cfg: SimConfig) -> MujocoSimulation:
        """A world with nothing but an endless floor at z = 0: calibration and reference walks."""
        no_terrain = (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))
        return cls(*no_terrain, ground_height=0.0, robot=robot, cfg=cfg)

    # -- state ----------------------------------------------------------------------------------

    def _ray_down(self, x: float, y: float, top: float) -> tuple[float, int]:
        """(height of the first terrain or ground surface under (x, y, top) [m], -inf if none
        down to z = -50; the geom it is on, -1 if none)."""
        dist = mujoco.mj_ray(
            self.model,
            self.data,
            np.array([x, y, top], dtype=np.float64),
            np.array([0.0, 0.0, -1.0]),
            _RAY_GROUPS,
            1,
            -1,
            self._hit,
        )
        z = top - dist
        if dist < 0 or z < -50.0:
            return -math.inf, -1
        geom = int(self._hit[0])
        if geom == self._terrain_geom and self._hole_level is not None:
            if z <= self._hole_level + 1e-6:  # the bottom of a hole stands for no surface
                return -math.inf, -1
        return z, geom

    def surface_height(self, x: float, y: float, below: float = 50.0) -> float:
        """Height of the highest terrain or ground surface at (x, y) [m] under z = below [m],
        -inf if none."""
        return self._ray_down(x, y, below)[0]

    def surface_heights(self, xy: np.ndarray, top: float = 50.0) -> tuple[np.ndarray, np.ndarray]:
        """For points xy (N, 2) [m]: the highest surface under z = top ((N,) [m], -inf where
        none) and whether it is the terrain rather than the ground plane ((N,) bool). The rays
        see no part of the robot, so it stays as it is."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        z = np.full(len(xy), -np.inf)
        on_terrain = np.zeros(len(xy), dtype=bool)
        for k, (x, y) in enumerate(xy.tolist()):
            z[k], geom = self._ray_down(x, y, top)
            on_terrain[k] = geom >= 0 and geom != self._ground_geom  # (the field or a prism)
        return z, on_terrain

    def reset(
        self,
        x: float,
        y: float,
        yaw: float,
        surface: float | None = None,
        *,
        phase: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        """Drop the robot at (x, y) [m] heading yaw [rad], legs in tripod stance, and settle.
        surface: the height the planner stands it on there [m]; the ground is then looked for
        just above it (under a table, the floor the plan is on, not the table top). phase: the
        (left, right) motors' phase to stand at [rad] (0: the tripod stance; a robot caught
        mid-stride). Everything else starts afresh (MuJoCo's mj_resetData): a reset world
        steps exactly as a new one."""
        r, m, d = self.robot, self.model, self.data
        mujoco.mj_resetData(m, d)
        mujoco.mj_kinematics(m, d)  # (the static geoms' frames, which the rays need)
        self._diverged = False

        def ground(gx: float, gy: float) -> float:
            return ground_height(self.surface_height, gx, gy, surface)

        z0 = start_height(ground, r, x, y, yaw)
        position = (x, y, z0 + r.standing_height + DROP_CLEARANCE)
        quat = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        tilted = support_plane_pose(ground, r, x, y, yaw)
        if tilted is not None:
            position, quat = tilted
        d.qpos[self._legs_q] = self._motors.reset(phase)
        self.place(position, quat)
        self.advance(round(self.cfg.settle_time / self.cfg.timestep))  # legs held, speed 0
        self.time = 0.0
        d.time = 0.0
        self.energy_per_leg[:] = 0.0

    def place(
        self,
        position: tuple[float, float, float],
        quat: tuple[float, float, float, float],
    ) -> None:
        """Put the body at position [m] with orientation quat (xyzw, world from body), at rest,
        legs as they are."""
        m, d = self.model, self.data
        qx, qy, qz, qw = quat
        if self._free:
            d.qpos[0:3] = position
            d.qpos[3:7] = (qw, qx, qy, qz)  # MuJoCo's quaternions are wxyz
            d.qvel[0:6] = 0.0
        else:  # a fixed body is where the model has it
            m.body_pos[self._body] = position
            m.body_quat[self._body] = (qw, qx, qy, qz)
        mujoco.mj_forward(m, d)

    def set_joint_damping(self, damping: float) -> None:
        """Viscous damping at every hip [N m s / rad] (0 on the robot: a test of the energy
        meter drives the legs against it)."""
        self.model.dof_damping[self._legs_dq] = damping

    def set_leg_speeds(self, left: float, right: float) -> None:
        """Command the left and right motors [rad/s], clipped to the motor's speed limit. With
        perturb()'s motor gains, each side then runs at gain x the command (a real motor's
        speed differs from what it is told)."""
        self._motors.command(left, right)

    def perturb(
        self, *, friction: float, mass_scale: float, motor_gain: tuple[float, float]
    ) -> None:
        """Set this world's physical uncertainty for the next drives (choose's rollouts):
        the Coulomb friction of terrain, ground and robot [-], the body's mass as a multiple
        of the robot's [-], and the (left, right) motors' speed gains [-] as multiples of the
        robot's own (RobotConfig.motor_gain, 1 on the nominal robot).
        perturb(friction=cfg.friction, mass_scale=1, motor_gain=(1, 1)) is the nominal world."""
        m, d = self.model, self.data
        m.geom_friction[:, 0] = friction
        # The body (a payload on it) only: the legs' inertia is their motors' reflected one.
        mass, inertia = self._nominal
        m.body_mass[self._body] = mass * mass_scale
        m.body_inertia[self._body] = inertia * mass_scale
        # The constants MuJoCo derives from the masses (the contacts' softness scales with the
        # inverse inertia); mj_setConst works on the data, so its state is kept round it.
        state = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_INTEGRATION.value))
        mujoco.mj_getState(m, d, state, mujoco.mjtState.mjSTATE_INTEGRATION.value)
        mujoco.mj_setConst(m, d)
        mujoco.mj_setState(m, d, state, mujoco.mjtState.mjSTATE_INTEGRATION.value)
        mujoco.mj_forward(m, d)
        self._motors.set_gain(motor_gain)

    def step(self) -> None:
        """Advance one timestep and meter the energy the leg motors spend (Tong 2018, 3.4)."""
        self.advance(1)

    def advance(self, n: int) -> None:
        """Advance n timesteps at the current leg speeds, metering the motors' energy.

        The hot loop of every drive: the legs' servo inputs for all n steps are computed at
        once and MuJoCo steps them in one call (mujoco.rollout, from the data's own state and
        solver warm start: the same steps as mj_step n times, bit for bit). A worker's rollouts
        stepped together (sim/_lockstep.py) use the same servo_inputs and advanced.
        """
        if n <= 0:
            return
        m, d = self.model, self.data
        ctrl = self.servo_inputs(n)[None]
        sensors = self._buffers.get(n)
        if sensors is None:
            sensors = self._buffers[n] = np.empty((1, n, m.nsensordata))
        mujoco.mj_getState(m, d, self._state[0], _STATE)
        self._warmstart[0] = d.qacc_warmstart
        unstable = self._resets()
        assert self._rollout is not None, "advance() after close()"
        self._rollout.rollout(
            [m],
            [d],
            self._state,
            ctrl,
            skip_checks=True,
            nstep=n,
            initial_warmstart=self._warmstart,
            state=None,
            sensordata=sensors,
        )
        self.advanced(n, sensors[0], diverged=self._resets() != unstable)

    def servo_inputs(self, n: int) -> np.ndarray:
        """(n, 6) each leg servo's input for the next n steps at the current leg speeds: the
        targets' part of its force, kp q_target + kd dq_target [N m] (the actuator adds
        -kp q - kd dq). Each leg is a PD servo on its share of its side's motor phase: the
        legs of a side stay in phase like the real linkage."""
        r = self.robot
        q, dq = self._motors.targets(n, self.cfg.timestep)  # (n, 6) each
        return r.motor_kp * q + r.motor_kd * dq

    @staticmethod
    def servo_inputs_together(sims: list[MujocoSimulation], n: int) -> np.ndarray:
        """(n, k, 6): [:, j] what sims[j].servo_inputs(n) gives, bit for bit, in one pass
        (rollouts in lockstep, sim/_lockstep.py; one robot description)."""
        r = sims[0].robot
        q, dq = targets_together([s._motors for s in sims], n, sims[0].cfg.timestep)
        return r.motor_kp * q + r.motor_kd * dq

    @staticmethod
    def metered(sensors: np.ndarray, dt: float) -> np.ndarray:
        """Each leg's energy over steps of dt [s] from their sensor readings ((..., n,
        nsensordata), each step's forward pass): (..., 6) [J]. The meter: E += |tau dq/dt| dt
        per leg (Tong 2018, 3.4), tau the servo's force as applied (after the torque limit),
        dq/dt the hip's speed as the step began (both are the sensors of the step's forward
        pass, as PyBullet's meter reads them)."""
        tau, dq = sensors[..., :6], sensors[..., 6:12]
        return np.abs(tau * dq).sum(axis=-2) * dt

    def advanced(
        self, n: int, sensors: np.ndarray, *, diverged: bool, energy: np.ndarray | None = None
    ) -> None:
        """After n steps with servo_inputs(n): meter them from their sensor readings ((n,
        nsensordata), each step's forward pass; or their energy per leg ((6,) [J], metered
        for several at once) and move the motors' phase and the clock on. diverged: MuJoCo
        found the state not finite and reset it meanwhile (it then goes on from its model's
        pose; the drive reads a body at no finite place, as PyBullet's)."""
        self._diverged = self._diverged or diverged
        dt = self.cfg.timestep
        self.energy_per_leg += self.metered(sensors, dt) if energy is None else energy
        self._motors.advance(n, dt)
        self.time += n * dt

    def _resets(self) -> int:
        """How many times MuJoCo has found the state not finite (or huge) and reset it."""
        w = self.data.warning
        return sum(w[k].number for k in _DIVERGED)

    def pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """(p_world_body [m], quat_world_body xyzw) as plain tuples: the controller's fast read."""
        if self._diverged:
            nan = math.nan
            return (nan, nan, nan), (nan, nan, nan, nan)
        if self._free:
            x, y, z, qw, qx, qy, qz = self.data.qpos[0:7].tolist()
        else:
            x, y, z = self.model.body_pos[self._body].tolist()
            qw, qx, qy, qz = self.model.body_quat[self._body].tolist()
        return (x, y, z), (qx, qy, qz, qw)

    def body_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(p_world_body (3,) [m], quat_world_body (4,) xyzw)."""
        pos, quat = self.pose()
        return np.array(pos), np.array(quat)

    def joint_angles(self) -> np.ndarray:
        """(6,) leg angles [rad], hip order L1 L2 L3 R1 R2 R3."""
        return self.data.qpos[self._legs_q].copy()

    @property
    def energy(self) -> float:
        """Energy spent by all leg motors since reset [J]."""
        return float(self.energy_per_leg.sum())

    def close(self) -> None:
        """Free the rollout's worker (once); the model and data go with the object."""
        if self._rollout is not None:
            self._rollout.close()
            self._rollout = None

    def __enter__(self) -> MujocoSimulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
