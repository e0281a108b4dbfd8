"""The browser app: a viser server showing the world, with Plan, Drive and Reset.

Threads: viser runs its callbacks on its own thread pool; they only put a command on a queue.
One loop thread owns everything that changes state: it drains the queue, runs planning and
driving in a fresh worker process each (OMPL holds the GIL while it solves, and a fresh process
is the only place OMPL's global RNG can still be seeded), and pushes poses to the browser.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import queue
import threading
import time
from dataclasses import dataclass

import numpy as np
import viser

from experiments import TrialResult, finish_trial, plan
from planning import PlanResult
from scenes import World, build_world, load_scene
from sim import Frame

# -- commands (what callbacks enqueue) ----------------------------------------------------------


@dataclass(frozen=True)
class PlanCmd:
    client_id: int | None


@dataclass(frozen=True)
class DriveCmd:
    client_id: int | None


@dataclass(frozen=True)
class ResetCmd:
    client_id: int | None


Command = PlanCmd | DriveCmd | ResetCmd

# -- worker processes ---------------------------------------------------------------------------

_CTX = mp.get_context("forkserver")
_CTX.set_forkserver_preload(["experiments._trial"])


def _plan_worker(conn, world: World, seed: int, start, goal) -> None:
    try:
        conn.send(("plan", plan(world, seed=seed, start=start, goal=goal)))
    except Exception as exc:  # reported to the user as a notification
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
    conn.close()


def _drive_worker(conn, world: World, planned: PlanResult, start, goal) -> None:
    try:
        result = finish_trial(
            world, planned, start=start, goal=goal, on_frame=lambda f: conn.send(("frame", f))
        )
        conn.send(("result", result))
    except Exception as exc:
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
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


# -- the app ------------------------------------------------------------------------------------


class RoachApp:
    """Owns the viser server and the state shown in it."""

    def __init__(self, world: World, *, host: str, port: int) -> None:
        self.world = world
        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.commands: queue.Queue[Command] = queue.Queue()
        self.trials: list[TrialResult] = []
        self.planned: PlanResult | None = None
        self.planned_endpoints: tuple[tuple, tuple] | None = None
        """(start, goal) poses the current plan was made for."""
        self._next_seed = world.scene.seed
        self._build_scene()
        self._build_gui()
        self._stop = threading.Event()
        self._loop = threading.Thread(target=self._run, name="roachplan-loop", daemon=True)
        self._loop.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    # scene -------------------------------------------------------------------------------

    def _build_scene(self) -> None:
        s, w, r = self.server.scene, self.world, self.world.robot
        scene = w.scene
        s.set_up_direction("+z")
        if len(w.mesh.faces):
            s.add_mesh_simple(
                "/terrain/mesh", w.mesh.vertices, w.mesh.faces, color=(196, 164, 120),
                flat_shading=True,
            )  # fmt: skip
        if scene.ground is not None:
            (lo, hi) = np.asarray(scene.bounds)
            size = np.ceil(hi - lo + 2.0)  # the bounds plus a metre around [m]
            s.add_grid(
                "/terrain/ground", width=float(size[0]), height=float(size[1]), cell_size=0.25,
                position=(*((lo + hi) / 2), scene.ground),
            )  # fmt: skip
        self.robot_node = s.add_box(
            "/robot", color=(60, 60, 70),
            dimensions=(r.body_length, r.body_width, r.body_height),
        )  # fmt: skip
        self.hip_nodes = []
        for k, hip in enumerate(r.hip_positions):
            hip_node = s.add_frame(f"/robot/hip{k}", show_axes=False, position=tuple(hip))
            s.add_box(
                f"/robot/hip{k}/leg", color=(200, 80, 40),
                dimensions=(2 * r.leg_radius, 2 * r.leg_radius, r.leg_length),
                position=(0.0, 0.0, -r.leg_length / 2),
            )  # fmt: skip
            self.hip_nodes.append(hip_node)
        self.start_control = s.add_transform_controls(
            "/markers/start", scale=0.25, disable_rotations=True, active_axes=(True, True, False),
            position=self._on_surface(scene.start), depth_test=False,
        )  # fmt: skip
        s.add_icosphere("/markers/start/ball", radius=0.03, color=(30, 160, 60))
        self.goal_control = s.add_transform_controls(
            "/markers/goal", scale=0.25, disable_rotations=True, active_axes=(True, True, False),
            position=self._on_surface(scene.goal), depth_test=False,
        )  # fmt: skip
        s.add_icosphere("/markers/goal/ball", radius=0.03, color=(40, 80, 220))
        self._show_robot_at_start()
        self.server.initial_camera.position = (2.6, -3.2, 2.4)
        self.server.initial_camera.look_at = (0.0, 0.0, 0.0)

    def _on_surface(self, pose) -> tuple[float, float, float]:
        z = float(self.world.heightfield.sample(np.array(pose[:2]))[()])
        return (float(pose[0]), float(pose[1]), z if np.isfinite(z) else 0.0)

    def _marker_pose(self, control, scene_pose) -> tuple[float, float, float]:
        """(x, y, yaw) of a marker; the yaw is the scene's unless the marker was moved, then it
        faces from start to goal."""
        x, y = (float(v) for v in control.position[:2])
        if np.allclose((x, y), scene_pose[:2], atol=1e-6):
            return tuple(scene_pose)
        s, g = self.start_control.position, self.goal_control.position
        return (x, y, math.atan2(g[1] - s[1], g[0] - s[0]))

    def _show_robot_at_start(self) -> None:
        start = self._marker_pose(self.start_control, self.world.scene.start)
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

    # gui ---------------------------------------------------------------------------------

    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.add_markdown(
            f"**roachplan** — scene `{self.world.scene.name}`  \n{self.world.scene.description}"
        )
        self.plan_button = gui.add_button("Plan")
        self.drive_button = gui.add_button("Drive", disabled=True)
        self.reset_button = gui.add_button("Reset")
        self.status = gui.add_markdown("Drag the start (green) and goal (blue), then **Plan**.")
        self.table = gui.add_markdown(self._table_markdown())
        self.plan_button.on_click(lambda ev: self.commands.put(PlanCmd(ev.client_id)))
        self.drive_button.on_click(lambda ev: self.commands.put(DriveCmd(ev.client_id)))
        self.reset_button.on_click(lambda ev: self.commands.put(ResetCmd(ev.client_id)))

    def _table_markdown(self) -> str:
        head = (
            "| # | seed | route | outcome | drive time [s] | energy [J] | rel. energy |\n"
            "|---|---|---|---|---|---|---|\n"
        )
        rows = "".join(
            f"| {k + 1} | {t.seed} | {t.route or '-'} | {t.outcome} | {t.drive_time:.2f} "
            f"| {t.energy:.3f} | {t.relative_energy:.2f} |\n"
            for k, t in enumerate(self.trials)
        )
        return "**Trials**\n\n" + head + (rows or "| | | | | | |\n")

    def _notify(self, client_id: int | None, title: str, body: str, *, error: bool = False):
        client = self.server.get_clients().get(client_id) if client_id is not None else None
        if client is not None:
            client.add_notification(
                title, body, auto_close_seconds=None if error else 4.0,
                color="red" if error else None,
            )  # fmt: skip

    # the loop ----------------------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                cmd = self.commands.get(timeout=0.1)
            except queue.Empty:
                continue
            for button in (self.plan_button, self.drive_button, self.reset_button):
                button.disabled = True
            try:
                match cmd:
                    case PlanCmd():
                        self._do_plan(cmd)
                    case DriveCmd():
                        self._do_drive(cmd)
                    case ResetCmd():
                        self._show_robot_at_start()
                        self.server.scene.remove_by_name("/trajectories/current")
                        self.status.content = "Robot back at the start."
            except Exception as exc:  # keep serving whatever went wrong in one command
                self._notify(cmd.client_id, "Error", f"{type(exc).__name__}: {exc}", error=True)
            finally:
                self.plan_button.disabled = False
                self.reset_button.disabled = False
                self.drive_button.disabled = self.planned is None or not self.planned.found

    def _do_plan(self, cmd: PlanCmd) -> None:
        scene = self.world.scene
        start = self._marker_pose(self.start_control, scene.start)
        goal = self._marker_pose(self.goal_control, scene.goal)
        seed = self._next_seed
        self._next_seed += 1
        self.status.content = f"Planning with {scene.planner.name} (seed {seed}) ..."
        self._show_robot_at_start()
        for kind, payload in _run_in_child(_plan_worker, self.world, seed, start, goal):
            if kind == "error":
                self.planned = None
                self.status.content = f"Planning failed: {payload}"
                self._notify(cmd.client_id, "Planning failed", payload, error=True)
                return
            self.planned = payload
        self.planned_endpoints = (start, goal)
        assert self.planned is not None
        if not self.planned.found:
            self.status.content = f"No path: {self.planned.message}"
            self.server.scene.remove_by_name("/plans/current")
            return
        self.server.scene.add_line_segments(
            "/plans/current", _segments(self.planned.path_xyz + [0, 0, 0.005]),
            colors=(0, 0, 0), thickness=3.0, thickness_units="screen",
        )  # fmt: skip
        self.status.content = (
            f"Path found in {self.planned.plan_time:.2f} s (seed {seed}). Press **Drive**."
        )

    def _do_drive(self, cmd: DriveCmd) -> None:
        if self.planned is None or not self.planned.found:
            self._notify(cmd.client_id, "Nothing to drive", "Plan a path first.", error=True)
            return
        start, goal = self.planned_endpoints
        self.status.content = "Driving ..."
        traj: list[tuple[float, float, float]] = []
        t_wall0 = time.perf_counter()
        result: TrialResult | None = None
        for kind, payload in _run_in_child(_drive_worker, self.world, self.planned, start, goal):
            if kind == "frame":
                # Play back at real time: wait until the wall clock catches up with sim time.
                delay = payload.t - (time.perf_counter() - t_wall0)
                if delay > 0:
                    time.sleep(delay)
                self._show_frame(payload)
                traj.append(payload.p_world_body)
                if len(traj) >= 2 and len(traj) % 5 == 0:
                    self._draw_trajectory(traj)
            elif kind == "result":
                result = payload
            else:
                self.status.content = f"Drive failed: {payload}"
                self._notify(cmd.client_id, "Drive failed", payload, error=True)
                return
        assert result is not None
        if len(traj) >= 2:
            self._draw_trajectory(traj)
        self.trials.append(result)
        self.table.content = self._table_markdown()
        self.status.content = (
            f"Trial {len(self.trials)}: **{result.outcome}** ({result.reason}), "
            f"{result.drive_time:.1f} s, {result.energy:.3f} J "
            f"({result.relative_energy:.2f} x a straight walk on the floor)."
        )

    def _draw_trajectory(self, traj) -> None:
        self.server.scene.add_line_segments(
            "/trajectories/current", _segments(np.array(traj)),
            colors=(30, 90, 255), thickness=3.0, thickness_units="screen",
        )  # fmt: skip

    def stop(self) -> None:
        self._stop.set()
        self._loop.join(timeout=5)
        self.server.stop()


def serve(*, scene: str, host: str, port: int) -> None:
    """Build the world and serve the app until interrupted."""
    world = build_world(load_scene(scene))
    app = RoachApp(world, host=host, port=port)
    print(f"roachplan: serving scene {world.scene.name!r} at http://{host}:{app.port}", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        app.stop()


__all__ = ["RoachApp", "serve"]
