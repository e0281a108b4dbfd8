"""The ground on small, far and tilted floors.

On held-out real rooms the ground was wrong on a floor that held few of the points (5.2 cm too
high) and beside a person standing in front of a wall (5.5 deg and 19 cm off). These are
synthetic depth captures of those kinds, rendered by the project's own renderer from built
meshes (a floor, walls that hold most of the pixels, desks, box "people", shelves), where the
ground is known exactly: the floor at z = 0, the camera's pose given. The Kinect v1's depth
(structured light, the sensor of NYU's and TUM's captures) is modelled too: its disparity is
an integer, so its depth comes in steps of z^2 / 351 m (4.6 cm at 4 m), on far floors and on
walls seen obliquely, where the steps' edges line up into planes that face up.

Before the fix (RANSAC's planes compared as found, their heights at the sensor, refits on
every point within a band that widened on its own scatter), each kind was off on some of its
noise draws by the figures in its comment; now every draw is found within 2 cm and 1 deg. The
real captures' measured ground (the data README's table) is kept within 2 cm and 2 deg.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple, cast

import numpy as np
import pytest
import trimesh

from roachplan.perception import (
    PRESETS,
    GroundConfig,
    NoiseModel,
    choose_ground,
    load_capture,
    look_at,
    reconstruct,
    render_depth,
    save_depth,
    voxel_downsample,
)
from test_perception import REAL
from test_real_terrain import GROUND_FACTS

HEIGHT_TOL = 0.02
"""Found camera height within this of the truth [m]."""
ANGLE_TOL = 1.0
"""Found ground normal within this of the truth [deg]."""
SEEDS = (0, 1)
"""Noise draws of each capture."""


class Room(NamedTuple):
    """A room seen by a depth camera; the floor's top is z = 0, y is the room's depth."""

    width: float
    """Between the side walls, centred on the camera [m]."""
    depth: float
    """From the camera to the back wall [m]."""
    desks: tuple[tuple[float, float, float, float, float], ...] = ()
    """(centre x, centre y, width, depth, height) [m]: a 3 cm top on four legs."""
    people: tuple[tuple[float, float, float], ...] = ()
    """(x, y, height) [m]: a 45 cm x 28 cm box standing on the floor."""
    boxes: tuple[tuple[tuple[float, float, float], tuple[float, float]], ...] = ()
    """((size x, y, z), (centre x, y)) [m]: shelves and cabinets standing on the floor."""
    camera: tuple[float, float, float, float] = (1.5, 0.0, 0.0, 0.0)
    """(height [m], yaw, pitch up, roll [deg]) of the camera at x = y = 0."""
    sensor: str = "kinect1"
    """"kinect1": structured light, integer disparity (_structured_light); else a preset
    rendered with the Kinect v2 noise model."""


def _box(size, centre) -> trimesh.Trimesh:
    b = trimesh.creation.box(size)
    b.apply_translation(centre)
    return b


def _mesh(room: Room) -> trimesh.Trimesh:
    """The room's mesh, world frame (z up)."""
    x1, y1, h = room.width / 2, room.depth, 2.6
    parts = [
        _box((20.0, 20.0, 0.02), (0.0, 0.0, -0.01)),
        _box((2 * x1 + 0.2, 0.1, h), (0.0, y1 + 0.05, h / 2)),
        _box((0.1, y1 + 3.0, h), (-x1 - 0.05, (y1 - 3.0) / 2, h / 2)),
        _box((0.1, y1 + 3.0, h), (x1 + 0.05, (y1 - 3.0) / 2, h / 2)),
    ]
    for cx, cy, w, d, top in room.desks:
        parts.append(_box((w, d, 0.03), (cx, cy, top - 0.015)))
        for dx in (-w / 2 + 0.03, w / 2 - 0.03):
            for dy in (-d / 2 + 0.03, d / 2 - 0.03):
                parts.append(_box((0.04, 0.04, top - 0.03), (cx + dx, cy + dy, (top - 0.03) / 2)))
    for x, y, tall in room.people:
        parts.append(_box((0.45, 0.28, tall), (x, y, tall / 2)))
    for size, (x, y) in room.boxes:
        parts.append(_box(size, (x, y, size[2] / 2)))
    return cast(trimesh.Trimesh, trimesh.util.concatenate(parts))


def _pose(room: Room) -> np.ndarray:
    """(4, 4) world_from_camera: at the room's camera height, turned by yaw (from +y toward
    +x), pitched up, then rolled about the optical axis."""
    height, yaw, pitch, roll = room.camera
    a, b, r = math.radians(yaw), math.radians(pitch), math.radians(roll)
    eye = np.array([0.0, 0.0, height])
    pose = look_at(eye, eye + [math.sin(a) * math.cos(b), math.cos(a) * math.cos(b), math.sin(b)])
    turn = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
    pose[:3, :3] = pose[:3, :3] @ turn
    return pose


def _structured_light(depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A Kinect v1's depth of an exact depth image [m]: its 11-bit disparity d (NYU's model,
    depth = 351.3 / (1092.5 - d), as perception reads raw disparity) with 0.35 of noise,
    rounded to an integer, back to depth; 0 = no reading."""
    seen = depth > 0
    d = np.round(1092.5 - 351.3 / np.where(seen, depth, 1.0) + rng.normal(0.0, 0.35, depth.shape))
    z = 351.3 / (1092.5 - d)
    return np.where(seen & (z > 0.4) & (z < 10.0), z, 0.0)


def _ground_error(tmp_path: Path, room: Room, seed: int = 0) -> tuple[float, float]:
    """(height error [m], angle error [deg]) of the ground found in the room's capture (a
    16-bit depth PNG, read and reconstructed as any capture), against the truth."""
    rng = np.random.default_rng(seed)
    pose = _pose(room)
    mesh = _mesh(room)
    if room.sensor == "kinect1":
        intr = PRESETS["kinect1"]
        depth = _structured_light(render_depth(mesh, intr, pose, NoiseModel(axial=False), rng), rng)
    else:
        intr = PRESETS[room.sensor]
        depth = render_depth(mesh, intr, pose, NoiseModel(), rng)
    png = tmp_path / "room.png"
    save_depth(png, depth, intr)
    rec = reconstruct(load_capture(png))
    assert rec.ground is not None
    up = pose[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # the floor's normal, camera frame
    angle = math.degrees(math.acos(np.clip(rec.ground.normal @ up, -1.0, 1.0)))
    return rec.ground.offset - pose[2, 3], angle


KINDS = {
    # Kinect v1, camera 1.71 m up, rolled 12 deg; the floor seen only beyond 4.2 m, past a
    # person 2.1 m away and a desk: 5 % of the points. Before: 21 cm and 3.0 deg off on one
    # draw of the room this is cut from (a tilted slab of the far floor passed below the
    # floor at the sensor, so it was "the lowest"); 1.8 cm at most on six draws of this one.
    "a person in front of a far floor": Room(
        width=5.0,
        depth=5.4,
        desks=((-0.31, 2.92, 1.54, 0.51, 0.75),),
        people=((0.55, 2.11, 1.83),),
        camera=(1.71, -18.0, 4.0, 12.0),
    ),
    # Kinect v1 rolled 22 deg: desks, people and shelves in front, the floor from 3.4 m on.
    # Before: 5.1 cm and 0.9 deg off (seed 0).
    "a far floor, camera rolled": Room(
        width=4.2,
        depth=3.8,
        desks=((-1.28, 3.22, 1.63, 0.69, 0.74), (1.30, 2.45, 1.32, 0.69, 0.68)),
        people=((-1.13, 3.46, 1.70), (1.46, 0.86, 1.79)),
        boxes=(((0.89, 0.4, 1.24), (-1.03, 3.6)), ((0.4, 0.98, 1.21), (-1.91, 0.73))),
        camera=(1.52, 12.4, 4.6, -22.0),
    ),
    # Kinect v1 0.93 m up, pitched up 10 deg: the back wall's disparity terraces line up
    # into planes that face up 45-60 deg off the camera's -y, larger than the floor (1.7 %
    # of the points). Before: 2.2 and 2.6 cm off (seeds 0, 1); on seeds 2 and 3 the wall
    # was the ground (90 and 81 deg off).
    "a low camera pitched up": Room(
        width=5.5,
        depth=3.38,
        desks=((0.27, 1.70, 1.55, 0.69, 0.74), (1.39, 2.60, 0.88, 0.70, 0.78)),
        people=((-1.57, 1.87, 1.73),),
        camera=(0.93, 11.3, 10.0, 4.0),
    ),
    # Kinect v1 rolled 27 deg; two desks and two people fill the view, the floor round them
    # is 2.3 % of the points (0.36 m^2 against the desks' 1.7 m^2; the desks 2.4 cm apart in
    # height). Before: 3.3 and 3.1 cm, 0.7 deg off (seeds 0, 1).
    "desks larger than the floor, camera rolled": Room(
        width=2.99,
        depth=3.89,
        desks=((0.37, 3.37, 1.36, 0.70, 0.69), (-0.07, 1.99, 1.53, 0.67, 0.71)),
        people=((-1.01, 2.99, 1.60), (-0.71, 2.27, 1.83)),
        boxes=(((0.99, 0.4, 2.01), (0.82, 3.69)), ((0.4, 0.88, 2.01), (-1.29, 1.07))),
        camera=(1.58, -9.1, -0.3, 27.0),
    ),
    # Kinect v1: desks and a person near, the floor from 4.1 m on. Before: 9.7 cm and 1.0
    # deg off on one draw of the room this is cut from; 1.4 cm at most on six of this one.
    "a far floor behind desks": Room(
        width=5.44,
        depth=5.34,
        desks=((-1.16, 1.63, 1.48, 0.88, 0.72), (-1.25, 3.34, 1.13, 0.64, 0.68)),
        people=((-1.24, 1.42, 1.79),),
        camera=(1.65, -0.8, 3.8, -14.0),
    ),
    # Kinect v2 (its noise model): shelves, a desk and two people; the floor 3 % of the
    # points, from 3.8 m. Before: 1.3 and 1.5 cm off (seeds 0, 1), 1.7 cm on the room's own.
    "a small floor among people and shelves (Kinect v2)": Room(
        width=2.64,
        depth=4.19,
        desks=((0.56, 1.48, 1.0, 0.77, 0.70),),
        people=((-0.12, 2.21, 1.74), (0.51, 1.42, 1.73)),
        boxes=(((0.4, 1.84, 2.07), (-1.12, 2.03)), ((0.4, 0.8, 1.99), (1.12, 0.57))),
        camera=(1.35, 18.2, 3.7, -1.0),
        sensor="kinect2-qhd",
    ),
}


def test_the_foot_of_a_wall_does_not_tilt_a_floor_strip():
    """A floor seen as a strip 15 cm deep (0.3 m^2) at the foot of a wall, a desk nearer, from
    a camera 1.4 m up pitched down 20 deg: points 1 cm apart with 3 mm of noise. The wall's
    lowest rows lie within the floor's band; fitted with them, the strip tilted 0.4 deg (2 cm
    at the camera). Only the points that face as the floor does are its own now."""
    rng = np.random.default_rng(0)
    g = np.arange(-1.0, 1.0, 0.01)
    x, y = np.meshgrid(g, np.arange(2.85, 3.0, 0.01))
    floor = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    x, z = np.meshgrid(g, np.arange(0.0, 2.0, 0.01))
    wall = np.column_stack([x.ravel(), np.full(x.size, 3.0), z.ravel()])
    x, y = np.meshgrid(g, np.arange(1.5, 2.3, 0.01))
    desk = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 0.75)])
    world = np.vstack([floor, wall, desk]) + rng.normal(
        0.0, 0.003, (len(floor) + len(wall) + len(desk), 3)
    )
    a = math.radians(20.0)
    forward = np.array([0.0, math.cos(a), -math.sin(a)])
    right = np.array([1.0, 0.0, 0.0])
    camera_from_world = np.array([right, np.cross(forward, right), forward])  # x right, y down
    points = voxel_downsample((world - [0.0, 0.0, 1.4]) @ camera_from_world.T, (0.01, 0.01, 0.01))
    ground = choose_ground(points, np.array([0.0, -1.0, 0.0]), GroundConfig())
    up = camera_from_world @ [0.0, 0.0, 1.0]
    angle = math.degrees(math.acos(np.clip(ground.normal @ up, -1.0, 1.0)))
    assert abs(ground.offset - 1.4) <= 0.005 and angle <= 0.2, (ground.offset, angle)


def test_ransac_scores_a_sample_first_and_chooses_as_every_point_would():
    """The plane hypotheses are scored on a sample of 1,000 points first, and only those it
    cannot tell from the best on all of them: the plane chosen is the one scoring every
    hypothesis on every point chooses (the first of the best on a tie), on a floor of a
    tenth of the points among walls, and on a floor that holds most of them, where hundreds
    of hypotheses lie within the sample's error of the best."""
    from roachplan.perception._ground import _ransac_plane

    def every_point(pts, rng):  # every hypothesis scored on every point, as it was
        t = rng.integers(0, len(pts), size=(1000, 3))
        a, b, c = pts[t[:, 0]], pts[t[:, 1]], pts[t[:, 2]]
        n = np.cross(b - a, c - a)
        length = np.linalg.norm(n, axis=1)
        n, a = n[length > 1e-12] / length[length > 1e-12, None], a[length > 1e-12]
        d = -np.einsum("ij,ij->i", n, a)
        counts = np.concatenate(
            [
                np.sum(np.abs(n[k : k + 64] @ pts.T + d[k : k + 64, None]) <= 0.015, axis=1)
                for k in range(0, len(n), 64)
            ]
        )
        best = int(np.argmax(counts))  # the first of the best
        return n[best], d[best]

    rng = np.random.default_rng(1)
    for floor_share in (0.1, 0.8):
        n_floor = int(20000 * floor_share)
        floor = np.column_stack([rng.uniform(-2, 2, (n_floor, 2)), np.zeros(n_floor)])
        walls = rng.uniform(-2, 2, (20000 - n_floor, 3))
        walls[: len(walls) // 2, 0] = 2.0
        walls[len(walls) // 2 :, 1] = 2.0
        pts = np.vstack([floor, walls]) + rng.normal(0.0, 0.005, (20000, 3))
        for seed in range(3):
            n, d, _ = _ransac_plane(pts, 0.015, 1000, np.random.default_rng(seed))
            n_all, d_all = every_point(pts, np.random.default_rng(seed))
            assert np.array_equal(n, n_all) and d == d_all


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", list(KINDS))
def test_the_ground_of_a_room_of_each_kind_is_found(tmp_path, kind, seed):
    height, angle = _ground_error(tmp_path, KINDS[kind], seed)
    assert abs(height) <= HEIGHT_TOL and angle <= ANGLE_TOL, (height, angle)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "flags", "up", "height"), GROUND_FACTS, ids=[g[0] for g in GROUND_FACTS]
)
def test_the_real_captures_ground_is_kept(name, flags, up, height):
    """Every capture of the data README's table: the camera's height within 2 cm of the
    measured one and the ground's normal within 2 deg."""
    settings = dict(zip(flags[::2], flags[1::2], strict=True))
    cap = load_capture(REAL / name, intrinsics=settings.get("--intrinsics"))
    rec = reconstruct(cap)
    assert rec.ground is not None
    up = np.asarray(up) / np.linalg.norm(up)
    angle = math.degrees(math.acos(np.clip(rec.ground.normal @ up, -1.0, 1.0)))
    assert angle <= 2.0, (angle, rec.ground.normal)
    assert abs(rec.report()["camera_height_m"] - height) <= 0.02
