"""Text point lists, .xyz and .pts: x y z [...] per line."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from ._capture import Capture
from ._errors import CaptureError
from ._headers import MAX_CLOUD_POINTS
from ._read_common import file_head

MAX_TEXT_BYTES = 4 * 1024**3
"""Largest text point list read [bytes] (about 100 million lines of x y z)."""


def read_text_points(path: Path) -> Capture:
    """x y z [...] per line; # comments; a .pts may start with its point count."""
    size = path.stat().st_size
    if size > MAX_TEXT_BYTES:
        raise CaptureError(
            f"{path}: a text point list of {size / 1e9:.1f} GB; at most "
            f"{MAX_TEXT_BYTES / 1e9:.1f} GB are read (use a binary .pcd or .ply)"
        )
    head = file_head(path, 65536)
    if b"\0" in head:
        raise CaptureError(f"{path}: not a text point list (binary content)")
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not just a character cut at the end of the sample
            raise CaptureError(f"{path}: not a text point list (binary content)") from None
    skip = 0
    for line in head.splitlines(keepends=True):  # .pts: a first line of one number is the count
        if line.strip() and not line.lstrip().startswith(b"#"):
            if len(line.split()) == 1:
                skip += len(line)
            break
        skip += len(line)
    with open(path, "rb") as f:
        f.seek(skip if skip < len(head) else 0)
        try:
            with warnings.catch_warnings():  # an empty list warns; it is refused below
                warnings.simplefilter("ignore", UserWarning)
                pts = np.loadtxt(
                    io.TextIOWrapper(f, encoding="utf-8"),
                    dtype=np.float64,
                    ndmin=2,
                    comments="#",
                    usecols=(0, 1, 2),
                    max_rows=MAX_CLOUD_POINTS + 1,
                )
        except UnicodeDecodeError:
            raise CaptureError(f"{path}: not a text point list (binary content)") from None
        except ValueError as exc:
            raise CaptureError(
                f"{path}: expected lines of 'x y z [...]' numbers, every line at least x y z "
                f"({str(exc)[:200]})"
            ) from None
    if len(pts) > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"{path}: more than {MAX_CLOUD_POINTS} points; clouds of at most "
            f"{MAX_CLOUD_POINTS // 1_000_000} million points are read"
        )
    return Capture(points=pts.reshape(-1, 3), shape=None, source=str(path))
