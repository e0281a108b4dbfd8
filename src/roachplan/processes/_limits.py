"""What a child process may use: the memory-limit settings (one parser for both variables),
the address-space limit itself, and dying with the parent."""

from __future__ import annotations

import ctypes
import os
import re
import resource
import signal

from ._errors import ChildError

CHILD_MEMORY_ENV = "ROACHPLAN_CHILD_MEMORY"
"""Memory limit of each child process (a plan, a drive, a scene load, an experiment worker):
16G, 512M, or bytes; 0: none. Unset: default_memory_limit()."""
SCAD_MEMORY_ENV = "ROACHPLAN_SCAD_MEMORY"
"""Memory limit of one OpenSCAD render: 16G, 512M, 1.5G, or bytes. Unset:
default_memory_limit()."""

_SIZE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kmgt]?)(?:i?b)?\s*", re.I)
_SMALLEST, _LARGEST = 64 << 20, 1 << 50


def default_memory_limit() -> int:
    """The memory limit when no setting gives one [bytes]: 8 GiB, or three quarters of the
    machine's memory if that is less. It counts everything mapped, libraries included (a
    planning process maps about 0.5 GiB before it plans; large CGAL renders need a few GiB)."""
    try:
        ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError):
        ram = 0
    return min(8 << 30, ram * 3 // 4) if ram > 0 else 8 << 30


def memory_setting(env: str, *, zero_means_none: bool) -> int:
    """The memory limit [bytes] the environment variable `env` sets: a size from 64M up (16G,
    512M, 1.5G, or bytes), or, where zero_means_none, 0 for no limit; default_memory_limit()
    when it is unset or blank. ChildError naming the variable, its value and what is accepted
    otherwise."""
    text = os.environ.get(env, "").strip()
    if not text:
        return default_memory_limit()
    m = _SIZE.fullmatch(text)
    size = float(m.group(1)) * 1024 ** " kmgt".index(m.group(2).lower() or " ") if m else -1.0
    if not (_SMALLEST <= size <= _LARGEST or (zero_means_none and size == 0)):
        none = ", or 0 for no limit" if zero_means_none else ""
        raise ChildError(
            f"{env}={text!r}: expected a memory size from 64M up, such as 16G or 512M{none}"
        )
    return int(size)


def child_memory_limit() -> int:
    """The address-space limit of a child process [bytes] (0: none): $ROACHPLAN_CHILD_MEMORY,
    else default_memory_limit()."""
    return memory_setting(CHILD_MEMORY_ENV, zero_means_none=True)


def size_text(size: int) -> str:
    """A memory size as people read it: "2 GiB", "300 MiB"."""
    return f"{size / (1 << 30):.3g} GiB" if size >= 1 << 30 else f"{size / (1 << 20):.3g} MiB"


def memory_advice(limit: int, env: str = CHILD_MEMORY_ENV) -> str:
    """How to let a child that ran out of `limit` bytes have more."""
    if not limit:
        return f"it had no limit ({env}=0): the machine has no more to give"
    return (
        f"raise its memory limit of {size_text(limit)} with {env}=SIZE "
        f"(e.g. {env}=16G; 0: no limit)"
    )


def limit_memory(limit: int | None = None, *, hard: bool = True) -> int:
    """Lower this process's address-space limit to `limit` bytes (default:
    child_memory_limit(); 0: leave it), never above a hard limit set already. It holds for the
    rest of the process's life: call it first thing in a child (roachplan.processes.Child does).
    hard=False lowers only the soft limit, so that a program this process starts may set its
    own, higher one (OpenSCAD in its jail). Returns the limit set (0: none)."""
    limit = child_memory_limit() if limit is None else limit
    if limit:
        _, ceiling = resource.getrlimit(resource.RLIMIT_AS)
        if ceiling != resource.RLIM_INFINITY:
            limit = min(limit, ceiling)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit if hard else ceiling))
    return limit


_PR_SET_PDEATHSIG = 1
try:
    _prctl = ctypes.CDLL(None, use_errno=True).prctl
except (OSError, AttributeError):  # not Linux: an orphan finishes its work and exits
    _prctl = None


def die_with_parent() -> None:
    """Ask Linux to SIGKILL this process when the thread that started it ends (with its
    process, normally): a killed parent leaves no orphans working for nobody. Not inherited by
    this process's own children, which ask for themselves."""
    if _prctl is not None:
        _prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
