"""PCL's .pcd point clouds (ascii, binary, binary_compressed; organized or not)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ._capture import Capture
from ._errors import CaptureError
from ._headers import HEAD_BYTES, PcdHeader, parse_pcd_header
from ._read_common import file_head, read_rows


def read_pcd(path: Path) -> Capture:
    """PCL's .pcd: the header is parsed and checked against the file's size first (pypcd4, which
    reads these too, trusts its header: a truncated file came out short, a lying one empty)."""
    h = parse_pcd_header(file_head(path, HEAD_BYTES + 8), path.stat().st_size, str(path))
    with open(path, "rb") as f:
        f.seek(h.data_offset)
        if h.data == "ascii":
            pts = _pcd_ascii(path, f, h)
        elif h.data == "binary":
            data = f.read(h.points * h.point_step)
            rows = np.frombuffer(data, dtype=_pcd_dtype(h), count=h.points)
            pts = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
        else:
            pts = _pcd_compressed(path, f, h)
    vp = h.viewpoint
    organized = h.height > 1
    return Capture(
        points=pts,
        shape=(h.height, h.width) if organized else None,
        source=str(path),
        sensor_origin=(vp[0], vp[1], vp[2]),
        frame="camera" if organized else None,  # organized: a camera's pixels, optical frame
    )


def _pcd_dtype(h: PcdHeader) -> np.dtype:
    """One binary point's x, y, z within its point_step bytes."""
    return np.dtype(
        {
            "names": list("xyz"),
            "formats": [h.field(k).dtype for k in "xyz"],
            "offsets": [h.byte_offset(k) for k in "xyz"],
            "itemsize": h.point_step,
        }
    )


def _pcd_compressed(path: Path, f, h: PcdHeader) -> np.ndarray:
    """binary_compressed: the 8-byte sizes, then LZF of the fields one after another (all
    points' x, then all y, ...). lzf is pypcd4's own dependency."""
    import lzf

    f.seek(8, os.SEEK_CUR)
    size = h.points * h.point_step
    try:  # the sizes were checked: this allocates at most `size`, which the file can hold
        raw = lzf.decompress(f.read(h.compressed_size), size)
    except ValueError:
        raw = None
    if raw is None or len(raw) != size:
        raise CaptureError(
            f"{path}: the PCD's compressed data is damaged: it does not decode (LZF) to the "
            f"{size} bytes its header describes"
        )
    return np.stack(
        [
            np.frombuffer(
                raw, dtype=h.field(k).dtype, count=h.points, offset=h.points * h.byte_offset(k)
            ).astype(np.float64)
            for k in "xyz"
        ],
        axis=1,
    )


def _pcd_ascii(path: Path, f, h: PcdHeader) -> np.ndarray:
    values = read_rows(path, f, h.points, "PCD ascii data")
    if values.shape != (h.points, h.values_per_point):
        raise CaptureError(
            f"{path}: the PCD header says {h.points} points of {h.values_per_point} values "
            f"(FIELDS {' '.join(x.name for x in h.fields)[:60]}), the ascii data has "
            f"{values.shape[0]} rows of {values.shape[1]} values"
        )
    return values[:, [h.column(k) for k in "xyz"]]
