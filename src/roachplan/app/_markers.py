"""The Start and goal folder: what a click on the terrain places, the two markers' yaws, and why
a marker is invalid (which validity condition, which leg), shown in red on the marker itself;
and the handlers of a click on the terrain and of a marker moved.
"""

from __future__ import annotations

import math

import numpy as np

from roachplan.planning import PlanningError
from roachplan.scenes import World, pose_problem

from ._app import App
from ._commands import MarkersCmd, PlaceCmd
from ._draw import INVALID, MARKER_COLOURS, SceneView, ground_plane, on_surface, yaw_wxyz
from ._loop import WhileBusy
from ._picking import click_point
from ._uploads import PLACE_THEM


def pick_failure(world: World) -> str | None:
    """Why start and goal of world could not be picked automatically, or None when they were
    (or were given). scenes/_world.py build_world (check_poses=False) leaves a failed pick as
    start = goal at the bounds' centre, the reason its last note."""
    sc = world.scene
    if sc.start is None or sc.goal is None or tuple(sc.start[:2]) != tuple(sc.goal[:2]):
        return None
    return world.notes[-1] if world.notes else "start and goal are one point"


def with_remedy(reason: str) -> str:
    """The reason a pick failed, as the page says it: ending in what to do in the page (unless
    the reason, in the page's words, says so already)."""
    if "Click places" in reason:
        return reason
    return f"{reason.rstrip('. ')}; {PLACE_THEM}."


def one_place(world: World, start, goal) -> str:
    """Why start and goal ((x [m], y [m], yaw [rad]) each) are no trip, or "": closer than the
    planner's goal radius, the robot stands at its goal already - a plan of them is one point
    and a drive of it 0 s, no trial (and where build_world could not pick them it leaves both
    at one placeholder point: scenes/_world.py)."""
    apart = math.dist(start[:2], goal[:2])
    radius = world.scene.planner.goal_radius
    if apart >= radius:
        return ""
    return (
        f"{apart:.2f} m apart, within the goal radius ({radius:g} m): there is nothing to "
        f"drive; place the goal elsewhere (Start and goal → Click places)"
    )


class StartGoal:
    """The folder's widgets, over the markers drawn by a SceneView."""

    def __init__(self, gui, put, view: SceneView) -> None:
        self.view = view
        with gui.add_folder("Start and goal"):
            self.click_mode = gui.add_dropdown("Click places", ("nothing", "start", "goal"))
            self.start_yaw = gui.add_slider("Start yaw [deg]", -180, 180, 1, 90)
            self.goal_yaw = gui.add_slider("Goal yaw [deg]", -180, 180, 1, 90)
            self.validity = gui.add_markdown("")
        self.failure: str | None = None
        """Why the world's start and goal could not be picked, in the page's words (None: they
        were, or were given)."""
        for slider in (self.start_yaw, self.goal_yaw):
            slider.on_update(lambda ev: put(MarkersCmd(ev.client_id)))

    def reset(self, world: World, failure: str | None = None) -> None:
        """The yaws of a newly shown world's start and goal (the markers are at them); failure:
        why they could not be picked (pick_failure, in the page's words), said above the
        markers' problems while either is invalid."""
        self.failure = None if failure is None else with_remedy(failure)
        self.start_yaw.value = round(math.degrees(world.start[2]))
        self.goal_yaw.value = round(math.degrees(world.goal[2]))

    def pose(self, which: str) -> tuple[float, float, float]:
        """The marker "start" or "goal" as (x [m], y [m], yaw [rad])."""
        x, y = (float(v) for v in self.view.controls[which].position[:2])
        yaw = self.start_yaw.value if which == "start" else self.goal_yaw.value
        return (x, y, math.radians(float(yaw)))

    def check(self, world: World) -> bool:
        """Colour each marker (red when invalid), turn it to its yaw, say why it is invalid;
        whether both are valid."""
        lines = []
        for which in ("start", "goal"):
            pose = self.pose(which)
            problem = pose_problem(world, pose)
            (lo, hi) = world.bounds
            if not problem and not (lo[0] <= pose[0] <= hi[0] and lo[1] <= pose[1] <= hi[1]):
                problem = (
                    f"outside the planning area x in [{lo[0]:g}, {hi[0]:g}], "
                    f"y in [{lo[1]:g}, {hi[1]:g}]"
                )
            colour = INVALID if problem else MARKER_COLOURS[which]
            if tuple(self.view.balls[which].color) != colour:
                self.view.balls[which].color = colour
            wxyz = yaw_wxyz(pose[2])
            if not np.allclose(self.view.controls[which].wxyz, wxyz):  # (a change calls back)
                self.view.controls[which].wxyz = wxyz
            if problem:
                lines.append(f"**{which} invalid**: {problem}")
        same = one_place(world, self.pose("start"), self.pose("goal"))
        if same:
            lines.append(f"**start and goal are one place**: {same}")
        if lines and self.failure is not None:
            lines.insert(0, f"**Start and goal were not picked**: {self.failure}")
        text = "  \n".join(lines) or "Start and goal are valid."
        if self.validity.content != text:
            self.validity.content = text
        return not lines

    def valid_poses(self, world: World) -> tuple[tuple, tuple]:
        """(start, goal); PlanningError saying why when either is invalid."""
        if not self.check(world):
            raise PlanningError(self.validity.content.replace("**", ""))
        return self.pose("start"), self.pose("goal")


def do_place(app: App, cmd: PlaceCmd) -> None:
    """A click on the terrain: the voxel study's square centred there, the capture's ground
    picked there, or a marker placed there (Page.click_target)."""
    target = app.page.click_target()
    if target == "nothing":
        return
    w = app.world
    hit = click_point(
        w.mesh.vertices,
        w.mesh.faces,
        w.heightfield,
        cmd.ray_origin,
        cmd.ray_direction,
        ground=ground_plane(w),
    )
    if hit is None:
        app.page.notify(cmd.client_id, "Missed", "That click does not hit the terrain.")
        return
    if target == "square":
        app.page.voxel_panel.set_centre(app, cmd, hit)
    elif target == "ground":  # the load panel's "Pick ground": re-level the capture there
        app.page.load_panel.relevel_at_click(app, cmd, hit)
    else:
        app.page.place_marker(target, tuple(float(v) for v in hit))
        app.page.check_markers()
        app.page.show_robot_at_start()
        app.page.set_status(f"{target.capitalize()} placed at ({hit[0]:.2f}, {hit[1]:.2f}).")


def click_while_busy(app: App, cmd: PlaceCmd) -> WhileBusy:
    """A click that picks the capture's ground or the square starts or changes background work
    (a load, the study's region): at once. One that places a marker waits its turn (the running
    command was clicked with the markers where they are)."""
    return "run" if app.page.click_target() in ("ground", "square") else "queue"


def do_check_markers(app: App, cmd: MarkersCmd) -> None:
    """A marker moved: re-check both, and stand the robot at the start. At the end of a drag
    the markers are put down on the surface where they stand: a drag moves a marker in the
    level plane of its height, so one dragged over lower (or higher) ground floats over (or
    sinks into) it, the place it stands on hidden behind (or in front of) it."""
    if cmd.settled:
        for which in ("start", "goal"):
            ctl = app.page.view.controls[which]
            p = on_surface(app.world, app.page.markers.pose(which))
            if abs(float(ctl.position[2]) - p[2]) > 1e-4:
                app.page.place_marker(which, p)
    app.page.check_markers()
    app.page.show_robot_at_start()
