"""No result without a run, and messages a person can act on.

A world whose start and goal nobody could pick (build_world leaves both at one placeholder
point) is never "valid": Plan refuses it in a sentence, Drive stays disabled, and no trial row is
written; a success with no path or no drive is never recorded. Errors are sentences for the
user: an unexpected exception is named, not shown. A notification too long for viser's box
shows its lead and the whole of it stays under the status line; every control a message names
is named as the page labels it. A click lands on the first surface along its ray; a dragged
marker is put down on the surface; a new scene clears the last one's drawings. The outdoor
lidar patch the user loaded (../shared/testdata/real/terrain_samp11-utm.pcd) in headless
Chromium. Screenshots go to test-artifacts/.
"""

from __future__ import annotations

import ast
import dataclasses
import re
import time
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pytest

from conftest import ROOT, free_port
from test_app import CHROMIUM, browser_pages, upload
from test_perception import REAL

if TYPE_CHECKING:
    from roachplan.app._app import App, Page
    from roachplan.app._jobs import Child
    from roachplan.app._loop import CommandLoop

SAMP11 = REAL / "terrain_samp11-utm.pcd"
NOT_PICKED = (
    "could not pick a start and goal the planner joins in the largest standable region "
    "(2.80 m^2): 1.84 m apart: prm found no path within its time limit; give start and goal"
)
"""build_world's note when the pick failed (as samp11's load says it)."""


def _until(done, timeout: float, what) -> None:
    end = time.monotonic() + timeout
    while not done():
        assert time.monotonic() < end, what() if callable(what) else what
        time.sleep(0.05)


# -- errors are sentences -------------------------------------------------------------------------


def test_an_unexpected_error_is_named_and_a_users_error_said_as_it_is():
    from roachplan.app._jobs import failure
    from roachplan.app._said import INTERNAL_LEAD, error_text, raised_text
    from roachplan.planning import PlanningError
    from roachplan.processes import Raised
    from roachplan.scenes import SceneError

    text = error_text(IndexError("index 0 is out of bounds for axis 0 with size 0"))
    assert text.startswith(INTERNAL_LEAD) and "(IndexError)" in text and "index 0" not in text
    assert error_text(SceneError("x.yaml: bounds: too large")) == "x.yaml: bounds: too large"
    assert error_text(ConnectionRefusedError(111, "Connection refused")) == "connection refused"
    # From a child: its exception, or (not pickled) its traceback's last line, names it.
    assert raised_text(None, "size 0", "Traceback ...\nIndexError: size 0").startswith(
        INTERNAL_LEAD
    )
    said = raised_text(None, "no path", "Traceback ...\nroachplan.PlanningError: no path")
    assert said == "no path"
    # A stand-in for a finished job: failure reads only its outcome and task.
    job = cast("Child[Any]", SimpleNamespace(outcome=Raised.of(KeyError("route")), task="planning"))
    said = failure(job)
    assert said is not None and "(KeyError)" in said and "route" not in said, said
    job = cast(
        "Child[Any]",
        SimpleNamespace(outcome=Raised.of(PlanningError("start invalid")), task="planning"),
    )
    assert failure(job) == "start invalid"


def test_a_handler_that_breaks_says_which_command_failed_and_logs_the_traceback(capfd):
    from roachplan.app._commands import Cmd
    from roachplan.app._loop import Command, CommandLoop

    @dataclasses.dataclass(frozen=True)
    class _BrokenCmd(Cmd):
        pass

    def broken(app, cmd) -> None:
        np.zeros(0)[0]  # the user's IndexError: "index 0 is out of bounds ..."

    from test_loop import FakeShell

    shell = FakeShell()
    loop = CommandLoop({_BrokenCmd: Command(handler=broken, name="Plan")}, shell=shell)
    loop.start(cast("App", SimpleNamespace()))  # (a stand-in: the handler never uses its app)
    try:
        loop.put(_BrokenCmd(4))
        _until(lambda: shell.statuses, 10, "the command did not run")
    finally:
        loop.stop()
    ((client, title, body, error),) = shell.notes
    assert (client, title, error) == (4, "Plan failed", True)
    assert body.startswith("an internal error (IndexError)") and "out of bounds" not in body
    assert shell.statuses == [f"Plan failed: {body}"]
    assert "IndexError: index 0 is out of bounds" in capfd.readouterr().err


# -- no result without a run ------------------------------------------------------------------


def test_a_success_without_a_path_or_a_drive_is_never_recorded(world, tmp_path):
    from roachplan.app._app import App, unrecordable

    shown: list[str] = []
    # Stand-ins: record touches only the page's status line and results table, and no loop.
    page = cast("Page", SimpleNamespace(set_status=shown.append, show_results=lambda trials: None))
    app = App(world, page=page, loop=cast("CommandLoop", None), upload_dir=tmp_path)
    path = [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]]
    good = dict(outcome="success", reason="reached the goal", drive_time=3.2, energy=0.4)
    good |= dict(relative_energy=1.1, path=path)
    one_point = good | dict(path=[[0.0, 0.0, 0.0]], drive_time=0.0, energy=0.0)
    no_drive = good | dict(drive_time=0.0)
    no_path = dict(good, outcome="no_path", reason="no path found", path=[], drive_time=0.0)
    assert unrecordable(good) is None and unrecordable(no_path) is None
    why_one_point, why_no_drive = unrecordable(one_point), unrecordable(no_drive)
    assert why_one_point is not None and "no path" in why_one_point, why_one_point
    assert why_no_drive is not None and "0 s" in why_no_drive, why_no_drive
    assert not app.record(one_point, "") and not app.record(no_drive, "batch")
    assert app.scene_trials == [] and shown[-1].startswith("No trial recorded: ")
    assert app.record(no_path, "batch") and app.record(good, "")  # (a real failure is kept)
    assert [t["outcome"] for t in app.scene_trials] == ["no_path", "success"]


def _not_picked(world):
    """world as build_world leaves one whose start and goal could not be picked: both at one
    point (here one where the robot can stand: the case the user met) and the reason last in
    its notes."""
    p = world.scene.start
    scene = dataclasses.replace(world.scene, start=p, goal=p)
    return dataclasses.replace(world, scene=scene, notes=(*world.notes, NOT_PICKED))


def test_start_and_goal_nobody_picked_are_never_valid_and_nothing_is_driven(world):
    from roachplan.app._commands import DriveCmd, PlanCmd, RunTrialsCmd
    from roachplan.app._markers import pick_failure
    from roachplan.app._server import RoachApp
    from roachplan.scenes import pose_problem

    placeholder = _not_picked(world)
    assert pick_failure(placeholder) == NOT_PICKED
    assert pose_problem(placeholder, placeholder.scene.start) == ""  # (each alone stands)
    app = RoachApp(placeholder, host="127.0.0.1", port=free_port())
    try:
        said = app.markers.validity.content
        assert "valid." not in said and "Start and goal were not picked" in said, said
        assert "one place" in said and "Start and goal → Click places" in said, said
        assert app.drive_button.disabled
        app.commands.put(PlanCmd(None))
        _until(lambda: app.status.content.startswith("Plan failed"), 60, app.status.content)
        status = app.status.content
        assert "Start and goal were not picked" in status and "index" not in status, status
        app.commands.put(DriveCmd(None))
        _until(lambda: "no planned path" in app.status.content, 30, app.status.content)
        app.commands.put(RunTrialsCmd(None))
        _until(lambda: app.status.content.startswith("Run trials failed"), 30, app.status.content)
        time.sleep(0.5)
        assert app.batch is None and app.scene_trials == [] and not app.plans
        assert app.drive_button.disabled
        assert "Trial 1" not in app.table.content
    finally:
        app.stop()


# -- where a click lands, where a dragged marker stands ---------------------------------------


def test_a_click_lands_on_the_first_surface_along_its_ray():
    """A slab 0.5 m over the floor (a table top: the height field keeps the floor under it,
    OVERHEAD) and a wall behind: a ray aimed at the slab's top lands on the slab, where the
    height field alone let it pass over and hit the wall; a ray at the floor lands there."""
    import trimesh

    from roachplan.app._picking import click_point, ray_hit_heightfield
    from roachplan.planning import heightfield_from_mesh

    floor = trimesh.creation.box((4.0, 4.0, 0.1), transform=_at(0.0, 0.0, -0.05))
    slab = trimesh.creation.box((0.6, 0.6, 0.05), transform=_at(0.0, 0.0, 0.5))
    wall = trimesh.creation.box((0.2, 4.0, 1.5), transform=_at(1.2, 0.0, 0.75))
    mesh = trimesh.util.concatenate([floor, slab, wall])
    assert isinstance(mesh, trimesh.Trimesh)
    hf = heightfield_from_mesh(
        mesh.vertices,
        mesh.faces,
        xy_min=(-2.0, -2.0),
        xy_max=(2.0, 2.0),
        resolution=0.01,
        ground_height=None,
        overhead=0.3,
    )
    camera = np.array([-2.5, 0.0, 2.0])
    at_slab = np.array([0.1, 0.0, 0.525]) - camera
    old = ray_hit_heightfield(hf, camera, at_slab)
    assert old is not None and old[0] > 0.5  # (the height field's own: behind the slab)
    hit = click_point(mesh.vertices, mesh.faces, hf, camera, at_slab)
    assert hit is not None and abs(hit[0] - 0.1) < 0.02 and abs(hit[1]) < 0.01, hit
    at_floor = np.array([-1.0, 0.5, 0.0]) - camera
    hit = click_point(mesh.vertices, mesh.faces, hf, camera, at_floor)
    assert hit is not None and np.allclose(hit, (-1.0, 0.5, 0.0), atol=0.01), hit
    # The ground plane as drawn (a scene's `ground`) is a surface too; nothing drawn: missed.
    up = np.array([0.0, 0.0, 1.0])
    assert click_point(mesh.vertices, mesh.faces, hf, camera, up) is None
    ground = (-0.2, (0.0, 0.0), (5.0, 5.0))
    beyond = np.array([-4.5, 0.0, -0.2]) - camera  # (past the floor box, on the plane)
    hit = click_point(mesh.vertices, mesh.faces, hf, camera, beyond, ground=ground)
    assert hit is not None and np.allclose(hit, (-4.5, 0.0, -0.2), atol=1e-6), hit


def _at(x: float, y: float, z: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def test_a_dragged_marker_is_put_down_on_the_surface_when_the_drag_ends(app):
    """A drag moves a marker in the level plane of its height: over lower ground it floats,
    and the place it stands on shows behind it. At the drag's end it is put down there."""
    from roachplan.app._commands import MarkersCmd
    from roachplan.app._draw import on_surface

    goal = app.controls["goal"]
    x, y, z = (float(v) for v in goal.position)
    goal.position = (x - 0.05, y, z + 0.4)  # (dragged, in the plane 0.4 m up)
    app.commands.put(MarkersCmd(None))  # (a drag's update: left where the drag has it)
    app.commands.put(MarkersCmd(None, settled=True))
    ground = on_surface(app.world, (x - 0.05, y, 0.0))[2]
    _until(lambda: abs(float(app.controls["goal"].position[2]) - ground) < 1e-6, 30, "floats")
    assert np.allclose(app.controls["goal"].position[:2], (x - 0.05, y))


def test_a_new_scene_clears_the_last_ones_drawings(app):
    """The robot's live track, trajectories, paths: none of the last scene's stays drawn."""
    from roachplan.app._commands import LoadSceneCmd
    from roachplan.app._draw import BLACK, BLUE, LIVE

    line = np.array([[0.0, 0.0, 0.1], [0.3, 0.2, 0.1], [0.6, 0.2, 0.1]])
    app.view.draw("/live/track", line, LIVE)
    app.view.draw("/trajectories/current", line, BLUE)
    app.view.draw("/plans/shown", line, BLACK)
    before = app.world
    app.commands.put(LoadSceneCmd(None, "flat"))
    _until(
        lambda: app.world is not before and app.status.content.startswith("Loaded"),
        180,
        lambda: app.status.content,
    )
    drawn = set(app.server.scene._handle_from_node_name)
    left = {n for n in drawn if n.startswith(("/live", "/trajectories/", "/plans/"))}
    assert not left, left


# -- messages a person can act on -------------------------------------------------------------


def test_a_long_notification_shows_its_lead_and_says_where_the_rest_is():
    from roachplan.app._said import NOTE_MORE, fits_a_note, note_body, note_lines

    assert note_lines("") == 1 and note_lines("a " * 13) == 1 and note_lines("a " * 14) == 2
    assert note_lines("x" * 60) == 3  # (a word longer than a line breaks anywhere)
    short = "It runs when Plan ends; Cancel (at the top) stops Plan and drops what is queued."
    assert note_body("Drive queued", short) == (short, False)
    title = "Loaded upload: terrain_samp11-utm.pcd: start and goal not picked"
    whole = f"{NOT_PICKED}; place them yourself: set Start and goal → Click places to start"
    shown, cut = note_body(title, whole)
    assert cut and shown.endswith(NOTE_MORE) and fits_a_note(title, shown), shown
    assert whole.startswith(shown.removesuffix(NOTE_MORE).rstrip("…"))


BOLD = re.compile(r"(?<![\w*`])\*\*([A-Za-z][^*`{}\n]*?)\*\*")
ITALIC = re.compile(r"(?<![\w*\\])\*([A-Z][^*`{}\n]{0,40}?)\*(?![\w*])")
PRESS = re.compile(r"\bpress (?:the )?(\*\*)?")
AFTER_A_NAME = re.compile(
    r"(?:\*\*)?(?:$|\s*[.,;:)(—]|\s+(?:to|and|or|again|first|then|once|when|at|on|for|"
    r"with|below|above|there|here|in the|\(|—)\b)"
)
"""What may follow a control's name in "press NAME ...": the end of the sentence or clause,
or a word that starts another (not "press Plan in this area", naming a button "Plan in this
area")."""
HEADINGS = {
    "Trials",
    "Summary per route",
    "Ranking",
    "Guarantee",
    "chosen",
    "roachplan",
    "Pending calibration",
    "Start and goal were not picked",
    "start and goal are one place",
    "Enter",  # (the command line's `robot` waits for the Enter key)
}
"""Bold or italic words in the app's messages that name no control: headings and leads."""


TERMINAL = {"cli.py", "_parser.py", "_flags.py"} | {
    p.name for p in (ROOT / "src" / "roachplan" / "app").glob("*_cli.py")
}
"""The command line's modules: their messages are read in a terminal, not in the page."""


def app_messages() -> list[tuple[str, str]]:
    """(where, text) of every string literal in the page's modules of app/ (f-strings whole,
    their fields as a number), docstrings and comments left out."""
    from test_page_advice import _render, message_literals

    found = []
    for path in sorted((ROOT / "src" / "roachplan" / "app").glob("*.py")):
        if path.name in TERMINAL:
            continue
        for n in message_literals(ast.parse(path.read_text())):
            found.append((f"{path.name}:{n.lineno}", _render(n, {})))
    return found


def names_in(text: str, labels: set[str]) -> list[tuple[str, bool]]:
    """(name, whether the page has it) of every control a message names: in bold or italics,
    after "press", or as "Folder → Control" (test_page_advice.named_controls)."""
    out = []
    for m in (*BOLD.finditer(text), *ITALIC.finditer(text)):
        name = m.group(1).strip()
        if "12" in name:  # (a value filled in: "**12 invalid**", "**12**")
            continue
        out.append((name, name in labels or name in HEADINGS or "→" in name))
    for m in PRESS.finditer(text):
        after = text[m.end() :]
        after = re.sub(r"^[\w ()]+? → ", "", after)  # (a folder named first)
        fits = [
            lb for lb in labels if after.startswith(lb) and AFTER_A_NAME.match(after[len(lb) :])
        ]
        out.append((after[:40], bool(fits)))
    return out


def test_every_control_a_message_names_is_one_the_page_has(app):
    """Bold and italic names, "press NAME" and "Folder → Control" in every message of the
    page's modules (its advice for the command line's words, app/_uploads.py PAGE_ADVICE,
    included) name a control, a folder or a heading of the page as it is labelled."""
    from test_page_advice import named_controls, page_controls

    pairs = page_controls(app)
    labels = {c for _, c in pairs} | {f for f, _ in pairs if f}
    wrong = []
    for where, text in app_messages():
        wrong += [f"{where}: {name!r}" for name, ok in names_in(text, labels) if not ok]
        if " → " in text and not where.startswith("_uploads.py"):  # (PAGE_ADVICE: its own test)
            try:
                named_controls(text, pairs)
            except AssertionError as exc:
                wrong.append(f"{where}: {exc}")
    assert not wrong, "\n".join(wrong)


def test_the_name_check_finds_a_button_the_page_does_not_have():
    labels = {"Plan", "Reload with this area", "Planning area", "Drive path"}
    assert names_in("then press Plan in this area", labels) == [("Plan in this area", False)]
    assert names_in("press Planning area → Reload with this area.", labels)[0][1]
    assert all(ok for _, ok in names_in("press **Plan**, then *Drive path*", labels))
    assert not names_in("press **Go to goal**", labels)[0][1]


# -- the user's lidar patch, in the page ------------------------------------------------------


def said_whole(note) -> str:
    """What a notification (a located .mantine-Notification-root, shown) says, whole: its own
    text (title and body, a line apart), or, where it was too long for its box and says where
    the rest is, its title and the body the message under the status line holds whole
    ("**title**: body")."""
    from roachplan.app._said import NOTE_MORE

    text = note.inner_text()
    if NOTE_MORE.strip(" ()") not in text:
        return text
    title = note.locator(".mantine-Notification-title").inner_text().strip()
    whole = note.page.locator("p").filter(has_text=re.compile("^" + re.escape(title) + ": "))
    whole.first.wait_for(timeout=10_000)
    return f"{title}\n{whole.first.inner_text().strip().removeprefix(title + ': ')}"


def _description_cut(page) -> list[str]:
    """The notifications shown cut (their text taller than their box), by title, once those
    sliding in have settled (within 5 s: a cut one stays cut)."""
    end = time.monotonic() + 5.0
    while (cut := _cut_now(page)) and time.monotonic() < end:
        page.wait_for_timeout(200)
    return cut


def _cut_now(page) -> list[str]:
    return page.evaluate(
        """() => [...document.querySelectorAll('.mantine-Notifications-notification')]
            .filter(n => n.scrollHeight > n.clientHeight + 1)
            .map(n => `${n.innerText.split('\\n')[0]} (${n.scrollHeight} px in ${n.clientHeight})`)"""
    )


BROWSER = pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed")


def _refused_and_nothing_driven(app, page, artifacts, name: str) -> None:
    """Plan (clicked) refuses in a sentence, shown whole, Drive stays disabled, and a Drive
    sent anyway (a click sent before it was disabled) writes no trial row."""
    from roachplan.app._commands import DriveCmd

    drive = page.get_by_role("button", name="Drive", exact=True)
    assert drive.is_disabled()
    page.get_by_role("button", name="Plan", exact=True).click()
    _until(lambda: app.status.content.startswith("Plan failed"), 60, app.status.content)
    lead = re.compile(r"^Plan failed: Start and goal were not picked")
    page.get_by_text(lead).first.wait_for(timeout=10_000)
    assert "index" not in app.status.content and "Error" not in app.status.content
    note = page.locator(".mantine-Notification-root").filter(has_text="Plan failed")
    note.wait_for(timeout=10_000)
    page.wait_for_timeout(600)  # (the notification slides in: measured and shot in place)
    page.screenshot(path=artifacts / f"messages-{name}-plan-refused.png")
    assert not _description_cut(page), _description_cut(page)
    assert "one place" in said_whole(note)
    assert drive.is_disabled()
    app.commands.put(DriveCmd(page_client(app)))
    _until(lambda: "no planned path" in app.status.content, 30, app.status.content)
    assert app.scene_trials == [] and page.get_by_text(re.compile(r"Trial 1")).count() == 0


@pytest.mark.slow
@BROWSER
def test_a_world_nobody_picked_start_and_goal_for_leaves_nothing_to_drive(world, artifacts):
    """The page of a world whose pick failed, its placeholder a place the robot can stand (as
    the user's lidar patch was): never "valid"; Plan refuses; no trial row."""
    from roachplan.app._server import RoachApp

    app = RoachApp(_not_picked(world), host="127.0.0.1", port=free_port())
    try:
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            said = page.get_by_text("Start and goal were not picked", exact=True)
            shown = page.locator("p", has=said)  # the Start and goal folder's paragraph
            shown.wait_for(timeout=30_000)
            assert "one place" in shown.inner_text()
            assert page.get_by_text("Start and goal are valid.").count() == 0
            page.screenshot(path=artifacts / "messages-01-not-picked.png")
            _refused_and_nothing_driven(app, page, artifacts, "02")
    finally:
        app.stop()


@pytest.mark.slow
@BROWSER
@pytest.mark.skipif(not Path(SAMP11).is_file(), reason="the real captures are not here")
def test_the_users_outdoor_lidar_patch_is_said_as_it_is(app, artifacts):
    """terrain_samp11-utm.pcd as it comes. Where no start and goal could be picked (as the
    user met it): the page never says "valid", shows its notification whole (the rest under
    the status line), Plan refuses in a sentence and no trial row appears. Where they were:
    they are valid, and a trial is written only for a path driven."""
    from roachplan.app._markers import pick_failure

    with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
        before = app.world
        upload(page, SAMP11)
        _until(
            lambda: app.world is not before and app.status.content.startswith("Loaded"),
            400,
            lambda: app.status.content,
        )
        said = app.markers.validity.content
        page.wait_for_timeout(600)  # (a notification slides in)
        page.screenshot(path=artifacts / "messages-03-samp11-loaded.png")
        assert not _description_cut(page), _description_cut(page)
        if pick_failure(app.world) is not None:
            assert "Start and goal are valid" not in said and "were not picked" in said, said
            note = page.locator(".mantine-Notification-root").filter(has_text="not picked")
            assert "whole message is at the top of the panel" in note.inner_text()
            whole = said_whole(note)
            assert "could not pick a start and goal" in whole, whole
            assert "Show where it can stand" in whole, whole
            _refused_and_nothing_driven(app, page, artifacts, "04-samp11")
            return
        assert said == "Start and goal are valid.", said
        page.get_by_role("button", name="Plan", exact=True).click()
        ended = re.compile(r"Path found|\d+ (?:of \d+ )?paths found|No path found|Plan failed")
        _until(lambda: ended.match(app.status.content), 120, lambda: app.status.content)
        assert "internal error" not in app.status.content and "index" not in app.status.content
        if not app.plans:
            assert page.get_by_role("button", name="Drive", exact=True).is_disabled()
            return
        page.get_by_role("button", name="Drive", exact=True).click()
        done = re.compile(r"Trial 1:|No trial recorded|Drive failed")
        _until(lambda: done.match(app.status.content), 240, lambda: app.status.content)
        for trial in app.scene_trials:
            assert len(trial["path"]) >= 2 and trial["drive_time"] > 0


def page_client(app) -> int:
    (client_id,) = app.server.get_clients()
    return client_id
