"""Processes as /proc shows them: who started whom, when a process started, and killing a
process with everything it started."""

from __future__ import annotations

import os
import signal
from pathlib import Path


def start_time(pid: int) -> int | None:
    """When the process started (clock ticks since boot), None if there is no such process:
    with the pid, it names one process even after the pid is reused."""
    try:
        return int(_fields(Path(f"/proc/{pid}/stat").read_text())[19])
    except (OSError, IndexError, ValueError):
        return None


def parent_of(pid: int) -> int | None:
    """The parent's pid of a process, None if there is no such process."""
    try:
        return int(_fields(Path(f"/proc/{pid}/stat").read_text())[1])
    except (OSError, IndexError, ValueError):
        return None


def _fields(stat: str) -> list[str]:
    """The fields of /proc/PID/stat after the name (the name may hold spaces and brackets):
    [0] the state, [1] the parent's pid, [19] the start time."""
    return stat.rsplit(")", 1)[1].split()


def children() -> dict[int, list[int]]:
    """Parent pid -> child pids of every process visible in /proc."""
    out: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                stat = Path(entry.path, "stat").read_text()
            except OSError:
                continue
            out.setdefault(int(_fields(stat)[1]), []).append(int(entry.name))
    return out


def descendants(pid: int) -> set[int]:
    """Every process under pid (its children, theirs, ...), not pid itself."""
    tree, found, todo = children(), set(), [pid]
    while todo:
        kids = tree.get(todo.pop(), [])
        found.update(kids)
        todo += kids
    return found


def kill_tree(pid: int) -> None:
    """SIGKILL a process and all its descendants. Not a process group: OpenSCAD runs in a
    session of its own (so that the terminal's Ctrl-C is its parent's to handle), which a group
    kill would miss. The root is stopped first so that it starts nothing new while the tree is
    read."""
    try:
        os.kill(pid, signal.SIGSTOP)
    except ProcessLookupError:
        return
    for p in (pid, *descendants(pid)):
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
