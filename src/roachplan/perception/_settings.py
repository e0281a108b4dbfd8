"""How to read and mesh a capture: the pipeline's settings, each with its validator
(roachplan/_settings.py), and the one reader of them from plain data: a scene's `perception:`
block, `roachplan mesh`'s flags, the page's Meshing and Camera boxes and `roachplan.mesh(...)`
all come through `CaptureSettings.from_mapping`. Importable without numpy, trimesh or Open3D
(the command line checks `--crop` and `--depth-range` before it loads anything)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Literal

from roachplan._settings import (
    MAX_SETTING_INT,
    SettingError,
    boolean,
    check_settings,
    integer,
    is_number,
    one_of,
    optional,
    positive,
    seed,
)
from roachplan._settings import setting as s

from ._choices import DEPTH_UNITS, FRAMES, METHODS, DepthUnits, Frame, Method

QUATERNION_TOLERANCE = 1e-3
"""How far from 1 a camera pose's quaternion norm may be [-] (four rounded decimals are within
it and are normalised; further off is a typing error)."""


def _finite(v: Any) -> bool:
    return is_number(v) and math.isfinite(v)


def _triple(v: Any) -> bool:
    return isinstance(v, tuple | list) and len(v) == 3 and all(map(_finite, v))


def _voxel(v: Any) -> str | None:
    """Voxel size dx, dy, dz, each above 0 [m]."""
    if _triple(v) and all(x > 0 for x in v):
        return None
    return "expected a voxel size above 0 [m], or three of them (dx, dy, dz)"


def _depth_range(v: Any) -> str | None:
    """(near, far) [m], 0 <= near < far (near 0: no near limit)."""
    expected = "expected NEAR, FAR [m]: two finite numbers with 0 <= NEAR < FAR"
    if isinstance(v, tuple | list) and len(v) == 2 and all(map(_finite, v)):
        return None if 0 <= v[0] < v[1] else expected
    return expected


def _crop(v: Any) -> str | None:
    """((xmin, ymin, zmin), (xmax, ymax, zmax)) [m], each min below its max."""
    expected = "expected a box: xmin, ymin, zmin then xmax, ymax, zmax [m], each min below its max"
    if not (isinstance(v, tuple | list) and len(v) == 2 and _triple(v[0]) and _triple(v[1])):
        return expected
    swapped = [axis for axis, lo, hi in zip("xyz", v[0], v[1], strict=True) if not lo < hi]
    return f"{expected}; not so for {', '.join(swapped)}" if swapped else None


def _camera_pose(v: Any) -> str | None:
    """x, y, z [m], qx, qy, qz, qw: a position and a unit quaternion."""
    expected = (
        f"expected x, y, z [m], qx, qy, qz, qw: 7 finite numbers, the last four a unit "
        f"quaternion (norm within {QUATERNION_TOLERANCE:g} of 1)"
    )
    if not (isinstance(v, tuple | list) and len(v) == 7 and all(map(_finite, v))):
        return expected
    norm = math.sqrt(sum(q * q for q in v[3:]))
    return (
        None if abs(norm - 1.0) <= QUATERNION_TOLERANCE else f"{expected}; its norm is {norm:.4g}"
    )


def _up(v: Any) -> str | None:
    """A direction x, y, z in the capture's frame, not zero."""
    if _triple(v) and any(x != 0 for x in v):
        return None
    return "expected a direction x, y, z: three finite numbers, not all 0"


def _point(v: Any) -> str | None:
    """x, y, z [m] in the capture's frame."""
    return None if _triple(v) else "expected a point x, y, z [m]: three finite numbers"


def _fraction(v: Any) -> str | None:
    return None if is_number(v) and 0 <= v < 1 else "expected a number from 0 to below 1 [-]"


@dataclass(frozen=True, kw_only=True)
class MeshingConfig:
    """Settings of the capture-to-mesh pipeline."""

    voxel: tuple[float, float, float] = s((0.01, 0.01, 0.01), _voxel)
    """Voxel size dx, dy, dz in the camera frame [m] (section 3.1)."""
    depth_range: tuple[float, float] | None = s(None, optional(_depth_range))
    """Keep points this near/far [m]: along the optical axis in a camera frame, from the
    sensor in a world frame; None: 0.3-8 m for a camera, everything for a world frame."""
    crop: tuple[tuple[float, float, float], tuple[float, float, float]] | None = s(
        None, optional(_crop)
    )
    """World-frame box ((xmin, ymin, zmin), (xmax, ymax, zmax)) to keep [m]; None: all."""
    outlier_neighbours: int = s(16, integer(1))
    outlier_std: float = s(3.0, positive())
    """Statistical outlier removal: drop points whose mean distance to their neighbours is
    more than outlier_std standard deviations above the average."""
    ground_threshold: float = s(0.015, positive("m"))
    """RANSAC inlier distance of the ground plane [m]."""
    ground_iterations: int = s(1000, integer(1))
    camera_pose: tuple[float, ...] | None = s(None, optional(_camera_pose))
    """World pose of the camera x, y, z [m], qx, qy, qz, qw; None: from the ground plane."""
    frame: Frame = s("auto", one_of(FRAMES))
    """The capture's frame: "camera" (optical: x right, y down, z forward), "world" (z up,
    or `up`), or "auto": what the file says (depth images, organized clouds, a bag's frame
    id), else "world" for a georeferenced cloud or one all round the sensor, else "camera"."""
    up: tuple[float, float, float] | None = s(None, optional(_up))
    """Up in the capture's frame (the gravity prior); None: a calibration's camera pose, a
    bag's IMU, -y for a camera frame, +z for a world frame."""
    ground_point: tuple[float, float, float] | None = s(None, optional(_point))
    """A point on the intended ground, capture frame [m]: the plane through it is the ground
    (the page's "click the ground to re-level")."""
    recentre: bool | None = s(None, optional(boolean()))
    """Put the cloud's centre at x = y = 0 (world frame); None: when georeferenced."""
    method: Method = s("sensor", one_of(METHODS))
    """"sensor": samples joined at the density the sensor took them (perception/_surface.py);
    "grid": a height field of cell-size cells; "poisson", "ball-pivot": Open3D's."""
    max_fill: float = s(0.3, positive("m"))
    """Sensor method: holes inside an observed surface at most this wide [m], with a flat rim,
    are filled from it; larger ones (and every shadow) stay unknown."""
    cell: float | None = s(None, optional(positive("m")))
    """Grid method: cell size of the height field [m] (default: dx, or the cloud's point
    spacing when it is sparser, as an airborne lidar's metres)."""
    fill_holes: int = s(2, integer(0))
    """Grid method: fill holes up to this many cells across from their neighbours."""
    poisson_depth: int = s(9, integer(1, 16))
    poisson_trim: float = s(0.05, _fraction)
    """Poisson: drop the vertices of the lowest-density fraction (surface the data never saw)."""
    seed: int = s(0, seed())
    """Seed of RANSAC."""

    def __post_init__(self) -> None:
        check_settings(self)


def _pixels(v: Any) -> str | None:
    """A focal length or principal point [px]."""
    return None if is_number(v) and 0 < v < math.inf else "expected a number > 0 [px]"


def _image_side(v: Any) -> str | None:
    whole = isinstance(v, int) and not isinstance(v, bool)
    return None if whole and 1 <= v <= MAX_SETTING_INT else "expected a whole number of pixels >= 1"


@dataclass(frozen=True, kw_only=True)
class PinholeNumbers:
    """Intrinsics given as numbers (a settings mapping, --fx/--fy/--cx/--cy) [px]; a missing
    width / height is the depth image's."""

    fx: float = s(check=_pixels)
    fy: float = s(check=_pixels)
    cx: float = s(check=_pixels)
    cy: float = s(check=_pixels)
    width: int | None = s(None, optional(_image_side))
    height: int | None = s(None, optional(_image_side))

    def __post_init__(self) -> None:
        check_settings(self)

    def to_json(self) -> dict:
        return {k: v for k, v in vars(self).items() if v is not None}


def _intrinsics(v: Any) -> str | None:
    """A preset's name or a calibration file (text), or the numbers (PinholeNumbers)."""
    if isinstance(v, PinholeNumbers) or (isinstance(v, str) and v and "\0" not in v):
        return None
    return "expected a preset name, a file name or a mapping {fx, fy, cx, cy[, width, height]} [px]"


def _topic(v: Any) -> str | None:
    return None if isinstance(v, str) and v else "expected a topic name"


SETTING_KEYS = (
    "voxel",
    "method",
    "intrinsics",
    "depth_scale",
    "depth_units",
    "units",
    "topic",
    "camera_pose",
    "crop",
    "depth_range",
    "cell",
    "outlier_std",
    "ground_threshold",
    "seed",
    "frame",
    "up",
    "ground_point",
    "recentre",
)
"""The keys of a `perception:` block (CaptureSettings.from_mapping): MeshingConfig's that a user
sets, and CaptureSettings' own."""


@dataclass(frozen=True, kw_only=True)
class CaptureSettings:
    """How to read and mesh one capture: a scene's `perception:` block or `roachplan mesh`'s
    flags."""

    meshing: MeshingConfig = field(default_factory=MeshingConfig)
    intrinsics: str | PinholeNumbers | None = s(None, optional(_intrinsics))
    """Preset name, calibration file path, or the numbers fx, fy, cx, cy[, width, height]
    (depth images; default: a calibration file beside the image)."""
    depth_scale: float | None = s(None, optional(positive("units per metre")))
    """Depth units per metre (depth images; default 1000 or the sidecar's)."""
    depth_units: DepthUnits | None = s(None, optional(one_of(DEPTH_UNITS)))
    """"kinect-disparity": the depth image holds a Kinect v1's raw disparity; None: depth in
    units of the depth scale (raw disparity is still recognised when plain)."""
    units: Literal["m", "mm"] | None = s(None, optional(one_of(("m", "mm"))))
    """Point cloud units; None: metres unless the cloud can only be millimetres."""
    topic: str | None = s(None, optional(_topic))
    """Bag topic."""

    def __post_init__(self) -> None:
        check_settings(self)

    @classmethod
    def from_mapping(
        cls, data: Any, resolve: Callable[[str], Any] = lambda name: name
    ) -> CaptureSettings:
        """Settings from a mapping of SETTING_KEYS (a `perception:` block; null: the default);
        SettingError naming the key. resolve: turns an intrinsics file name into a path (e.g.
        beside a scene file); a preset's name is kept as it is."""
        if not isinstance(data, Mapping):
            raise SettingError("", data, f"expected a mapping with keys {', '.join(SETTING_KEYS)}")
        data = {k: v for k, v in data.items() if v is not None}
        for k in data:
            if k not in SETTING_KEYS:
                raise SettingError(
                    str(k), data[k], "", f"unknown key; accepted keys: {', '.join(SETTING_KEYS)}"
                )
        meshing_keys = {f.name for f in fields(MeshingConfig)}
        meshing = {k: _as_tuple(v) for k, v in data.items() if k in meshing_keys}
        if is_number(meshing.get("voxel")):  # one size for dx, dy and dz
            meshing["voxel"] = (float(meshing["voxel"]),) * 3
        config = MeshingConfig(**meshing)
        intrinsics = data.get("intrinsics")
        if isinstance(intrinsics, Mapping):
            intrinsics = _pinhole_numbers(intrinsics)
        elif isinstance(intrinsics, str) and _intrinsics(intrinsics) is None:
            from ._camera import PRESETS  # (numpy: only when a capture is being set up)

            intrinsics = intrinsics if intrinsics in PRESETS else str(resolve(intrinsics))
        return cls(
            meshing=config,
            intrinsics=intrinsics,
            depth_scale=data.get("depth_scale"),
            depth_units=data.get("depth_units"),
            units=data.get("units"),
            topic=data.get("topic"),
        )


def _as_tuple(v: Any) -> Any:
    """Lists (of lists) as the tuples a frozen config holds."""
    return tuple(_as_tuple(x) for x in v) if isinstance(v, list | tuple) else v


def _pinhole_numbers(v: Mapping) -> PinholeNumbers:
    """{fx, fy, cx, cy[, width, height]} [px]."""
    names = ("fx", "fy", "cx", "cy", "width", "height")
    unknown = [str(n) for n in v if n not in names]
    missing = [n for n in names[:4] if n not in v]
    if unknown or missing:
        raise SettingError(
            "intrinsics",
            dict(v),
            "",
            "expected a mapping {fx, fy, cx, cy[, width, height]} [px]; "
            + (f"unknown {', '.join(unknown)}" if unknown else f"missing {', '.join(missing)}"),
        )
    try:
        return PinholeNumbers(**{n: v[n] for n in names if n in v})
    except SettingError as exc:
        raise exc.within("intrinsics") from None


def capture_settings(
    data: Any, resolve: Callable[[str], Any] = lambda name: name
) -> CaptureSettings:
    """CaptureSettings.from_mapping, with a CaptureError naming the key ("crop: ...") for
    callers that know no file (a script, `roachplan.mesh(...)`)."""
    from ._errors import CaptureError

    try:
        return CaptureSettings.from_mapping(data, resolve)
    except SettingError as exc:
        raise CaptureError(str(exc)) from None
