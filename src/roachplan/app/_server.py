"""The browser app's viser shell: the server, the page's controls, and what the page shows.

Threads: viser runs callbacks on its own thread pool; they only put a command (app/_commands.py)
on the command loop's queue (app/_loop.py). The loop's thread owns the state (app/_app.py `App`)
and runs each command by its handler (app/_registry.py); the heavy work runs outside the
server's process. A plan, drive or best path runs in a child that the loop follows (progress,
elapsed time, Cancel kills it at once); commands clicked meanwhile wait their turn and are shown
as queued. A scene load runs in the background (app/_loading.py): the current scene stays in
use, and the new world replaces it when ready, between commands. A batch of trials runs on a
worker pool fed by a thread of its own (app/_batch.py). The state is shared: every open browser
sees the same world and trials, and its own notifications.

`RoachApp` is the loop's `Shell` and the handlers' `Page`: the only place here that holds viser
handles (with the folders it builds: app/_load_panel.py, ...).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Literal

import numpy as np
import viser

from roachplan.experiments import LabelledPlan
from roachplan.planning import PLANNER_NAMES, standable_map
from roachplan.scenes import LIBRARY, World, list_scenes
from roachplan.sim import ENGINES, Frame

from ._app import App, PlanSettings
from ._batch import Batch, BatchPanel
from ._choose_panel import ChoosePanel
from ._commands import (
    BestPathCmd,
    CancelCmd,
    DriveCmd,
    EngineCmd,
    ExportCmd,
    LoadSceneCmd,
    MarkersCmd,
    PlaceCmd,
    PlanCmd,
    ResetCmd,
    ShareCmd,
    ShowTrialCmd,
    UploadCmd,
    ViewCmd,
)
from ._draw import (
    ROBOT_PIXELS,
    VIEW_DIRECTION,
    SceneView,
    framing,
    on_surface,
    robot_distance,
    terrain_box,
    wxyz_from_xyzw,
    yaw_wxyz,
)
from ._jobs import load_world, with_page_engine
from ._load_panel import LoadPanel
from ._loading import BackgroundLoad, follow_load
from ._loop import CommandLoop
from ._markers import StartGoal, pick_failure
from ._panel import energy_plot, summary_markdown, trials_markdown
from ._registry import COMMANDS
from ._relevel import CaptureView
from ._robot_panel import RobotPanel
from ._said import note_body
from ._uploads import MAX_UPLOAD_BYTES, limit_uploads, public_message
from ._voxel_panel import VoxelPanel

# The pickers' options before there are paths or trials (typed str, not the literal: the
# options change to path and trial numbers).
_NAMES_NONE: tuple[str, ...] = ("none",)
_NAMES_NO_TRIAL: tuple[str, ...] = ("-",)


class RoachApp:
    """Owns the viser server and the page's controls; shows the state of `core`, which the
    command loop (`loop`) changes."""

    def __init__(
        self,
        world: World,
        *,
        host: str,
        port: int,
        upload_dir: Path | None = None,
        max_upload_bytes: int = MAX_UPLOAD_BYTES,
        view: CaptureView | None = None,
        engine: str | None = None,
    ):
        """view: the capture view of world (load_world), to re-mesh and re-level it. engine:
        the physics engine of every drive, this world's and every one loaded (None: each
        scene's own sim.engine); the page's Physics engine picker changes it."""
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.loop = CommandLoop(COMMANDS, shell=self)
        self.core = App(
            with_page_engine(world, engine),
            page=self,
            loop=self.loop,
            upload_dir=Path(upload_dir or tempfile.mkdtemp(prefix="roachplan-uploads-")),
            engine=engine,
        )
        """The state and services the command handlers get."""
        self._standable = None
        """(StandableMap, the start's cell (i, j) it was made for) of this world, made when the
        overlay is first shown."""
        self._followed = 0.0
        """When the cameras last moved with the robot (time.monotonic() [s])."""
        self._follow_offsets: dict[int, np.ndarray] = {}
        """Client id -> its camera's offset from the robot while following [m], world frame."""
        self.max_upload_bytes = max_upload_bytes
        limit_uploads(self.server, max_upload_bytes, self._refuse_upload)
        path = Path(world.scene.path).resolve()
        if path != (LIBRARY / f"{world.scene.name}.yaml").resolve():
            self.core.files[f"file: {path.name}"] = (str(path), False)
        self.view = SceneView(self.server.scene)
        # Light the scene cheaply: in software WebGL (a browser without a GPU) viser's default
        # image-based lighting took ~10 s to prepare in a new page (the first Plan click waited
        # behind it: 11.6 s, then 1.0 s without it) and halved the frame rate of a drive, and
        # shadow maps cost two thirds of each frame (bench_app.py). A sky/ground hemisphere
        # light, z up, keeps the faces of the terrain apart instead.
        self.server.scene.configure_default_lights(cast_shadow=False)
        self.server.scene.configure_environment_map(hdri=None)
        self.server.scene.add_light_hemisphere(
            "/lights/sky", ground_color=(120, 110, 100), intensity=1.5, position=(0.0, 0.0, 1.0)
        )
        self._build_gui()
        self.core.show_world()
        self.load_panel.show_loaded(world, view)
        self.loop.start(self.core, setup=self.core.warm_up)

    @property
    def port(self) -> int:
        return self.server.get_port()

    # The state, as tests and benchmarks read it (the loop's thread changes it).

    @property
    def world(self) -> World:
        return self.core.world

    @property
    def scene_trials(self) -> list[dict]:
        return self.core.scene_trials

    @property
    def plans(self) -> list[LabelledPlan]:
        return self.core.plans

    @property
    def drive_path(self) -> int:
        return self.core.drive_path

    @property
    def upload_dir(self) -> Path:
        return self.core.upload_dir

    @property
    def commands(self):
        """The command loop's queue (put a command on it as a callback would)."""
        return self.loop.commands

    @property
    def running(self) -> str | None:
        """The name of the command whose job runs now."""
        return self.loop.running

    @property
    def batch(self) -> Batch | None:
        """The batch of trials running, if any."""
        return self.batch_panel.batch

    @property
    def controls(self) -> dict:
        """Marker name ("start", "goal") -> the marker's transform control."""
        return self.view.controls

    @property
    def balls(self) -> dict:
        return self.view.balls

    # gui ---------------------------------------------------------------------------------

    def _build_gui(self) -> None:  # noqa: PLR0915 - one widget per statement
        gui, put = self.server.gui, self.loop.put
        self.title = gui.add_markdown("")
        # What is running (with its progress and Cancel) stays in view at the top.
        self.status = gui.add_markdown("Drag the start (green) and goal (blue), then **Plan**.")
        # The whole of the last notification too long to show whole (notify), until the next
        # one, new work (a followed job) or a new world.
        self.message = gui.add_markdown("", visible=False)
        self.job_bar = gui.add_progress_bar(0.0, visible=False)
        self.cancel_job = gui.add_button(
            "Cancel",
            visible=False,
            color="red",
            hint="Stop the running command now, and drop what is queued behind it",
        )
        with gui.add_folder("Scene"):
            self.scene_picker = gui.add_dropdown(
                "Scene",
                (*list_scenes(), *self.core.files),
                initial_value=self.core.picker_label(),
            )
            self.upload = gui.add_upload_button(
                "Load file",
                hint=f"capture, .scad, mesh or scene .yaml (<= {MAX_UPLOAD_BYTES >> 20} MB)",
            )
            self.loading = BackgroundLoad(gui, put)
            self.load_panel = LoadPanel(gui, put)
        self.voxel_panel = VoxelPanel(gui, put)  # (the loaded capture's table 3.1)
        self.markers = StartGoal(gui, put, self.view)
        self.click_mode = self.markers.click_mode
        self.start_yaw, self.goal_yaw = self.markers.start_yaw, self.markers.goal_yaw
        with gui.add_folder("Plan and drive"):
            self.planner = gui.add_dropdown(
                "Planner", PLANNER_NAMES, initial_value=self.core.world.scene.planner.name
            )
            self.time_limit = gui.add_number(
                "Time budget [s]",
                20.0,
                min=0.1,
                max=3600.0,
                step=0.5,
                hint="For the whole Plan: every try at every path",
            )
            self.count = gui.add_number("Paths (K)", 1, min=1, max=20, step=1)
            self.engine: viser.GuiDropdownHandle[str] = gui.add_dropdown(
                "Physics engine",
                ENGINES,
                initial_value=self.core.world.scene.sim.engine,
                hint="Who simulates every drive, batch and Choose: pybullet (the reference) "
                "or mujoco (faster), each at the timestep it was calibrated at",
            )
            self.show_roadmap = gui.add_checkbox("Show roadmap", False)
            self.drive_path_picker: viser.GuiDropdownHandle[str] = gui.add_dropdown(
                "Drive path",
                _NAMES_NONE,
                hint="The path Drive takes (the thick one, labelled Drive)",
            )
            self.plan_button = gui.add_button("Plan")
            self.drive_button = gui.add_button("Drive", disabled=True)
            self.reset_button = gui.add_button("Reset")
            self.best_button = gui.add_button("Best path")
            self.speed = gui.add_slider("Playback speed [x real time]", 1, 10, 1, 1)
        with gui.add_folder("View"):
            self.follow = gui.add_checkbox(
                "Follow robot", False, hint="Every browser's camera follows the robot"
            )
            self.zoom_button = gui.add_button("Zoom to robot")
            self.show_paths = gui.add_checkbox("Show paths", True)
            self.show_trajectories = gui.add_checkbox("Show trajectories", True)
            self.show_standable = gui.add_checkbox(
                "Show where it can stand",
                False,
                hint="Green: the region the start is in; yellow: other places it can stand",
            )
        self.choose_panel = ChoosePanel(gui, put)
        self.batch_panel = BatchPanel(gui, put)
        self.robot_panel = RobotPanel(gui, put)
        with gui.add_folder("Results"):
            self.show_trial: viser.GuiDropdownHandle[str] = gui.add_dropdown(
                "Show trial", _NAMES_NO_TRIAL
            )
            self.export_button = gui.add_button("Export CSV")
            self.share_button = gui.add_button("Share")  # the shown trial as an offline page
            self.table = gui.add_markdown(trials_markdown([]))
            self.summary = gui.add_markdown("")
            self.plot = gui.add_image(energy_plot([]), label="Energy per trial")

        self.scene_picker.on_update(
            lambda ev: put(LoadSceneCmd(ev.client_id, self.scene_picker.value))
        )
        self.upload.on_upload(
            lambda ev: put(UploadCmd(ev.client_id, ev.target.value.name, ev.target.value.content))
        )
        self.click_mode.on_update(lambda ev: self._set_click_mode())
        self.load_panel.pick_ground.on_update(lambda ev: self._set_click_mode())
        self.voxel_panel.pick_centre.on_update(lambda ev: self._set_click_mode())
        self.engine.on_update(lambda ev: put(EngineCmd(ev.client_id, self.engine.value)))
        self.plan_button.on_click(lambda ev: put(PlanCmd(ev.client_id)))
        self.drive_button.on_click(lambda ev: put(DriveCmd(ev.client_id)))
        self.reset_button.on_click(lambda ev: put(ResetCmd(ev.client_id)))
        self.best_button.on_click(lambda ev: put(BestPathCmd(ev.client_id)))
        self.cancel_job.on_click(lambda ev: put(CancelCmd(ev.client_id)))
        self.show_trial.on_update(lambda ev: put(ShowTrialCmd(ev.client_id)))
        self.export_button.on_click(lambda ev: put(ExportCmd(ev.client_id)))
        self.share_button.on_click(lambda ev: put(ShareCmd(ev.client_id)))
        self.show_roadmap.on_update(lambda ev: put(ViewCmd(ev.client_id, "roadmap")))
        self.drive_path_picker.on_update(lambda ev: put(ViewCmd(ev.client_id, "drive_path")))
        self.follow.on_update(lambda ev: put(ViewCmd(ev.client_id, "follow")))
        self.zoom_button.on_click(lambda ev: put(ViewCmd(ev.client_id, "zoom")))
        self.show_standable.on_update(lambda ev: put(ViewCmd(ev.client_id, "standable")))
        self.show_paths.on_update(lambda ev: put(ViewCmd(ev.client_id, "paths")))
        self.show_trajectories.on_update(lambda ev: put(ViewCmd(ev.client_id, "trajectories")))

    def _set_click_mode(self) -> None:
        """Listen for clicks on the scene only while something is to be placed (a listening
        scene does not orbit on click)."""
        scene = self.server.scene
        scene.remove_click_callback()
        if self.click_target() != "nothing":
            scene.on_click()(
                lambda ev: self.loop.put(PlaceCmd(ev.client_id, ev.ray_origin, ev.ray_direction))
            )

    def _refuse_upload(self, client_id, name: str, size: int) -> None:
        self.notify(
            client_id,
            "File too large",
            f"{name}: {size / 1e6:.3f} MB; the limit is {self.max_upload_bytes / 1e6:.3f} MB",
            error=True,
        )

    # the loop's Shell ------------------------------------------------------------------------

    def set_status(self, text: str) -> None:
        if self.status.content != text:
            self.status.content = text

    def notify(self, client_id: int | None, title: str, body: str, *, error: bool = False) -> None:
        client = self.server.get_clients().get(client_id) if client_id is not None else None
        if client is None:
            return
        body = self.public(body)  # (the page's words, no server paths)
        # viser cuts a notification at 200 px, and its first lines go with the title: a longer
        # one shows its lead and points to the whole of it, under the status line.
        shown, cut = note_body(title, body)
        if cut:
            whole = body.replace("_", "\\_").replace("*", "\\*")  # (markdown: as written)
            self.message.content = f"**{title}**: {whole}"
            self.message.visible = True
        client.add_notification(
            title,
            shown,
            auto_close_seconds=None if error or cut else 4.0,
            color="red" if error else None,
        )

    def public(self, text: str) -> str:
        return public_message(text, self.core.upload_dir)

    def show_job(self, running: bool) -> None:
        self.cancel_job.visible = running
        if running:
            self.clear_message()  # (new work: the last one's message is done with)
            self.job_bar.value, self.job_bar.visible = 0.0, True
        else:
            self.job_bar.visible = False

    def set_job_progress(self, percent: float) -> None:
        if self.job_bar.value != percent:
            self.job_bar.value = percent

    def between(self, *, idle: bool) -> None:
        self.batch_panel.drain(lambda trial: self.core.record(trial, "batch"))
        follow_load(self.core, idle=idle)

    def command_done(self) -> None:
        self.drive_button.disabled = not self.core.plans

    def clear_message(self) -> None:
        """The whole of the last cut notification (notify) goes: new work started, or a new
        world is shown."""
        if self.message.visible:
            self.message.visible = False
            self.message.content = ""

    # the handlers' Page: what the controls say -------------------------------------------------

    def send_file(self, client_id: int | None, name: str, data: bytes) -> None:
        client = self.server.get_clients().get(client_id) if client_id is not None else None
        if client is not None:
            client.send_file_download(name, data, save_immediately=True)

    def plan_settings(self) -> PlanSettings:
        return PlanSettings(
            planner=self.planner.value,
            time_limit=float(self.time_limit.value),
            count=int(self.count.value),
        )

    def playback_speed(self) -> float:
        return float(self.speed.value)

    def shown_trial(self) -> int | None:
        return None if self.show_trial.value == "-" else int(self.show_trial.value)

    def click_target(self) -> Literal["nothing", "start", "goal", "ground", "square"]:
        if self.voxel_panel.pick_centre.value:
            return "square"
        if self.load_panel.pick_ground.value:
            return "ground"
        return self.click_mode.value

    def show_engine(self, engine: str) -> None:
        if self.engine.value != engine:
            self.engine.value = engine  # (its callback's EngineCmd finds nothing to change)

    def set_scene_picker(self, label: str, labels: tuple[str, ...] | None = None) -> None:
        if labels is not None:
            self.scene_picker.options = labels
        self.scene_picker.value = label

    # the handlers' Page: the world in the scene -----------------------------------------------

    def show_world(self) -> None:
        world = self.core.world
        self.clear_message()
        self.view.show(
            world,
            lambda ev: self.loop.put(
                MarkersCmd(ev.client_id, settled=getattr(ev, "phase", "end") == "end")
            ),
        )
        failure = pick_failure(world)
        self.markers.reset(world, None if failure is None else self.public(failure))
        self._standable = None
        self.choose_panel.clear()
        self.voxel_panel.clear()
        self.check_markers()
        self.show_robot_at_start()
        if self.show_standable.value:
            self._show_standable()
        self._frame_world()
        scene = world.scene
        self.title.content = f"**roachplan** — scene `{scene.name}`  \n{scene.description}"

    def _frame_world(self) -> None:
        """Every view - the first view of a browser opened later, and every open browser's -
        frames the terrain the robot plans on (terrain_box) with start and goal: after a load
        or a re-mesh the old camera may be inside the new terrain or looking past it."""
        world = self.core.world
        points = [
            *terrain_box(world),
            *(on_surface(world, p) for p in (world.scene.start, world.scene.goal)),
        ]
        position, look_at = framing(points, self.server.initial_camera.fov)
        self.server.initial_camera.position = tuple(position)
        self.server.initial_camera.look_at = tuple(look_at)
        for client in self.server.get_clients().values():
            cam = client.camera
            aspect = cam.image_width / cam.image_height if cam.image_height else 1.0
            position, look_at = framing(
                points, cam.fov or self.server.initial_camera.fov, aspect=aspect
            )
            with client.atomic():
                # Position first: viser moves the look-at along with a new position.
                cam.position, cam.look_at = position, look_at

    def check_markers(self) -> bool:
        valid = self.markers.check(self.core.world)
        if self.show_standable.value and self._standable is not None:
            self._show_standable()  # (the start's region, when the start left it)
        return valid

    def place_marker(self, which: Literal["start", "goal"], p_world: tuple) -> None:
        self.view.controls[which].position = p_world

    def show_robot_at_start(self) -> None:
        start = self.markers.pose("start")
        x, y, z = on_surface(self.core.world, start)
        r = self.core.world.robot
        q0, _ = r.leg_angle(r.leg_phase_offsets)
        self.view.show_robot(self.server, (x, y, z + r.standing_height), yaw_wxyz(start[2]), q0)

    def show_frame(self, frame: Frame) -> None:
        self.show_robot_pose(
            frame.p_world_body, wxyz_from_xyzw(frame.quat_world_body), frame.leg_angles
        )

    def show_robot_pose(self, position, wxyz, leg_angles) -> None:
        self.view.show_robot(self.server, position, wxyz, leg_angles)
        now = time.monotonic()
        if self.follow.value and now - self._followed > 1 / 20:  # (20 camera moves a second)
            self._followed = now
            for client in self.server.get_clients().values():
                self._aim(client, position, zoom=False)

    def list_plans(self, count: int) -> None:
        # Drive only while there is a path to drive (a new world, a new plan clear them).
        self.drive_button.disabled = count == 0
        names = tuple(str(k + 1) for k in range(count)) or ("none",)
        self.drive_path_picker.options = names
        self.drive_path_picker.value = names[0]

    def show_plans(self, plans: list[LabelledPlan], selected: int, *, drawn: bool = False) -> None:
        if not plans:
            self.view.hide_paths()
            return
        if drawn and len(self.view.path_nodes) == len(plans):
            self.view.mark_path(selected)
        else:
            self.view.show_paths([lp.plan.path_xyz for lp in plans], selected)
        self._show_roadmap()

    def mark_drive_path(self, k: int) -> None:
        self.view.mark_path(k)
        if self.drive_path_picker.value != str(k + 1):  # (the picker calls back: a no-op)
            self.drive_path_picker.value = str(k + 1)

    def show_results(self, trials: list[dict]) -> None:
        self.table.content = trials_markdown(trials)
        self.summary.content = summary_markdown(trials)
        self.plot.image = energy_plot(trials)
        self.show_trial.options = ("-", *(str(k + 1) for k in range(len(trials))))

    # the handlers' Page: the view ------------------------------------------------------------

    def change_view(self, cmd: ViewCmd) -> None:
        match cmd.what:
            case "roadmap":
                self._show_roadmap()
            case "drive_path":
                if self.drive_path_picker.value != "none":
                    self.core.select_path(int(self.drive_path_picker.value) - 1)
            case "paths":
                self.view.set_shown("/plans", self.show_paths.value)
            case "trajectories":
                self.view.set_shown("/trajectories", self.show_trajectories.value)
            case "standable":
                if self.show_standable.value:
                    self._show_standable()
                if self.view.standable_node is not None:
                    self.view.standable_node.visible = bool(self.show_standable.value)
            case "follow" | "zoom":
                if cmd.what == "zoom" or self.follow.value:
                    self._aim_at_robot(cmd)

    def _aim_at_robot(self, cmd: ViewCmd) -> None:
        """Follow (every client's camera) or Zoom (the camera of the client that clicked): turn
        to the robot."""
        clients = self.server.get_clients()
        if cmd.what == "follow":
            chosen = list(clients.values())
        else:
            chosen = [clients[cmd.client_id]] if cmd.client_id in clients else []
        for client in chosen:
            robot = self.view.robot_node
            assert robot is not None  # (drawn with the world, before the page is served)
            self._aim(client, robot.position, zoom=True)

    def _aim(self, client, p_world_robot, *, zoom: bool) -> None:
        """Turn client's camera to the robot at p_world_robot [m]. zoom: from the camera's
        direction (at least 20 degrees above the ground), where the robot's body spans
        ROBOT_PIXELS of the view's height; that offset is then kept while following. (A
        camera's reported position can lag behind its look-at by one update; following by
        what it reports would drift to the ground.)"""
        cam, target = client.camera, np.asarray(p_world_robot, dtype=float)
        offset = self._follow_offsets.get(client.client_id)
        if zoom or offset is None:
            fov = cam.fov or self.server.initial_camera.fov
            near = robot_distance(
                self.core.world.robot.body_length, fov, cam.image_height or 900, ROBOT_PIXELS
            )
            offset = np.asarray(cam.position) - np.asarray(cam.look_at)
            d = float(np.linalg.norm(offset))
            offset = offset / d if d > 1e-6 and offset[2] > 0.34 * d else VIEW_DIRECTION
            offset = near * offset
            self._follow_offsets[client.client_id] = offset
        with client.atomic():
            # Position first: viser moves the look-at along with a new position.
            cam.position, cam.look_at = target + offset, target

    def _show_roadmap(self) -> None:
        roadmap = self.core.roadmap
        if self.show_roadmap.value and roadmap is not None and self.view.path_nodes:
            self.view.draw_roadmap(self.core.world, roadmap)
        else:
            self.view.remove("/plans/roadmap")

    def _show_standable(self) -> None:
        """The standability overlay, computed once per world (the planner's own standable map:
        4 cm cells, 8 headings), again only when the start leaves the region drawn."""
        (x, y, _), done = self.markers.pose("start"), self._standable
        if done is not None and self.view.standable_node is not None:
            sm, cell = done
            i, j = round((x - sm.x0) / sm.cell), round((y - sm.y0) / sm.cell)
            inside = 0 <= j < sm.reachable.shape[0] and 0 <= i < sm.reachable.shape[1]
            if (i, j) == cell or (inside and sm.reachable[j, i]):
                return
        w = self.core.world
        sm = standable_map(w.heightfield, w.footprint, w.scene.planner.validity, w.bounds, (x, y))
        self._standable = (sm, (round((x - sm.x0) / sm.cell), round((y - sm.y0) / sm.cell)))
        self.view.show_standable(w, sm)

    def stop(self) -> None:
        self.batch_panel.cancel()
        self.loading.stop()
        self.loop.stop()
        self.core.close()
        self.server.stop()


def serve(*, scene: str, host: str, port: int, engine: str | None = None) -> None:
    """Build the world (a library scene, a scene file or any terrain file) and serve the app
    until interrupted. engine: the physics engine of every drive (None: each scene's)."""
    import sys

    from roachplan.processes import call

    # In a child, as the page's loads are (its memory limit, a soft one: the OpenSCAD it may
    # start sets its own); its renders' progress reaches the command line's bars.
    world, view = call(
        load_world,
        (scene,),
        {"from_upload": False, "check_poses": True},
        hard_memory=False,
        task="loading",
    )
    for note in world.notes:
        print(f"roachplan: {note}", file=sys.stderr)
    app = RoachApp(world, host=host, port=port, view=view, engine=engine)
    print(f"roachplan: serving scene {world.scene.name!r} at http://{host}:{app.port}", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        app.stop()


__all__ = ["RoachApp", "serve"]
