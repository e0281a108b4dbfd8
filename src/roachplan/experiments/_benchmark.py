"""`roachplan benchmark`: planners compared in OMPL's benchmark format (issue 19).

Each planner plans `runs` times on one scene, run k with seed seed + k (every planner sees the
same seeds), through the same `plan` the trials use; with `simulate`, each plan is then driven
in PyBullet (`finish_trial`) and the drive's outcome joins OMPL's usual columns.

Two outputs, both what OMPL's tools make:
- `benchmark_log`: the text log `ompl::tools::Benchmark::saveResultsToFile` writes, in the
  grammar `ompl_benchmark_statistics.py` reads (`readBenchmarkLog`, OMPL 1.7; the EBNF in OMPL's
  doc/markdown/benchmark.md, "The benchmark logfile format").
- `write_benchmark_db`: the SQLite database that script makes of such a log, which Planner Arena
  (plannerarena.org) opens: tables experiments, plannerConfigs, enums, runs, progress; one
  column of `runs` per run property, named with its words joined by "_".

Columns we cannot fill honestly are left out rather than faked: OMPL's "memory" (our plans run
in a forked child whose growth is not measured) and "solution clearance" (our validity checker
has no clearance).
"""

from __future__ import annotations

import dataclasses
import math
import re
import socket
import sqlite3
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import get_args

import numpy as np

from roachplan.planning import PlannerConfig, PlanResult
from roachplan.scenes import World

from ._outputs import WRITTEN_BY, atomic_path
from ._trial import TrialOutcome, finish_trial, plan

STATUS = (
    "Unknown status",
    "Invalid start",
    "Invalid goal",
    "Unrecognized goal type",
    "Timeout",
    "Approximate solution",
    "Exact solution",
    "Crash",
    "Unknown status",
    "Unknown status",
)
"""OMPL's `status` enum as OMPL 1.7.0's Benchmark writes it: PlannerStatus(i).asString() for i
below TYPE_COUNT (1.7.0 names ABORT and INFEASIBLE "Unknown status"; a test checks the list
against the bindings)."""
EXACT_SOLUTION, TIMEOUT = 6, 4
"""Our two statuses: a plan found, or none within the budget (OMPL's TIMEOUT covers both its
time and its iteration limits)."""
FAILURE_MODES: tuple[str, ...] = ("none",) + tuple(
    o for o in get_args(TrialOutcome) if o != "success"
)
"""Values of the `failure_mode` enum: "none" for a drive that reached the goal, else the
trial's outcome (no_path: nothing to drive)."""
DB_APPLICATION_ID = 0x52504C4E
"""SQLite `application_id` of the databases we write ("RPLN"): `--db` replaces such a file
without --force."""
PLANNER_PREFIX = "geometric_"
"""OMPL names geometric planners "geometric_<name>"; Planner Arena strips the prefix."""


@dataclass(frozen=True, kw_only=True)
class BenchmarkRun:
    """One planner run, with its drive when simulated."""

    planner: str
    """roachplan planner name (PLANNER_NAMES)."""
    seed: int
    """Seed of the run's plan (and drive)."""
    time: float
    """Wall time spent planning [s]."""
    solved: bool
    status: int
    """Index into STATUS."""
    solution_length: float | None
    """Length of the solution in the plane, over the planner's states [m]; None: unsolved."""
    solution_smoothness: float | None
    """OMPL's PathGeometric::smoothness over the states in the plane [1/m^2] (0: straight);
    None: unsolved."""
    solution_segments: int | None
    collision_checks: int
    """States whose validity was computed [-] (OMPL's "collision checks")."""
    graph_states: int
    """Vertices of the planner's graph [-]."""
    graph_motions: int
    """Edges of the planner's graph, as OMPL's PlannerData counts them (PRM's both ways) [-]."""
    outcome: TrialOutcome | None = None
    """The drive's outcome (no_path: no plan); None: not simulated."""
    energy: float | None = None
    """Energy the leg motors spent [J]; None: not simulated or nothing driven."""
    relative_energy: float | None = None
    """energy / energy of the flat-floor walk of the start-goal distance [-]."""
    drive_time: float | None = None
    """Simulated time of the drive [s]."""

    @property
    def simulated_success(self) -> bool:
        return self.outcome == "success"

    @property
    def failure_mode(self) -> int:
        """Index into FAILURE_MODES."""
        return FAILURE_MODES.index("none" if self.outcome == "success" else self.outcome)


@dataclass(frozen=True, kw_only=True)
class BenchmarkResult:
    """A whole benchmark: what the log's header and planner blocks say."""

    name: str
    """Experiment name (no whitespace: OMPL's reader takes the line's last word)."""
    hostname: str
    started: str
    """Start, UTC, as OMPL writes it (boost's to_simple_string: 2026-Nov-24 05:16:46.123456)."""
    setup: str
    """Free text: the problem (scene, start, goal, bounds, driver)."""
    seed: int
    """Seed of run 0; run k uses seed + k."""
    time_limit: float
    """Per plan [s]."""
    memory_limit: float
    """Per plan [MB] (the planning child's address-space limit; 0: none)."""
    runs_per_planner: int
    total_time: float
    """Wall time of the whole benchmark [s]."""
    simulated: bool
    planners: tuple[PlannerConfig, ...]
    runs: tuple[BenchmarkRun, ...]
    ompl_version: str

    def runs_of(self, planner: str) -> list[BenchmarkRun]:
        return [r for r in self.runs if r.planner == planner]


def _xy_smoothness(xy: np.ndarray) -> float:
    """OMPL's PathGeometric::smoothness() on a planar polyline ((K, 2) [m]): the sum over
    consecutive segment pairs a, b of (2 * turning angle / (a + b))^2; a straight path is 0."""
    if len(xy) < 3:
        return 0.0
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    a, b = seg[:-1], seg[1:]
    c = np.linalg.norm(xy[2:] - xy[:-2], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos = (a * a + b * b - c * c) / (2.0 * a * b)
        # OMPL skips the triples where acos is undefined or the corner is flat (cos = -1).
        keep = (cos > -1.0) & (cos < 1.0)
        k = 2.0 * (math.pi - np.arccos(cos[keep])) / (a[keep] + b[keep])
    return float(np.sum(k * k))


def benchmark_run(planned: PlanResult, trial=None) -> BenchmarkRun:
    """The log's row of one plan (and of its drive, a TrialResult, when simulated)."""
    xy = planned.states[:, :2]
    solved = bool(planned.found)
    physics = {}
    if trial is not None:
        driven = trial.outcome != "no_path"
        physics = dict(
            outcome=trial.outcome,
            energy=trial.energy if driven else None,
            relative_energy=trial.relative_energy if driven else None,
            drive_time=trial.drive_time if driven else None,
        )
    return BenchmarkRun(
        planner=planned.planner,
        seed=planned.seed,
        time=planned.plan_time,
        solved=solved,
        status=EXACT_SOLUTION if solved else TIMEOUT,
        solution_length=(
            float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))) if solved else None
        ),
        solution_smoothness=_xy_smoothness(xy) if solved else None,
        solution_segments=len(xy) - 1 if solved else None,
        collision_checks=planned.validity_checks,
        graph_states=planned.graph_states,
        graph_motions=len(planned.roadmap),
        **physics,
    )


def run_benchmark(
    world: World,
    planners: Sequence[PlannerConfig],
    *,
    runs: int,
    seed: int,
    simulate: bool = False,
    on_run: Callable[[BenchmarkRun], object] | None = None,
) -> BenchmarkResult:
    """Plan `runs` times with each planner config from the scene's start to its goal (run k:
    seed + k), driving each plan when `simulate`; on_run(run) after each (progress)."""
    from importlib.metadata import version

    from roachplan.processes import child_memory_limit

    scene = world.scene
    started = datetime.now(UTC).strftime("%Y-%b-%d %H:%M:%S.%f")
    t0 = time.perf_counter()
    out: list[BenchmarkRun] = []
    sim = world.simulation() if simulate else None  # one PyBullet client; reset per drive
    try:
        for given in planners:
            # keep_roadmap: the graph's size (graph states, graph motions) comes back with it.
            cfg = dataclasses.replace(given, keep_roadmap=True)
            for k in range(runs):
                planned = plan(world, seed=seed + k, planner=cfg)
                trial = None
                if sim is not None:
                    trial = finish_trial(
                        world, planned, start=world.start, goal=world.goal, sim=sim
                    )
                out.append(benchmark_run(planned, trial))
                if on_run is not None:
                    on_run(out[-1])
    finally:
        if sim is not None:
            sim.close()
    (xa, ya), (xb, yb) = world.bounds
    setup = (
        "\n".join(
            [
                WRITTEN_BY,
                f"scene {scene.name}",
                "start x y yaw [m, m, rad] " + " ".join(f"{v:g}" for v in world.start),
                "goal x y yaw [m, m, rad] " + " ".join(f"{v:g}" for v in world.goal),
                f"bounds x [{xa:g}, {xb:g}] y [{ya:g}, {yb:g}] m",
                f"run k plans with seed {seed} + k"
                + (
                    f"; each plan driven by the {scene.driver.kind} driver in PyBullet"
                    if simulate
                    else ""
                ),
            ]
        )
        + "\n"
    )
    return BenchmarkResult(
        name=re.sub(r"\s+", "_", scene.name) or "NO_NAME",
        hostname=(socket.gethostname().split() or ["UNKNOWN"])[0],
        started=started,
        setup=setup,
        seed=seed,
        time_limit=max(cfg.time_limit for cfg in planners),
        memory_limit=child_memory_limit() / (1 << 20),
        runs_per_planner=runs,
        total_time=time.perf_counter() - t0,
        simulated=simulate,
        planners=tuple(planners),
        runs=tuple(out),
        ompl_version=version("ompl"),
    )


def _settings(cfg: PlannerConfig) -> list[tuple[str, str]]:
    """The planner's common properties (name, value), sorted as OMPL sorts them."""
    flat = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if f.name == "keep_roadmap":  # how we ask for the graph, not how we plan
            continue
        if dataclasses.is_dataclass(value):
            flat.update(
                {f"{f.name}.{g.name}": getattr(value, g.name) for g in dataclasses.fields(value)}
            )
        else:
            flat[f.name] = value
    return sorted((k, _text(v)) for k, v in flat.items())


def _run_properties(simulated: bool) -> list[tuple[str, str, Callable[[BenchmarkRun], object]]]:
    """(name, type, value of a run) of every run column, sorted by "name TYPE" as OMPL's
    Benchmark sorts its property keys."""
    props = [
        ("time", "REAL", lambda r: r.time),
        ("solved", "BOOLEAN", lambda r: r.solved),
        ("approximate solution", "BOOLEAN", lambda r: False),  # we accept exact paths only
        ("status", "ENUM", lambda r: r.status),
        ("solution length", "REAL", lambda r: r.solution_length),
        ("solution smoothness", "REAL", lambda r: r.solution_smoothness),
        ("solution segments", "INTEGER", lambda r: r.solution_segments),
        ("collision checks", "INTEGER", lambda r: r.collision_checks),
        ("graph states", "INTEGER", lambda r: r.graph_states),
        ("graph motions", "INTEGER", lambda r: r.graph_motions),
        ("seed", "INTEGER", lambda r: r.seed),
    ]
    if simulated:
        props += [
            ("simulated success", "BOOLEAN", lambda r: r.simulated_success),
            ("energy", "REAL", lambda r: r.energy),
            ("relative energy", "REAL", lambda r: r.relative_energy),
            ("drive time", "REAL", lambda r: r.drive_time),
            ("failure mode", "ENUM", lambda r: r.failure_mode),
        ]
    return sorted(props, key=lambda p: f"{p[0]} {p[1]}")


def _enums(simulated: bool) -> list[tuple[str, tuple[str, ...]]]:
    """(name, values): the name is the run column's, words joined by "_", which is how the
    statistics script and Planner Arena find the descriptions of an ENUM column."""
    return [("status", STATUS)] + ([("failure_mode", FAILURE_MODES)] if simulated else [])


def _text(v) -> str:
    """A value as the log writes it: booleans 0/1, floats round-trip exact, None empty."""
    if v is None:
        return ""
    if isinstance(v, bool | np.bool_):
        return str(int(v))
    if isinstance(v, float | np.floating):
        return repr(float(v)) if math.isfinite(v) else ("nan" if math.isnan(v) else "inf")
    return str(v)


def _planner_name(cfg: PlannerConfig) -> str:
    return PLANNER_PREFIX + cfg.name


def benchmark_log(result: BenchmarkResult) -> str:
    """The OMPL benchmark log of `result` (what ompl::tools::Benchmark writes)."""
    lines = [
        f"OMPL version {result.ompl_version}",
        f"Experiment {result.name}",
        "1 experiment properties",
        f"simulated BOOLEAN = {int(result.simulated)}",
        f"Running on {result.hostname}",
        f"Starting at {result.started}",
        "<<<|",
        result.setup.rstrip("\n"),
        "|>>>",
        f"{result.seed} is the random seed",
        f"{_text(result.time_limit)} seconds per run",
        f"{_text(result.memory_limit)} MB per run",
        f"{result.runs_per_planner} runs per planner",
        f"{_text(result.total_time)} seconds spent to collect the data",
    ]
    enums = _enums(result.simulated)
    lines.append(f"{len(enums)} enum types")
    lines += ["|".join((name, *values)) for name, values in enums]
    props = _run_properties(result.simulated)
    lines.append(f"{len(result.planners)} planners")
    for cfg in result.planners:
        settings = _settings(cfg)
        runs = result.runs_of(cfg.name)
        lines.append(_planner_name(cfg))
        lines.append(f"{len(settings)} common properties")
        lines += [f"{k} = {v}" for k, v in settings]
        lines.append(f"{len(props)} properties for each run")
        lines += [f"{name} {kind}" for name, kind, _ in props]
        lines.append(f"{len(runs)} runs")
        # Every value ends in "; ", the last one too: the reader drops what follows the last.
        lines += ["".join(f"{_text(value(r))}; " for _, _, value in props) for r in runs]
        lines.append(".")  # no progress properties: OMPL writes the terminator alone
    return "\n".join(lines) + "\n"


def write_benchmark_db(result: BenchmarkResult, path: str | Path) -> Path:
    """Write `result` as the SQLite database ompl_benchmark_statistics.py makes of its log (the
    schema of its readBenchmarkLog; Planner Arena opens it), atomically, replacing `path`."""
    props = _run_properties(result.simulated)
    with atomic_path(path) as tmp:
        conn = sqlite3.connect(tmp)
        try:
            _fill_db(conn, result, props)
            conn.commit()
        finally:
            conn.close()
    return Path(path)


def _column(name: str) -> str:
    return "_".join(name.split())


def _fill_db(conn: sqlite3.Connection, result: BenchmarkResult, props) -> None:
    c = conn.cursor()
    c.execute(f"PRAGMA application_id = {DB_APPLICATION_ID}")
    c.execute("PRAGMA foreign_keys = ON")
    c.executescript(
        """
        CREATE TABLE experiments (
            id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512), totaltime REAL,
            timelimit REAL, memorylimit REAL, runcount INTEGER, version VARCHAR(128),
            hostname VARCHAR(1024), cpuinfo TEXT, date DATETIME, seed VARCHAR(24), setup TEXT,
            simulated BOOLEAN);
        CREATE TABLE plannerConfigs (
            id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512) NOT NULL, settings TEXT);
        CREATE TABLE enums (
            name VARCHAR(512), value INTEGER, description TEXT, PRIMARY KEY (name, value));
        CREATE TABLE runs (
            id INTEGER PRIMARY KEY AUTOINCREMENT, experimentid INTEGER, plannerid INTEGER,
            FOREIGN KEY (experimentid) REFERENCES experiments(id) ON DELETE CASCADE,
            FOREIGN KEY (plannerid) REFERENCES plannerConfigs(id) ON DELETE CASCADE);
        CREATE TABLE progress (
            runid INTEGER, time REAL, PRIMARY KEY (runid, time),
            FOREIGN KEY (runid) REFERENCES runs(id) ON DELETE CASCADE);
        """
    )
    for name, kind in ((_column(n), k) for n, k, _ in props):
        c.execute(f"ALTER TABLE runs ADD {name} {kind}")
    for name, values in _enums(result.simulated):
        c.executemany(
            "INSERT INTO enums VALUES (?, ?, ?)", [(name, j, v) for j, v in enumerate(values)]
        )
    c.execute(
        "INSERT INTO experiments (name, totaltime, timelimit, memorylimit, runcount, version, "
        "hostname, cpuinfo, date, seed, setup, simulated) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
        (
            result.name,
            result.total_time,
            result.time_limit,
            result.memory_limit,
            result.runs_per_planner,
            f"OMPL {result.ompl_version}",
            result.hostname,
            None,
            result.started,
            str(result.seed),
            result.setup,
            int(result.simulated),
        ),
    )
    experiment = c.lastrowid
    columns = ", ".join(["experimentid", "plannerid"] + [_column(n) for n, _, _ in props])
    marks = ", ".join("?" * (len(props) + 2))
    for cfg in result.planners:
        # The script's settings: each common-property line with its newline, then ";".
        settings = "".join(f"{k} = {v}\n;" for k, v in _settings(cfg))
        c.execute(
            "INSERT INTO plannerConfigs (name, settings) VALUES (?, ?)",
            (_planner_name(cfg), settings),
        )
        planner = c.lastrowid
        for r in result.runs_of(cfg.name):
            values = [_db_value(value(r)) for _, _, value in props]
            c.execute(
                f"INSERT INTO runs ({columns}) VALUES ({marks})", [experiment, planner, *values]
            )


def _db_value(v):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return None  # the script stores "", "nan" and "inf" as NULL
    if isinstance(v, bool | np.bool_):
        return int(v)
    return v


def is_benchmark_db(head: bytes) -> bool:
    """Whether a file's first bytes are a SQLite database we wrote (its application_id)."""
    return head.startswith(b"SQLite format 3\0") and head[68:72] == DB_APPLICATION_ID.to_bytes(
        4, "big"
    )


def benchmark_bar(enabled: bool, total: int):
    """The progress bar of a benchmark's runs, in the experiment's style."""
    from ._runner import _bar

    return _bar(enabled, total, 0, "runs")
