"""Every capture a scene: synthetic depth captures of each library scene, at each Kinect 2 and
RealSense preset, from three viewpoints, each used as a scene as a user would (`roachplan trial
--scene cap.png`), with the time of each stage.

    make bench        (or: .venv/bin/python benchmarks/bench_captures.py [--quick])

Viewpoints (perception.survey_views), around the scene's terrain: low and near, high and far,
oblique. Stages: render (the synthetic depth image), world (perception,
height field, start and goal picked), sim terrain (what PyBullet is given), plan (PRM, seed 1),
drive (the tracking driver). A row ends in one of: driven (and its outcome), "no pick" (no
start and goal the planner joins: the message says why), "no path", or "ERROR" (an exception
that is not an input error: the goal is none). Then the time from a 1920x1080 and a 640x480
capture to the first path, side by side. --quick: one viewpoint and two presets;
--first-path: that comparison alone.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from roachplan import drive, plan
from roachplan._errors import InputError
from roachplan.perception import (
    PRESETS,
    NoiseModel,
    look_at,
    render_depth,
    save_depth,
    survey_views,
)
from roachplan.scenes import (
    LIBRARY,
    build_terrain_mesh,
    build_world,
    library_names,
    load_scene,
    seen_mesh,
)

CAMERAS = ("kinect2-sd", "kinect2-qhd", "kinect2-hd", "realsense-d435-1280x720")


def scene_mesh(name: str) -> tuple[trimesh.Trimesh, dict]:
    """A library scene's terrain with its ground as a large slab (what the camera sees), and
    the survey views of its terrain (of its planning area where it has none)."""
    scene = load_scene(name)
    mesh = build_terrain_mesh(scene)
    if len(mesh.faces):
        views = survey_views(mesh.bounds)
    else:
        assert scene.bounds is not None  # (a scene without terrain gives its bounds)
        (x0, y0), (x1, y1) = scene.bounds
        views = survey_views([[x0, y0, scene.ground or 0.0], [x1, y1, scene.ground or 0.0]])
    return seen_mesh(scene), views


def run(png: Path) -> dict:
    """One capture used as a scene: each stage's time [s] and how it ended."""
    row: dict = {}
    t = time.perf_counter()
    try:
        world = build_world(load_scene(str(png)))
    except InputError as exc:
        row.update(world=time.perf_counter() - t, end="no pick", why=str(exc).split(": ")[-1])
        return row
    row["world"] = time.perf_counter() - t
    row["triangles"] = len(world.mesh.faces)
    t = time.perf_counter()
    terrain = world.sim_terrain
    row["sim"] = time.perf_counter() - t
    row["sim_triangles"] = len(terrain.faces)
    row["distance"] = float(np.hypot(*np.subtract(world.goal[:2], world.start[:2])))
    t = time.perf_counter()
    planned = plan(world, seed=1)
    row["plan"] = time.perf_counter() - t
    if not planned.found:
        row["end"] = "no path"
        return row
    t = time.perf_counter()
    driven = drive(world, planned)
    row["drive"] = time.perf_counter() - t
    row["end"] = f"driven: {driven.outcome}"
    return row


def sweep(quick: bool) -> None:
    cameras = CAMERAS[:2] if quick else CAMERAS
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in library_names(LIBRARY):
            mesh, views = scene_mesh(name)
            for view, (eye, target) in list(views.items())[: 1 if quick else 3]:
                for camera in cameras:
                    intr = PRESETS[camera]
                    png = Path(tmp) / f"{name}-{view}-{camera}.png"
                    t = time.perf_counter()
                    depth = render_depth(
                        mesh, intr, look_at(eye, target), NoiseModel(), np.random.default_rng(0)
                    )
                    save_depth(png, depth, intr, world_from_camera=look_at(eye, target))
                    render = time.perf_counter() - t
                    row: dict = {}
                    try:
                        row = run(png)
                    except Exception as exc:  # the goal: none
                        row = {"end": f"ERROR {type(exc).__name__}: {str(exc)[:80]}"}
                    row.update(scene=name, view=view, camera=camera, render=render)
                    rows.append(row)
                    print(_line(row), flush=True)
    driven = [r for r in rows if r["end"].startswith("driven") and r["distance"] >= 1.0]
    errors = [r for r in rows if r["end"].startswith("ERROR")]
    print(
        f"\n{len(rows)} captures: {len(errors)} errors, {len(driven)} planned and driven "
        f"at least 1 m, {sum(r['end'] == 'no pick' for r in rows)} with no start and goal, "
        f"{sum(r['end'] == 'no path' for r in rows)} with no path"
    )


def _line(r: dict) -> str:
    times = " ".join(
        f"{k} {r[k]:5.1f}s" if k in r else f"{k}   -  " for k in ("world", "sim", "plan", "drive")
    )
    size = (
        f"{r['triangles']:>7,} -> {r['sim_triangles']:>6,} tri  {r['distance']:.2f} m"
        if "sim_triangles" in r
        else " " * 33
    )
    return (
        f"{r['scene']:<20} {r['view']:<9} {r['camera']:<24} render {r['render']:4.1f}s {times} "
        f"{size}  {r['end']}{': ' + r['why'][:60] if 'why' in r else ''}"
    )


def first_path() -> None:
    """Capture to first path: 1920x1080 beside 640x480, the same view of double_bridge."""
    mesh, views = scene_mesh("double_bridge")
    eye, target = views["high-far"]
    times = {}
    with tempfile.TemporaryDirectory() as tmp:
        for camera in ("kinect2-hd", "realsense-d435-640x480"):
            intr = PRESETS[camera]
            png = Path(tmp) / f"{camera}.png"
            depth = render_depth(
                mesh, intr, look_at(eye, target), NoiseModel(), np.random.default_rng(0)
            )
            save_depth(png, depth, intr, world_from_camera=look_at(eye, target))
            t = time.perf_counter()
            world = build_world(load_scene(str(png)))
            planned = plan(world, seed=1)
            times[camera] = time.perf_counter() - t
            print(
                f"{camera:<24} {intr.width}x{intr.height}: file to first path "
                f"{times[camera]:.1f} s (found: {planned.found})"
            )
    ratio = times["kinect2-hd"] / times["realsense-d435-640x480"]
    print(f"1920x1080 / 640x480: {ratio:.2f}x (goal: the 1920x1080 within 10 s on 2 cores)")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="one view, two cameras")
    parser.add_argument(
        "--first-path", action="store_true", help="only the capture-to-first-path timing"
    )
    args = parser.parse_args()
    if not args.first_path:
        sweep(args.quick)
        print()
    first_path()


if __name__ == "__main__":
    main()
