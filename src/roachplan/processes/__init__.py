"""Work in other processes, one way: a function in a fresh child (Child, call), forks of a
long-lived host holding one value (Host), a pool of workers (Pool), an external program
(run_program). Each is limited (memory: $ROACHPLAN_CHILD_MEMORY; time), cancelled with
everything it started (kill_tree), reaped, and dies with its parent; what it reports travels as
typed events in one stream (emit, listening), then one outcome (Returned, Raised, Died).

Imports nothing of the other subpackages (they all use it) and never viser.
"""

from ._child import Child, Host, Start, call, preload, unwrap
from ._errors import ChildError, WorkerDied
from ._events import (
    CHANNEL,
    Channel,
    Died,
    Outcome,
    Raised,
    Returned,
    Running,
    emit,
    listening,
)
from ._limits import (
    CHILD_MEMORY_ENV,
    SCAD_MEMORY_ENV,
    child_memory_limit,
    default_memory_limit,
    limit_memory,
    memory_advice,
    memory_setting,
    size_text,
)
from ._pool import CallDone, Pool
from ._program import ProgramRun, run_program
from ._tree import descendants, kill_tree, parent_of, start_time

__all__ = [
    "CHANNEL",
    "CHILD_MEMORY_ENV",
    "SCAD_MEMORY_ENV",
    "CallDone",
    "Channel",
    "Child",
    "ChildError",
    "Died",
    "Host",
    "Outcome",
    "Pool",
    "ProgramRun",
    "Raised",
    "Returned",
    "Running",
    "Start",
    "WorkerDied",
    "call",
    "child_memory_limit",
    "default_memory_limit",
    "descendants",
    "emit",
    "kill_tree",
    "limit_memory",
    "listening",
    "memory_advice",
    "memory_setting",
    "parent_of",
    "preload",
    "run_program",
    "size_text",
    "start_time",
    "unwrap",
]
