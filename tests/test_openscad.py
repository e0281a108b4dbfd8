"""The real OpenSCAD pipeline: the rough bridge's bumps, the cache, the confinement, the limit."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from conftest import roachplan
from roachplan.scenes import SceneError, build_terrain_mesh, build_world, load_scene, render_scad
from roachplan.scenes._scad_sandbox import confined, sandbox_available
from roachplan.scenes._scad_source import scad_variables

LIBRARY = Path(__file__).resolve().parent.parent / "scenes" / "library"


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch) -> Path:
    """An empty render cache, so OpenSCAD really runs."""
    cache = tmp_path / "cache"
    monkeypatch.setenv("ROACHPLAN_CACHE", str(cache))
    return cache


def rough_params(**changes) -> dict:
    params = dict(load_scene("double_bridge_rough").terrain[0].params)
    return {**params, **changes}


def peaks(mesh: trimesh.Trimesh) -> dict[str, np.ndarray]:
    """Bump peaks (x, y, height above the bridge top [m]) per bridge."""
    v = np.unique(mesh.vertices.round(9), axis=0)
    on_bridge = (np.abs(v[:, 1]) < 0.5) & (np.abs(v[:, 0]) > 0.5) & (v[:, 2] > 0.2 + 1e-9)
    p = v[on_bridge] - (0, 0, 0.2)
    return {"left": p[p[:, 0] < 0], "right": p[p[:, 0] > 0]}


def test_rough_bridge_bumps_follow_appendix_c2():
    # The binary, the reference (test_scad_backend.py checks the default backend against it).
    mesh = trimesh.load_mesh(
        render_scad(LIBRARY / "double_bridge.scad", rough_params(), backend="cgal")
    )
    assert mesh.is_watertight
    bumps = peaks(mesh)
    for side, max_height in (("left", 0.015), ("right", 0.010)):
        p = bumps[side]
        # One peak per 2.5 cm cell of the 20 x 40 grid (a draw of exactly 0 would merge away).
        assert len(p) >= 795
        assert len(np.unique(p[:, 0].round(5))) == 20 and len(np.unique(p[:, 1].round(5))) == 40
        assert np.allclose(np.diff(np.unique(p[:, 0].round(5))), 0.025)
        assert np.all(p[:, 2] > 0) and np.all(p[:, 2] < max_height)
        # Uniform on [0, max): the tallest of 800 draws is close to max, the mean near max / 2.
        assert p[:, 2].max() > 0.97 * max_height
        assert p[:, 2].mean() == pytest.approx(max_height / 2, rel=0.08)
    assert bumps["left"][:, 2].mean() > bumps["right"][:, 2].mean() + 0.001


@pytest.mark.slow
def test_rough_bridge_renders_the_same_for_a_seed_and_differently_for_another(
    tmp_path, monkeypatch
):
    meshes = []
    for run, seed in enumerate((0, 0, 7)):
        monkeypatch.setenv("ROACHPLAN_CACHE", str(tmp_path / f"cache{run}"))
        meshes.append(
            trimesh.load_mesh(
                render_scad(
                    LIBRARY / "double_bridge.scad", rough_params(bump_seed=seed), backend="cgal"
                )
            )
        )
    same, other = peaks(meshes[1]), peaks(meshes[2])
    first = peaks(meshes[0])
    for side in ("left", "right"):
        np.testing.assert_array_equal(first[side], same[side])
        a = {(round(x, 4), round(y, 4)): h for x, y, h in first[side]}
        b = {(round(x, 4), round(y, 4)): h for x, y, h in other[side]}
        equal = sum(abs(a[k] - b[k]) < 1e-9 for k in a.keys() & b.keys())
        assert equal < 0.01 * len(a), f"{equal} of {len(a)} bumps unchanged by another seed"
    np.testing.assert_array_equal(meshes[0].vertices, meshes[1].vertices)


def test_the_cache_covers_files_the_model_reads(tmp_path, fresh_cache):
    for name in ("heightmap.scad", "heightmap.dat"):
        shutil.copy(LIBRARY / name, tmp_path / name)
    first = render_scad(tmp_path / "heightmap.scad")
    assert render_scad(tmp_path / "heightmap.scad") == first
    dat = tmp_path / "heightmap.dat"
    dat.write_text(dat.read_text().replace("2.500", "9.000"))
    second = render_scad(tmp_path / "heightmap.scad")
    assert second != first
    assert trimesh.load_mesh(second).bounds[1][2] > trimesh.load_mesh(first).bounds[1][2]


def test_the_heightmap_scene_is_a_surface_height_map():
    mesh = trimesh.load_mesh(render_scad(LIBRARY / "heightmap.scad"))
    # 81 rows x 61 columns 5 cm apart: 3 x 4 m, heights up to 14.5 cm, solid down to -1 cm.
    np.testing.assert_allclose(mesh.bounds[:, :2], [[-1.5, -2.0], [1.5, 2.0]], atol=1e-9)
    assert mesh.bounds[0][2] == pytest.approx(-0.01)
    assert 0.12 < mesh.bounds[1][2] < 0.15


@pytest.mark.parametrize(
    ("files", "expected"),
    [
        (
            {"m.scad": 'surface(file = "../outside.dat");'},
            r"m\.scad, line 1: surface '\.\./outside\.dat': a model may only read files in its own folder",
        ),
        (
            {"m.scad": 'import("/etc/passwd");'},
            r"line 1: import '/etc/passwd': a model may only read files",
        ),
        ({"m.scad": "cube(1);\ninclude </etc/x.scad>"}, r"line 2: include '/etc/x\.scad'"),
        (
            {"m.scad": 'p = "/etc";\nimport(str(p, "/passwd"));'},
            r"line 2: import: the file must be a literal string",
        ),
        ({"m.scad": 'linear_extrude(height = 1, file = "~/x.dxf");'}, r"linear_extrude '~/x\.dxf'"),
        (
            {"m.scad": "use <lib.scad>\ncube(1);", "lib.scad": 'import("sub/../../outside.dat");'},
            r"lib\.scad, line 1: import 'sub/\.\./\.\./outside\.dat'",
        ),
        (
            {"m.scad": 'surface(file = "link.dat");', "link.dat": "->outside.dat"},
            r"surface 'link\.dat' leads outside the model's folder",
        ),
        (
            {"m.scad": "include <MCAD/units.scad>\ncube(1);"},
            r"include 'MCAD/units\.scad': no such file .*library includes",
        ),
    ],
    ids=[
        "dotdot",
        "absolute",
        "include-absolute",
        "computed",
        "home",
        "via-use",
        "symlink",
        "system-library",
    ],
)
def test_a_model_may_not_read_outside_its_folder(tmp_path, fresh_cache, files, expected):
    (tmp_path / "outside.dat").write_text("1 2\n3 4\n")
    model = tmp_path / "model"
    model.mkdir()
    for name, text in files.items():
        if text.startswith("->"):
            (model / name).symlink_to(tmp_path / text[2:])
        else:
            (model / name).write_text(text)
    with pytest.raises(SceneError, match=expected):
        render_scad(model / "m.scad")
    assert not list(fresh_cache.glob("*.stl"))


@pytest.mark.parametrize("backend", ["cgal", "auto"])
def test_openscad_errors_are_passed_through(tmp_path, fresh_cache, backend):
    # auto: the evaluator fails on it too, and the binary's own words are the ones given.
    (tmp_path / "bad.scad").write_text("cube(1);\nsphere(;\n")
    with pytest.raises(
        SceneError,
        match=r"bad\.scad: OpenSCAD failed:\nERROR: Parser error: syntax error in file bad\.scad, line 2",
    ):
        render_scad(tmp_path / "bad.scad", backend=backend)


@pytest.mark.parametrize("backend", ["cgal", "manifold"])
def test_a_2d_model_is_refused_where_it_loaded_as_a_1_m_cube(tmp_path, fresh_cache, backend):
    """`square(1);` loaded as "1 terrain object(s), 12 triangles, 1.00x1.00x1.00 m" (the
    evaluator's preview of it); the binary failed with its statistics and "Current top level
    object is not a 3D object". Both now say what is wrong and how to mend it."""
    (tmp_path / "plate.scad").write_text("square(1);\n")
    out = roachplan("scene", "check", "--scad-backend", backend, str(tmp_path / "plate.scad"))
    assert out.returncode == 1
    assert "12 triangles" not in out.stdout and "Traceback" not in out.stderr
    assert out.stdout.startswith(f"FAIL {tmp_path / 'plate.scad'}: ")
    assert (
        f"{tmp_path / 'plate.scad'}: the model is 2-D: its top level draws only flat shapes "
        in out.stdout
    )
    assert "no height" in out.stdout
    assert "`linear_extrude(height = 0.05) square(1);`" in out.stdout
    assert "CGAL" not in out.stdout  # not the binary's statistics


def test_an_unknown_parameter_names_the_models_variables():
    with pytest.raises(
        SceneError,
        match=r"parameter 'seperation' is not a variable of the model; its variables: .*separation",
    ):
        render_scad(LIBRARY / "double_bridge.scad", {"seperation": 0.8})


def test_a_render_past_its_time_limit_is_killed(tmp_path, fresh_cache):
    # A billion loop iterations: OpenSCAD would need minutes.
    scad = tmp_path / "slow.scad"
    scad.write_text(
        "x = [for (i = [0:999]) for (j = [0:999]) for (k = [0:999]) if (i < 0) i];\ncube(1);\n"
    )
    with pytest.raises(
        SceneError, match=r"slow\.scad: OpenSCAD did not finish within its time limit of 1 s"
    ):
        render_scad(scad, timeout=1.0, backend="cgal")
    running = subprocess.run(
        ["pgrep", "-f", str(scad)], capture_output=True, text=True, check=False
    )
    assert running.stdout == ""
    assert not list(fresh_cache.rglob("*.stl"))


@pytest.mark.skipif(not sandbox_available(), reason="no unprivileged user namespaces here")
def test_the_sandbox_shows_the_model_folder_and_hides_the_rest():
    # Belt and braces behind the static check: inside, only the model's folder is readable.
    with (
        tempfile.TemporaryDirectory(dir=Path.home()) as home_dir,
        tempfile.TemporaryDirectory() as tmp_dir,
    ):
        model, work = Path(home_dir) / "model", Path(tmp_dir)
        model.mkdir()
        (model / "m.scad").write_text("cube(1);")
        (Path(home_dir) / "secret.txt").write_text("secret")
        (work / "secret.txt").write_text("secret")
        # Shell built-ins only: the jail holds the program and its libraries, not `cat`.
        read = 'while IFS= read -r line || [ -n "$line" ]; do printf %s "$line"; done < '
        script = f"{read} m.scad; {read} {home_dir}/secret.txt; {read} {tmp_dir}/secret.txt"
        argv = ["sh", "-c", script]
        out = subprocess.run(
            confined(argv, model, work), capture_output=True, text=True, cwd=model, check=False
        )
    assert out.stdout == "cube(1);"
    assert "No such file" in out.stderr


def test_the_heightmap_worlds_height_field_reproduces_the_data_file():
    world = build_world(load_scene("heightmap"))
    rows = [
        [float(v) for v in line.split()]
        for line in (LIBRARY / "heightmap.dat").read_text().splitlines()
        if line and not line.startswith("#")
    ]
    data = np.array(rows) / 100  # [m]; row 0 at y = -2, column 0 at x = -1.5
    ys, xs = np.meshgrid(np.linspace(-2, 2, 81), np.linspace(-1.5, 1.5, 61), indexing="ij")
    (x0, y0), (x1, y1) = world.heightfield.covered_bounds()
    on = (xs >= x0) & (xs <= x1) & (ys >= y0) & (ys <= y1)
    xy = np.stack([xs[on], ys[on]], axis=-1)
    assert on.sum() > 4000
    np.testing.assert_allclose(world.heightfield.sample(xy), data[on], atol=1e-6)


# -- models in millimetres, parameters that do something, time limits ----------------------------


def scad_scene(folder: Path, obj: dict) -> Path:
    """A scene file in folder with one terrain object (start and goal on a 1 x 1 m top)."""
    data = {
        "terrain": [obj],
        "ground": None,
        "robot": {"start": [0.5, 0.2, 90]},
        "goal": [0.5, 0.8, 90],
        "bounds": [[0.3, 0.1], [0.7, 0.9]],
    }
    path = folder / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_scad_model_in_millimetres_is_refused_and_loads_with_scale(tmp_path, fresh_cache):
    (tmp_path / "plate.scad").write_text("size = [1000, 1000, 100];\ncube(size);\n")
    with pytest.raises(
        SceneError,
        match=r"terrain\[0\]\.scad: the mesh is 1000 m across; .*millimetres: add `scale: "
        r"0\.001` to this terrain object \(or --scale 0\.001\)",
    ):
        build_terrain_mesh(load_scene(scad_scene(tmp_path, {"scad": "plate.scad"})))
    scene = load_scene(scad_scene(tmp_path, {"scad": "plate.scad", "scale": 0.001}))
    assert scene.terrain[0].scale == (0.001, 0.001, 0.001)
    world = build_world(scene)  # the robot stands on the 10 cm high plate
    np.testing.assert_allclose(world.mesh.bounds, [[0, 0, 0], [1, 1, 0.1]], atol=1e-9)


MODULE_MODEL = """\
// a typical public model: one top-level setting, module parameters, a multi-line call
height = 2;
module post(width = 3,
            depth = 4) {
  inner = width / 2;
  cube([width, depth, height]);
}
function twice(x = 1) = 2 * x;
post(
  width = 5,
  depth = twice(1));
"""


def test_module_and_call_arguments_are_not_parameters(tmp_path, fresh_cache):
    scad = tmp_path / "post.scad"
    scad.write_text(MODULE_MODEL)
    assert scad_variables(scad) == {"height": "2"}
    for name in ("width", "depth", "inner", "x"):
        with pytest.raises(
            SceneError,
            match=rf"parameter '{name}' is not a variable of the model; its variables: height "
            r"\(the top-level assignments of post\.scad; module and function parameters",
        ):
            render_scad(scad, {name: 1})
    # The one real parameter does what it says: the post is 5 x 2 x 7.
    mesh = trimesh.load_mesh(render_scad(scad, {"height": 7}))
    np.testing.assert_allclose(mesh.extents, [5, 2, 7])
    with pytest.raises(SceneError, match=r"terrain\[0\]\.params\.width: 'width' is not a var"):
        load_scene(scad_scene(tmp_path, {"scad": "post.scad", "params": {"width": 9}}))


def test_variables_of_an_included_file_are_parameters_and_the_last_assignment_wins(tmp_path):
    (tmp_path / "settings.scad").write_text('label = "A";\nrows = 3;\nmodule m(k = 1) { j = 2; }\n')
    (tmp_path / "m.scad").write_text(
        "include <settings.scad>\nuse <lib.scad>\nrows = 4;\nif (rows > 3) { inside = 1; }\n"
    )
    (tmp_path / "lib.scad").write_text("hidden = 1;\n")
    assert scad_variables(tmp_path / "m.scad") == {"label": '"A"', "rows": "4"}


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("tall", r"'height' defaults to 2 in post\.scad, so it takes a number; got 'tall', a str"),
        (True, r"'height' defaults to 2 .* a number; got True, a boolean"),
    ],
)
def test_a_value_of_another_type_than_the_default_is_refused(
    tmp_path, fresh_cache, value, expected
):
    (tmp_path / "post.scad").write_text(MODULE_MODEL)
    with pytest.raises(SceneError, match=expected):
        render_scad(tmp_path / "post.scad", {"height": value})
    with pytest.raises(SceneError, match=r"terrain\[0\]\.params\.height: " + expected):
        load_scene(scad_scene(tmp_path, {"scad": "post.scad", "params": {"height": value}}))
    assert not list(fresh_cache.rglob("*.stl"))


def test_string_and_boolean_defaults_take_their_own_type_only(tmp_path):
    (tmp_path / "m.scad").write_text('label = "x";\nsolid = true;\nr = 2 * 3;\ncube(r);\n')
    with pytest.raises(SceneError, match=r"'label' defaults to \"x\" .* a string; got 5, a number"):
        load_scene(scad_scene(tmp_path, {"scad": "m.scad", "params": {"label": 5}}))
    with pytest.raises(SceneError, match=r"'solid' defaults to true .*; got 'no', a string"):
        load_scene(scad_scene(tmp_path, {"scad": "m.scad", "params": {"solid": "no"}}))
    scene = load_scene(
        scad_scene(tmp_path, {"scad": "m.scad", "params": {"label": "y", "solid": False, "r": 1.5}})
    )
    assert dict(scene.terrain[0].params) == {"label": "y", "r": 1.5, "solid": False}


@pytest.mark.parametrize("timeout", [1.0e9, 0, -5, float("inf"), "slow", True])
def test_an_absurd_time_limit_is_refused_cleanly(tmp_path, fresh_cache, timeout):
    (tmp_path / "m.scad").write_text("cube(1);\n")
    with pytest.raises(
        SceneError,
        match=r"terrain\[0\]\.timeout: expected a number of seconds "
        r"above 0 and at most 86400 \(24 h\)",
    ):
        load_scene(scad_scene(tmp_path, {"scad": "m.scad", "timeout": timeout}))
    if not isinstance(timeout, str):
        with pytest.raises(SceneError, match=r"m\.scad: render time limit: expected a number"):
            render_scad(tmp_path / "m.scad", timeout=timeout)


def test_the_default_time_limit_suits_slow_public_models_and_a_scene_can_set_one(tmp_path):
    (tmp_path / "m.scad").write_text("cube(1);\n")
    assert load_scene(scad_scene(tmp_path, {"scad": "m.scad"})).terrain[0].timeout >= 600
    assert (
        load_scene(scad_scene(tmp_path, {"scad": "m.scad", "timeout": 3600})).terrain[0].timeout
        == 3600.0
    )
