"""OpenSCAD renders: the Debian binary (2021.01, CGAL) beside a Manifold-based evaluator.

    .venv/bin/python benchmarks/bench_openscad.py [--only NAME ...] [--timeout S]

Models: every .scad object of the library scenes, with its scene's params, and the public-style
models in benchmarks/scad/ (millimetres, `text()`, `include`/`use`, hull, minkowski, a
honeycomb of difference()s: the shape of a typical Thingiverse model).

Backends, each run once as a separate process, as roachplan would run it (wall time, process
start included):
- cgal: the `openscad` binary (Debian 2021.01 has no --backend=manifold), params as `-D`.
- manifold: `openscad_evaluator` (PyPI `openscad-evaluator`, Manifold CSG via `manifold3d`), if
  installed; params by a wrapper that includes the model and then assigns them, which is what
  `-D` does (an assignment after the model's own; the last one wins).

Agreement of the two meshes: bounds, volume (both closed) and a symmetric surface distance
(20,000 points sampled on each surface, their distance to the other surface; the max is a
Hausdorff estimate), relative to the bounding-box diagonal.

Measured (2 cores, openscad_evaluator 1.8.1 + manifold3d 3.5.4 against Debian 2021.01):
    double_bridge          cgal  0.07 s  manifold 0.95 s    agree (1.6e-6)
    double_bridge_rough    cgal  5.33 s  manifold 1.67 s    agree (Hausdorff 3.4e-3)
    heightmap              cgal  0.13 s  manifold 1.27 s    DIFFER: surface()'s base at 0,
                                                            not 1 below the lowest value
    plywood_bridge         cgal  0.24 s  manifold 0.95 s    DIFFER: a polyhedron wound the
                                                            other way stays an open mesh, not
                                                            unioned (interior walls)
    voxel_wall             cgal  0.05 s  manifold 0.94 s    agree
    public nameplate       cgal 46.86 s  manifold 5.93 s    DIFFER: text placed up to 1.6 mm apart
    public vented_box      cgal  9.64 s  manifold 0.91 s    DIFFER: text up to 0.7 mm apart
So Manifold is 8-11x faster on CSG-heavy public models, but it renders 2 of 4 library models
differently from OpenSCAD, and text too: it is not a drop-in backend, and roachplan keeps the
Debian binary. Debian 12 has no OpenSCAD newer than 2021.01 (no --backend=manifold).
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import open3d as o3d
import trimesh

from roachplan.scenes import LIBRARY, list_scenes, load_scene
from roachplan.scenes._openscad import _scad_literal, scad_dependencies

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


def run(cmd: list[str], cwd: Path, timeout: float) -> tuple[float, str]:
    """Wall time [s] of cmd (inf past timeout) and its error text if it failed."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout,
                              check=False)  # fmt: skip
    except subprocess.TimeoutExpired:
        return float("inf"), f"timed out after {timeout:g} s"
    wall = time.perf_counter() - t0
    return wall, "" if proc.returncode == 0 else (proc.stderr.strip().splitlines() or ["?"])[-1]


def render_cgal(model: Path, params: dict, out: Path, timeout: float) -> tuple[float, str]:
    defines = [a for k, v in sorted(params.items()) for a in ("-D", f"{k}={_scad_literal(v)}")]
    cmd = ["openscad", "--export-format", "binstl", "-o", str(out), *defines, model.name]
    return run(cmd, model.parent, timeout)


def render_manifold(model: Path, params: dict, out: Path, timeout: float) -> tuple[float, str]:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for f in (model, *scad_dependencies(model)):
            target = folder / f.relative_to(model.parent)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(f, target)
        wrapper = folder / "__params__.scad"
        wrapper.write_text(
            f"include <{model.name}>\n"
            + "".join(f"{k} = {_scad_literal(v)};\n" for k, v in sorted(params.items()))
        )
        cmd = [sys.executable, "-m", "openscad_evaluator.cli", wrapper.name, "-o", str(out)]
        return run(cmd, folder, timeout)


def surface_distances(a: trimesh.Trimesh, b: trimesh.Trimesh, n: int = 20_000) -> np.ndarray:
    """Distances [model units] of n points sampled on a's surface to b's surface."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(b.vertices.astype(np.float32)), o3d.core.Tensor(b.faces.astype(np.uint32))
    )
    points, _ = trimesh.sample.sample_surface(a, n, seed=0)
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def compare(cgal: Path, manifold: Path) -> dict:
    a, b = trimesh.load(cgal, force="mesh"), trimesh.load(manifold, force="mesh")
    diag = float(np.linalg.norm(a.extents))
    d = np.concatenate([surface_distances(a, b), surface_distances(b, a)])
    closed = a.is_watertight and b.is_watertight
    volume = abs(a.volume - b.volume) / abs(a.volume) if closed else float("nan")
    bounds = float(np.abs(a.bounds - b.bounds).max()) / diag
    agree = bounds <= AGREE_BOUNDS and d.max() / diag <= AGREE_DISTANCE
    agree = agree and (volume <= AGREE_VOLUME if closed else True)
    return {"triangles": (len(a.faces), len(b.faces)), "bounds": bounds, "volume": volume,
            "p99": float(np.quantile(d, 0.99)) / diag, "hausdorff": float(d.max()) / diag,
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
            t_cgal, err_cgal = render_cgal(model, params, a, args.timeout)
            if not has_manifold:
                print(f"{name:44s} {t_cgal:9.2f}  {err_cgal}", flush=True)
                continue
            t_mf, err_mf = render_manifold(model, params, b, args.timeout)
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
