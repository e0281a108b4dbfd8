"""Render OpenSCAD models with the real `openscad` binary, through a content-addressed cache."""

from __future__ import annotations

import functools
import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path

from ._errors import SceneError

ScadValue = float | int | bool | str


def cache_dir() -> Path:
    """Where rendered meshes are kept: $ROACHPLAN_CACHE or ~/.cache/roachplan."""
    root = os.environ.get("ROACHPLAN_CACHE") or Path.home() / ".cache" / "roachplan"
    return Path(root) / "openscad"


def openscad_binary() -> str:
    exe = shutil.which("openscad")
    if exe is None:
        raise SceneError(
            "the `openscad` program is not installed; `make run` / `make test` install it "
            "(Debian: apt-get install openscad)"
        )
    return exe


@functools.cache
def openscad_version() -> str:
    out = subprocess.run(
        [openscad_binary(), "--version"], capture_output=True, text=True, timeout=30, check=False
    )
    return (out.stdout + out.stderr).strip()


def _scad_literal(value: ScadValue) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(value)  # a double-quoted string OpenSCAD accepts


def render_scad(
    scad_file: Path, params: Mapping[str, ScadValue] | None = None, *, timeout: float = 60.0
) -> Path:
    """Render scad_file with `-D name=value` overrides to an STL and return its cached path.

    The cache key covers the model text, the overrides and the OpenSCAD version, so a changed
    parameter renders again and an unchanged model never does. OpenSCAD's own error text is
    passed through when the model is wrong.
    """
    scad_file = Path(scad_file)
    if not scad_file.is_file():
        raise SceneError(f"{scad_file}: no such OpenSCAD file")
    params = dict(params or {})
    defines = [f"{k}={_scad_literal(v)}" for k, v in sorted(params.items())]
    key = hashlib.sha256(
        json.dumps(
            [scad_file.read_text(errors="replace"), defines, openscad_version()]
        ).encode()
    ).hexdigest()[:32]
    out = cache_dir() / f"{scad_file.stem}-{key}.stl"
    if out.is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [openscad_binary(), "-o", "", "--export-format", "binstl"]
    for d in defines:
        cmd += ["-D", d]
    # Render to a temporary file in the cache folder and rename: a killed render leaves no
    # half-written mesh behind under the final name.
    with tempfile.NamedTemporaryFile(dir=out.parent, suffix=".stl", delete=False) as tmp:
        tmp_path = Path(tmp.name)
    cmd[2] = str(tmp_path)
    cmd.append(str(scad_file))
    try:
        proc = subprocess.run(
            cmd, capture_output=True, text=True, timeout=timeout, cwd=scad_file.parent, check=False
        )
    except subprocess.TimeoutExpired:
        tmp_path.unlink(missing_ok=True)
        raise SceneError(
            f"{scad_file}: OpenSCAD did not finish within {timeout:g} s and was stopped"
        ) from None
    if proc.returncode != 0 or tmp_path.stat().st_size == 0:
        tmp_path.unlink(missing_ok=True)
        detail = "\n".join(
            line for line in proc.stderr.splitlines() if "ERROR" in line or "WARNING" in line
        ) or proc.stderr.strip()
        raise SceneError(f"{scad_file}: OpenSCAD failed:\n{detail}")
    tmp_path.replace(out)
    return out
