"""The app as a command's handler sees it (app/_registry.py lists the handlers).

`App` holds the state the command loop owns - the world and the process it is hosted in, the
seeds, the plans, the trials, the scene files loaded - and the services a handler uses: `page`
(what the page says, what its controls are set to, what it draws), `loop` (follow a job in a
child process, its progress, Cancel) and jobs on the world (`world_job`). Nothing here imports
viser: the viser shell (app/_server.py RoachApp) is the app's `Page`, and a unit test's fake is
another (tests/test_loop.py).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol

from roachplan.planning import PlanningError

from ._jobs import Job, WorldHost, _warm_job, run_to_end
from ._uploads import load_announcement

if TYPE_CHECKING:
    from roachplan.experiments import LabelledPlan
    from roachplan.planning import PlannerConfig
    from roachplan.scenes import World
    from roachplan.sim import Frame

    from ._batch import BatchPanel
    from ._choose_panel import ChoosePanel
    from ._commands import Cmd, ViewCmd
    from ._draw import SceneView
    from ._load_panel import LoadPanel
    from ._loading import BackgroundLoad
    from ._loop import CommandLoop
    from ._markers import StartGoal
    from ._robot_panel import RobotPanel, RobotSession
    from ._voxel_panel import VoxelPanel


@dataclass(frozen=True, kw_only=True)
class PlanSettings:
    """The Plan and drive folder's planner settings."""

    planner: str
    """The planner's name (planning.PLANNER_NAMES)."""
    time_limit: float
    """One budget for the whole Plan, every try at every path [s]."""
    count: int
    """Distinct paths wanted (K)."""


class Page(Protocol):
    """The page as a handler sees it: the viser shell (app/_server.py RoachApp), or a unit
    test's fake. The world it shows is its app's (App.world)."""

    view: SceneView
    """The scene's nodes: terrain, robot, markers, paths, trajectories."""
    markers: StartGoal
    """The Start and goal folder (the markers' poses, and whether they are valid)."""
    loading: BackgroundLoad
    """The scene load running in the background, in the Scene folder."""
    load_panel: LoadPanel
    voxel_panel: VoxelPanel
    choose_panel: ChoosePanel
    batch_panel: BatchPanel
    robot_panel: RobotPanel

    def set_status(self, text: str) -> None:
        """The status line at the top of the panel."""
        ...

    def notify(self, client_id: int | None, title: str, body: str, *, error: bool = False) -> None:
        """A notification to one browser (none for None), in the page's words."""
        ...

    def send_file(self, client_id: int | None, name: str, data: bytes) -> None:
        """A download to one browser (none for None)."""
        ...

    def plan_settings(self) -> PlanSettings: ...

    def playback_speed(self) -> float:
        """Drive playback [x real time]."""
        ...

    def shown_trial(self) -> int | None:
        """The Show trial picker's trial (1 for the first), None when it shows none."""
        ...

    def click_target(self) -> Literal["nothing", "start", "goal", "ground", "square"]:
        """What the next click on the terrain sets: a marker (Click places), the capture's
        ground (Pick ground) or the voxel study's square (Pick square centre)."""
        ...

    def set_scene_picker(self, label: str, labels: tuple[str, ...] | None = None) -> None:
        """The scene picker shows label (labels: its choices, when they changed)."""
        ...

    def show_engine(self, engine: str) -> None:
        """The Physics engine picker shows engine (the world's)."""
        ...

    def show_world(self) -> None:
        """Draw the app's world afresh (a new world): terrain, markers at its start and goal,
        the folders that held something of the last world cleared, every view framing it."""
        ...

    def check_markers(self) -> bool:
        """Colour the markers by whether they are valid (and say why not); whether both are."""
        ...

    def place_marker(self, which: Literal["start", "goal"], p_world: tuple) -> None:
        """Move a marker to a world point [m]."""
        ...

    def show_robot_at_start(self) -> None: ...

    def show_frame(self, frame: Frame) -> None:
        """The robot as in a simulation frame (cameras following it, when ticked)."""
        ...

    def show_robot_pose(self, position, wxyz, leg_angles) -> None:
        """The robot at a pose (world frame [m], wxyz) with its legs at angles [rad] (a real
        robot's live pose; cameras following it, when ticked)."""
        ...

    def list_plans(self, count: int) -> None:
        """The Drive path picker offers paths 1 to count, the first chosen."""
        ...

    def show_plans(self, plans: list[LabelledPlan], selected: int, *, drawn: bool = False) -> None:
        """Draw the paths, plans[selected] marked for Drive, and the first's roadmap when it is
        ticked; none: nothing drawn. drawn: the view shows these paths already, in this order
        (Plan draws each as it is found): only the mark is added."""
        ...

    def mark_drive_path(self, k: int) -> None:
        """Path k (index) drawn thick and labelled Drive, and chosen in the Drive path picker."""
        ...

    def show_results(self, trials: list[dict]) -> None:
        """The Results folder: table, summary, plot, the Show trial picker's choices."""
        ...

    def change_view(self, cmd: ViewCmd) -> None:
        """Apply a View command (ViewCmd): toggles, the Drive path picker, the cameras."""
        ...


class App:
    """The app's state and services, handed to every command's handler. Owned by the loop
    thread: only handlers (and what the loop runs between commands) touch it."""

    def __init__(
        self,
        world: World,
        *,
        page: Page,
        loop: CommandLoop,
        upload_dir: Path,
        engine: str | None = None,
    ) -> None:
        self.world = world
        """The world shown, planned and driven on."""
        self.engine = engine
        """The physics engine of every drive and choice ("pybullet", "mujoco"; None: each
        scene's own sim.engine): `serve --engine`, the Physics engine picker."""
        self.page = page
        self.loop = loop
        self.upload_dir = upload_dir
        """Where uploads and the app's scene files are written."""
        self.trials: dict[str, list[dict]] = {}
        """Trial records (TrialResult.to_json() + "label") per scene file."""
        self.next_seed = world.scene.seed
        """The seed of the next Plan, batch or Choose path."""
        self.next_seeds: dict[str, int] = {}
        """Scene file -> the next seed of the scenes switched away from (app/_loading.py)."""
        self.plans: list[LabelledPlan] = []
        """The paths drawn, which Drive can take."""
        self.plan_endpoints: tuple[tuple, tuple] | None = None
        """The (start, goal) the plans were made for."""
        self.drive_path = 0
        """Index in plans of the path Drive takes (select_path)."""
        self.files: dict[str, tuple[str, bool]] = {}
        """Scene picker label -> (scene file, written by the app) of each scene loaded from a
        file: uploads, re-meshed copies, `serve --scene FILE`."""
        self.robot: RobotSession | None = None
        """The real robot connected in the Robot folder, its plan and loop."""
        self._host: WorldHost | None = None

    @property
    def scene_trials(self) -> list[dict]:
        """The current scene's trial records."""
        return self.trials.setdefault(str(self.world.scene.path), [])

    @property
    def roadmap(self):
        """The first plan's roadmap ((E, 2, 2) xy segments [m]) or None, kept for Show
        roadmap."""
        return self.plans[0].plan.roadmap if self.plans else None

    # -- jobs on the world -----------------------------------------------------------------------

    @property
    def host(self) -> WorldHost | None:
        """The process plans and drives on the world are forked from, when it is up."""
        return self._host

    def warm_up(self) -> None:
        """Start the fork server (~1 s, its modules preloaded) and host the world: on the loop
        thread before the first command, not on the first click."""
        run_to_end(_warm_job)
        self.host_world()

    def host_world(self) -> None:
        """Hand the current world to a new WorldHost (the old one ends): once per world, on
        the loop thread, so that no click waits for it."""
        if self._host is not None:
            self._host.close()
        self._host = None
        try:
            self._host = WorldHost(self.world)
        except OSError:  # (no process to be had now: jobs go to plain children, world_job)
            pass

    def world_job(self, target, *args) -> Job:
        """target(conn, self.world, *args) in a fresh child: a fork of the world's host, or,
        while it is not up (or has died), a child that is sent the world."""
        host = self._host
        if host is not None and host.world is self.world and host.alive:
            try:
                return Job(target, *args, host=host)
            except (OSError, EOFError):  # the host died: a plain child this time
                pass
        job = Job(target, self.world, *args)
        self.host_world()  # (a new host for the next click, while this job starts)
        return job

    def close(self) -> None:
        """Stop a robot still held or driven, and end the world's host."""
        if self.robot is not None:
            self.robot.close()
            self.robot = None
        if self._host is not None:
            self._host.close()

    def start_load(
        self, cmd: Cmd, ref: str, *, from_upload: bool, label: str, what: str | None = None
    ) -> None:
        """Start loading a scene in the background (replacing a load still running); it
        replaces the world when ready and nothing runs (app/_loading.py)."""
        # Said by what the scene holds, not by the file's suffix: a .zip may hold a capture.
        what = what or load_announcement(label, ref)
        replaced = self.page.loading.start(
            cmd, ref, from_upload=from_upload, label=label, what=what
        )
        if replaced is not None:
            self.page.notify(
                replaced.client_id,
                f"Stopped loading {replaced.label}",
                f"{label} is loaded instead.",
            )
        if self.loop.running is None:
            self.page.set_status(
                f"`{self.world.scene.name}` stays in use while {label} loads (Scene folder)."
            )

    # -- the world's plans and trials -----------------------------------------------------------

    def show_world(self) -> None:
        """The world on the page afresh (a new world): no plans, its trials; a robot held or
        driven on the last world stopped."""
        if self.robot is not None:
            self.robot.close()
            self.robot = None
        self.plan_endpoints = None
        self.page.show_world()
        self.set_plans([])
        self.page.show_results(self.scene_trials)

    def picker_label(self) -> str:
        """The scene picker's label of the current world."""
        path = str(Path(self.world.scene.path).resolve())
        return next(
            (k for k, (v, _) in self.files.items() if str(Path(v).resolve()) == path),
            self.world.scene.name,
        )

    def planner(self, settings: PlanSettings) -> PlannerConfig:
        """The scene's planner with the page's settings."""
        return dataclasses.replace(
            self.world.scene.planner,
            name=settings.planner,
            time_limit=float(settings.time_limit),
            keep_roadmap=True,
        )  # (Show roadmap shows it at once)

    def set_plans(self, plans: list[LabelledPlan], *, drawn: bool = False) -> None:
        """The paths Drive can take (none: nothing drawn), drawn with the first marked for
        Drive. drawn: the page shows these paths already, in this order (Page.show_plans)."""
        self.plans, self.drive_path = list(plans), 0
        try:
            self.page.list_plans(len(self.plans))
            self.page.show_plans(self.plans, 0, drawn=drawn)
        except BaseException:
            self.plans = []  # (what failed to be shown is not left for Drive to take)
            raise

    def select_path(self, k: int) -> None:
        """Make path k (an index into plans, 0 to K - 1; the page labels it k + 1) the one
        Drive takes."""
        if not 0 <= k < len(self.plans):
            raise PlanningError(
                f"path {k + 1}: there are {len(self.plans)} planned path(s); "
                f"choose 1 to {len(self.plans)} (Plan first if there are none)"
            )
        self.drive_path = k
        self.page.mark_drive_path(k)

    def record(self, trial: dict, label: str) -> bool:
        """Keep a trial's record (TrialResult.to_json()) with label ("" for Drive, "batch",
        ...); the Results folder and the status line show it. A success without a drive
        (unrecordable) is not kept, and the status line says why; whether it was kept."""
        why = unrecordable(trial)
        if why is not None:
            self.page.set_status(f"No trial recorded: {why}.")
            return False
        trial = {**trial, "label": label}
        self.scene_trials.append(trial)
        self.page.show_results(self.scene_trials)
        k = len(self.scene_trials)
        self.page.set_status(
            f"Trial {k}: **{trial['outcome']}** ({trial['reason']}), {trial['drive_time']:.1f} "
            f"s, {trial['energy']:.3f} J ({trial['relative_energy']:.2f} x a straight walk on "
            f"the floor)."
        )
        return True


def unrecordable(trial: dict) -> str | None:
    """Why a trial's record (TrialResult.to_json()) is not one to keep, or None: a "success"
    with no path to drive (fewer than two waypoints: start and goal one point) or no drive
    (0 s simulated) is no run at all, and a results table that counted it would count a
    success that never happened. A failure without a path ("no_path") is a real
    outcome of planning, and is kept."""
    if trial.get("outcome") != "success":
        return None
    if len(trial.get("path") or ()) < 2:
        return "there is no path to drive (start and goal are one point)"
    if not float(trial.get("drive_time") or 0.0) > 0.0:
        return "nothing was driven (0 s simulated)"
    return None
