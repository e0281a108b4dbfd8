"""PLY point clouds: a .ply's vertices (ascii or binary), whatever else it holds; a .ply with
faces is a mesh to the scene loader (_inputs.input_kind), and its vertices still a cloud here."""

from __future__ import annotations

import ctypes
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from ._capture import Capture
from ._errors import CaptureError
from ._headers import HEAD_BYTES, PlyHeader, parse_ply_header
from ._read_common import file_head, read_rows


def read_ply(path: Path) -> Capture:
    """A .ply's vertices. The header is parsed and checked against the file's size first; the
    usual layouts (vertices of scalar properties, after elements of fixed size or in ascii) are
    read here with numpy, others by Open3D with its messages captured (it prints to the
    terminal and returns an empty cloud when it fails)."""
    h = parse_ply_header(file_head(path, HEAD_BYTES), path.stat().st_size, str(path))
    before = h.elements[: h.elements.index(h.vertex)]
    vertex = h.vertex
    if vertex.fixed and h.format == "ascii":
        with open(path, "rb") as f:
            f.seek(h.data_offset)
            for _ in range(sum(e.count for e in before)):  # ascii: one line per entry
                f.readline()
            names = [p.name for p in vertex.properties]
            pts = read_rows(path, f, vertex.count, "PLY ascii vertex data")
            if pts.shape != (vertex.count, len(names)):
                raise CaptureError(
                    f"{path}: the PLY header says {vertex.count} vertices of {len(names)} "
                    f"properties, the ascii data has {pts.shape[0]} rows of {pts.shape[1]} values"
                )
            pts = pts[:, [names.index(k) for k in "xyz"]]
    elif vertex.fixed and all(e.fixed for e in before):
        dtype = np.dtype([(p.name, h.endian + p.type) for p in vertex.properties])
        with open(path, "rb") as f:
            f.seek(h.data_offset + sum(e.count * e.min_bytes for e in before))
            rows = np.frombuffer(f.read(vertex.count * dtype.itemsize), dtype=dtype)
        pts = np.stack([rows[k].astype(np.float64) for k in "xyz"], axis=1)
    else:
        pts = _ply_by_open3d(path, h)
    return Capture(points=pts, shape=None, source=str(path))


def _ply_by_open3d(path: Path, h: PlyHeader) -> np.ndarray:
    import open3d as o3d

    with _captured_output() as said:
        cloud = o3d.io.read_point_cloud(os.fspath(path), remove_nan_points=False)  # pyright: ignore[reportArgumentType] (its stubs ask for PathLike; it takes a str)
    pts = np.asarray(cloud.points, dtype=np.float64)
    told = " ".join(re.sub(r"\x1b\[[0-9;]*m|\[Open3D \w+\]", "", said.getvalue()).split())
    # When RPly fails part way Open3D still returns the vertex count, of uninitialised values.
    if len(pts) != h.vertex.count or re.search(r"fail|error", told, re.IGNORECASE):
        raise CaptureError(
            f"{path}: the PLY could not be read (Open3D: {told[:300] or 'no message'}; the header says "
            f"{', '.join(f'{e.count} {e.name}' for e in h.elements)[:120]})"
        )
    return pts


class _captured_output:  # noqa: N801 - used as a context manager, like contextlib's
    """Collect what a C library prints on the process's stdout and stderr (file descriptors 1
    and 2, which Python's sys.stdout cannot redirect) into .getvalue()."""

    def __enter__(self) -> _captured_output:
        sys.stdout.flush()
        sys.stderr.flush()
        self._file = tempfile.TemporaryFile()
        self._saved = [os.dup(1), os.dup(2)]
        for fd in (1, 2):
            os.dup2(self._file.fileno(), fd)
        return self

    def __exit__(self, *exc) -> None:
        # What the library left in C's stdio buffers belongs to the capture too (written
        # later it would reach the user's terminal or a --json stdout).
        ctypes.CDLL(None).fflush(None)
        for fd, saved in zip((1, 2), self._saved, strict=True):
            os.dup2(saved, fd)
            os.close(saved)
        self._file.seek(0)
        self._text = self._file.read(20_000).decode("utf-8", "replace")
        self._file.close()

    def getvalue(self) -> str:
        return self._text
