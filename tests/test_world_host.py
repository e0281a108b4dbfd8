"""The app's world host (issue 16): plans and drives run in forks of a process that received
the world once, so a click does not wait for the world to be sent. A fork plans what a child
sent the world plans (the same seed gives the same path), Cancel kills the fork and the host
serves the next job, and the app falls back to a plain child when its host has died."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from roachplan.app._jobs import Job, WorldHost, _plan_job, failure


def _paths(job: Job, timeout: float = 120) -> list[np.ndarray]:
    """The paths a plan job sent, once it has finished."""
    out, end = [], time.monotonic() + timeout
    while not job.done and time.monotonic() < end:
        for attempt in job.poll(timeout=0.5):
            if attempt.plan is not None:
                out.append(np.asarray(attempt.plan.plan.path_xyz))
        assert failure(job) is None, failure(job)
    assert job.done, "the plan job did not finish"
    return out


def _request(world, seed: int, **planner) -> dict:
    import dataclasses

    cfg = dataclasses.replace(world.scene.planner, **planner)
    return dict(seed=seed, start=None, goal=None, planner=cfg)


@pytest.fixture(scope="module")
def host(world):
    h = WorldHost(world)
    yield h
    h.close()


def test_a_fork_of_the_host_plans_what_a_child_sent_the_world_plans(world, host):
    far = time.monotonic() + 60
    hosted = [_paths(Job(_plan_job, 2, _request(world, 5), far, host=host)) for _ in range(2)]
    plain = _paths(Job(_plan_job, world, 2, _request(world, 5), far))
    assert len(plain) == 2
    for paths in hosted:  # (the host never draws: each fork starts from OMPL's clean state)
        assert len(paths) == len(plain)
        for a, b in zip(paths, plain):
            np.testing.assert_array_equal(a, b)
    other = _paths(Job(_plan_job, 1, _request(world, 6), far, host=host))
    assert not np.array_equal(other[0], plain[0]), "another seed, another path"


def test_cancel_kills_the_fork_and_the_host_serves_the_next_job(world, host):
    # Fifty distinct paths asked for: it plans for seconds, up to 160 tries.
    job = Job(_plan_job, 50, _request(world, 0, time_limit=30.0), time.monotonic() + 300, host=host)
    time.sleep(0.5)
    assert host.is_parent_of(job.pid) and not job.done
    job.cancel()
    for _ in range(100):
        if not host.is_parent_of(job.pid):
            break
        time.sleep(0.05)
    assert not host.is_parent_of(job.pid), "the cancelled fork is gone"
    assert len(_paths(Job(_plan_job, 1, _request(world, 3), time.monotonic() + 60, host=host))) == 1


def test_the_app_plans_without_its_host_once_it_has_died(world):
    from conftest import free_port
    from roachplan.app._server import RoachApp

    app = RoachApp(world, host="127.0.0.1", port=free_port())
    try:
        for _ in range(200):
            if app.core.host is not None:
                break
            time.sleep(0.05)
        assert app.core.host is not None and app.core.host.world is app.world
        job = app.core.world_job(_plan_job, 1, _request(world, 1), time.monotonic() + 60)
        assert job._host is app.core.host
        hosted = _paths(job)
        os.kill(app.core.host._proc.pid, signal.SIGKILL)
        app.core.host._proc.join(timeout=5)
        job = app.core.world_job(_plan_job, 1, _request(world, 1), time.monotonic() + 60)
        assert job._host is None, "a plain child, sent the world"
        np.testing.assert_array_equal(_paths(job)[0], hosted[0])
        assert app.core.host is not None and app.core.host.alive, (
            "and a new host for the next click"
        )
        job = app.core.world_job(_plan_job, 1, _request(world, 1), time.monotonic() + 60)
        assert job._host is app.core.host
        np.testing.assert_array_equal(_paths(job)[0], hosted[0])
    finally:
        app.stop()


def _gone(pid: int) -> bool:
    """No such process, or only its exit status left (a zombie)."""
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def test_cancel_kills_a_fork_whose_host_has_closed_meanwhile(world):
    # A new scene loaded while a plan runs closes the old world's host; Cancel must still
    # reach the plan, now a child of init's.
    old = WorldHost(world)
    job = Job(_plan_job, 50, _request(world, 0, time_limit=30.0), time.monotonic() + 300, host=old)
    time.sleep(0.3)
    old.close()
    assert not old.is_parent_of(job.pid) and not _gone(job.pid), "it runs on, orphaned"
    job.cancel()
    for _ in range(100):
        if _gone(job.pid):
            break
        time.sleep(0.05)
    assert _gone(job.pid)
