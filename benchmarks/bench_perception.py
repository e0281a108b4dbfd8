"""The capture-to-mesh pipeline on a 960x540 and a 1920x1080 Kinect v2 capture, per stage.

    make bench        (or: .venv/bin/python benchmarks/bench_perception.py)

Captures: synthetic Kinect v2 depth PNGs of the plywood bridge (as kinect_bridge), from the
same pose, in the QHD and HD modes. Stages: load (PNG decode + back-projection), depth range,
voxel (1 cm), outliers, ground (RANSAC + transform), mesh (default: grid), STL export.
Best of 5 runs after a warm-up (imports excluded). Targets: <= 1 s for 960x540 and <= 3 s
for 1920x1080 with the default meshing.

Then the reconstruction on the real captures with a floor or a table (../shared/testdata/real
or $ROACHPLAN_TESTDATA), the sensor method (the default) beside the grid method, in one run:
the share of the observed ground (4 cm cells holding capture points within 3 cm of the ground
plane) where the robot can stand at some heading, the largest region it can stand in, and the
time from file to planning world (mesh, height field, standable map), with their ratios.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
import time
from pathlib import Path
from typing import cast

import numpy as np
from scipy import ndimage

from roachplan.perception import (
    PRESETS,
    MeshingConfig,
    NoiseModel,
    capture_settings,
    load_capture,
    look_at,
    mesh_capture,
    reconstruct,
    render_depth,
    save_depth,
)
from roachplan.perception._choices import Method
from roachplan.scenes import build_terrain_mesh, build_world, load_scene

REAL_CAPTURES = {
    "tutorials_region_growing_rgb_tutorial.pcd": {},
    "tutorials_pairwise_capture0002.pcd": {},
    "rtabmap/depth_154.png": {"intrinsics": "rtabmap/calib_154.yaml"},
    "office_desk_160x120.pcd": {},
    "rough_ground_ouster_4x4m.pcd": {},
    "frame_20121214T142255.814212.pcd": {},
    "table_scene_mug_stereo_textured.pcd": {},
}
"""The real captures with a floor or a table (file -> capture settings, paths relative)."""


def run_once(png: Path, stl: Path, method: Method = "sensor") -> dict[str, float]:
    t0 = time.perf_counter()
    cap = load_capture(png)
    load = time.perf_counter() - t0
    rec = reconstruct(cap, MeshingConfig(method=method))
    t1 = time.perf_counter()
    rec.mesh.export(stl)
    return {
        "load": load,
        **rec.times,
        "STL": time.perf_counter() - t1,
        "total": time.perf_counter() - t0,
        "triangles": len(rec.mesh.faces),
    }


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
            for method in ("sensor", "grid"):  # the default, and the grid beside it
                runs = [run_once(png, Path(tmp) / "out.stl", method) for _ in range(5)]
                best = min(runs, key=lambda r: r["total"])
                stages = "  ".join(
                    f"{k} {v:.3f}" for k, v in best.items() if k not in ("total", "triangles")
                )
                if method == "sensor":
                    sensor = best["total"]
                    print(
                        f"{intr.width}x{intr.height} ({int((depth > 0).sum())} points), "
                        f"{method}: total {best['total']:.3f} s (target <= {target:g} s, "
                        f"{target / best['total']:.1f}x under), {best['triangles']} "
                        f"triangles\n    {stages}"
                    )
                else:
                    print(
                        f"  {method}: total {best['total']:.3f} s (sensor / grid "
                        f"{sensor / best['total']:.2f}x), {best['triangles']} triangles\n"
                        f"    {stages}"
                    )


def real_data() -> Path | None:
    """The real captures' folder, or None when it is not here."""
    root = Path(__file__).resolve().parent.parent
    for c in (os.environ.get("ROACHPLAN_TESTDATA"), root.parent / "shared" / "testdata" / "real"):
        if c and (Path(c) / "README.md").is_file():
            return Path(c)
    return None


def walkable(path: Path, settings: dict) -> dict[str, float]:
    """Reconstruct path with settings into a planning world; the share of its observed ground
    the robot can stand on, its largest standing region [m^2], and the seconds it took."""
    from roachplan.perception import load_capture
    from roachplan.scenes._scene import terrain_file_scene

    t = time.perf_counter()
    cs = capture_settings(settings)
    scene = terrain_file_scene(path)
    obj = dataclasses.replace(scene.terrain[0], capture=cs)
    # Start and goal given (and not checked): the time is the reconstruction's, not picking's.
    scene = dataclasses.replace(scene, terrain=(obj,), start=(0.0, 0.0, 0.0), goal=(0.0, 0.0, 0.0))
    world = build_world(scene, check_poses=False)
    sm = world.regions  # the standable map, as the planner's sampler uses it
    seconds = time.perf_counter() - t
    rec = mesh_capture(path, cs)
    cap = load_capture(path, intrinsics=cs.intrinsics)
    pts = cap.finite_points() @ rec.world_from_camera[:3, :3].T + rec.world_from_camera[:3, 3]
    ground = pts[np.abs(pts[:, 2]) < 0.03][:, :2]
    ij = np.round((ground - [sm.x0, sm.y0]) / sm.cell).astype(int)
    ny, nx = sm.standable.shape
    ij = np.unique(
        ij[(ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)], axis=0
    )
    # scipy.ndimage.label is unannotated: pyright infers the int it returns given `output`
    labels, n = cast("tuple[np.ndarray, int]", ndimage.label(sm.standable))
    largest = ndimage.sum(np.ones_like(labels), labels, np.arange(1, n + 1)).max() if n else 0.0
    return {
        "share": float(sm.standable[ij[:, 1], ij[:, 0]].mean()) if len(ij) else 0.0,
        "largest": float(largest) * sm.cell**2,
        "seconds": seconds,
    }


def real_captures() -> None:
    data = real_data()
    if data is None:
        print("real captures: not found (set ROACHPLAN_TESTDATA); skipped")
        return
    print(
        "\nreal captures, sensor (default) vs grid: share of the observed ground the robot "
        "can stand on, largest standing region, seconds from file to world"
    )
    for name, settings in REAL_CAPTURES.items():
        s = {k: str(data / v) if k == "intrinsics" else v for k, v in settings.items()}
        a = walkable(data / name, {**s, "method": "sensor"})
        b = walkable(data / name, {**s, "method": "grid"})
        print(
            f"  {name}: share {a['share']:.2f} vs {b['share']:.2f} "
            f"({a['share'] / max(b['share'], 1e-9):.1f}x), largest {a['largest']:.2f} vs "
            f"{b['largest']:.2f} m^2 ({a['largest'] / max(b['largest'], 1e-9):.1f}x), "
            f"{a['seconds']:.1f} vs {b['seconds']:.1f} s "
            f"({a['seconds'] / max(b['seconds'], 1e-9):.1f}x)"
        )


if __name__ == "__main__":
    main()
    real_captures()
