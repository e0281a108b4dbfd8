"""The errors of running work in other processes."""

from __future__ import annotations

from concurrent.futures.process import BrokenProcessPool


class ChildError(RuntimeError):
    """A child process ended without an answer (a crash, its memory or time limit, a cancel),
    or could not be started as configured (a bad memory setting); the message says which, and
    how to allow more where a limit stopped it."""


class WorkerDied(ChildError, BrokenProcessPool):
    """A worker of a Pool ended while calls were left (killed, crashed, or its set-up failed).
    Also a BrokenProcessPool, what concurrent.futures' pools raise then, so that a caller
    written for those (the `experiment` command) answers as it did."""
