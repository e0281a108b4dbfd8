"""The one way roachplan runs work in another process (roachplan.processes): a child starts,
sends its events in order and then its outcome, is held to its memory and time limits (and
says which stopped it), is cancelled with everything it started, is reaped, and dies with its
parent; the same for forks of a host, a pool's workers and an external program."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from roachplan.processes import (
    CHANNEL,
    Child,
    ChildError,
    Died,
    Host,
    Pool,
    Raised,
    Returned,
    Running,
    WorkerDied,
    call,
    descendants,
    emit,
    listening,
    memory_setting,
    run_program,
    size_text,
)

STARTS = ["fork", "forkserver", "spawn"]


def _gone(pid: int) -> bool:
    """No such process, or only its exit status left (a zombie)."""
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return True
    return stat.rsplit(")", 1)[1].split()[0] in ("Z", "X")


def _until(condition, seconds: float = 10.0) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def _follow(child: Child, seconds: float = 60.0) -> list[object]:
    """Every event of child, once it has ended."""
    events, end = [], time.monotonic() + seconds
    while not child.done and time.monotonic() < end:
        events += child.poll(timeout=0.5)
    assert child.done, "the child did not end"
    return events


# -- functions the children run (module level: the fork server and spawn pickle them) ---------


def _count(n: int) -> str:
    for k in range(n):
        emit(("step", k))
    return "counted"


def _fail(text: str) -> None:
    raise KeyError(text)


def _hungry() -> float:
    import numpy as np

    return float(np.ones(1 << 30).sum())  # 8 GiB


def _crash() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def _sleep(seconds: float) -> None:
    time.sleep(seconds)


def _sleep_in(value, seconds: float) -> None:  # (a fork of a host: its value first)
    time.sleep(seconds)


def _tree(seconds: float) -> None:
    """A child that starts a program and a fork of itself, says their pids and waits."""
    program = subprocess.Popen(["sleep", str(seconds)])
    forked = os.fork()
    if forked == 0:
        time.sleep(seconds)
        os._exit(0)
    emit(("pids", program.pid, forked))
    time.sleep(seconds)


def _rlimit() -> tuple[int, int]:
    return resource.getrlimit(resource.RLIMIT_AS)


def _with_value(value, extra):
    emit(("value", value))
    return (value, extra)


def _job(events, world, k):  # an app-style job: its channel first
    events.send(("job", world, k))
    events.close()
    return k


# -- a child ---------------------------------------------------------------------------------


@pytest.mark.parametrize("start", STARTS)
def test_events_arrive_in_order_then_the_outcome(start):
    child = Child(_count, (300,), start=start, task="counting")
    events = _follow(child)
    assert events == [("step", k) for k in range(300)]
    assert child.outcome == Returned(value="counted")
    assert _gone(child.pid), "reaped"
    with pytest.raises(ChildProcessError):
        os.waitpid(child.pid, os.WNOHANG)  # (not left for this process to reap)


@pytest.mark.parametrize("start", STARTS)
def test_an_error_comes_back_as_itself_with_the_childs_traceback(start):
    child = Child(_fail, ("no such key",), start=start)
    _follow(child)
    assert isinstance(child.outcome, Raised)
    assert "no such key" in child.outcome.message
    assert "_fail" in child.outcome.traceback
    with pytest.raises(KeyError, match="no such key") as caught:
        call(_fail, ("no such key",), start=start)
    assert any("_fail" in note for note in caught.value.__notes__)


def _say_and_exit() -> None:
    print("printed by the child")
    print("written to stderr by the child", file=sys.stderr)
    sys.exit("the child exits")


def test_a_childs_output_and_an_unusual_end_reach_the_log(capfd):
    child = Child(_say_and_exit, start="fork")
    _follow(child)
    out, err = capfd.readouterr()
    assert "printed by the child" in out and "written to stderr by the child" in err
    assert isinstance(child.outcome, Raised) and child.outcome.message == "the child exits"
    assert "SystemExit: the child exits" in err, "(not an Exception: its traceback is logged)"


def test_call_hands_the_childs_events_to_this_processes_listeners():
    heard = []
    with listening(heard.append):
        assert call(_count, (5,), start="fork") == "counted"
        assert call(_job, (CHANNEL, "world", 3), start="forkserver") == 3  # (a channel argument)
    assert heard == [*(("step", k) for k in range(5)), ("job", "world", 3)]


def _mapped() -> int:
    """The address space this process maps [bytes] (a fork starts with as much)."""
    status = open("/proc/self/status").read()
    return int(status.split("VmSize:")[1].split()[0]) * 1024


@pytest.mark.parametrize("start", ["fork", "forkserver"])
def test_a_child_out_of_memory_says_which_limit_and_how_to_raise_it(monkeypatch, start):
    limit = (_mapped() >> 30) + 2 << 30  # (room above what a fork of this process maps)
    monkeypatch.setenv("ROACHPLAN_CHILD_MEMORY", f"{limit >> 20}M")
    child = Child(_hungry, start=start, task="meshing")
    _follow(child)
    assert isinstance(child.outcome, Died) and child.outcome.cause == "memory"
    why = child.outcome.why
    assert "the meshing process ran out of memory" in why
    assert size_text(limit) in why and "ROACHPLAN_CHILD_MEMORY=SIZE" in why
    assert call(_rlimit, start=start) == (limit, limit)
    soft, hard = call(_rlimit, start=start, memory=limit, hard_memory=False)
    assert soft == limit and hard != limit


def test_a_child_killed_by_a_signal_says_so_and_suggests_memory():
    child = Child(_crash, start="fork", memory=2 << 30, task="planning")
    _follow(child)
    assert isinstance(child.outcome, Died) and child.outcome.cause == "signal"
    assert child.outcome.status == -signal.SIGKILL
    assert "SIGKILL" in child.outcome.why and "memory limit of 2 GiB" in child.outcome.why
    with pytest.raises(ChildError, match="planning process died without an answer"):
        call(_crash, start="fork", task="planning")


@pytest.mark.parametrize("start", ["fork", "forkserver"])
def test_a_child_past_its_time_limit_is_stopped_and_says_so(start):
    child = Child(_tree, (60,), start=start, time_limit=1.5, task="driving")
    events = _follow(child, 30)
    (_, program, forked) = events[0]
    assert 1.5 <= child.elapsed < 10
    assert isinstance(child.outcome, Died) and child.outcome.cause == "time"
    assert "the driving process did not finish within its time limit of 1.5 s" in child.outcome.why
    for pid in (child.pid, program, forked):
        assert _until(lambda p=pid: _gone(p)), f"{pid} outlived the time limit"


@pytest.mark.parametrize("start", STARTS)
def test_cancel_leaves_no_process_of_the_tree_behind(start):
    child = Child(_tree, (60,), start=start)
    events = []
    while not events:
        events += child.poll(timeout=1.0)
    (_, program, forked) = events[0]
    tree = {child.pid, program, forked} | descendants(child.pid)
    child.cancel()
    assert child.done and child.outcome.cause == "cancelled"
    for pid in tree:
        assert _until(lambda p=pid: _gone(p)), f"{pid} outlived Cancel"
    child.cancel()  # (again: nothing)


_ORPHAN = textwrap.dedent(
    """
    import sys, time
    from roachplan.processes import Child
    from test_processes import _sleep
    child = Child(_sleep, (60,), start=sys.argv[1])
    print(child.pid, flush=True)
    time.sleep(60)
    """
)


@pytest.mark.parametrize("start", STARTS)
def test_a_child_dies_with_its_parent(start):
    env = {**os.environ, "PYTHONPATH": os.path.dirname(__file__)}
    parent = subprocess.Popen(
        [sys.executable, "-c", _ORPHAN, start], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        pid = int(parent.stdout.readline())
        assert not _gone(pid)
        parent.kill()  # (no exit handler runs: only the kernel can end the child)
        parent.wait()
        assert _until(lambda: _gone(pid), 20), "the child outlived its parent"
    finally:
        parent.kill()
        parent.wait()


def test_a_bad_memory_setting_is_named_and_what_is_accepted_said(monkeypatch):
    monkeypatch.setenv("ROACHPLAN_CHILD_MEMORY", "0")
    assert memory_setting("ROACHPLAN_CHILD_MEMORY", zero_means_none=True) == 0
    monkeypatch.setenv("ROACHPLAN_SCAD_MEMORY", "0")
    with pytest.raises(ChildError, match=r"ROACHPLAN_SCAD_MEMORY='0': expected .* 16G or 512M$"):
        memory_setting("ROACHPLAN_SCAD_MEMORY", zero_means_none=False)
    monkeypatch.setenv("ROACHPLAN_SCAD_MEMORY", "1.5g")
    assert memory_setting("ROACHPLAN_SCAD_MEMORY", zero_means_none=False) == 3 << 29
    monkeypatch.setenv("ROACHPLAN_CHILD_MEMORY", "lots")
    with pytest.raises(ChildError, match="ROACHPLAN_CHILD_MEMORY='lots': .* or 0 for no limit"):
        Child(_sleep, (0,))


# -- a host --------------------------------------------------------------------------------


def test_a_host_forks_with_its_value_and_a_cancel_reaches_a_fork_it_has_left():
    host = Host({"world": 7})
    try:
        child = Child(_with_value, ("x",), start=host)
        assert _follow(child) == [("value", {"world": 7})]
        assert child.outcome == Returned(value=({"world": 7}, "x"))
        slow = Child(_sleep_in, (60,), start=host)
        assert _until(lambda: host.is_parent_of(slow.pid))
    finally:
        host.close()
    assert not host.alive and not _gone(slow.pid), "the fork runs on without its host"
    slow.cancel()
    assert _until(lambda: _gone(slow.pid))


# -- a pool --------------------------------------------------------------------------------


class _Worker:
    def __init__(self, offset: int) -> None:
        self.offset = offset


def _add(worker: _Worker, call: tuple):
    kind, value = call
    if kind == "fail":
        raise ValueError(f"refused {value}")
    if kind == "sleep":
        time.sleep(value)
    return worker.offset + value


def test_a_pool_answers_every_call_and_raises_a_calls_error():
    pool = Pool(2, _Worker, (100,), handle=_add, task="adding")
    try:
        assert sorted(pool.run(("add", k) for k in range(10))) == [100 + k for k in range(10)]
        with pytest.raises(ValueError, match="refused 3"):
            list(pool.run([("add", 1), ("fail", 3)]))
        assert list(pool.run([("add", 5)])) == [105]  # (the failed call's run left nothing)
    finally:
        pool.close()
    assert all(_gone(c.pid) for c in pool._children)


def test_a_terminated_pool_raises_worker_died_and_leaves_no_worker():
    import threading

    pool = Pool(2, _Worker, (0,), handle=_add, task="adding")
    pids = [c.pid for c in pool._children]
    threading.Timer(1.0, pool.terminate).start()
    with pytest.raises(WorkerDied, match="worker ended with calls left: the adding process died"):
        list(pool.run([("sleep", 30)] * 4))
    pool.close()
    for pid in pids:
        assert _until(lambda p=pid: _gone(p))


# -- an external program -------------------------------------------------------------------


def test_a_program_is_followed_limited_and_its_output_kept_at_both_ends(tmp_path):
    heard: list[Running] = []
    script = "yes roachplan | head -c 300000 >&2; sleep 60 & sleep 60"
    with listening(heard.append):
        run = run_program(["sh", "-c", script], time_limit=2.0, what="slow.scad", keep=1000)
    assert run.timed_out and run.status == -signal.SIGKILL and 2.0 <= run.seconds < 10
    assert run.stderr.startswith("roachplan\n") and "bytes left out" in run.stderr
    assert len(run.stderr) < 2100
    assert [e.what for e in heard] == ["slow.scad"] * len(heard) and len(heard) >= 3
    assert [e.elapsed for e in heard] == sorted(e.elapsed for e in heard)
    assert heard[-1].elapsed == pytest.approx(2.0, abs=0.5) and heard[-1].limit == 2.0
    done = run_program(["sh", "-c", "echo out; exit 3"], time_limit=10, output=True)
    assert done.status == 3 and done.stdout == "out\n" and not done.timed_out
