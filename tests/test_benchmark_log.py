"""`roachplan benchmark` (issue 19): a real benchmark (OMPL, PyBullet) written as OMPL's log,
read back by OMPL's grammar into Planner Arena's SQLite schema, its physics columns checked
against the trials themselves.

The pinned wheel (ompl 1.7.0) does not ship scripts/ompl_benchmark_statistics.py, so
`read_benchmark_log` below is a faithful reading of that script's `readBenchmarkLog` (OMPL 1.7):
the same line-by-line grammar (tokens tested at the same positions, optional lines undone by a
seek), the same tables and the same SQL typing of values.
"""

from __future__ import annotations

import dataclasses
import math
import shutil
import sqlite3
from pathlib import Path

import pytest

from conftest import roachplan

SEED = 5
RUNS = 2
PLANNERS = ("prm", "rrtconnect")
TIME_LIMIT = 5.0
PHYSICS = ("simulated_success", "energy", "relative_energy", "drive_time", "failure_mode")


# --- a faithful reading of readBenchmarkLog ------------------------------------------------


def _value(f, index: int, expected: dict[int, str] | None):
    """readLogValue: the line's token at `index` if the expected tokens are where expected,
    else None and the line is left unread."""
    start = f.tell()
    tokens = f.readline().split()
    for i, token in (expected or {}).items():
        if tokens[i] != token:
            f.seek(start)
            return None
    return tokens[index]


def _required(what: str, f, index: int, expected: dict[int, str] | None = None) -> str:
    v = _value(f, index, expected)
    if v is None:
        raise ValueError(f"Unable to read {what}")
    return v


def _multiline(f, optional: bool):
    start = f.tell()
    line = f.readline()
    if not line.startswith("<<<|"):
        if optional:
            f.seek(start)
            return None
        raise ValueError("Expected prefix <<<| was not found")
    text, line = "", f.readline()
    while not line.startswith("|>>>"):
        text, line = text + line, f.readline()
    return text


def read_benchmark_log(dbname: Path, filename: Path) -> None:  # noqa: PLR0912, PLR0915
    """readBenchmarkLog(dbname, [filename], moveitformat=False), step by step, in one function
    as the script has it."""
    conn = sqlite3.connect(dbname)
    c = conn.cursor()
    c.execute("PRAGMA FOREIGN_KEYS = ON")
    c.executescript(
        """CREATE TABLE IF NOT EXISTS experiments
        (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512), totaltime REAL,
        timelimit REAL, memorylimit REAL, runcount INTEGER, version VARCHAR(128),
        hostname VARCHAR(1024), cpuinfo TEXT, date DATETIME, seed VARCHAR(24), setup TEXT);
        CREATE TABLE IF NOT EXISTS plannerConfigs
        (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512) NOT NULL, settings TEXT);
        CREATE TABLE IF NOT EXISTS enums
        (name VARCHAR(512), value INTEGER, description TEXT, PRIMARY KEY (name, value));
        CREATE TABLE IF NOT EXISTS runs
        (id INTEGER PRIMARY KEY AUTOINCREMENT, experimentid INTEGER, plannerid INTEGER,
        FOREIGN KEY (experimentid) REFERENCES experiments(id) ON DELETE CASCADE,
        FOREIGN KEY (plannerid) REFERENCES plannerConfigs(id) ON DELETE CASCADE);
        CREATE TABLE IF NOT EXISTS progress
        (runid INTEGER, time REAL, PRIMARY KEY (runid, time),
        FOREIGN KEY (runid) REFERENCES runs(id) ON DELETE CASCADE)"""
    )
    with open(filename) as f:
        start = f.tell()
        libname = _value(f, 0, {1: "version"}) or "OMPL"
        f.seek(start)
        version = " ".join([libname, _value(f, -1, {1: "version"}) or "0.0.0"])
        expname = _required("experiment name", f, -1, {0: "Experiment"})
        nexp = int(_value(f, 0, {-2: "experiment", -1: "properties"}) or 0)
        expprops = {}
        for _ in range(nexp):
            entry = f.readline().strip().split(" = ")
            name_type = entry[0].split(" ")
            expprops["".join(name_type[:-1]).replace("-", "_")] = (entry[1], name_type[-1])
        c.execute("PRAGMA table_info(experiments)")
        columns = [col[1] for col in c.fetchall()]
        for name in sorted(expprops):
            if name not in columns:
                c.execute(f"ALTER TABLE experiments ADD {name} {expprops[name][1]}")
        hostname = _required("hostname", f, -1, {0: "Running"})
        line = f.readline()
        assert line.startswith("Starting"), "Expected prefix Starting was not found"
        date = " ".join(line.split()[2:])
        setup = _multiline(f, optional=False)
        cpuinfo = _multiline(f, optional=True)
        seed = _required("random seed", f, 0, {-2: "random", -1: "seed"})
        timelimit = float(_required("time limit", f, 0, {-3: "seconds", -2: "per", -1: "run"}))
        memorylimit = float(_required("memory limit", f, 0, {-3: "MB", -2: "per", -1: "run"}))
        nruns = _value(f, 0, {-3: "runs", -2: "per", -1: "planner"})
        nruns = -1 if nruns is None else int(nruns)
        totaltime = float(_required("total time", f, 0, {-3: "collect", -2: "the", -1: "data"}))
        for _ in range(int(_value(f, 0, {-2: "enum"}) or 0)):
            enum = f.readline()[:-1].split("|")
            c.execute("SELECT * FROM enums WHERE name IS ?", (enum[0],))
            if c.fetchone() is None:
                for j in range(len(enum) - 1):
                    c.execute("INSERT INTO enums VALUES (?,?,?)", (enum[0], j, enum[j + 1]))
        names = [
            "name",
            "totaltime",
            "timelimit",
            "memorylimit",
            "runcount",
            "version",
            "hostname",
            "cpuinfo",
            "date",
            "seed",
            "setup",
            *expprops,
        ]
        values = [
            expname,
            totaltime,
            timelimit,
            memorylimit,
            nruns,
            version,
            hostname,
            cpuinfo,
            date,
            seed,
            setup,
            *(v for v, _ in expprops.values()),
        ]
        c.execute(
            f"INSERT INTO experiments ({','.join(names)}) VALUES ({','.join('?' * len(values))})",
            values,
        )
        experiment = c.lastrowid
        for _ in range(int(_required("planner count", f, 0, {-1: "planners"}))):
            planner_name = f.readline()[:-1]
            settings = ""
            for _ in range(int(f.readline().split()[0])):
                settings = settings + f.readline() + ";"
            c.execute(
                "SELECT id FROM plannerConfigs WHERE (name=? AND settings=?)",
                (planner_name, settings),
            )
            p = c.fetchone()
            if p is None:
                c.execute(
                    "INSERT INTO plannerConfigs VALUES (?,?,?)", (None, planner_name, settings)
                )
                planner = c.lastrowid
            else:
                planner = p[0]
            c.execute("PRAGMA table_info(runs)")
            columns = [col[1] for col in c.fetchall()]
            props = ["experimentid", "plannerid"]
            for _ in range(int(f.readline().split()[0])):
                field = f.readline().split()
                if "_".join(field[:-1]) not in columns:
                    c.execute(f"ALTER TABLE runs ADD {'_'.join(field[:-1])} {field[-1]}")
                props.append("_".join(field[:-1]))
            insert = f"INSERT INTO runs ({','.join(props)}) VALUES ({','.join('?' * len(props))})"
            run_ids = []
            for _ in range(int(f.readline().split()[0])):
                data = [
                    None if not x or x in ("nan", "inf") else x
                    for x in f.readline().split("; ")[:-1]
                ]
                c.execute(insert, (experiment, planner, *data))
                run_ids.append(c.lastrowid)
            next_line = f.readline().strip()
            if next_line != ".":  # progress properties, then one line of samples per run
                c.execute("PRAGMA table_info(progress)")
                columns = [col[1] for col in c.fetchall()]
                pnames = ["runid"]
                for _ in range(int(next_line.split()[0])):
                    field = f.readline().split()
                    if "_".join(field[:-1]) not in columns:
                        c.execute(f"ALTER TABLE progress ADD {'_'.join(field[:-1])} {field[-1]}")
                    pnames.append("_".join(field[:-1]))
                insert = (
                    f"INSERT INTO progress ({','.join(pnames)}) VALUES "
                    f"({','.join('?' * len(pnames))})"
                )
                for j in range(int(f.readline().split()[0])):
                    for sample in f.readline().split(";")[:-1]:
                        data = [
                            None if not x or x in ("nan", "inf") else x
                            for x in sample.split(",")[:-1]
                        ]
                        c.execute(insert, (run_ids[j], *data))
                f.readline()
    conn.commit()
    conn.close()


# --- the benchmark -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bench(tmp_path_factory, artifacts) -> dict:
    """2 planners x 2 runs on double_bridge, simulated; the log, our database and the log read
    by the script's grammar into a database of its own."""
    folder = tmp_path_factory.mktemp("bench")
    log, db, parsed = folder / "bench.log", folder / "bench.db", folder / "parsed.db"
    out = roachplan(
        "benchmark",
        "--scene",
        "double_bridge",
        "--planners",
        ",".join(PLANNERS),
        "--runs",
        str(RUNS),
        "--time-limit",
        str(TIME_LIMIT),
        "--seed",
        str(SEED),
        "--simulate",
        "--quiet",
        "-o",
        str(log),
        "--db",
        str(db),
    )
    assert out.returncode == 0, out.stderr
    read_benchmark_log(parsed, log)
    for p in (log, db):  # for a look, or Planner Arena
        shutil.copy(p, artifacts / f"benchmark_{p.name}")
    return {"log": log, "db": db, "parsed": parsed, "stdout": out.stdout}


def _rows(db: Path, sql: str) -> list[dict]:
    conn = sqlite3.connect(db)
    conn.row_factory = sqlite3.Row
    try:
        return [dict(r) for r in conn.execute(sql)]
    finally:
        conn.close()


@pytest.mark.slow
def test_log_reads_into_planner_arena_tables(bench):
    (exp,) = _rows(bench["parsed"], "SELECT * FROM experiments")
    assert exp["name"] == "double_bridge" and exp["version"] == "OMPL 1.7.0"
    assert exp["runcount"] == RUNS and exp["timelimit"] == TIME_LIMIT
    assert exp["seed"] == str(SEED) and exp["simulated"] == 1
    assert "written by roachplan" in exp["setup"] and exp["totaltime"] > 0
    configs = _rows(bench["parsed"], "SELECT * FROM plannerConfigs ORDER BY id")
    assert [c["name"] for c in configs] == [f"geometric_{p}" for p in PLANNERS]
    assert f"time_limit = {TIME_LIMIT}\n;" in configs[0]["settings"]
    enums = _rows(bench["parsed"], "SELECT * FROM enums WHERE name = 'failure_mode'")
    assert [e["description"] for e in sorted(enums, key=lambda e: e["value"])][:2] == [
        "none",
        "fell",
    ]
    runs = _rows(bench["parsed"], "SELECT * FROM runs")
    assert len(runs) == len(PLANNERS) * RUNS
    for column in (
        *PHYSICS,
        "time",
        "solved",
        "status",
        "solution_length",
        "graph_states",
        "graph_motions",
        "collision_checks",
    ):
        assert column in runs[0], column


@pytest.mark.slow
def test_physics_columns_match_the_trials_themselves(bench, world):
    from roachplan.experiments import run_trial

    runs = _rows(
        bench["parsed"],
        "SELECT plannerConfigs.name AS planner, runs.*, s.description AS status_text, "
        "f.description AS failure_text FROM runs JOIN plannerConfigs ON runs.plannerid = "
        "plannerConfigs.id JOIN enums s ON s.name = 'status' AND s.value = runs.status "
        "JOIN enums f ON f.name = 'failure_mode' AND f.value = runs.failure_mode ORDER BY runs.id",
    )
    assert [(r["planner"], r["seed"]) for r in runs] == [
        (f"geometric_{p}", SEED + k) for p in PLANNERS for k in range(RUNS)
    ]
    straight = math.dist(world.scene.start[:2], world.scene.goal[:2])
    for r in runs:
        cfg = dataclasses.replace(
            world.scene.planner, name=r["planner"].removeprefix("geometric_"), time_limit=TIME_LIMIT
        )
        trial = run_trial(world, seed=r["seed"], planner=cfg)  # the same plan, driven afresh
        assert r["solved"] == int(trial.path_found)
        assert r["status_text"] == ("Exact solution" if trial.path_found else "Timeout")
        assert r["simulated_success"] == int(trial.outcome == "success")
        assert r["failure_text"] == ("none" if trial.outcome == "success" else trial.outcome)
        if trial.outcome == "no_path":
            assert r["energy"] is None and r["drive_time"] is None
            continue
        # The log writes floats round-trip exact, and the same seed drives the same way.
        assert r["energy"] == trial.energy and r["energy"] > 0
        assert r["relative_energy"] == trial.relative_energy
        assert r["drive_time"] == trial.drive_time
        assert r["solution_length"] >= straight
        assert r["graph_states"] >= 2 and r["graph_motions"] >= 1
        assert r["time"] > 0


@pytest.mark.slow
def test_our_database_is_what_the_script_makes_of_the_log(bench):
    conn = sqlite3.connect(bench["db"])
    assert conn.execute("PRAGMA application_id").fetchone()[0] == 0x52504C4E
    conn.close()
    for table in ("experiments", "plannerConfigs", "enums", "runs", "progress"):
        info = f"PRAGMA table_info({table})"
        ours, script = _rows(bench["db"], info), _rows(bench["parsed"], info)
        assert [(c["name"], c["type"]) for c in ours] == [(c["name"], c["type"]) for c in script]
        every = f"SELECT * FROM {table} ORDER BY 1, 2"
        assert _rows(bench["db"], every) == _rows(bench["parsed"], every), table


def test_status_enum_is_omplS_own():
    from roachplan.experiments._benchmark import STATUS
    from roachplan.planning._ompl_import import ob

    count = int(ob.PlannerStatus.TYPE_COUNT)
    assert STATUS == tuple(
        ob.PlannerStatus(ob.PlannerStatus.StatusType(i)).asString() for i in range(count)
    )


def test_smoothness_is_omplS_formula():
    import numpy as np

    from roachplan.experiments._benchmark import _xy_smoothness

    assert _xy_smoothness(np.array([[0, 0], [1, 0], [2, 0], [3, 0.0]])) == pytest.approx(0)
    # One right angle between unit segments: (2 (pi/2) / (1 + 1))^2.
    corner = np.array([[0, 0], [1, 0], [1, 1.0]])
    assert _xy_smoothness(corner) == pytest.approx((math.pi / 2) ** 2)
    # Halving the segments of the same corner quadruples it (the angle over a shorter arc).
    assert _xy_smoothness(corner / 2) == pytest.approx(4 * (math.pi / 2) ** 2)


BASE = ["benchmark", "--scene", "double_bridge", "--runs", "1", "--quiet"]


@pytest.mark.parametrize(
    ("flags", "says"),
    [
        (["--planners", "prm,foo"], "'foo' is not a planner; choose from prm,"),
        (["--planners", "prm,prm"], "a planner is named twice"),
        (["--planners", "prm", "--runs", "0"], "--runs 0: expected a whole number from 1"),
        (["--planners", "prm", "--time-limit", "-1"], "--time-limit -1: expected a number above 0"),
        (["--planners", "prm", "--seed", "2147483645", "--runs", "3"], "give a smaller --seed"),
        (["--planners", "prm", "-o", "{dir}/out.txt"], "must end in one of .log"),
        (["--planners", "prm", "--db", "{dir}/out.csv"], "--db"),
        (["--planners", "prm", "-o", "{dir}/nowhere/out.log"], "does not exist"),
    ],
)
def test_bad_flags_are_refused_in_one_line(tmp_path, flags, says):
    args = [*BASE, "-o", str(tmp_path / "out.log"), *flags]
    out = roachplan(*(a.replace("{dir}", str(tmp_path)) for a in args))
    assert out.returncode == 2, out.stderr
    assert says in out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == [], "nothing is written when refused"


@pytest.mark.slow
def test_replaces_its_own_outputs_only(bench, tmp_path):
    foreign_log, foreign_db = tmp_path / "notes.log", tmp_path / "mine.db"
    foreign_log.write_text("my notes\n")
    conn = sqlite3.connect(foreign_db)
    conn.execute("CREATE TABLE t (x)")
    conn.commit()
    conn.close()
    before = foreign_db.read_bytes()
    small = [*BASE, "--planners", "rrtconnect", "--time-limit", "5"]
    out = roachplan(*small, "-o", str(foreign_log))
    assert out.returncode == 2 and "is not a benchmark log roachplan wrote" in out.stderr
    out = roachplan(*small, "-o", str(tmp_path / "new.log"), "--db", str(foreign_db))
    assert out.returncode == 2 and "--force" in out.stderr
    assert foreign_log.read_text() == "my notes\n" and foreign_db.read_bytes() == before
    assert not (tmp_path / "new.log").exists()
    # Its own earlier log and database are replaced: now one planner, one run, no physics.
    log, db = tmp_path / "old.log", tmp_path / "old.db"
    shutil.copy(bench["log"], log)
    shutil.copy(bench["db"], db)
    out = roachplan(*small, "-o", str(log), "--db", str(db))
    assert out.returncode == 0, out.stderr
    text = log.read_text()
    assert "1 planners\ngeometric_rrtconnect\n" in text and "failure mode" not in text
    assert len(_rows(db, "SELECT * FROM runs")) == 1
