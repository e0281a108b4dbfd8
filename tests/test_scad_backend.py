"""The opt-in OpenSCAD backend `manifold` (issue 14, item 5): openscad-evaluator on the Manifold
library, measured against the real `openscad` binary (Debian's 2021.01, CGAL), which stays the
reference: every agreement below renders the same model with both, in the same jail.

Agreement tolerance. Both backends evaluate the same faceted primitives (the same $fn), so where
they agree the two surfaces coincide up to how each one rounds the new vertices of a boolean
operation and to the STL's float32 coordinates (7 digits). Measured (benchmarks/bench_openscad.py,
exact float64 distances): at most 1e-5 of the bounding-box diagonal (Hausdorff) on double_bridge,
its rough variant, voxel_wall and a CSG-heavy public-style model. AGREE = 1e-4 of the diagonal
is 0.1 mm on the 1 m scale of the library's ramps and bridges, a hundredth of the planner's 1 cm
height-field cell, so an agreeing mesh is the same terrain to the planner; ten times the measured
spread, so rounding does not fail it; and far below what does differ: the rough bridge with
another seed (bumps moved by up to 1.5 cm: 4e-3, checked below), text() placed 1.6 mm apart on a
10 cm plate (1.6e-2), surface()'s base 1 unit lower.
"""

from __future__ import annotations

import os
import re
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml
from conftest import ROOT, roachplan
from roachplan.scenes import LIBRARY, SceneError, load_scene, render_scad
from roachplan.scenes._manifold_main import openscad_rands
from roachplan.scenes._mesh import disagreement
from roachplan.scenes._openscad import (
    JAIL_OUT,
    _manifold_argv,
    _sandbox_available,
    confined,
    manifold_version,
)  # fmt: skip

AGREE = 1e-4
"""Largest surface distance between the two meshes [fraction of the bounding-box diagonal]."""
AGREE_P99 = 2e-5
"""Largest 99th percentile of that distance [fraction of the diagonal]: agreement is not a
few close points but the whole surface."""
AGREE_BOUNDS = 1e-5
"""Largest difference of the bounding boxes [fraction of the diagonal]."""

ROUGH = {"bump_columns": 20, "bump_rows": 40, "left_bump_height": 0.015,
         "right_bump_height": 0.010, "bump_seed": 0}  # fmt: skip
"""double_bridge_rough's params: 1,600 pyramids from OpenSCAD's seeded rands()."""

CSG_BOX = """// A vented box with softened edges: hull, minkowski, difference, intersection. Millimetres.
use <parts.scad>
inner = [50, 40, 20];
wall = 2;
$fn = 24;
outer = inner + [2 * wall, 2 * wall, wall];
difference() {
    rounded_box(outer, r = 4);
    translate([wall, wall, wall]) rounded_box([inner[0], inner[1], inner[2] + 1], r = 2);
    translate([10, 10, -1]) honeycomb([outer[0] - 20, outer[1] - 20, wall + 2], cell = 5, wall = 1.2);
}
translate([0, outer[1] + 5, 0]) minkowski() {
    cube([30, 10, 4]);
    sphere(r = 1.5, $fn = 12);
}
"""
"""A public-style model (hull, minkowski, a honeycomb of difference()s) using the shared helpers
of benchmarks/scad/parts.scad, without text() (which the backend refuses)."""

SECRET_HEIGHT = 7.0
"""Height of the secret solid outside a model's folder [model units]."""

needs_jail = pytest.mark.skipif(
    not _sandbox_available(), reason="no unprivileged user namespaces here (renders refuse)"
)


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path, monkeypatch):
    """An empty render cache per test, so both programs really run."""
    monkeypatch.setenv("ROACHPLAN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("ROACHPLAN_UNSAFE_SCAD", raising=False)






def _csg_box(tmp_path: Path) -> Path:
    folder = tmp_path / "box"
    folder.mkdir()
    (folder / "parts.scad").write_bytes((ROOT / "benchmarks" / "scad" / "parts.scad").read_bytes())
    (folder / "box.scad").write_text(CSG_BOX)
    return folder / "box.scad"


CASES = {
    "double_bridge": lambda tmp: (LIBRARY / "double_bridge.scad", {}),
    "double_bridge_rough": lambda tmp: (LIBRARY / "double_bridge.scad", ROUGH),
    "csg_box": lambda tmp: (_csg_box(tmp), {}),
}


@needs_jail
@pytest.mark.parametrize("name", CASES)
def test_manifold_agrees_with_the_binary(name, tmp_path):
    model, params = CASES[name](tmp_path)
    reference = trimesh.load(render_scad(model, params, backend="cgal"))
    fast_path = render_scad(model, params, backend="manifold")
    fast = trimesh.load(fast_path)
    assert fast.is_watertight and fast.volume > 0
    err = disagreement(reference, fast)
    assert err["bounds"] <= AGREE_BOUNDS, err
    assert err["p99"] <= AGREE_P99, err
    assert err["hausdorff"] <= AGREE, err
    assert abs(fast.volume - reference.volume) <= 1e-4 * reference.volume
    # Cached apart from the binary's render, under the backend's own key; a second render is
    # the cached file, not a new one.
    assert fast_path.name.startswith(f"{model.stem}-manifold-")
    stamp = fast_path.stat().st_mtime_ns
    assert render_scad(model, params, backend="manifold") == fast_path
    assert fast_path.stat().st_mtime_ns == stamp


@needs_jail
def test_the_tolerance_catches_a_real_difference():
    """Control: the same rough bridge with another seed (bumps moved) is not 'agreeing'."""
    a = trimesh.load(render_scad(LIBRARY / "double_bridge.scad", ROUGH, backend="cgal"))
    b = trimesh.load(
        render_scad(LIBRARY / "double_bridge.scad", {**ROUGH, "bump_seed": 1}, backend="manifold")
    )
    assert disagreement(a, b)["hausdorff"] > AGREE


@pytest.mark.parametrize("seed", [0, 7, 42, -3, 123456])
def test_seeded_rands_draws_what_openscad_draws(seed, tmp_path):
    (tmp_path / "r.scad").write_text(f"echo(rands(-2, 5, 6, {seed}));\ncube(1);\n")
    proc = subprocess.run(["openscad", "-o", str(tmp_path / "r.stl"), "r.scad"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60, check=True)  # fmt: skip
    echoed = re.search(r"ECHO: \[(.*)\]", proc.stderr).group(1)
    reference = [float(v) for v in echoed.split(",")]
    assert openscad_rands(-2, 5, 6, seed) == pytest.approx(reference, abs=1e-5)  # 6 digits


def _model(tmp_path: Path, code: str) -> Path:
    folder = tmp_path / "model"
    folder.mkdir(exist_ok=True)
    (folder / "m.scad").write_text(code)
    return folder / "m.scad"


def test_text_is_refused_with_the_construct_and_the_way_out(tmp_path):
    src = _model(tmp_path, 'cube([60, 20, 2]);\nlinear_extrude(4) text("ROACH", size = 8);\n')
    out = tmp_path / "out.stl"
    proc = roachplan("scene", "build", str(src), "-o", str(out), "--scale", "0.001",
                     "--scad-backend", "manifold")  # fmt: skip
    text = proc.stdout + proc.stderr
    assert proc.returncode != 0 and not out.exists()
    assert "Traceback" not in text
    assert f"{src}, line 2: text()" in text
    assert "backend: cgal" in text


def test_surface_is_refused_from_a_scene_file(tmp_path):
    src = _model(tmp_path, 'surface(file = "h.dat");\n')
    (src.parent / "h.dat").write_text("0 1\n1 0\n")
    scene = src.parent / "scene.yaml"
    scene.write_text(yaml.safe_dump({"terrain": [{"scad": "m.scad", "backend": "manifold"}]}))
    with pytest.raises(SceneError, match=r"line 1: surface\(\).*backend: cgal"):
        render_scad(src, backend=load_scene(scene).terrain[0].backend)


@needs_jail
def test_a_polyhedron_wound_the_other_way_is_refused():
    """plywood_bridge's ramps are wound counter-clockwise: the binary makes solids of them, the
    evaluator open shells; the check after the render says so instead of caching it."""
    with pytest.raises(SceneError, match=r"plywood_bridge.scad, line \d+: polyhedron\(\).*cgal"):
        render_scad(LIBRARY / "plywood_bridge.scad", backend="manifold")


@needs_jail
def test_a_non_integer_rands_seed_is_refused(tmp_path):
    src = _model(tmp_path, "h = rands(0, 1, 2, 0.5);\ncube([1, 1, 1 + h[0]]);\n")
    with pytest.raises(SceneError, match=r"seed 0.5.*backend: cgal"):
        render_scad(src, backend="manifold")


@needs_jail
def test_a_syntax_error_is_shown_with_its_line(tmp_path):
    src = _model(tmp_path, "cube(1);\nsphere(;\n")
    with pytest.raises(SceneError) as err:
        render_scad(src, backend="manifold")
    text = str(err.value)
    assert "backend manifold (openscad-evaluator 1.8.1" in text
    assert f"Syntax error in {src} at line 2" in text  # the jail's /model turned back


@needs_jail
def test_the_time_limit_stops_the_evaluator(tmp_path):
    src = _model(tmp_path, "x = [for (i = [0:999]) for (j = [0:999]) for (k = [0:999]) i];\n"
                           "cube(1);\n")  # fmt: skip
    t0 = time.monotonic()
    with pytest.raises(SceneError, match="did not finish within its time limit of 3 s"):
        render_scad(src, timeout=3, backend="manifold")
    assert time.monotonic() - t0 < 20
    assert not list((tmp_path / "cache" / "openscad").glob("*.stl"))


# -- the jail holds for the evaluator too -----------------------------------------------------


def _outside(tmp_path: Path) -> Path:
    out = tmp_path / "outside"
    out.mkdir()
    box = trimesh.creation.box(extents=(1, 1, SECRET_HEIGHT))
    box.apply_translation((0.5, 0.5, SECRET_HEIGHT / 2))
    box.export(out / "secret.stl")
    (out / "secret.scad").write_text(f"cube([1, 1, {SECRET_HEIGHT}]);\n")
    return out


@needs_jail
@pytest.mark.parametrize("code", ["import(\"../outside/secret.stl\");",
                                  "include <../outside/secret.scad>"])  # fmt: skip
def test_the_scan_refuses_an_outside_file(code, tmp_path):
    _outside(tmp_path)
    src = _model(tmp_path, "cube(1);\n" + code + "\n")
    out = tmp_path / "out.stl"
    proc = roachplan("scene", "build", str(src), "-o", str(out), "--scad-backend", "manifold")
    assert proc.returncode != 0 and not out.exists()
    assert "'..'" in proc.stderr and "Traceback" not in proc.stderr


JAIL_CASES = {
    "absolute-import": 'cube(1);\nimport(str("{out}", "/secret.stl"));',
    "absolute-include": "cube(1);\ninclude <{out}/secret.scad>",
}


@needs_jail
@pytest.mark.parametrize("name", JAIL_CASES)
def test_the_jail_alone_keeps_the_secret_from_the_evaluator(name, tmp_path):
    """Models the scan would refuse, run by the evaluator directly: without the jail it reads
    the secret (the control), in the jail it cannot."""
    out = _outside(tmp_path)
    src = _model(tmp_path, JAIL_CASES[name].replace("{out}", str(out)) + "\n")
    for jail in (False, True):
        work = tmp_path / f"work-{jail}"
        (work / "out").mkdir(parents=True)
        model = "/model/m.scad" if jail else str(src)
        target = f"{JAIL_OUT}/mesh.stl" if jail else str(work / "out" / "mesh.stl")
        argv, layout = _manifold_argv(model, target)
        cmd = confined(argv, src.parent, work, jail=jail, layout=layout)
        proc = subprocess.run(cmd, cwd=src.parent, capture_output=True, text=True, timeout=120,
                              check=False)  # fmt: skip
        mesh = work / "out" / "mesh.stl"
        if not jail:
            assert proc.returncode == 0, proc.stderr
            assert trimesh.load(mesh).bounds[1][2] >= SECRET_HEIGHT - 1e-6
        else:
            assert not mesh.exists() or trimesh.load(mesh).bounds[1][2] < SECRET_HEIGHT / 2, (
                proc.stderr
            )


@needs_jail
def test_the_jail_shows_the_evaluator_only_its_own_packages(tmp_path):
    (tmp_path / "model").mkdir()
    (tmp_path / "work").mkdir()
    argv, layout = _manifold_argv("/model/m.scad", f"{JAIL_OUT}/mesh.stl")
    python, paths = argv[0], argv[5]
    probe = (
        "import sys, json, os; sys.path[:0] = json.loads(sys.argv[1])\n"
        "import manifold3d, openscad_evaluator\n"
        "for name in ('trimesh', 'roachplan', 'yaml'):\n"
        "    try:\n        __import__(name); print('imported', name)\n"
        "    except ImportError:\n        print('hidden', name)\n"
        f"print(os.path.exists({str(ROOT / 'README.md')!r}), os.path.exists('/etc/passwd'))\n"
    )
    cmd = confined([python, "-I", "-S", "-c", probe, paths], tmp_path / "model", tmp_path / "work",
                   layout=layout)  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split("\n")[:4] == ["hidden trimesh", "hidden roachplan", "hidden yaml",
                                           "False False"]  # fmt: skip
    # The same probe outside the jail does see them: the jail hides them, not their absence.
    outside = subprocess.run([python, "-I", "-S", "-c", probe, paths], capture_output=True,
                             text=True, timeout=60, check=False)  # fmt: skip
    assert "imported trimesh" in outside.stdout and "True True" in outside.stdout


# -- the setting: scene key, command line -------------------------------------------------------


@pytest.mark.parametrize("value", ["fast", "CGAL", 1, None, ["manifold"]])
def test_a_bad_backend_value_is_refused(value, tmp_path):
    _model(tmp_path, "cube(1);\n")
    scene = tmp_path / "model" / "scene.yaml"
    scene.write_text(yaml.safe_dump({"terrain": [{"scad": "m.scad", "backend": value}]}))
    with pytest.raises(SceneError) as err:
        load_scene(scene)
    assert "terrain[0].backend" in str(err.value) and "cgal, manifold" in str(err.value)


def test_backend_on_a_mesh_object_is_refused(tmp_path):
    trimesh.creation.box(extents=(1, 1, 0.1)).export(tmp_path / "m.stl")
    scene = tmp_path / "scene.yaml"
    scene.write_text(yaml.safe_dump({"terrain": [{"mesh": "m.stl", "backend": "manifold"}]}))
    with pytest.raises(SceneError, match=r"terrain\[0\]\.backend.*only a scad object"):
        load_scene(scene)


def test_a_bad_backend_flag_is_refused():
    proc = roachplan("scene", "build", "double_bridge", "-o", os.devnull, "--scad-backend", "fast")
    assert proc.returncode == 2
    assert "--scad-backend" in proc.stderr and "'cgal', 'manifold'" in proc.stderr
    assert "Traceback" not in proc.stderr


@needs_jail
def test_scene_build_with_the_manifold_backend(tmp_path):
    out = tmp_path / "out.stl"
    proc = roachplan("scene", "build", "double_bridge", "-o", str(out), "--scad-backend",
                     "manifold")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    built = trimesh.load(out)
    assert np.allclose(built.bounds[1][2], 0.2, atol=1e-6)
    cached = list((tmp_path / "cache" / "openscad").glob("double_bridge-manifold-*.stl"))
    assert len(cached) == 1
    assert manifold_version().startswith("openscad-evaluator ")


# -- the page: the load panel's OpenSCAD backend -------------------------------------------------

PLATFORM = """// Metres: a hull()ed platform with a hole, and a minkowski()-rounded rail.
difference() {
    hull() for (x = [0, 1.5], y = [0, 1]) translate([x, y, 0]) cylinder(r = 0.1, h = 0.05, $fn = 24);
    translate([0.75, 0.5, 0]) cylinder(r = 0.2, h = 1, center = true, $fn = 24);
}
translate([0, 1.3, 0]) minkowski() { cube([1.5, 0.2, 0.03]); sphere(r = 0.02, $fn = 8); }
"""


def _dropdown(page, label: str, option: str) -> None:
    row = page.locator(f"xpath=//label[text()='{label}']/ancestor::div[.//input][1]")
    row.locator("input:visible").first.click()
    page.get_by_role("option", name=option, exact=True).click()


@needs_jail
def test_the_page_renders_with_the_backend_chosen_and_says_why_it_refuses(tmp_path, artifacts):
    from test_app import CHROMIUM, browser_pages, title, upload

    if CHROMIUM is None:
        pytest.skip("Debian chromium not installed")
    from conftest import free_port
    from roachplan.app._server import RoachApp
    from roachplan.scenes import build_world

    app = RoachApp(build_world(load_scene("double_bridge")), host="127.0.0.1", port=free_port())
    try:
        text_model = tmp_path / "label.scad"
        text_model.write_text('cube([1, 1, 0.02]);\nlinear_extrude(0.01) text("R", size = 0.5);\n')
        platform = tmp_path / "platform.scad"
        platform.write_text(PLATFORM)
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            _dropdown(page, "OpenSCAD backend", "manifold")
            upload(page, text_model)
            page.get_by_text(re.compile(r"line 2: text\(\) is not rendered alike by backend "
                                        r"manifold")).wait_for(timeout=60_000)  # fmt: skip
            page.get_by_text(re.compile(r"set Scene → OpenSCAD backend to cgal")).first.wait_for()
            page.screenshot(path=artifacts / "backend-01-text-refused.png")
            assert "double_bridge" in title(page)
            upload(page, platform)
            page.get_by_text(re.compile(r"Loaded `?platform")).wait_for(timeout=120_000)
            page.screenshot(path=artifacts / "backend-02-manifold-loaded.png")
            assert "platform" in title(page)
        raw = yaml.safe_load(app.world.scene.path.read_text())
        assert raw["terrain"][0]["backend"] == "manifold"
        # The page's load ran in a child of the app's fork server, which may have started
        # before this test's render cache was set: the same render (cached by content) here.
        rendered = render_scad(platform, backend="manifold")
        # The page's terrain is that render, and it agrees with the binary's.
        reference = trimesh.load(render_scad(platform, backend="cgal"))
        err = disagreement(reference, trimesh.load(rendered))
        assert err["hausdorff"] <= AGREE, err
        assert np.allclose(app.world.mesh.bounds[1][2], reference.bounds[1][2], atol=1e-4)
    finally:
        app.stop()
