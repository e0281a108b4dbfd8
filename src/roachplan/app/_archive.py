"""An uploaded .zip, unpacked safely: an OpenSCAD model with its includes and data files, or a
capture with its camera calibration (a depth image and its intrinsics, loaded together).

Refused: members with absolute paths, drive letters or '..' parts, symbolic links, more than
MAX_MEMBERS members, or more than MAX_UNPACKED_BYTES unpacked (counted as they are read, not as
the archive claims). The model is the .scad at the archive's top level (or at the top of its
only folder, as zipping a folder gives) that no other file includes or uses.
"""

from __future__ import annotations

import io
import re
import stat
import zipfile
from pathlib import Path, PurePosixPath

from roachplan.scenes import SceneError

MAX_MEMBERS = 2000
"""Most files an uploaded archive may hold."""
MAX_UNPACKED_BYTES = 256 * 1024 * 1024
"""Most bytes an uploaded archive may unpack to [bytes]."""


def _member_path(label: str, info: zipfile.ZipInfo) -> PurePosixPath | None:
    """The member's relative path, None for a folder; SceneError when it is unsafe."""
    name = info.filename.replace("\\", "/")
    mode = info.external_attr >> 16
    if stat.S_ISLNK(mode):
        raise SceneError(
            f"{label}: {info.filename!r} is a symbolic link; archives may hold only files"
        )
    path = PurePosixPath(name)
    if (
        name.startswith("/")
        or (len(name) > 1 and name[1] == ":")
        or "\x00" in name
        or any(part == ".." for part in path.parts)
    ):
        raise SceneError(
            f"{label}: {info.filename!r} points outside the archive (absolute or '..'); "
            f"archives may hold only relative paths"
        )
    if info.is_dir() or not path.parts:
        return None
    return path


def extract_zip(label: str, data: bytes, folder: Path) -> list[PurePosixPath]:
    """Unpack the archive `data` (an upload named `label`) into folder; its files' paths
    relative to folder."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile as exc:
        raise SceneError(f"{label}: not a zip archive ({exc})") from None
    infos = archive.infolist()
    if len(infos) > MAX_MEMBERS:
        raise SceneError(f"{label}: {len(infos)} files; an archive may hold at most {MAX_MEMBERS}")
    members = [(info, p) for info in infos if (p := _member_path(label, info)) is not None]
    folder = folder.resolve()
    total = 0
    for info, rel in members:
        target = folder.joinpath(*rel.parts)
        if not target.resolve().is_relative_to(folder):
            raise SceneError(f"{label}: {info.filename!r} points outside the archive")
        target.parent.mkdir(parents=True, exist_ok=True)
        with archive.open(info) as src, open(target, "wb") as dst:
            while chunk := src.read(1 << 20):
                total += len(chunk)
                if total > MAX_UNPACKED_BYTES:
                    raise SceneError(
                        f"{label}: unpacks to more than {MAX_UNPACKED_BYTES >> 20} MB; refused"
                    )
                dst.write(chunk)
    return [rel for _, rel in members]


def scad_model(label: str, paths: list[PurePosixPath], folder: Path) -> str:
    """The model among an unpacked archive's files (paths relative to folder): the .scad at its
    top level, or at the top of its only folder, that no other file includes or uses."""
    tops = {rel.parts[0] for rel in paths}
    base = PurePosixPath(next(iter(tops))) if len(tops) == 1 and len(paths[0].parts) > 1 else None
    models = [
        rel
        for rel in paths
        if rel.suffix.lower() == ".scad" and rel.parent == (base or PurePosixPath("."))
    ]
    if len(models) > 1:  # the model is the one no other file includes or uses
        used = set()
        for rel in paths:
            if rel.suffix.lower() == ".scad":
                text = folder.joinpath(*rel.parts).read_text(errors="replace")
                for ref in re.findall(r"(?:include|use)\s*<([^>]+)>", text):
                    used.add(PurePosixPath(rel.parent, ref.strip()))
        models = [m for m in models if m not in used]
    if len(models) != 1:
        where = f"in its folder {base}/" if base else "at its top level"
        found = ", ".join(str(m) for m in models) if models else "none"
        raise SceneError(
            f"{label}: expected exactly one .scad model {where} (the others are its includes "
            f"and data in sub-folders); found {found}"
        )
    return str(models[0])


CALIBRATION_SUFFIXES = (".json", ".xml", ".yaml", ".yml")
"""Files an archive may hold beside a capture: its camera calibration."""


def capture_in_zip(
    label: str, paths: list[PurePosixPath], capture_suffixes: tuple[str, ...]
) -> tuple[str, str | None] | None:
    """(capture, calibration or None), paths relative to the unpacked folder, for an archive of
    one capture (a cloud, a depth image, a bag) and at most one calibration file; None when it
    holds no capture (it may be a model); SceneError when it holds several."""
    captures = [p for p in paths if p.suffix.lower() in capture_suffixes]
    if not captures:
        return None
    calibrations = [p for p in paths if p.suffix.lower() in CALIBRATION_SUFFIXES]
    if len(captures) > 1 or len(calibrations) > 1:
        raise SceneError(
            f"{label}: an archive of a capture holds one capture and at most one calibration "
            f"file; found {', '.join(str(p) for p in captures + calibrations)}"
        )
    return str(captures[0]), (str(calibrations[0]) if calibrations else None)
