"""One table of input kinds (perception.INPUT_KINDS, input_kind): the command line's capture
reader (load_capture, `roachplan mesh`), the scene loader (a terrain file as a scene of its own)
and the page's upload decide what a file is by it, and so agree on every file: the real
captures and model in ../shared/testdata/real/ and made-up files of every kind.

Which reader load_capture picks is seen by replacing the readers with a spy: no file is read
here beyond its header, so the real captures cost nothing."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

import roachplan.perception._inputs as inputs
from roachplan.app._uploads import scene_from_upload
from roachplan.perception import (
    CAPTURE_SUFFIXES,
    INPUT_KINDS,
    INPUT_SUFFIXES,
    MESH_SUFFIXES,
    CaptureError,
    input_kind,
    load_capture,
)
from roachplan.scenes import TERRAIN_SUFFIXES, load_scene, terrain_file_scene
from test_perception import REAL

REAL_FILES = sorted(
    p for p in REAL.rglob("*") if p.is_file() and p.suffix.lower() in INPUT_SUFFIXES
)

PLY_CLOUD = (
    b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    b"property float z\nend_header\n0 0 1\n1 0 1\n0 1 1\n"
)
PLY_MESH = (
    b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
)
PLY_NO_FACES = PLY_CLOUD.replace(b"end_header", b"element face 0\nend_header")
STL = (
    b"\0" * 80
    + struct.pack("<I", 1)
    + struct.pack("<12fH", *([0.0] * 3), 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
)
MADE_UP: dict[str, tuple[bytes, str, str]] = {
    # name: (content, kind, format)
    "cloud.ply": (PLY_CLOUD, "capture", "ply"),
    "faces0.ply": (PLY_NO_FACES, "capture", "ply"),
    "mesh.ply": (PLY_MESH, "mesh", "mesh"),
    "MESH.PLY": (PLY_MESH, "mesh", "mesh"),
    "step.stl": (STL, "mesh", "mesh"),
    "rock.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "mesh", "mesh"),
    "scene.glb": (b"glTF", "mesh", "mesh"),
    "bridge.scad": (b"cube(1);\n", "model", "scad"),
    "run.bag": (b"#ROSBAG V2.0\n", "capture", "bag"),
    "run.db3": (b"SQLite format 3\0", "capture", "bag"),
    "run.mcap": (b"\x89MCAP0\r\n", "capture", "bag"),
    "depth.png": (b"\x89PNG\r\n\x1a\n", "capture", "depth-image"),
    "depth.pgm": (b"P5\n1 1\n65535\n\0\1", "capture", "depth-image"),
    "depth.ppm": (b"P6\n1 1\n65535\n\0\1\0\1\0\1", "capture", "depth-image"),
    "room.pcd": (b"# .PCD v0.7\n", "capture", "pcd"),
    "room.xyz": (b"0 0 1\n", "capture", "text"),
    "room.pts": (b"1\n0 0 1\n", "capture", "text"),
    "room.npy": (b"\x93NUMPY", "capture", "npy"),
}


def _made_up(tmp_path: Path, name: str) -> Path:
    path = tmp_path / "made-up" / name
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(MADE_UP[name][0])
    return path


def _scene_kind(path: Path) -> str:
    """What the scene loader makes of the file as a scene of its own."""
    kind = terrain_file_scene(path).terrain[0].kind
    assert load_scene(path).terrain[0].kind == kind  # (load_scene goes through it)
    return {"scad": "model"}.get(kind, kind)


def _upload_kind(path: Path, root: Path) -> str:
    """What the page's upload makes of the file: the key of its scene's terrain object."""
    root.mkdir(exist_ok=True)
    scene = scene_from_upload(path.name, path.read_bytes(), root, {})
    (key,) = {"scad", "mesh", "capture"} & set(yaml.safe_load(scene.read_text())["terrain"][0])
    return {"scad": "model"}.get(key, key)


class _Read(Exception):
    """Raised by the spies in place of a reader: which one load_capture picked."""


def _cli_reader(path: Path, monkeypatch) -> str:
    """Which reader load_capture (`roachplan mesh FILE`) reads the file with, or "refused"
    when it takes the file for no capture."""
    spies = {
        "read_pcd": "pcd",
        "read_ply": "ply",
        "read_text_points": "text",
        "read_npy": "npy",
        "read_depth_image": "depth-image",
        "read_bag": "bag",
    }
    for function, name in spies.items():

        def spy(*_, name=name):
            raise _Read(name)

        monkeypatch.setattr(inputs, function, spy)
    try:
        load_capture(path)
    except _Read as read:
        return str(read)
    except CaptureError as exc:
        assert "unknown capture type" in str(exc), exc
        return "refused"
    raise AssertionError(f"{path}: load_capture read it with no reader")


def _check_agreement(path: Path, tmp_path: Path, monkeypatch) -> str:
    found = input_kind(path)
    assert found is not None, path
    assert _scene_kind(path) == found.kind, path
    assert _upload_kind(path, tmp_path / "uploads") == found.kind, path
    cli = _cli_reader(path, monkeypatch)
    if found.kind == "capture":
        assert cli == found.name, path
    elif path.suffix.lower() == ".ply":  # `roachplan mesh` meshes a mesh's vertices as a cloud
        assert cli == "ply", path
    else:
        assert cli == "refused", path
    return found.name


def test_the_real_files_are_all_there():
    names = {p.relative_to(REAL).as_posix() for p in REAL_FILES}
    assert {"jsk_watercan.bag", "rtabmap/depth_154.png", "openscad/example010.scad"} <= names
    assert len(names) >= 11


@pytest.mark.parametrize("path", REAL_FILES, ids=[p.name for p in REAL_FILES])
def test_the_three_callers_agree_on_each_real_file(path, tmp_path, monkeypatch):
    expected = {".pcd": "pcd", ".png": "depth-image", ".bag": "bag", ".scad": "scad"}
    assert _check_agreement(path, tmp_path, monkeypatch) == expected[path.suffix]


@pytest.mark.parametrize("name", sorted(MADE_UP))
def test_the_three_callers_agree_on_made_up_files(name, tmp_path, monkeypatch):
    path = _made_up(tmp_path, name)
    _, kind, fmt = MADE_UP[name]
    assert _check_agreement(path, tmp_path, monkeypatch) == fmt
    found = input_kind(path)
    assert found is not None and found.kind == kind


def test_a_ros2_bag_folder_is_a_bag_whatever_its_name(tmp_path, monkeypatch):
    for name in ("rosbag2_run", "odd.pcd"):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
        found = input_kind(folder)
        assert found is not None and found.name == "bag"
        assert _cli_reader(folder, monkeypatch) == "bag"
    assert input_kind(tmp_path / "notes.txt") is None


def test_the_table_is_the_only_list_of_suffixes():
    capture = [s for row in INPUT_KINDS if row.kind == "capture" for s in row.suffixes]
    assert CAPTURE_SUFFIXES == tuple(capture)
    assert MESH_SUFFIXES == (".stl", ".obj", ".ply", ".glb")  # (the order messages list)
    assert TERRAIN_SUFFIXES == INPUT_SUFFIXES
    both = [s for s in INPUT_SUFFIXES if sum(s in row.suffixes for row in INPUT_KINDS) > 1]
    assert both == [".ply"]  # the one suffix the header decides
    for row in INPUT_KINDS:
        assert (row.reader is not None) == (row.kind == "capture"), row.name


def test_a_mesh_ply_is_still_read_as_its_vertices_by_load_capture(tmp_path):
    """The command line meshes a .ply's vertices whether or not it has faces (as before)."""
    path = _made_up(tmp_path, "mesh.ply")
    cap = load_capture(path, units="m")
    assert np.allclose(cap.points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
