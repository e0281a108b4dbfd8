"""Choose path in the page (issue 17), in headless Chromium on the real planner, PyBullet and
rollout workers: progress while it races, the candidates coloured by P(success) as the ranking
says, the chosen one marked, then Drive drives it; Cancel stops the race and its workers; a
moved marker is refused with why."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from conftest import free_port
from test_app import CHROMIUM, browser_pages, set_value
from test_page_view import dropdown

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="Debian chromium not installed"),
]


def _app(scene: str):
    from roachplan.app._server import RoachApp
    from roachplan.scenes import build_world, load_scene

    return RoachApp(build_world(load_scene(scene)), host="127.0.0.1", port=free_port())


def _ranking_rows(page) -> list[list[str]]:
    """The ranking table's body rows, as cell texts."""
    table = page.locator("table").filter(has_text="P(success)")
    rows = table.get_by_role("row").all()[1:]
    return [[c.inner_text().strip() for c in r.get_by_role("cell").all()] for r in rows]


def _race_processes(app) -> set[int]:
    """The processes under the app's fork server: the race's child and its rollout workers
    (the fork server itself, and the world's host under it, stay for the next job)."""
    import os

    host = {app.core.host._proc.pid} if app.core.host is not None else set()
    return {
        pid
        for server in _descendants(os.getpid())
        if _is_forkserver(server)
        for pid in _descendants(server)
    } - host


def _running(pid: int) -> bool:
    """pid exists and is not a zombie (a killed orphan waits there for init to reap it)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _descendants(pid: int) -> set[int]:
    from roachplan.processes import descendants

    return descendants(pid)


def _check_guarantee(said: str, again: str, chosen: int) -> None:
    """The quick mode's choice: its guarantee in words, at the quick mode's level, the path
    named as in the page, the Bayesian posterior beside it labelled as not a confidence, and
    the same race's command with --quick (and the engine it ran in). A race stopped before
    any fresh rollout says what its rollouts showed instead of a bound."""
    command = again.rstrip().rsplit("from the command line: ", 1)[-1]
    assert " --quick" in command and command.endswith("--engine pybullet"), again
    assert re.search(
        rf"Guarantee: path {chosen}( \(not certified\))?: (at 95% confidence it succeeds at "
        rf"least|it succeeded in (\d+) of its \3 rollouts; the race stopped before)",
        said,
    ), said
    assert "90%" in said or "(not certified)" in said, said
    assert re.search(r"Bayesian posterior probability .*not a confidence", said), said


def test_choose_path_races_colours_ranks_and_drive_takes_the_chosen(artifacts):
    from roachplan.app._choose_panel import p_colour

    app = _app("double_bridge")
    k = 2
    try:
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            set_value(page, "Candidates (K)", str(k))
            set_value(page, "Choose budget [s]", "10")
            set_value(page, "Playback speed [x real time]", "10")
            dropdown(page, "Choose mode", "Quick")
            page.get_by_role("button", name="Choose path", exact=True).last.click()
            # In the panel: progress, Cancel, then the candidates drawn (grey until driven).
            racing = page.get_by_text(re.compile(r"Choose path: \d candidates planned; racing"))
            racing.last.wait_for(timeout=60_000)
            # Two bars under way (the one at the top and the panel's); the others stand at 0.
            bars = page.get_by_role("progressbar").all()
            assert sum(float(b.get_attribute("aria-valuenow") or 0) > 0 for b in bars) == 2
            assert page.get_by_role("button", name="Cancel choose").is_visible()
            handles = app.server.scene._handle_from_node_name
            assert {f"/plans/choose/{i}" for i in range(k)} <= set(handles)
            page.screenshot(path=artifacts / "choose-01-racing.png")

            done = page.get_by_text(re.compile(r"^Chosen: path \d+ \(")).first
            done.wait_for(timeout=150_000)
            said = re.search(r"Chosen: path (\d+)", done.inner_text())
            assert said is not None
            chosen = int(said.group(1))
            rows = _ranking_rows(page)
            assert len(rows) == k, rows
            assert re.fullmatch(rf"{chosen} \w+ chosen", rows[0][0])  # best first
            assert sum("chosen" in r[0] for r in rows) == 1
            # Each path is drawn in the colour of its P(success) in the table; the chosen one
            # is the one Drive takes, drawn thick.
            nodes = app.view.path_nodes
            assert len(nodes) == len(app.plans) == k
            for r in rows:
                path, p = int(r[0].split()[0]), float(r[1].split()[0])
                assert tuple(nodes[path - 1].colors[0, 0]) == p_colour(p), r
                assert nodes[path - 1].thickness == (7.0 if path == chosen else 3.0)
            assert app.drive_path == chosen - 1
            again = page.get_by_text(re.compile(r"Same race from the command line")).inner_text()
            assert (
                "Same race from the command line: roachplan choose --scene double_bridge" in again
            )
            _check_guarantee(done.inner_text(), again, chosen)
            page.screenshot(path=artifacts / "choose-02-ranked.png")

            page.get_by_role("button", name="Drive", exact=True).click()
            page.get_by_text(re.compile(r"^Trial 1: ")).wait_for(timeout=120_000)
            trial = app.scene_trials[0]
            assert np.allclose(trial["path"], app.plans[chosen - 1].plan.path_xyz)
            assert trial["route"] == rows[0][0].split()[1]
            trials = page.locator("table").filter(has_text="rel. energy").get_by_role("row")
            assert trials.count() == 2  # the header and the chosen path's trial
            page.screenshot(path=artifacts / "choose-03-driven.png")
    finally:
        app.stop()


def test_cancel_stops_the_race_and_a_moved_marker_is_refused(artifacts):
    app = _app("double_bridge")
    try:
        with browser_pages(f"http://127.0.0.1:{app.port}") as (page,):
            set_value(page, "Candidates (K)", "2")
            page.get_by_role("button", name="Choose path", exact=True).last.click()
            racing = page.get_by_text(re.compile(r"Choose path: \d+ candidates planned"))
            racing.last.wait_for(timeout=60_000)  # (at the top and in the panel)
            deadline = time.monotonic() + 60
            while len(race := _race_processes(app)) < 3:  # its child and two rollout workers
                assert time.monotonic() < deadline, f"the race's processes: {race}"
                time.sleep(0.2)
            page.get_by_role("button", name="Cancel choose").click()
            page.get_by_text(re.compile(r"Choose path cancelled after")).first.wait_for(
                timeout=10_000
            )
            deadline = time.monotonic() + 10
            while alive := [pid for pid in race if _running(pid)]:
                assert time.monotonic() < deadline, f"{alive} outlived Cancel"
                time.sleep(0.2)
            assert app.plans == [] and app.view.path_nodes == []
            page.screenshot(path=artifacts / "choose-04-cancelled.png")

            app.controls["start"].position = (0.2, -1.5, 0.0)
            page.get_by_role("button", name="Choose path", exact=True).last.click()
            page.get_by_text(
                re.compile(
                    r"races from the scene's start and goal; the start "
                    r"marker is at \(0\.20, -1\.50"
                )
            ).first.wait_for(timeout=30_000)
            assert app.running is None and app.plans == []
    finally:
        app.stop()


def _is_forkserver(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return b"forkserver" in f.read()
    except OSError:
        return False


def test_colours_run_from_red_through_yellow_to_green_and_grey_before_rollouts():
    from roachplan.app._choose_panel import UNTRIED, p_colour

    assert p_colour(float("nan")) == UNTRIED
    assert p_colour(0.0) == (220, 0, 40) and p_colour(1.0) == (0, 180, 40)
    ps = np.linspace(0, 1, 21)
    red, green = zip(*(p_colour(p)[:2] for p in ps), strict=True)
    assert all(np.diff(red) <= 0) and all(np.diff(green) >= 0)  # redder to greener
    assert p_colour(0.5) == (220, 180, 40)  # yellow halfway


def test_the_folder_shows_a_race_from_its_events_as_values():
    """What the Choose folder shows (RaceView, the ranking's rows) is built from the race's
    events alone: each row says why a candidate left the race from the Knockout's reason,
    never from the words of a sentence."""
    import dataclasses

    from roachplan.app._choose_panel import (
        Failed,
        RaceView,
        follow_race,
        ranking_markdown,
        ranking_row,
    )
    from roachplan.experiments import (
        CandidatesPlanned,
        ChooseConfig,
        Decided,
        Knockout,
        RoundDone,
    )
    from test_choose import _race

    events: list = []
    truths = [(1.0, 1.8, 0.05), (0.5, 1.0, 0.05), (1.0, 2.6, 0.05)]
    choice = _race(truths, on_event=events.append, rollouts=600, seed=5)
    planned = CandidatesPlanned(candidates=tuple(c.plan for c in choice.candidates))
    view = follow_race(RaceView(message="planning 3 candidate paths (seed 5)"), planned)
    assert view.message == "3 candidates planned; racing them"
    assert view.paths is planned.candidates and view.standings == () and view.decided is None
    words = {None: None, "less_likely": "out: less likely", "costs_more": "out: costs more"}
    for event in events:
        view = follow_race(view, event)
        if isinstance(event, RoundDone):
            assert view.standings is event.standings
            assert view.message == (
                f"{event.rollouts} rollouts, {event.racing} of 3 candidates in the race"
            )
            for s in view.standings:  # index order while racing
                row = ranking_row(s, None)
                assert row.startswith(f"| **{s.candidate + 1}** r |")
                assert f"({s.rollouts}) |" in row and "chosen" not in row
                why = words[s.knocked_out and s.knocked_out.reason]
                assert row.endswith(f"{why} |") if why else "out:" not in row
    decided = events[-1]
    assert isinstance(decided, Decided) and view.decided is decided and view.failed is None
    assert view.standings is decided.standings  # best first once decided
    table = ranking_markdown(view.standings, decided.chosen, ChooseConfig(procedure="race"))
    rows = [line for line in table.splitlines() if line.startswith("| **")]
    assert rows[0].startswith("| **1** r **chosen** |")
    assert sum("chosen" in r for r in rows) == 1
    path = {int(r.split("**")[1]): r for r in rows}
    assert path[2].endswith("out: less likely |") and path[3].endswith("out: costs more |")

    # The words come from the value: a Knockout makes the row, whatever the race said.
    racing = decided.standings[0]
    beaten = Knockout(reason="costs_more", by=2, own_bound=2.1, rival_bound=1.9)
    assert ranking_row(dataclasses.replace(racing, knocked_out=beaten), None).endswith(
        "out: costs more |"
    )
    below = Knockout(reason="below_min_success", by=None, own_bound=0.7, rival_bound=0.9)
    assert ranking_row(dataclasses.replace(racing, knocked_out=below), None).endswith(
        "out: P(success) upper bound below 0.9 |"
    )
    assert follow_race(view, Failed(error="no path")).failed == "no path"
