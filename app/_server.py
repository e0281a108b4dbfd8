"""The browser app: the world, the roach and its start and goal markers, and every service of
the report's performance evaluator (plan, drive, reset, best path, batches of trials).

Threads: viser runs callbacks on its own thread pool; they only put a command on a queue (the
batch Cancel button also raises a flag the batch thread polls). Commands run one at a time, in
the order they were clicked, from any browser. One loop thread owns the state:
it drains the queue and runs each piece of work outside the server's process - planning,
driving and scene loading (meshing a capture, rendering OpenSCAD) in a fresh child each (OMPL
holds the GIL while it solves, and a fresh process is where OMPL's global RNG can be seeded);
batches of trials in a pool of worker processes fed by a batch thread. The state is shared:
every open browser sees the same world and trials, and its own notifications.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing as mp
import os
import queue
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import viser

from experiments import ExperimentSpec, TrialResult, finish_trial, plan_many
from experiments._workers import LocalPool
from planning import PLANNER_NAMES, PlanningError
from scenes import World, build_world, list_scenes, load_scene, pose_problem
from sim import Frame

from ._panel import energy_plot, summary_markdown, trials_csv, trials_markdown
from ._picking import ray_hit_heightfield
from ._load_panel import LoadPanel, PanelCmd, needs_millimetre_scale, view_of_upload
from ._uploads import MAX_UPLOAD_BYTES, prepare_upload_scene, public_message

# -- commands (what callbacks enqueue) ----------------------------------------------------------


@dataclass(frozen=True)
class Cmd:
    client_id: int | None


@dataclass(frozen=True)
class PlanCmd(Cmd):
    pass


@dataclass(frozen=True)
class DriveCmd(Cmd):
    pass


@dataclass(frozen=True)
class ResetCmd(Cmd):
    pass


@dataclass(frozen=True)
class BestPathCmd(Cmd):
    pass


@dataclass(frozen=True)
class LoadSceneCmd(Cmd):
    name: str


@dataclass(frozen=True)
class UploadCmd(Cmd):
    name: str
    data: bytes


@dataclass(frozen=True)
class PlaceCmd(Cmd):
    ray_origin: tuple[float, float, float]
    ray_direction: tuple[float, float, float]


@dataclass(frozen=True)
class MarkersCmd(Cmd):
    """A marker was dragged or a yaw slider moved: re-check start and goal."""


@dataclass(frozen=True)
class RunTrialsCmd(Cmd):
    pass


@dataclass(frozen=True)
class ShowTrialCmd(Cmd):
    pass


@dataclass(frozen=True)
class ExportCmd(Cmd):
    pass


# -- work in child processes --------------------------------------------------------------------

_CTX = mp.get_context("forkserver")
_CTX.set_forkserver_preload(["experiments._trial"])


def _plan_job(conn, world: World, count: int, request: dict) -> None:
    """request: plan_many's keyword arguments (seed, start, goal, planner)."""
    try:
        conn.send(("plans", plan_many(world, count, **request)))
    except Exception as exc:  # reported to the user as a notification
        conn.send(("error", f"{exc}"))
    conn.close()


def _drive_job(conn, world: World, planned, start, goal) -> None:
    try:
        result = finish_trial(
            world, planned, start=start, goal=goal, on_frame=lambda f: conn.send(("frame", f))
        )
        conn.send(("result", result))
    except Exception as exc:
        conn.send(("error", f"{exc}"))
    conn.close()


def _load_job(conn, ref: str, from_upload: bool) -> None:
    try:
        if from_upload:
            world = prepare_upload_scene(Path(ref))
        else:
            world = build_world(load_scene(ref), check_poses=False)
        world.regions  # noqa: B018 - computed here, once, and sent along
        if from_upload:  # the capture's camera, to re-level it in the page
            conn.send(("capture", view_of_upload(world.scene)))
        conn.send(("world", world))
    except Exception as exc:
        conn.send(("error", f"{exc}"))
    conn.close()


def _warm_job(conn) -> None:
    conn.close()


def _run_in_child(target, *args):
    """Run target(conn, *args) in a fresh process; yield what it sends until it closes."""
    parent, child = _CTX.Pipe(duplex=False)
    proc = _CTX.Process(target=target, args=(child, *args), daemon=True)
    proc.start()
    child.close()
    try:
        while True:
            try:
                yield parent.recv()
            except EOFError:
                return
    finally:
        proc.join(timeout=5)


def _limit_uploads(server: viser.ViserServer, max_bytes: int, refuse) -> None:
    """Refuse an upload larger than max_bytes when it starts (before its parts are buffered),
    and drop one whose parts outgrow what it announced. refuse(client_id, name, size)."""
    from viser import _messages

    gui = server.gui
    ws = gui._websock_interface  # viser has no upload limit of its own (1.1)
    start, part = gui._handle_file_transfer_start, gui._handle_file_transfer_part

    def on_start(client_id, message) -> None:
        if message.size_bytes > max_bytes:
            refuse(client_id, message.filename, message.size_bytes)
            return
        start(client_id, message)

    def on_part(client_id, message) -> None:
        state = gui._current_file_upload_states.get(message.transfer_uuid)
        if state is not None and state["transferred_bytes"] + len(message.content) > max_bytes:
            gui._current_file_upload_states.pop(message.transfer_uuid, None)
            refuse(client_id, state["filename"], state["transferred_bytes"] + len(message.content))
            return
        part(client_id, message)

    ws.unregister_handler(_messages.FileTransferStartUpload, start)
    ws.unregister_handler(_messages.FileTransferPart, part)
    ws.register_handler(_messages.FileTransferStartUpload, on_start)
    ws.register_handler(_messages.FileTransferPart, on_part)


# -- geometry helpers ---------------------------------------------------------------------------


def wxyz_from_xyzw(q) -> tuple[float, float, float, float]:
    """PyBullet's xyzw quaternion as viser's wxyz."""
    x, y, z, w = q
    return (w, x, y, z)


def _yaw_wxyz(yaw: float) -> tuple[float, float, float, float]:
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def _segments(points: np.ndarray) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float32)
    return np.stack([pts[:-1], pts[1:]], axis=1)


BLACK, BLUE = (0, 0, 0), (30, 90, 255)
MARKER_COLOURS = {"start": (30, 160, 60), "goal": (40, 80, 220)}
INVALID = (220, 30, 30)


@dataclass
class Batch:
    """A running batch of trials."""

    total: int
    done: int = 0
    successes: int = 0
    started: float = 0.0
    cancel: threading.Event = dataclasses.field(default_factory=threading.Event)


# -- the app ------------------------------------------------------------------------------------


class RoachApp:
    """Owns the viser server and the state shown in it."""

    def __init__(
        self, world: World, *, host: str, port: int, upload_dir: Path | None = None,
        max_upload_bytes: int = MAX_UPLOAD_BYTES,
    ):  # fmt: skip
        self.world = world
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.commands: queue.Queue[Cmd] = queue.Queue()
        self.batch_results: queue.Queue[tuple[str, object]] = queue.Queue()
        self.trials: dict[str, list[dict]] = {}
        """Trial records (TrialResult.to_json() + "label") per scene file."""
        self.plans: list = []
        self.plan_endpoints: tuple[tuple, tuple] | None = None
        self.batch: Batch | None = None
        self.uploads: dict[str, str] = {}
        """Scene dropdown label -> scene file of each loaded upload."""
        self.upload_dir = Path(upload_dir or tempfile.mkdtemp(prefix="roachplan-uploads-"))
        self._next_seed = world.scene.seed
        self.max_upload_bytes = max_upload_bytes
        _limit_uploads(self.server, max_upload_bytes, self._refuse_upload)
        self._build_gui()
        self._show_world()
        self._stop = threading.Event()
        self._loop = threading.Thread(target=self._run, name="roachplan-loop", daemon=True)
        self._loop.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    @property
    def scene_trials(self) -> list[dict]:
        return self.trials.setdefault(str(self.world.scene.path), [])

    # gui ---------------------------------------------------------------------------------

    def _build_gui(self) -> None:  # noqa: PLR0915 - one widget per statement
        gui, put = self.server.gui, self.commands.put
        self.title = gui.add_markdown("")
        with gui.add_folder("Scene"):
            self.scene_picker = gui.add_dropdown(
                "Scene", list_scenes(), initial_value=self.world.scene.name
            )
            self.upload = gui.add_upload_button(
                "Load file",
                hint=f"capture, .scad, mesh or scene .yaml (<= {MAX_UPLOAD_BYTES >> 20} MB)",
            )
            self.load_panel = LoadPanel(gui, put)
        with gui.add_folder("Start and goal"):
            self.click_mode = gui.add_dropdown("Click places", ("nothing", "start", "goal"))
            self.start_yaw = gui.add_slider("Start yaw [deg]", -180, 180, 1, 90)
            self.goal_yaw = gui.add_slider("Goal yaw [deg]", -180, 180, 1, 90)
            self.validity = gui.add_markdown("")
        with gui.add_folder("Plan and drive"):
            self.planner = gui.add_dropdown(
                "Planner", PLANNER_NAMES, initial_value=self.world.scene.planner.name
            )
            self.time_limit = gui.add_number("Time budget [s]", 20.0, min=0.1, max=300.0, step=0.5)
            self.count = gui.add_number("Paths (K)", 1, min=1, max=20, step=1)
            self.show_roadmap = gui.add_checkbox("Show roadmap", False)
            self.plan_button = gui.add_button("Plan")
            self.drive_button = gui.add_button("Drive", disabled=True)
            self.reset_button = gui.add_button("Reset")
            self.best_button = gui.add_button("Best path")
            self.speed = gui.add_slider("Playback speed [x real time]", 1, 10, 1, 1)
        with gui.add_folder("Batch of trials"):
            self.batch_n = gui.add_number("Trials (N)", 20, min=1, max=1000, step=1)
            self.batch_workers = gui.add_number(
                "Workers", os.cpu_count() or 1, min=1, max=64, step=1
            )
            self.run_button = gui.add_button("Run trials")
            self.cancel_button = gui.add_button("Cancel", disabled=True)
            self.progress = gui.add_progress_bar(0.0)
            self.batch_status = gui.add_markdown("")
        self.status = gui.add_markdown("Drag the start (green) and goal (blue), then **Plan**.")
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
        for slider in (self.start_yaw, self.goal_yaw):
            slider.on_update(lambda ev: put(MarkersCmd(ev.client_id)))
        self.plan_button.on_click(lambda ev: put(PlanCmd(ev.client_id)))
        self.drive_button.on_click(lambda ev: put(DriveCmd(ev.client_id)))
        self.reset_button.on_click(lambda ev: put(ResetCmd(ev.client_id)))
        self.best_button.on_click(lambda ev: put(BestPathCmd(ev.client_id)))
        self.run_button.on_click(lambda ev: put(RunTrialsCmd(ev.client_id)))
        self.cancel_button.on_click(lambda ev: self.batch and self.batch.cancel.set())
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

    # the world in the scene ------------------------------------------------------------------

    def _show_world(self) -> None:
        s, w = self.server.scene, self.world
        scene, r = w.scene, w.robot
        for name in ("/terrain", "/plans", "/trajectories", "/robot", "/markers"):
            s.remove_by_name(name)
        s.set_up_direction("+z")
        if len(w.mesh.faces):
            s.add_mesh_simple("/terrain/mesh", w.mesh.vertices, w.mesh.faces, color=(196, 164, 120),
                              flat_shading=True)  # fmt: skip
        if scene.ground is not None:
            (lo, hi) = np.asarray(scene.bounds)
            size = np.ceil(hi - lo + 2.0)  # the bounds plus a metre around [m]
            s.add_grid("/terrain/ground", width=float(size[0]), height=float(size[1]),
                       cell_size=0.25, position=(*((lo + hi) / 2), scene.ground))  # fmt: skip
        self.robot_node = s.add_box("/robot", color=(60, 60, 70),
                                    dimensions=(r.body_length, r.body_width, r.body_height))  # fmt: skip
        self.hip_nodes = []
        for k, hip in enumerate(r.hip_positions):
            hip_node = s.add_frame(f"/robot/hip{k}", show_axes=False, position=tuple(hip))
            s.add_box(f"/robot/hip{k}/leg", color=(200, 80, 40),
                      dimensions=(2 * r.leg_radius, 2 * r.leg_radius, r.leg_length),
                      position=(0.0, 0.0, -r.leg_length / 2))  # fmt: skip
            self.hip_nodes.append(hip_node)
        self.controls, self.balls = {}, {}
        for which, pose in (("start", scene.start), ("goal", scene.goal)):
            ctl = s.add_transform_controls(
                f"/markers/{which}", scale=0.25, disable_rotations=True,
                active_axes=(True, True, False), position=self._on_surface(pose), depth_test=False,
            )  # fmt: skip
            self.balls[which] = s.add_icosphere(f"/markers/{which}/ball", radius=0.03,
                                                color=MARKER_COLOURS[which])  # fmt: skip
            s.add_line_segments(f"/markers/{which}/heading", np.array([[[0, 0, 0.01], [0.12, 0, 0.01]]]),
                                colors=MARKER_COLOURS[which], thickness=4.0, thickness_units="screen")  # fmt: skip
            ctl.on_update(lambda ev: self.commands.put(MarkersCmd(ev.client_id)))
            self.controls[which] = ctl
        self.start_yaw.value = round(math.degrees(scene.start[2]))
        self.goal_yaw.value = round(math.degrees(scene.goal[2]))
        self.plans, self.plan_endpoints = [], None
        self._check_markers()
        self._show_robot_at_start()
        (lo, hi) = np.asarray(scene.bounds)
        c, ext = (lo + hi) / 2, float(np.max(hi - lo))
        self.server.initial_camera.position = (c[0] + 0.8 * ext, c[1] - 1.0 * ext, 0.75 * ext)
        self.server.initial_camera.look_at = (c[0], c[1], 0.0)
        self.title.content = f"**roachplan** — scene `{scene.name}`  \n{scene.description}"
        self._refresh_results()

    def _on_surface(self, pose) -> tuple[float, float, float]:
        z = float(self.world.heightfield.sample(np.array(pose[:2]))[()])
        return (float(pose[0]), float(pose[1]), z if np.isfinite(z) else 0.0)

    def _marker_pose(self, which: str) -> tuple[float, float, float]:
        x, y = (float(v) for v in self.controls[which].position[:2])
        yaw = self.start_yaw.value if which == "start" else self.goal_yaw.value
        return (x, y, math.radians(float(yaw)))

    def _check_markers(self) -> bool:
        """Colour each marker (red when invalid), turn it to its yaw, say why it is invalid."""
        lines = []
        for which in ("start", "goal"):
            pose = self._marker_pose(which)
            problem = pose_problem(self.world, pose)
            (lo, hi) = self.world.scene.bounds
            if not problem and not (lo[0] <= pose[0] <= hi[0] and lo[1] <= pose[1] <= hi[1]):
                problem = f"outside the planning area x in [{lo[0]:g}, {hi[0]:g}], y in [{lo[1]:g}, {hi[1]:g}]"
            colour = INVALID if problem else MARKER_COLOURS[which]
            if tuple(self.balls[which].color) != colour:
                self.balls[which].color = colour
            wxyz = _yaw_wxyz(pose[2])
            if not np.allclose(self.controls[which].wxyz, wxyz):  # (a change calls back)
                self.controls[which].wxyz = wxyz
            if problem:
                lines.append(f"**{which} invalid**: {problem}")
        text = "  \n".join(lines) or "Start and goal are valid."
        if self.validity.content != text:
            self.validity.content = text
        return not lines

    def _show_robot_at_start(self) -> None:
        start = self._marker_pose("start")
        x, y, z = self._on_surface(start)
        r = self.world.robot
        q0, _ = r.leg_angle(r.leg_phase_offsets)
        self._show_robot((x, y, z + r.standing_height), _yaw_wxyz(start[2]), q0)

    def _show_frame(self, f: Frame) -> None:
        self._show_robot(f.p_world_body, wxyz_from_xyzw(f.quat_world_body), f.leg_angles)

    def _show_robot(self, position, wxyz, leg_angles) -> None:
        """Body pose (world frame, wxyz) and leg angles [rad] (rotations about body +y)."""
        with self.server.atomic():
            self.robot_node.position = position
            self.robot_node.wxyz = wxyz
            for node, q in zip(self.hip_nodes, leg_angles, strict=True):
                node.wxyz = (math.cos(q / 2), 0.0, math.sin(q / 2), 0.0)

    def _draw(self, name: str, points, colour) -> None:
        if len(points) >= 2:
            self.server.scene.add_line_segments(name, _segments(np.asarray(points)), colors=colour,
                                                thickness=3.0, thickness_units="screen")  # fmt: skip

    def _refresh_results(self) -> None:
        trials = self.scene_trials
        self.table.content = trials_markdown(trials)
        self.summary.content = summary_markdown(trials)
        self.plot.image = energy_plot(trials)
        self.show_trial.options = ("-", *(str(k + 1) for k in range(len(trials))))

    # the loop ----------------------------------------------------------------------------

    def _run(self) -> None:
        # Start the fork server now (~1 s, its modules preloaded), not on the first click.
        for _ in _run_in_child(_warm_job):
            pass
        while not self._stop.is_set():
            self._drain_batch()
            try:
                cmd = self.commands.get(timeout=0.05)
            except queue.Empty:
                continue
            # The buttons stay enabled while a command runs: viser drops a click on a disabled
            # button, so another browser's click would be lost; clicks queue here instead.
            try:
                self._handle(cmd)
            except Exception as exc:  # keep serving whatever went wrong in one command
                self._notify(cmd.client_id, "Error", f"{exc}", error=True)
                self.status.content = f"Error: {exc}"
            finally:
                self.drive_button.disabled = not self.plans

    def _handle(self, cmd: Cmd) -> None:  # noqa: PLR0912 - one branch per command
        match cmd:
            case PlanCmd():
                self._do_plan(cmd)
            case DriveCmd():
                self._do_drive(cmd)
            case ResetCmd():
                self._show_robot_at_start()
                self.server.scene.remove_by_name("/trajectories")
                self.status.content = "Robot back at the start."
            case BestPathCmd():
                self._do_best_path(cmd)
            case LoadSceneCmd():
                if cmd.name != self._picker_label():  # (setting the picker also calls back)
                    ref = self.uploads.get(cmd.name, cmd.name)
                    self._load(cmd, ref, from_upload=cmd.name in self.uploads, label=cmd.name)
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
                self._do_show_trial()
            case ExportCmd():
                client = self.server.get_clients().get(cmd.client_id)
                if client is not None:
                    client.send_file_download(
                        f"{self.world.scene.name}-trials.csv",
                        trials_csv(self.scene_trials).encode(),
                        save_immediately=True,
                    )

    def _load(self, cmd: Cmd, ref: str, *, from_upload: bool, label: str) -> None:
        if self.batch is not None:
            raise RuntimeError("a batch of trials is running; cancel it before changing the scene")
        self.status.content = f"Loading {label} ..."
        world = view = None
        for kind, payload in _run_in_child(_load_job, ref, from_upload):
            if kind == "error":
                payload = public_message(payload, self.upload_dir)
                self.status.content = (
                    f"Could not load {label}; the scene `{self.world.scene.name}` stays."
                )
                self.scene_picker.value = self._picker_label()
                mm = from_upload and needs_millimetre_scale(payload)
                self.load_panel.offer_scale((Path(ref), label) if mm else None)
                if mm:
                    payload += "  \nPress **Scale x0.001** (Scene panel) to load it in metres."
                self._notify(cmd.client_id, f"Could not load {label}", payload, error=True)
                return
            if kind == "capture":
                view = payload
                continue
            world = payload
        self.load_panel.offer_scale(None)
        self.load_panel.show_capture(view)
        if world.notes:
            self._notify(cmd.client_id, f"Loaded {label}", " ".join(world.notes))
        self.world = world
        if from_upload:
            self.uploads[label] = ref
            self.scene_picker.options = (*list_scenes(), *self.uploads)
        self.scene_picker.value = self._picker_label()
        self._next_seed = world.scene.seed
        self._show_world()
        self.status.content = f"Loaded `{world.scene.name}` ({len(world.mesh.faces)} triangles)."

    def _picker_label(self) -> str:
        path = str(self.world.scene.path)
        return next((k for k, v in self.uploads.items() if v == path), self.world.scene.name)

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

    def _do_plan(self, cmd: Cmd) -> None:
        if not self._check_markers():
            raise PlanningError(self.validity.content.replace("**", ""))
        start, goal = self._marker_pose("start"), self._marker_pose("goal")
        count, seed = int(self.count.value), self._next_seed
        planner = self._planner()
        self.status.content = f"Planning with {planner.name} (seed {seed}) ..."
        self._show_robot_at_start()
        self.server.scene.remove_by_name("/plans")
        plans = []
        for kind, payload in _run_in_child(
            _plan_job, self.world, count, dict(seed=seed, start=start, goal=goal, planner=planner)
        ):
            if kind == "error":
                self.plans = []
                self.status.content = f"Planning failed: {payload}"
                self._notify(cmd.client_id, "Planning failed", payload, error=True)
                return
            plans = payload
        self._next_seed = (
            (max(lp.plan.seed for lp in plans) + 1) if plans else seed + 3 * count + 10
        )
        self.plans, self.plan_endpoints = plans, (start, goal)
        if not plans:
            self.status.content = f"No path found ({planner.name}, seeds from {seed})."
            return
        for k, lp in enumerate(plans):
            self._draw(f"/plans/{k}", lp.plan.path_xyz + [0, 0, 0.005], BLACK)
        graph = plans[0].plan.roadmap
        if len(graph):  # the first plan's roadmap or tree, grey, just above the surface
            z = self.world.heightfield.sample(graph.reshape(-1, 2)).reshape(-1, 2, 1)
            segs = np.concatenate([graph, np.nan_to_num(z) + 0.003], axis=2).astype(np.float32)
            self.server.scene.add_line_segments("/plans/roadmap", segs, colors=(150, 150, 150),
                                                thickness=1.0, thickness_units="screen")  # fmt: skip
        first = plans[0].plan
        if count == 1:
            self.status.content = (
                f"Path found in {first.plan_time:.2f} s (seed {first.seed}). Press **Drive**."
            )
        else:
            self.status.content = (
                f"{len(plans)} paths found (seeds {', '.join(str(lp.plan.seed) for lp in plans)}; "
                f"routes {', '.join(lp.route for lp in plans)}). **Drive** drives the first."
            )

    def _do_drive(self, cmd: Cmd) -> None:
        if not self.plans:
            self._notify(cmd.client_id, "Nothing to drive", "Plan a path first.", error=True)
            return
        start, goal = self.plan_endpoints
        result = self._drive(self.plans[0].plan, start, goal, cmd)
        if result is not None:
            self._record(result.to_json(), "")

    def _drive(self, planned, start, goal, cmd: Cmd) -> TrialResult | None:
        """Drive in a child and play the frames back at `speed` x real time (every frame the
        browser can take: at most 60 per second)."""
        self.status.content = "Driving ..."
        self.server.scene.remove_by_name("/trajectories")
        traj: list = []
        t_wall0, shown = time.perf_counter(), 0.0
        result = None
        for kind, payload in _run_in_child(_drive_job, self.world, planned, start, goal):
            if kind == "frame":
                traj.append(payload.p_world_body)
                speed = max(float(self.speed.value), 1.0)
                delay = payload.t / speed - (time.perf_counter() - t_wall0)
                if delay > 0:
                    time.sleep(delay)
                now = time.perf_counter()
                if now - shown >= 1 / 60:
                    self._show_frame(payload)
                    shown = now
                    if len(traj) % 5 == 0:
                        self._draw("/trajectories/current", traj, BLUE)
                self._drain_batch()
            elif kind == "result":
                result = payload
            else:
                self.status.content = f"Drive failed: {payload}"
                self._notify(cmd.client_id, "Drive failed", payload, error=True)
                return None
        self._draw("/trajectories/current", traj, BLUE)
        return result

    def _record(self, trial: dict, label: str) -> None:
        trial = {**trial, "label": label}
        self.scene_trials.append(trial)
        self._refresh_results()
        k = len(self.scene_trials)
        self.status.content = (
            f"Trial {k}: **{trial['outcome']}** ({trial['reason']}), {trial['drive_time']:.1f} s, "
            f"{trial['energy']:.3f} J ({trial['relative_energy']:.2f} x a straight walk on the floor)."
        )

    def _do_best_path(self, cmd: Cmd) -> None:
        """The report's best_path: drive the lowest-energy successful path again."""
        ok = [
            (k, t)
            for k, t in enumerate(self.scene_trials)
            if t["outcome"] == "success" and t["path"]
        ]
        if not ok:
            self._notify(cmd.client_id, "No best path yet", "Drive or run trials until one succeeds.",
                         error=True)  # fmt: skip
            return
        k, best = min(ok, key=lambda kt: kt[1]["relative_energy"])
        planned = self._stub_plan(best)
        self._draw("/plans/0", np.asarray(best["path"]) + [0, 0, 0.005], BLACK)
        result = self._drive(planned, tuple(best["start"]), tuple(best["goal"]), cmd)
        if result is not None:
            self._record(result.to_json(), f"best (trial {k + 1})")

    def _stub_plan(self, trial: dict):
        """The PlanResult of a stored trial's path (to drive it again)."""
        from planning import PlanResult

        return PlanResult(
            found=True, planner=trial["planner"], seed=trial["seed"], states=np.zeros((0, 3)),
            path_xyz=np.asarray(trial["path"]), plan_time=0.0, message="stored path",
        )  # fmt: skip

    def _do_show_trial(self) -> None:
        if self.show_trial.value == "-":
            return
        t = self.scene_trials[int(self.show_trial.value) - 1]
        self.server.scene.remove_by_name("/plans")
        self.server.scene.remove_by_name("/trajectories")
        self._draw("/plans/shown", np.asarray(t["path"]) + [0, 0, 0.005], BLACK)
        self._draw("/trajectories/shown", [p[1:] for p in t["trajectory"]], BLUE)
        self.status.content = f"Trial {self.show_trial.value}: {t['outcome']} ({t['reason']})."

    # batches -----------------------------------------------------------------------------

    def _start_batch(self, cmd: Cmd) -> None:
        if self.batch is not None:
            self._notify(cmd.client_id, "Busy", "A batch is already running.", error=True)
            return
        if not self._check_markers():
            raise PlanningError(self.validity.content.replace("**", ""))
        n, workers = int(self.batch_n.value), int(self.batch_workers.value)
        scene = self.world.scene
        spec = ExperimentSpec(
            name="app", path=scene.path, scene=scene.path, planner=self._planner(), sim=scene.sim,
            driver=scene.driver, trials_per_route=n, seed=self._next_seed,
        )  # fmt: skip
        start, goal = self._marker_pose("start"), self._marker_pose("goal")
        calls = [("trial", (k, spec.seed + k, "", None), {"start": start, "goal": goal})
                 for k in range(n)]  # fmt: skip
        self._next_seed += n
        self.batch = Batch(total=n, started=time.perf_counter())
        self.run_button.disabled, self.cancel_button.disabled = True, False
        self.progress.value = 0.0
        self.batch_status.content = f"Starting {n} trials on {workers} workers ..."
        threading.Thread(target=self._batch_thread, args=(spec, calls, workers, self.batch.cancel),
                         name="roachplan-batch", daemon=True).start()  # fmt: skip

    def _batch_thread(self, spec, calls, workers: int, cancel: threading.Event) -> None:
        """Feeds the worker pool and passes each finished trial to the loop thread."""
        try:
            pool = LocalPool(spec, workers)
            try:
                for rec in pool.run(calls):
                    self.batch_results.put(("trial", rec))
                    if cancel.is_set():
                        break
            finally:
                pool.close()
            self.batch_results.put(("done", "cancelled" if cancel.is_set() else "finished"))
        except Exception as exc:  # noqa: BLE001 - reported in the panel
            self.batch_results.put(("done", f"failed: {exc}"))

    def _drain_batch(self) -> None:
        while True:
            try:
                kind, payload = self.batch_results.get_nowait()
            except queue.Empty:
                return
            b = self.batch
            if b is None:
                continue
            if kind == "trial":
                b.done += 1
                b.successes += payload["outcome"] == "success"
                self._record({k: v for k, v in payload.items() if k not in ("kind", "index", "target_route")},
                             "batch")  # fmt: skip
                elapsed = time.perf_counter() - b.started
                eta = elapsed / b.done * (b.total - b.done)
                self.progress.value = 100.0 * b.done / b.total
                self.batch_status.content = (
                    f"{b.done}/{b.total} trials, {b.successes} successes, ETA {eta:.0f} s"
                )
            else:
                self.batch_status.content = (
                    f"Batch {payload}: {b.done}/{b.total} trials, {b.successes} successes, "
                    f"{time.perf_counter() - b.started:.1f} s."
                )
                self.batch = None
                self.run_button.disabled, self.cancel_button.disabled = False, True

    def stop(self) -> None:
        if self.batch is not None:
            self.batch.cancel.set()
        self._stop.set()
        self._loop.join(timeout=5)
        self.server.stop()


def serve(*, scene: str, host: str, port: int) -> None:
    """Build the world and serve the app until interrupted."""
    world = build_world(load_scene(scene))
    world.regions  # noqa: B018 - once, before the first plan
    app = RoachApp(world, host=host, port=port)
    print(f"roachplan: serving scene {world.scene.name!r} at http://{host}:{app.port}", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        app.stop()


__all__ = ["RoachApp", "serve"]
