"""The Choose path folder (issue 17 in the page): K candidate paths raced by simulation under
the uncertainty model (roachplan.experiments.choose), drawn coloured by P(success) as their
rollouts come in, a ranking table, the chosen path highlighted; Drive then takes the chosen one.

The race runs in a child of the app's fork server (app/_jobs.py): choose() with its own pool of
rollout workers, its events (CandidatesPlanned, KnockedOut, RoundDone, Decided) sent to the
loop as they happen. The loop follows the child with `app.loop.follow` (progress bar, status,
Cancel kills the child and its workers at once) like Plan and Drive, folds the events into what
the folder shows (follow_race) and draws from them. The candidates start at the scene's start
and goal: the rollout workers rebuild the scene from its file, as `roachplan choose` does, so
the page's choice is the command line's for the same seed and budget.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import re
import time
from dataclasses import dataclass
from dataclasses import replace as dataclass_replace
from typing import TYPE_CHECKING

import numpy as np

from roachplan.experiments import (
    DEFAULT_MODE,
    QUICK_MODE,
    CandidatePlan,
    CandidatesPlanned,
    ChooseConfig,
    ChooseError,
    CrossChecked,
    Decided,
    Knockout,
    LabelledPlan,
    RoundDone,
    Standing,
    choose,
)
from roachplan.planning import PlanResult
from roachplan.processes import limit_memory

from ._app import App
from ._commands import CancelCmd, ChooseCmd
from ._draw import segments
from ._jobs import Job
from ._said import error_text, is_for_the_user, log_internal

if TYPE_CHECKING:  # (the loop and the handlers import no viser: tests/test_loop.py)
    from viser import LineSegmentsHandle

MODES = {"Default": DEFAULT_MODE, "Quick": QUICK_MODE}
"""The Choose mode dropdown's choices: their (eps_P, eps_E) (ChooseConfig.indifference)."""
UNTRIED = (150, 150, 150)
"""Colour of a candidate without rollouts yet."""
LIFT = 0.006
"""Candidates are drawn this far above the surface [m] (over the terrain, under the chosen)."""
GRACE = 60.0
"""How long past its budget the race's child may run before it is killed [s]: the race stops
by itself before a round that would overrun the budget; this bounds a round gone slow."""


def p_colour(p: float) -> tuple[int, int, int]:
    """Red (P(success) 0) through yellow to green (1); grey without rollouts (p nan)."""
    if not math.isfinite(p):
        return UNTRIED
    p = min(max(p, 0.0), 1.0)
    return (round(220 * min(1.0, 2 * (1 - p))), round(180 * min(1.0, 2 * p)), 40)


def _f(v, digits: int = 2) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def _out_words(why: Knockout) -> str:
    """Why a candidate left the race, in the table's few words."""
    match why.reason:
        case "less_likely":
            return "less likely"
        case "costs_more":
            return "costs more"
        case _:
            return why.sentence


def ranking_row(s: Standing, chosen: int | None) -> str:
    """One candidate's row of the ranking table (markdown): its path number (from 1, as the
    page labels it: candidate k of `roachplan choose` is path k + 1), route, P(success) with
    its interval and rollouts, energy and time over the successes, failures and, once it has
    left the race, why."""
    fails = ", ".join(f"{what} {n}" for what, n in s.failures)
    if s.failed_at:  # where the first failed rollout ended [m]
        fails += " (first at {:.2f}, {:.2f})".format(*s.failed_at[0])
    if s.knocked_out is not None:
        fails += ("; out: " if fails else "out: ") + _out_words(s.knocked_out)
    mark = " **chosen**" if s.candidate == chosen else ""
    return (
        f"| **{s.candidate + 1}** {s.route or '-'}{mark} "
        f"| {_f(s.p_success)} [{_f(s.p_low)}, {_f(s.p_high)}] ({s.rollouts}) "
        f"| {_f(s.relative_energy)} [{_f(s.relative_energy_low)}, "
        f"{_f(s.relative_energy_high)}], {_f(s.energy_j_per_m)} J/m; "
        f"{_f(s.drive_time_s, 1)} s | {fails or '-'} |"
    )


def ranking_markdown(standings: tuple[Standing, ...], chosen: int | None, cfg: ChooseConfig) -> str:
    """The ranking table, a row per standing in the order given, the chosen one marked."""
    k, confidence = max(len(standings), 1), cfg.confidence
    # Four columns: the panel is about 300 px wide, and a wider table hides its right part.
    head = "| path | P(success) (n) | energy; time | failures |\n|---|---|---|---|\n"
    rows = [ranking_row(s, chosen) for s in standings]
    each = (
        f"valid at every look, at {1 - (1 - confidence) / 4 / k:.2%} each"
        if cfg.procedure == "certify"
        else f"at {1 - (1 - confidence) / k:.2%} each ({confidence:.0%} jointly over {k})"
    )
    note = (
        f"Best first. Intervals {each}; n: rollouts; energy: mean over the successes, × a straight walk "
        f"on the floor; time: their mean drive time; out: left the race, beaten. Lines: red "
        f"(P = 0) to green (P = 1), grey before their first rollouts; the chosen one thick."
    )
    return "**Ranking**\n\n" + head + "\n".join(rows) + "\n\n" + note


@dataclass(frozen=True, kw_only=True)
class Failed:
    """The race's child failed before a decision (sent in place of the events)."""

    error: str


@dataclass(frozen=True, kw_only=True)
class RaceView:
    """What the Choose folder shows of a race: built from the race's events alone."""

    message: str
    """The progress line."""
    paths: tuple[CandidatePlan, ...] = ()
    """The candidates, in index order."""
    standings: tuple[Standing, ...] = ()
    """Every candidate's last standing: in index order while racing, best first once
    decided."""
    decided: Decided | None = None
    failed: str | None = None
    """Why the race failed."""
    checked: dict | None = None
    """The cross-check's result, once made (experiments/_cross_check.py)."""


def follow_race(view: RaceView, event) -> RaceView:
    """The view after one more of the race's events (or a Failed)."""
    match event:
        case CandidatesPlanned():
            return dataclass_replace(view, message=event.message, paths=event.candidates)
        case RoundDone():
            return dataclass_replace(view, message=event.message, standings=event.standings)
        case Decided():
            return dataclass_replace(view, standings=event.standings, decided=event)
        case CrossChecked():
            return dataclass_replace(view, checked=event.result)
        case Failed():
            return dataclass_replace(view, failed=event.error)
    return view  # (a KnockedOut: the RoundDone that follows it has its standing)


class ChoosePanel:
    """The Choose path folder: K, the time budget, the button, the outcome and the ranking."""

    def __init__(self, gui, put) -> None:
        with gui.add_folder("Choose path"):
            self.candidates = gui.add_number(
                "Candidates (K)",
                4,
                min=2,
                max=16,
                step=1,
                hint="Distinct paths to race (a route each, in turn, where the scene names "
                "routes); at least 2: a race needs two",
            )
            self.budget = gui.add_number(
                "Choose budget [s]",
                60.0,
                min=5.0,
                max=3600.0,
                step=5.0,
                hint="Wall time for planning the candidates and racing them",
            )
            self.confidence = gui.add_number("Confidence", 0.95, min=0.5, max=0.99, step=0.01)
            self.mode = gui.add_dropdown(
                "Choose mode",
                tuple(MODES),
                initial_value="Default",
                hint="Default: the chosen path succeeds at least 95 % of the time and is within "
                "5 % of the lowest energy among the paths that safe; Quick: 90 % and 10 %, in "
                "about a quarter of the rollouts. Either is certified on fresh rollouts at the "
                "confidence above",
            )
            self.cross_check = gui.add_checkbox(
                "Cross-check engines",
                False,
                hint="After the race, drive its rollouts again under the other physics engine "
                "(the same paths in the same drawn worlds) and say whether the two agree; "
                "takes about as long again, after the budget",
            )
            self.button = gui.add_button(
                "Choose path",
                hint="Drive each candidate many times in worlds drawn from the uncertainty "
                "model (start pose, friction, motors, mass), from the scene's start and goal; "
                "Drive then takes the chosen path",
            )
            # The race's progress and Cancel here too, where the person who clicked is (the
            # ones at the top of the panel may be scrolled out of view).
            self.progress = gui.add_progress_bar(0.0, visible=False)
            self.cancel = gui.add_button(
                "Cancel choose",
                color="red",
                visible=False,
                hint="Stop the race now; nothing is chosen",
            )
            self.summary = gui.add_markdown("")
            self.table = gui.add_markdown("")
        self.button.on_click(lambda ev: put(ChooseCmd(ev.client_id)))
        self.cancel.on_click(lambda ev: put(CancelCmd(ev.client_id)))
        self.lines: dict[int, LineSegmentsHandle] = {}
        """Candidate index -> its line segments handle (recoloured as rollouts come in)."""

    def clear(self) -> None:
        """A new world: the last choice was on another."""
        self.lines = {}
        self.summary.content = self.table.content = ""


def _choose_job(conn, world, cfg: ChooseConfig, workers: int, cross_check: bool) -> None:
    """choose() on the page's world, each of its events sent as it happens; a Failed
    instead of the rest when it fails."""
    limit_memory()
    # The job's child is a daemon (it dies with the server) and multiprocessing refuses a
    # daemon children; the rollout workers die with this process (PR_SET_PDEATHSIG) and
    # Cancel kills them with it (kill_tree), so none is left behind either way.
    multiprocessing.current_process().daemon = False
    try:
        choose(world, cfg, workers=workers, cross_check=cross_check, on_event=conn.send)
    except Exception as exc:  # reported to the user as a notification, in the page's words
        if not is_for_the_user(exc):
            log_internal(exc, where="the Choose path process")
        conn.send(Failed(error=error_text(exc)))
    conn.close()


def _at_scene_poses(app: App) -> None:
    """ChooseError unless the markers are at the scene's start and goal (the rollouts start
    there: their workers rebuild the scene from its file)."""
    world = app.world
    for which, pose in zip(("start", "goal"), app.page.markers.valid_poses(world), strict=True):
        want = world.start if which == "start" else world.goal
        turn = abs((pose[2] - want[2] + math.pi) % (2 * math.pi) - math.pi)
        if math.dist(pose[:2], want[:2]) > 0.005 or turn > math.radians(0.6):
            raise ChooseError(
                f"Choose path races from the scene's start and goal; the {which} marker is at "
                f"({pose[0]:.2f}, {pose[1]:.2f}, {math.degrees(pose[2]):.0f}°), the scene's "
                f"{which} at ({want[0]:.2f}, {want[1]:.2f}, {math.degrees(want[2]):.0f}°): pick "
                f"the scene again to put the markers back"
            )


def do_choose(app: App, cmd: ChooseCmd) -> None:
    """Race K candidates in a child followed by the loop; then Drive takes the chosen one."""
    panel = app.page.choose_panel
    _at_scene_poses(app)
    budget = float(panel.budget.value)
    cfg = ChooseConfig(
        candidates=int(panel.candidates.value),
        budget_s=budget,
        confidence=float(panel.confidence.value),
        indifference=MODES.get(str(panel.mode.value), DEFAULT_MODE),
        seed=app.next_seed,
    )
    app.next_seed += 1  # (a second click draws fresh candidates and rollouts)
    workers = os.cpu_count() or 1  # (every core, as `roachplan choose` takes by default)
    app.page.show_robot_at_start()
    # Only this race's candidates are shown, and Drive has nothing to take until it chooses.
    app.plan_endpoints = None
    app.set_plans([])
    app.page.view.clear("/trajectories")
    panel.lines, panel.table.content = {}, ""
    view = RaceView(message=f"planning {cfg.candidates} candidate paths (seed {cfg.seed})")
    took = 0.0  # wall time from the job's start to the decision [s]
    cross_check = bool(panel.cross_check.value)
    job = Job(_choose_job, app.world, cfg, workers, cross_check)

    def step(events) -> bool:
        nonlocal view, took
        for event in events:
            view = follow_race(view, event)
            match event:
                case CandidatesPlanned():
                    _draw_candidates(app, panel, event.candidates)
                case RoundDone():
                    _recolour(panel, event.standings)
                    panel.table.content = ranking_markdown(event.standings, None, cfg)
                case Decided():
                    took = job.elapsed
        t = job.elapsed
        text = f"Choose path: {view.message}; {t:.1f} s of the {budget:g} s budget"
        app.loop.progress(t / budget, f"{text} ({workers} workers)")
        value = round(100.0 * min(t / budget, 1.0), 1)
        if panel.progress.value != value:
            panel.progress.value = value
        if panel.summary.content != text:
            panel.summary.content = text
        return job.done

    panel.progress.value, panel.progress.visible, panel.cancel.visible = 0.0, True, True
    try:
        # (a cross-check drives the race's rollouts again: as long again, after the budget)
        end = app.loop.follow(
            job,
            "Choose path",
            step,
            hard_stop=time.monotonic() + budget * (1 + cross_check) + GRACE,
        )
    finally:
        panel.progress.visible = panel.cancel.visible = False
    if view.failed is not None:
        panel.summary.content = f"Choose path failed: {view.failed}"
        app.page.set_status(panel.summary.content)
        app.page.notify(cmd.client_id, "Choose path failed", view.failed, error=True)
        return
    if end != "done" or view.decided is None:
        how = "cancelled" if end == "cancelled" else "stopped (past its budget)"
        panel.summary.content = (
            f"Choose path {how} after {job.elapsed:.1f} s: nothing chosen; the candidates "
            f"drawn are coloured by the rollouts done."
        )
        app.page.set_status(panel.summary.content)
        return
    _show_choice(app, panel, cfg, view.decided, view.paths, took=took, checked=view.checked)


def _draw_candidates(app, panel: ChoosePanel, paths: tuple[CandidatePlan, ...]) -> None:
    """Each candidate's path, grey until its first rollouts, labelled with its number."""
    for c in paths:
        pts = np.asarray(c.path_xyz) + [0, 0, LIFT]
        panel.lines[c.index] = app.page.view.scene.add_line_segments(
            f"/plans/choose/{c.index}",
            segments(pts),
            colors=UNTRIED,
            thickness=3.0,
            thickness_units="screen",
        )
        app.page.view.scene.add_label(
            f"/plans/choose/{c.index}/label",
            str(c.index + 1),
            position=tuple(pts[len(pts) // 2] + [0, 0, 0.03]),
        )


def _recolour(panel: ChoosePanel, standings: tuple[Standing, ...]) -> None:
    for s in standings:
        handle = panel.lines.get(s.candidate)
        if handle is not None:
            n = len(handle.points)
            rgb = np.array(p_colour(s.p_success), dtype=np.uint8)
            handle.colors = np.broadcast_to(rgb, (n, 2, 3)).copy()


def _show_choice(
    app: App,
    panel: ChoosePanel,
    cfg: ChooseConfig,
    decided: Decided,
    paths: tuple[CandidatePlan, ...],
    *,
    took: float,
    checked: dict | None = None,
) -> None:
    """The ranking; the candidates become the plan's paths, the chosen one marked for Drive.
    took: the wall time to the decision [s]; checked: the cross-check's result, if one was
    made (experiments/_cross_check.py)."""
    ranking, chosen, scene = decided.standings, decided.chosen, app.world.scene
    panel.table.content = ranking_markdown(ranking, chosen, cfg)
    again = (
        f"`roachplan choose --scene {scene.name} --candidates {cfg.candidates} "
        f"--budget-s {cfg.budget_s:g} --confidence {cfg.confidence:g} --seed {cfg.seed}"
        f"{' --quick' if cfg.indifference == QUICK_MODE else ''} --engine {scene.sim.engine}"
        f"{' --cross-check' if checked is not None else ''}`"
    )
    ran = f"{decided.rollouts} rollouts in {took:.1f} s ({decided.stopped})"
    # The candidates become the plan's paths (labelled 1..K, as in the table), the chosen one
    # marked for Drive (thick, "Drive") and every one keeping its P(success) colour.
    app.page.view.scene.remove_by_name("/plans/choose")
    app.plan_endpoints = (app.world.start, app.world.goal)
    app.set_plans([_labelled(scene, c) for c in paths])  # (in index order)
    if chosen is not None:
        app.select_path(chosen)
    panel.lines = dict(enumerate(app.page.view.path_nodes))
    _recolour(panel, ranking)
    if chosen is None:
        why = (
            "only one candidate path was found: there was nothing to race"
            if decided.rollouts == 0
            else "no candidate succeeded in any rollout"
        )
        panel.summary.content = (
            f"Nothing chosen: {why}; {ran}. **Drive** drives path 1 (*Drive path* picks another). "
            f"Same race: {again}"
        )
        app.page.set_status(panel.summary.content)
        return
    row = next(s for s in ranking if s.candidate == chosen)
    text = (
        f"Chosen: path {chosen + 1} ({row.route or 'no route'}), P(success) "
        f"{_f(row.p_success)} [{_f(row.p_low)}, {_f(row.p_high)}], energy "
        f"{_f(row.relative_energy)} × a straight walk; {ran}."
    )
    g = decided.guarantee
    if g is not None:  # (path k of the page is candidate k - 1)
        text += (
            f"  \n**Guarantee**: {g.sentence(chosen, noun='path', first=1)}. Bayesian posterior "
            f"probability (flat priors, not a confidence) that it meets the claim: "
            f"{g.posterior:.2f}."
        )
    if checked is not None:
        text += f"  \n**Cross-check engines**: {_pathed(checked['sentence'])}."
    app.page.set_status(text + " **Drive** drives it (*Drive path* picks another).")
    panel.summary.content = f"{text}  \nSame race from the command line: {again}"


def _pathed(sentence: str) -> str:
    """A cross-check's sentence in the page's words: candidate k is path k + 1."""
    return re.sub(r"candidates? ([\d, ]+)", lambda m: _plus_one(m.group(0)), sentence)


def _plus_one(words: str) -> str:
    """'candidate 0' -> 'path 1'; 'candidates 1, 2' -> 'paths 2, 3'."""
    noun = "paths" if words.startswith("candidates") else "path"
    rest = words.split(" ", 1)[1]
    return f"{noun} " + re.sub(r"\d+", lambda m: str(int(m.group(0)) + 1), rest)


def _labelled(scene, c: CandidatePlan) -> LabelledPlan:
    """A candidate as the plan Drive takes (its path as planned with the scene's planner)."""
    planner = scene.planner
    return LabelledPlan(
        route=c.route,
        plan=PlanResult(
            found=True,
            planner=planner.name,
            seed=c.seed,
            states=np.zeros((0, 3)),
            path_xyz=c.path_xyz,
            plan_time=0.0,
            message="chosen by simulation",
            turning_radius=planner.turning_radius,
            spins=c.spins,
        ),
    )
