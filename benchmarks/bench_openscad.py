"""OpenSCAD renders: the Debian binary (2021.01, CGAL) beside a Manifold-based evaluator.

    .venv/bin/python benchmarks/bench_openscad.py [--only NAME ...] [--timeout S]

Models: every .scad object of the library scenes, with its scene's params, and the public-style
models in benchmarks/scad/ (millimetres, `text()`, `include`/`use`, hull, minkowski, a
honeycomb of difference()s: the shape of a typical Thingiverse model).

Backends, each run once through roachplan's own render_scad (jail, limits, an empty cache;
wall time, process start included):
- cgal: the `openscad` binary (Debian 2021.01 has no --backend=manifold), params as `-D`.
- manifold: `openscad-evaluator` (PyPI; Manifold CSG via `manifold3d`) through
  scenes/_manifold_main.py, which draws seeded rands() as OpenSCAD 2021.01 does; params by a
  wrapper that includes the model and then assigns them, which is what `-D` does. Models using
  a construct it renders differently are REFUSED (text(), surface(); polyhedron() when the
  result is not a closed solid), as `backend: manifold` refuses them.

Agreement of the two meshes: bounds, volume (both closed) and a symmetric surface distance
(20,000 points sampled on each surface, their distance to the other surface, exact in float64
where Open3D's fast query says more than 1e-5 of the diagonal; the max is a Hausdorff
estimate), relative to the bounding-box diagonal.

Measured (2 shared cores, openscad-evaluator 1.8.1 + manifold3d 3.5.4 against Debian 2021.01):
    double_bridge          cgal  0.16 s  manifold 0.99 s   AGREE (Hausdorff 1.6e-6)
    double_bridge_rough    cgal  1.84 s  manifold 0.65 s   AGREE (1.0e-5; seeded rands() drawn
                                                           as OpenSCAD does: 3.4e-3 before)
    heightmap              cgal  0.08 s  REFUSED: surface() (base at 0, not 1 below the lowest
                                         value)
    plywood_bridge         cgal  0.13 s  REFUSED: polyhedron() (wound the other way: an open
                                         shell, not a solid)
    voxel_wall             cgal  0.14 s  manifold 0.44 s   AGREE (9.9e-6)
    public fan_shroud      cgal  3.40 s  manifold 0.65 s   AGREE (9.9e-6), 5.2x
    public vented_box      cgal  3.80 s  REFUSED: text() (placed up to 0.7 mm apart)
    public nameplate       cgal 46.86 s  REFUSED: text() (earlier run, evaluator alone: 5.93 s,
                                         placed up to 1.6 mm apart)
So Manifold is 3-5x faster on the CSG-heavy models it renders here (hull, minkowski,
honeycombs of difference()s, 1,600 seeded bumps; 8-11x on the text() models, which it refuses)
and agrees with the binary within 1e-5 of the diagonal wherever it is not refused; on simple
models the Python start (~0.4 s, and ~0.7 s once per process to list the jail's libraries)
makes it slower. Hence `backend: manifold` is opt-in per terrain object (or --scad-backend),
and cgal, the reference, stays the default. Debian 12 has no OpenSCAD newer than 2021.01.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import trimesh
from roachplan.scenes import SceneError, list_scenes, load_scene, render_scad
from roachplan.scenes._mesh import disagreement
from roachplan.scenes._openscad import scad_dependencies

HERE = Path(__file__).resolve().parent
AGREE_BOUNDS = 1e-3
"""Bounds may differ by this fraction of the diagonal (curves are faceted alike: same $fn)."""
AGREE_DISTANCE = 5e-3
"""The Hausdorff estimate may be this fraction of the diagonal."""
AGREE_VOLUME = 1e-2
"""Relative volume difference allowed."""


def cases() -> list[tuple[str, Path, dict]]:
    """(name, model, params) for each distinct scad object of the library, then benchmarks/scad."""
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
    return out


def render(model: Path, params: dict, backend: str, out: Path, timeout: float
           ) -> tuple[float, str]:  # fmt: skip
    """Wall time [s] of roachplan's render of model by backend (jail, limits and the
    evaluator's entry point included; an empty cache, so it really runs), the mesh copied to
    out; and the refusal or error text if it failed."""
    os.environ["ROACHPLAN_CACHE"] = tempfile.mkdtemp(dir=out.parent)
    t0 = time.perf_counter()
    try:
        shutil.copy(render_scad(model, params, timeout=timeout, backend=backend), out)
    except SceneError as exc:
        text = str(exc)
        refused = re.search(r"line (\d+): (\w+)\(\)", text) if "backend: cgal" in text else None
        if refused:  # the backend's own refusal of a construct it renders differently
            return time.perf_counter() - t0, f"REFUSED: {refused[2]}() at line {refused[1]}"
        return time.perf_counter() - t0, text.splitlines()[-1][-160:]
    return time.perf_counter() - t0, ""




def compare(cgal: Path, manifold: Path) -> dict:
    a, b = trimesh.load(cgal, force="mesh"), trimesh.load(manifold, force="mesh")
    apart = disagreement(a, b)
    closed = a.is_watertight and b.is_watertight
    volume = abs(a.volume - b.volume) / abs(a.volume) if closed else float("nan")
    agree = apart["bounds"] <= AGREE_BOUNDS and apart["hausdorff"] <= AGREE_DISTANCE
    agree = agree and (volume <= AGREE_VOLUME if closed else True)
    return {"triangles": (len(a.faces), len(b.faces)), **apart, "volume": volume,
            "agree": agree}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", default=None, help="case names containing these")
    parser.add_argument("--timeout", type=float, default=900.0, help="per render [s]")
    args = parser.parse_args()
    has_manifold = importlib.util.find_spec("openscad_evaluator") is not None
    version = subprocess.run(["openscad", "--version"], capture_output=True, text=True).stderr
    print(f"cgal: {version.strip()}")
    print("manifold: " + ("openscad_evaluator " + _version("openscad-evaluator") + ", manifold3d "
                          + _version("manifold3d") if has_manifold else "not installed "
                          "(pip install openscad-evaluator): CGAL times only"))  # fmt: skip
    print(f"{'model':44s} {'cgal [s]':>9s} {'manifold [s]':>12s} {'ratio':>6s}  agreement")
    with tempfile.TemporaryDirectory() as tmp:
        for name, model, params in cases():
            if args.only and not any(o in name for o in args.only):
                continue
            a, b = Path(tmp) / "cgal.stl", Path(tmp) / "manifold.stl"
            t_cgal, err_cgal = render(model, params, "cgal", a, args.timeout)
            if not has_manifold:
                print(f"{name:44s} {t_cgal:9.2f}  {err_cgal}", flush=True)
                continue
            t_mf, err_mf = render(model, params, "manifold", b, args.timeout)
            if err_mf.startswith("REFUSED") and not err_cgal:
                verdict = err_mf  # refused, not timed: no ratio
                print(f"{name:44s} {t_cgal:9.2f} {'-':>12s} {'-':>6s}  {verdict}", flush=True)
                continue
            if err_cgal or err_mf:
                verdict = f"cgal: {err_cgal or 'ok'}; manifold: {err_mf or 'ok'}"
            else:
                c = compare(a, b)
                verdict = (
                    f"{'AGREE' if c['agree'] else 'DIFFER'}: bounds {c['bounds']:.1e}, volume "
                    f"{c['volume']:.1e}, p99 {c['p99']:.1e}, Hausdorff {c['hausdorff']:.1e} of "
                    f"the diagonal; triangles {c['triangles'][0]} / {c['triangles'][1]}"
                )
            print(f"{name:44s} {t_cgal:9.2f} {t_mf:12.2f} {t_cgal / t_mf:6.1f}  {verdict}",
                  flush=True)  # fmt: skip


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)


if __name__ == "__main__":
    main()
