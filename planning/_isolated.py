"""Run one function in a fresh child process and hand its result back.

Why: OMPL keeps one process-global seed generator, and `RNG.setSeed` only takes effect before
the process's first random draw. A plan made in a child forked from a process that never drew
starts from that clean state, so the same seed gives the same plan however many plans the
parent has asked for before. A fork of a warm process costs a few milliseconds.

A bare fork is only safe from a single-threaded process (a thread holding a lock at the fork
leaves it locked forever in the child). From a process with other threads running (a Ray worker,
a web server), the child comes from multiprocessing's fork server instead: a clean
single-threaded interpreter that forks on request; it costs the pickling of the arguments.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import threading
from collections.abc import Callable
from typing import Literal, TypeVar

T = TypeVar("T")

Method = Literal["auto", "fork", "forkserver"]


class IsolationError(RuntimeError):
    """The child process died without returning (e.g. a crash inside OMPL)."""


def run_isolated(
    fn: Callable[..., T], /, *args, isolation: Method = "auto", preload: str = "", **kwargs
) -> T:
    """fn(*args, **kwargs) in a child process; its return value, or its exception re-raised.

    isolation: "fork" forks this process; "forkserver" asks the fork server (fn and the
    arguments must pickle); "auto" forks unless other threads are running. preload: a module
    the fork server imports once, so that children start warm.
    """
    if isolation == "auto":
        isolation = "fork" if threading.active_count() == 1 else "forkserver"
    if isolation == "forkserver":
        return _via_forkserver(fn, args, kwargs, preload)
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into the caller's stack
        status = 1
        try:
            os.close(read_fd)
            with os.fdopen(write_fd, "wb") as pipe:
                pipe.write(_outcome(fn, args, kwargs))
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
        why = (
            f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status)
            else f"exit status {os.WEXITSTATUS(status)}"
        )  # fmt: skip
        raise IsolationError(f"the planning process died without an answer ({why})")
    return _unwrap(data)


def _outcome(fn: Callable, args: tuple, kwargs: dict) -> bytes:
    """The pickled (ok, value-or-exception) of calling fn; every failure is sent back."""
    try:
        outcome = (True, fn(*args, **kwargs))
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


def _forkserver_child(conn, fn: Callable, args: tuple, kwargs: dict) -> None:
    conn.send_bytes(_outcome(fn, args, kwargs))
    conn.close()


def _via_forkserver(fn: Callable, args: tuple, kwargs: dict, preload: str):
    ctx = multiprocessing.get_context("forkserver")
    if preload:
        ctx.set_forkserver_preload([preload])  # takes effect when the server first starts
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_forkserver_child, args=(send, fn, args, kwargs), daemon=True)
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
        raise IsolationError(
            f"the planning process died without an answer (exit code {child.exitcode})"
        )
    return _unwrap(data)
