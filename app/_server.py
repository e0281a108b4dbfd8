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
from roachplan.planning import PLANNER_NAMES
from roachplan.scenes import LIBRARY, World, list_scenes
from roachplan.sim import Frame

from ._batch import Batch, BatchPanel
from ._commands import do_best_path, do_drive, do_plan, record, show_trial
from ._draw import SceneView, on_surface, wxyz_from_xyzw, yaw_wxyz
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
    _warm_job,
    load_world,
    run_to_end,
)
from ._load_panel import LoadPanel, PanelCmd
from ._loading import BackgroundLoad, report_failure, swap_in
from ._markers import StartGoal
from ._panel import energy_plot, summary_markdown, trials_csv, trials_markdown
from ._picking import ray_hit_heightfield
from ._relevel import CaptureView
from ._uploads import MAX_UPLOAD_BYTES, limit_uploads, public_message

AT_ONCE = (LoadSceneCmd, UploadCmd, PanelCmd, ExportCmd, CancelCmd)
"""Commands handled even while a plan or drive runs: they start or stop background work."""


class RoachApp:
    """Owns the viser server and the state shown in it."""

    def __init__(
        self, world: World, *, host: str, port: int, upload_dir: Path | None = None,
        max_upload_bytes: int = MAX_UPLOAD_BYTES, view: CaptureView | None = None,
    ):  # fmt: skip
        """view: the capture view of world (load_world), to re-mesh and re-level it."""
        self.world = world
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
        self.files: dict[str, tuple[str, bool]] = {}
        """Scene picker label -> (scene file, written by the app) of each scene loaded from a
        file: uploads, re-meshed copies, `serve --scene FILE`."""
        self.upload_dir = Path(upload_dir or tempfile.mkdtemp(prefix="roachplan-uploads-"))
        self._next_seed = world.scene.seed
        self.max_upload_bytes = max_upload_bytes
        limit_uploads(self.server, max_upload_bytes, self._refuse_upload)
        path = Path(world.scene.path).resolve()
        if path != (LIBRARY / f"{world.scene.name}.yaml").resolve():
            self.files[f"file: {path.name}"] = (str(path), False)
        self.view = SceneView(self.server.scene)
        self._build_gui()
        self._show_world()
        self.load_panel.show_capture(view, world.mesh.bounds if view is not None else None)
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
            "Cancel", visible=False, color="red",
            hint="Stop the running command now, and drop what is queued behind it",
        )  # fmt: skip
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
        self.markers = StartGoal(gui, put, self.view)
        self.click_mode = self.markers.click_mode
        self.start_yaw, self.goal_yaw = self.markers.start_yaw, self.markers.goal_yaw
        with gui.add_folder("Plan and drive"):
            self.planner = gui.add_dropdown(
                "Planner", PLANNER_NAMES, initial_value=self.world.scene.planner.name
            )
            self.time_limit = gui.add_number(
                "Time budget [s]", 20.0, min=0.1, max=3600.0, step=0.5,
                hint="For the whole Plan: every try at every path",
            )  # fmt: skip
            self.count = gui.add_number("Paths (K)", 1, min=1, max=20, step=1)
            self.show_roadmap = gui.add_checkbox("Show roadmap", False)
            self.plan_button = gui.add_button("Plan")
            self.drive_button = gui.add_button("Drive", disabled=True)
            self.reset_button = gui.add_button("Reset")
            self.best_button = gui.add_button("Best path")
            self.speed = gui.add_slider("Playback speed [x real time]", 1, 10, 1, 1)
        self.batch_panel = BatchPanel(gui, put)
        with gui.add_folder("Results"):
            self.show_trial = gui.add_dropdown("Show trial", ("-",))
            self.export_button = gui.add_button("Export CSV")
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
        self.plan_button.on_click(lambda ev: put(PlanCmd(ev.client_id)))
        self.drive_button.on_click(lambda ev: put(DriveCmd(ev.client_id)))
        self.reset_button.on_click(lambda ev: put(ResetCmd(ev.client_id)))
        self.best_button.on_click(lambda ev: put(BestPathCmd(ev.client_id)))
        self.cancel_job.on_click(lambda ev: put(CancelCmd(ev.client_id, "job")))
        self.show_trial.on_update(lambda ev: put(ShowTrialCmd(ev.client_id)))
        self.export_button.on_click(lambda ev: put(ExportCmd(ev.client_id)))

    def _set_click_mode(self) -> None:
        """Listen for clicks on the scene only while a marker is to be placed (a listening
        scene does not orbit on click)."""
        scene = self.server.scene
        scene.remove_click_callback()
        if self.click_mode.value != "nothing" or self.load_panel.pick_ground.value:
            scene.on_click()(
                lambda ev: self.commands.put(
                    PlaceCmd(ev.client_id, ev.ray_origin, ev.ray_direction)
                )
            )

    def _notify(self, client_id: int | None, title: str, body: str, *, error: bool = False):
        client = self.server.get_clients().get(client_id) if client_id is not None else None
        if client is not None:
            client.add_notification(
                title, body, auto_close_seconds=None if error else 4.0,
                color="red" if error else None,
            )  # fmt: skip

    def _refuse_upload(self, client_id, name: str, size: int) -> None:
        self._notify(client_id, "File too large",
                     f"{name}: {size / 1e6:.3f} MB; the limit is {self.max_upload_bytes / 1e6:.3f} MB",
                     error=True)  # fmt: skip

    def _progress(self, fraction: float | None, text: str) -> None:
        """The running command's status line and progress bar (fraction 0-1; None: unknown),
        with the commands queued behind it."""
        if fraction is not None:
            value = round(100.0 * min(max(fraction, 0.0), 1.0), 1)
            if self.job_bar.value != value:
                self.job_bar.value = value
        if self.waiting:
            names = [NAMES.get(type(c), "command") for c in self.waiting if type(c) is not MarkersCmd]
            text += f"  \nQueued: {', '.join(names)}" if names else ""
        if self.status.content != text:
            self.status.content = text

    # the world in the scene ------------------------------------------------------------------

    def _show_world(self) -> None:
        scene = self.world.scene
        self.view.show(self.world, lambda ev: self.commands.put(MarkersCmd(ev.client_id)))
        self.markers.reset(self.world)
        self.plans, self.plan_endpoints = [], None
        self._check_markers()
        self._show_robot_at_start()
        (lo, hi) = np.asarray(scene.bounds)
        c, ext = (lo + hi) / 2, float(np.max(hi - lo))
        self.server.initial_camera.position = (c[0] + 0.8 * ext, c[1] - 1.0 * ext, 0.75 * ext)
        self.server.initial_camera.look_at = (c[0], c[1], 0.0)
        self.title.content = f"**roachplan** — scene `{scene.name}`  \n{scene.description}"
        self._refresh_results()

    def _marker_pose(self, which: str) -> tuple[float, float, float]:
        return self.markers.pose(which)

    def _check_markers(self) -> bool:
        return self.markers.check(self.world)

    def _show_robot_at_start(self) -> None:
        start = self._marker_pose("start")
        x, y, z = on_surface(self.world, start)
        r = self.world.robot
        q0, _ = r.leg_angle(r.leg_phase_offsets)
        self.view.show_robot(self.server, (x, y, z + r.standing_height), yaw_wxyz(start[2]), q0)

    def _show_frame(self, f: Frame) -> None:
        self.view.show_robot(self.server, f.p_world_body, wxyz_from_xyzw(f.quat_world_body),
                             f.leg_angles)  # fmt: skip

    def _draw(self, name: str, points, colour) -> None:
        self.view.draw(name, points, colour)

    def _refresh_results(self) -> None:
        trials = self.scene_trials
        self.table.content = trials_markdown(trials)
        self.summary.content = summary_markdown(trials)
        self.plot.image = energy_plot(trials)
        self.show_trial.options = ("-", *(str(k + 1) for k in range(len(trials))))

    # the loop ----------------------------------------------------------------------------

    def _run(self) -> None:
        # Start the fork server now (~1 s, its modules preloaded), not on the first click.
        run_to_end(_warm_job)
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
            picking = isinstance(cmd, PlaceCmd) and self.load_panel.pick_ground.value
            if isinstance(cmd, AT_ONCE) or picking:
                self._safely(cmd)
            elif isinstance(cmd, MarkersCmd):  # a drag sends many: one re-check afterwards
                if not any(type(c) is MarkersCmd for c in self.waiting):
                    self.waiting.append(cmd)
            else:
                self.waiting.append(cmd)
                name = NAMES.get(type(cmd), "Command")
                self._notify(cmd.client_id, f"{name} queued",
                             f"It runs when {self.running} ends; Cancel (at the top) stops "
                             f"{self.running} and drops what is queued.")  # fmt: skip

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
                self._notify(cmd.client_id, f"{NAMES.get(type(cmd), 'Command')} not run",
                             f"{name} was cancelled, and what was queued behind it dropped.")  # fmt: skip
        self._check_markers()

    def _handle(self, cmd: Cmd) -> None:  # noqa: PLR0912 - one branch per command
        match cmd:
            case PlanCmd():
                do_plan(self, cmd)
            case DriveCmd():
                do_drive(self, cmd)
            case ResetCmd():
                self._show_robot_at_start()
                self.server.scene.remove_by_name("/trajectories")
                self.status.content = "Robot back at the start."
            case BestPathCmd():
                do_best_path(self, cmd)
            case CancelCmd(what="job"):
                self._cancel = self.running is not None
            case CancelCmd(what="load"):
                ld = self.loading.stop()
                if ld is not None:
                    self.loading.show(f"Loading {ld.label} cancelled after {ld.job.elapsed:.1f} s; "
                                      f"the scene `{self.world.scene.name}` stays.")  # fmt: skip
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
            case PlaceCmd():
                self._do_place(cmd)
            case MarkersCmd():
                self._check_markers()
                self._show_robot_at_start()
            case RunTrialsCmd():
                self._start_batch(cmd)
            case ShowTrialCmd():
                show_trial(self)
            case ExportCmd():
                client = self.server.get_clients().get(cmd.client_id)
                if client is not None:
                    client.send_file_download(
                        f"{self.world.scene.name}-trials.csv",
                        trials_csv(self.scene_trials).encode(),
                        save_immediately=True,
                    )

    # loading ---------------------------------------------------------------------------------

    def _load(self, cmd: Cmd, ref: str, *, from_upload: bool, label: str,
              what: str | None = None) -> None:  # fmt: skip
        """Start loading a scene in the background (replacing a load still running)."""
        replaced = self.loading.start(cmd, ref, from_upload=from_upload, label=label,
                                      what=what or f"Loading {label}")  # fmt: skip
        if replaced is not None:
            self._notify(replaced.client_id, f"Stopped loading {replaced.label}",
                         f"{label} is loaded instead.")  # fmt: skip
        if self.running is None:
            self.status.content = (f"`{self.world.scene.name}` stays in use while {label} "
                                   f"loads (Scene folder).")  # fmt: skip

    def _picker_label(self) -> str:
        path = str(Path(self.world.scene.path).resolve())
        return next((k for k, (v, _) in self.files.items() if str(Path(v).resolve()) == path),
                    self.world.scene.name)  # fmt: skip

    # commands --------------------------------------------------------------------------------

    def _do_place(self, cmd: PlaceCmd) -> None:
        which, picking = self.click_mode.value, self.load_panel.pick_ground.value
        if which == "nothing" and not picking:
            return
        hit = ray_hit_heightfield(self.world.heightfield, cmd.ray_origin, cmd.ray_direction)
        if hit is None:
            self._notify(cmd.client_id, "Missed", "That click does not hit the terrain.")
            return
        if picking:  # the load panel's "Pick ground": re-level the capture there
            self.load_panel.relevel_at_click(self, cmd, hit)
            return
        self.controls[which].position = tuple(float(v) for v in hit)
        self._check_markers()
        self._show_robot_at_start()
        self.status.content = f"{which.capitalize()} placed at ({hit[0]:.2f}, {hit[1]:.2f})."

    def _planner(self):
        return dataclasses.replace(self.world.scene.planner, name=self.planner.value,
                                   time_limit=float(self.time_limit.value),
                                   keep_roadmap=bool(self.show_roadmap.value))  # fmt: skip

    # batches -----------------------------------------------------------------------------

    def _start_batch(self, cmd: Cmd) -> None:
        if self.batch is not None:
            self._notify(cmd.client_id, "Busy", "A batch is already running.", error=True)
            return
        start, goal = self.markers.valid_poses(self.world)
        scene, n = self.world.scene, int(self.batch_panel.n.value)
        spec = ExperimentSpec(
            name="app", path=scene.path, scene=scene.path, planner=self._planner(), sim=scene.sim,
            driver=scene.driver, trials_per_route=n, seed=self._next_seed,
        )  # fmt: skip
        self._next_seed += n
        self.batch_panel.start(spec, start, goal)

    def stop(self) -> None:
        self.batch_panel.cancel()
        self.loading.stop()
        self._stop.set()
        self._loop.join(timeout=5)
        self.server.stop()


def serve(*, scene: str, host: str, port: int) -> None:
    """Build the world (a library scene, a scene file or any terrain file) and serve the app
    until interrupted."""
    import sys

    world, view = load_world(scene, from_upload=False, check_poses=True)
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
