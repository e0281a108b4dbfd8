"""What a child process tells its parent: events while it runs, then one outcome.

An event is a frozen dataclass (any picklable value travels, but the project's are typed: a
plan's Attempt, a drive's Frame, a program's Running). Every process has one stream of them:
`emit(event)` hands an event to whoever listens in this process (`listening(handler)`: the
command line's progress bars); in a child started by roachplan.processes, the stream leads to
the parent instead, which reads the events in order (Child.poll) and, when it waits for the
child (Child.wait, call), emits them in its own stream. So an OpenSCAD render deep inside a scene
load says how long it has been running to whoever started the load, in this process or
another, without a callback passed down to it.

The outcome is the last thing a child sends (or its parent concludes, when it sends nothing):
Returned, Raised or Died.
"""

from __future__ import annotations

import threading
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal

# -- events -------------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class Running:
    """An external program (an OpenSCAD render) is running: sent about twice a second while it
    runs, and once more when it ends (run_program)."""

    what: str
    """What it works on, as a user names it (the model's file name)."""
    elapsed: float
    """Wall time since it started [s]."""
    limit: float
    """Its time limit [s]."""


# -- outcomes ---------------------------------------------------------------------------------


class Outcome:
    """How a child ended: Returned, Raised or Died."""


@dataclass(frozen=True, kw_only=True)
class Returned(Outcome):
    """The child's function returned."""

    value: object


@dataclass(frozen=True, kw_only=True)
class Raised(Outcome):
    """The child's function raised."""

    message: str
    """str(error): what a user is told."""
    error: BaseException | None
    """The exception itself, None when it did not survive pickling."""
    traceback: str
    """Its traceback in the child, as Python prints it."""

    @staticmethod
    def of(exc: BaseException) -> Raised:
        return Raised(
            message=str(exc), error=exc, traceback="".join(traceback.format_exception(exc))
        )


Cause = Literal["memory", "time", "signal", "exit", "cancelled"]


@dataclass(frozen=True, kw_only=True)
class Died(Outcome):
    """The child ended without an answer."""

    cause: Cause
    """memory: it ran out of its memory limit; time: its parent killed it at its time limit;
    signal: a signal ended it (a crash, an allocation past the limit in C++, a kill); exit: it
    exited without answering; cancelled: its parent cancelled it."""
    why: str
    """One sentence for a user, saying which limit stopped it and how to allow more."""
    status: int | None = None
    """Its exit status, or -signal; None where it is not known (a fork of a Host is reaped by
    the host, not by the process that asked for it)."""


# -- this process's stream --------------------------------------------------------------------

_handlers: list[Callable[[object], None]] = []
_lock = threading.Lock()


def emit(event: object) -> None:
    """Hand event to this process's stream: every listening handler gets it, in the order they
    started listening; in a child of roachplan.processes, the parent gets it. Without a
    listener, nothing happens."""
    with _lock:
        handlers = list(_handlers)
    for handler in handlers:
        handler(event)


@contextmanager
def listening(handler: Callable[[object], None]) -> Iterator[None]:
    """While inside, handler(event) is called for every event emitted in this process (and
    every event of a child this process waits for)."""
    with _lock:
        _handlers.append(handler)
    try:
        yield
    finally:
        with _lock:
            _handlers.remove(handler)


def _only(handler: Callable[[object], None]) -> None:
    """In a new child: its stream leads to handler alone (not to what the parent listened
    with, which the fork copied)."""
    with _lock:
        _handlers[:] = [handler]


class Channel:
    """A child's end of its stream, for a function that takes one as an argument (the app's
    jobs): send(event) is emit(event). Picklable: it names no process, so it works wherever the
    function runs."""

    def send(self, event: object) -> None:
        emit(event)

    def close(self) -> None:
        """Nothing: the stream ends when the child does."""


CHANNEL = Channel()
