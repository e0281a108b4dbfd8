"""`roachplan mesh`, `voxel-study` and `synth-capture`: captures to terrain meshes, table 3.1 of
a capture, and synthetic captures of a scene. Their capture flags are read as a scene's
`perception:` block is (app/_flags.py capture_settings_of)."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from roachplan.experiments import check_output_file
from roachplan.perception import CaptureError

from ._flags import UsageError, capture_settings_of, clip, numbers
from ._progress import stage_progress
from ._scene_cli import MESH_WRITTEN, export_mesh, scene_inputs


def _mesh_with_progress(path: str, settings):
    """mesh_capture with a bar over its stages (run in the meshing child)."""
    from roachplan.perception import STAGES, mesh_capture

    meshing, on_stage = stage_progress(("read", *STAGES), "meshing")
    with meshing:
        return mesh_capture(path, settings, on_stage)


def cmd_mesh(args: argparse.Namespace) -> int:
    settings = capture_settings_of(args)
    out = check_output_file(
        args.output,
        suffixes=(".stl", ".ply", ".obj"),
        inputs=(args.input, args.intrinsics),
        kind=MESH_WRITTEN,
        force=args.force,
    )
    import open3d  # noqa: F401 - mapped here, not under the child's address-space limit
    import tqdm  # noqa: F401

    from roachplan.perception import mesh_capture  # noqa: F401 - its pipeline, likewise
    from roachplan.planning import run_isolated

    # In a child under the memory limit (issue 15): a capture that needs more ends in a clear
    # error, not by taking the machine; its progress bar is drawn by the child, which inherits
    # the libraries loaded above (loading them under the limit would fail first).
    rec = run_isolated(_mesh_with_progress, args.input, settings, isolation="fork", task="meshing")
    export_mesh(rec.mesh, out)
    report = {"input": args.input, "output": str(out), **rec.report()}
    if args.json:
        print(json.dumps(report))
        return 0
    print(f"wrote {out}: {report['triangles']} triangles, bounds {report['bounds']} m")
    print("points: " + ", ".join(f"{k} {v}" for k, v in rec.counts.items()))
    print("seconds: " + ", ".join(f"{k} {v:.3f}" for k, v in rec.times.items()))
    print(f"frame: {report['frame']}; up: {report['up_source']}")
    if report["camera_pose"] is not None:
        g = report.get("ground") or {}
        print(
            f"camera: {report['camera_height_m']:.3f} m above the ground, pitched "
            f"{report['pitch_down_deg']:.1f} deg down, roll {report['roll_deg']:.1f} deg; ground "
            f"support {100 * g.get('support_fraction', 1.0):.0f} % of the points, "
            f"{g.get('area_m2', 0.0):.2f} m^2 seen"
        )
        print(
            "camera pose in the world (x,y,z,qx,qy,qz,qw): "
            + ",".join(f"{v:.5f}" for v in report["camera_pose"])
        )
    for note in report["notes"]:
        print(f"note: {note}")
    for warning in report["warnings"]:
        print(f"roachplan: warning: {warning}", file=sys.stderr)
    return 0


def _study_flags(args: argparse.Namespace) -> tuple[list[float], list[float] | None]:
    """voxel-study's --sizes [cm] and --region (x0, y0, x1, y1 [m], camera frame), checked."""
    sizes = numbers(args.sizes, "--sizes", tuple(range(1, 32)))
    assert sizes is not None  # (--sizes has a default)
    if not all(s > 0 for s in sizes):
        raise UsageError(
            f"--sizes {clip(repr(args.sizes), 80)}: voxel sizes must be numbers > 0 [cm]"
        )
    region = numbers(args.region, "--region", (4,))
    if region is not None:
        x0, y0, x1, y1 = region
        if not (x0 < x1 and y0 < y1):
            raise UsageError(
                f"--region {clip(repr(args.region), 80)}: expected x0,y0,x1,y1 [m] in the "
                f"camera frame with x0 < x1 and y0 < y1"
            )
        if args.square is not None:
            raise UsageError("pass either --square or --region, not both")
    return sizes, region


def cmd_voxel_study(args: argparse.Namespace) -> int:
    from roachplan.experiments import atomic_write
    from roachplan.perception import (
        format_study,
        load_capture,
        planarity_warning,
        plane_region,
        rect_region,
        square_region,
        study_csv,
        study_json,
        voxel_study,
    )

    sizes, region = _study_flags(args)
    settings = capture_settings_of(args)
    if args.csv is not None:  # before the study's work, not after it
        header = study_csv([]).encode()  # a CSV that starts with the study's header: ours
        check_output_file(
            args.csv,
            flag="--csv",
            suffixes=(".csv",),
            inputs=(args.capture, args.intrinsics),
            kind="a voxel-study table",
            replaceable=lambda head: head.startswith(header),
            force=args.force,
        )
    cap = load_capture(
        args.capture,
        intrinsics=settings.intrinsics,
        depth_scale=settings.depth_scale,
        topic=settings.topic,
        units=settings.units,
        depth_units=settings.depth_units,
    )
    pts = cap.finite_points() - cap.sensor_origin
    total, where = len(pts), "the whole capture"
    if args.square is not None:
        pts, where = square_region(pts, args.square), f"the {args.square:g} m square"
    elif region is not None:
        pts, where = rect_region(pts, *region), f"the region {args.region}"
    if len(pts) < 4:
        raise CaptureError(f"{args.capture}: {len(pts)} points within {where}; 4 or more needed")
    if args.plane:
        pts = plane_region(pts, settings.meshing.seed)
        where = f"the dominant plane of {where} (seed {settings.meshing.seed})"
    rows = voxel_study(pts, sizes)
    warning = planarity_warning(rows[0], float(np.median(np.linalg.norm(pts, axis=1))))
    if args.json:
        print(
            json.dumps(
                {
                    "capture": args.capture,
                    "region": where,
                    "capture_points": total,
                    **study_json(rows, warning),
                }
            )
        )
    else:
        print(f"{len(pts)} of {total} points: {where}")
        print(format_study(rows))
    if warning is not None:
        print(f"roachplan: warning: {warning}", file=sys.stderr)
    if args.csv:
        atomic_write(args.csv, study_csv(rows))
        print(f"wrote {args.csv}", file=sys.stderr if args.json else sys.stdout)
    return 0


def cmd_synth_capture(args: argparse.Namespace) -> int:
    from roachplan.perception import (
        NO_NOISE,
        NoiseModel,
        load_intrinsics,
        look_at,
        render_depth,
        save_depth,
    )
    from roachplan.scenes import load_scene, seen_mesh

    scene = load_scene(args.scene)
    eye = numbers(args.eye, "--eye", (3,))
    target = numbers(args.target, "--target", (3,))
    # A capture may be a real one, not ours to replace: an existing file needs --force.
    inputs = (*scene_inputs(scene), args.intrinsics)
    out = check_output_file(
        args.output,
        suffixes=(".png", ".pcd", ".ply", ".npy"),
        inputs=inputs,
        replaceable=None,
        kind="a capture, perhaps a real one, is replaced only with --force",
        force=args.force,
    )
    if out.suffix.lower() == ".png":  # and its calibration beside it
        check_output_file(
            out.with_suffix(".json"),
            flag="-o (the .png's sidecar)",
            inputs=inputs,
            replaceable=None,
            kind="a capture's calibration is replaced only with --force",
            force=args.force,
        )
    mesh = seen_mesh(scene)  # (the endless floor as a big square)
    intr = load_intrinsics(args.intrinsics)
    pose = look_at(eye, target)
    noise = NO_NOISE if args.no_noise else NoiseModel()
    depth = render_depth(mesh, intr, pose, noise, np.random.default_rng(args.seed))
    written = save_depth(out, depth, intr, world_from_camera=pose)
    print(
        f"wrote {', '.join(map(str, written))}: {intr.width}x{intr.height}, "
        f"{np.mean(depth > 0) * 100:.1f} % of pixels measured, seed {args.seed}"
    )
    return 0
