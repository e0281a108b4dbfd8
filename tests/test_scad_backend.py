"""The OpenSCAD backends: `auto` (the default) renders with `manifold`, openscad-evaluator on the
Manifold library, where it renders the model as the real `openscad` binary (Debian's 2021.01,
CGAL) does, and with the binary otherwise, saying which and why. The binary stays the
reference: every agreement below renders the same model with both, in the same jail.

Agreement tolerance. Both backends evaluate the same faceted primitives (the same $fn), so where
they agree the two surfaces coincide up to how each one rounds the new vertices of a boolean
operation and to the STL's float32 coordinates (7 digits). Measured (benchmarks/bench_openscad.py,
exact float64 distances): at most 1e-5 of the bounding-box diagonal (Hausdorff) on double_bridge,
its rough variant, voxel_wall and a CSG-heavy public-style model. AGREE = 1e-4 of the diagonal
is 0.1 mm on the 1 m scale of the library's ramps and bridges, a hundredth of the planner's 1 cm
height-field cell, so an agreeing mesh is the same terrain to the planner; ten times the measured
spread, so rounding does not fail it; and far below what does differ: the rough bridge with
another seed (bumps moved by up to 1.5 cm: 4e-3, checked below), surface()'s base 1 unit lower,
solids touching face to face left apart (plywood_bridge before they were merged: walls 6.7 cm
inside the solid; tests/test_scad_procedural.py). text() has its own bound, in model units per
unit of its size (TEXT_DEVIATION, checked below).
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
from roachplan.scenes import (
    LIBRARY,
    SceneError,
    build_terrain,
    load_scene,
    render_scad,
    render_scad_result,
)
from roachplan.scenes._manifold_main import openscad_quad_diagonal, openscad_rands
from roachplan.scenes._mesh import clean_terrain_mesh, disagreement, surface_distances
from roachplan.scenes._scad_manifold import TEXT_DEVIATION, manifold_argv, manifold_version
from roachplan.scenes._scad_sandbox import (
    JAIL_OUT,
    confined,
    render_warnings,
    sandbox_available,
)

AGREE = 1e-4
"""Largest surface distance between the two meshes [fraction of the bounding-box diagonal]."""
AGREE_P99 = 2e-5
"""Largest 99th percentile of that distance [fraction of the diagonal]: agreement is not a
few close points but the whole surface."""
AGREE_BOUNDS = 1e-5
"""Largest difference of the bounding boxes [fraction of the diagonal]."""

ROUGH = {
    "bump_columns": 20,
    "bump_rows": 40,
    "left_bump_height": 0.015,
    "right_bump_height": 0.010,
    "bump_seed": 0,
}
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
of benchmarks/scad/parts.scad."""

SECRET_HEIGHT = 7.0
"""Height of the secret solid outside a model's folder [model units]."""

needs_jail = pytest.mark.skipif(
    not sandbox_available(), reason="no unprivileged user namespaces here (renders refuse)"
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


@pytest.mark.slow
@needs_jail
@pytest.mark.parametrize("name", CASES)
def test_manifold_agrees_with_the_binary(name, tmp_path):
    model, params = CASES[name](tmp_path)
    reference = trimesh.load_mesh(render_scad(model, params, backend="cgal"))
    fast_path = render_scad(model, params, backend="manifold")
    fast = trimesh.load_mesh(fast_path)
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


def _library_objects() -> dict:
    """Each distinct OpenSCAD object of the library's scenes: (model, params, backend)."""
    from roachplan.scenes import list_scenes

    out = {}
    for name in list_scenes():
        for obj in load_scene(name).terrain:
            if obj.kind == "scad":
                out.setdefault((obj.source.name, obj.params), (name, obj))
    return {name: obj for name, obj in out.values()}


LIBRARY_BACKENDS = {
    "double_bridge": "manifold",
    "double_bridge_rough": "manifold",
    "heightmap": "cgal",
    "plywood_bridge": "manifold",
    "voxel_wall": "manifold",
}
"""Who auto picks for each library model: surface() (heightmap) goes to the binary; the solids
of plywood_bridge that touch face to face are merged as the binary merges them."""


@pytest.mark.slow
@needs_jail
@pytest.mark.parametrize("name", LIBRARY_BACKENDS)
def test_every_library_model_renders_by_default_as_the_binary_renders_it(name):
    obj = _library_objects()[name]
    assert obj.backend == "auto"  # the library's scenes say nothing: the default
    auto = render_scad_result(obj.source, dict(obj.params), backend=obj.backend)
    assert auto.backend == LIBRARY_BACKENDS[name], auto.note()
    reference = trimesh.load_mesh(render_scad(obj.source, dict(obj.params), backend="cgal"))
    err = disagreement(reference, trimesh.load_mesh(auto.path))
    assert err["bounds"] <= AGREE_BOUNDS and err["hausdorff"] <= AGREE, err


PUBLIC_TILE = ROOT / "tests" / "data" / "public_tile"
"""A public-style terrain tile (ours): millimetres, settings from an include, modules from a
use, a height-field polyhedron wound inward, an embossed text() label and an engraved one."""


@needs_jail
def test_a_public_style_tile_loads_with_manifold_by_default_and_says_what_it_may_change(tmp_path):
    (tmp_path / "tile").mkdir()
    for f in PUBLIC_TILE.iterdir():
        (tmp_path / "tile" / f.name).write_bytes(f.read_bytes())
    scene = tmp_path / "tile" / "scene.yaml"
    scene.write_text(
        yaml.safe_dump({"terrain": [{"scad": "tile.scad", "scale": 0.02}], "ground": 0})
    )
    terrain = build_terrain(load_scene(scene))
    (note,) = terrain.notes
    assert re.fullmatch(
        r"tile\.scad: rendered with manifold \(openscad-evaluator 1\.8\.1, "
        r"manifold3d 3\.5\.4\) in [\d.]+ s; text\(\): glyphs may sit up to "
        r"0\.009 model units from OpenSCAD's \(0\.15% of their size, up to 6 "
        r"here\), 0\.18 mm of terrain at scale 0\.02",
        note,
    ), note
    # 80 x 60 mm at 0.02 m per mm; the hills at most 3 + 6 mm up.
    np.testing.assert_allclose(terrain.mesh.bounds[:, :2], [[0, 0], [1.6, 1.2]], atol=1e-6)
    assert 0.02 * 3 < terrain.mesh.bounds[1][2] <= 0.02 * 9
    # The binary's render of the same tile, the reference: the same terrain.
    binary = trimesh.load_mesh(render_scad(tmp_path / "tile" / "tile.scad", backend="cgal"))
    fast = trimesh.load_mesh(render_scad(tmp_path / "tile" / "tile.scad"))
    assert fast.is_watertight and fast.volume > 0  # the inward height field made a solid
    d = np.concatenate([surface_distances(binary, fast), surface_distances(fast, binary)])
    assert d.max() <= TEXT_DEVIATION * 6  # the labels' bound; the rest agrees closer still
    assert np.quantile(d, 0.99) <= AGREE_P99 * np.linalg.norm(binary.extents)


@pytest.mark.slow
@needs_jail
def test_the_tolerance_catches_a_real_difference():
    """Control: the same rough bridge with another seed (bumps moved) is not 'agreeing'."""
    a = trimesh.load_mesh(render_scad(LIBRARY / "double_bridge.scad", ROUGH, backend="cgal"))
    b = trimesh.load_mesh(
        render_scad(LIBRARY / "double_bridge.scad", {**ROUGH, "bump_seed": 1}, backend="manifold")
    )
    assert disagreement(a, b)["hausdorff"] > AGREE


@pytest.mark.parametrize("seed", [0, 7, 42, -3, 123456])
def test_seeded_rands_draws_what_openscad_draws(seed, tmp_path):
    (tmp_path / "r.scad").write_text(f"echo(rands(-2, 5, 6, {seed}));\ncube(1);\n")
    proc = subprocess.run(
        ["openscad", "-o", str(tmp_path / "r.stl"), "r.scad"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    echo = re.search(r"ECHO: \[(.*)\]", proc.stderr)
    assert echo is not None, proc.stderr
    echoed = echo.group(1)
    reference = [float(v) for v in echoed.split(",")]
    assert openscad_rands(-2, 5, 6, seed) == pytest.approx(reference, abs=1e-5)  # 6 digits


def _model(tmp_path: Path, code: str) -> Path:
    folder = tmp_path / "model"
    folder.mkdir(exist_ok=True)
    (folder / "m.scad").write_text(code)
    return folder / "m.scad"


TEXTS = {
    "default-font": 'text("Roach terrain 42", size = 2);',
    "bold-fallback-font": 'text("GITHUB.COM/ORSOERIC", size = 3, spacing = 1.1, '
    'font = "Futura:style=Bold");',
    "centred": 'text("Tile #7 - grass", size = 5, halign = "center", valign = "center");',
    "right-top": 'text("Wq@&%$ Roach 42", size = 10, halign = "right", valign = "top");',
    "bottom-fn": 'text("Sg", size = 20, valign = "bottom", $fn = 24);',
}
"""text() calls of public models: OpenSCAD's default font (fontconfig's DejaVu Sans here), a
font this system lacks (fontconfig's fallback, DejaVu Sans Bold), alignments, $fn."""


@pytest.mark.slow
@needs_jail
@pytest.mark.parametrize("name", TEXTS)
def test_text_renders_within_the_stated_deviation_of_the_binary(name, tmp_path):
    src = _model(tmp_path, f"cube([1, 1, 1]);\nlinear_extrude(2) {TEXTS[name]}\n")
    reference = trimesh.load_mesh(render_scad(src, backend="cgal"))
    fast = render_scad_result(src, backend="manifold")
    size_arg = re.search(r"size = (\d+)", TEXTS[name])
    assert size_arg is not None  # every TEXTS call has a size
    size = float(size_arg.group(1))
    assert fast.backend == "manifold" and fast.text_size == pytest.approx(size)
    mesh = trimesh.load_mesh(fast.path)
    d = np.concatenate([surface_distances(reference, mesh), surface_distances(mesh, reference)])
    assert d.max() <= TEXT_DEVIATION * size, (d.max(), TEXT_DEVIATION * size)
    assert len(mesh.faces) == pytest.approx(len(reference.faces), rel=0.02)  # same curve cuts
    assert "text(): glyphs may sit up to" in fast.note(scale=0.02)


@pytest.mark.slow
@needs_jail
def test_the_text_bound_catches_glyphs_moved_by_more(tmp_path):
    """Control: the same label moved by twice the bound is not within it."""
    code = 'linear_extrude(2) translate([{dx}, 0]) text("ROACH 7", size = 6);\n'
    src = _model(tmp_path, code.format(dx=0))
    moved = tmp_path / "moved.scad"
    moved.write_text(code.format(dx=2 * TEXT_DEVIATION * 6))
    a = trimesh.load_mesh(render_scad(moved, backend="cgal"))
    b = trimesh.load_mesh(render_scad(src, backend="manifold"))
    assert surface_distances(a, b).max() > TEXT_DEVIATION * 6


@needs_jail
def test_text_is_rendered_by_manifold_with_its_deviation_in_metres_of_terrain(tmp_path):
    src = _model(tmp_path, 'cube([60, 20, 2]);\nlinear_extrude(4) text("ROACH", size = 8);\n')
    out = tmp_path / "out.stl"
    proc = roachplan(
        "scene", "build", str(src), "-o", str(out), "--scale", "0.02", "--scad-backend", "manifold"
    )
    assert proc.returncode == 0, proc.stderr
    # 0.15 % of size 8 is 0.012 model units; at 0.02 m per unit, 0.24 mm of terrain.
    assert re.search(
        r"m\.scad: rendered with manifold \(openscad-evaluator 1\.8\.1, manifold3d "
        r"3\.5\.4\) in [\d.]+ s; text\(\): glyphs may sit up to 0\.012 model units "
        r"from OpenSCAD's \(0\.15% of their size, up to 8 here\), 0\.24 mm of terrain "
        r"at scale 0\.02",
        proc.stderr,
    ), proc.stderr
    assert trimesh.load_mesh(out).extents[0] == pytest.approx(1.2, abs=1e-6)


def test_surface_is_refused_from_a_scene_file(tmp_path):
    src = _model(tmp_path, 'surface(file = "h.dat");\n')
    (src.parent / "h.dat").write_text("0 1\n1 0\n")
    scene = src.parent / "scene.yaml"
    scene.write_text(yaml.safe_dump({"terrain": [{"scad": "m.scad", "backend": "manifold"}]}))
    with pytest.raises(SceneError, match=r"line 1: surface\(\).*backend: cgal.*backend: auto"):
        render_scad(src, backend=load_scene(scene).terrain[0].backend)


INWARD_CUBE = """pts = [[0,0,0],[10,0,0],[10,10,0],[0,10,0],[0,0,5],[10,0,5],[10,10,5],[0,10,5]];
// every face counter-clockwise seen from outside: the other way from what OpenSCAD asks
module inward() polyhedron(pts, [[3,2,1,0],[5,6,7,4],[1,5,4,0],[2,6,5,1],[3,7,6,2],[0,4,7,3]]);
"""


@needs_jail
def test_a_polyhedron_wound_the_other_way_is_made_a_solid_as_the_binary_makes_it(tmp_path):
    """In a union the binary's CGAL makes a solid of an inward polyhedron (measured: 508 =
    500 + the 8 of the cube outside it); the evaluator's union with it was an open shell of
    volume -484 before _manifold_main.py turned its faces round."""
    src = _model(
        tmp_path, INWARD_CUBE + "union() { inward(); translate([5, 5, 4]) cube([2, 2, 3]); }\n"
    )
    reference = trimesh.load_mesh(render_scad(src, backend="cgal"))
    fast = trimesh.load_mesh(render_scad(src, backend="manifold"))
    assert reference.volume == pytest.approx(508.0)
    assert fast.is_watertight and fast.is_winding_consistent
    assert fast.volume == pytest.approx(508.0)
    err = disagreement(reference, fast)
    assert err["hausdorff"] <= AGREE, err


@needs_jail
def test_a_lone_inward_polyhedron_is_the_same_terrain_as_the_binarys(tmp_path):
    """Alone the binary exports it as given, inside out; roachplan's cleaning turns that
    outward. The evaluator's is outward already: the same cleaned mesh."""
    src = _model(tmp_path, INWARD_CUBE + "inward();\n")
    reference = trimesh.load_mesh(render_scad(src, backend="cgal"))
    fast = trimesh.load_mesh(render_scad(src, backend="manifold"))
    assert reference.volume == pytest.approx(-500.0)  # the binary's, as given
    assert fast.volume == pytest.approx(500.0)
    a, b = (clean_terrain_mesh(m, "cube") for m in (reference, fast))
    assert a.volume == pytest.approx(b.volume) and disagreement(a, b)["hausdorff"] <= AGREE


def _height_field(seed: int, cells: int = 10, inward: bool = False) -> str:
    """A height-field block as generated public terrains make one: a polyhedron whose top is
    a grid of non-planar quadrilaterals (heights 2-8, the grid's points moved by up to a
    quarter cell, so that some cells are decided by the sweep, some by the Delaunay flip),
    listed as OpenSCAD asks, or the other way round (inward)."""
    rng = np.random.default_rng(seed)
    n = cells + 1
    xy = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="xy"), -1).reshape(-1, 2) * 10.0
    inner = (xy > 0).all(1) & (xy < cells * 10).all(1)
    xy[inner] += rng.uniform(-2.5, 2.5, (inner.sum(), 2))
    top = np.column_stack([xy, rng.uniform(2, 8, len(xy))])
    pts = np.vstack([top, np.column_stack([xy, np.zeros(len(xy))])])
    k = lambda i, j: j * n + i  # noqa: E731
    faces = [
        [k(i, j + 1), k(i + 1, j + 1), k(i + 1, j), k(i, j)]  # clockwise from above
        for j in range(cells)
        for i in range(cells)
    ]
    faces.append(
        [n * n + k(i, 0) for i in range(n)]
        + [n * n + k(cells, j) for j in range(1, n)]
        + [n * n + k(i, cells) for i in range(cells - 1, -1, -1)]
        + [n * n + k(0, j) for j in range(cells - 1, 0, -1)]
    )
    ring = (
        [k(i, 0) for i in range(n)]
        + [k(cells, j) for j in range(1, n)]
        + [k(i, cells) for i in range(cells - 1, -1, -1)]
        + [k(0, j) for j in range(cells - 1, 0, -1)]
    )
    for a, b in zip(ring, ring[1:] + ring[:1]):  # the sides, clockwise from outside
        faces.append([a, b, n * n + b, n * n + a])
    if inward:
        faces = [f[::-1] for f in faces]
    text = ", ".join(f"[{x:.4f}, {y:.4f}, {z:.4f}]" for x, y, z in pts)
    return f"polyhedron([{text}], {faces});\n"


@needs_jail
@pytest.mark.parametrize("inward", [False, True], ids=["as-asked", "inward"])
def test_a_height_fields_quadrilaterals_are_cut_as_the_binary_cuts_them(inward, tmp_path):
    """A height field's cells are non-planar quadrilaterals, and which diagonal cuts each one
    moves the surface: the evaluator's own choice differed from the binary's libtess2 in 54 %
    of the public tile's cells (surfaces 0.09 of 80 model units apart); cut as the binary
    does (_manifold_main.openscad_quad_diagonal) they agree. In a union, as public models put
    them."""
    src = _model(
        tmp_path,
        "union() {\n"
        + _height_field(seed=5, inward=inward)
        + "translate([-5, -5, 0]) cube([10, 10, 3]);\n}\n",
    )
    reference = trimesh.load_mesh(render_scad(src, backend="cgal"))
    fast = trimesh.load_mesh(render_scad(src, backend="manifold"))
    assert fast.is_watertight and fast.volume > 0
    err = disagreement(reference, fast)
    assert err["hausdorff"] <= AGREE, err


def test_the_quad_rule_picks_the_binarys_diagonal_on_recorded_faces():
    """Faces whose diagonal Debian's binary was seen to choose (corners in the polyhedron()
    call's order): a rectangle either way round (a tie, decided by the sweep), a kite (the
    Delaunay flip) and a near-tie inside libtess2's pi + 0.01 slack."""

    def cut(quad):  # the diagonal's ends, (x, y)
        return sorted(tuple(quad[i][:2]) for i in openscad_quad_diagonal(quad))

    rect = [[0, 10, 7], [10, 10, 5], [10, 0, 7], [0, 0, 5]]  # clockwise from above
    assert cut(rect) == [(0, 10), (10, 0)]
    assert cut(rect[::-1]) == [(0, 0), (10, 10)]
    kite = [[10, 2, 6.5], [20, 0, 5], [10, -2, 6], [0, 0, 5]]
    assert cut(kite) == [(10, -2), (10, 2)]  # the short one
    skew = [[-1, 9, 7], [11, 10, 5], [10, -1, 7], [0, 0, 5]]  # opposite angles 178 deg
    assert cut(skew) == [(0, 0), (11, 10)]
    # A public fractal terrain's cell, twisted so far that it crosses itself seen along x,
    # libtess2's axis for it: the binary joins the first and third corners listed.
    twisted = [
        [-43.75, 31.25, 36.284],
        [-43.75, 37.5, 38.475],
        [-37.5, 37.5, 32.163],
        [-37.5, 31.25, 37.078],
    ]
    assert cut(twisted) == [(-43.75, 31.25), (-37.5, 37.5)]
    assert cut(twisted[1:] + twisted[:1]) == [(-43.75, 37.5), (-37.5, 31.25)]


NEAR_TOUCH = "cube(1);\ntranslate([1.0000004, 0, 0]) cube([1, 1, 2]);\n"
"""Two blocks 4e-7 apart: one plane to the touching check, no closed solid once cut."""


@needs_jail
def test_solids_touching_face_to_face_that_cannot_be_merged_go_to_the_binary(tmp_path):
    """Solids that touch face to face are merged (plywood_bridge:
    tests/test_scad_procedural.py); where that does not give a closed solid (here, two blocks
    not quite touching), manifold refuses, and auto says why and renders with the binary."""
    src = _model(tmp_path, NEAR_TOUCH)
    with pytest.raises(
        SceneError,
        match=r"m.scad: solids that touch face to face "
        r"\(near \[.*\]\) stay apart in backend manifold.*backend: auto",
    ):
        render_scad(src, backend="manifold")
    auto = render_scad_result(src)
    assert auto.backend == "cgal" and auto.asked == "auto"
    assert "solids that touch face to face" in auto.why
    assert auto.path == render_scad(src, backend="cgal")
    plywood = render_scad_result(LIBRARY / "plywood_bridge.scad")
    assert plywood.backend == "manifold" and plywood.merged > 0
    assert "solids touching face to face (on " in plywood.note()


@needs_jail
def test_a_non_integer_rands_seed_is_refused_and_auto_remembers_it(tmp_path):
    src = _model(tmp_path, "h = rands(0, 1, 2, 0.5);\ncube([1, 1, 1 + h[0]]);\n")
    with pytest.raises(SceneError, match=r"seed 0.5.*backend: cgal"):
        render_scad(src, backend="manifold")
    auto = render_scad_result(src)
    assert auto.backend == "cgal" and not auto.cached
    assert auto.why.startswith(
        "backend manifold could not render it alike: rands() with the seed 0.5"
    )
    assert "rendered with the openscad binary in" in auto.note()
    # Next time straight to the binary's cached mesh, for the same reason.
    again = render_scad_result(src)
    assert again.cached and again.path == auto.path and again.why == auto.why


FLAT_MODELS = {
    "square": ("square(1);\n", {}),
    "lifted": ("translate([0, 0, 2]) circle(0.5, $fn = 12);\n", {}),
    "params": ("w = 1;\nsquare([w, 2]);\n", {"w": 3}),
}
"""Models whose top level is 2-D: the binary refuses them ("Current top level object is not a
3D object"); openscad-evaluator wrote its preview instead, the shape extruded 1 unit up from
where it lies (square(1): a 1 x 1 x 1 cube of 12 triangles, loaded as terrain)."""


@needs_jail
@pytest.mark.parametrize("backend", ["cgal", "manifold", "auto"])
@pytest.mark.parametrize("name", sorted(FLAT_MODELS))
def test_a_2d_model_is_refused_by_every_backend(name, backend, tmp_path):
    code, params = FLAT_MODELS[name]
    src = _model(tmp_path, code)
    with pytest.raises(SceneError) as err:
        render_scad(src, params, backend=backend)
    text = str(err.value)
    assert text.startswith(f"{src}: the model is 2-D: its top level draws only flat shapes")
    assert "which have no height, so it is no terrain" in text
    assert (
        "extrude what it draws into a solid, e.g. `linear_extrude(height = 0.05) square(1);`"
        in text
    )
    assert "backend auto gave it to the binary" not in text  # auto: manifold's own refusal
    assert not list((tmp_path / "cache" / "openscad").glob("*.stl"))  # nothing cached


@needs_jail
def test_a_solid_shaped_like_the_evaluators_2d_stand_in_is_rendered(tmp_path):
    """A slab 1 unit thick is also what a real extrusion makes: the evaluator is asked for the
    model as a drawing, which it refuses for a 3-D model, and the slab renders."""
    cases = {
        "linear_extrude(1) square(1);\n": [[0, 0, 0], [1, 1, 1]],
        "translate([0, 0, 0.5]) linear_extrude(1) square([2, 1]);\n": [[0, 0, 0.5], [2, 1, 1.5]],
    }
    for code, bounds in cases.items():
        src = _model(tmp_path, code)
        for backend in ("cgal", "manifold"):
            mesh = trimesh.load_mesh(render_scad(src, backend=backend))
            assert np.allclose(mesh.bounds, bounds), (code, backend)
        assert render_scad_result(src).backend == "manifold"


@needs_jail
def test_a_2d_stand_in_cached_before_the_refusal_is_refused(tmp_path):
    """A render cache from before 2-D models were refused may hold the evaluator's slab."""
    from roachplan.scenes._openscad import _cache_path

    src = _model(tmp_path, "square(1);\n")
    cached = _cache_path("manifold", src.resolve(), {}, [])
    cached.parent.mkdir(parents=True)
    trimesh.creation.box((1, 1, 1), trimesh.transformations.translation_matrix([0.5] * 3)).export(
        cached
    )
    with pytest.raises(SceneError, match=r"m\.scad: the model is 2-D"):
        render_scad(src, backend="manifold")


# -- auto, the default: who renders, and the note that says so ------------------------------------


@needs_jail
def test_auto_renders_a_plain_model_with_manifold_and_says_so(tmp_path):
    src = _model(tmp_path, PLATFORM)
    auto = render_scad_result(src)
    assert (auto.asked, auto.backend, auto.why) == ("auto", "manifold", "")
    assert re.fullmatch(
        r"m\.scad: rendered with manifold \(openscad-evaluator 1\.8\.1, "
        r"manifold3d 3\.5\.4\) in \d+\.\d s",
        auto.note(),
    ), auto.note()
    reference = trimesh.load_mesh(render_scad(src, backend="cgal"))
    assert disagreement(reference, trimesh.load_mesh(auto.path))["hausdorff"] <= AGREE
    again = render_scad_result(src)
    assert again.cached and again.path == auto.path
    assert again.note().endswith(" s (cached)")


@needs_jail
def test_auto_renders_surface_with_the_binary_and_says_why(tmp_path):
    src = _model(tmp_path, 'cube(1);\nsurface(file = "h.dat");\n')
    (src.parent / "h.dat").write_text("0 1\n1 0\n")
    auto = render_scad_result(src)
    assert auto.backend == "cgal" and auto.asked == "auto"
    assert auto.note().startswith("m.scad: rendered with the openscad binary in ")
    assert auto.note().endswith(
        ": surface() (m.scad, line 2) is rendered differently by "
        "manifold (its base is at z = 0, not 1 below the lowest height "
        "as in OpenSCAD)"
    )
    assert not list((tmp_path / "cache" / "openscad").glob("*-manifold-*"))  # never tried


@needs_jail
def test_the_cache_keys_the_backend_that_rendered(tmp_path):
    src = _model(tmp_path, "cube([2, 3, 4]);\n")
    binary = render_scad_result(src, backend="cgal")
    fast = render_scad_result(src, backend="manifold")
    assert binary.path != fast.path
    assert fast.path.name.startswith("m-manifold-") and not binary.path.name.startswith(
        "m-manifold"
    )
    auto = render_scad_result(src)  # auto took manifold: its cached mesh, not the binary's
    assert auto.cached and auto.path == fast.path and auto.backend == "manifold"
    src.write_text("cube([2, 3, 5]);\n")  # a changed model is a new key for both
    assert render_scad_result(src).path not in (binary.path, fast.path)


@needs_jail
def test_a_syntax_error_is_shown_with_its_line(tmp_path):
    src = _model(tmp_path, "cube(1);\nsphere(;\n")
    with pytest.raises(SceneError) as err:
        render_scad(src, backend="manifold")
    text = str(err.value)
    assert "backend manifold (openscad-evaluator 1.8.1" in text
    assert f"Syntax error in {src} at line 2" in text  # the jail's /model turned back


REPEATED_COMMAS = """// Commas repeated in vectors and calls, which OpenSCAD 2021.01 reads (a public model has them).
cube([4,, 3, 2,,]);
translate([0, 0,, 2]) cube([1, 1, 1],, center = false);
echo(v = [,]);
"""


@needs_jail
def test_repeated_commas_are_read_as_the_binary_reads_them(tmp_path):
    src = _model(tmp_path, REPEATED_COMMAS)
    reference = trimesh.load_mesh(render_scad(src, backend="cgal"))
    fast = trimesh.load_mesh(render_scad(src, backend="manifold"))
    assert np.allclose(reference.bounds, [[0, 0, 0], [4, 3, 3]])
    assert disagreement(reference, fast)["hausdorff"] <= AGREE


@needs_jail
def test_a_used_files_repeated_commas_keep_its_part(tmp_path):
    """A public model staircase had `,,` in the file holding its steps: the evaluator dropped
    the file, and with it the steps, without a word."""
    src = _model(tmp_path, "use <step.scad>\ncube([10, 10, 1]);\nstep();\n")
    (src.parent / "step.scad").write_text("module step() translate([0,, 0, 1]) cube([10, 2, 5]);\n")
    for backend in ("manifold", "cgal"):
        mesh = trimesh.load_mesh(render_scad(src, backend=backend))
        assert np.allclose(mesh.bounds, [[0, 0, 0], [10, 10, 6]]), backend


@needs_jail
def test_a_used_file_that_cannot_be_parsed_is_not_left_out_silently(tmp_path):
    """manifold refuses it; auto goes to the binary, which renders without the file's modules
    (as OpenSCAD does) and the note carries its messages, so the user learns the part is gone."""
    src = _model(tmp_path, "use <step.scad>\ncube([10, 10, 1]);\nstep();\n")
    (src.parent / "step.scad").write_text(
        "module step() translate([0, 0, 1]) cube([10, 2, 5]);\nx = [1;\n"
    )
    with pytest.raises(
        SceneError,
        match=r"Syntax error in \S*step\.scad at line 2, column \d+: backend manifold could not parse it",
    ):
        render_scad(src, backend="manifold")
    auto = render_scad_result(src)
    assert auto.backend == "cgal" and "could not parse it" in auto.why
    assert np.allclose(trimesh.load_mesh(auto.path).bounds, [[0, 0, 0], [10, 10, 1]])
    note = auto.note()
    assert "parts of the model may be missing" in note
    assert "syntax error in file step.scad, line 2" in note
    assert "Ignoring unknown module 'step'" in note
    again = render_scad_result(src)  # the cached render says it too
    assert again.cached and again.warnings == auto.warnings


def test_the_note_keeps_the_models_messages_not_the_mesh_writers():
    """What a user must read (a file not parsed, a module not known) is kept, each once and
    at most 4; the renderers' notes on the mesh they write, which the cleaning repairs, not."""
    from roachplan.processes import ProgramRun

    err = "\n".join(
        [
            "ERROR: Parser error: syntax error in file /model/step.scad, line 2",
            *["WARNING: Ignoring unknown module 'step' in file /model/m.scad, line 3"] * 3,
            "TRACE: called by 'model'",
            "WARNING: Object may not be a valid 2-manifold and may need repair!",
            "WARNING: export: removed 10 zero-area face(s) before writing.",
            *[f"WARNING: Ignoring unknown variable 'v{i}'" for i in range(4)],
        ]
    )
    run = ProgramRun(status=0, stdout="", stderr=err, seconds=1.0, timed_out=False)
    shown = render_warnings(run, jail=True)
    assert shown == (
        "ERROR: Parser error: syntax error in file step.scad, line 2",
        "WARNING: Ignoring unknown module 'step' in file m.scad, line 3",
        "WARNING: Ignoring unknown variable 'v0'",
        "WARNING: Ignoring unknown variable 'v1'",
        "... and 2 more lines",
    )


@pytest.mark.slow
@needs_jail
def test_the_time_limit_stops_the_evaluator(tmp_path):
    src = _model(
        tmp_path, "x = [for (i = [0:999]) for (j = [0:999]) for (k = [0:999]) i];\ncube(1);\n"
    )
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
@pytest.mark.parametrize(
    "code", ['import("../outside/secret.stl");', "include <../outside/secret.scad>"]
)
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


@pytest.mark.slow
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
        argv, layout = manifold_argv(model, target)
        cmd = confined(argv, src.parent, work, jail=jail, layout=layout)
        proc = subprocess.run(
            cmd, cwd=src.parent, capture_output=True, text=True, timeout=120, check=False
        )
        mesh = work / "out" / "mesh.stl"
        if not jail:
            assert proc.returncode == 0, proc.stderr
            assert trimesh.load_mesh(mesh).bounds[1][2] >= SECRET_HEIGHT - 1e-6
        else:
            assert not mesh.exists() or trimesh.load_mesh(mesh).bounds[1][2] < SECRET_HEIGHT / 2, (
                proc.stderr
            )


@needs_jail
def test_the_jail_shows_the_evaluator_only_its_own_packages(tmp_path):
    (tmp_path / "model").mkdir()
    (tmp_path / "work").mkdir()
    argv, layout = manifold_argv("/model/m.scad", f"{JAIL_OUT}/mesh.stl")
    python, paths = argv[0], argv[5]
    probe = (
        "import sys, json, os; sys.path[:0] = json.loads(sys.argv[1])\n"
        "import manifold3d, openscad_evaluator\n"
        "for name in ('trimesh', 'roachplan', 'yaml'):\n"
        "    try:\n        __import__(name); print('imported', name)\n"
        "    except ImportError:\n        print('hidden', name)\n"
        f"print(os.path.exists({str(ROOT / 'README.md')!r}), os.path.exists('/etc/passwd'))\n"
    )
    cmd = confined(
        [python, "-I", "-S", "-c", probe, paths],
        tmp_path / "model",
        tmp_path / "work",
        layout=layout,
    )
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split("\n")[:4] == [
        "hidden trimesh",
        "hidden roachplan",
        "hidden yaml",
        "False False",
    ]
    # The same probe outside the jail does see them: the jail hides them, not their absence.
    outside = subprocess.run(
        [python, "-I", "-S", "-c", probe, paths],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
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
    proc = roachplan(
        "scene", "build", "double_bridge", "-o", str(out), "--scad-backend", "manifold"
    )
    assert proc.returncode == 0, proc.stderr
    built = trimesh.load_mesh(out)
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


@pytest.mark.slow
@needs_jail
def test_the_page_loads_with_auto_and_says_who_rendered_it_and_why(tmp_path, artifacts):
    import zipfile

    from test_app import CHROMIUM, browser_pages, title, upload

    if CHROMIUM is None:
        pytest.skip("Debian chromium not installed")
    from conftest import free_port
    from roachplan.app._server import RoachApp
    from roachplan.scenes import build_world

    app = RoachApp(build_world(load_scene("double_bridge")), host="127.0.0.1", port=free_port())
    try:
        label = tmp_path / "label.scad"  # metres: a plate with a letter on it
        label.write_text(
            "cube([1, 1, 0.02]);\n"
            'translate([0.2, 0.2, 0.02]) linear_extrude(0.01) text("R", size = 0.5);\n'
        )
        heights = tmp_path / "heights.zip"
        with zipfile.ZipFile(heights, "w") as z:
            z.writestr("heights.scad", 'cube([1, 1, 0.02]);\nsurface(file = "h.dat");\n')
            z.writestr("h.dat", "0 0.01\n0.01 0\n")
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            # auto, the default: manifold draws the label, and the page says so.
            upload(page, label)
            # In the notification, and in the status, which stays (and the whole notification
            # under it, when it is cut: the first of those).
            rendered_by = page.get_by_test_id("floating-panel").get_by_text(
                re.compile(
                    r"label\.scad: rendered with manifold \(openscad-evaluator 1\.8\.1, manifold3d "
                    r"3\.5\.4\) in"
                )
            )
            rendered_by.first.wait_for(timeout=120_000)
            page.get_by_text(
                re.compile(
                    r"text\(\): glyphs may sit up to 0\.00075 model units "
                    r"from OpenSCAD's"
                )
            ).first.wait_for()
            page.screenshot(path=artifacts / "backend-01-auto-manifold-text.png")
            assert "label" in title(page)
            # manifold asked for, on a model using surface(): refused, and the page names auto.
            _dropdown(page, "OpenSCAD backend", "manifold")
            upload(page, heights)
            page.get_by_text(
                re.compile(
                    r"line 2: surface\(\) is not rendered alike by backend "
                    r"manifold"
                )
            ).wait_for(timeout=60_000)
            page.get_by_text(
                re.compile(r"set Scene → OpenSCAD backend to auto \(or cgal\)")
            ).first.wait_for()
            page.screenshot(path=artifacts / "backend-02-manifold-refuses-surface.png")
            assert "label" in title(page)  # the scene loaded before stays
        raw = yaml.safe_load(app.world.scene.path.read_text())
        assert "backend" not in raw["terrain"][0]  # auto, the default: not written
        # The page's load ran in a child of the app's fork server, which may have started
        # before this test's render cache was set: the same render (cached by content) here.
        rendered = render_scad_result(label)
        assert rendered.backend == "manifold" and rendered.text_size == pytest.approx(0.5)
        # The page's terrain is that render, within the text bound of the binary's.
        reference = trimesh.load_mesh(render_scad(label, backend="cgal"))
        fast = trimesh.load_mesh(rendered.path)
        d = np.concatenate([surface_distances(reference, fast), surface_distances(fast, reference)])
        assert d.max() <= TEXT_DEVIATION * 0.5
        assert np.allclose(app.world.mesh.bounds[1][2], reference.bounds[1][2], atol=1e-4)
    finally:
        app.stop()
