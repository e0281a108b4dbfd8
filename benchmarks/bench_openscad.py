"""OpenSCAD renders: the Debian binary (2021.01, CGAL) beside backend auto, the default.

    .venv/bin/python benchmarks/bench_openscad.py [--only NAME ...] [--extra FILE.scad ...]
                                                  [--manifold] [--timeout S]
    .venv/bin/python benchmarks/bench_openscad.py --text     # where TEXT_DEVIATION comes from

Models: every .scad object of the library scenes, with its scene's params; the public-style
models in benchmarks/scad/ (millimetres, `text()`, `include`/`use`, hull, minkowski, a
honeycomb of difference()s: the shape of a typical Thingiverse model); tests/data/public_tile
(a terrain tile: an include, a use, a height-field polyhedron wound inward, text()); and any
--extra model (public models downloaded for a timing, not kept in the repository).

Backends, each run once through roachplan's own render_scad_result (jail, limits, an empty
cache each; wall time, process start included), one after the other on the same model:
- cgal: the `openscad` binary (Debian 2021.01 has no --backend=manifold), params as `-D`.
- auto: what a scene that says nothing gets: `openscad-evaluator` on Manifold through
  scenes/_manifold_main.py where it renders the model as the binary does, else the binary
  (the table says which, and why).
- manifold (--manifold): the evaluator alone, refused where it differs.

Agreement with the binary's mesh: bounds, volume (both closed) and a symmetric surface
distance (20,000 points sampled on each surface, their distance to the other surface, exact
in float64 where Open3D's fast query says more than 1e-5 of the diagonal; the max is a
Hausdorff estimate), relative to the bounding-box diagonal; and, for models with text(), the
largest distance in model units against TEXT_DEVIATION x the text's size.

Measured (a shared 2-core VM, other jobs running: load average 2.0 at the start;
openscad-evaluator 1.8.1 + manifold3d 3.5.4 against Debian 2021.01; ratio = cgal / auto;
agreement as a fraction of the diagonal, text in model units against its bound):
    double_bridge                  cgal   0.11 s  auto   0.91 s  0.1x  manifold  AGREE 1.6e-6
    double_bridge_rough            cgal   2.13 s  auto   0.66 s  3.2x  manifold  AGREE 1.0e-5
    heightmap                      cgal   0.07 s  auto   0.07 s  1.0x  cgal: surface()
    plywood_bridge                 cgal   0.13 s  auto   0.55 s  0.2x  cgal: solids touching
    voxel_wall                     cgal   0.07 s  auto   0.37 s  0.2x  manifold  AGREE 9.9e-6
    public fan_shroud              cgal   4.18 s  auto   0.49 s  8.6x  manifold  AGREE 9.9e-6
    public nameplate               cgal  20.89 s  auto   3.69 s  5.7x  manifold  AGREE 2.9e-5,
                                                                  text 0.0042 (bound 0.017)
    public vented_box              cgal   5.06 s  auto   0.70 s  7.2x  manifold  AGREE 2.9e-5,
                                                                  text 0.0032 (bound 0.0096)
    tests public_tile              cgal   0.68 s  auto   0.59 s  1.1x  manifold  AGREE 2.3e-5,
                                                                  text 0.0023 (bound 0.0072)
    --extra, public models not kept here (OrsoEric/Gridfinity-medieval-tiles, rands() seeded
    so that the meshes compare):
    tile_grass.scad (25 tiles)     cgal 306.03 s  auto   6.56 s 46.7x  manifold  AGREE 9.6e-6,
                                                                  text 0.0033 (bound 0.0036)
    terrain.scad                   cgal   0.43 s  auto   0.60 s  0.7x  manifold  AGREE 9.6e-6
(The text bounds above are from TEXT_DEVIATION = 1.2e-3 at that run; it is 1.5e-3 now.)
--text: at most 1.01e-3 x size over 40 strings, sizes, alignments and fonts.
The evaluator's Python start (~0.4 s, and ~0.7 s once per process to list the jail's libraries)
makes auto slower than the binary on small models; it is 3-47x faster on CSG-heavy and text()
models. Debian 12 has no OpenSCAD newer than 2021.01.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from roachplan.scenes import (
    ScadRender,
    SceneError,
    list_scenes,
    load_scene,
    render_scad,
    render_scad_result,
)
from roachplan.scenes._mesh import disagreement, surface_distances
from roachplan.scenes._openscad import Backend
from roachplan.scenes._scad_manifold import TEXT_DEVIATION, manifold_version
from roachplan.scenes._scad_source import scad_dependencies

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
AGREE_BOUNDS = 1e-3
"""Bounds may differ by this fraction of the diagonal (curves are faceted alike: same $fn)."""
AGREE_DISTANCE = 5e-3
"""The Hausdorff estimate may be this fraction of the diagonal."""
AGREE_VOLUME = 1e-2
"""Relative volume difference allowed."""


def cases(extra: list[Path]) -> list[tuple[str, Path, dict]]:
    """(name, model, params): each distinct scad object of the library, benchmarks/scad, the
    public-style tile of the tests, then the --extra models."""
    out, seen = [], set()
    for name in list_scenes():
        for obj in load_scene(name).terrain:
            key = (obj.source, obj.params)
            if obj.kind == "scad" and key not in seen:
                seen.add(key)
                out.append((f"{name}:{obj.source.name}", obj.source, dict(obj.params)))
    models = sorted((HERE / "scad").glob("*.scad"))
    helpers = {d for m in models for d in scad_dependencies(m)}  # included or used by another
    out += [(f"public:{m.name}", m, {}) for m in models if m.resolve() not in helpers]
    out.append(("tests:public_tile/tile.scad", ROOT / "tests/data/public_tile/tile.scad", {}))
    out += [(f"extra:{m.parent.name}/{m.name}", m.resolve(), {}) for m in extra]
    return out


def render(
    model: Path, params: dict, backend: Backend, out: Path, timeout: float
) -> tuple[float, ScadRender | None, str]:
    """(wall time [s], ScadRender or None, error text) of roachplan's render of model by backend
    with an empty cache (so it really runs); the mesh copied to out."""
    os.environ["ROACHPLAN_CACHE"] = tempfile.mkdtemp(dir=out.parent)
    t0 = time.perf_counter()
    try:
        r = render_scad_result(model, params, timeout=timeout, backend=backend)
    except SceneError as exc:
        return time.perf_counter() - t0, None, str(exc).splitlines()[-1][-160:]
    took = time.perf_counter() - t0
    shutil.copy(r.path, out)
    return took, r, ""


def compare(cgal: Path, other: Path, text_size: float) -> str:
    a, b = trimesh.load_mesh(cgal), trimesh.load_mesh(other)
    apart = disagreement(a, b)
    closed = a.is_watertight and b.is_watertight
    volume = abs(a.volume - b.volume) / abs(a.volume) if closed else float("nan")
    agree = apart["bounds"] <= AGREE_BOUNDS and apart["hausdorff"] <= AGREE_DISTANCE
    agree = agree and (volume <= AGREE_VOLUME if closed else True)
    text = ""
    if text_size > 0:
        d = np.concatenate([surface_distances(a, b), surface_distances(b, a)])
        bound = TEXT_DEVIATION * text_size
        text = f"; text: {d.max():.2g} model units apart, bound {bound:.2g} " + (
            "(within)" if d.max() <= bound else "(BEYOND)"
        )
    return (
        f"{'AGREE' if agree else 'DIFFER'}: bounds {apart['bounds']:.1e}, volume {volume:.1e}, "
        f"p99 {apart['p99']:.1e}, Hausdorff {apart['hausdorff']:.1e} of the diagonal; "
        f"triangles {len(a.faces)} / {len(b.faces)}{text}"
    )


def bench_backends(args) -> None:
    version = subprocess.run(
        ["openscad", "--version"], capture_output=True, text=True, check=False
    ).stderr
    print(f"cgal: {version.strip()}; manifold: {manifold_version()}")
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 shared cores)")
    print(f"{'model':40s} {'cgal [s]':>9s} {'auto [s]':>9s} {'ratio':>6s}  auto chose  agreement")
    with tempfile.TemporaryDirectory() as tmp:
        for name, model, params in cases(args.extra):
            if args.only and not any(o in name for o in args.only):
                continue
            a, b = Path(tmp) / "cgal.stl", Path(tmp) / "auto.stl"
            t_cgal, _, err_cgal = render(model, params, "cgal", a, args.timeout)
            t_auto, r, err_auto = render(model, params, "auto", b, args.timeout)
            chose = r.backend + (f" ({r.why[:70]})" if r.why else "") if r else "-"
            if err_cgal or err_auto:
                verdict = f"cgal: {err_cgal or 'ok'}; auto: {err_auto or 'ok'}"
            else:
                assert r is not None  # auto rendered: no error text
                verdict = "the binary's mesh" if r.backend == "cgal" else compare(a, b, r.text_size)
            print(
                f"{name:40s} {t_cgal:9.2f} {t_auto:9.2f} {t_cgal / t_auto:6.1f}  {chose}  "
                f"{verdict}",
                flush=True,
            )
            if args.manifold:
                t_mf, rm, err_mf = render(model, params, "manifold", b, args.timeout)
                if err_mf or err_cgal:
                    shown = err_mf
                else:
                    assert rm is not None  # manifold rendered: no error text
                    shown = compare(a, b, rm.text_size)
                print(
                    f"{'  manifold alone':40s} {'':9s} {t_mf:9.2f} {t_cgal / t_mf:6.1f}  {shown}",
                    flush=True,
                )


TEXT_STRINGS = ("Wq@&%$ Roach 42", "The quick brown fox jumps over the lazy dog 0123456789")
TEXT_SIZES = (1, 3, 10, 30, 100)
TEXT_ALIGN = (
    'halign = "left", valign = "baseline"',
    'halign = "right", valign = "top"',
    'halign = "center", valign = "center"',
    'valign = "bottom"',
)
TEXT_FONTS = ("", "DejaVu Sans Mono:style=Bold", "Futura:style=Bold", "Liberation Serif")


def bench_text(args) -> None:
    """text() by backend manifold against the binary: every string, size, alignment and font
    above (fonts this system lacks get fontconfig's stand-in, in both), the largest distance
    between the two meshes per unit of size. TEXT_DEVIATION is the largest, rounded up."""
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["ROACHPLAN_CACHE"] = str(Path(tmp) / "cache")
        for text in TEXT_STRINGS:
            for size in TEXT_SIZES:
                for k, (align, font) in enumerate(zip(TEXT_ALIGN * 2, TEXT_FONTS * 2)):
                    if k >= len(TEXT_ALIGN):
                        break
                    model = Path(tmp) / f"t{len(text)}-{size}-{k}.scad"
                    model.write_text(
                        f'linear_extrude(2) text("{text}", size = {size}, '
                        f'font = "{font}", {align});\n'
                    )
                    a = trimesh.load_mesh(render_scad(model, backend="cgal"))
                    b = trimesh.load_mesh(render_scad(model, backend="manifold"))
                    d = np.concatenate([surface_distances(a, b), surface_distances(b, a)])
                    worst = max(worst, d.max() / size)
                    print(
                        f"{len(text):3d} glyphs  size {size:5g}  {align:38s} "
                        f"{font or '(default)':28s} max {d.max():.4f} = {d.max() / size:.2e} x "
                        f"size",
                        flush=True,
                    )
    print(f"largest: {worst:.2e} x size; TEXT_DEVIATION = {TEXT_DEVIATION:.2e}")


def main() -> None:
    assert __doc__ is not None
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="case names containing these")
    parser.add_argument(
        "--extra",
        nargs="*",
        type=Path,
        default=[],
        help="more .scad models to time (e.g. public ones not kept here)",
    )
    parser.add_argument("--manifold", action="store_true", help="time backend manifold alone too")
    parser.add_argument("--text", action="store_true", help="measure text()'s deviation instead")
    parser.add_argument("--timeout", type=float, default=900.0, help="per render [s]")
    args = parser.parse_args()
    bench_text(args) if args.text else bench_backends(args)


if __name__ == "__main__":
    main()
