"""Run one function in a fresh child process and hand its result back.

Why: OMPL keeps one process-global seed generator, and `RNG.setSeed` only takes effect before
the process's first random draw. A plan made in a child forked from a process that never drew
starts from that clean state, so the same seed gives the same plan however many plans the
parent has asked for before. A fork of a warm process costs a few milliseconds.

A bare fork is only safe from a single-threaded process (a thread holding a lock at the fork
leaves it locked forever in the child). From a process with other threads running (a Ray worker,
a web server), the child comes from multiprocessing's fork server instead: a clean
single-threaded interpreter that forks on request; it costs the pickling of the arguments.

Each child runs under a memory limit (RLIMIT_AS, $ROACHPLAN_CHILD_MEMORY, generous by default),
so a runaway plan is stopped with an error that says so instead of taking the machine.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import re
import resource
import signal
import threading
from collections.abc import Callable
from typing import Literal, TypeVar

T = TypeVar("T")

Method = Literal["auto", "fork", "forkserver"]


class IsolationError(RuntimeError):
    """The child process died without returning (e.g. a crash inside OMPL), or ran out of its
    memory limit."""


MEMORY_ENV = "ROACHPLAN_CHILD_MEMORY"
"""Memory limit of each planning (or driving) child process: 16G, 512M, or bytes; 0: none."""

_SIZE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kmgt]?)(?:i?b)?\s*", re.I)


def child_memory_limit() -> int:
    """The address-space limit of a child [bytes] (0: none): $ROACHPLAN_CHILD_MEMORY, else
    8 GiB or three quarters of the machine's memory, whichever is less. It counts everything
    mapped, libraries included (a planning process maps about 0.5 GiB before it plans)."""
    text = os.environ.get(MEMORY_ENV, "").strip()
    if not text:
        try:
            ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        except (ValueError, OSError):
            ram = 0
        return min(8 << 30, ram * 3 // 4) if ram > 0 else 8 << 30
    m = _SIZE.fullmatch(text)
    size = float(m.group(1)) * 1024 ** " kmgt".index(m.group(2).lower() or " ") if m else -1.0
    if size != 0 and not 64 << 20 <= size <= 1 << 50:
        raise IsolationError(
            f"{MEMORY_ENV}={text!r}: expected a memory size from 64M up, such as 16G or "
            f"512M, or 0 for no limit"
        )
    return int(size)


def _size_text(size: int) -> str:
    return f"{size / (1 << 30):.3g} GiB" if size >= 1 << 30 else f"{size / (1 << 20):.3g} MiB"


def limit_child_memory(limit: int | None = None, *, hard: bool = True) -> int:
    """Lower this process's address-space limit to `limit` bytes (default:
    child_memory_limit(); 0: leave it). Call it first thing in a child process: it holds for
    the rest of the process's life. hard=False lowers only the soft limit, so that a program
    this process starts may set its own, higher one (OpenSCAD in its jail). Returns the limit
    set (0: none)."""
    limit = child_memory_limit() if limit is None else limit
    if limit:
        _, ceiling = resource.getrlimit(resource.RLIMIT_AS)
        if ceiling != resource.RLIM_INFINITY:
            limit = min(limit, ceiling)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit if hard else ceiling))
    return limit


def _memory_advice(limit: int) -> str:
    if not limit:
        return f"it had no limit ({MEMORY_ENV}=0): the machine has no more to give"
    return (
        f"raise its memory limit of {_size_text(limit)} with {MEMORY_ENV}=SIZE "
        f"(e.g. {MEMORY_ENV}=16G; 0: no limit)"
    )


def run_isolated(
    fn: Callable[..., T],
    /,
    *args,
    isolation: Method = "auto",
    preload: str = "",
    task: str = "planning",
    **kwargs,
) -> T:
    """fn(*args, **kwargs) in a child process under the memory limit; its return value, or its
    exception re-raised.

    isolation: "fork" forks this process; "forkserver" asks the fork server (fn and the
    arguments must pickle); "auto" forks unless other threads are running. preload: a module
    the fork server imports once, so that children start warm. task: what the child does, for
    the messages when it dies or runs out of memory ("the meshing process ...").
    """
    limit = child_memory_limit()
    if isolation == "auto":
        isolation = "fork" if threading.active_count() == 1 else "forkserver"
    if isolation == "forkserver":
        return _via_forkserver(fn, args, kwargs, preload, limit, task)
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into the caller's stack
        status = 1
        try:
            os.close(read_fd)
            with os.fdopen(write_fd, "wb") as pipe:
                pipe.write(_outcome(fn, args, kwargs, limit, task))
            status = 0
        finally:
            os._exit(status)
    os.close(write_fd)
    try:
        with os.fdopen(read_fd, "rb") as pipe:
            data = pipe.read()
        _, status = os.waitpid(pid, 0)
    except BaseException:  # e.g. KeyboardInterrupt: do not leave the child running
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        raise
    if not data:
        code = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
        raise _died(code, limit, task)
    return _unwrap(data)


def _died(code: int, limit: int, task: str = "planning") -> IsolationError:
    """The error for a child that sent nothing back; code: its exit status, or -signal."""
    if code >= 0:
        return IsolationError(f"the {task} process died without an answer (exit status {code})")
    name = signal.Signals(-code).name if -code in signal.valid_signals() else f"signal {-code}"
    why = f"the {task} process died without an answer ({name})"
    if limit:  # a C++ allocation past the limit aborts or crashes rather than raising
        why += f"; if it needed more memory than allowed, {_memory_advice(limit)}"
    return IsolationError(why)


def _outcome(fn: Callable, args: tuple, kwargs: dict, limit: int, task: str = "planning") -> bytes:
    """The pickled (ok, value-or-exception) of calling fn under the memory limit; every failure
    is sent back."""
    try:
        limit_child_memory(limit)
        outcome = (True, fn(*args, **kwargs))
    except MemoryError:
        outcome = (
            False,
            IsolationError(
                f"the {task} process ran out of memory and was stopped; {_memory_advice(limit)}"
            ),
        )
    except BaseException as exc:  # noqa: BLE001
        outcome = (False, exc)
    try:
        return pickle.dumps(outcome)
    except Exception as exc:  # noqa: BLE001
        return pickle.dumps((False, IsolationError(f"unpicklable result: {exc!r}")))


def _unwrap(data: bytes):
    ok, value = pickle.loads(data)
    if ok:
        return value
    raise value


def _forkserver_child(
    conn, fn: Callable, args: tuple, kwargs: dict, limit: int, task: str = "planning"
) -> None:
    conn.send_bytes(_outcome(fn, args, kwargs, limit, task))
    conn.close()


def _via_forkserver(
    fn: Callable, args: tuple, kwargs: dict, preload: str, limit: int, task: str = "planning"
):
    ctx = multiprocessing.get_context("forkserver")
    if preload:
        ctx.set_forkserver_preload([preload])  # takes effect when the server first starts
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(
        target=_forkserver_child, args=(send, fn, args, kwargs, limit, task), daemon=True
    )
    child.start()
    send.close()
    try:
        try:
            data = recv.recv_bytes()
        except EOFError:
            data = b""
        child.join()
    except BaseException:
        child.kill()
        child.join()
        raise
    finally:
        recv.close()
    if not data:
        raise _died(child.exitcode, limit, task)
    return _unwrap(data)
