"""The page's Voxel study folder (issue 14, item 6): table 3.1 of the report on the loaded capture.

The user picks the region: a square of the terrain (side [m], centred on the next click on it,
world x and y as drawn), or the ground plane the load found. The study itself is
perception's `voxel_study` (the 5-sigma rejection loop, so "points kept" is real) and
`planarity_warning` (a region that is plainly not one flat surface is said so, in the panel and
as a notification); it runs in a child process (`Job`), followed by `app.loop.follow` with
progress and Cancel. The table can be downloaded as CSV (`study_csv`, the CLI's format).

Callbacks only put a VoxelCmd on the app's queue; the command loop runs `do_voxel` (and
`set_centre` for a click on the terrain, app/_markers.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from roachplan.perception import CaptureError
from roachplan.perception._voxel_study import (
    VoxelStudyRow,
    planarity_warning,
    plane_region,
    study_csv,
    voxel_study,
)
from roachplan.processes import Channel, Died, Returned

from ._app import App
from ._commands import VoxelCmd
from ._jobs import Job, failure

MODES = ("Square", "Ground plane")
"""The region choices of the folder's dropdown."""
DEFAULT_SIZES = "1,2,5,10,20"
"""Voxel sizes [cm] the folder starts with (a subset of the report's table 3.1)."""
MAX_SIZES = 31
"""At most this many voxel sizes (as `roachplan voxel-study --sizes`)."""
GROUND_SLAB = 0.05
"""Ground plane: the points within this height of the ground found (z = 0) [m] are where
plane_region looks for it. Wider than the ground finder's 1.5 cm RANSAC band so that a noisy
far floor is not cut to the band (plane_region then settles its own band at 3 standard errors),
narrower than a step or a chair's feet, which are not the floor."""
PAGE_HINT = "study one surface: a smaller square on the floor or a wall, or Region: Ground plane"
"""What planarity_warning advises, in the page's terms."""
SQUARE_COLOUR = (255, 140, 0)
"""The studied square's outline (orange: apart from the green start and blue goal)."""
SQUARE_LIFT = 0.01
"""The outline is drawn this far above the terrain [m] so that the surface does not hide it."""


@dataclass(frozen=True, kw_only=True)
class StudyRequest:
    """What the study's child needs (plain data: it is pickled to the child)."""

    scene_path: Path
    """The loaded scene file (one capture object)."""
    world_from_camera: np.ndarray
    """(4, 4) capture-frame points [m] -> the ground frame the load found (z up, ground z = 0)."""
    sizes_cm: tuple[float, ...]
    """Voxel edges [cm]."""
    mode: Literal["Square", "Ground plane"]
    centre: tuple[float, float] | None
    """Square: its centre, world x, y [m] (the scene's frame, as drawn)."""
    side: float
    """Square: its side [m]."""
    seed: int
    """Seed of plane_region's RANSAC (Ground plane)."""


@dataclass(frozen=True, kw_only=True)
class StudyResult:
    rows: tuple[VoxelStudyRow, ...]
    """The raw points' row, then one per voxel size."""
    warning: str | None
    """planarity_warning's words, or None for a flat region."""
    points: int
    """Points in the region studied."""
    total: int
    """Finite points of the capture."""
    where: str
    """The region in words."""


def parse_sizes(text: str) -> tuple[float, ...]:
    """Voxel sizes [cm] typed as "1,2,5,10,20"; CaptureError in one line when they are not."""
    accepted = f"1 to {MAX_SIZES} numbers > 0 [cm] separated by commas, e.g. {DEFAULT_SIZES}"
    try:
        sizes = tuple(float(s) for s in text.replace(" ", "").split(",") if s != "")
    except ValueError:
        raise CaptureError(f"Voxel sizes [cm] {text!r}: expected {accepted}") from None
    if not 1 <= len(sizes) <= MAX_SIZES or not all(math.isfinite(s) and s > 0 for s in sizes):
        raise CaptureError(f"Voxel sizes [cm] {text!r}: expected {accepted}")
    return sizes


def _placed(obj, world_from_camera: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Capture-frame points [m] -> the scene's world frame: the load's ground frame, then the
    object's scale and placement (as scenes places its mesh)."""
    from scipy.spatial.transform import Rotation

    g = points @ world_from_camera[:3, :3].T + world_from_camera[:3, 3]
    g = g * np.asarray(obj.scale)
    return g @ Rotation.from_quat(obj.orientation).as_matrix().T + np.asarray(obj.position)


def run_study(req: StudyRequest, on_stage=lambda name: None) -> StudyResult:
    """The study of the requested region of the scene's capture (the CLI's `voxel-study`, with
    the region picked in the world frame). on_stage(name) as "read" and "region" end."""
    from roachplan.perception import load_capture
    from roachplan.scenes import load_scene

    scene = load_scene(req.scene_path)
    obj = next(o for o in scene.terrain if o.kind == "capture")
    s = obj.capture
    cap = load_capture(
        obj.source,
        intrinsics=s.intrinsics,
        depth_scale=s.depth_scale,
        topic=s.topic,
        units=s.units,
        depth_units=s.depth_units,
    )
    raw = cap.finite_points()
    on_stage("read")
    wfc = np.asarray(req.world_from_camera, dtype=np.float64)
    if req.mode == "Square":
        if req.centre is None:
            raise CaptureError("Square: tick Pick square centre, then click the terrain")
        world = _placed(obj, wfc, raw)
        half = req.side / 2
        inside = (np.abs(world[:, 0] - req.centre[0]) <= half) & (
            np.abs(world[:, 1] - req.centre[1]) <= half
        )
        where = f"the {req.side:g} m square at ({req.centre[0]:.2f}, {req.centre[1]:.2f})"
        pts = raw[inside]
    else:
        ground_z = raw @ wfc[2, :3] + wfc[2, 3]  # height above the ground found [m]
        near = raw[np.abs(ground_z) <= GROUND_SLAB]
        if len(near) < 4:
            raise CaptureError(
                f"{len(near)} points within {GROUND_SLAB * 100:g} cm of the "
                f"ground found: too few to study; pick a Square instead"
            )
        pts = plane_region(near, req.seed)
        where = f"the ground plane (seed {req.seed})"
    if len(pts) < 4:
        raise CaptureError(
            f"{len(pts)} points within {where}; 4 or more needed: click the "
            f"capture's terrain, or a larger Square side"
        )
    on_stage("region")
    # The study in the capture's own frame about its sensor, as the CLI does: the voxel grid is
    # the camera's (section 3.1), and the range that sets the noise limit is from the sensor.
    pts = pts - np.asarray(cap.sensor_origin)
    rows = voxel_study(pts, list(req.sizes_cm))
    range_m = float(np.median(np.linalg.norm(pts, axis=1)))
    return StudyResult(
        rows=tuple(rows),
        warning=planarity_warning(rows[0], range_m, PAGE_HINT),
        points=len(pts),
        total=len(raw),
        where=where,
    )


@dataclass(frozen=True, kw_only=True)
class StudyStage:
    """A study job's event: one of run_study's stages ("read", "region") is done."""

    name: str


def _study_job(events: Channel, req: StudyRequest) -> StudyResult:
    """run_study in a child (under the child memory limit: a study of a huge cloud ends in a
    notification, not by taking the machine), a StudyStage event per stage."""
    return run_study(req, on_stage=lambda name: events.send(StudyStage(name=name)))


def _study_failure(job: Job) -> str:
    outcome = job.outcome
    if isinstance(outcome, Died) and outcome.cause == "memory":
        return "the study needed more memory than the server allows a job: pick a smaller square"
    return failure(job) or "the study's process ended without a result"


def table_markdown(result: StudyResult) -> str:
    """Table 3.1's columns as a markdown table, with the region and the warning."""
    lines = [
        f"{result.points} of {result.total} points: {result.where}.",
        "",
        "| voxel size [cm] | points | points kept | error [mm] |",
        "|---:|---:|---:|---:|",
    ]
    for r in result.rows:
        size = "N/A" if r.voxel_cm is None else f"{r.voxel_cm:g}"
        lines.append(f"| {size} | {r.points} | {r.kept} | {r.error_mm:.3f} |")
    if result.warning is not None:
        lines += ["", f"⚠ {result.warning}"]
    return "\n".join(lines)


def square_outline(heightfield, centre, side: float, n: int = 24) -> np.ndarray:
    """(4 n + 1, 3) points [m] of the square's outline draped on the terrain (z = 0 where the
    height field has no surface), lifted SQUARE_LIFT."""
    h = side / 2
    cx, cy = centre
    corners = np.array(
        [[cx - h, cy - h], [cx + h, cy - h], [cx + h, cy + h], [cx - h, cy + h], [cx - h, cy - h]]
    )
    t = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
    xy = np.concatenate(
        [a + t * (b - a) for a, b in zip(corners[:-1], corners[1:])] + [corners[-1:]]
    )
    z = np.nan_to_num(heightfield.sample(xy), nan=0.0) + SQUARE_LIFT
    return np.column_stack([xy, z])


class VoxelPanel:
    """The folder's widgets and what the app keeps for them: the square's centre and the last
    study."""

    def __init__(self, gui, put) -> None:
        self.centre: tuple[float, float] | None = None
        """The square's centre, world x, y [m], picked on the current world."""
        self.result: StudyResult | None = None
        self.scene_name = ""
        """The scene the last study was of (the CSV's name)."""
        with gui.add_folder("Voxel study"):
            self.sizes = gui.add_text(
                "Voxel sizes [cm]",
                DEFAULT_SIZES,
                hint="Edges of the voxels, comma separated (table 3.1)",
            )
            self.mode = gui.add_dropdown(
                "Region",
                MODES,
                initial_value=MODES[0],
                hint="Square: a square of the terrain; Ground plane: the plane the load found",
            )
            self.side = gui.add_number("Square side [m]", 0.5, min=0.02, max=20.0, step=0.01)
            self.pick_centre = gui.add_checkbox(
                "Pick square centre", False, hint="The next click on the terrain centres the square"
            )
            self.run_button = gui.add_button(
                "Run voxel study", hint="Table 3.1 of the loaded capture's region"
            )
            self.csv_button = gui.add_button("Download study CSV", disabled=True)
            self.info = gui.add_markdown("Load a capture, pick a region, then **Run voxel study**.")
        self.run_button.on_click(lambda ev: put(VoxelCmd(ev.client_id, "run")))
        self.csv_button.on_click(lambda ev: put(VoxelCmd(ev.client_id, "csv")))

    def clear(self) -> None:
        """A new world: its square and study are gone (the /markers root is redrawn)."""
        self.centre, self.result = None, None
        self.pick_centre.value = False
        self.csv_button.disabled = True
        self.info.content = "Load a capture, pick a region, then **Run voxel study**."

    def _draw_square(self, app: App) -> None:
        if self.centre is None:
            return
        pts = square_outline(app.world.heightfield, self.centre, float(self.side.value))
        app.page.view.draw("/markers/voxel_square", pts, SQUARE_COLOUR, thickness=4.0)

    def set_centre(self, app: App, cmd, hit) -> None:
        """The square's centre at a clicked terrain point (world [m]); one click, one centre."""
        self.pick_centre.value = False
        self.centre = (float(hit[0]), float(hit[1]))
        self._draw_square(app)
        self.info.content = (
            f"Square of {float(self.side.value):g} m at ({hit[0]:.2f}, "
            f"{hit[1]:.2f}): press **Run voxel study**."
        )

    def handle(self, app: App, cmd: VoxelCmd) -> None:
        if cmd.action == "csv":
            if self.result is not None:
                app.page.send_file(
                    cmd.client_id,
                    f"{self.scene_name}-voxel-study.csv",
                    study_csv(list(self.result.rows)).encode(),
                )
        elif cmd.action == "run":
            self._run(app, cmd)

    def _run(self, app: App, cmd: VoxelCmd) -> None:
        view = app.page.load_panel.view
        if view is None:
            app.page.notify(
                cmd.client_id,
                "No capture loaded",
                "The voxel study works on a capture loaded from a file.",
                error=True,
            )
            return
        sizes = parse_sizes(self.sizes.value)
        mode, side = self.mode.value, float(self.side.value)
        if mode == "Square" and self.centre is None:
            app.page.notify(
                cmd.client_id,
                "No square yet",
                "Tick Pick square centre, then click the terrain where the square goes.",
                error=True,
            )
            return
        if mode == "Square" and not (math.isfinite(side) and side > 0):
            raise CaptureError(f"Square side [m] {side!r}: expected a length > 0")
        if mode == "Square":
            self._draw_square(app)  # (the side may have changed since the click)
        else:
            app.page.view.remove("/markers/voxel_square")
        req = StudyRequest(
            scene_path=view.scene_path,
            world_from_camera=view.world_from_camera,
            sizes_cm=sizes,
            mode=mode,
            centre=self.centre,
            side=side,
            seed=app.world.scene.seed,
        )
        job, stages = Job(_study_job, req), []
        steps = {
            "read": (0.3, "capture read; finding the region"),
            "region": (0.5, f"fitting planes at {len(sizes) + 1} voxel sizes"),
        }

        def step(events: list[StudyStage]) -> bool:
            stages.extend(event.name for event in events)
            done, what = (
                steps.get(stages[-1], (0.5, "")) if stages else (0.05, "reading the capture")
            )
            app.loop.progress(done, f"Voxel study: {what}, {job.elapsed:.1f} s")
            return job.done

        end = app.loop.follow(job, "Voxel study", step)
        if end != "done":
            app.page.set_status(f"Voxel study cancelled after {job.elapsed:.1f} s.")
            return
        if not isinstance(job.outcome, Returned):
            why = _study_failure(job)
            app.page.set_status(f"Voxel study failed: {why}")
            app.page.notify(cmd.client_id, "Voxel study failed", why, error=True)
            return
        self.result, self.scene_name = job.outcome.value, app.world.scene.name
        self.info.content = table_markdown(self.result)
        self.csv_button.disabled = False
        app.page.set_status(
            f"Voxel study of {self.result.where}: {self.result.points} points, "
            f"in {job.elapsed:.1f} s (table in the Voxel study folder)."
        )
        if self.result.warning is not None:
            app.page.notify(cmd.client_id, "Region not planar", self.result.warning)


def do_voxel(app: App, cmd: VoxelCmd) -> None:
    """A button of the Voxel study folder."""
    app.page.voxel_panel.handle(app, cmd)
