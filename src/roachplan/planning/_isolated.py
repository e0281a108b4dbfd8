"""Every plan runs in a fresh child process (plan_path, through roachplan.processes, which
says why: OMPL's process-global seed generator and PRM's thread), handed its result back.

A plan forks this process when it is single-threaded, and otherwise (a Ray worker, a web
server) asks the fork server, which preloads the planner, for a child; either way under the
child memory limit ($ROACHPLAN_CHILD_MEMORY), so a runaway plan is stopped with an error that
says so instead of taking the machine.

The names here are roachplan.processes' under the names the command line (app/cli.py) and the
choose panel import them by; new code imports roachplan.processes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, TypeVar

from roachplan.processes import ChildError, call, child_memory_limit, limit_memory

T = TypeVar("T")

Method = Literal["auto", "fork", "forkserver"]

IsolationError = ChildError
"""What a planning child that died, or ran out of its memory limit, raises (the command line's
name for it; roachplan.processes.ChildError)."""

limit_child_memory = limit_memory
"""(roachplan.processes.limit_memory, by the name the choose panel imports it under.)"""

__all__ = ["IsolationError", "Method", "child_memory_limit", "limit_child_memory", "run_isolated"]


def run_isolated(
    fn: Callable[..., T],
    /,
    *args,
    isolation: Method = "auto",
    preload: str = "",
    task: str = "planning",
    **kwargs,
) -> T:
    """fn(*args, **kwargs) in a fresh child process under the memory limit; its return value,
    or its exception re-raised (IsolationError when it died without one).

    isolation: "fork" forks this process; "forkserver" asks the fork server (fn and the
    arguments must pickle); "auto" forks unless other threads are running. preload: a module
    the fork server imports once, so that children start warm. task: what the child does, for
    the messages when it dies or runs out of memory ("the meshing process ...").
    """
    return call(
        fn,
        args,
        kwargs,
        start=isolation,
        task=task,
        preload=(preload,) if preload else (),
    )
