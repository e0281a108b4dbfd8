"""NumPy .npy point arrays: (N, >= 3), or organized (H, W, >= 3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._capture import Capture
from ._errors import CaptureError
from ._headers import MAX_CLOUD_POINTS
from ._read_common import file_head


def read_npy(path: Path) -> Capture:
    """A NumPy array of numbers, (N, >= 3) or organized (H, W, >= 3); its header is read and
    checked against the file's size before anything is allocated."""
    _sniff(path, (b"\x93NUMPY",), "NumPy .npy")
    fmt = np.lib.format
    with open(path, "rb") as f:
        try:
            version = fmt.read_magic(f)
            read = {(1, 0): fmt.read_array_header_1_0, (2, 0): fmt.read_array_header_2_0}
            if version not in read:
                raise ValueError(f"format version {version[0]}.{version[1]} (1.0 and 2.0 are read)")
            shape, _, dtype = read[version](f)
        except ValueError as exc:
            raise CaptureError(f"{path}: cannot read this .npy ({str(exc)[:200]})") from None
        offset = f.tell()
    if dtype.names is not None or dtype.kind not in "iuf":
        raise CaptureError(f"{path}: an array of {dtype}; expected numbers (integers or floats)")
    if not ((len(shape) == 3 and shape[2] >= 3) or (len(shape) == 2 and shape[1] >= 3)):
        raise CaptureError(f"{path}: expected an (N, 3) or (H, W, 3) array, got shape {shape}")
    points = int(np.prod(shape[:-1]))
    if points > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"{path}: shape {shape} is {points} points; clouds of at most "
            f"{MAX_CLOUD_POINTS // 1_000_000} million points are read"
        )
    need = int(np.prod(shape)) * dtype.itemsize
    if path.stat().st_size - offset < need:
        raise CaptureError(
            f"{path}: the .npy header says shape {shape} of {dtype} ({need} bytes), but "
            f"{path.stat().st_size - offset} bytes follow it: the file is truncated"
        )
    a = np.load(path, mmap_mode="r", allow_pickle=False)
    pts = np.array(a[..., :3], dtype=np.float64).reshape(-1, 3)
    return Capture(points=pts, shape=shape[:2] if len(shape) == 3 else None, source=str(path))


def _sniff(path: Path, magic: tuple[bytes, ...], what: str) -> None:
    head = file_head(path, 64)
    if not any(head.startswith(m) for m in magic):
        raise CaptureError(f"{path}: not a {what} file (it starts with {head[:16]!r})")
