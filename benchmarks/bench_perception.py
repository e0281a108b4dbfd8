"""The capture-to-mesh pipeline on a 960x540 and a 1920x1080 Kinect v2 capture, per stage.

    make bench        (or: .venv/bin/python benchmarks/bench_perception.py)

Captures: synthetic Kinect v2 depth PNGs of the plywood bridge (as kinect_bridge), from the
same pose, in the QHD and HD modes. Stages: load (PNG decode + back-projection), depth range,
voxel (1 cm), outliers, ground (RANSAC + transform), mesh (default: grid), STL export.
Best of 5 runs after a warm-up (imports excluded). Targets (issue 7): <= 1 s for 960x540 and
<= 3 s for 1920x1080 with the default meshing.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from roachplan.perception import (
    PRESETS,
    MeshingConfig,
    NoiseModel,
    load_capture,
    look_at,
    reconstruct,
    render_depth,
    save_depth,
)
from roachplan.scenes import build_terrain_mesh, load_scene


def run_once(png: Path, stl: Path) -> dict[str, float]:
    t0 = time.perf_counter()
    cap = load_capture(png)
    load = time.perf_counter() - t0
    rec = reconstruct(cap, MeshingConfig())
    t1 = time.perf_counter()
    rec.mesh.export(stl)
    return {"load": load, **rec.times, "STL": time.perf_counter() - t1,
            "total": time.perf_counter() - t0, "triangles": len(rec.mesh.faces)}  # fmt: skip


def main() -> None:
    mesh = build_terrain_mesh(load_scene("plywood_bridge"))
    pose = look_at((0, -2.2, 1.5), (0, 0, 0))
    with tempfile.TemporaryDirectory() as tmp:
        for mode, target in (("kinect2-qhd", 1.0), ("kinect2-hd", 3.0)):
            intr = PRESETS[mode]
            depth = render_depth(mesh, intr, pose, NoiseModel(), np.random.default_rng(0))
            png = Path(tmp) / f"{mode}.png"
            save_depth(png, depth, intr)
            run_once(png, Path(tmp) / "warm.stl")
            runs = [run_once(png, Path(tmp) / "out.stl") for _ in range(5)]
            best = min(runs, key=lambda r: r["total"])
            stages = "  ".join(
                f"{k} {v:.3f}" for k, v in best.items() if k not in ("total", "triangles")
            )
            print(f"{intr.width}x{intr.height} ({int((depth > 0).sum())} points): "
                  f"total {best['total']:.3f} s (target <= {target:g} s, "
                  f"{target / best['total']:.1f}x under), {best['triangles']} triangles\n"
                  f"    {stages}")  # fmt: skip


if __name__ == "__main__":
    main()
