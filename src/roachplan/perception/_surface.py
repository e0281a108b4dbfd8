"""A capture's surface at the density the sensor sampled it (Tong 2018, section 3.2).

One idea for three kinds of input: neighbouring samples are joined into triangles unless a
depth discontinuity separates them; small holes inside an observed surface are filled from
their rim; what the sensor never saw (the shadow behind an object, the floor beyond its range)
stays open: unknown, and so not walkable.

- An organized capture (a depth image, an organized cloud): neighbouring pixels are joined, as
  PCL's organized meshing (OrganizedFastMesh) does, after averaging blocks of pixels about a
  voxel across at the median range (block_image: a 1920 x 1080 view 2-4 m away in blocks of
  3 x 3, a 640 x 480 one not at all; the pipeline finds the ground on a pixel of each). A
  floor seen from a low camera is sampled more sparsely than any fixed grid far away (7 cm
  between rows at 4 m from 0.4 m up); its triangles span that, where a 1 cm height grid was
  mostly holes.
- An unorganized cloud in a camera frame: the Delaunay triangulation of the samples'
  directions from the sensor (x/z, y/z), the image the sensor would have made.
- A cloud in a world frame (a lidar's, a map's): the Delaunay triangulation in x, y with edges
  at most a multiple of the local sample spacing, as greedy projection triangulation (Marton,
  Rusu and Beetz 2009, the method the report's PCL meshing uses) does.

Which edges are discontinuities. An edge nearly along the sensor's ray (within GRAZING_DEG)
either crosses a depth jump (an object's edge and the floor far behind it) or lies on a
surface seen at a grazing angle (the far floor). It is kept when it is nearly level and no
longer than a few times the spacing a level surface at that range and depth below the sensor
has; every other edge is kept.

Each vertex carries its height noise [m]: the sensor's noise along its ray at that range,
fitted to the local spread of the capture's own samples (sigma(d) = a + b d^2, the form of
structured-light, stereo and time-of-flight depth noise alike; an organized capture's pixels,
not its blocks' means), times the ray's vertical part.
The planner's checks take it into account (planning/_validity.py), so a floor that is flat
within the noise is flat, and a step higher than the noise is still a step.

Frames: camera = x right, y down, z forward, the sensor at the origin; world = z up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
from scipy import ndimage

GRAZING_DEG = 15.0
"""An edge within this angle of the sensor's ray is grazing [deg] (PCL's OrganizedFastMesh
uses 12.5)."""
LEVEL_RISE = (0.02, 0.15)
"""A grazing edge is level when it rises at most a + b x its horizontal length [m, -]: a floor
within the noise, not an object's top joined to the floor behind it."""
GAP_FACTOR = 3.0
"""A grazing, level edge may be this many times the spacing expected on a level surface at its
range and depth below the sensor (quantised depth makes bands of samples; rows go missing)."""
MIN_PIECE = 8
"""Connected pieces of fewer triangles are dropped: flying pixels, specks [-]."""
NOISE_FALLBACK = (0.001, 0.0015)
"""sigma(d) = a + b d^2 [m, 1/m] when a capture has too few samples to fit its own: a
structured-light camera's (Khoshelham and Oude Elberink 2012: about 1.4 mm / m^2)."""


@dataclass(frozen=True, eq=False)
class Surface:
    """A triangulated capture, world frame."""

    vertices: np.ndarray
    """(V, 3) float64, world frame [m]."""
    faces: np.ndarray
    """(F, 3) int64, each facet facing the sensor (a world-frame cloud's: up)."""
    height_noise: np.ndarray
    """(V,) float64: standard deviation of each vertex's height [m]."""
    filled: np.ndarray
    """(V,) bool: the vertex was not measured but filled in from a hole's rim."""
    filled_faces: np.ndarray
    """(F,) bool: the triangle fills a hole (it has a filled vertex, or it spans a hole
    between measured samples)."""
    noise_model: tuple[float, float]
    """(a [m], b [1/m]): the sensor's noise along its ray at range d is a + b d^2."""
    observed_area: float
    """Area of the triangles between measured samples [m^2]."""
    filled_area: float
    """Area of the triangles that fill holes [m^2]."""


# -- organized captures -----------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Blocks:
    """An organized capture averaged in blocks of stride x stride pixels (block_image)."""

    points: np.ndarray
    """(h, w, 3) each block's mean, camera frame [m], the sensor at the origin; NaN where a
    block has too few pixels: what is meshed."""
    samples: np.ndarray
    """(h, w, 3) each block's pixel of median range, as points: what the ground is found on.
    A sample the sensor took keeps its scatter and quantisation; a block's mean blends a far
    floor's disparity steps, and the normals of its nearest neighbours then turned away from
    the floor (on a Kinect v1's strip of far floor, 1.7 % of the pixels, the ground's surface
    held a seventh of the points it holds on the pixels, and was 2.4 cm off)."""
    count: np.ndarray
    """(h, w) int: pixels each block averages (0: none)."""
    stride: int
    """Pixels per block side [-]."""
    pitch: float
    """Angle between neighbouring blocks [rad]."""
    rays: np.ndarray | None
    """(h, w, 3) directions (x/z, y/z, 1) of the block centres, from a pinhole fitted to the
    pixels; None with too few pixels."""

    @property
    def ok(self) -> np.ndarray:
        """(h, w) bool: the blocks that have a point."""
        return self.count > 0


def block_image(points: np.ndarray, valid: np.ndarray, voxel: float) -> Blocks:
    """An organized capture (points (H, W, 3) camera frame [m], the sensor at the origin;
    valid (H, W) bool: measured and kept) averaged in blocks of pixels about voxel [m] across
    at the median range: every stage after it (ground, mesh) works at that resolution, which
    is all the voxel grid and the planner's height field keep. A 1920 x 1080 view of a floor
    2-4 m away has pixels 2-4 mm apart; a 640 x 480 view 3 m away, 8 mm: the first is
    averaged in blocks of 3 x 3, the second not at all. The pixels' spacing is taken from the
    pinhole fitted to their directions, not from neighbouring points (on a far floor a
    high-resolution sensor's depth noise exceeds the spacing, which then read twice what it
    is)."""
    points = np.where(valid[..., None], points, np.nan)
    pinhole = _fit_pinhole(points, valid)
    # The pinhole's x/z per column; for directions that are no pinhole's (off its fit by more
    # than half a column), what neighbouring points measure.
    if pinhole is not None and pinhole[2] <= 0.5 * abs(pinhole[0][0]):
        pitch = abs(float(pinhole[0][0]))
    else:
        pitch = _angular_pitch(points, valid)
    ranges = np.linalg.norm(points[valid], axis=1)
    median_range = float(np.median(ranges)) if len(ranges) else 1.0
    stride = _nearest_stride(voxel / max(pitch * median_range, 1e-9))
    grid, count, samples = _block_average(points, stride)
    rays = None
    if pinhole is not None:
        au, av, _ = pinhole
        centre = (stride - 1) / 2
        cu = np.polyval(au, np.arange(count.shape[1]) * stride + centre)
        cv = np.polyval(av, np.arange(count.shape[0]) * stride + centre)
        rays = np.stack(np.broadcast_arrays(cu[None, :], cv[:, None], np.ones(count.shape)), -1)
    return Blocks(
        points=grid, samples=samples, count=count, stride=stride, pitch=pitch * stride, rays=rays
    )


def _nearest_stride(pixels: float) -> int:
    """The whole number of pixels (1 to 16) nearest, by ratio, to a block pixels across (the
    voxel over a pixel's footprint): a block too fine and one too coarse by the same factor
    are as far off (between 1 and 2 pixels the choice turns at 1.41, not 1.5)."""
    low = int(np.clip(math.floor(pixels), 1, 16))
    high = min(low + 1, 16)
    return high if pixels * pixels > low * high else low


def organized_surface(
    blocks: Blocks,
    valid: np.ndarray,
    world_from_camera: np.ndarray,
    max_fill: float,
    noise_model: tuple[float, float],
) -> Surface:
    """The surface of an organized capture averaged in blocks (block_image): valid ((h, w)
    bool: the blocks kept), world_from_camera ((4, 4)). Neighbouring blocks are joined;
    holes of at most max_fill [m] with a flat rim are filled from it. noise_model: the
    sensor's (range_noise_model of its own pixels, not of the blocks: a block's mean is no
    better known than the sensor's noise where that noise is correlated between neighbouring
    pixels, as structured light's and stereo's is)."""
    grid = np.where(valid[..., None], blocks.points, np.nan)
    ok = valid.copy()
    filled = np.zeros_like(ok)
    if blocks.rays is not None:
        grid, ok, filled = _fill_grid_holes(grid, ok, blocks.rays, world_from_camera, max_fill)
    faces = _grid_faces(grid, ok, world_from_camera, blocks.pitch)
    index = np.full(ok.shape, -1, dtype=np.int64)
    index[ok] = np.arange(int(ok.sum()))
    faces = index.ravel()[faces]
    return _finish(grid[ok], faces, filled[ok], world_from_camera, noise_model=noise_model)


def _angular_pitch(points: np.ndarray, valid: np.ndarray) -> float:
    """The angle between neighbouring pixels [rad] of an organized cloud that is no pinhole's:
    the median of |p(i, j+1) - p(i, j)| / range over side-by-side valid pixels at nearly the
    same range (a surface facing the sensor)."""
    rows = slice(None, None, max(1, points.shape[0] // 120))  # 120 rows are plenty
    a, b = points[rows, :-1], points[rows, 1:]
    both = valid[rows, :-1] & valid[rows, 1:]
    ra, rb = np.linalg.norm(a[both], axis=1), np.linalg.norm(b[both], axis=1)
    same = np.abs(ra - rb) <= 0.01 * ra
    if same.sum() < 10:
        return 1.0 / 525.0  # a 640 x 480 Kinect-class camera's
    step = np.linalg.norm(a[both][same] - b[both][same], axis=1) / ra[same]
    return float(np.median(step))


def _block_average(points: np.ndarray, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((h, w, 3) block means [m], (h, w) pixels averaged, (h, w, 3) each block's pixel of
    median range [m]) of points ((H, W, 3), NaN = none) in blocks of stride x stride pixels.
    Only the pixels within 3 % (+1 cm) of a block's median range are averaged, so a block on
    an object's edge does not mix it with the floor behind; a block with fewer than a quarter
    of its pixels is empty (NaN in both)."""
    if stride == 1:
        ok = np.all(np.isfinite(points), axis=-1)
        return points.copy(), ok.astype(np.int64), points.copy()
    height, width = points.shape[:2]
    h, w = -(-height // stride), -(-width // stride)

    def blocks(image: np.ndarray, fill: float) -> np.ndarray:
        """(h, w, stride * stride) the pixels of each block of an (H, W) image."""
        pad = np.full((h * stride, w * stride), fill)
        pad[:height, :width] = image
        return pad.reshape(h, stride, w, stride).transpose(0, 2, 1, 3).reshape(h, w, -1)

    # One coordinate at a time: an image's (H, W) planes, not its (H, W, 3) rows of three.
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    r = blocks(np.sqrt(x * x + y * y + z * z), np.nan)
    # The pixel of median range of each block (NaN last when sorted; the lower one when even).
    order = np.argsort(r, axis=-1)
    valid = np.isfinite(r).sum(axis=-1)
    middle = np.take_along_axis(order, np.maximum(valid - 1, 0)[..., None] // 2, axis=-1)
    median = np.take_along_axis(r, middle, axis=-1)[..., 0]
    keep = np.abs(r - median[..., None]) <= 0.03 * median[..., None] + 0.01
    count = keep.sum(axis=-1)
    mean, sample = np.empty((h, w, 3)), np.empty((h, w, 3))
    for c, image in enumerate((x, y, z)):
        mean[..., c] = np.where(keep, blocks(image, 0.0), 0.0).sum(axis=-1)
        sample[..., c] = np.take_along_axis(blocks(image, np.nan), middle, axis=-1)[..., 0]
    mean /= np.maximum(count, 1)[..., None]
    enough = count >= max(1, stride * stride // 4)
    mean[~enough] = np.nan
    sample[~enough] = np.nan
    return mean, np.where(enough, count, 0), sample


def _fit_pinhole(
    points: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(x/z as a line in the column (2,), y/z as a line in the row (2,), the fit's larger rms
    residual) of a pinhole fitted to the valid pixels of points ((H, W, 3)); None with too few
    pixels. A residual of more than half a column's step: no pinhole's directions (an organized
    lidar's scan)."""
    rows, cols = np.nonzero(valid)
    if len(rows) < 100:
        return None
    pick = slice(None, None, max(1, len(rows) // 20000))
    rows, cols = rows[pick], cols[pick]
    p = points[rows, cols]
    u, v = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
    au, av = np.polyfit(cols, u, 1), np.polyfit(rows, v, 1)
    off = max(
        float(np.sqrt(np.mean((u - np.polyval(au, cols)) ** 2))),
        float(np.sqrt(np.mean((v - np.polyval(av, rows)) ** 2))),
    )
    return au, av, off


def _fill_grid_holes(
    grid: np.ndarray,
    ok: np.ndarray,
    rays: np.ndarray,
    world_from_camera: np.ndarray,
    max_fill: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Holes of the block grid ((h, w) ok False, not touching the border) whose rim (the valid
    blocks round them) is at most max_fill [m] across and flat (a plane within the noise),
    filled with that plane along each block's ray ((h, w, 3)). A shadow behind an object has
    the object's edge and the floor far behind on its rim: not flat, left open."""
    grid, ok = grid.copy(), ok.copy()
    filled = np.zeros_like(ok)
    labels, n = cast("tuple[np.ndarray, int]", ndimage.label(~ok))
    if n == 0:
        return grid, ok, filled
    h, w = ok.shape
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    rot, shift = world_from_camera[:3, :3], world_from_camera[:3, 3]
    for k, window in enumerate(ndimage.find_objects(labels), start=1):
        if window is None or k in border:
            continue
        r0, r1 = max(window[0].start - 1, 0), min(window[0].stop + 1, h)
        c0, c1 = max(window[1].start - 1, 0), min(window[1].stop + 1, w)
        hole = labels[r0:r1, c0:c1] == k
        rim = ndimage.binary_dilation(hole, structure=np.ones((3, 3))) & ok[r0:r1, c0:c1]
        pts = grid[r0:r1, c0:c1][rim]
        if len(pts) < 4:
            continue
        world = pts @ rot.T + shift
        if np.linalg.norm(np.ptp(world, axis=0)) > max_fill:
            continue
        centre = pts.mean(axis=0)
        normal = np.linalg.svd(pts - centre, full_matrices=False)[2][2]
        rms = float(np.sqrt(np.mean(((pts - centre) @ normal) ** 2)))
        if rms > 0.005 + 0.003 * float(np.linalg.norm(centre)):
            continue
        d = rays[r0:r1, c0:c1][hole]
        t = (centre @ normal) / (d @ normal)
        if not np.all(np.isfinite(t) & (t > 0)):
            continue
        sub_grid = grid[r0:r1, c0:c1]
        sub_grid[hole] = d * t[:, None]
        ok[r0:r1, c0:c1] |= hole
        filled[r0:r1, c0:c1] |= hole
    return grid, ok, filled


def _grid_faces(
    grid: np.ndarray, ok: np.ndarray, world_from_camera: np.ndarray, pitch: float
) -> np.ndarray:
    """(F, 3) flat indices into the (h, w) grid of the triangles joining neighbouring blocks
    that no discontinuity separates: per 2 x 2 quad, the diagonal that keeps more triangles,
    then the shorter one; a quad with one corner missing keeps the triangle of the other three."""
    h, w = ok.shape
    idx = np.arange(h * w).reshape(h, w)

    def joined(p: np.ndarray, q: np.ndarray, okp: np.ndarray, okq: np.ndarray) -> np.ndarray:
        both = okp & okq
        out = np.zeros(both.shape, dtype=bool)
        out[both] = _kept_edges(p[both], q[both], world_from_camera, pitch)
        return out

    # Each edge once: the quads' top and bottom sides are the same horizontal edges, one row
    # apart, and so for the vertical ones.
    across = joined(grid[:, :-1], grid[:, 1:], ok[:, :-1], ok[:, 1:])  # (h, w - 1)
    down = joined(grid[:-1], grid[1:], ok[:-1], ok[1:])  # (h - 1, w)
    diag_ad = joined(grid[:-1, :-1], grid[1:, 1:], ok[:-1, :-1], ok[1:, 1:])
    diag_bc = joined(grid[:-1, 1:], grid[1:, :-1], ok[:-1, 1:], ok[1:, :-1])
    ab, cd, ac, bd = across[:-1], across[1:], down[:, :-1], down[:, 1:]
    t_abd, t_adc = ab & bd & diag_ad, diag_ad & cd & ac
    t_abc, t_bdc = ab & diag_bc & ac, bd & cd & diag_bc
    n1 = t_abd.astype(np.int8) + t_adc
    n2 = t_abc.astype(np.int8) + t_bdc
    with np.errstate(invalid="ignore"):
        len_ad = np.linalg.norm(grid[:-1, :-1] - grid[1:, 1:], axis=-1)
        len_bc = np.linalg.norm(grid[:-1, 1:] - grid[1:, :-1], axis=-1)
        first = (n1 > n2) | ((n1 == n2) & ~(len_bc < len_ad))
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    faces = [
        np.stack([a, b, d], -1)[first & t_abd],
        np.stack([a, d, c], -1)[first & t_adc],
        np.stack([a, b, c], -1)[~first & t_abc],
        np.stack([b, d, c], -1)[~first & t_bdc],
    ]
    return np.concatenate(faces).astype(np.int64)


def _kept_edges(
    a: np.ndarray, b: np.ndarray, world_from_camera: np.ndarray, pitch: np.ndarray | float
) -> np.ndarray:
    """(E,) bool: the edges a-b ((E, 3) camera frame [m], the sensor at the origin) that no
    depth discontinuity cuts (see the module docstring); pitch: the angle between neighbouring
    samples [rad] ((E,) or one)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        e = b - a
        length = np.sqrt(np.einsum("ij,ij->i", e, e))
        ra, rb = np.sqrt(np.einsum("ij,ij->i", a, a)), np.sqrt(np.einsum("ij,ij->i", b, b))
        mid = a + b
        along = np.abs(np.einsum("ij,ij->i", e, mid)) / np.sqrt(np.einsum("ij,ij->i", mid, mid))
        grazing = along > math.cos(math.radians(GRAZING_DEG)) * length
        up, height = world_from_camera[2, :3], world_from_camera[2, 3]
        za, zb = a @ up + height, b @ up + height  # world heights
        rise = np.abs(za - zb)
        run = np.sqrt(np.maximum(length**2 - rise**2, 0.0))
        level = rise <= LEVEL_RISE[0] + LEVEL_RISE[1] * run
        near = np.minimum(ra, rb)
        depth_below = np.maximum(height - np.where(ra <= rb, za, zb), 0.05)
        gap = GAP_FACTOR * np.asarray(pitch) * near**2 / depth_below + 0.02
        return np.isfinite(length) & (~grazing | (level & (length <= gap)))


# -- unorganized clouds -----------------------------------------------------------------------


def projected_surface(
    points: np.ndarray, world_from_camera: np.ndarray, max_fill: float
) -> Surface:
    """The surface of an unorganized cloud in a camera frame (points (N, 3) [m], the sensor
    at the origin, z > 0): the Delaunay triangulation of (x/z, y/z), its edges cut at depth
    discontinuities as an organized capture's are; small holes (cut triangles in groups at
    most max_fill [m] across, on a flat rim) are put back."""
    from scipy.spatial import KDTree

    pts = points[points[:, 2] > 1e-6]
    uv = pts[:, :2] / pts[:, 2:3]
    pitch = KDTree(uv).query(uv, k=2, workers=-1)[0][:, 1] if len(pts) >= 3 else np.zeros(len(pts))

    def kept(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return _kept_edges(pts[a], pts[b], world_from_camera, np.maximum(pitch[a], pitch[b]))

    world = pts @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
    return _delaunay_surface(
        uv, pts, world=world, kept=kept, max_fill=max_fill, world_from_camera=world_from_camera
    )


def scattered_surface(points: np.ndarray, max_fill: float, mu: float = 2.5) -> Surface:
    """The surface of a cloud in a world frame (points (N, 3) [m], z up): the Delaunay
    triangulation in x, y keeping the triangles whose edges are at most mu times the sample
    spacing at their ends (the distance to a point's third nearest neighbour in x, y), as
    greedy projection triangulation does; small holes (dropped triangles in groups at most
    max_fill [m] across, not on the outer edge) are put back."""
    from scipy.spatial import KDTree

    xy = points[:, :2]
    spacing = (
        KDTree(xy).query(xy, k=4, workers=-1)[0][:, 3] if len(points) >= 4 else np.zeros(len(xy))
    )

    def kept(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        length = np.linalg.norm(points[a] - points[b], axis=1)
        return length <= mu * np.minimum(spacing[a], spacing[b])

    return _delaunay_surface(
        xy, points, world=points, kept=kept, max_fill=max_fill, world_from_camera=None
    )


def _delaunay_surface(
    flat: np.ndarray,
    points: np.ndarray,
    *,
    world: np.ndarray,
    kept,
    max_fill: float,
    world_from_camera: np.ndarray | None,
) -> Surface:
    """The Surface of points ((N, 3): camera frame with world_from_camera, else world) from
    the Delaunay triangulation of flat ((N, 2): their image or their x, y): the triangles whose
    every edge kept(a, b) ((E,) vertex indices each -> (E,) bool) keeps, and the cut ones in
    small holes (_small_holes, world (N, 3) [m]) put back as filled."""
    from scipy.spatial import Delaunay

    if len(points) < 4:
        empty = np.zeros((0, 3), dtype=np.int64)
        return _finish(points, empty, np.zeros(len(points), dtype=bool), world_from_camera)
    tri = Delaunay(flat)
    faces = tri.simplices.astype(np.int64)
    ok = np.ones(len(faces), dtype=bool)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        ok &= kept(faces[:, i], faces[:, j])
    back = _small_holes(tri, ~ok, world, max_fill)
    keep = ok | back
    return _finish(
        points,
        faces[keep],
        np.zeros(len(points), dtype=bool),
        world_from_camera,
        filled_faces=back[keep],
    )


def _small_holes(tri, cut: np.ndarray, world: np.ndarray, max_fill: float) -> np.ndarray:
    """(F,) bool: the cut triangles of a Delaunay triangulation (cut (F,) bool) that lie in
    groups (joined across shared edges) at most max_fill [m] across in world ((N, 3)), not on
    the triangulation's outer edge, and whose corners are flat within 2 cm: holes to put back."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    nb = tri.neighbors
    f = np.flatnonzero(cut)
    back = np.zeros(len(cut), dtype=bool)
    if len(f) == 0:
        return back
    rows, cols = [], []
    for k in range(3):
        other = nb[f, k]
        both = (other >= 0) & cut[np.maximum(other, 0)]
        rows.append(f[both])
        cols.append(other[both])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(cut), len(cut)))
    _, label = connected_components(graph, directed=False)
    outer = np.zeros(len(cut), dtype=bool)
    outer[f] = (nb[f] < 0).any(axis=1)
    groups = label[f]
    order = np.argsort(groups, kind="stable")
    f_sorted, g_sorted = f[order], groups[order]
    starts = np.flatnonzero(np.r_[True, g_sorted[1:] != g_sorted[:-1]])
    for s, e in zip(starts, np.r_[starts[1:], len(f_sorted)], strict=True):
        members = f_sorted[s:e]
        if outer[members].any():
            continue
        corners = world[np.unique(tri.simplices[members])]
        if np.linalg.norm(np.ptp(corners, axis=0)) > max_fill:
            continue
        centre = corners.mean(axis=0)
        if len(corners) >= 3:
            normal = np.linalg.svd(corners - centre, full_matrices=False)[2][2]
            if np.max(np.abs((corners - centre) @ normal)) > 0.02:
                continue
        back[members] = True
    return back


# -- common -----------------------------------------------------------------------------------


def _finish(
    points: np.ndarray,
    faces: np.ndarray,
    filled: np.ndarray,
    world_from_camera: np.ndarray | None,
    filled_faces: np.ndarray | None = None,
    *,
    noise_model: tuple[float, float] | None = None,
) -> Surface:
    """The Surface of vertices points ((V, 3), camera frame when world_from_camera ((4, 4)) is
    given, else world) and faces ((F, 3) into them): specks and unused vertices dropped, each
    facet turned to face the sensor (a world-frame cloud's: up), noise and areas computed.
    filled: (V,) bool vertices filled in from a rim; filled_faces: (F,) bool triangles put back
    into a hole (default: those with a filled vertex). A vertex is filled when it was filled in
    or only filled triangles use it. noise_model: the sensor's (a, b) (range_noise_model);
    None: fitted to points."""
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if filled_faces is None:
        filled_faces = np.asarray(filled[faces].any(axis=1))
    keep = _not_specks(faces, len(points))
    faces, filled_faces = faces[keep], np.asarray(filled_faces, dtype=bool)[keep]
    used = np.zeros(len(points), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    faces = remap[faces]
    points, filled = points[used], filled[used]
    camera = world_from_camera is not None
    model = range_noise_model(points, camera=camera) if noise_model is None else noise_model
    points, averaged = denoise(points, model, camera)
    if camera:
        world = points @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
    else:
        world = points
    tri = world[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if world_from_camera is not None:
        away = np.einsum("ij,ij->i", tri.mean(axis=1) - world_from_camera[:3, 3], normal) > 0
    else:
        away = normal[:, 2] < 0
    faces[away] = faces[away][:, ::-1]
    area = 0.5 * np.linalg.norm(normal, axis=1)
    measured_use = np.zeros(len(points), dtype=bool)
    measured_use[faces[~filled_faces].ravel()] = True
    filled = filled | ~measured_use
    if camera:
        ranges = np.linalg.norm(points, axis=1)
        vertical = np.abs(points @ world_from_camera[2, :3]) / np.maximum(ranges, 1e-9)
        noise = (model[0] + model[1] * ranges**2) * vertical
    else:
        noise = np.full(len(world), model[0])
    noise = noise / np.sqrt(averaged)  # a smoothed vertex is the mean of that many samples
    return Surface(
        vertices=world,
        faces=faces,
        height_noise=noise,
        filled=filled,
        filled_faces=filled_faces,
        noise_model=model,
        observed_area=float(area[~filled_faces].sum()),
        filled_area=float(area[filled_faces].sum()),
    )


def _not_specks(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(F,) bool: the faces ((F, 3)) in connected pieces (sharing vertices) of at least
    MIN_PIECE triangles (the rest: flying pixels, specks)."""
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    _, label = connected_components(graph, directed=False)
    per_face = label[faces[:, 0]]
    size = np.bincount(per_face, minlength=label.max() + 1)
    return size[per_face] >= MIN_PIECE


SMOOTH_NEIGHBOURS = 12
"""Samples a vertex is smoothed with (itself and its nearest neighbours) [-]."""


def denoise(
    points: np.ndarray, model: tuple[float, float], camera: bool
) -> tuple[np.ndarray, np.ndarray]:
    """(points moved onto their local surface (N, 3), (N,) samples each now averages): each
    sample of points ((N, 3); camera: camera frame, the sensor at the origin; else world, z up)
    is moved onto the plane fitted to it and its SMOOTH_NEIGHBOURS - 1 nearest neighbours,
    along its ray (a camera's) or vertically, when those lie on that plane within twice the
    noise (model: sigma(d) = a + b d^2 along a ray [m]): a floor flat within the noise
    becomes flat, while at a step, an edge or an object the spread is larger and the samples
    stay where they were measured. One pass, like a moving-least-squares smoothing of order 1
    with an edge guard."""
    from scipy.spatial import KDTree

    n = len(points)
    averaged = np.ones(n)
    k = min(SMOOTH_NEIGHBOURS, n)
    if k < 4:
        return points, averaged
    idx = np.asarray(KDTree(points).query(points, k=k, workers=-1)[1])
    nbr = points[idx]  # (N, k, 3), the point itself first
    centre = nbr.mean(axis=1)
    cov = np.einsum("nki,nkj->nij", nbr - centre[:, None], nbr - centre[:, None])
    values, vectors = np.linalg.eigh(cov)
    normal = vectors[:, :, 0]
    spread = np.sqrt(np.maximum(values[:, 0], 0.0) / k)  # rms distance to the plane [m]
    if camera:
        ranges = np.linalg.norm(points, axis=1)
        ray = points / np.maximum(ranges, 1e-12)[:, None]
        cos = np.abs(np.einsum("ij,ij->i", ray, normal))
        sigma = model[0] + model[1] * ranges**2
        flat = spread <= 2.0 * sigma * np.maximum(cos, 0.2)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", centre, normal) / np.einsum("ij,ij->i", ray, normal)
        move = flat & (cos >= 0.2) & np.isfinite(t) & (np.abs(t - ranges) <= 3.0 * sigma)
        out = points.copy()
        out[move] = ray[move] * t[move, None]
    else:
        sigma = np.full(n, model[0])
        flat = spread <= 2.0 * sigma
        up = np.abs(normal[:, 2])
        with np.errstate(divide="ignore", invalid="ignore"):
            dz = -np.einsum("ij,ij->i", points - centre, normal) / normal[:, 2]
        move = flat & (up >= 0.5) & np.isfinite(dz) & (np.abs(dz) <= 3.0 * sigma)
        out = points.copy()
        out[move, 2] += dz[move]
    averaged[move] = k
    return out, averaged


def range_noise_model(points: np.ndarray, camera: bool, k: int = 8) -> tuple[float, float]:
    """(a [m], b [1/m]): the noise along a sample's ray at range d is a + b d^2, fitted to the
    local spread of points ((N, 3) [m]; camera: camera frame, the sensor at the origin; else a
    world frame, where only a (b = 0) is fitted). Each point's distance to the plane of its k
    nearest neighbours, divided by the cosine of its incidence (a sample moves along its ray),
    is a noise sample; per 0.5 m of range the median of them (robust to the edges and
    textures a scene also has) gives sigma there, and a, b >= 0 are fitted to those by least
    squares. NOISE_FALLBACK with too few points."""
    from scipy.optimize import nnls
    from scipy.spatial import KDTree

    pts = points[:: max(1, len(points) // 20000)]
    if len(pts) < 200:
        return NOISE_FALLBACK if camera else (NOISE_FALLBACK[0] * 10, 0.0)
    idx = np.asarray(KDTree(pts).query(pts, k=k + 1)[1])
    nbr = pts[idx[:, 1:]]  # (N, k, 3)
    centre = nbr.mean(axis=1)
    cov = np.einsum("nki,nkj->nij", nbr - centre[:, None], nbr - centre[:, None])
    normal = np.linalg.eigh(cov)[1][:, :, 0]
    res = np.abs(np.einsum("ij,ij->i", pts - centre, normal)) / math.sqrt(1 + 1 / k)
    if not camera:
        return (float(1.4826 * np.median(res)), 0.0)
    ranges = np.linalg.norm(pts, axis=1)
    incidence = np.abs(np.einsum("ij,ij->i", pts, normal)) / np.maximum(ranges, 1e-9)
    use = incidence >= 0.5
    along = res[use] / incidence[use]
    bins = np.floor(ranges[use] / 0.5).astype(np.int64)
    d, s, w = [], [], []
    for b in np.unique(bins):
        sel = bins == b
        if sel.sum() >= 50:
            d.append(float(np.median(ranges[use][sel])))
            s.append(float(1.4826 * np.median(along[sel])))
            w.append(math.sqrt(sel.sum()))
    if len(d) < 1:
        return NOISE_FALLBACK
    d_, s_, w_ = np.array(d), np.array(s), np.array(w)
    coef, _ = nnls(np.column_stack([np.ones_like(d_), d_**2]) * w_[:, None], s_ * w_)
    return float(coef[0]), float(coef[1])
