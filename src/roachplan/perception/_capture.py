"""Captures: what a depth camera saw, as points in its frame, and the checks every capture
passes whatever file it came from (check_capture, depth_scale_advice).

The files people bring are read by one reader per format (_read_pcd, _read_ply, _read_text,
_read_npy, _read_depth, _read_bag); which reader reads a file is decided by the table of input
kinds (_inputs: input_kind, load_capture).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ._camera import Intrinsics
from ._errors import CaptureError


@dataclass(frozen=True, eq=False)
class Capture:
    """Points a depth camera saw."""

    points: np.ndarray
    """(N, 3) float64, camera frame [m]; rows of NaN are pixels without a measurement."""
    shape: tuple[int, int] | None
    """(H, W) when organized: N == H * W, row-major, as the sensor's pixels."""
    source: str
    """Where it came from, for messages."""
    intrinsics: Intrinsics | None = None
    sensor_origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The camera's centre in the points' frame [m] (PCD VIEWPOINT; else the origin)."""
    up: tuple[float, float, float] | None = None
    """Measured up direction in the points' frame (an IMU's gravity), if the file has one."""
    frame: Literal["camera", "world"] | None = None
    """What the file says of its frame: a camera's optical frame (x right, y down, z forward),
    a z-up world or robot frame (REP 103), or None when it does not say."""
    notes: tuple[str, ...] = ()
    """What the reader assumed, for the user."""
    base_from_camera: np.ndarray | None = None
    """(4, 4) transform of camera-frame points into the robot's base frame (z up) [m], when
    the calibration says (OpenCV YAML's local_transform); a gravity prior, not the world."""
    depth_scale: float | None = None
    """Depth units per metre the depth image was read with; None for point clouds."""

    @functools.cached_property
    def valid(self) -> np.ndarray:
        """(N,) bool: rows with a finite measurement (found once: the pipeline asks often, and
        a 1920 x 1080 image has two million rows)."""
        return np.all(np.isfinite(self.points), axis=1)

    def finite_points(self) -> np.ndarray:
        return self.points[self.valid]


GEOREFERENCED_M = 1000.0
"""A cloud whose centre is this far from its origin [m], and much farther than the cloud is
wide, is in a map frame (UTM, a site grid): it is recentred, and never taken for millimetres."""
MAX_RANGE_M = 200.0
"""No depth camera or ordinary lidar sees a median point this far away [m]: a camera-frame
cloud whose median distance is larger is in millimetres (a depth camera's nearest range,
0.3 m, is already 300 in millimetres)."""


def is_georeferenced(points: np.ndarray) -> bool:
    """points: (N, 3) finite. Its centre lies far from the origin compared with its size."""
    centre = np.median(points, axis=0)
    size = float(np.max(np.percentile(points, 98, axis=0) - np.percentile(points, 2, axis=0)))
    far = float(np.linalg.norm(centre))
    return far > GEOREFERENCED_M and far > 20.0 * max(size, 1e-9)


def check_capture(cap: Capture, units_given: bool = False) -> Capture:
    """Refuse captures nothing useful can come from, saying why. Without units given, a
    sensor-frame cloud whose median distance is beyond any sensor's range is refused as
    millimetres; a georeferenced cloud (far from its origin, small beside that distance) is
    not judged by its distance."""
    if len(cap.points) == 0:
        raise CaptureError(f"{cap.source}: the capture has no points")
    pts = cap.finite_points()
    if len(pts) == 0:
        raise CaptureError(f"{cap.source}: every point is invalid (NaN or zero depth)")
    if units_given or is_georeferenced(pts):
        return cap
    depth = np.median(np.linalg.norm(pts - np.asarray(cap.sensor_origin), axis=1))
    if depth > MAX_RANGE_M and cap.depth_scale is not None:  # a depth image: its scale is off
        raise CaptureError(
            depth_scale_advice(cap, (0.3, 8.0))  # a depth camera's range [m]
            or f"{cap.source}: the median depth is {depth:.0f} m at {cap.depth_scale:g} units "
            f"per metre: check the depth scale (--depth-scale)"
        )
    if depth > MAX_RANGE_M:
        raise CaptureError(
            f"{cap.source}: the median distance from the sensor is {depth:.0f}; in metres that "
            f"is beyond any depth camera or lidar, so it looks like millimetres: pass units mm "
            f"(--units mm), or units m (--units m) if it really is in metres"
        )
    return cap


def depth_to_points(depth_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """(H, W) depth along the optical axis [m] (0 or NaN = none) -> (H*W, 3) camera-frame
    points [m], NaN where there is no depth."""
    z = np.where(depth_m > 0, depth_m, np.nan)
    pts = np.empty((*z.shape, 3))
    # As intr.rays() * z, a pixel's direction a row or a column of numbers, not a full image.
    pts[..., 0] = ((np.arange(intr.width) - intr.cx) / intr.fx)[None, :] * z
    pts[..., 1] = ((np.arange(intr.height) - intr.cy) / intr.fy)[:, None] * z
    pts[..., 2] = z
    return pts.reshape(-1, 3)


STANDARD_DEPTH_SCALES: dict[float, str] = {
    1.0: "metres, e.g. 32-bit float images",
    100.0: "centimetres",
    1000.0: "millimetres: Kinect, PrimeSense, RealSense D435, PCL, rtabmap",
    5000.0: "TUM RGB-D",
    10000.0: "0.1 mm, e.g. RealSense D405",
}
"""Depth units per metre that depth datasets and drivers use, with who uses them."""
TYPICAL_DEPTH_M = 2.5
"""Median depth of a typical depth-camera capture [m] (Kinect, PrimeSense and RealSense work
best at about 0.5-5 m); only breaks ties between depth scales that fit equally well."""


def depth_scale_advice(cap: Capture, depth_range: tuple[float, float]) -> str | None:
    """When most (> 50 %) of a depth image's measured pixels fall outside depth_range (near,
    far along the optical axis [m]), a message saying how many and which standard depth scale
    (STANDARD_DEPTH_SCALES) would put most of them inside; None when the capture is no depth
    image or most pixels are inside."""
    if cap.depth_scale is None:
        return None
    z = cap.points[cap.valid, 2]
    if len(z) == 0:
        return None
    lo, hi = depth_range
    near, far = float(np.mean(z < lo)), float(np.mean(z > hi))
    if near + far <= 0.5:
        return None
    span = f"{lo:g}–{hi:g} m"
    if near == 0 or far == 0:
        where = f"beyond {hi:g} m" if far > 0 else f"nearer than {lo:g} m"
        where = f"{(near + far) * 100:.0f} % of the measured pixels are {where}"
    else:
        where = (
            f"{(near + far) * 100:.0f} % of the measured pixels are outside {span} "
            f"({far * 100:.0f} % beyond, {near * 100:.0f} % nearer)"
        )
    msg = f"{cap.source}: {where} at {cap.depth_scale:g} units per metre"
    raw = z * cap.depth_scale
    inside = {
        s: float(np.mean((raw / s >= lo) & (raw / s <= hi)))
        for s in STANDARD_DEPTH_SCALES
        if s != cap.depth_scale
    }
    top = max(inside.values(), default=0.0)
    if top <= 0.5:
        return msg + "; no standard depth scale puts most of them inside: check the depth scale"
    # A wide depth range fits two scales (TUM's 5000 and 10000 both put a room inside
    # 0.3-8 m): of those within 5 points of the best, take the one whose median depth is
    # nearest a depth camera's typical working distance.
    median = float(np.median(raw))
    best = min(
        (s for s, f in inside.items() if f >= top - 0.05),
        key=lambda s: abs(np.log(median / s / TYPICAL_DEPTH_M)),
    )
    return (
        f"{msg}; with a depth scale of {best:g} ({STANDARD_DEPTH_SCALES[best]}) "
        f"{inside[best] * 100:.0f} % fall within {span}: pass --depth-scale {best:g} "
        f"(depth_scale: {best:g} in a scene)"
    )
