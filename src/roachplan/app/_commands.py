"""What the page's callbacks put on the command loop's queue: one frozen dataclass per command.

Each is listed once, with its handler, its name on the page and what a click on it does while
another command runs, in app/_registry.py; the loop (app/_loop.py) runs them one at a time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class Cmd:
    client_id: int | None
    """The browser that sent it (its notifications go there); None: none (a test, a script)."""


# -- Plan and drive, Results ---------------------------------------------------------------------


@dataclass(frozen=True)
class PlanCmd(Cmd):
    """Plan: up to K paths between the markers within the time budget."""


@dataclass(frozen=True)
class DriveCmd(Cmd):
    """Drive: walk the marked path in the simulation, played back as it comes."""


@dataclass(frozen=True)
class ResetCmd(Cmd):
    """Reset: the roach back at the start marker."""


@dataclass(frozen=True)
class BestPathCmd(Cmd):
    """Best path: drive the lowest-energy successful path of the scene's trials again."""


@dataclass(frozen=True)
class ChooseCmd(Cmd):
    """Choose path: race K candidate paths by simulation; Drive then takes the chosen one."""


@dataclass(frozen=True)
class RunTrialsCmd(Cmd):
    """Run trials: a batch of N trials on worker processes."""


@dataclass(frozen=True)
class ShowTrialCmd(Cmd):
    """The Show trial picker changed: draw that trial's path and trajectory."""


@dataclass(frozen=True)
class ExportCmd(Cmd):
    """Export CSV: the scene's trials, as a download to the browser that clicked."""


@dataclass(frozen=True)
class ShareCmd(Cmd):
    """Share: the shown trial (else the last) as a replay page, a download."""


# -- Robot ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RobotPlanCmd(Cmd):
    """Route from robot: connect, locate the robot, plan from where it stands, predict, hold it."""


@dataclass(frozen=True)
class RobotGoCmd(Cmd):
    """Go: drive the held robot along its plan."""


@dataclass(frozen=True)
class RobotStopCmd(Cmd):
    """Stop (the Robot folder's): the robot stopped now, even while Go runs."""


# -- Start and goal, View -------------------------------------------------------------------------


@dataclass(frozen=True)
class PlaceCmd(Cmd):
    """A click on the terrain, as viser gives it: a ray (world frame [m])."""

    ray_origin: tuple[float, float, float]
    ray_direction: tuple[float, float, float]


@dataclass(frozen=True)
class MarkersCmd(Cmd):
    """A marker was dragged or a yaw slider moved: re-check start and goal."""

    settled: bool = False
    """The drag ended (the marker is put down on the surface where it stands)."""


@dataclass(frozen=True)
class ViewCmd(Cmd):
    """A change of what is seen: "roadmap", "paths", "trajectories", "standable" (the
    toggles), "drive_path" (the Drive path picker), "follow", "zoom" (the clicking browser's
    camera)."""

    what: Literal["roadmap", "paths", "trajectories", "standable", "drive_path", "follow", "zoom"]


@dataclass(frozen=True)
class EngineCmd(Cmd):
    """The Physics engine picker changed: every drive, batch and Choose from now on, on this
    scene and those loaded after it, runs in this engine."""

    engine: str
    """"pybullet" or "mujoco" (sim.ENGINES)."""


# -- Scene, loading --------------------------------------------------------------------------------


@dataclass(frozen=True)
class LoadSceneCmd(Cmd):
    """The scene picker changed: load the scene it names."""

    name: str
    """The picker's label: a library scene's name, or a loaded file's label."""


@dataclass(frozen=True)
class UploadCmd(Cmd):
    """Load file: a file uploaded from the page."""

    name: str
    """The file's name as uploaded."""
    data: bytes


@dataclass(frozen=True)
class PanelCmd(Cmd):
    """A load-panel action: "scale" (reload in millimetres), "repose" (re-mesh with the typed
    camera pose), "remesh" (re-mesh with the meshing boxes), "up" (re-mesh with the Up
    direction), "place" (reload the model with its position and ground plane), "area" (reload
    the scene with the planning area), "forget" (drop the pending calibration)."""

    action: Literal["scale", "repose", "remesh", "up", "place", "area", "forget"]


@dataclass(frozen=True)
class VoxelCmd(Cmd):
    """A Voxel study action: "run" (the study on the chosen region) or "csv" (download the
    last table)."""

    action: Literal["run", "csv"]


# -- stopping --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CancelCmd(Cmd):
    """Cancel (at the top, and Cancel choose): the running command, at once, and what is
    queued behind it."""


@dataclass(frozen=True)
class CancelLoadCmd(Cmd):
    """Cancel load: the scene being loaded."""


@dataclass(frozen=True)
class CancelBatchCmd(Cmd):
    """Cancel batch: the batch of trials."""
