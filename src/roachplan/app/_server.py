"""The browser app: the world, the roach and its start and goal markers, and every service of
the report's performance evaluator (plan, drive, reset, best path, batches of trials).

Threads: viser runs callbacks on its own thread pool; they only put a command (app/_jobs.py) on
a queue. One loop thread owns the state and drains the queue; the heavy work runs outside the
server's process. A plan, drive or best path runs in a child that the loop follows (progress,
elapsed time, Cancel kills it at once); commands clicked meanwhile wait their turn and are shown
as queued. A scene load runs in the background (app/_loading.py): the current scene stays in
use, and the new world replaces it when ready, between commands. A batch of trials runs on a
worker pool fed by a thread of its own (app/_batch.py). The state is shared: every open browser
sees the same world and trials, and its own notifications.
"""

from __future__ import annotations

import dataclasses
import queue
import tempfile
import threading
import time
from collections import deque
from pathlib import Path

import numpy as np
import viser

from roachplan.experiments import ExperimentSpec
from roachplan.planning import PLANNER_NAMES, PlanningError, standable_map
from roachplan.scenes import LIBRARY, World, list_scenes
from roachplan.sim import Frame

from ._batch import Batch, BatchPanel
from ._choose_panel import ChooseCmd, ChoosePanel, do_choose
from ._commands import do_best_path, do_drive, do_plan, record, show_trial
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
from ._jobs import (
    NAMES,
    BestPathCmd,
    CancelCmd,
    Cmd,
    DriveCmd,
    ExportCmd,
    Job,
    LoadSceneCmd,
    MarkersCmd,
    PlaceCmd,
    PlanCmd,
    ResetCmd,
    RunTrialsCmd,
    ShowTrialCmd,
    UploadCmd,
    ViewCmd,
    WorldHost,
    _warm_job,
    load_world,
    run_to_end,
)
from ._load_panel import LoadPanel, PanelCmd
from ._loading import BackgroundLoad, report_failure, swap_in
from ._markers import StartGoal, pick_failure
from ._panel import energy_plot, summary_markdown, trials_csv, trials_markdown
from ._picking import ray_hit_heightfield
from ._relevel import CaptureView
from ._replay import ShareCmd, share_trial
from ._uploads import MAX_UPLOAD_BYTES, limit_uploads, load_announcement, public_message
from ._voxel_panel import VoxelCmd, VoxelPanel

AT_ONCE = (LoadSceneCmd, UploadCmd, PanelCmd, ExportCmd, CancelCmd, ViewCmd)
"""Commands handled even while a plan or drive runs: they start or stop background work."""


class RoachApp:
    """Owns the viser server and the state shown in it."""

    def __init__(
        self,
        world: World,
        *,
        host: str,
        port: int,
        upload_dir: Path | None = None,
        max_upload_bytes: int = MAX_UPLOAD_BYTES,
        view: CaptureView | None = None,
    ):
        """view: the capture view of world (load_world), to re-mesh and re-level it."""
        self.world = world
        self._host: WorldHost | None = None
        """The process plans and drives on this world are forked from (host_world)."""
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.commands: queue.Queue[Cmd] = queue.Queue()
        self.waiting: deque[Cmd] = deque()
        """Commands clicked while another ran, in order."""
        self.running: str | None = None
        """The name of the plan, drive or best path running now."""
        self._cancel = False
        self.trials: dict[str, list[dict]] = {}
        """Trial records (TrialResult.to_json() + "label") per scene file."""
        self.plans: list = []
        self.plan_endpoints: tuple[tuple, tuple] | None = None
        self.drive_path = 0
        """Index in plans of the path Drive takes (select_path)."""
        self.roadmap: np.ndarray | None = None
        """The first plan's roadmap ((E, 2, 2) xy segments [m]), kept for Show roadmap."""
        self._standable = None
        """(StandableMap, the start's cell (i, j) it was made for) of this world, made when the
        overlay is first shown."""
        self._followed = 0.0
        self._follow_offsets: dict[int, np.ndarray] = {}
        """Client id -> its camera's offset from the robot while following [m], world frame."""
        """When the cameras last moved with the robot (time.monotonic() [s])."""
        self.files: dict[str, tuple[str, bool]] = {}
        """Scene picker label -> (scene file, written by the app) of each scene loaded from a
        file: uploads, re-meshed copies, `serve --scene FILE`."""
        self.upload_dir = Path(upload_dir or tempfile.mkdtemp(prefix="roachplan-uploads-"))
        self._next_seed = world.scene.seed
        self.next_seeds: dict[str, int] = {}
        """Scene file -> the next seed of the scenes switched away from (app/_loading.py)."""
        self.max_upload_bytes = max_upload_bytes
        limit_uploads(self.server, max_upload_bytes, self._refuse_upload)
        path = Path(world.scene.path).resolve()
        if path != (LIBRARY / f"{world.scene.name}.yaml").resolve():
            self.files[f"file: {path.name}"] = (str(path), False)
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
        self._show_world()
        self.load_panel.show_loaded(world, view)
        self._stop = threading.Event()
        self._loop = threading.Thread(target=self._run, name="roachplan-loop", daemon=True)
        self._loop.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def scene_trials(self) -> list[dict]:
        return self.trials.setdefault(str(self.world.scene.path), [])

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
        gui, put = self.server.gui, self.commands.put
        self.title = gui.add_markdown("")
        # What is running (with its progress and Cancel) stays in view at the top.
        self.status = gui.add_markdown("Drag the start (green) and goal (blue), then **Plan**.")
        self.job_bar = gui.add_progress_bar(0.0, visible=False)
        self.cancel_job = gui.add_button(
            "Cancel",
            visible=False,
            color="red",
            hint="Stop the running command now, and drop what is queued behind it",
        )
        with gui.add_folder("Scene"):
            self.scene_picker = gui.add_dropdown(
                "Scene", (*list_scenes(), *self.files), initial_value=self._picker_label()
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
                "Planner", PLANNER_NAMES, initial_value=self.world.scene.planner.name
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
            self.show_roadmap = gui.add_checkbox("Show roadmap", False)
            self.drive_path_picker = gui.add_dropdown(
                "Drive path", ("none",), hint="The path Drive takes (the thick one, labelled Drive)"
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
        with gui.add_folder("Results"):
            self.show_trial = gui.add_dropdown("Show trial", ("-",))
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
        self.plan_button.on_click(lambda ev: put(PlanCmd(ev.client_id)))
        self.drive_button.on_click(lambda ev: put(DriveCmd(ev.client_id)))
        self.reset_button.on_click(lambda ev: put(ResetCmd(ev.client_id)))
        self.best_button.on_click(lambda ev: put(BestPathCmd(ev.client_id)))
        self.cancel_job.on_click(lambda ev: put(CancelCmd(ev.client_id, "job")))
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
        """Listen for clicks on the scene only while a marker is to be placed (a listening
        scene does not orbit on click)."""
        scene = self.server.scene
        scene.remove_click_callback()
        if (
            self.click_mode.value != "nothing"
            or self.load_panel.pick_ground.value
            or self.voxel_panel.pick_centre.value
        ):
            scene.on_click()(
                lambda ev: self.commands.put(
                    PlaceCmd(ev.client_id, ev.ray_origin, ev.ray_direction)
                )
            )

    def _notify(self, client_id: int | None, title: str, body: str, *, error: bool = False):
        client = self.server.get_clients().get(client_id) if client_id is not None else None
        if client is not None:
            body = public_message(body, self.upload_dir)  # (the page's words, no server paths)
            client.add_notification(
                title,
                body,
                auto_close_seconds=None if error else 4.0,
                color="red" if error else None,
            )

    def _refuse_upload(self, client_id, name: str, size: int) -> None:
        self._notify(
            client_id,
            "File too large",
            f"{name}: {size / 1e6:.3f} MB; the limit is {self.max_upload_bytes / 1e6:.3f} MB",
            error=True,
        )

    def _progress(self, fraction: float | None, text: str) -> None:
        """The running command's status line and progress bar (fraction 0-1; None: unknown),
        with the commands queued behind it."""
        if fraction is not None:
            value = round(100.0 * min(max(fraction, 0.0), 1.0), 1)
            if self.job_bar.value != value:
                self.job_bar.value = value
        if self.waiting:
            names = [
                NAMES.get(type(c), "command") for c in self.waiting if type(c) is not MarkersCmd
            ]
            text += f"  \nQueued: {', '.join(names)}" if names else ""
        if self.status.content != text:
            self.status.content = text

    # the world in the scene ------------------------------------------------------------------

    def _show_world(self) -> None:
        scene = self.world.scene
        self.view.show(self.world, lambda ev: self.commands.put(MarkersCmd(ev.client_id)))
        failure = pick_failure(self.world)
        self.markers.reset(
            self.world, None if failure is None else public_message(failure, self.upload_dir)
        )
        self.plan_endpoints, self._standable = None, None
        self.set_plans([])
        self.choose_panel.clear()
        self.voxel_panel.clear(self)
        self._check_markers()
        self._show_robot_at_start()
        if self.show_standable.value:
            self._show_standable()
        self._frame_world()
        self.title.content = f"**roachplan** — scene `{scene.name}`  \n{scene.description}"
        self._refresh_results()

    def _frame_world(self) -> None:
        """Every view - the first view of a browser opened later, and every open browser's -
        frames the terrain the robot plans on (terrain_box) with start and goal: after a load
        or a re-mesh the old camera may be inside the new terrain or looking past it."""
        scene = self.world.scene
        points = [
            *terrain_box(self.world),
            *(on_surface(self.world, p) for p in (scene.start, scene.goal)),
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

    def _marker_pose(self, which: str) -> tuple[float, float, float]:
        return self.markers.pose(which)

    def _check_markers(self) -> bool:
        valid = self.markers.check(self.world)
        if self.show_standable.value and self._standable is not None:
            self._show_standable()  # (the start's region, when the start left it)
        return valid

    def _show_robot_at_start(self) -> None:
        start = self._marker_pose("start")
        x, y, z = on_surface(self.world, start)
        r = self.world.robot
        q0, _ = r.leg_angle(r.leg_phase_offsets)
        self.view.show_robot(self.server, (x, y, z + r.standing_height), yaw_wxyz(start[2]), q0)

    def _show_frame(self, f: Frame) -> None:
        self.view.show_robot(
            self.server, f.p_world_body, wxyz_from_xyzw(f.quat_world_body), f.leg_angles
        )
        now = time.monotonic()
        if self.follow.value and now - self._followed > 1 / 20:  # (20 camera moves a second)
            self._followed = now
            for client in self.server.get_clients().values():
                self._aim(client, f.p_world_body, zoom=False)

    # the view ----------------------------------------------------------------------------

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
                self.world.robot.body_length, fov, cam.image_height or 900, ROBOT_PIXELS
            )
            offset = np.asarray(cam.position) - np.asarray(cam.look_at)
            d = float(np.linalg.norm(offset))
            offset = offset / d if d > 1e-6 and offset[2] > 0.34 * d else VIEW_DIRECTION
            offset = near * offset
            self._follow_offsets[client.client_id] = offset
        with client.atomic():
            # Position first: viser moves the look-at along with a new position.
            cam.position, cam.look_at = target + offset, target

    def select_path(self, k: int) -> None:
        """Make path k (an index into self.plans, 0 to K - 1; the page labels it k + 1) the one
        Drive takes: it is drawn thick and labelled Drive, and the Drive path picker shows it.
        Run on the loop thread (a command's handler), like every change of state."""
        if not 0 <= k < len(self.plans):
            raise PlanningError(
                f"path {k + 1}: there are {len(self.plans)} planned path(s); "
                f"choose 1 to {len(self.plans)} (Plan first if there are none)"
            )
        self.drive_path = k
        self.view.mark_path(k)
        if self.drive_path_picker.value != str(k + 1):  # (the picker calls back: a no-op)
            self.drive_path_picker.value = str(k + 1)

    def set_plans(self, plans: list, *, drawn: bool = False) -> None:
        """The plan's paths (LabelledPlans; none: nothing drawn), drawn with the first marked
        for Drive; and the roadmap of the first, always kept (so Show roadmap acts at once).
        drawn: the view shows these paths already, in this order (Plan draws each as it is
        found): only the mark is added, not every path sent to the browsers again."""
        self.plans, self.drive_path = list(plans), 0
        self.roadmap = self.plans[0].plan.roadmap if self.plans else None
        names = tuple(str(k + 1) for k in range(len(self.plans))) or ("none",)
        self.drive_path_picker.options = names
        self.drive_path_picker.value = names[0]
        if self.plans and drawn and len(self.view.path_nodes) == len(self.plans):
            self.view.mark_path(0)
            self._show_roadmap()
        elif self.plans:
            self.show_plans()
        else:
            self.view.hide_paths()

    def show_plans(self) -> None:
        """Draw the planned paths (Drive's marked) and, when ticked, the roadmap."""
        self.view.show_paths([lp.plan.path_xyz for lp in self.plans], self.drive_path)
        self._show_roadmap()

    def _show_roadmap(self) -> None:
        if self.show_roadmap.value and self.roadmap is not None and self.view.path_nodes:
            self.view.draw_roadmap(self.world, self.roadmap)
        else:
            self.server.scene.remove_by_name("/plans/roadmap")

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
        w = self.world
        sm = standable_map(
            w.heightfield, w.footprint, w.scene.planner.validity, w.scene.bounds, (x, y)
        )
        self._standable = (sm, (round((x - sm.x0) / sm.cell), round((y - sm.y0) / sm.cell)))
        self.view.show_standable(w, sm)

    def _do_view(self, cmd: ViewCmd) -> None:
        match cmd.what:
            case "roadmap":
                self._show_roadmap()
            case "drive_path":
                if self.drive_path_picker.value != "none":
                    self.select_path(int(self.drive_path_picker.value) - 1)
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
                clients = self.server.get_clients()
                chosen = clients.values() if cmd.what == "follow" else [clients.get(cmd.client_id)]
                if cmd.what == "zoom" or self.follow.value:
                    for client in chosen:
                        if client is not None:
                            self._aim(client, self.view.robot_node.position, zoom=True)

    def _draw(self, name: str, points, colour) -> None:
        self.view.draw(name, points, colour)

    def _refresh_results(self) -> None:
        trials = self.scene_trials
        self.table.content = trials_markdown(trials)
        self.summary.content = summary_markdown(trials)
        self.plot.image = energy_plot(trials)
        self.show_trial.options = ("-", *(str(k + 1) for k in range(len(trials))))

    # jobs on the world ------------------------------------------------------------------

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

    # the loop ----------------------------------------------------------------------------

    def _run(self) -> None:
        # Start the fork server now (~1 s, its modules preloaded), not on the first click.
        run_to_end(_warm_job)
        self.host_world()
        while not self._stop.is_set():
            self._background(idle=not self.waiting)
            if self.waiting:
                cmd = self.waiting.popleft()
            else:
                try:
                    cmd = self.commands.get(timeout=0.05)
                except queue.Empty:
                    continue
            # The buttons stay enabled while a command runs: viser drops a click on a disabled
            # button, so another browser's click would be lost; clicks queue here instead.
            self._safely(cmd)

    def _safely(self, cmd: Cmd) -> None:
        try:
            self._handle(cmd)
        except Exception as exc:  # keep serving whatever went wrong in one command
            text = public_message(f"{exc}", self.upload_dir)
            self._notify(cmd.client_id, "Error", text, error=True)
            self.status.content = f"Error: {text}"
        finally:
            self.drive_button.disabled = not self.plans

    def _background(self, *, idle: bool) -> None:
        """Follow the batch and the load; a loaded world replaces the current one only when
        idle (no command running or queued: those were clicked on the current scene)."""
        self.batch_panel.drain(lambda trial: record(self, trial, "batch"))
        ld = self.loading.poll()
        if ld is None:
            return
        if ld.error is not None:
            report_failure(self, self.loading.take())
        elif idle and self.running is None and self.batch is None:
            swap_in(self, self.loading.take())
        else:
            after = "the batch of trials" if self.batch is not None else "the running command"
            self.loading.show(f"{ld.label} is ready: it replaces this scene when {after} ends.")

    def _intake(self) -> None:
        """While a command runs: handle what starts or stops background work now; queue the
        rest, saying so to whoever clicked."""
        while True:
            try:
                cmd = self.commands.get_nowait()
            except queue.Empty:
                return
            picking = isinstance(cmd, PlaceCmd) and (
                self.load_panel.pick_ground.value or self.voxel_panel.pick_centre.value
            )
            if isinstance(cmd, AT_ONCE) or picking:
                self._safely(cmd)
            elif isinstance(cmd, MarkersCmd):  # a drag sends many: one re-check afterwards
                if not any(type(c) is MarkersCmd for c in self.waiting):
                    self.waiting.append(cmd)
            else:
                self.waiting.append(cmd)
                name = NAMES.get(type(cmd), "Command")
                self._notify(
                    cmd.client_id,
                    f"{name} queued",
                    f"It runs when {self.running} ends; Cancel (at the top) stops "
                    f"{self.running} and drops what is queued.",
                )

    def _follow(self, job: Job, name: str, step, *, hard_stop: float | None = None) -> str:
        """Keep the page live while job runs: step(messages) shows its progress and returns
        True when the work is complete. Returns "done", "cancelled" (Cancel: the child is
        killed at once, the queued commands dropped) or "stopped" (past hard_stop)."""
        self.running, self._cancel = name, False
        self.cancel_job.visible = True
        self.job_bar.value, self.job_bar.visible = 0.0, True
        try:
            while True:
                if step(job.poll(timeout=1 / 60)):
                    return "done"
                self._intake()
                if self._cancel or self._stop.is_set():
                    job.cancel()
                    self._drop_waiting(name)
                    return "cancelled"
                if hard_stop is not None and time.monotonic() > hard_stop:
                    job.cancel()
                    return "stopped"
                self._background(idle=False)
        finally:
            job.cancel()  # (nothing when it finished; a failed step leaves no child behind)
            self.running = None
            self.cancel_job.visible = self.job_bar.visible = False

    def _drop_waiting(self, name: str) -> None:
        while self.waiting:
            cmd = self.waiting.popleft()
            if type(cmd) is not MarkersCmd:
                self._notify(
                    cmd.client_id,
                    f"{NAMES.get(type(cmd), 'Command')} not run",
                    f"{name} was cancelled, and what was queued behind it dropped.",
                )
        self._check_markers()

    def _handle(self, cmd: Cmd) -> None:  # noqa: PLR0912 - one branch per command
        match cmd:
            case PlanCmd():
                do_plan(self, cmd)
            case DriveCmd():
                do_drive(self, cmd)
            case ResetCmd():
                self._show_robot_at_start()
                self.view.clear("/trajectories")
                self.status.content = "Robot back at the start."
            case BestPathCmd():
                do_best_path(self, cmd)
            case ChooseCmd():
                do_choose(self, self.choose_panel, cmd)
            case CancelCmd(what="job"):
                self._cancel = self.running is not None
            case CancelCmd(what="load"):
                ld = self.loading.stop()
                if ld is not None:
                    self.loading.show(
                        f"Loading {ld.label} cancelled after {ld.job.elapsed:.1f} s; "
                        f"the scene `{self.world.scene.name}` stays."
                    )
                    self.scene_picker.value = self._picker_label()
            case CancelCmd(what="batch"):
                self.batch_panel.cancel()
            case LoadSceneCmd():
                if cmd.name != self._picker_label():  # (setting the picker also calls back)
                    ref, owned = self.files.get(cmd.name, (cmd.name, False))
                    self._load(cmd, ref, from_upload=owned, label=cmd.name)
            case UploadCmd():
                self.load_panel.upload(self, cmd)
            case PanelCmd():
                self.load_panel.handle(self, cmd)
            case VoxelCmd():
                self.voxel_panel.handle(self, cmd)
            case PlaceCmd():
                self._do_place(cmd)
            case MarkersCmd():
                self._check_markers()
                self._show_robot_at_start()
            case RunTrialsCmd():
                self._start_batch(cmd)
            case ShowTrialCmd():
                show_trial(self)
            case ViewCmd():
                self._do_view(cmd)
            case ShareCmd():
                share_trial(self, cmd)
            case ExportCmd():
                client = self.server.get_clients().get(cmd.client_id)
                if client is not None:
                    client.send_file_download(
                        f"{self.world.scene.name}-trials.csv",
                        trials_csv(self.scene_trials).encode(),
                        save_immediately=True,
                    )

    # loading ---------------------------------------------------------------------------------

    def _load(
        self, cmd: Cmd, ref: str, *, from_upload: bool, label: str, what: str | None = None
    ) -> None:
        """Start loading a scene in the background (replacing a load still running)."""
        # Said by what the scene holds, not by the file's suffix: a .zip may hold a capture.
        what = what or load_announcement(label, ref)
        replaced = self.loading.start(cmd, ref, from_upload=from_upload, label=label, what=what)
        if replaced is not None:
            self._notify(
                replaced.client_id,
                f"Stopped loading {replaced.label}",
                f"{label} is loaded instead.",
            )
        if self.running is None:
            self.status.content = (
                f"`{self.world.scene.name}` stays in use while {label} loads (Scene folder)."
            )

    def _picker_label(self) -> str:
        path = str(Path(self.world.scene.path).resolve())
        return next(
            (k for k, (v, _) in self.files.items() if str(Path(v).resolve()) == path),
            self.world.scene.name,
        )

    # commands --------------------------------------------------------------------------------

    def _do_place(self, cmd: PlaceCmd) -> None:
        which, picking = self.click_mode.value, self.load_panel.pick_ground.value
        square = self.voxel_panel.pick_centre.value
        if which == "nothing" and not picking and not square:
            return
        hit = ray_hit_heightfield(self.world.heightfield, cmd.ray_origin, cmd.ray_direction)
        if hit is None:
            self._notify(cmd.client_id, "Missed", "That click does not hit the terrain.")
            return
        if square:  # the Voxel study's square, centred here
            self.voxel_panel.set_centre(self, cmd, hit)
            return
        if picking:  # the load panel's "Pick ground": re-level the capture there
            self.load_panel.relevel_at_click(self, cmd, hit)
            return
        self.controls[which].position = tuple(float(v) for v in hit)
        self._check_markers()
        self._show_robot_at_start()
        self.status.content = f"{which.capitalize()} placed at ({hit[0]:.2f}, {hit[1]:.2f})."

    def _planner(self):
        return dataclasses.replace(
            self.world.scene.planner,
            name=self.planner.value,
            time_limit=float(self.time_limit.value),
            keep_roadmap=True,
        )  # (Show roadmap shows it at once)

    # batches -----------------------------------------------------------------------------

    def _start_batch(self, cmd: Cmd) -> None:
        if self.batch is not None:
            self._notify(cmd.client_id, "Busy", "A batch is already running.", error=True)
            return
        start, goal = self.markers.valid_poses(self.world)
        scene, n = self.world.scene, int(self.batch_panel.n.value)
        spec = ExperimentSpec(
            name="app",
            path=scene.path,
            scene=scene.path,
            planner=self._planner(),
            sim=scene.sim,
            driver=scene.driver,
            trials_per_route=n,
            seed=self._next_seed,
        )
        self._next_seed += n
        self.batch_panel.start(spec, start, goal)

    def stop(self) -> None:
        self.batch_panel.cancel()
        self.loading.stop()
        self._stop.set()
        self._loop.join(timeout=5)
        if self._host is not None:
            self._host.close()
        self.server.stop()


def serve(*, scene: str, host: str, port: int) -> None:
    """Build the world (a library scene, a scene file or any terrain file) and serve the app
    until interrupted."""
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
    app = RoachApp(world, host=host, port=port, view=view)
    print(f"roachplan: serving scene {world.scene.name!r} at http://{host}:{app.port}", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        app.stop()


__all__ = ["RoachApp", "serve"]
