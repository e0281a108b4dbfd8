"""A .zip of an OpenSCAD model with its data files: unpacked safely, the model found and built;
unsafe archives refused with the member named. Messages never show the app's upload folders."""

from __future__ import annotations

import io
import stat
import zipfile

import pytest
import yaml

from roachplan.app._jobs import capture_view
from roachplan.app._uploads import prepare_upload_scene, public_message, scene_from_upload
from roachplan.scenes import SceneError
from roachplan.scenes._autopose import MAX_AUTO_EXTENT
from test_perception import REAL


def _zip(files: dict[str, bytes], links: tuple[str, ...] = ()) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
        for name in links:
            info = zipfile.ZipInfo(name)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            z.writestr(info, "/etc/passwd")
    return buf.getvalue()


def test_a_zip_with_a_scad_and_its_data_file_builds(tmp_path):
    scad = (REAL / "openscad" / "example010.scad").read_bytes()
    dat = (REAL / "openscad" / "example010.dat").read_bytes()
    data = _zip({"example010.scad": scad, "example010.dat": dat})
    path = scene_from_upload("terrain.zip", data, tmp_path, {})
    assert yaml.safe_load(path.read_text())["terrain"][0]["scad"] == "example010.scad"
    raw_text = path.read_text()
    assert "robot" not in yaml.safe_load(raw_text)  # picked when built, then written back
    try:
        world = prepare_upload_scene(path)
    except SceneError as exc:  # OpenSCAD's example is in millimetre-ish units
        assert "scale: 0.001" in str(exc)
        return
    raw = yaml.safe_load(path.read_text())
    assert len(raw["robot"]["start"]) == 3 and len(raw["bounds"]) == 2 and world.notes
    # The model is 45 m across: planning stays within the centre window, said in a note.
    (x0, y0), (x1, y1) = raw["bounds"]
    assert max(x1 - x0, y1 - y0) <= MAX_AUTO_EXTENT + 1e-6
    assert any("at its centre" in n for n in world.notes)


@pytest.mark.parametrize(
    ("files", "links", "why"),
    [
        ({"../evil.scad": b"cube(1);"}, (), "outside the archive"),
        ({"/abs.scad": b"cube(1);"}, (), "outside the archive"),
        ({"a.scad": b"cube(1);"}, ("link.dat",), "symbolic link"),
        ({"a.scad": b"cube(1);", "b.scad": b"cube(2);"}, (), "exactly one .scad"),
    ],
)
def test_unsafe_or_unclear_archives_are_refused(tmp_path, files, links, why):
    with pytest.raises(SceneError, match=why):
        scene_from_upload("m.zip", _zip(files, links), tmp_path, {})


def test_the_model_is_the_file_no_other_includes(tmp_path):
    data = _zip(
        {
            "main.scad": b"include <lib.scad>\nblock();\n",
            "lib.scad": b"module block() cube([1, 1, 0.1]);\n",
        }
    )
    path = scene_from_upload("m.zip", data, tmp_path, {})
    assert yaml.safe_load(path.read_text())["terrain"][0]["scad"] == "main.scad"
    world = prepare_upload_scene(path)
    assert abs(world.mesh.extents[2] - 0.1) < 1e-6


def test_messages_name_the_file_not_the_upload_folder(tmp_path):
    msg = f"{tmp_path}/upload-ab_12/cube.yaml: terrain[0].scad: too big"
    assert public_message(msg, tmp_path) == "cube.yaml: terrain[0].scad: too big"


def test_a_zip_of_a_depth_image_with_its_calibration_loads_them_together(tmp_path):
    rtab = REAL / "rtabmap"  # the calibration's name differs from the image's
    data = _zip(
        {
            "capture/depth_154.png": (rtab / "depth_154.png").read_bytes(),
            "capture/calib_154.yaml": (rtab / "calib_154.yaml").read_bytes(),
        }
    )
    path = scene_from_upload("room.zip", data, tmp_path, {"voxel": 0.02})
    obj = yaml.safe_load(path.read_text())["terrain"][0]
    assert obj["capture"] == "capture/depth_154.png"
    assert obj["perception"] == {"voxel": 0.02, "intrinsics": "capture/calib_154.yaml"}
    world = prepare_upload_scene(path)
    # The calibration's fx = fy = 525 and its camera pose: the floor 0.42 m under the camera
    # (the data's README); a Kinect v2 preset would put it elsewhere.
    view = capture_view(world.scene)
    assert view is not None  # the scene is the one capture
    camera_z = view.report["camera_height_m"]
    assert 0.35 < camera_z < 0.5


def test_a_zip_of_two_captures_is_refused_naming_them(tmp_path):
    png = (REAL / "rtabmap" / "depth_154.png").read_bytes()
    with pytest.raises(SceneError, match=r"one capture .*a\.png, b\.png"):
        scene_from_upload("two.zip", _zip({"a.png": png, "b.png": png}), tmp_path, {})


def test_the_announcement_says_what_is_really_done_with_each_upload(tmp_path):
    """A .zip of a capture is read and meshed, not "rendered with OpenSCAD"; a model is
    rendered (by whom, under which limit); a mesh is read."""
    from roachplan.app._uploads import load_announcement

    rtab = REAL / "rtabmap"
    capture = _zip(
        {
            "depth_154.png": (rtab / "depth_154.png").read_bytes(),
            "calib_154.yaml": (rtab / "calib_154.yaml").read_bytes(),
        }
    )
    model = _zip(
        {
            "example010.scad": (REAL / "openscad" / "example010.scad").read_bytes(),
            "example010.dat": (REAL / "openscad" / "example010.dat").read_bytes(),
        }
    )
    cases = {
        "room.zip": (capture, "upload: room.zip: reading and meshing the capture depth_154.png"),
        "terrain.zip": (
            model,
            "upload: terrain.zip: rendering example010.scad with Manifold or, "
            "where it must, OpenSCAD (limit 120 s)",
        ),
        "depth_154.png": (
            (rtab / "depth_154.png").read_bytes(),
            "Reading and meshing the capture depth_154.png",
        ),
        "example010.scad": (
            (REAL / "openscad" / "example010.scad").read_bytes(),
            "Rendering example010.scad with Manifold or, where it must, OpenSCAD (limit 120 s)",
        ),
    }
    for name, (data, said) in cases.items():
        path = scene_from_upload(name, data, tmp_path, {}, scad_timeout=120.0)
        assert load_announcement(f"upload: {name}", path) == said
    import trimesh
    from trimesh.exchange.stl import export_stl

    mesh = export_stl(trimesh.creation.box((1.0, 1.0, 0.1)))
    path = scene_from_upload("step.stl", mesh, tmp_path, {}, scad_backend="manifold")
    assert load_announcement("upload: step.stl", path) == "Reading the mesh step.stl"
    path = scene_from_upload("m.scad", b"cube(1);", tmp_path, {}, scad_backend="manifold")
    assert load_announcement("upload: m.scad", path).startswith("Rendering m.scad with Manifold")


def test_the_page_announces_a_capture_zip_as_meshing_while_it_loads(app, tmp_path):
    """Through the app's queue, as a browser's upload arrives: the Scene folder's status line
    while the load runs."""
    import time

    from roachplan.app._commands import UploadCmd

    rtab = REAL / "rtabmap"
    data = _zip(
        {
            "depth_154.png": (rtab / "depth_154.png").read_bytes(),
            "calib_154.yaml": (rtab / "calib_154.yaml").read_bytes(),
        }
    )
    app.commands.put(UploadCmd(None, "room.zip", data))
    deadline = time.monotonic() + 60
    while not app.loading.status.content and time.monotonic() < deadline:
        time.sleep(0.02)
    shown = app.loading.status.content
    assert shown.startswith("upload: room.zip: reading and meshing the capture depth_154.png")
    assert "OpenSCAD" not in shown
