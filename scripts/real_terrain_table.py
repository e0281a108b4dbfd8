"""The README's table of real captures: for each file in ../shared/testdata/real (or
$ROACHPLAN_TESTDATA), the ground found, and as a scene of its own: the start-goal distance
picked, the plan time and the trial's outcome, and the load (mesh + world) time.

    .venv/bin/python scripts/real_terrain_table.py
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from roachplan.experiments import run_trial  # noqa: E402
from roachplan.perception import CaptureSettings, capture_settings, mesh_capture  # noqa: E402
from roachplan.scenes import (  # noqa: E402
    SceneError,
    build_world,
    load_scene,
    terrain_file_scene,
)
from test_perception import REAL  # noqa: E402

FILES = {
    "tutorials_region_growing_rgb_tutorial.pcd": {},
    "table_scene_mug_stereo_textured.pcd": {},
    "tutorials_pairwise_capture0002.pcd": {},
    "rtabmap/depth_154.png": {"intrinsics": str(REAL / "rtabmap" / "calib_154.yaml")},
    "frame_20121214T142255.814212.pcd": {},
    "frame_20121214T142255.814212_depth_mm.png": {},
    "terrain_samp11-utm.pcd": {},
    "jsk_watercan.bag": {},
    "office_desk_160x120.pcd": {},
    "rough_ground_ouster_4x4m.pcd": {},
}


def main() -> None:
    print("| file | ground found | start-goal | plan | outcome | load |")
    print("|---|---|---|---|---|---|")
    for name, settings in FILES.items():
        path = REAL / name
        cs = capture_settings(settings) if settings else CaptureSettings()
        t = time.perf_counter()
        rec = mesh_capture(path, cs)
        r = rec.report()
        if r["camera_pose"] is not None:
            ground = (
                f"camera {r['camera_height_m']:.2f} m up, pitch {r['pitch_down_deg']:.0f} deg, "
                f"{100 * r['ground']['support_fraction']:.0f} % of points"
            )
        else:
            ground = "world frame (z up); " + (
                "recentred" if any("recentred" in n for n in r["notes"]) else "kept"
            )
        scene = terrain_file_scene(path)
        obj = scene.terrain[0]
        import dataclasses

        scene = dataclasses.replace(scene, terrain=(dataclasses.replace(obj, capture=cs),))
        try:
            world = build_world(scene)
        except SceneError as exc:
            load = time.perf_counter() - t
            why = str(exc).split(": ", 1)[-1].split(": check")[0]  # the reason, not the advice
            print(f"| `{name}` | {ground} | - | - | not a scene: {why} | {load:.1f} s |")
            continue
        load = time.perf_counter() - t
        trial = run_trial(world, seed=0)
        d = math.dist(trial.start[:2], trial.goal[:2])
        print(
            f"| `{name}` | {ground} | {d:.2f} m | {trial.plan_time:.2f} s | {trial.outcome} "
            f"({trial.drive_time:.1f} s driven) | {load:.1f} s |"
        )
    for model in sorted(REAL.glob("**/*.scad")):  # public models: a scene of their own
        t = time.perf_counter()
        world = build_world(load_scene(model))
        load = time.perf_counter() - t
        trial = run_trial(world, seed=0)
        d = math.dist(trial.start[:2], trial.goal[:2])
        size = "x".join(f"{v:.0f}" for v in world.mesh.extents[:2])
        print(
            f"| `{model.relative_to(REAL)}` | a model on the ground plane ({size} m) | {d:.2f} m "
            f"| {trial.plan_time:.2f} s | {trial.outcome} ({trial.drive_time:.1f} s driven) "
            f"| {load:.1f} s |"
        )


if __name__ == "__main__":
    main()
