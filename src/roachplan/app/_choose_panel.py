"""The Choose path folder (issue 17 in the page): K candidate paths raced by simulation under
the uncertainty model (experiments/_choose.py), drawn coloured by P(success) as their rollouts
come in, a ranking table, the chosen path highlighted; Drive then takes the chosen one.

The race runs in a child of the app's fork server (app/_jobs.py) with its own pool of rollout
workers; the loop follows it with `app.loop.follow` (progress bar, status, Cancel kills the child
and its workers at once) like Plan and Drive. The candidates start at the scene's start and
goal: the rollout workers rebuild the scene from its file, as `roachplan choose` does, so the
page's choice is the command line's for the same seed and budget.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
from dataclasses import replace as dataclass_replace

import numpy as np

from roachplan.experiments._choose import ChooseConfig, ChooseError, plan_candidates, race
from roachplan.experiments._trial import LabelledPlan
from roachplan.planning import PlanResult
from roachplan.planning._isolated import limit_child_memory

from ._app import App
from ._commands import CancelCmd, ChooseCmd
from ._draw import segments
from ._jobs import Job

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


def ranking_markdown(ranking: list[dict], chosen: int | None, confidence: float) -> str:
    """The ranking, best first (experiments/_choose.py summaries); the chosen row marked. Paths
    are numbered from 1 as the page labels them (candidate k of `roachplan choose` is path
    k + 1)."""
    k = max(len(ranking), 1)
    # Four columns: the panel is about 300 px wide, and a wider table hides its right part.
    head = "| path | P(success) (n) | energy; time | failures |\n|---|---|---|---|\n"
    rows = []
    for r in ranking:
        fails = ", ".join(f"{what} {n}" for what, n in r["failures"].items())
        if r["failed_at"]:  # where the first failed rollout ended [m]
            fails += " (first at {:.2f}, {:.2f})".format(*r["failed_at"][0])
        out = r["out"]
        if out:
            fails += ("; out: " if fails else "out: ") + (
                "costs more"
                if out.startswith("costs more")
                else "less likely"
                if out.startswith("less likely")
                else out
            )
        mark = " **chosen**" if r["candidate"] == chosen else ""
        rows.append(
            f"| **{r['candidate'] + 1}** {r['route'] or '-'}{mark} "
            f"| {_f(r['p_success'])} [{_f(r['p_low'])}, {_f(r['p_high'])}] ({r['rollouts']}) "
            f"| {_f(r['relative_energy'])} [{_f(r['relative_energy_low'])}, "
            f"{_f(r['relative_energy_high'])}], {_f(r['energy_j_per_m'])} J/m; "
            f"{_f(r['drive_time_s'], 1)} s | {fails or '-'} |"
        )
    note = (
        f"Best first. Intervals at {1 - (1 - confidence) / k:.2%} each ({confidence:.0%} "
        f"jointly over {k}); n: rollouts; energy: mean over the successes, × a straight walk "
        f"on the floor; time: their mean drive time; out: left the race, beaten. Lines: red "
        f"(P = 0) to green (P = 1), grey before their first rollouts; the chosen one thick."
    )
    return "**Ranking**\n\n" + head + "\n".join(rows) + "\n\n" + note


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
        self.lines: dict[int, object] = {}
        """Candidate index -> its line segments handle (recoloured as rollouts come in)."""

    def clear(self) -> None:
        """A new world: the last choice was on another."""
        self.lines = {}
        self.summary.content = self.table.content = ""


def _choose_job(conn, world, cfg: ChooseConfig, workers: int) -> None:
    """Plan the candidates and race them, as experiments' choose() does, sending each step:
    ("candidates", [(index, route, plan seed, path_xyz)]), ("round", (message, summaries))
    after each round, then ("choice", {...}) or ("error", text). choose() says only a progress
    line, and the page draws every candidate's P(success) as it comes in."""
    from roachplan.experiments._runner import _make_pool
    from roachplan.experiments._spec import ExperimentSpec

    limit_child_memory()
    # The job's child is a daemon (it dies with the server) and multiprocessing refuses a
    # daemon children; the rollout workers die with this process (PR_SET_PDEATHSIG) and
    # Cancel kills them with it (kill_tree), so none is left behind either way.
    multiprocessing.current_process().daemon = False
    try:
        t0, scene = time.monotonic(), world.scene
        if cfg.uncertainty is None:  # (the scene's `uncertainty:`, as choose() takes it)
            cfg = dataclass_replace(cfg, uncertainty=scene.uncertainty)
        candidates = plan_candidates(world, cfg, budget=cfg.budget_s)
        if not candidates:
            raise ChooseError(f"{scene.name}: the planner found no path to choose from")
        conn.send(("candidates", [(c.index, c.route, c.seed, c.path_xyz) for c in candidates]))
        conf = 1 - (1 - cfg.confidence) / len(candidates)  # (as race() has it)
        mass = world.robot.mass
        spec = ExperimentSpec(
            name=f"choose-{scene.name}",
            path=scene.path,
            scene=scene.path,
            planner=scene.planner,
            sim=scene.sim,
            driver=scene.driver,
            uncertainty=cfg.uncertainty,
        )
        pool = _make_pool(spec, workers, "local", None)
        spins = {c.index: c.spins for c in candidates}  # (each candidate's turns on the spot)
        try:
            left = max(cfg.budget_s - (time.monotonic() - t0), 0.0)
            choice = race(
                candidates,
                dataclass_replace(cfg, budget_s=left),
                lambda calls: list(
                    pool.run(
                        ("rollout", (*c, cfg.uncertainty), {"spins": spins[c[0]]}) for c in calls
                    )
                ),
                mass=mass,
                progress=lambda message, _: conn.send(
                    ("round", (message, [c.summary(conf, mass) for c in candidates]))
                ),
            )
        finally:
            pool.close()
        conn.send(
            (
                "choice",
                {
                    "chosen": choice.chosen,
                    "ranking": choice.ranking,
                    "stopped": choice.stopped,
                    "rollouts": choice.rollouts,
                    "wall_time": time.monotonic() - t0,
                },
            )
        )
    except Exception as exc:  # reported to the user as a notification
        conn.send(("error", f"{exc}"))
    conn.close()


def _at_scene_poses(app: App) -> None:
    """ChooseError unless the markers are at the scene's start and goal (the rollouts start
    there: their workers rebuild the scene from its file)."""
    scene = app.world.scene
    for which, pose in zip(("start", "goal"), app.page.markers.valid_poses(app.world), strict=True):
        want = scene.start if which == "start" else scene.goal
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
    cfg = ChooseConfig(
        candidates=int(panel.candidates.value),
        budget_s=float(panel.budget.value),
        confidence=float(panel.confidence.value),
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
    paths: dict[int, tuple[str, int, np.ndarray]] = {}
    got: dict[str, object] = {
        "message": f"planning {cfg.candidates} candidate paths (seed {cfg.seed})"
    }
    job = Job(_choose_job, app.world, cfg, workers)

    def step(messages) -> bool:
        for kind, payload in messages:
            if kind == "candidates":
                for index, route, seed, xyz in payload:
                    pts = np.asarray(xyz) + [0, 0, LIFT]
                    paths[index] = (route, seed, np.asarray(xyz))
                    panel.lines[index] = app.page.view.scene.add_line_segments(
                        f"/plans/choose/{index}",
                        segments(pts),
                        colors=UNTRIED,
                        thickness=3.0,
                        thickness_units="screen",
                    )
                    app.page.view.scene.add_label(
                        f"/plans/choose/{index}/label",
                        str(index + 1),
                        position=tuple(pts[len(pts) // 2] + [0, 0, 0.03]),
                    )
                got["message"] = f"{len(payload)} candidates planned; racing them"
            elif kind == "round":
                got["message"], ranking = payload
                _recolour(panel, ranking)
                panel.table.content = ranking_markdown(
                    sorted(ranking, key=lambda r: r["candidate"]), None, cfg.confidence
                )
            else:
                got[kind] = payload
        t = job.elapsed
        text = f"Choose path: {got['message']}; {t:.1f} s of the {cfg.budget_s:g} s budget"
        app.loop.progress(t / cfg.budget_s, f"{text} ({workers} workers)")
        value = round(100.0 * min(t / cfg.budget_s, 1.0), 1)
        if panel.progress.value != value:
            panel.progress.value = value
        if panel.summary.content != text:
            panel.summary.content = text
        return job.done

    panel.progress.value, panel.progress.visible, panel.cancel.visible = 0.0, True, True
    try:
        end = app.loop.follow(
            job, "Choose path", step, hard_stop=time.monotonic() + cfg.budget_s + GRACE
        )
    finally:
        panel.progress.visible = panel.cancel.visible = False
    if "error" in got:
        panel.summary.content = f"Choose path failed: {got['error']}"
        app.page.set_status(panel.summary.content)
        app.page.notify(cmd.client_id, "Choose path failed", str(got["error"]), error=True)
        return
    if end != "done" or "choice" not in got:
        how = "cancelled" if end == "cancelled" else "stopped (past its budget)"
        panel.summary.content = (
            f"Choose path {how} after {job.elapsed:.1f} s: nothing chosen; the candidates "
            f"drawn are coloured by the rollouts done."
        )
        app.page.set_status(panel.summary.content)
        return
    _show_choice(app, panel, cfg, got["choice"], paths)


def _recolour(panel: ChoosePanel, ranking: list[dict]) -> None:
    for r in ranking:
        handle = panel.lines.get(r["candidate"])
        if handle is not None:
            n = len(handle.points)
            handle.colors = np.broadcast_to(np.uint8(p_colour(r["p_success"])), (n, 2, 3)).copy()


def _show_choice(
    app: App, panel: ChoosePanel, cfg: ChooseConfig, choice: dict, paths: dict
) -> None:
    """The ranking; the candidates become the plan's paths, the chosen one marked for Drive."""
    ranking, chosen, scene = choice["ranking"], choice["chosen"], app.world.scene
    panel.table.content = ranking_markdown(ranking, chosen, cfg.confidence)
    again = (
        f"`roachplan choose --scene {scene.name} --candidates {cfg.candidates} "
        f"--budget-s {cfg.budget_s:g} --confidence {cfg.confidence:g} --seed {cfg.seed}`"
    )
    ran = f"{choice['rollouts']} rollouts in {choice['wall_time']:.1f} s ({choice['stopped']})"
    # The candidates become the plan's paths (labelled 1..K, as in the table), the chosen one
    # marked for Drive (thick, "Drive") and every one keeping its P(success) colour.
    app.page.view.scene.remove_by_name("/plans/choose")
    app.plan_endpoints = (scene.start, scene.goal)
    app.set_plans([_labelled(scene, *paths[i]) for i in sorted(paths)])
    if chosen is not None:
        app.select_path(chosen)
    panel.lines = dict(enumerate(app.page.view.path_nodes))
    _recolour(panel, ranking)
    if chosen is None:
        why = (
            "only one candidate path was found: there was nothing to race"
            if choice["rollouts"] == 0
            else "no candidate succeeded in any rollout"
        )
        panel.summary.content = (
            f"Nothing chosen: {why}; {ran}. **Drive** drives path 1 (*Drive path* picks another). "
            f"Same race: {again}"
        )
        app.page.set_status(panel.summary.content)
        return
    row = next(r for r in ranking if r["candidate"] == chosen)
    route = paths[chosen][0]
    text = (
        f"Chosen: path {chosen + 1} ({route or 'no route'}), P(success) "
        f"{_f(row['p_success'])} [{_f(row['p_low'])}, {_f(row['p_high'])}], energy "
        f"{_f(row['relative_energy'])} × a straight walk; {ran}."
    )
    app.page.set_status(text + " **Drive** drives it (*Drive path* picks another).")
    panel.summary.content = f"{text}  \nSame race from the command line: {again}"


def _labelled(scene, route: str, seed: int, xyz: np.ndarray) -> LabelledPlan:
    """A candidate as the plan Drive takes (its path as planned with the scene's planner)."""
    planner = scene.planner
    return LabelledPlan(
        route=route,
        plan=PlanResult(
            found=True,
            planner=planner.name,
            seed=seed,
            states=np.zeros((0, 3)),
            path_xyz=xyz,
            plan_time=0.0,
            message="chosen by simulation",
            turning_radius=planner.turning_radius,
        ),
    )
