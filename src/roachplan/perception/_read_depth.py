"""Depth images: a 16-bit PNG or netpbm PGM/PPM, with a depth scale (units per metre) and
pinhole intrinsics (a preset, a calibration file, numbers, or a calibration file beside the
image), or raw Kinect v1 disparity (_disparity)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ._camera import CALIBRATION_FORMATS, PRESETS, is_calibration_yaml, load_calibration
from ._capture import Capture, depth_to_points
from ._choices import DEPTH_UNITS, DepthUnits
from ._disparity import (
    KINECT_MAX_DEPTH_M,
    KINECT_NO_READING,
    as_disparity,
    kinect_disparity_to_m,
    recognise_disparity,
    swapped_bytes,
)
from ._errors import CaptureError
from ._headers import parse_netpbm_header, parse_png_header
from ._read_common import file_head
from ._yaml import short_repr

SIDECAR_SUFFIXES = (".json", ".xml", ".yaml", ".yml")
"""A calibration file beside a depth image (find_sidecar)."""


def _sidecars(path: Path) -> list[Path]:
    stems = [path.stem]
    if "_depth" in path.stem:
        stems.append(path.stem.split("_depth")[0])
    return [path.with_name(s + ext) for s in stems for ext in SIDECAR_SUFFIXES]


def find_sidecar(path: Path) -> Path | None:
    """The calibration file beside a depth image, if any: the same stem (or the stem before
    "_depth") with a SIDECAR_SUFFIXES suffix. A YAML file there that is no calibration (an
    uploaded capture's scene file is named like it) is passed over."""
    for p in _sidecars(path):
        if p.is_file() and (p.suffix.lower() not in (".yaml", ".yml") or is_calibration_yaml(p)):
            return p
    return None


def _needs_intrinsics(
    path: Path, why: str = "a depth image needs intrinsics", size: tuple[int, int] | None = None
) -> CaptureError:
    """The refusal of a depth image without usable intrinsics; with the image's size (w, h),
    the presets of that size come first."""
    fits = [k for k, v in PRESETS.items() if size is not None and (v.width, v.height) == size]
    names = [*fits, *(k for k in PRESETS if k not in fits)]
    lead = f"presets of {size[0]}x{size[1]}: {', '.join(fits)}; " if fits and size else ""
    return CaptureError(
        f"{path}: {why}: {lead}pass --intrinsics with a preset "
        f"({', '.join(names)}) or a calibration file, or the numbers --fx --fy --cx --cy "
        f"(`intrinsics: {{fx, fy, cx, cy}}` in a scene), or put {path.stem}.json, .xml, .yaml "
        f"or .yml beside it. Calibration files: {CALIBRATION_FORMATS}"
    )


def read_depth_image(
    path: Path, intrinsics, depth_scale: float | None, depth_units: DepthUnits | None = None
) -> Capture:
    _check_depth_units(path, depth_scale, depth_units)
    if path.suffix.lower() == ".png":
        raw, notes = _read_depth_png(path), []
    else:
        raw, note = _read_netpbm(path)
        notes = [note] if note else []
    h, w = raw.shape
    sidecar = find_sidecar(path)
    spec = intrinsics if intrinsics is not None else sidecar
    if spec is None:
        raise _needs_intrinsics(path)
    calib = load_calibration(spec, size=(w, h))
    intr = calib.intrinsics
    # Raw Kinect disparity is looked for only when no depth scale was given: a scale given
    # says the samples are depth. A calibration's scale does not: it is the camera's usual
    # one, not a statement about this file.
    disparity = depth_units == "kinect-disparity"
    if depth_units is None and depth_scale is None:
        disparity = recognise_disparity(path, raw, notes)
    if disparity:
        raw = as_disparity(path, raw, notes, told=depth_units is not None)
        depth_m, depth_scale = kinect_disparity_to_m(raw), None
    else:
        if depth_scale is None:
            depth_scale = calib.depth_scale
        if depth_scale is None and sidecar is not None and intrinsics is not None:
            depth_scale = _sidecar_depth_scale(sidecar, (w, h))
        depth_scale = depth_scale or 1000.0
        depth_m = raw.astype(np.float64) / depth_scale
    if (intr.width, intr.height) != (w, h):
        if abs(intr.width / w - intr.height / h) > 1e-6:
            raise _needs_intrinsics(
                path,
                f"the image is {w}x{h}, the intrinsics are for {intr.width}x"
                f"{intr.height} (another aspect ratio)",
                size=(w, h),
            )
        intr = intr.scaled(w, h)
    if not np.any(raw > 0):
        raise CaptureError(f"{path}: every pixel is 0 (no depth measured)")
    if not np.any(depth_m > 0):
        raise CaptureError(
            f"{path}: no pixel holds a Kinect disparity within its model (every "
            f"one is {KINECT_NO_READING}, 0 or beyond {KINECT_MAX_DEPTH_M:g} m)"
        )
    pts = depth_to_points(depth_m, intr)
    return Capture(
        points=pts,
        shape=(h, w),
        source=str(path),
        intrinsics=intr,
        frame="camera",
        base_from_camera=calib.base_from_camera,
        depth_scale=depth_scale,
        notes=tuple(notes),
    )


def _sidecar_depth_scale(sidecar: Path, size: tuple[int, int]) -> float | None:
    """Intrinsics given, the depth scale may still be written beside the image."""
    try:
        return load_calibration(sidecar, size=size).depth_scale
    except CaptureError:
        return None


def _check_depth_units(path: Path, depth_scale: float | None, depth_units) -> None:
    if depth_units is not None and depth_units not in DEPTH_UNITS:
        raise CaptureError(
            f"{path}: depth_units {short_repr(depth_units)}: accepted: "
            f"{', '.join(DEPTH_UNITS)} (or none: depth in units of the depth "
            f"scale)"
        )
    if depth_units is not None and depth_scale is not None:
        raise CaptureError(
            f"{path}: both a depth scale ({depth_scale:g}) and depth units ({depth_units}) "
            f"were given: a depth scale is for depth stored in units, {depth_units} is "
            f"converted by the sensor's own model; give one of them"
        )


def _read_depth_png(path: Path) -> np.ndarray:
    """A 16-bit greyscale PNG -> (H, W) raw depth units. The size, bit depth and colour type
    are checked on the IHDR chunk (always the first) before Pillow decodes anything."""
    from PIL import Image

    parse_png_header(file_head(path, 26), str(path))
    try:
        with warnings.catch_warnings():  # the size is checked above, against our own limit
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                if im.mode not in ("I;16", "I;16B", "I", "I;16L"):
                    raise CaptureError(
                        f"{path}: a depth PNG must be 16-bit greyscale (mode I;16), this one is "
                        f"{im.mode} - an 8-bit or colour image has no depth in it"
                    )
                return np.asarray(im)
    except (OSError, SyntaxError, ValueError, Image.DecompressionBombError) as exc:
        raise CaptureError(f"{path}: cannot decode this PNG: {str(exc)[:200]}") from None


def read_netpbm_depth(path: Path) -> np.ndarray:
    """A 16-bit netpbm image -> (H, W) uint16 raw depth units (_read_netpbm, without its note)."""
    return _read_netpbm(path)[0]


def _read_netpbm(path: Path) -> tuple[np.ndarray, str]:
    """A 16-bit netpbm image -> (H, W) uint16 raw depth units: PGM (P5 binary, P2 ASCII) or PPM
    (P6, P3), of which only the first channel is read (a colour pixmap has no depth; a depth
    tool that writes PPM repeats the depth in every channel). maxval > 255 means 16 bits per
    sample, big-endian (netpbm's rule); the samples are not rescaled by maxval. The header is
    checked against the file's real size before anything is allocated (parse_netpbm_header).
    Pillow is not used: it reads 16-bit PGM but not 16-bit PPM, and trusts the header's size.
    The note: samples that exceed maxval as netpbm orders their bytes but fit it swapped were
    written little-endian (some depth tools do), and are read so."""
    h = parse_netpbm_header(file_head(path, 4096), path.stat().st_size, str(path))
    samples = h.samples
    with open(path, "rb") as f:
        f.seek(h.data_offset)
        if h.binary:
            data = np.frombuffer(f.read(2 * samples), dtype=">u2")
        else:
            words = f.read().split()
            if len(words) < samples or not all(w.isdigit() for w in words[:samples]):
                raise CaptureError(
                    f"{path}: the ASCII netpbm image needs {samples} decimal samples after the "
                    f"header, it has {len(words)} words (or some are not numbers)"
                )
            try:
                data = np.array(words[:samples], dtype=np.int64)
            except OverflowError:  # more digits than any 16-bit sample has
                raise CaptureError(
                    f"{path}: a sample is over {h.maxval}, the header's maxval"
                ) from None
    note = ""
    if data.max() > h.maxval and h.binary and swapped_bytes(data).max() <= h.maxval:
        data = swapped_bytes(data)
        note = (
            f"its 16-bit samples are little-endian (netpbm's are big-endian): as written "
            f"they exceed the header's maxval {h.maxval}, swapped they do not"
        )
    if data.max() > h.maxval:
        raise CaptureError(
            f"{path}: a sample is {data.max()}, above the header's maxval {h.maxval}"
        )
    return data.reshape(h.height, h.width, h.channels)[..., 0].astype(np.uint16), note
