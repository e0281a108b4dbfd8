from __future__ import annotations

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

ROOT = Path(__file__).resolve().parent.parent
ARTIFACTS = ROOT / "test-artifacts"
ROACHPLAN = [sys.executable, "-m", "roachplan"]

# The slow tests of two files being rewritten on another branch, marked here (`make test-fast`
# leaves them out) until those files carry their own @pytest.mark.slow. None: every test.
_SLOW_ELSEWHERE: dict[str, frozenset[str] | None] = {
    "test_page_choose.py": None,  # the Choose path panel in a browser
    "test_choose.py": frozenset(
        {
            "test_the_safe_route_wins_and_the_same_seed_gives_the_same_ranking",
            "test_validate_agrees_with_the_prediction_within_its_intervals",
            "test_a_race_chooses_wrongly_no_more_often_than_its_confidence_allows",
            "test_choose_on_a_ray_cluster_by_address_drives_the_same_rollouts",
            "test_a_bad_uncertainty_is_refused_naming_file_key_and_range",
            "test_choose_tells_the_candidates_it_planned_then_its_race",
            "test_a_scene_s_uncertainty_changes_the_draws_of_its_rollouts",
        }
    ),
}


@pytest.hookimpl(tryfirst=True)  # (before -m "not slow" deselects by marker)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name not in _SLOW_ELSEWHERE:
            continue
        names = _SLOW_ELSEWHERE[item.path.name]
        if names is None or getattr(item, "originalname", item.name) in names:
            item.add_marker(pytest.mark.slow)


def roachplan(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the `roachplan` command line from the repository root; never raises on failure."""
    return subprocess.run(
        [*ROACHPLAN, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, check=False
    )


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
