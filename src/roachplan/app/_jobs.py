"""The work that runs outside the server's process: each plan, drive and scene load in a fresh
child process (OMPL holds the GIL while it solves, and a fresh process is where its seed takes
effect), which the command loop follows without blocking and can kill at once (Cancel).

A scene load is a child of the fork server. A plan or a drive is a fork of the current world's
host (WorldHost): a child of the fork server that received the world once, when it was loaded,
and forks on request. Handing the world (0.7 MB pickled) to a new child on every click cost
0.33-0.38 s of the 0.5 s a Plan took in the server (issue 16).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading
import time
import traceback
from contextlib import contextmanager
from multiprocessing import reduction
from multiprocessing.connection import Connection, wait
from pathlib import Path

from roachplan.experiments import finish_trial, plan_many
from roachplan.perception import mesh_capture
from roachplan.planning._isolated import limit_child_memory
from roachplan.scenes import World, build_world, load_scene

from ._relevel import CaptureView

# -- work in child processes --------------------------------------------------------------------

_CTX = mp.get_context("forkserver")
_CTX.set_forkserver_preload(["roachplan.experiments._trial"])


def _plan_job(conn, world: World, count: int, request: dict, deadline: float) -> None:
    """request: plan_many's keyword arguments (seed, start, goal, planner); deadline: the end of
    the whole plan's budget on time.monotonic() (CLOCK_MONOTONIC is one clock for every process
    on Linux, so the budget counts from the click, not from this child's start)."""
    limit_child_memory()  # a runaway plan ends in a notification, not by taking the machine
    try:
        plan_many(
            world,
            count,
            **request,
            budget=max(0.0, deadline - time.monotonic()),
            on_attempt=lambda seed, lp: conn.send(("attempt", (seed, lp))),
        )
        conn.send(("done", None))
    except Exception as exc:  # reported to the user as a notification
        conn.send(("error", f"{exc}"))
    conn.close()


def _drive_job(conn, world: World, planned, start, goal) -> None:
    limit_child_memory()
    try:
        result = finish_trial(
            world, planned, start=start, goal=goal, on_frame=lambda f: conn.send(("frame", f))
        )
        conn.send(("result", result))
    except Exception as exc:
        conn.send(("error", f"{exc}"))
    conn.close()


def _load_job(conn, ref: str, from_upload: bool) -> None:
    # Only the soft limit: the OpenSCAD it may start sets its own, possibly higher, limit,
    # which an inherited hard limit would forbid. A capture that needs more than this process
    # may have ends in a notification, not by taking the machine (issue 15).
    limit = limit_child_memory(hard=False)
    try:
        conn.send(("world", load_world(ref, from_upload=from_upload)))
    except MemoryError:
        conn.send(
            (
                "error",
                f"loading this file needed more memory than the server allows a "
                f"load ({limit / 2**30:.1f} GiB): set a larger Meshing "
                f"(captures) → Voxel [m], or tick Meshing (captures) → Crop and "
                f"set its box, and load it again",
            )
        )
    except Exception as exc:
        conn.send(("error", f"{exc}"))
    conn.close()


def _warm_job(conn) -> None:
    conn.close()


class Job:
    """target(conn, *args) in a fresh child process: what it has sent so far, without blocking;
    `cancel` kills it (and whatever it started) at once. With host, target(conn, host's world,
    *args) in a fork of that WorldHost instead."""

    def __init__(self, target, *args, host: WorldHost | None = None) -> None:
        self.started = time.monotonic()
        self._conn, child = _CTX.Pipe(duplex=False)
        self._host, self._proc, self._born = host, None, None
        try:
            if host is None:
                self._proc = _CTX.Process(target=target, args=(child, *args), daemon=True)
                self._proc.start()
                self.pid = self._proc.pid
            else:
                self.pid = host.fork(target, args, child)
                self._born = _start_time(self.pid)
        finally:
            child.close()  # (the child holds the only writer: its exit is this end's EOF)
        self.done = False
        """The child has closed its end (finished, failed or killed)."""

    @property
    def elapsed(self) -> float:
        """Wall time since the job started [s]."""
        return time.monotonic() - self.started

    def poll(self, timeout: float = 0.0) -> list[tuple[str, object]]:
        """The messages sent since the last poll, waiting up to timeout [s] for the first."""
        out: list[tuple[str, object]] = []
        if self.done:
            time.sleep(timeout)  # (the caller's pace, as when waiting for a message)
            return out
        if not wait([self._conn], timeout):
            return out
        while not self.done and self._conn.poll():
            try:
                out.append(self._conn.recv())
            except (EOFError, OSError):
                self.done = True
                if self._proc is not None:
                    self._proc.join(timeout=5)
        return out

    def _running(self) -> bool:
        """The child has not exited (an exited child's pid may soon belong to another)."""
        if self._proc is not None:
            return self._proc.exitcode is None
        # A fork of a host: the same pid and start time (it outlives a host closed meanwhile,
        # a new scene loaded while it ran, and is then a child of init's).
        return self._born is not None and _start_time(self.pid) == self._born

    def cancel(self) -> None:
        """Kill the child and every process under it, now."""
        if self.done:
            return
        if self._running():
            kill_tree(self.pid)
        self.done = True
        self._conn.close()
        if self._proc is not None:
            self._proc.join(timeout=5)


def _host_main(conn, world: World) -> None:
    """A WorldHost's process: for each (target, args) and writable end received, fork a child
    that runs target(end, world, *args), and answer its pid. It never plans or draws a random
    number itself, so each child starts from OMPL's clean state (planning/_isolated.py), and
    it has one thread, so a bare fork is safe."""
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # (the kernel reaps the children)
    while True:
        try:
            target, args = conn.recv()
            fd = reduction.recv_handle(conn)
        except (EOFError, OSError):  # the server closed its end or died: so does the host
            return
        pid = os.fork()
        if pid == 0:  # the child: never returns into the loop
            status = 1
            try:
                signal.signal(signal.SIGCHLD, signal.SIG_DFL)  # (it waits for its own children)
                conn.close()
                target(Connection(fd, readable=False), world, *args)
                status = 0
            except BaseException:  # (as a Process would show it: the server's log)
                traceback.print_exc()
            finally:
                sys.stdout.flush()  # (os._exit flushes nothing)
                sys.stderr.flush()
                os._exit(status)
        os.close(fd)
        conn.send(pid)


class WorldHost:
    """A long-lived child of the fork server holding one world, which forks a fresh child of
    itself for each job on that world (Job(..., host=)): a job starts in a few milliseconds, where a
    child of the fork server first has to receive the world."""

    def __init__(self, world: World) -> None:
        self.world = world
        self._conn, child = _CTX.Pipe(duplex=True)  # (a socket pair: it can carry an fd)
        self._proc = _CTX.Process(
            target=_host_main, args=(child, world), daemon=True, name="roachplan-world-host"
        )
        self._proc.start()
        child.close()
        self._lock = threading.Lock()

    @property
    def alive(self) -> bool:
        return self._proc.exitcode is None and not self._conn.closed

    def fork(self, target, args: tuple, end) -> int:
        """Start target(end, world, *args) in a fork of the host; its pid."""
        with self._lock:
            self._conn.send((target, args))
            reduction.send_handle(self._conn, end.fileno(), self._proc.pid)
            return self._conn.recv()

    def is_parent_of(self, pid: int) -> bool:
        try:
            return _parent(Path(f"/proc/{pid}/stat").read_text()) == self._proc.pid
        except OSError:
            return False

    def close(self) -> None:
        """End the host (the jobs it started run on until they finish or are cancelled)."""
        if not self._lock.acquire(timeout=2):  # (a fork request stuck mid-way: end it hard)
            self._proc.kill()
            self._lock.acquire()
        try:
            if not self._conn.closed:
                self._conn.close()  # (its recv ends: it returns)
        finally:
            self._lock.release()
        self._proc.join(timeout=1)
        if self._proc.exitcode is None:
            self._proc.kill()
            self._proc.join(timeout=5)


def run_to_end(target, *args) -> list[tuple[str, object]]:
    """Every message of a job, once it has finished (for quick jobs)."""
    job, out = Job(target, *args), []
    while not job.done:
        out += job.poll(timeout=1.0)
    return out


def _start_time(pid: int) -> int | None:
    """When the process started (clock ticks since boot), None if there is no such process:
    with the pid, it names one process even after the pid is reused."""
    try:
        return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return None


def _parent(stat: str) -> int:
    """The parent pid in the text of /proc/PID/stat."""
    return int(stat.rsplit(")", 1)[1].split()[1])  # (the name may hold spaces)


def _children() -> dict[int, list[int]]:
    """Parent pid -> child pids of every process visible in /proc."""
    out: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                stat = Path(entry.path, "stat").read_text()
            except OSError:
                continue
            out.setdefault(_parent(stat), []).append(int(entry.name))
    return out


def kill_tree(pid: int) -> None:
    """SIGKILL a process and all its descendants. Not a process group: OpenSCAD runs in a
    session of its own (so its time limit can kill it whole), which a group kill would miss.
    The root is stopped first so that it starts nothing new while the tree is read."""
    try:
        os.kill(pid, signal.SIGSTOP)
    except ProcessLookupError:
        return
    children, tree, todo = _children(), [], [pid]
    while todo:
        kids = children.get(todo.pop(), [])
        tree += kids
        todo += kids
    for p in (pid, *tree):
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass


# -- loading a scene ------------------------------------------------------------------------------


@contextmanager
def _recording_reconstructions():
    """The capture reconstructions made while a world is built, as (source, settings, rec).
    scenes meshes a capture through perception.mesh_capture and keeps only the mesh; the page
    also shows the camera and ground that meshing found, and meshing again for them doubled
    every capture load. scenes has no hook to hand the reconstruction out, so its module's
    reference is wrapped for the duration (in a load's own process)."""
    import roachplan.scenes._world as world_module

    made: list = []
    original = getattr(world_module, "mesh_capture", None)
    if original is None:  # scenes changed how it meshes: capture_view meshes once more
        yield made
        return

    def recording(source, settings):
        rec = original(source, settings)
        made.append((Path(source), settings, rec))
        return rec

    world_module.mesh_capture = recording
    try:
        yield made
    finally:
        world_module.mesh_capture = original


def capture_view(scene, made=()) -> CaptureView | None:
    """The reconstruction of a scene's one capture object (its camera pose and report, to show
    and re-level it), or None for other scenes; taken from `made` when it was recorded."""
    captures = [o for o in scene.terrain if o.kind == "capture"]
    if len(captures) != 1 or len(scene.terrain) != 1:
        return None
    obj = captures[0]
    rec = next(
        (r for src, cfg, r in made if src == Path(obj.source) and cfg == obj.capture), None
    ) or mesh_capture(obj.source, obj.capture)
    return CaptureView(
        scene_path=Path(scene.path), world_from_camera=rec.world_from_camera, report=rec.report()
    )


def load_world(
    ref: str, *, from_upload: bool, check_poses: bool = False
) -> tuple[World, CaptureView | None]:
    """The world of a scene (a library name, a scene file, a terrain file), with its standable
    regions computed, and the view of its capture when it is one. from_upload: a scene file
    the app wrote (prepare_upload_scene picks what it leaves out and writes it back).
    check_poses: SceneError when its start or goal is not a place to stand (else the page
    shows the markers red, with why)."""
    from ._uploads import prepare_upload_scene

    with _recording_reconstructions() as made:
        if from_upload:
            world = prepare_upload_scene(Path(ref))
        else:
            world = build_world(load_scene(ref), check_poses=check_poses)
    world.regions  # noqa: B018 - computed here, once, and sent along
    return world, capture_view(world.scene, made)
