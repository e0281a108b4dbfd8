"""Which surface of a capture is the ground: gravity first, not the largest plane.

A room capture's largest plane is often a wall, and a table capture's a background surface;
in a level-camera office or a room with people in it the floor may be a few per cent of the
points, behind walls and furniture. So the ground is searched for as a person would: gravity
points roughly along the camera's +y (a level camera's "up" is -y) unless a calibration, an
IMU or the user says otherwise; only surfaces that face up under that prior are searched,
however small a share of the cloud they are (each point's normal decides, so a floor of 3 %
of the points is found among walls of 60 %). Each plane found there is settled on its own
surface - the points near it that face as it does, not the foot of a wall or of a person
beside it, in a band that widens with range as depth noise does - and measured by the area
it covers, not by its count of points (a far floor is sparse). Up is the orientation of the
largest group of parallel surfaces near the prior under which the scene's walls, people and
furniture stand upright; the horizontal surfaces are those parallel to it, and the ground is
the lowest of them that is large enough, heights compared where the surfaces lie (the floor
under a desk, not the desk; never a wall, nor a far floor's tilted slab that passes below
the sensor).

All directions here are in the capture's frame (a camera's: x right, y down, z forward).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from ._errors import CaptureError

CAMERA_UP = (0.0, -1.0, 0.0)
"""A level camera's up in its optical frame (x right, y down, z forward)."""
Z_UP = (0.0, 0.0, 1.0)
"""Up in a world or robot frame (REP 103: z up)."""
MAX_BAND = 0.05
"""Widest band round a plane its fit takes points from [m]: a rough or noisy ground's
scatter, short of what a curb or a rug would add."""
STRIP = 0.1
"""A ground whose points spread less than this across (the standard deviation of its
narrower in-plane direction [m]; 0.1 is a strip 35 cm deep) has its tilt across set by the
other level surfaces as much as by itself; a wider one, less so, by (STRIP / its spread)^2 per
point: its own tilt is then known better than a desk top is parallel to it (two desks 1 cm
apart in height read as one plane tilted 1 deg, 4 cm at the camera)."""
REACH = 0.25
"""Farthest a point may lie from a plane [m] and still be in the rounds that settle it: its
band is at most MAX_BAND, and it moves by centimetres."""
MIN_PIECE = 0.05
"""Smallest connected part of another level surface that joins the ground's fit [m^2]."""
SETTLE_ROUNDS = 10
"""Most rounds of fitting a plane on its band and the band on the plane's scatter (3 to 5
settle it)."""


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
    prior_sigma_deg: float = 30.0
    """How far gravity is likely to be from the prior [deg]: a surface's area counts toward
    the up direction weighed by a Gaussian of this width in its angle from the prior (at 30
    deg 0.61, at 45 deg 0.32, at 60 deg 0.14)."""
    parallel_deg: float = 6.0
    """Planes within this angle of the chosen up are horizontal (parallel to the ground)."""
    min_area: float = 0.25
    """A horizontal plane needs this much area (occupied 5 cm cells) [m^2] to be the ground:
    50 cm x 50 cm, a few robot lengths; smaller patches below the floor are noise."""
    surface_deg: float = 35.0
    """A point counts toward a plane only where its own surface (its normal, from its 16
    nearest neighbours) is within this angle of the plane's: not the foot of a wall, a person
    or a desk leg, which lies within centimetres of the floor but faces sideways [deg]."""
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
    """Every candidate plane, in extraction order, as settled on its own surface (_settle;
    with the ground through a given point: as RANSAC found them)."""
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
    if len(normals) == 0:
        return np.array([0.0, 0.0, 1.0]), 0.0, np.zeros(0, dtype=np.int64)
    # Each hypothesis is first scored on an even sample of the points; only those the sample
    # cannot tell from the best (4 sigmas of the binomial sampling error of two counts'
    # difference) are scored on all of them, and the best of those, the first on a tie, is
    # the one every point would have chosen.
    which = np.arange(len(normals))
    if len(pts) >= 4 * SCORE_SAMPLE:
        sample = pts[:: len(pts) // SCORE_SAMPLE]
        rough = _inlier_counts(sample, normals, offsets, threshold)
        top = int(rough.max())
        sigma = np.sqrt(2.0 * max(top * (1.0 - top / len(sample)), 1.0))
        which = np.flatnonzero(rough >= top - 4.0 * sigma)
    counts = _inlier_counts(pts, normals[which], offsets[which], threshold)
    best = int(which[int(np.argmax(counts))])
    n, d = normals[best], float(offsets[best])
    return n, d, np.flatnonzero(np.abs(pts @ n + d) <= threshold)


SCORE_SAMPLE = 1000
"""Points a RANSAC hypothesis is first scored on [-] (_ransac_plane)."""


def _inlier_counts(
    pts: np.ndarray, normals: np.ndarray, offsets: np.ndarray, threshold: float
) -> np.ndarray:
    """(M,) how many of pts ((N, 3) [m]) lie within threshold [m] of each plane n . p + d = 0
    (normals (M, 3) unit, offsets (M,))."""
    counts = np.empty(len(normals), dtype=np.int64)
    for k0 in range(0, len(normals), 64):  # 64 planes x N distances at a time
        dist = np.abs(normals[k0 : k0 + 64] @ pts.T + offsets[k0 : k0 + 64, None])
        counts[k0 : k0 + 64] = np.sum(dist <= threshold, axis=1)
    return counts


def _area(points: np.ndarray, normal: np.ndarray, cell: float = 0.05) -> float:
    """Area [m^2] covered by points ((N, 3)) lying on a plane with this normal: occupied cells
    of a cell x cell grid in the plane."""
    uv = np.floor(points @ _in_plane(normal).T / cell).astype(np.int64)
    if len(uv) == 0:
        return 0.0
    uv -= uv.min(axis=0)
    return len(np.unique(uv[:, 0] * (int(uv[:, 1].max()) + 1) + uv[:, 1])) * cell * cell


def _narrow_spread(points: np.ndarray, normal: np.ndarray) -> float:
    """Standard deviation [m] of points ((N, 3)) on a plane with this normal ((3,) unit) along
    their narrower in-plane principal direction."""
    if len(points) < 3:
        return 0.0
    uv = points @ _in_plane(normal).T
    return float(np.sqrt(max(np.linalg.eigvalsh(np.cov(uv.T))[0], 1e-12)))


def _in_plane(normal: np.ndarray) -> np.ndarray:
    """(2, 3) two unit vectors spanning the plane with this normal ((3,) unit)."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return np.array([u, np.cross(normal, u)])


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
    2. Each is settled on its own surface (_settle): the points near it whose own normal
       agrees with it (not the foot of a wall or a person), in a band that grows with range as
       the sensor's noise does; its area is measured there, on all the points.
    3. The best group of mutually parallel surfaces gives the refined up (the floor and a
       desk agree on it; a sloping surface does not): by area, near the prior, and with the
       scene upright under it (_refined_up).
    4. The level surfaces (within parallel_deg of the refined up) at least min_area large are
       ground candidates; the lowest one, its height taken where it lies along the refined
       up, is the ground.
    5. The ground and the other level surfaces, piece by piece, are fitted jointly (_settle).
    near: a point ((3,), capture frame [m]) on the intended ground: then the plane through it
    is the ground whatever its orientation (the user's re-levelling click).
    """
    up = np.asarray(up, dtype=np.float64)
    up = up / np.linalg.norm(up)
    # Planes are searched in an even subsample (RANSAC's cost grows with the points; 30,000
    # still put dozens in every 5 cm cell of a surface); they are settled on all the points.
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
    normals = _normals(sub, up, toward_sensor)
    facing = normals @ up >= np.cos(np.radians(cfg.prior_tolerance_deg))
    planes = []
    if facing.sum() >= 50:
        planes = find_planes(sub[facing], up, cfg, toward_sensor, cone_deg=cfg.prior_tolerance_deg)
    candidates = [p for p in planes if p.angle_deg <= cfg.prior_tolerance_deg]
    if not candidates:
        planes = find_planes(sub, up, cfg, toward_sensor)
        if not planes:
            raise CaptureError("no plane found in the capture: nothing to take as the ground")
        best = min(planes, key=lambda p: p.angle_deg)
        warnings.append(
            f"no plane faces up within {cfg.prior_tolerance_deg:g} deg of the assumed gravity; "
            f"took the closest ({best.angle_deg:.0f} deg off); if that is wrong, give the up "
            f"direction (--up) or the camera pose, or click the ground in the page"
        )
        candidates = [best]

    cloud = _Cloud.of(points, sub, normals, candidates, toward_sensor=toward_sensor)
    fits = [_fit(cloud, p, up, cfg) for p in candidates]
    # A steep candidate (a sensor's ripples on a wall, 55 deg off) may settle onto the wall it
    # lies on: what left the cone is no candidate (unless the cone held none).
    fits = [f for f in fits if f.plane.angle_deg <= cfg.prior_tolerance_deg] or fits
    refined = _refined_up(fits, up, normals, cfg, warnings)
    ground, well = _lowest_level(
        fits, refined, cfg, total=len(points), toward_sensor=toward_sensor, warnings=warnings
    )
    # The level surfaces share one normal (a floor and the desks on it): fitted jointly, their
    # up is better known than from the ground alone, which may be a strip a few tens of
    # centimetres deep at the bottom of the view (2 deg there is 5 cm at the camera).
    # Each other surface counts piece by piece, each connected part at its own height: two
    # desks 2 cm apart in height are one level (level_gap), and as one plane they read tilted
    # 1 deg (4 cm at the camera).
    n = ground.plane.normal
    level: list[_Level] = [(n, ground.plane.offset, None)]
    claimed = ground.on.copy()  # two candidates may have settled on one surface
    for f in well:
        for r in _pieces(cloud, f) if f is not ground else []:
            own = r & f.on & ~claimed
            if _area(points[own], n) >= MIN_PIECE:  # its offset under the ground's normal
                level.append((n, float(-n @ points[own].mean(axis=0)), r & ~claimed))
                claimed |= r
    spread = _narrow_spread(points[ground.on], ground.plane.normal)
    others = 1.0 if spread <= STRIP else (STRIP / spread) ** 2
    n, offsets, _ = _settle(cloud, level, cfg, others=others)
    d = offsets[0]
    support = int(np.sum(np.abs(points @ n + d) <= cfg.threshold))
    return GroundChoice(
        normal=n,
        offset=d,
        support=support,
        fraction=support / len(points),
        area=ground.plane.area,
        planes=tuple(f.plane for f in fits),
        warnings=tuple(warnings),
    )


@dataclass(frozen=True, eq=False)
class _Cloud:
    """The points a plane is settled on, with what decides which of them are its surface."""

    points: np.ndarray
    """(N, 3) [m]."""
    normals: np.ndarray
    """(N, 3) unit normal of each point's surface (zero where not needed: far from every
    candidate plane)."""
    ranges: np.ndarray | None
    """(N,) distance from the sensor [m], or None when the origin is not the sensor (a world
    frame): then the noise is taken as the same everywhere."""

    @classmethod
    def of(
        cls,
        points: np.ndarray,
        sub: np.ndarray,
        normals: np.ndarray,
        planes: list[Plane],
        *,
        toward_sensor: bool,
    ) -> _Cloud:
        """points ((N, 3)) with each one's normal taken from its nearest point of sub ((M, 3),
        a subsample of them whose normals ((M, 3)) are known): only the points within MAX_BAND
        of one of the planes need one (estimating normals on all the points took a second on
        a 300,000-point capture, under load)."""
        from scipy.spatial import KDTree

        near = np.zeros(len(points), dtype=bool)
        for p in planes:
            near |= np.abs(points @ p.normal + p.offset) <= MAX_BAND
        full = np.zeros_like(points)
        if len(sub) == len(points):  # not subsampled: its own normals
            full[near] = normals[near]
        elif near.any():
            full[near] = normals[KDTree(sub).query(points[near], k=1, workers=-1)[1]]
        ranges = np.linalg.norm(points, axis=1) if toward_sensor else None
        return cls(points=points, normals=full, ranges=ranges)


@dataclass(frozen=True, eq=False)
class _Fit:
    """A candidate plane settled on its own surface (_settle) and measured there."""

    plane: Plane
    """The plane, its support and area counted on its surface's points."""
    centre: np.ndarray
    """(3,) centroid of its surface's points [m]: where its height is taken."""
    on: np.ndarray
    """(N,) bool: its surface's points in the cloud."""


def _fit(cloud: _Cloud, plane: Plane, up: np.ndarray, cfg: GroundConfig) -> _Fit:
    """A RANSAC plane settled on its own surface's points in the cloud, and measured there."""
    n, (d,), (on,) = _settle(cloud, [(plane.normal, plane.offset, None)], cfg)
    pts = cloud.points[on]
    return _Fit(
        plane=Plane(
            normal=n,
            offset=d,
            support=len(pts),
            area=_area(pts, n) if len(pts) else 0.0,
            angle_deg=_angle(n, up),
        ),
        centre=pts.mean(axis=0) if len(pts) else -d * n,
        on=on,
    )


def _pieces(cloud: _Cloud, f: _Fit) -> list[np.ndarray]:
    """(N,) bool regions, one per connected part (5 cm cells, 8-connected) of a settled
    surface at least MIN_PIECE large: the cloud's points near its plane whose cell is in that
    part. One piece, all its points near, when it is too wide for a grid of cells (a survey's
    ground)."""
    from scipy import ndimage

    pts, n = cloud.points, f.plane.normal
    near = np.abs(pts @ n + f.plane.offset) <= MAX_BAND
    cells = np.floor(pts[near] @ _in_plane(n).T / 0.05).astype(np.int64)
    own = cells[f.on[near]]
    if len(own) == 0:
        return []
    lo = own.min(axis=0)
    shape = own.max(axis=0) - lo + 1
    if np.prod(shape) > 4_000_000:  # wider than 100 m: no room's desks
        return [near]
    grid = np.zeros(shape, dtype=bool)
    grid[tuple((own - lo).T)] = True
    labels, count = cast("tuple[np.ndarray, int]", ndimage.label(grid, structure=np.ones((3, 3))))
    at = cells - lo
    inside = np.all((at >= 0) & (at < shape), axis=1)
    part = np.zeros(len(pts), dtype=np.int64)
    part[np.flatnonzero(near)[inside]] = labels[tuple(at[inside].T)]
    size = np.bincount(labels.ravel(), minlength=count + 1) * 0.05**2
    return [part == k for k in range(1, count + 1) if size[k] >= MIN_PIECE]


_Level = tuple[np.ndarray, float, "np.ndarray | None"]
"""A plane to settle: its normal ((3,) unit), offset [m], and the region ((N,) bool) its
points must lie in, or None: anywhere."""


def _settle(
    cloud: _Cloud, level: list[_Level], cfg: GroundConfig, others: float = 1.0
) -> tuple[np.ndarray, list[float], list[np.ndarray]]:
    """(unit normal, an offset per plane, each plane's inlier mask (N,)) of the parallel planes
    level (the ground first) fitted jointly: one normal, an offset per plane, by least squares
    weighted by the noise expected at each point's range, and the other planes' points by
    others beside the first's.

    A plane's points are those within its band whose own normal is within surface_deg of the
    plane's: the foot of a wall, of a person or of a desk's legs lies within centimetres of
    the floor, and on a small floor such points outnumbered the floor's own near the band's
    edge, tilting it (a strip 15 cm deep at a wall's foot: 0.4 deg, 2 cm at the camera; an
    office's floor behind desks and people: 5 cm). The band settles on the plane's own scatter
    as it grows with range (3 robust sigmas in bins of range, never less at a longer range;
    between threshold and MAX_BAND): a far, noisy floor is fitted on its whole band, a near
    one on its centimetre, and the near points, known better, weigh more."""
    # Only points within REACH of a plane can join it as it settles: the rest are left out
    # of the rounds (most of a room's points are walls and furniture).
    n = np.asarray(level[0][0], dtype=np.float64)
    offsets = [float(d) for _, d, _ in level]
    reach = np.zeros(len(cloud.points), dtype=bool)
    for _, d, r in level:
        reach |= (np.abs(cloud.points @ n + d) <= REACH) & (True if r is None else r)
    pts, normals = cloud.points[reach], cloud.normals[reach]
    ranges = None if cloud.ranges is None else cloud.ranges[reach]
    regions = [None if r is None else r[reach] for _, _, r in level]
    cos_s = np.cos(np.radians(cfg.surface_deg))
    bands = [np.full(len(pts), cfg.threshold) for _ in level]
    masks = [np.zeros(len(pts), dtype=bool) for _ in level]
    for _ in range(SETTLE_ROUNDS):
        agree = normals @ n >= cos_s
        heights = pts @ n
        masks = [
            agree & (np.abs(heights + dk) <= bk) & (True if rk is None else rk)
            for dk, bk, rk in zip(offsets, bands, regions, strict=True)
        ]
        if masks[0].sum() < 3:
            break
        weights = [
            (1.0 if k == 0 else others) / bk[mk] ** 2  # the band is 3 sigmas of the noise
            for k, (mk, bk) in enumerate(zip(masks, bands, strict=True))
        ]
        m, new = _orthogonal(pts, masks, weights, n=n, offsets=offsets)
        settled = (
            _angle(m, n) < 0.01
            and max(abs(a - b) for a, b in zip(new, offsets, strict=True)) < 5e-4
        )
        n, offsets = m, new
        bands = [
            _band(pts @ n + dk, mk, ranges, cfg) if mk.sum() >= 3 else bk
            for dk, mk, bk in zip(offsets, masks, bands, strict=True)
        ]
        if settled:
            break
    full = [np.zeros(len(cloud.points), dtype=bool) for _ in masks]
    for f, mk in zip(full, masks, strict=True):
        f[reach] = mk
    return n, offsets, full


def _orthogonal(
    pts: np.ndarray,
    masks: list[np.ndarray],
    weights: list[np.ndarray],
    *,
    n: np.ndarray,
    offsets: list[float],
) -> tuple[np.ndarray, list[float]]:
    """(unit normal, offsets) of parallel planes, each through the weighted centroid of its
    points (masks: (N,) bool; weights: one per masked point), the normal minimizing the
    weighted squared distances to them (each plane's points centred on their centroid). n,
    offsets: the planes so far (the normal's side; the offsets of planes with no points)."""
    stacked, centres = [], []
    for mk, w in zip(masks, weights, strict=True):
        if mk.sum() < 3:
            centres.append(None)
            continue
        c = (w[:, None] * pts[mk]).sum(axis=0) / w.sum()
        stacked.append(np.sqrt(w)[:, None] * (pts[mk] - c))
        centres.append(c)
    x = np.concatenate(stacked)
    m = np.linalg.eigh(x.T @ x)[1][:, 0]
    m = m if m @ n >= 0 else -m
    return m, [
        float(-m @ c) if c is not None else dk for c, dk in zip(centres, offsets, strict=True)
    ]


def _band(
    residuals: np.ndarray, on: np.ndarray, ranges: np.ndarray | None, cfg: GroundConfig
) -> np.ndarray:
    """(N,) half-width of a plane's band at each point [m]: 3 robust sigmas (1.48 median
    absolute residual) of the plane's points (on: (N,) bool; residuals (N,) [m]) at that
    range, in up to 6 bins of range that each hold 100 points or more, never less at a longer
    range (the noise grows with range), between cfg.threshold and MAX_BAND. ranges: (N,) [m],
    or None: one sigma for all."""
    res = residuals[on]
    bins = 0 if ranges is None else min(6, len(res) // 100)
    if bins <= 1 or ranges is None:
        sigma = np.full(len(residuals), _mad(res))
    else:
        r = ranges[on]
        order = np.argsort(r)
        parts = np.array_split(order, bins)
        centres = np.array([np.median(r[k]) for k in parts])
        sigmas = np.maximum.accumulate([_mad(res[k]) for k in parts])
        sigma = np.interp(ranges, centres, sigmas)
    return np.clip(3.0 * sigma, cfg.threshold, MAX_BAND)


def _mad(x: np.ndarray) -> float:
    """Robust sigma of x: 1.4826 median absolute deviation from its median. About the median,
    not the plane: points off the plane on one side (a baseboard, a row of a wall's foot)
    are no noise to widen the band for."""
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


def _refined_up(
    fits: list[_Fit],
    up: np.ndarray,
    normals: np.ndarray,
    cfg: GroundConfig,
    warnings: list[str],
) -> np.ndarray:
    """(3,) unit up refined by the best group of mutually parallel candidate surfaces (the
    floor and a desk agree on it; a sloping surface does not). A group scores its area, each
    surface's weighed by how likely gravity is that far from the prior (a Gaussian of
    prior_sigma_deg), times the share of the scene that stands level or upright under it
    (_upright: walls, people, the sides of desks and shelves), so that neither a tilted prior
    nor a sensor's artefacts decide alone: the disparity terraces of a far wall seen from
    below face up 45-60 deg off, larger than the floor, but under them almost nothing stands
    upright (7 % of the points, against 53 % under the floor). Only the surfaces large
    enough to be a ground count when there are any; a warning when another orientation
    scores nearly as well. normals: (M, 3) unit normals of the scene's points."""
    big = [f for f in fits if _is_surface(f, cfg)] or fits

    def group(f: _Fit) -> list[_Fit]:
        return [g for g in big if _angle(f.plane.normal, g.plane.normal) <= cfg.parallel_deg]

    def score(f: _Fit) -> float:
        members = group(f)
        mean = np.sum([g.plane.area * g.plane.normal for g in members], axis=0)
        prior = sum(
            g.plane.area * np.exp(-0.5 * (g.plane.angle_deg / cfg.prior_sigma_deg) ** 2)
            for g in members
        )
        return prior * _upright(normals, mean / np.linalg.norm(mean))

    scores = {id(f): score(f) for f in big}
    best = max(big, key=lambda f: scores[id(f)])
    refined = np.sum([g.plane.area * g.plane.normal for g in group(best)], axis=0)
    refined /= np.linalg.norm(refined)
    rivals = [f for f in big if _angle(f.plane.normal, refined) > cfg.parallel_deg]
    if rivals and max(scores[id(r)] for r in rivals) >= 0.5 * scores[id(best)]:
        r = max(rivals, key=lambda r: scores[id(r)])
        warnings.append(
            f"two surface orientations are nearly as well supported: the ground chosen is "
            f"{_angle(refined, up):.0f} deg from the assumed gravity, another "
            f"{r.plane.angle_deg:.0f} deg; check the result, or give --up or the camera pose"
        )
    return refined


def _upright(normals: np.ndarray, up: np.ndarray, tolerance_deg: float = 10.0) -> float:
    """Share of the normals ((M, 3) unit) level or upright under up ((3,) unit), within
    tolerance_deg: how much of a built scene agrees that up is gravity."""
    c = np.abs(normals @ up)
    t = np.radians(tolerance_deg)
    return float(np.mean((c >= np.cos(t)) | (c <= np.sin(t))))


def _is_surface(f: _Fit, cfg: GroundConfig) -> bool:
    """Whether a settled plane is a surface the robot could stand on: min_area large, counted
    in cells its own points occupy (not a count of points: a far floor is sparse, and a
    floor's share of a cloud of walls and desks may be one per cent)."""
    return f.plane.area >= cfg.min_area


def _lowest_level(
    fits: list[_Fit],
    refined: np.ndarray,
    cfg: GroundConfig,
    *,
    total: int,
    toward_sensor: bool,
    warnings: list[str],
) -> tuple[_Fit, list[_Fit]]:
    """(the ground, every large level surface): among the surfaces level to refined ((3,)
    unit; not a fragment of a larger one at its height), those that are surfaces (_is_surface)
    compete, and the lowest of them is the ground. Heights are taken along refined at each
    surface's own centroid, not at the sensor: two planes a few degrees apart (a far floor's
    slab and the floor) differ at the sensor by tens of centimetres where they meet on the
    floor. total: the points, for the warnings' shares."""

    def height(f: _Fit) -> float:  # below the sensor (above the origin in a world frame)
        return float(-refined @ f.centre)

    horizontal: list[_Fit] = []
    for f in sorted(fits, key=lambda f: -f.plane.area):
        level = _angle(f.plane.normal, refined) <= cfg.parallel_deg
        if level and all(abs(height(f) - height(g)) >= cfg.level_gap for g in horizontal):
            horizontal.append(f)
    if not horizontal:  # none level to the refined up: the candidates' best
        horizontal = [max(fits, key=lambda f: f.plane.area)]
    well = [f for f in horizontal if _is_surface(f, cfg)]
    if not well:
        well = [max(horizontal, key=lambda f: f.plane.area)]
        warnings.append(
            f"the ground seen is small ({well[0].plane.area:.2f} m^2, "
            f"{100 * well[0].plane.support / total:.0f} % of the points)"
        )
    ground = max(well, key=height)  # the lowest: farthest below the sensor
    if toward_sensor and ground.plane.offset <= 0:
        warnings.append("the sensor is not above the ground chosen: check the up direction")
    higher = [f for f in well if f is not ground and f.plane.area > ground.plane.area]
    if higher:
        h = max(higher, key=lambda f: f.plane.area)
        warnings.append(
            f"the ground is the lowest level surface ({ground.plane.area:.2f} m^2), "
            f"{height(ground) - height(h):.2f} m below a larger one ({h.plane.area:.2f} m^2); "
            f"if the robot stands on that one, click it in the page or give the camera pose"
        )
    if ground.plane.angle_deg > 50.0:
        warnings.append(
            f"the ground is tilted {ground.plane.angle_deg:.0f} deg from the assumed gravity: a "
            f"steep camera, or the wrong surface"
        )
    return ground, well


def _normals(points: np.ndarray, up: np.ndarray, toward_sensor: bool) -> np.ndarray:
    """(N, 3) unit normal of each point's surface ((N, 3) [m]): the smallest principal
    direction of its 16 nearest neighbours (Open3D), turned to face the sensor at the origin
    (toward_sensor: a surface seen from below, a ceiling or a table's underside, then faces
    down) or else up ((3,) unit)."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(16))
    normals = np.asarray(cloud.normals)
    if toward_sensor:
        return np.where(np.einsum("ij,ij->i", normals, points)[:, None] > 0, -normals, normals)
    return np.where((normals @ up)[:, None] < 0, -normals, normals)


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
    for _ in range(SETTLE_ROUNDS):  # the inliers move with the planes and the band
        groups = [points[np.abs(points @ n + dk) <= band] for dk in offsets]
        if len(groups[0]) < 3:
            break
        stacked = np.concatenate([g - g.mean(axis=0) for g in groups if len(g) >= 3])
        m = np.linalg.svd(stacked, full_matrices=False)[2][2]
        m = m if m @ n >= 0 else -m
        new = [
            float(-m @ g.mean(axis=0)) if len(g) >= 3 else dk
            for g, dk in zip(groups, offsets, strict=True)
        ]
        # Settled when the band and the planes are: a band that stays put while the planes
        # still move (a noisy floor's 1.5 cm band from a RANSAC plane 2 deg off) left the
        # plane where that band cut it, 1.2 cm from where it settles.
        moved = (
            _angle(m, n) >= 0.01
            or max(abs(a - b) for a, b in zip(new, offsets, strict=True)) >= 5e-4
        )
        n, offsets = m, new
        rms = float(np.sqrt(np.mean((groups[0] @ n + offsets[0]) ** 2)))
        wider = min(max(threshold, 2.5 * rms), MAX_BAND)
        if abs(wider - band) < 1e-3 and not moved:
            break
        band = wider
    return n, offsets[0]


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two unit vectors [deg]."""
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))
