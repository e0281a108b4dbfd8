"""Replays anyone can open (issue 19): a trial, a whole experiment or a choice as one HTML file
that plays offline, or as a `.viser` recording.

The HTML is viser's own client (its build is one self-contained index.html, the JS and CSS
inlined) with the recording inlined as base64 (`StateSerializer.as_html`): it needs no server and
no network, and opens from a file:// URL. The recording is made by a private, loopback-only viser
server that no browser connects to: the scene is drawn with the app's own `SceneView` (terrain,
robot, paths in black, trajectories in blue), then the robot is moved frame by frame with a
recorded pause between frames, so the client's player plays it at real time (and loops).

The robot's pose per frame is not in a results store (a trial keeps its body positions only), so
the trial is re-driven: the stored path from the stored start on the recorded world, which drives
exactly as it did (the simulation is deterministic); the re-drive is checked against the stored
trajectory and any difference is shown in the page.
"""

from __future__ import annotations

import contextlib
import dataclasses
import html
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roachplan.experiments import ExperimentError, drive, read_manifest, reference_energy
from roachplan.scenes import World
from roachplan.sim import Frame

from ._commands import ShareCmd
from ._draw import (
    BLACK,
    BLUE,
    LIVE,
    MARKER_COLOURS,
    SceneView,
    look_ahead_lines,
    on_surface,
    wxyz_from_xyzw,
    yaw_wxyz,
)

if TYPE_CHECKING:
    from ._app import App

SUFFIXES = (".html", ".viser")
"""What `replay -o` writes: a standalone page, or viser's recording."""
HTML_MARK = "<!-- written by roachplan: a replay -->"
"""Put in every replay page's head: `-o` may replace a page that carries it without --force."""
ZSTD_MAGIC = bytes.fromhex("28b52ffd")
"""A .viser recording is an 8-byte length, then one zstd frame (viser's StateSerializer)."""
END_HOLD = 1.5
"""Pause at the end of the recording before the player loops [s]."""
MAX_TABLE_ROWS = 200
"""Rows of the experiment's trial table the page lists (the rest are counted)."""


@dataclass(frozen=True, kw_only=True)
class Replay:
    """What a replay shows: a world, the trials drawn on it and the one that plays."""

    title: str
    """First line of the page, e.g. "bridge_rough: trial 3"."""
    world: World
    trials: tuple[dict, ...]
    """Trial records as `TrialResult.to_json()` (path [x, y, z] and trajectory [t, x, y, z] in
    the world frame [m], outcome and numbers), each with a "label" ("trial 3")."""
    shown: int
    """Index into `trials` of the one whose robot walks."""
    frames: tuple[Frame, ...]
    """The shown trial's robot per frame (empty: it stays at its start)."""
    note: str = ""
    """Anything the viewer should know (a re-drive that differs from the store)."""
    rows: tuple[tuple[str, str], ...] = ()
    """The numbers shown (name, value); empty: the shown trial's (`numbers`)."""
    lines: tuple[tuple[str, tuple, tuple[int, int, int]], ...] = ()
    """More polylines to draw: (node name, points [[x, y, z]...] [m], colour)."""
    legend: str = "planned path black, driven trajectory blue"
    """What the colours are."""


# -- building a replay from a results folder -----------------------------------------------------


def redrive(world: World, record: dict) -> tuple[tuple[Frame, ...], str]:
    """Drive a trial record's path again from its start: (frames, note). The note is empty when
    the re-drive matches the stored trajectory, else says by how much it differs [m]."""
    if not record.get("path"):
        return (), "no path was planned: nothing was driven"
    frames: list[Frame] = []
    driven = drive(
        world,
        np.asarray(record["path"], dtype=float),
        start=tuple(record["start"]),
        on_frame=frames.append,
        spins=record.get("spins") or (),
    )
    stored = np.asarray(record.get("trajectory") or [], dtype=float).reshape(-1, 4)
    again = np.asarray(driven.trajectory, dtype=float).reshape(-1, 4)
    if len(stored) == 0:
        return tuple(frames), ""
    if len(stored) != len(again):
        return tuple(frames), (
            f"the re-drive lasted {again[-1, 0]:.2f} s, the stored one "
            f"{stored[-1, 0]:.2f} s: the robot shown may not follow the blue "
            f"line"
        )
    gap = float(np.max(np.linalg.norm(stored[:, 1:] - again[:, 1:], axis=1)))
    if gap > 0.0:
        return tuple(frames), (
            f"the re-drive differs from the stored trajectory by up to {gap * 1000:.2g} mm"
        )
    return tuple(frames), ""


def load_replay(
    folder: str | Path, *, trial: int | None = None, scene: str | None = None
) -> Replay:
    """The replay of an experiment's results folder (every trial, or only `trial`), of a
    choice's folder (its chosen path) or of a robot run's log (LOG.mcap: on `scene`, default
    the scene file it names). ExperimentError naming the folder or --trial when it holds
    neither, or not that trial."""
    folder = Path(folder)
    if is_run_log(folder):
        if trial is not None:
            raise ExperimentError(f"--trial {trial}: {folder} is one robot run; drop --trial")
        return run_replay(folder, scene=scene)
    if scene is not None:
        raise ExperimentError(
            f"--scene {scene}: a results folder replays on its own recorded scene; --scene is "
            f"for a robot run's log"
        )
    if not folder.is_dir():
        raise ExperimentError(
            f"{folder}: not a folder; give an experiment's results folder "
            f"(`roachplan experiment --out`) or a choice's (`choose --out`)"
        )
    if (folder / "choice.json").is_file() and not (folder / "manifest.json").exists():
        if trial is not None:
            raise ExperimentError(
                f"--trial {trial}: {folder} holds a choice, which replays its "
                f"chosen path; drop --trial"
            )
        return _choice_replay(folder)
    return _experiment_replay(folder, trial)


def _experiment_replay(folder: Path, trial: int | None) -> Replay:
    from roachplan.experiments import (
        MANIFEST,
        ResultStore,
        check_same_world,
        spec_from_manifest,
    )
    from roachplan.scenes import build_world

    try:
        manifest = read_manifest(folder)
    except ExperimentError as exc:
        raise ExperimentError(f"{exc} (nor a choice's folder: no choice.json)") from None
    records = sorted(
        (r for r in ResultStore(folder / "trials.jsonl").records() if r["kind"] == "trial"),
        key=lambda r: r["index"],
    )
    if not records:
        raise ExperimentError(f"{folder}: no trial is stored yet (trials.jsonl); nothing to replay")
    if trial is not None:
        chosen = [r for r in records if r["index"] == trial]
        if not chosen:
            have = ", ".join(str(r["index"]) for r in records[:20])
            raise ExperimentError(
                f"--trial {trial}: {folder} has stored trials {have}"
                + (" ..." if len(records) > 20 else "")
            )
        records = chosen
    spec = spec_from_manifest(manifest, folder / MANIFEST)
    world = build_world(spec.scene_with_settings())
    check_same_world(manifest, world, folder)
    for r in records:
        r["label"] = f"trial {r['index']}"
    shown = 0 if trial is not None else _best(folder, records)
    frames, note = redrive(world, records[shown])
    what = records[0]["label"] if trial is not None else f"{len(records)} trials"
    return Replay(
        title=f"{spec.name} ({world.scene.name}): {what}",
        world=world,
        trials=tuple(records),
        shown=shown,
        frames=frames,
        note=note,
    )


def _best(folder: Path, records: list[dict]) -> int:
    """Which trial plays in a whole-experiment replay: the experiment's best path (best_path.json),
    else the lowest-energy success, else the first trial with a path."""
    index = None
    try:
        index = json.loads((folder / "best_path.json").read_text())["index"]
    except (OSError, ValueError, KeyError, TypeError):
        ok = [r for r in records if r["outcome"] == "success"]
        if ok:
            index = min(ok, key=lambda r: r["relative_energy"])["index"]
    for k, r in enumerate(records):
        if r["index"] == index:
            return k
    return next((k for k, r in enumerate(records) if r.get("path")), 0)


def _choice_replay(folder: Path) -> Replay:
    from roachplan.experiments import reference_settings
    from roachplan.scenes import build_world, load_scene

    where = folder / "choice.json"
    try:
        choice = json.loads(where.read_text())
        scene_name, chosen = choice["scene"], choice["chosen"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ExperimentError(
            f"{where}: not a choice that `roachplan choose` wrote ({exc})"
        ) from None
    if chosen is None or not choice.get("chosen_path"):
        raise ExperimentError(
            f"{where}: no candidate was chosen (none succeeded); nothing to replay"
        )
    scene = load_scene(scene_name)
    if choice.get("driver") == "reference" and scene.driver.kind != "reference":
        planner, driver = reference_settings(scene.planner, scene.driver)
        scene = dataclasses.replace(scene, planner=planner, driver=driver)
    world = build_world(scene)
    row = next((r for r in choice.get("ranking", []) if r.get("candidate") == chosen), {})
    path = np.asarray(choice["chosen_path"], dtype=float)
    spins = choice.get("chosen_spins") or ()
    frames: list[Frame] = []
    driven = drive(world, path, on_frame=frames.append, spins=spins)
    record = {
        "label": f"chosen candidate {chosen}",
        "scene": scene.name,
        "seed": choice.get("seed"),
        "planner": scene.planner.name,
        "route": row.get("route", ""),
        "outcome": driven.outcome,
        "reason": driven.reason,
        "drive_time": driven.drive_time,
        "energy": driven.energy,
        "relative_energy": driven.energy / reference_energy(world, world.start, world.goal),
        "start": list(world.start),
        "goal": list(world.goal),
        "path": path.tolist(),
        "spins": [list(s) for s in spins],
        "trajectory": [list(p) for p in driven.trajectory],
        "p_success": row.get("p_success"),
        "p_low": row.get("p_low"),
        "p_high": row.get("p_high"),
        "rollouts": row.get("rollouts"),
    }
    return Replay(
        title=f"{scene.name}: the chosen path (candidate {chosen}, nominal drive)",
        world=world,
        trials=(record,),
        shown=0,
        frames=tuple(frames),
    )


# -- recording ---------------------------------------------------------------------------------


def numbers(record: dict) -> list[tuple[str, str]]:
    """(name, value) rows of a trial's numbers, as the page and the 3D label show them."""
    rows = [
        ("scene", str(record.get("scene", ""))),
        ("seed", str(record.get("seed"))),
        ("planner", str(record.get("planner", ""))),
        ("route", record.get("route") or "-"),
        ("outcome", f"{record['outcome']} ({record.get('reason', '')})"),
        ("drive time", f"{record['drive_time']:.2f} s"),
        ("energy", f"{record['energy']:.3f} J"),
        ("relative energy", f"{record['relative_energy']:.3f}"),
    ]
    if record.get("plan_time") is not None:
        rows.append(("plan time", f"{record['plan_time']:.2f} s"))
    if record.get("p_success") is not None:
        lo, hi = record.get("p_low"), record.get("p_high")
        bounds = f" [{lo:.2f}, {hi:.2f}]" if lo is not None and hi is not None else ""
        rows.append(
            (
                "P(success)",
                f"{record['p_success']:.2f}{bounds} over {record.get('rollouts')} rollouts",
            )
        )
    return rows


def _record(replay: Replay):
    """A viser StateSerializer holding the replay (not yet serialized), from a private server."""
    import viser

    world, shown = replay.world, replay.trials[replay.shown]
    # Loopback and an ephemeral port: nothing connects; the server only feeds the recorder.
    # (Its banner would be noise on a command's output.)
    with contextlib.redirect_stdout(io.StringIO()):
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        view = SceneView(server.scene)
        view.show(world, on_marker=lambda event: None)
        # The app's markers are draggable gizmos; a replay shows plain ones at the trial's poses.
        server.scene.remove_by_name("/markers")
        for which in ("start", "goal"):
            pose = tuple(shown.get(which) or getattr(world, which))
            server.scene.add_icosphere(
                f"/markers/{which}",
                radius=0.03,
                color=MARKER_COLOURS[which],
                position=on_surface(world, pose),
                wxyz=yaw_wxyz(pose[2]),
            )
        for k, t in enumerate(replay.trials):
            if t.get("path"):
                view.draw(f"/plans/{k}", np.asarray(t["path"]) + [0, 0, 0.005], BLACK)
            if t.get("trajectory"):
                view.draw(f"/trajectories/{k}", [p[1:] for p in t["trajectory"]], BLUE)
        for name, points, colour in replay.lines:
            view.draw(name, points, colour)
        lo, hi = (
            np.asarray(world.mesh.bounds)
            if len(world.mesh.faces)
            else np.asarray([[*world.bounds[0], 0.0], [*world.bounds[1], 0.0]])
        )
        centre, span = (lo + hi) / 2, float(max(hi[0] - lo[0], hi[1] - lo[1], 0.5))
        server.initial_camera.look_at = tuple(centre)
        server.initial_camera.position = tuple(centre + np.array([-0.25, -0.6, 0.5]) * span)
        label = " · ".join(v for _, v in (replay.rows or numbers(shown)[3:8]))
        start = on_surface(world, tuple(shown.get("start") or world.start))
        server.scene.add_label(
            "/replay/numbers",
            f"{shown['label']}: {label}",
            position=(start[0], start[1], start[2] + 0.15),
        )
        _pose(server, view, world, replay.frames[0] if replay.frames else None, shown)
        serializer = server.get_scene_serializer()
        for prev, f in zip(replay.frames, replay.frames[1:], strict=False):
            serializer.insert_sleep(max(0.0, f.t - prev.t))
            _pose(server, view, world, f, shown)
        serializer.insert_sleep(END_HOLD)
        return serializer
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()


def _pose(server, view: SceneView, world: World, f: Frame | None, record: dict) -> None:
    if f is not None:
        view.show_robot(server, f.p_world_body, wxyz_from_xyzw(f.quat_world_body), f.leg_angles)
        return
    x, y, yaw = tuple(record.get("start") or world.start)
    _, _, z = on_surface(world, (x, y))
    view.show_robot(
        server,
        (x, y, z + world.robot.standing_height),
        yaw_wxyz(yaw),
        (0.0,) * len(world.robot.hip_positions),
    )


def replay_viser(replay: Replay) -> bytes:
    """The replay as viser's `.viser` recording (open it with viser's client, `?playbackPath=`)."""
    return _record(replay).serialize()


def replay_html(replay: Replay) -> str:
    """The replay as one standalone HTML page: viser's client, the recording and the numbers."""
    page = _record(replay).as_html()
    head = page.index("<head>") + len("<head>")
    page = page[:head] + HTML_MARK + page[head:]
    # The browser tab names the replay, not "Viser".
    page = page.replace("<title>Viser</title>", f"<title>{html.escape(replay.title)}</title>", 1)
    body = page.rindex("</body>")
    return page[:body] + _overlay(replay) + page[body:]


def _overlay(replay: Replay) -> str:
    """The trial's numbers in a box over the 3D view (top left, clear of viser's panels)."""
    esc = html.escape
    shown = replay.trials[replay.shown]
    rows = "".join(
        f"<tr><td>{esc(k)}</td><td>{esc(v)}</td></tr>" for k, v in (replay.rows or numbers(shown))
    )
    table = ""
    if len(replay.trials) > 1:
        head = (
            "<tr><th>trial</th><th>seed</th><th>route</th><th>outcome</th><th>rel. energy</th></tr>"
        )
        lines = "".join(
            f"<tr{' class=shown' if k == replay.shown else ''}><td>{esc(t['label'])}</td>"
            f"<td>{esc(str(t['seed']))}</td><td>{esc(t['route'] or '-')}</td>"
            f"<td>{esc(t['outcome'])}</td><td>{t['relative_energy']:.2f}</td></tr>"
            for k, t in enumerate(replay.trials[:MAX_TABLE_ROWS])
        )
        more = len(replay.trials) - MAX_TABLE_ROWS
        table = (
            f"<details><summary>all {len(replay.trials)} trials (black: planned, blue: "
            f"driven)</summary><table>{head}{lines}</table>"
            + (f"<div>... and {more} more</div>" if more > 0 else "")
            + "</details>"
        )
    note = f"<div class=note>{esc(replay.note)}</div>" if replay.note else ""
    return (
        "<style>#roachplan-replay{position:fixed;left:12px;top:12px;z-index:1000;max-width:420px;"
        "max-height:80vh;overflow:auto;background:rgba(255,255,255,.9);color:#222;"
        "font:12px/1.35 system-ui,sans-serif;padding:8px 10px;border-radius:6px;"
        "box-shadow:0 1px 4px rgba(0,0,0,.3)}#roachplan-replay td,#roachplan-replay th{"
        "padding:0 6px 0 0;text-align:left;vertical-align:top}#roachplan-replay .shown{"
        "font-weight:bold}#roachplan-replay .note{color:#a33}</style>"
        f"<div id=roachplan-replay><b>{esc(replay.title)}</b><div>{esc(shown['label'])} "
        f"plays: {esc(replay.legend)}</div><table id=roachplan-numbers>"
        f"{rows}</table>{note}{table}</div>"
    )


def write_replay(replay: Replay, out: Path) -> int:
    """Write the replay to `out` (.html or .viser) atomically; its size [bytes]."""
    from roachplan.experiments import atomic_write

    data = replay_viser(replay) if out.suffix.lower() == ".viser" else replay_html(replay).encode()
    atomic_write(out, data)
    return len(data)


def replay_written(head: bytes) -> bool:
    """Whether an existing output is a replay roachplan wrote (a page with HTML_MARK, or a
    .viser recording): `replay -o` replaces those without --force."""
    return HTML_MARK.encode() in head or head[8:12] == ZSTD_MAGIC


def replay_inputs(folder: str | Path) -> list[Path]:
    """The files a replay of `folder` reads: never its output."""
    folder = Path(folder)
    if is_run_log(folder):
        return [folder]
    return [folder / n for n in ("manifest.json", "trials.jsonl", "choice.json", "best_path.json")]


# -- a robot run's log ------------------------------------------------------------------------------

REPLAY_RATE = 30.0
"""Frames per second of a robot run's replay (its poses come at the mocap's rate)."""


def is_run_log(path: Path) -> bool:
    """A robot run's log by its name (LOG.mcap, or a killed run's LOG.mcap.partial)."""
    return path.name.endswith((".mcap", ".mcap.partial")) and not path.is_dir()


def _look_ahead_shown(log, path) -> tuple[list, list]:
    """(lines, rows) of a run log's look-aheads on its plan `path` ((N, 3) [m]; empty: none
    drawn): each one's stretch of the path ahead in its risk colour and its rollouts' failures
    (look_ahead_lines), the lowest chance seen, and a re-plan's places kept clear of."""
    lines, rows = [], []
    if log.lookaheads and len(path):
        for k, ahead in enumerate(log.lookaheads):
            for suffix, points, colour in look_ahead_lines(ahead, path):
                name = f"/lookahead/{k}" + (f"/{suffix}" if suffix else "")
                lines.append((name, tuple(map(tuple, points.tolist())), colour))
        low = min(log.lookaheads, key=lambda a: a["p_hold"])
        rows.append(
            (
                "look-ahead",
                f"{len(log.lookaheads)} made; the lowest chance of going on {low['horizon']:g} s "
                f"{low['p_hold']:.2f}, from ({low['start'][0]:.2f}, {low['start'][1]:.2f})",
            )
        )
    plan = log.plan or {}
    if plan.get("avoid"):
        clear = plan.get("clearance")
        rows.append(
            (
                "re-planned",
                f"clear of {len(plan['avoid'])} places its rollouts failed"
                + ("" if clear is None else f": its path keeps {clear:.2f} m"),
            )
        )
    return lines, rows


def run_replay(path: Path, *, scene: str | None = None) -> Replay:
    """A robot run as a replay: the plan (black), the simulation's prediction from the robot's
    start (blue) and where the robot went (green), the robot walking its logged poses (legs
    at the phase of its commands), and the run's numbers."""
    from roachplan.robot import log_world, motor_phase, read_run

    log = read_run(path)
    world = log_world(log, scene)
    t_go = log.t_go
    poses = log.poses
    t_stop = next((e["t"] for e in log.events if e["name"] == "stop"), math.inf)
    if t_go is None:
        keep = np.ones(len(poses["t_receive"]), dtype=bool)
        t0 = float(poses["t_receive"][0]) if len(poses["t_receive"]) else 0.0
    else:
        keep = (poses["t_receive"] >= t_go) & (poses["t_receive"] <= t_stop + 0.5)
        t0 = t_go
    t = poses["t_receive"][keep] - t0
    p, q = poses["world_p"][keep], poses["world_q"][keep]
    ct = log.commands["t"] - t0
    stop = log.commands["stop"]
    left = np.where(stop, 0.0, log.commands["left"])
    right = np.where(stop, 0.0, log.commands["right"])
    after = ct >= 0
    phase = motor_phase(
        ct[after], left[after], right[after], world.robot.motor_gain, world.robot.max_motor_speed
    )
    robot = world.robot
    frames: list[Frame] = []
    for k in range(len(t)):
        if frames and t[k] < frames[-1].t + 1.0 / REPLAY_RATE:
            continue
        pl, pr = phase(float(t[k]))
        sides = np.where(np.asarray(robot.leg_sides) == 0, pl, pr)
        legs, _ = robot.leg_angle(sides + np.asarray(robot.leg_phase_offsets))
        frames.append(
            Frame(
                t=float(t[k]),
                p_world_body=tuple(float(v) for v in p[k]),  # type: ignore[arg-type]
                quat_world_body=tuple(float(v) for v in q[k]),  # type: ignore[arg-type]
                leg_angles=tuple(float(a) for a in legs),
            )
        )
    result = log.result or {}
    prediction = log.prediction or {}
    plan = log.plan or {}
    start = log.start or (tuple(plan["start"]) if plan.get("start") else world.scene.start)
    record = {
        "label": "the robot's run",
        "start": list(start) if start is not None else None,
        "goal": plan.get("goal") or (list(world.scene.goal) if world.scene.goal else None),
        "path": plan.get("path") or [],
        "trajectory": [[r[0], r[1], r[2], r[3]] for r in prediction.get("trajectory", [])],
    }
    rows = [
        ("scene", world.scene.name),
        ("log", path.name + ("" if log.complete else " (incomplete: the run was killed)")),
        ("stopped", f"{result.get('reason', '?')}: {result.get('detail', '')}"),
    ]
    if result.get("t_go") is not None and result.get("t_stop") is not None:
        rows.append(("drive time", f"{result['t_stop'] - result['t_go']:.2f} s"))
    if result.get("periods"):
        rows.append(("late periods", f"{result['late']} of {result['periods']}"))
    if prediction:
        rows.append(
            (
                "prediction",
                f"{prediction['outcome']} ({prediction['reason']}) in "
                f"{prediction['drive_time']:.2f} s",
            )
        )
        if prediction.get("trajectory") and len(p):
            end = np.asarray(prediction["trajectory"][-1][1:3])
            rows.append(
                ("robot's end to predicted", f"{float(np.linalg.norm(p[-1, :2] - end)):.3f} m")
            )
    lines = [("/live/track", tuple(map(tuple, p.tolist())), LIVE)] if len(p) >= 2 else []
    look_lines, look_rows = _look_ahead_shown(log, record["path"])
    lines += look_lines
    rows += look_rows
    note = "" if frames else "no pose of the robot was logged between Go and the stop"
    return Replay(
        title=f"{world.scene.name}: robot run {path.name}",
        world=world,
        trials=(record,),
        shown=0,
        frames=tuple(frames),
        note=note,
        rows=tuple(rows),
        lines=tuple(lines),
        legend="planned path black, the simulation's prediction blue, the robot green"
        + (
            "; the look-ahead's chance along the path ahead, green (holds) to red, and where "
            "its rollouts failed, red squares"
            if log.lookaheads
            else ""
        ),
    )


# -- the page's Share button ----------------------------------------------------------------------


def _share_job(events, world: World, record: dict, title: str) -> bytes:
    """In a child (a re-drive holds the GIL for seconds): the replay page of one trial."""
    frames, note = redrive(world, record)
    replay = Replay(title=title, world=world, trials=(record,), shown=0, frames=frames, note=note)
    return replay_html(replay).encode()


def share_trial(app: App, cmd: ShareCmd) -> None:
    """Export the trial chosen in *Show trial* (else the last one) as a replay page, sent to the
    browser that clicked as a download. Followed like a drive: progress, Cancel."""
    from roachplan.processes import Returned

    from ._jobs import Job, failure

    trials = app.scene_trials
    if not trials:
        app.page.notify(cmd.client_id, "Nothing to share", "Drive or run trials first.", error=True)
        return
    k = app.page.shown_trial() or len(trials)
    record: dict[str, Any] = dict(
        trials[k - 1], label=f"trial {k} ({trials[k - 1].get('label') or 'drive'})"
    )
    name = app.world.scene.name
    job = Job(_share_job, app.world, record, f"{name}: trial {k}")

    def step(events: list) -> bool:  # (it sends none: its progress is its time)
        t, total = job.elapsed, max(record.get("drive_wall_time") or 1.0, 1.0) + 2.0
        app.loop.progress(
            min(t / total, 0.99), f"Share: re-driving trial {k} and recording it, {t:.1f} s"
        )
        return job.done

    end = app.loop.follow(job, "Share", step)
    if not isinstance(job.outcome, Returned):
        why = failure(job) or f"the export was {end}"
        app.page.notify(cmd.client_id, "Share failed", why, error=True)
        app.page.set_status(f"Share failed: {why}")
        return
    html = job.value
    app.page.send_file(cmd.client_id, f"{name}-trial-{k}.html", html)
    app.page.set_status(
        f"Trial {k} exported as {name}-trial-{k}.html ({len(html) / 1e6:.1f} "
        f"MB): it opens offline in any browser."
    )
