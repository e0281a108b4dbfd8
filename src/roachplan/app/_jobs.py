"""The work that runs outside the server's process: each plan, drive and scene load in a fresh
child process (OMPL holds the GIL while it solves, and a fresh process is where its seed takes
effect), which the command loop follows without blocking and can kill at once (Cancel). The
processes are roachplan.processes' Child and Host; a job's progress is typed events (Attempt,
sim.Frame), its end an outcome (Returned, Raised, Died).

A scene load is a child of the fork server. A plan or a drive is a fork of the current world's
host (WorldHost): a child of the fork server that received the world once, when it was loaded,
and forks on request. Handing the world (0.7 MB pickled) to a new child on every click cost
0.33-0.38 s of the 0.5 s a Plan took in the server (issue 16).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar, cast

from roachplan.experiments import LabelledPlan, TrialResult, finish_trial, plan_many
from roachplan.perception import CaptureSettings, Reconstruction, mesh_capture
from roachplan.processes import (
    CHANNEL,
    Channel,
    Child,
    Died,
    Host,
    Raised,
    Returned,
    preload,
)
from roachplan.scenes import World, build_world, load_scene, with_engine

from ._relevel import CaptureView
from ._said import INTERNAL_LEAD, log_internal, raised_text

# -- work in child processes --------------------------------------------------------------------

preload("roachplan.experiments._trial")

T = TypeVar("T")


@dataclass(frozen=True, kw_only=True)
class Attempt:
    """A plan job's event: one try of plan_many done."""

    seed: int
    """The seed it planned with."""
    plan: LabelledPlan | None
    """The new distinct path it found, None if it found none (or one too like another)."""


def _plan_job(events: Channel, world: World, count: int, request: dict, deadline: float) -> None:
    """Plan up to count distinct paths, an Attempt event per try. request: plan_many's keyword
    arguments (seed, start, goal, planner); deadline: the end of the whole plan's budget on
    time.monotonic() (CLOCK_MONOTONIC is one clock for every process on Linux, so the budget
    counts from the click, not from this child's start)."""
    plan_many(
        world,
        count,
        **request,
        budget=max(0.0, deadline - time.monotonic()),
        on_attempt=lambda seed, lp: events.send(Attempt(seed=seed, plan=lp)),
    )


def _drive_job(events: Channel, world: World, planned, start, goal) -> TrialResult:
    """Drive the plan, each sim.Frame an event as it is simulated; the trial's result."""
    return finish_trial(world, planned, start=start, goal=goal, on_frame=events.send)


def _load_job(events: Channel, ref: str, from_upload: bool) -> tuple[World, CaptureView | None]:
    """load_world in a child (under only a soft memory limit, _JOBS: the OpenSCAD it may start
    sets its own, possibly higher, limit, which an inherited hard limit would forbid)."""
    return load_world(ref, from_upload=from_upload)


def _warm_job(events: Channel) -> None:
    pass


def load_outcome(job: Job) -> tuple[tuple[World, CaptureView | None] | None, str | None]:
    """(the (World, CaptureView | None) a finished load job returned, why it failed): one of
    them is None. A capture that needs more memory than a load may have ends in what to change
    in the page, not by taking the machine (issue 15)."""
    outcome = job.outcome
    if isinstance(outcome, Returned):  # (what _load_job returned)
        return cast("tuple[World, CaptureView | None]", outcome.value), None
    if isinstance(outcome, Died) and outcome.cause == "memory":
        return None, (
            f"loading this file needed more memory than the server allows a "
            f"load ({job.memory / 2**30:.1f} GiB): set a larger Meshing "
            f"(captures) → Voxel [m], or tick Meshing (captures) → Crop and "
            f"set its box, and load it again"
        )
    return None, failure(job) or "the loading process ended without a result"


def failure(job: Child) -> str | None:
    """Why a finished job failed, in the page's words: its error's message when that is written
    for the user, else that an internal error happened (its traceback to the server's log:
    app/_said.py), or how its process died; None when it returned (or has not ended, or was
    cancelled: what cancelled it says so)."""
    outcome = job.outcome
    if isinstance(outcome, Raised):
        text = raised_text(outcome.error, outcome.message, outcome.traceback)
        if text.startswith(INTERNAL_LEAD):
            log_internal(outcome.error, outcome.traceback, where=f"the {job.task} process")
        return text
    if isinstance(outcome, Died) and outcome.cause != "cancelled":
        return outcome.why
    return None


_JOBS = {
    _plan_job: ("planning", True),
    _drive_job: ("driving", True),
    _load_job: ("loading", False),
}
"""Job target -> (what its process is called in messages: "the planning process ran out of
memory ...", whether its memory limit is also the hard limit). Other targets: ("job", True)."""


class Job(Child[T]):
    """target(events, *args) in a fresh child of the fork server (roachplan.processes.Child),
    under the child memory limit; with host, target(events, host's world, *args) in a fork of
    that WorldHost instead. events: the child's Channel (send(event)); what target sends
    arrives in order (poll), then its outcome (`outcome`; `failure`). `cancel` kills it and
    whatever it started, at once."""

    def __init__(self, target: Callable[..., T], *args, host: WorldHost | None = None) -> None:
        task, hard_memory = _JOBS.get(target, ("job", True))
        if host is None:
            super().__init__(
                target, (CHANNEL, *args), start="forkserver", hard_memory=hard_memory, task=task
            )
        else:
            super().__init__(
                _in_world, (target, args), start=host, hard_memory=hard_memory, task=task
            )
        self._host = host


def _in_world(world: World, target, args: tuple):
    """A fork of a WorldHost: target(events, the host's world, *args)."""
    return target(CHANNEL, world, *args)


class WorldHost(Host[World]):
    """A long-lived child of the fork server holding one world, which forks a fresh child of
    itself for each job on that world (Job(..., host=)): a job starts in a few milliseconds, where a
    child of the fork server first has to receive the world (roachplan.processes.Host)."""

    def __init__(self, world: World) -> None:
        super().__init__(world, name="roachplan-world-host")

    @property
    def world(self) -> World:
        return self.value


def run_to_end(target, *args) -> list[object]:
    """Every event of a job, once it has finished (for quick jobs)."""
    job, out = Job(target, *args), []
    while not job.done:
        out += job.poll(timeout=1.0)
    return out


# -- loading a scene ------------------------------------------------------------------------------


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


def with_page_engine(world: World, engine: str | None) -> World:
    """world simulated by the page's physics engine (None: its scene's own), as calibrated
    (scenes.with_engine); what the world computed is kept."""
    if engine is None or engine == world.scene.sim.engine:
        return world
    scene = with_engine(world.scene, engine)
    return world.with_sim(scene.sim, scene.driver)


def load_world(
    ref: str, *, from_upload: bool, check_poses: bool = False
) -> tuple[World, CaptureView | None]:
    """The world of a scene (a library name, a scene file, a terrain file), with its standable
    regions computed, and the view of its capture when it is one. from_upload: a scene file
    the app wrote (prepare_upload_scene picks what it leaves out and writes it back).
    check_poses: SceneError when its start or goal is not a place to stand (else the page
    shows the markers red, with why)."""
    from ._uploads import prepare_upload_scene

    # scenes keeps only a capture's mesh; the page also shows the camera and ground that
    # meshing found, and meshing again for them would double every capture load.
    made: list[tuple[Path, CaptureSettings, Reconstruction]] = []

    def record(source: Path, settings: CaptureSettings, rec: Reconstruction) -> None:
        made.append((source, settings, rec))

    if from_upload:
        world = prepare_upload_scene(Path(ref), on_capture=record)
    else:
        world = build_world(load_scene(ref), check_poses=check_poses, on_capture=record)
    world.regions  # noqa: B018 - computed here, once, and sent along
    return world, capture_view(world.scene, made)
