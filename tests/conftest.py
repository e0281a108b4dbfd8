from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# Property-based fuzzing (issue 15): brief in `make test`, long in `make fuzz`
# (ROACHPLAN_FUZZ=1). Examples are derived from a fixed database-free seed so a run repeats.
settings.register_profile(
    "test",
    max_examples=60,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.register_profile(
    "fuzz",
    max_examples=5000,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
settings.load_profile("fuzz" if os.environ.get("ROACHPLAN_FUZZ") else "test")

# The test files in order of their last measured time, longest first: `make test`'s workers
# take whole files (--dist loadfile) in collection order, so a long file taken last leaves the
# other worker idle at the end. tests/file_durations.json holds each file's seconds (setup,
# call and teardown summed); ROACHPLAN_RECORD_DURATIONS=1 writes it anew from a run. A file it
# does not know yet goes first (its time unknown).
FILE_DURATIONS = Path(__file__).with_name("file_durations.json")
_measured: dict[str, float] = {}


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


def pytest_collection_modifyitems(config, items) -> None:
    try:
        seconds = json.loads(FILE_DURATIONS.read_text())
    except (OSError, ValueError):
        return
    files = list(dict.fromkeys(_file_of(item.nodeid) for item in items))
    rank = {f: k for k, f in enumerate(sorted(files, key=lambda f: -seconds.get(f, math.inf)))}
    items.sort(key=lambda item: rank[_file_of(item.nodeid)])  # (stable: a file keeps its order)


def pytest_runtest_logreport(report) -> None:
    _measured[_file_of(report.nodeid)] = _measured.get(_file_of(report.nodeid), 0.0) + float(
        report.duration
    )


def pytest_sessionfinish(session) -> None:
    if not os.environ.get("ROACHPLAN_RECORD_DURATIONS") or hasattr(session.config, "workerinput"):
        return  # (the controller writes, once, what every worker reported)
    try:
        seconds = json.loads(FILE_DURATIONS.read_text())
    except (OSError, ValueError):
        seconds = {}
    seconds.update({f: round(s, 1) for f, s in _measured.items()})
    FILE_DURATIONS.write_text(json.dumps(dict(sorted(seconds.items())), indent=1) + "\n")


ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"
ROACHPLAN = [sys.executable, "-m", "roachplan"]


def bridge_edge_x(world, y: float, yaw: float, room: float = 0.01) -> float:
    """x [m] of the pose (x, y, yaw) on the double bridge's left bridge, walking from its middle
    towards the gap in 2 mm steps: the first whose footprint `room` further on would not stand
    (the planner's validity checks)."""
    import numpy as np

    from roachplan.planning import check_states

    hf, fp, cfg = world.heightfield, world.footprint, world.scene.planner.validity
    for x in np.arange(-0.77, -0.45, 0.002):
        if not check_states(hf, fp, cfg, np.array([[x + room, y, yaw]])).valid[0]:
            return float(x)
    raise AssertionError("no edge found")


def roachplan(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the `roachplan` command line from the repository root, as a fork of a process that
    has imported it (tests/cli_forks.py): its own output, exit status and the test's
    environment, as a subprocess; never raises on failure (TimeoutExpired at timeout [s])."""
    from cli_forks import forked_roachplan

    return forked_roachplan(list(args), timeout)


def fresh_roachplan(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the `roachplan` command line from the repository root in a new interpreter (what a
    fork cannot show: a command's own imports and start-up, Open3D's log); never raises on
    failure."""
    return subprocess.run(
        [*ROACHPLAN, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False
    )


def synth_capture(
    out: Path, scene: str, intrinsics: str, eye=(0.0, -3.2, 1.8), target=(0.0, 0.0, 0.0)
) -> Path:
    """`roachplan synth-capture` of scene from eye to target (x, y, z [m]; by default the
    report's Kinect view of the double bridge, 3.2 m behind it and 1.8 m up) into out; the
    test fails if the command does."""
    made = roachplan(
        "synth-capture", scene, "--intrinsics", intrinsics, "-o", str(out),
        "--eye", ",".join(f"{v:.4f}" for v in eye),
        "--target", ",".join(f"{v:.4f}" for v in target),
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    return out


@pytest.fixture(scope="session")
def world():
    from roachplan.scenes import build_world, load_scene

    return build_world(load_scene("double_bridge"))


@pytest.fixture(scope="session")
def artifacts() -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS


@pytest.fixture
def app():
    """The browser app on double_bridge, in this process (to read its state), on a free port."""
    from roachplan.app._server import RoachApp
    from roachplan.scenes import build_world, load_scene

    app = RoachApp(build_world(load_scene("double_bridge")), host="127.0.0.1", port=free_port())
    yield app
    app.stop()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def server_url():
    """Start `roachplan serve` on a free port; yield its URL; stop it."""
    port = free_port()
    proc = subprocess.Popen(
        [*ROACHPLAN, "serve", "--port", str(port)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    url = None
    deadline = time.monotonic() + 60
    lines = []
    assert proc.stdout is not None  # stdout=PIPE
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if line.startswith("roachplan: serving"):
            url = line.rsplit(" at ", 1)[1].strip()
            break
    if url is None:
        proc.kill()
        pytest.fail("server did not start:\n" + "".join(lines))
    yield url
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
