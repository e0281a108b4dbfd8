"""Run one function in a forked child process and hand its result back.

Why: OMPL keeps one process-global seed generator, and `RNG.setSeed` only takes effect before
the process's first random draw. A plan made in a child forked from a process that never drew
starts from that clean state, so the same seed gives the same plan however many plans the
parent has asked for before. A fork of a warm process costs a few milliseconds.
"""

from __future__ import annotations

import os
import pickle
import signal
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


class IsolationError(RuntimeError):
    """The child process died without returning (e.g. a crash inside OMPL)."""


def run_isolated(fn: Callable[..., T], *args, **kwargs) -> T:
    """fn(*args, **kwargs) in a forked child; its return value, or its exception re-raised."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into the caller's stack
        status = 1
        try:
            os.close(read_fd)
            try:
                outcome = (True, fn(*args, **kwargs))
            except BaseException as exc:  # noqa: BLE001 - every failure goes to the parent
                outcome = (False, exc)
            try:
                data = pickle.dumps(outcome)
            except Exception as exc:  # noqa: BLE001
                data = pickle.dumps((False, IsolationError(f"unpicklable result: {exc!r}")))
            with os.fdopen(write_fd, "wb") as pipe:
                pipe.write(data)
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
    ok, value = pickle.loads(data)
    if ok:
        return value
    raise value
