"""Raw Kinect v1 disparity in a depth image: recognised by its values, or as told, and
converted to depth by NYU Depth v2's model."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._errors import CaptureError

KINECT_NO_READING = 2047
"""A Kinect v1's raw 11-bit disparity for a pixel without a reading (libfreenect's
FREENECT_DEPTH_11BIT, NYU Depth v2's raw dumps)."""
KINECT_DISPARITY_MODEL = (351.3, 1092.5)
"""(a, b) of depth [m] = a / (b - d) for raw disparity d: NYU Depth v2's toolbox
(camera_params.m, depthParam1/2). Chosen over ROS/OpenKinect's 1 / (3.3309495161 - 0.0030711016
d) because NYU's raw dumps are where raw disparity files come from, and with their own model
the metres agree with the dataset's released depth maps; the two differ by 5 % at 1 m, 3 % at
2 m, under 2 % at 3-4 m and 7 % at 6 m."""
KINECT_MAX_DEPTH_M = 10.0
"""Farthest depth taken from disparity [m] (NYU's maxDepth): beyond it the model's metres per
disparity step exceed a quarter of a metre; such pixels, like 0, 2047 and d >= 1092.5 (no
depth in the model), are no reading rather than NYU's clamp to 10 m (a wall that is not
there)."""
KINECT_NEAR_M = 0.4
"""Nearest depth a Kinect v1 reads [m] (rated 0.8 m, 0.4 m in near mode)."""
MARKER_SHARE = 0.001
"""Share of pixels at 2047 from which it counts as the no-reading marker: a Kinect frame has
its shadow band at the left edge and dropouts on dark or shiny surfaces (NYU frames: several
%); a depth image in millimetres has only scattered pixels at 2.047 m."""
MODEL_SHARE = 0.95
"""Share of the other non-zero samples that must be disparities of KINECT_NEAR_M to
KINECT_MAX_DEPTH_M for raw disparity to be taken without being told."""


def kinect_disparity_to_m(raw: np.ndarray) -> np.ndarray:
    """(H, W) raw Kinect v1 disparity -> depth [m] by KINECT_DISPARITY_MODEL; 0 (no reading)
    where the sample is 0 or KINECT_NO_READING, or out of the model (d >= 1092.5, or further
    than KINECT_MAX_DEPTH_M)."""
    a, b = KINECT_DISPARITY_MODEL
    d = np.asarray(raw, dtype=np.float64)
    ok = (d > 0) & (d < KINECT_NO_READING) & (d < b)
    depth = np.zeros_like(d)
    depth[ok] = a / (b - d[ok])
    depth[depth > KINECT_MAX_DEPTH_M] = 0.0
    return depth


def _disparity_of(depth_m: float) -> float:
    a, b = KINECT_DISPARITY_MODEL
    return b - a / depth_m


def kinect_disparity_verdict(raw: np.ndarray) -> tuple[str, str]:
    """Whether a depth image's samples are a Kinect v1's raw disparity, by what they look like:
    ("yes" | "maybe" | "no", the evidence in words). Disparity is 11 bits (nothing above
    2047), with 2047 marking no reading - a spike: the values just below it are no disparity
    the model maps to a depth - on a share of the pixels (MARKER_SHARE); and nearly all the other
    samples (MODEL_SHARE) are disparities of 0.4-10 m (214-1057), which in millimetres would be
    a scene within 1.06 m with many pixels at exactly 2.047 m. "maybe": 11 bits with the marker,
    but the rest not so."""
    v = np.asarray(raw).ravel()
    if v.size == 0 or int(v.max()) > KINECT_NO_READING:
        return "no", ""
    marker = int(np.count_nonzero(v == KINECT_NO_READING))
    below = int(np.count_nonzero((v >= KINECT_NO_READING - 10) & (v < KINECT_NO_READING)))
    if marker < MARKER_SHARE * v.size or marker < 20 * (below / 10 + 1):
        return "no", ""
    rest = v[(v > 0) & (v < KINECT_NO_READING)]
    lo, hi = _disparity_of(KINECT_NEAR_M), _disparity_of(KINECT_MAX_DEPTH_M)
    share = float(np.mean((rest >= lo) & (rest <= hi))) if rest.size else 0.0
    evidence = (
        f"11-bit samples, {100 * marker / v.size:.1f} % of the pixels at "
        f"{KINECT_NO_READING} (the Kinect's no-reading value), {100 * share:.0f} % of "
        f"the others disparities of {KINECT_NEAR_M:g}-{KINECT_MAX_DEPTH_M:g} m "
        f"({lo:.0f}-{hi:.0f})"
    )
    return ("yes" if share >= MODEL_SHARE else "maybe"), evidence


def swapped_bytes(raw: np.ndarray) -> np.ndarray:
    r = np.asarray(raw, dtype=np.uint16)
    return ((r & 0xFF) << 8) | (r >> 8)


TELL_DISPARITY = "pass --depth-units kinect-disparity (depth_units: kinect-disparity in a scene)"
TELL_DEPTH = "pass its depth scale (--depth-scale N; 1000 for millimetres)"


def recognise_disparity(path: Path, raw: np.ndarray, notes: list[str]) -> bool:
    """Whether to read a depth image given no depth scale or depth units as raw Kinect
    disparity (a note says so); CaptureError, naming disparity and both settings, when it
    may be disparity but is not plainly so. A netpbm file's samples are also judged
    byte-swapped: NYU's dumps are read either way by the tools people use."""
    verdict, evidence = kinect_disparity_verdict(raw)
    if verdict == "no" and path.suffix.lower() != ".png":
        verdict, evidence = kinect_disparity_verdict(swapped_bytes(raw))
        evidence += " once its bytes are swapped" if evidence else ""
    if verdict == "maybe":
        raise CaptureError(
            f"{path}: this may be a Kinect v1's raw disparity, not depth ({evidence}), but it "
            f"is not plainly so: if it is disparity, {TELL_DISPARITY}; if it is depth, "
            f"{TELL_DEPTH}"
        )
    return verdict == "yes"


def as_disparity(path: Path, raw: np.ndarray, notes: list[str], *, told: bool) -> np.ndarray:
    """raw as 11-bit disparity, byte-swapped if that is what makes it so (a netpbm file written
    little-endian, against netpbm's rule); the note that says how it was read."""
    a, b = KINECT_DISPARITY_MODEL
    swapped = ""
    if int(raw.max()) > KINECT_NO_READING:
        if path.suffix.lower() == ".png" or int(swapped_bytes(raw).max()) > KINECT_NO_READING:
            raise CaptureError(
                f"{path}: depth units kinect-disparity were given, but samples reach "
                f"{int(raw.max())}: raw Kinect disparity has 11 bits (at most "
                f"{KINECT_NO_READING}); if it is depth, {TELL_DEPTH}"
            )
        raw, swapped = swapped_bytes(raw), " (its 16-bit samples little-endian)"
    how = "as told" if told else "recognised by its values"
    notes.append(
        f"read as a Kinect v1's raw disparity, {how}{swapped}, and converted by NYU Depth v2's "
        f"model: depth = {a:g} / ({b:g} - d) m; {KINECT_NO_READING}, 0 and disparities beyond "
        f"{KINECT_MAX_DEPTH_M:g} m are no reading"
        + ("" if told else f". If it is depth, {TELL_DEPTH}")
    )
    return raw
