"""Every command of the page, in one table: its handler, its name on the page and what a click on
it does while another command runs (app/_loop.py `Command`).

Adding a button: a command class (app/_commands.py), a callback that puts it (one line where the
button is made), its handler (`handler(app, cmd)`, app/_app.py `App`) and its entry here.
"""

from __future__ import annotations

from typing import Any

from ._app import App
from ._batch import do_cancel_batch, do_run_trials
from ._choose_panel import do_choose
from ._commands import (
    BestPathCmd,
    CancelBatchCmd,
    CancelCmd,
    CancelLoadCmd,
    ChooseCmd,
    Cmd,
    DriveCmd,
    EngineCmd,
    ExportCmd,
    LoadSceneCmd,
    MarkersCmd,
    PanelCmd,
    PlaceCmd,
    PlanCmd,
    ResetCmd,
    RobotGoCmd,
    RobotPlanCmd,
    RobotStopCmd,
    RunTrialsCmd,
    ShareCmd,
    ShowTrialCmd,
    UploadCmd,
    ViewCmd,
    VoxelCmd,
)
from ._load_panel import do_panel, do_upload
from ._loading import do_cancel_load, do_load_scene
from ._loop import Command
from ._markers import click_while_busy, do_check_markers, do_place
from ._plan_drive import (
    do_best_path,
    do_drive,
    do_engine,
    do_export,
    do_plan,
    do_reset,
    show_trial,
)
from ._replay import share_trial
from ._robot_panel import do_robot_go, do_robot_plan, do_robot_stop
from ._voxel_panel import do_voxel


def cancel_running(app: App, cmd: CancelCmd) -> None:
    """Cancel: the running command's child killed, what is queued behind it dropped."""
    app.loop.cancel()


def change_view(app: App, cmd: ViewCmd) -> None:
    """A toggle of the View or Plan and drive folder, or a camera's move."""
    app.page.change_view(cmd)


COMMANDS: dict[type[Cmd], Command[Any]] = {
    # Each waits its turn while another runs (a click made meanwhile is on the state as it is).
    PlanCmd: Command(handler=do_plan, name="Plan"),
    DriveCmd: Command(handler=do_drive, name="Drive"),
    ResetCmd: Command(handler=do_reset, name="Reset"),
    BestPathCmd: Command(handler=do_best_path, name="Best path"),
    ChooseCmd: Command(handler=do_choose, name="Choose path"),
    RunTrialsCmd: Command(handler=do_run_trials, name="Run trials"),
    ShowTrialCmd: Command(handler=show_trial, name="Show trial"),
    ShareCmd: Command(handler=share_trial, name="Share"),
    VoxelCmd: Command(handler=do_voxel, name="Voxel study"),
    RobotPlanCmd: Command(handler=do_robot_plan, name="Route from robot"),
    RobotGoCmd: Command(handler=do_robot_go, name="Go"),
    PlaceCmd: Command(handler=do_place, name="Click", while_busy=click_while_busy),
    # A drag sends many: one re-check after the running command, unannounced.
    MarkersCmd: Command(handler=do_check_markers, name="Marker check", while_busy="once"),
    # At once even while a command runs: they start or stop background work (a load, a batch,
    # the running command itself), or change only what is seen or downloaded.
    LoadSceneCmd: Command(handler=do_load_scene, name="Load scene", while_busy="run"),
    UploadCmd: Command(handler=do_upload, name="Load file", while_busy="run"),
    PanelCmd: Command(handler=do_panel, name="Load panel", while_busy="run"),
    ExportCmd: Command(handler=do_export, name="Export CSV", while_busy="run"),
    ViewCmd: Command(handler=change_view, name="View", while_busy="run"),
    EngineCmd: Command(handler=do_engine, name="Physics engine", while_busy="queue"),
    CancelCmd: Command(handler=cancel_running, name="Cancel", while_busy="run"),
    RobotStopCmd: Command(handler=do_robot_stop, name="Stop robot", while_busy="run"),
    CancelLoadCmd: Command(handler=do_cancel_load, name="Cancel load", while_busy="run"),
    CancelBatchCmd: Command(handler=do_cancel_batch, name="Cancel batch", while_busy="run"),
}
"""Command class -> how the loop runs it."""
