"""Which surface of a capture is the ground: gravity first, not the largest plane.

A room capture's largest plane is often a wall, and a table capture's a background surface;
in a level-camera office or a room with people in it the floor may be a few per cent of the
points, behind walls and furniture. So the ground is searched for as a person would: gravity
points roughly along the camera's +y (a level camera's "up" is -y) unless a calibration, an
IMU or the user says otherwise; only surfaces that face up under that prior are searched,
however small a share of the cloud they are (each point's normal decides, so a floor of 3 %
of the points is found among walls of 60 %); among the planes found there, the horizontal
ones are those parallel to the best-supported one; the ground is the lowest of them that is
well supported (the floor under a desk, not the desk; never a wall).

All directions here are in the capture's frame (a camera's: x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._errors import CaptureError

CAMERA_UP = (0.0, -1.0, 0.0)
"""A level camera's up in its optical frame (x right, y down, z forward)."""
Z_UP = (0.0, 0.0, 1.0)
"""Up in a world or robot frame (REP 103: z up)."""
MAX_BAND = 0.05
"""Widest band round the ground plane its final fit takes points from [m]: a rough or noisy
ground's scatter, short of what a curb or a rug would add."""


@dataclass(frozen=True, kw_only=True)
class GroundConfig:
    """How the ground plane is searched for."""

    threshold: float = 0.015
    """RANSAC inlier distance of a plane [m]."""
    iterations: int = 1000
    """RANSAC iterations per plane."""
    max_planes: int = 8
    """Planes extracted one after the other (each plane's inliers removed)."""
    prior_tolerance_deg: float = 60.0
    """A plane whose up-facing normal is within this angle of the gravity prior may be the
    ground: a camera pitched down 46 deg at a desk still qualifies, a wall (90 deg) or a
    surface above the camera (> 90 deg) does not."""
    parallel_deg: float = 6.0
    """Planes within this angle of the chosen up are horizontal (parallel to the ground)."""
    min_area: float = 0.25
    """A horizontal plane needs this much area (occupied 5 cm cells) [m^2] to be the ground:
    50 cm x 50 cm, a few robot lengths; smaller patches below the floor are noise."""
    min_fraction: float = 0.02
    """...and this fraction of the points."""
    level_gap: float = 0.05
    """Level planes closer than this [m] to a larger one are fragments of it (a noisy floor
    far from the camera comes out of RANSAC as several slightly tilted slabs), not a level of
    their own."""
    seed: int = 0
    """Seed of RANSAC."""


@dataclass(frozen=True, kw_only=True)
class Plane:
    """A plane found in a cloud: n.p + d = 0, n unit, facing up (n . prior_up > 0 when it can)."""

    normal: np.ndarray
    """(3,) unit normal, capture frame."""
    offset: float
    """d [m]: the origin (the sensor) is at signed distance d from the plane."""
    support: int
    """Inlier points."""
    area: float
    """Area its inliers cover, counted in occupied 5 cm cells [m^2]."""
    angle_deg: float
    """Angle between the normal and the gravity prior [deg]."""


@dataclass(frozen=True, kw_only=True)
class GroundChoice:
    """The ground plane and how it was chosen."""

    normal: np.ndarray
    """(3,) unit up normal of the ground, capture frame."""
    offset: float
    """d [m] with n.p + d = 0: the sensor's height above the ground when positive."""
    support: int
    """Points on the ground plane."""
    fraction: float
    """Share of the cloud's points on the ground plane."""
    area: float
    """Area of the ground seen [m^2]."""
    planes: tuple[Plane, ...]
    """Every plane that was found, in extraction order."""
    warnings: tuple[str, ...] = ()
    """Why the choice may be wrong, for the user to check."""


def find_planes(
    points: np.ndarray,
    up: np.ndarray,
    cfg: GroundConfig,
    toward_sensor: bool = True,
    cone_deg: float | None = None,
) -> list[Plane]:
    """Up to cfg.max_planes planes of points ((N, 3), capture frame [m]), by sequential seeded
    RANSAC (_ransac_plane). toward_sensor: each normal faces the sensor (the origin), so a
    surface seen from below (a ceiling, a table's underside) faces away from up and cannot be
    the ground; else (a world-frame cloud, whose origin may be anywhere) each faces up ((3,)).
    cone_deg: only planes within this angle of up ((3,) unit) are hypotheses (None: any)."""
    if len(points) < 3:
        raise CaptureError("too few points left to find the ground plane")
    rng = np.random.default_rng(cfg.seed)
    rest = points
    planes: list[Plane] = []
    min_points = max(50, int(0.01 * len(points)))
    cone = None if cone_deg is None else (up, float(np.cos(np.radians(cone_deg))))
    while len(planes) < cfg.max_planes and len(rest) >= min_points:
        n, d, inliers = _ransac_plane(rest, cfg.threshold, cfg.iterations, rng, cone)
        if len(inliers) < min_points:
            break
        if (d < 0) if toward_sensor else (n @ up < 0):
            n, d = -n, -d
        planes.append(
            Plane(
                normal=n,
                offset=float(d),
                support=len(inliers),
                area=_area(rest[inliers], n),
                angle_deg=float(np.degrees(np.arccos(np.clip(n @ up, -1.0, 1.0)))),
            )
        )
        keep = np.ones(len(rest), dtype=bool)
        keep[inliers] = False
        rest = rest[keep]
    return planes


def _ransac_plane(
    points: np.ndarray,
    threshold: float,
    iterations: int,
    rng: np.random.Generator,
    cone: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, float, np.ndarray]:
    """(unit normal (3,), offset d, inlier indices) of the plane n . p + d = 0 through three of
    the points ((N, 3) [m]) that the most points lie within threshold [m] of, over `iterations`
    random triples. cone (up (3,) unit, cos of the largest angle): triples whose plane is
    steeper than that to up are no hypotheses. Ours, not Open3D's segment_plane: that one
    draws its triples across OpenMP threads, so the same seed gave different planes under
    different machine load."""
    pts = np.asarray(points, dtype=np.float64)
    triples = rng.integers(0, len(pts), size=(iterations, 3))
    a, b, c = pts[triples[:, 0]], pts[triples[:, 1]], pts[triples[:, 2]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    ok = length > 1e-12  # three distinct, not collinear points
    if cone is not None:
        ok &= np.abs(normals @ cone[0]) >= cone[1] * length
    normals, a = normals[ok] / length[ok, None], a[ok]
    offsets = -np.einsum("ij,ij->i", normals, a)
    best, best_count = 0, -1
    for k0 in range(0, len(normals), 64):  # 64 candidates x N distances at a time
        dist = np.abs(normals[k0 : k0 + 64] @ pts.T + offsets[k0 : k0 + 64, None])
        counts = np.sum(dist <= threshold, axis=1)
        k = int(np.argmax(counts))
        if counts[k] > best_count:
            best, best_count = k0 + k, int(counts[k])
    if best_count < 0:
        return np.array([0.0, 0.0, 1.0]), 0.0, np.zeros(0, dtype=np.int64)
    n, d = normals[best], float(offsets[best])
    return n, d, np.flatnonzero(np.abs(pts @ n + d) <= threshold)


def _area(points: np.ndarray, normal: np.ndarray, cell: float = 0.05) -> float:
    """Area [m^2] covered by points ((N, 3)) lying on a plane with this normal: occupied cells
    of a cell x cell grid in the plane."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    uv = np.floor(np.column_stack([points @ u, points @ v]) / cell).astype(np.int64)
    return len(np.unique(uv, axis=0)) * cell * cell


def choose_ground(
    points: np.ndarray,
    up: np.ndarray,
    cfg: GroundConfig,
    near: np.ndarray | None = None,
    toward_sensor: bool = True,
) -> GroundChoice:
    """The ground plane of points ((N, 3), capture frame [m]) under the gravity prior up ((3,)).

    1. Planes are found one after another (find_planes) among the points facing up within
       prior_tolerance_deg of the prior, as hypotheses inside that cone (gravity first).
    2. The best-supported group of mutually parallel candidates gives the refined up (the
       floor and a desk agree on it; a sloping surface does not).
    3. The horizontal planes (within parallel_deg of the refined up) that are well supported
       (min_area, min_fraction) are ground candidates; the lowest one (farthest below the
       sensor) is the ground.
    near: a point ((3,), capture frame [m]) on the intended ground: then the plane through it
    is the ground whatever its orientation (the user's re-levelling click).
    """
    up = np.asarray(up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    # Planes are searched in an even subsample (RANSAC's cost grows with the points; 30,000
    # still put dozens in every 5 cm cell of a surface); the chosen one is refitted on all.
    sub = points[:: max(1, len(points) // 30000)]
    warnings: list[str] = []
    if near is not None:
        planes = find_planes(sub, up, cfg, toward_sensor)
        if not planes:
            raise CaptureError("no plane found in the capture: nothing to take as the ground")
        return _ground_through(
            points,
            planes,
            np.asarray(near, dtype=np.float64),
            cfg,
            up=up,
            toward_sensor=toward_sensor,
        )
    # Gravity first: only points whose surface faces up under the prior are searched, and
    # only planes within the prior's cone are hypotheses. Searching the whole cloud found the
    # largest planes first (walls, furniture), and a floor of a few per cent was never among
    # the eight (a level-camera office, a room with a person in it).
    facing = _facing_up(sub, up, cfg.prior_tolerance_deg, toward_sensor)
    planes = []
    if facing.sum() >= 50:
        planes = find_planes(sub[facing], up, cfg, toward_sensor, cone_deg=cfg.prior_tolerance_deg)
    pool = int(facing.sum())  # the points a ground may be a share of
    candidates = [p for p in planes if p.angle_deg <= cfg.prior_tolerance_deg]
    if not candidates:
        planes = find_planes(sub, up, cfg, toward_sensor)
        if not planes:
            raise CaptureError("no plane found in the capture: nothing to take as the ground")
        pool = len(sub)
        best = min(planes, key=lambda p: p.angle_deg)
        warnings.append(
            f"no plane faces up within {cfg.prior_tolerance_deg:g} deg of the assumed gravity; "
            f"took the closest ({best.angle_deg:.0f} deg off); if that is wrong, give the up "
            f"direction (--up) or the camera pose, or click the ground in the page"
        )
        candidates = [best]

    refined = _refined_up(candidates, up, cfg, warnings)
    ground, well = _lowest_level(
        planes,
        refined,
        cfg,
        pool=pool,
        total=len(sub),
        toward_sensor=toward_sensor,
        warnings=warnings,
    )
    # The level surfaces share one normal (a floor and the desks on it): fitted jointly, their
    # up is better known than from the ground alone, which may be a strip a few tens of
    # centimetres deep at the bottom of the view (2 deg there is 5 cm at the camera).
    level = [(p.normal, p.offset) for p in [ground, *[q for q in well if q is not ground]]]
    n, d = _refit_level(points, level, cfg.threshold)
    support = int(np.sum(np.abs(points @ n + d) <= cfg.threshold))
    return GroundChoice(
        normal=n,
        offset=d,
        support=support,
        fraction=support / len(points),
        area=ground.area,
        planes=tuple(planes),
        warnings=tuple(warnings),
    )


def _refined_up(
    candidates: list[Plane], up: np.ndarray, cfg: GroundConfig, warnings: list[str]
) -> np.ndarray:
    """(3,) unit up refined by the best-supported group of mutually parallel candidate planes
    (the floor and a desk agree on it; a sloping surface does not); a warning when another
    orientation is nearly as well supported."""

    def group(p: Plane) -> list[Plane]:
        return [q for q in candidates if _angle(p.normal, q.normal) <= cfg.parallel_deg]

    scores = [sum(q.support for q in group(p)) for p in candidates]
    order = np.argsort(scores)[::-1]
    members = group(candidates[int(order[0])])
    refined = np.sum([q.support * q.normal for q in members], axis=0)
    refined /= np.linalg.norm(refined)
    rivals = [
        candidates[int(k)]
        for k in order[1:]
        if _angle(candidates[int(k)].normal, refined) > cfg.parallel_deg
    ]
    if rivals and max(sum(q.support for q in group(r)) for r in rivals) >= 0.5 * scores[order[0]]:
        r = max(rivals, key=lambda r: sum(q.support for q in group(r)))
        warnings.append(
            f"two surface orientations are nearly as well supported: the ground chosen is "
            f"{_angle(refined, up):.0f} deg from the assumed gravity, another "
            f"{r.angle_deg:.0f} deg; check the result, or give --up or the camera pose"
        )
    return refined


def _lowest_level(
    planes: list[Plane],
    refined: np.ndarray,
    cfg: GroundConfig,
    *,
    pool: int,
    total: int,
    toward_sensor: bool,
    warnings: list[str],
) -> tuple[Plane, list[Plane]]:
    """(the ground, every well-supported level plane): among the planes level to refined
    ((3,) unit; not a thin fragment of a larger one), those min_area large and min_fraction of
    pool points are well supported, and the lowest of them is the ground. total: the points
    searched, for the warnings' shares."""
    horizontal: list[Plane] = []
    for p in sorted(planes, key=lambda p: -p.support):
        level = _angle(p.normal, refined) <= cfg.parallel_deg
        if level and all(abs(p.offset - q.offset) >= cfg.level_gap for q in horizontal):
            horizontal.append(p)
    well = [
        p for p in horizontal if p.area >= cfg.min_area and p.support >= cfg.min_fraction * pool
    ]
    if not well:
        well = [max(horizontal, key=lambda p: p.support)]
        warnings.append(
            f"the ground seen is small ({well[0].area:.2f} m^2, "
            f"{100 * well[0].support / total:.0f} % of the points)"
        )
    ground = max(well, key=lambda p: p.offset)  # the lowest: farthest below the sensor
    if toward_sensor and ground.offset <= 0:
        warnings.append("the sensor is not above the ground chosen: check the up direction")
    higher = [p for p in well if p is not ground and p.support > ground.support]
    if higher:
        h = max(higher, key=lambda p: p.support)
        warnings.append(
            f"the ground is the lowest level surface ({100 * ground.support / total:.0f} % of "
            f"the points), {ground.offset - h.offset:.2f} m below a larger one "
            f"({100 * h.support / total:.0f} %); if the robot stands on that one, click it in "
            f"the page or give the camera pose"
        )
    if ground.angle_deg > 50.0:
        warnings.append(
            f"the ground is tilted {ground.angle_deg:.0f} deg from the assumed gravity: a steep "
            f"camera, or the wrong surface"
        )
    return ground, well


def _facing_up(
    points: np.ndarray, up: np.ndarray, tolerance_deg: float, toward_sensor: bool
) -> np.ndarray:
    """(N,) bool: the points ((N, 3) [m]) whose surface faces up within tolerance_deg of up
    ((3,) unit). Each point's normal is the smallest principal direction of its 16 nearest
    neighbours (Open3D), turned to face the sensor at the origin (toward_sensor: a surface
    seen from below, a ceiling or a table's underside, then faces down) or else up."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(16))
    normals = np.asarray(cloud.normals)
    if toward_sensor:
        normals = np.where(np.einsum("ij,ij->i", normals, points)[:, None] > 0, -normals, normals)
    else:
        normals = np.where((normals @ up)[:, None] < 0, -normals, normals)
    return normals @ up >= np.cos(np.radians(tolerance_deg))


def _ground_through(
    points: np.ndarray,
    planes: list[Plane],
    near: np.ndarray,
    cfg: GroundConfig,
    *,
    up: np.ndarray,
    toward_sensor: bool = True,
) -> GroundChoice:
    """The plane through a point the user picked ((3,), capture frame [m]).

    The point comes from a click on the mesh, which is built from the highest point of each
    cell, so it sits above the surface by about the sensor's noise, and a far floor comes out
    of RANSAC as several slightly tilted slabs, so neither the point alone nor the slab nearest
    it is the ground. The cloud's points within 25 cm of it decide: among the found planes that
    hold at least 30 % of them (within 3 thresholds), the best supported is the ground, refitted
    on all its points, so a click on a patch of floor levels the capture on the whole floor.
    When a plane fitted to the local points holds most of them (a clear surface, not a noisy
    far floor), only found planes parallel to it (within 10 deg) count: a click on a floor
    beside a wall is not the wall. With none, the local plane is refitted on the cloud's points
    that lie on it.
    """
    total = len(points)
    local = points[np.linalg.norm(points - near, axis=1) <= 0.25]
    if len(local) < 10:
        raise CaptureError(
            f"no points within 25 cm of the picked point {near.round(3).tolist()}: pick a "
            f"point on the captured surface"
        )
    n_loc, d_loc, inliers = _ransac_plane(
        local, cfg.threshold, min(cfg.iterations, 300), np.random.default_rng(cfg.seed)
    )
    clear = len(inliers) >= 0.5 * len(local)
    on_it = [
        p
        for p in planes
        if np.mean(np.abs(local @ p.normal + p.offset) <= 3 * cfg.threshold) >= 0.3
        and (not clear or _angle(p.normal, n_loc) <= 10.0 or _angle(p.normal, -n_loc) <= 10.0)
    ]
    if on_it:
        best = max(on_it, key=lambda p: p.support)
        n, d = _refit_level(points, [(best.normal, best.offset)], cfg.threshold)
    else:
        if (d_loc < 0) if toward_sensor else (n_loc @ up < 0):
            n_loc, d_loc = -n_loc, -d_loc
        n, d = n_loc, float(d_loc)
        for _ in range(3):  # refit on the cloud's points on it; a few rounds settle it
            n, d = _refit(points, n, d, cfg.threshold)
        n, d = _refit_level(points, [(n, d)], cfg.threshold)
    on = np.abs(points @ n + d) <= cfg.threshold
    support = int(np.sum(on))
    return GroundChoice(
        normal=n,
        offset=float(d),
        support=support,
        fraction=support / total,
        area=_area(points[on], n),
        planes=tuple(planes),
        warnings=(),
    )


def _refit(
    points: np.ndarray, normal: np.ndarray, offset: float, threshold: float
) -> tuple[np.ndarray, float]:
    """Least-squares plane (unit normal, offset) of the points within threshold of the plane
    normal . p + offset = 0 (a RANSAC plane is only as good as its best 3-point sample); its
    normal keeps that plane's side."""
    near = points[np.abs(points @ normal + offset) <= threshold]
    if len(near) < 3:
        return normal, offset
    centre = near.mean(axis=0)
    n = np.linalg.svd(near - centre, full_matrices=False)[2][2]
    if n @ normal < 0:
        n = -n
    return n, float(-n @ centre)


def _refit_level(
    points: np.ndarray, level: list[tuple[np.ndarray, float]], threshold: float
) -> tuple[np.ndarray, float]:
    """(unit normal, offset of level[0]) of parallel planes fitted jointly by least squares to
    the points ((N, 3) [m]) near each plane (normal (3,), offset [m]) of level (the ground
    first): one normal, an offset per plane (each plane's points centred on their own centroid). "Near" starts at threshold
    [m] and settles on the ground's own scatter (2.5 rms, at most MAX_BAND): a rough or noisy
    ground (wood chips, a far floor) is fitted on its whole band, not on a 1.5 cm slab of it."""
    n, d = _refit(points, *level[0], threshold)
    offsets = [d]
    for normal, offset in level[1:]:  # each one's offset under the common normal
        on = points[np.abs(points @ normal + offset) <= threshold]
        offsets.append(float(-n @ on.mean(axis=0)) if len(on) else offset)
    band = threshold
    for _ in range(10):  # the inliers move with the planes and the band until it settles
        groups = [points[np.abs(points @ n + dk) <= band] for dk in offsets]
        if len(groups[0]) < 3:
            break
        stacked = np.concatenate([g - g.mean(axis=0) for g in groups if len(g) >= 3])
        m = np.linalg.svd(stacked, full_matrices=False)[2][2]
        n = m if m @ n >= 0 else -m
        offsets = [
            float(-n @ g.mean(axis=0)) if len(g) >= 3 else dk
            for g, dk in zip(groups, offsets, strict=True)
        ]
        rms = float(np.sqrt(np.mean((groups[0] @ n + offsets[0]) ** 2)))
        wider = min(max(threshold, 2.5 * rms), MAX_BAND)
        if abs(wider - band) < 1e-3:
            break
        band = wider
    return n, offsets[0]


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two unit vectors [deg]."""
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))
