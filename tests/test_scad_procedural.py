"""Procedural terrains: many solids side by side or stacked, touching face
to face, as public terrain generators make them. The binary's CGAL takes minutes on them (a
public one: 21 min); backend auto renders them with manifold, merging the solids that touch
(openscad-evaluator joins a loop's solids without a boolean, which leaves both walls inside the
solid), and the terrain the planner and the simulator get is the binary's. Where the binary
still renders, its progress line says why and how long it is expected to take.

Each model here is rendered by the real binary (the reference) and by auto; the height fields
are made as a world makes them (scenes' mesh cleaning, the planner's overhead rule), on a grid
whose points lie off the blocks' edges: a point exactly on a step's edge may take either
side's height in either mesh (each triangulates the step otherwise), which no mesh gets wrong.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from roachplan.planning import heightfield_from_mesh
from roachplan.processes import Running, listening
from roachplan.scenes import (
    LIBRARY,
    SceneError,
    build_terrain,
    load_scene,
    render_scad,
    render_scad_result,
)
from roachplan.scenes._mesh import clean_terrain_mesh, read_mesh
from roachplan.scenes._openscad import BINARY_PACE, CsgSize, csg_size
from roachplan.scenes._scad_manifold import _touching_walls, merge_touching
from roachplan.scenes._scad_sandbox import sandbox_available
from roachplan.scenes._world import HEIGHTFIELD_RESOLUTION, OVERHEAD

needs_jail = pytest.mark.skipif(
    not sandbox_available(), reason="no unprivileged user namespaces here (renders refuse)"
)

HEIGHT_AGREE = 1e-3
"""Largest difference of the two height fields [m]: a millimetre (measured: under 2e-6)."""

BLOCKS = """// Blocks of seeded heights side by side [m].
n = 8;
cell = 0.1;
h = rands(0.02, 0.25, n * n, 42);
for (i = [0:n - 1], j = [0:n - 1])
    translate([i * cell, j * cell, 0]) cube([cell, cell, h[i * n + j]]);
"""
COLUMNS = """// polyhedron() columns whose tops follow a smooth height function [m].
n = 8;
cell = 0.1;
function h(x, y) = 0.12 + 0.06 * sin(x * 200) * cos(y * 150) + 0.03 * sin((x + y) * 420);
module column(x, y) {
    polyhedron(
        points = [
            [x, y, 0], [x + cell, y, 0], [x + cell, y + cell, 0], [x, y + cell, 0],
            [x, y, h(x, y)], [x + cell, y, h(x + cell, y)],
            [x + cell, y + cell, h(x + cell, y + cell)], [x, y + cell, h(x, y + cell)],
        ],
        faces = [[0, 1, 2, 3], [4, 7, 6], [4, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3],
                 [3, 7, 4, 0]]
    );
}
for (i = [0:n - 1], j = [0:n - 1]) column(i * cell, j * cell);
"""
VOXELS = """// Columns of stacked voxels, a block world [m].
n = 8;
cell = 0.1;
h = rands(1, 4, n * n, 3);
for (i = [0:n - 1], j = [0:n - 1], k = [0:floor(h[i * n + j]) - 1])
    translate([i * cell, j * cell, k * cell]) cube(cell);
"""
PLATES = """// Blocks side by side, each with a plate lying on it, and a plank across [m].
n = 4;
cell = 0.1;
h = rands(0.02, 0.25, n * n, 42);
for (i = [0:n - 1], j = [0:n - 1]) {
    translate([i * cell, j * cell, 0]) cube([cell, cell, h[i * n + j]]);
    translate([i * cell + 0.02, j * cell + 0.02, h[i * n + j]]) cube([0.06, 0.06, 0.01]);
}
translate([0, 0.15, 0.25]) cube([n * cell, 0.1, 0.02]);
"""
HULLS = """// Hills: hull()s of spheres on a floor [m] (overlapping, not touching).
n = 3;
p = rands(0, 1, 4 * n * n, 7);
$fn = 12;
translate([-0.1, -0.1, -0.02]) cube([n * 0.2 + 0.2, n * 0.2 + 0.2, 0.02]);
for (i = [0:n - 1], j = [0:n - 1]) {
    k = 4 * (i * n + j);
    hull() {
        translate([i * 0.2, j * 0.2, 0]) sphere(r = 0.05 + 0.05 * p[k]);
        translate([i * 0.2 + 0.15 * p[k + 1], j * 0.2 + 0.15 * p[k + 2], 0.05])
            sphere(r = 0.04 + 0.04 * p[k + 3]);
    }
}
"""
TERRAINS = {
    "blocks": BLOCKS,
    "columns": COLUMNS,
    "voxels": VOXELS,
    "plates": PLATES,
    "hulls": HULLS,
}
"""Procedural terrains; all but the hulls have solids touching face to face."""
MERGED = {"blocks", "columns", "voxels"}
"""Those whose touching solids the evaluator leaves apart (not all: where a loop's coordinates
add up exactly, as 0.1 + 0.1 = 2 * 0.1, Manifold joins them itself; 0.7 + 0.1 < 8 * 0.1)."""


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path, monkeypatch):
    """An empty render cache per test, so both programs really run."""
    monkeypatch.setenv("ROACHPLAN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("ROACHPLAN_UNSAFE_SCAD", raising=False)


def _model(tmp_path: Path, code: str, name: str = "terrain.scad") -> Path:
    folder = tmp_path / "model"
    folder.mkdir(exist_ok=True)
    (folder / name).write_text(code)
    return folder / name


def _terrain(model: Path, backend: str) -> trimesh.Trimesh:
    """The model's terrain mesh as a world gets it (rendered, cleaned) [m]."""
    scene = model.with_name(f"{backend}.yaml")
    scene.write_text(
        yaml.safe_dump({"terrain": [{"scad": model.name, "backend": backend}], "ground": None})
    )
    return build_terrain(load_scene(scene)).mesh


def _heights(mesh: trimesh.Trimesh, bounds: np.ndarray) -> np.ndarray:
    """The planner's height field of mesh [m] over bounds ((2, 3): the reference's), on a grid
    whose points lie off the models' 0.1 m (and 1 cm) lattice."""
    off = np.array([0.00123, 0.00377])
    return heightfield_from_mesh(
        mesh.vertices,
        mesh.faces,
        xy_min=tuple(bounds[0, :2] - 0.05 + off),
        xy_max=tuple(bounds[1, :2] + 0.05),
        resolution=HEIGHTFIELD_RESOLUTION,
        ground_height=None,
        overhead=OVERHEAD,
    ).heights


@needs_jail
@pytest.mark.parametrize("name", TERRAINS)
def test_a_procedural_terrain_is_rendered_by_manifold_as_the_binary_renders_it(name, tmp_path):
    model = _model(tmp_path, TERRAINS[name])
    auto = render_scad_result(model)
    assert auto.backend == "manifold", auto.note()
    assert (auto.merged > 0) == (name in MERGED), auto.note()
    if name in MERGED:
        assert re.search(r"solids touching face to face \(on \d+ planes?\) merged", auto.note())
    mesh = trimesh.load_mesh(auto.path)
    assert _touching_walls(mesh) is None  # no face inside the solid
    assert mesh.volume > 0
    # The world's terrain: the binary's height field within a millimetre, everywhere.
    reference = _terrain(model, "cgal")
    fast = _terrain(model, "auto")
    a, b = _heights(reference, reference.bounds), _heights(fast, reference.bounds)
    assert np.array_equal(np.isnan(a), np.isnan(b))
    assert np.isfinite(a).sum() > 0.3 * a.size
    assert np.nanmax(np.abs(a - b)) <= HEIGHT_AGREE
    np.testing.assert_allclose(fast.bounds, reference.bounds, atol=1e-5)


TOWER = """// A tower standing on a slab: the slab's top at 0.7 + 0.1 = 0.7999999999999999, the
// tower's foot at 0.8: a gap of 1e-16, which the binary closes and Manifold keeps [m].
cube([1, 1, 0.7 + 0.1]);
translate([0.2, 0.2, 0.8]) cube([0.5, 0.5, 0.5]);
"""


@needs_jail
def test_unmerged_a_tower_on_a_slab_would_be_overhead_to_the_planner(tmp_path, monkeypatch):
    """Control: the evaluator's own mesh keeps the slab's top under the tower, an upward face
    inside the solid, 0.5 m below the tower's top: the planner's overhead rule takes it for
    the ground under a shelf, and the tower is gone. Merged, it is the binary's terrain."""
    import roachplan.scenes._openscad as openscad

    model = _model(tmp_path, TOWER)
    raw = tmp_path / "raw.stl"
    merge = openscad.merge_touching

    def keep_raw(mesh: Path) -> int:
        shutil.copy(mesh, raw)
        return merge(mesh)

    monkeypatch.setattr(openscad, "merge_touching", keep_raw)
    auto = render_scad_result(model)
    assert auto.backend == "manifold" and auto.merged == 1, auto.note()
    assert _touching_walls(trimesh.load_mesh(raw)) is not None  # faces inside the solid
    merged = trimesh.load_mesh(auto.path)
    assert merged.is_watertight and _touching_walls(merged) is None

    def tower_height(path: Path) -> float:
        mesh = clean_terrain_mesh(read_mesh(path, "x"), "x")  # as a world cleans it
        hf = heightfield_from_mesh(
            mesh.vertices, mesh.faces, xy_min=(0.45, 0.45), xy_max=(0.46, 0.46),
            resolution=HEIGHTFIELD_RESOLUTION, ground_height=None, overhead=OVERHEAD,
        )  # fmt: skip
        return float(hf.heights[0, 0])

    assert tower_height(render_scad(model, backend="cgal")) == pytest.approx(1.3, abs=1e-5)
    assert tower_height(auto.path) == pytest.approx(1.3, abs=1e-5)
    assert tower_height(raw) == pytest.approx(0.8, abs=1e-5)


def test_the_csg_tree_is_counted_as_the_binary_makes_its_solids():
    tree = """multmatrix([[1, 0, 0, -0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) {
\tcube(size = [1, 1, 0.02], center = false);
}
group() {
\thull() {
\t\tsphere($fn = 16, $fa = 12, $fs = 2, r = 0.06);
\t\tsphere($fn = 0, $fa = 12, $fs = 2, r = 10);
\t}
\tdifference() {
\t\tcylinder($fn = 12, $fa = 12, $fs = 2, h = 1, r1 = 1, r2 = 0, center = false);
\t\tpolyhedron(points = [[0, 0, 0]], faces = [[0, 1, 2, 3], [4, 7, 6], [4, 6, 5]], convexity = 1);
\t\tlinear_extrude(height = 1, center = false, convexity = 1, scale = [1, 1]) {
\t\t\tcircle($fn = 30, $fa = 12, $fs = 2, r = 2);
\t\t\tsquare(size = [1, 1], center = false);
\t\t}
\t}
}
surface(file = "h.dat", center = false, invert = false, timestamp = 0);
"""
    size = csg_size(tree)
    # Solids: cube, 2 spheres, cylinder, polyhedron, the extrusion (its 2-D children are not
    # solids), surface. Booleans: hull 1, difference 2, group 1, the top level 2.
    # Triangles: 12 + 2*16*8 + 2*30*15 (r = 10 at $fa = 12, $fs = 2: 30 fragments) + 4*12
    # + (2 + 1 + 1) + 12 (the extrusion) + 12 (surface).
    assert size == CsgSize(solids=7, booleans=6, triangles=12 + 256 + 900 + 48 + 4 + 12 + 12)
    # A minkowski() sum costs CGAL the product of its children's triangles.
    minkowski = "minkowski(convexity = 0) {\n\tcube(size = [1, 1, 1], center = false);\n"
    minkowski += "\tsphere($fn = 8, $fa = 12, $fs = 2, r = 0.1);\n}\n"
    assert csg_size(minkowski) == CsgSize(solids=2, booleans=1, triangles=12 * 2 * 8 * 4)
    assert csg_size("") == CsgSize(solids=0, booleans=0, triangles=0)
    assert csg_size("}\n}\n") == CsgSize(solids=0, booleans=0, triangles=0)  # (no error)


SURFACE_BLOCKS = """// Blocks on a height map: surface() sends it to the binary.
for (i = [0:4]) translate([i * 0.1, 0, 0]) cube([0.1, 0.1, 0.05 + 0.02 * i]);
translate([0, 0, -0.3]) scale([0.1, 0.1, 0.1]) surface(file = "h.dat");
"""


@needs_jail
def test_the_binarys_progress_line_says_why_and_how_long_it_is_expected_to_take(tmp_path):
    model = _model(tmp_path, SURFACE_BLOCKS)
    (model.parent / "h.dat").write_text("0 1 0\n1 2 1\n0 1 0\n")
    heard: list[Running] = []
    with listening(lambda e: heard.append(e) if isinstance(e, Running) else None):
        auto = render_scad_result(model)
    assert auto.backend == "cgal" and auto.why.startswith("surface() (terrain.scad, line 3)")
    said = {e.what for e in heard}
    # 5 cubes and the surface: 6 solids, 5 booleans, 72 triangles: 36 to 576 ms.
    assert said == {
        "terrain.scad with the openscad binary (surface() is rendered differently by "
        "manifold), expected to take under 1 s (an estimate: 6 solids, 5 booleans, 72 "
        f"triangles in its CSG tree, at {BINARY_PACE[0] * 1000:g}-{BINARY_PACE[1] * 1000:g} "
        "ms a triangle)"
    }, said
    # Asked for by name, the binary says so; cached, it does not run (nor say anything).
    heard.clear()
    with listening(lambda e: heard.append(e) if isinstance(e, Running) else None):
        render_scad_result(model, backend="cgal")
    assert not heard
    other = _model(tmp_path, "for (i = [0:199]) translate([i, 0, 0]) cube(1);\n", "row.scad")
    with listening(lambda e: heard.append(e) if isinstance(e, Running) else None):
        try:
            render_scad_result(other, backend="cgal", timeout=2.0)
        except SceneError as exc:  # a row of 200 cubes may or may not take 2 s here
            assert "did not finish within its time limit of 2 s" in str(exc)
            assert "; it was expected to take 1.2 s to 19 s (an estimate: 200 solids" in str(exc)
    assert {e.what for e in heard} == {
        "row.scad with the openscad binary (backend: cgal), expected to take 1.2 s to 19 s (an "
        "estimate: 200 solids, 199 booleans, 2,400 triangles in its CSG tree, at 0.5-8 ms a "
        "triangle), maybe more than its 2 s limit"
    }


@needs_jail
def test_plywood_bridge_is_merged_and_is_the_binarys_terrain():
    """The library's plywood bridge: a plank lying on its blocks, ramps against its ends (solids
    touching face to face, up and sideways). Merged, the block tops under the plank are gone
    (the planner's overhead rule would take one for the ground under a shelf) and the terrain
    is the binary's."""
    model = LIBRARY / "plywood_bridge.scad"
    auto = render_scad_result(model)
    assert auto.backend == "manifold" and auto.merged >= 2, auto.note()
    mesh = trimesh.load_mesh(auto.path)
    assert mesh.is_watertight and _touching_walls(mesh) is None
    # No upward face under the plank's top (z = 0.12) but the floor's.
    up = mesh.face_normals[:, 2] > 0.99
    z = mesh.triangles_center[:, 2]
    assert set(np.round(z[up], 4)) <= {0.0, 0.1, 0.12}
    under_plank = up & (np.abs(z - 0.1) < 1e-6)
    centres = mesh.triangles_center[under_plank]
    assert not np.any((np.abs(centres[:, 0]) < 0.45) & (np.abs(centres[:, 1]) < 0.15))
    reference = trimesh.load_mesh(render_scad(model, backend="cgal"))
    assert abs(mesh.volume - reference.volume) <= 1e-4 * reference.volume


def _boxes(path: Path, *boxes: tuple[tuple[float, ...], tuple[float, ...]]) -> Path:
    """An STL of boxes (lower corner, upper corner) [model units], each a closed solid of its
    own, as the evaluator writes solids it did not join."""
    parts = []
    for lo, hi in boxes:
        box = trimesh.creation.box(extents=np.subtract(hi, lo))
        box.apply_translation(np.add(lo, hi) / 2)
        parts.append(box)
    trimesh.util.concatenate(parts).export(path)
    return path


def test_blocks_side_by_side_are_merged_into_one_closed_solid(tmp_path):
    # A low block, a tall one beside it, a plank across both: walls back to back, and the
    # plank's underside on both tops.
    stl = _boxes(
        tmp_path / "m.stl",
        ((0, 0, 0), (1, 1, 1)),
        ((1, 0, 0), (2, 1, 2)),
        ((0.5, 0.25, 2), (1.75, 0.75, 2.25)),
    )
    before = trimesh.load_mesh(stl)
    assert _touching_walls(before) is not None
    assert merge_touching(stl) == 2  # the wall x = 1, the tall block's top z = 2
    after = trimesh.load_mesh(stl)
    assert after.is_watertight and after.is_winding_consistent
    assert after.volume == pytest.approx(1 + 2 + 1.25 * 0.5 * 0.25, rel=1e-9)
    assert _touching_walls(after) is None
    # No upward face left inside the solid: the tall block's top under the plank is gone
    # (its strips beside the plank stay, and the plank's foot on the low block, x < 1).
    centres = after.triangles_center
    top_under_plank = (
        (after.face_normals[:, 2] > 0.99)
        & np.isclose(centres[:, 2], 2)
        & (centres[:, 0] > 1) & (centres[:, 0] < 1.75)
        & (centres[:, 1] > 0.25) & (centres[:, 1] < 0.75)
    )  # fmt: skip
    assert not top_under_plank.any()
    # The union's surface: floor 2; low block 1 + 2 + 1; tall block 0.625 (its top but the
    # plank's foot) + 4 + 2 + 1 (its wall above the low block); plank 0.625 + 0.25 (its
    # underside over the low block) + 0.625 + 0.25.
    assert after.area == pytest.approx(15.375, rel=1e-9)
    assert merge_touching(stl) == 0  # nothing touches any more


def test_solids_that_only_nearly_touch_are_left_as_they_are(tmp_path):
    # 4e-7 apart: one plane to the check (1e-6 of the size), no closed solid once cut.
    stl = _boxes(tmp_path / "m.stl", ((0, 0, 0), (1, 1, 1)), ((1.0000004, 0, 0), (2, 1, 2)))
    data = stl.read_bytes()
    assert _touching_walls(trimesh.load_mesh(stl)) is not None
    assert merge_touching(stl) == 0 and stl.read_bytes() == data
    # Apart by more, they do not touch at all.
    apart = _boxes(tmp_path / "a.stl", ((0, 0, 0), (1, 1, 1)), ((1.01, 0, 0), (2, 1, 2)))
    assert merge_touching(apart) == 0


def test_the_pages_load_status_says_what_the_binary_expects_while_it_renders():
    """The Scene folder's load status adds what a render says of itself when that is more
    than the model's name (the binary's why and expectation), while it runs."""
    from types import SimpleNamespace

    from roachplan.app._loading import BackgroundLoad, Loading

    said = (
        "terrain.scad with the openscad binary (surface() is rendered differently by "
        "manifold), expected to take 2.4 s to 38 s (an estimate: 401 solids, 400 booleans, "
        "4,812 triangles in its CSG tree, at 0.5-8 ms a triangle)"
    )

    class Job:
        elapsed, done, events = 12.0, False, []

        def poll(self):
            events, self.events = self.events, []
            return events

    gui = SimpleNamespace(
        add_markdown=lambda content: SimpleNamespace(content=content),
        add_button=lambda *a, **k: SimpleNamespace(on_click=lambda f: None, visible=False),
    )
    lane = BackgroundLoad(gui, put=None)
    job = Job()
    lane.current = Loading(
        job=job,  # type: ignore[arg-type]
        client_id=None,
        ref="terrain.yaml",
        label="terrain",
        from_upload=False,
        what="Rendering terrain.scad with Manifold or, where it must, OpenSCAD (limit 600 s)",
    )
    job.events = [Running(what="terrain.scad", elapsed=11.5, limit=600.0)]
    assert lane.poll() is None
    assert lane.status.content == (
        "Rendering terrain.scad with Manifold or, where it must, OpenSCAD (limit 600 s) ... 12 s"
    )
    job.events = [Running(what=said, elapsed=0.5, limit=599.0)]
    lane.poll()
    assert lane.status.content.endswith(f" ... 12 s; OpenSCAD {said}")
    job.elapsed = 20.0  # no word from the render for 8 s: it ended, the load goes on
    lane.poll()
    assert lane.status.content.endswith("OpenSCAD (limit 600 s) ... 20 s")
