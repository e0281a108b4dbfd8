"""The app's command loop without a browser or a viser server: a fake page (the only thing that
cannot run here) and the real plan and drive jobs, in their child processes."""

from __future__ import annotations

import dataclasses
import inspect
import subprocess
import sys
import time
from pathlib import Path
from typing import cast

import pytest

from roachplan.app._app import App, Page, PlanSettings
from roachplan.app._commands import (
    CancelCmd,
    Cmd,
    DriveCmd,
    MarkersCmd,
    PlanCmd,
    ResetCmd,
)
from roachplan.app._loop import Command, CommandLoop
from roachplan.app._registry import COMMANDS


class FakeView:
    """The scene's drawing, as names."""

    def __init__(self) -> None:
        self.path_nodes: list = []
        self.drawn: list[str] = []

    def clear(self, root: str) -> None:
        self.drawn = [n for n in self.drawn if not n.startswith(root)]

    def add_path(self, points) -> None:
        self.path_nodes.append(points)

    def hide_paths(self) -> None:
        self.path_nodes = []

    def draw(self, name: str, points, colour, *, thickness: float = 3.0) -> None:
        self.drawn.append(name)


class FakeMarkers:
    """The markers at the scene's start and goal."""

    def __init__(self, world) -> None:
        self.world = world

    def valid_poses(self, world):
        return tuple(world.scene.start), tuple(world.scene.goal)


class FakeShell:
    """The loop's Shell without a browser: what the page was told, in order."""

    def __init__(self) -> None:
        self.statuses: list[str] = []
        self.notes: list[tuple[int | None, str, str, bool]] = []
        self.commands_done = 0

    def set_status(self, text: str) -> None:
        self.statuses.append(text)

    def notify(self, client_id, title: str, body: str, *, error: bool = False) -> None:
        self.notes.append((client_id, title, body, error))

    def public(self, text: str) -> str:
        return text

    def show_job(self, running: bool) -> None:
        pass

    def set_job_progress(self, percent: float) -> None:
        pass

    def between(self, *, idle: bool) -> None:
        pass

    def command_done(self) -> None:
        self.commands_done += 1


class FakePage(FakeShell):
    """The loop's Shell and the handlers' Page without a browser: what the page was told, in
    order, and the controls as a test sets them."""

    def __init__(self, world) -> None:
        super().__init__()
        self.view = FakeView()
        self.markers = FakeMarkers(world)
        self.settings = PlanSettings(planner=world.scene.planner.name, time_limit=20.0, count=1)
        self.speed = 10.0
        self.trials: list[dict] = []
        self.marker_checks = 0
        self.frames = 0

    # Page
    def plan_settings(self) -> PlanSettings:
        return self.settings

    def playback_speed(self) -> float:
        return self.speed

    def show_robot_at_start(self) -> None:
        pass

    def show_frame(self, frame) -> None:
        self.frames += 1

    def check_markers(self) -> bool:
        self.marker_checks += 1
        return True

    def list_plans(self, count: int) -> None:
        pass

    def show_plans(self, plans, selected: int, *, drawn: bool = False) -> None:
        pass

    def mark_drive_path(self, k: int) -> None:
        pass

    def show_results(self, trials: list[dict]) -> None:
        self.trials = list(trials)

    def show_engine(self, engine: str) -> None:
        pass

    # what the test reads
    def titles(self, client_id: int) -> list[str]:
        return [title for cid, title, _, _ in self.notes if cid == client_id]

    def said(self, prefix: str) -> int:
        """Index of the first status line starting with prefix (ValueError: none)."""
        return next(k for k, s in enumerate(self.statuses) if s.startswith(prefix))


@dataclasses.dataclass(frozen=True)
class BoomCmd(Cmd):
    """A command whose handler fails."""


@dataclasses.dataclass(frozen=True)
class UnlistedCmd(Cmd):
    """A command the registry does not list."""


def _boom(app: App, cmd: BoomCmd) -> None:
    raise RuntimeError("the handler broke")


def until(predicate, timeout: float, what: object) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, what
        time.sleep(0.01)


@pytest.fixture
def served(world, tmp_path):
    """(app, page, loop): the loop serving the registry's commands on double_bridge."""
    page = FakePage(world)
    loop = CommandLoop({**COMMANDS, BoomCmd: Command(handler=_boom, name="Boom")}, shell=page)
    # (The fake has what the commands run here touch, not the load, voxel and choose panels.)
    app = App(world, page=cast(Page, page), loop=loop, upload_dir=tmp_path)
    loop.start(app, setup=app.warm_up)
    yield app, page, loop
    loop.stop()
    app.close()


def _plan(page: FakePage, loop: CommandLoop, client_id: int = 1) -> None:
    loop.put(PlanCmd(client_id))
    until(lambda: any(s.startswith("Path found") for s in page.statuses), 60, page.statuses)


def test_commands_run_in_order_and_a_click_meanwhile_waits_its_turn(served):
    app, page, loop = served
    _plan(page, loop)
    assert len(app.plans) == 1 and app.next_seed == app.world.scene.seed + 1
    loop.put(DriveCmd(1))
    loop.put(ResetCmd(2))
    loop.put(PlanCmd(3))
    until(lambda: page.statuses.count("Robot back at the start.") == 1, 120, page.statuses)
    until(lambda: sum(s.startswith("Path found") for s in page.statuses) == 2, 60, page.statuses)
    until(lambda: page.commands_done == 4, 10, "every command done")

    # Drive ran to its end, then Reset, then the second Plan: one at a time, in order.
    drove = page.said("Trial 1: ")
    assert page.frames > 0 and len(page.trials) == 1 and page.trials[0]["label"] == ""
    assert drove < page.statuses.index("Robot back at the start.")
    assert page.statuses.index("Robot back at the start.") < max(
        k for k, s in enumerate(page.statuses) if s.startswith("Path found")
    )
    # Those clicked while Drive ran were told so, and the status line listed them.
    assert page.titles(2) == ["Reset queued"] and page.titles(3) == ["Plan queued"]
    assert any(s.startswith("Drive: ") and "Queued: Reset, Plan" in s for s in page.statuses)
    assert app.next_seed == app.world.scene.seed + 2


def test_cancel_kills_the_running_job_and_drops_what_waits(served):
    app, page, loop = served
    _plan(page, loop)
    page.speed = 1.0  # (real time: the drive outlasts the test's clicks)
    loop.put(DriveCmd(1))
    loop.put(ResetCmd(2))
    loop.put(MarkersCmd(3))  # (a drag: many re-checks, one run after the command)
    loop.put(MarkersCmd(3))
    until(lambda: loop.running == "Drive" and len(loop.waiting) == 2, 30, list(loop.waiting))
    until(lambda: page.frames > 0, 60, "the drive plays")
    job = loop.job
    assert job is not None
    pid = job.pid
    assert _alive(pid)
    loop.put(CancelCmd(4))
    until(lambda: any(s.startswith("Drive cancelled after") for s in page.statuses), 10, "")
    until(lambda: not _alive(pid), 10, f"the drive's child {pid} outlived Cancel")

    until(lambda: page.marker_checks == 1, 10, "the marker re-check ran once")
    assert page.titles(2) == ["Reset queued", "Reset not run"]
    assert "Robot back at the start." not in page.statuses
    assert page.trials == [] and loop.running is None and not loop.waiting
    # The loop goes on serving.
    loop.put(ResetCmd(2))
    until(lambda: "Robot back at the start." in page.statuses, 10, page.statuses)


def test_a_failing_command_is_a_notification_and_the_loop_goes_on(served):
    app, page, loop = served
    loop.put(BoomCmd(7))
    loop.put(UnlistedCmd(8))
    loop.put(ResetCmd(7))
    until(lambda: "Robot back at the start." in page.statuses, 30, page.statuses)
    # A handler's own exception text is not for the user: its kind is named, and the server
    # log has the rest (app/_said.py).
    internal = "an internal error (RuntimeError); the server log has the details"
    assert (7, "Boom failed", internal, True) in page.notes
    assert page.statuses[0] == f"Boom failed: {internal}"
    ((_, title, body, error),) = [n for n in page.notes if n[0] == 8]
    assert title == "UnlistedCmd failed" and error and "(TypeError)" in body
    assert page.commands_done == 3


def test_every_command_is_listed_with_a_handler_and_a_name():
    import roachplan.app._commands as commands

    classes = {
        c
        for c in vars(commands).values()
        if inspect.isclass(c) and issubclass(c, Cmd) and c is not Cmd
    }
    assert classes == set(COMMANDS), "each command class has one entry, and no other entry"
    names = [entry.name for entry in COMMANDS.values()]
    assert all(names) and len(set(names)) == len(names)
    for cls, entry in COMMANDS.items():
        assert dataclasses.is_dataclass(cls) and getattr(cls, "__dataclass_params__").frozen, cls
        assert len(inspect.signature(entry.handler).parameters) == 2, entry.handler
        assert callable(entry.while_busy) or entry.while_busy in ("run", "queue", "once")


def test_the_loop_and_the_handlers_interface_import_no_viser():
    code = (
        "import sys, roachplan.app._loop, roachplan.app._app, roachplan.app._registry; "
        "print('viser' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "False"


def _alive(pid: int) -> bool:
    """A process with this pid that is not only its exit status (a zombie)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
