"""Run one function in a fresh child process: start it, limit it, follow its events, cancel it
with everything it started, and reap it.

Why a fresh process: OMPL keeps one process-global seed generator, and `RNG.setSeed` only takes
effect before the process's first random draw; PRM builds its roadmap in a thread of its own. A
plan made in a child forked from a process that never drew starts from that clean state, so the
same seed gives the same plan however many plans the parent made before (a fork of a warm
process costs a few milliseconds). A fresh process is also what can be killed at once (Cancel:
OMPL holds the GIL while it solves) and held to a memory limit without harming its parent.

How a child starts (`start`):
- "fork": a bare fork of this process. Only safe from a single-threaded process: a thread
  holding a lock at the fork leaves it locked forever in the child.
- "forkserver": a fork of multiprocessing's fork server, a clean single-threaded interpreter
  (its modules preloaded, `preload`) that forks on request; the function and its arguments are
  pickled. What a process with other threads (a web server, a Ray worker) uses.
- "spawn": a fresh interpreter (experiment workers: nothing inherited at all).
- "auto": fork when this process has one thread, else forkserver.
- a Host: a fork of that long-lived child, which holds one value (the app's world) received once,
  so that a job does not wait for the world to be sent (0.33-0.38 s of a 0.5 s plan in the app);
  the function gets that value as its first argument.

Every child ignores Ctrl-C (its parent decides: it cancels), runs under an address-space limit
($ROACHPLAN_CHILD_MEMORY, generous by default) so that a runaway is stopped with an error that
says so, and dies with its parent (PR_SET_PDEATHSIG), except a fork of a Host, which outlives a
host closed meanwhile (a new scene loaded while a plan runs) and is still cancelled by its pid
and start time; it ends when it finishes, is cancelled, or sends an event its parent is no longer
there to read. Whatever a child prints goes where its parent's output goes (the server's log);
the traceback of an error travels back with it (Raised.traceback) and, when the error is no
ordinary Exception or does not pickle, is printed there too.
"""

from __future__ import annotations

import atexit
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from multiprocessing import reduction
from multiprocessing.connection import Connection, wait
from typing import Literal

from ._errors import ChildError
from ._events import Died, Outcome, Raised, Returned, _only, emit
from ._limits import child_memory_limit, die_with_parent, limit_memory, memory_advice
from ._tree import kill_tree, parent_of, start_time

Start = Literal["auto", "fork", "forkserver", "spawn"]

_FORKSERVER = mp.get_context("forkserver")
_SPAWN = mp.get_context("spawn")
_PRELOADED: set[str] = set()


def preload(*modules: str) -> None:
    """Modules the fork server imports once, when it starts, so that its children start warm
    (no effect once it has started)."""
    _preload(modules)


def _preload(modules) -> None:
    if not set(modules) <= _PRELOADED:
        _PRELOADED.update(modules)
        _FORKSERVER.set_forkserver_preload(sorted(_PRELOADED))


@dataclass(frozen=True)
class _Work:
    """What a child runs, and under which limits (pickled to the fork server, a spawned
    interpreter or a Host)."""

    fn: Callable
    args: tuple
    kwargs: dict = field(default_factory=dict)
    memory: int = 0
    """Address-space limit [bytes]; 0: none."""
    hard_memory: bool = True
    """Also the hard limit (else only the soft one: a program the child starts may set its
    own, higher one)."""
    task: str = "child"
    die_with_parent: bool = True
    parent: int | None = None
    """The pid of the process a bare fork was forked from (else None)."""


_live: set[Child] = set()
"""Children started here and not yet ended: killed when this process exits."""


class Child:
    """fn(*args, **kwargs) in a fresh child process (module docstring: `start`), under a memory
    limit (`memory` bytes, default $ROACHPLAN_CHILD_MEMORY; 0: none) and, with time_limit [s],
    a wall-time limit counted from the start. Its events arrive in order (poll), then its
    outcome (`outcome`: Returned, Raised or Died). task names what it does in the messages
    ("the planning process ran out of memory ...")."""

    def __init__(
        self,
        fn: Callable,
        args: tuple = (),
        kwargs: dict | None = None,
        *,
        start: Start | Host = "auto",
        memory: int | None = None,
        hard_memory: bool = True,
        time_limit: float | None = None,
        task: str = "child",
        preload: tuple[str, ...] = (),
    ) -> None:
        self.task = task
        self.memory = child_memory_limit() if memory is None else memory
        """Its address-space limit [bytes] (0: none)."""
        self.time_limit = time_limit
        """Its wall-time limit [s] (None: none)."""
        self.host = start if isinstance(start, Host) else None
        """The Host it is a fork of, if any."""
        self.done = False
        """It has ended (returned, raised, died, or was cancelled); `outcome` says how."""
        self.outcome: Outcome | None = None
        if start == "auto":
            start = "fork" if threading.active_count() == 1 else "forkserver"
        self.how = "host" if self.host is not None else start
        """How it was started: fork, forkserver, spawn or host."""
        work = _Work(
            fn,
            tuple(args),
            dict(kwargs or {}),
            memory=self.memory,
            hard_memory=hard_memory,
            task=task,
            die_with_parent=self.host is None,
        )
        self._proc: mp.process.BaseProcess | None = None
        self._forked = False
        self.started = time.monotonic()
        """When it started (time.monotonic()) [s]."""
        self.pid = self._start(work, start, preload)
        self._born = start_time(self.pid)
        _live.add(self)

    def _start(self, work: _Work, start: Start | Host, preload: tuple[str, ...]) -> int:
        """Start the child (sets _conn, the reading end of its stream); its pid."""
        if self.host is not None:
            self._conn, end = _FORKSERVER.Pipe(duplex=False)
            try:
                return self.host.fork(work, end)
            finally:
                end.close()  # (the child holds the only writer: its exit is this end's EOF)
        if start == "fork":
            self._conn, end = mp.Pipe(duplex=False)
            work = replace(work, parent=os.getpid())
            pid = os.fork()
            if pid == 0:  # the child: never returns into the caller's stack
                status = 1
                try:
                    self._conn.close()
                    _run(end, work)
                    status = 0
                finally:
                    _exit(status)
            end.close()
            self._forked = True
            return pid
        if start not in ("forkserver", "spawn"):
            raise ValueError(
                f"start: expected auto, fork, forkserver, spawn or a Host, got {start!r}"
            )
        ctx = _FORKSERVER if start == "forkserver" else _SPAWN
        if start == "forkserver" and preload:
            _preload(preload)
        self._conn, end = ctx.Pipe(duplex=False)
        # daemon: were this process to end without cancelling it, multiprocessing would stop
        # it rather than wait for it.
        self._proc = ctx.Process(
            target=_run, args=(end, work), daemon=True, name=f"roachplan {work.task}"
        )
        try:
            self._proc.start()
        finally:
            end.close()
        return self._proc.pid

    @property
    def elapsed(self) -> float:
        """Wall time since it started [s]."""
        return time.monotonic() - self.started

    def poll(self, timeout: float = 0.0) -> list[object]:
        """The events sent since the last poll, in order, waiting up to timeout [s] for the
        first. Once it has ended, an empty list after `timeout` (the caller's pace, as while
        waiting for events). Past its time limit, it is killed here: Died(cause="time")."""
        if self.done:
            time.sleep(timeout)
            return []
        if self.time_limit is not None:
            timeout = min(timeout, max(self.time_limit - self.elapsed, 0.0))
        events: list[object] = []
        if wait([self._conn], timeout):
            while not self.done and self._conn.poll():
                try:
                    message = self._conn.recv()
                except (EOFError, OSError):  # it exited (or was killed) without an outcome
                    self._end(None)
                    break
                if isinstance(message, Outcome):
                    self._end(message)
                else:
                    events.append(message)
        if not self.done and self.time_limit is not None and self.elapsed >= self.time_limit:
            self.kill()
            self._end(
                Died(
                    cause="time",
                    why=f"the {self.task} process did not finish within its time limit of "
                    f"{self.time_limit:g} s and was stopped",
                )
            )
        return events

    def wait(self, on_event: Callable[[object], None] = emit) -> Outcome:
        """Its outcome, once it has ended; each event meanwhile goes to on_event (default: this
        process's stream, so that what listens here hears the child too). Interrupted (Ctrl-C),
        it cancels the child first."""
        try:
            while not self.done:
                for event in self.poll(timeout=1.0):
                    on_event(event)
        except BaseException:
            self.cancel()
            raise
        assert self.outcome is not None
        return self.outcome

    def result(self, on_event: Callable[[object], None] = emit):
        """What fn returned, once it has; its exception re-raised (with the child's traceback
        as a note), or ChildError saying how it died."""
        return unwrap(self.wait(on_event))

    def kill(self) -> None:
        """SIGKILL the child and every process under it, now. Touches no pipe, so another
        thread may call it while one polls (which then finds it ended)."""
        if not self.done and self._running():
            kill_tree(self.pid)

    def cancel(self) -> None:
        """Kill the child and everything it started, now; its outcome is Died(cause=
        "cancelled"). Nothing when it has ended."""
        if self.done:
            return
        self.kill()
        self._end(Died(cause="cancelled", why=f"the {self.task} process was cancelled"))

    def _running(self) -> bool:
        """The child has not been reaped (an exited child's pid may soon be another's): the
        same pid and start time. A fork of a Host outlives a host closed meanwhile, and is
        then a child of init's."""
        return self._born is not None and start_time(self.pid) == self._born

    def _end(self, outcome: Outcome | None) -> None:
        """It ended: reap it, and record how (outcome None: it sent none; its exit says)."""
        status = self._reap()
        self.outcome = outcome if outcome is not None else self._died(status)
        self.done = True
        self._conn.close()
        _live.discard(self)

    def _reap(self) -> int | None:
        """Wait for the child's exit: its status (or -signal), None when not ours to reap
        (a fork of a Host: the host reaps it)."""
        if self._forked:
            # It exits right after its outcome, which closes its end of the pipe: wait for
            # that, then for the exit itself. One that lingers is killed, not waited for.
            if not wait([self._conn], timeout=2.0):
                kill_tree(self.pid)
            return os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])
        if self._proc is not None:
            self._proc.join(timeout=2)
            if self._proc.exitcode is None:
                kill_tree(self.pid)
                self._proc.join()
            return self._proc.exitcode
        return None

    def _died(self, status: int | None) -> Died:
        """How a child that sent no outcome ended, from its exit status (None: unknown)."""
        if status is not None and status >= 0:
            return Died(
                cause="exit",
                status=status,
                why=f"the {self.task} process died without an answer (exit status {status})",
            )
        if status is None:
            why, cause = f"the {self.task} process ended without an answer", "exit"
        else:
            name = (
                signal.Signals(-status).name
                if -status in signal.valid_signals()
                else f"signal {-status}"
            )
            why, cause = f"the {self.task} process died without an answer ({name})", "signal"
        if self.memory:  # a C++ allocation past the limit aborts or crashes rather than raising
            why += f"; if it needed more memory than allowed, {memory_advice(self.memory)}"
        return Died(cause=cause, why=why, status=status)


def unwrap(outcome: Outcome):
    """The value of a Returned; a Raised's exception re-raised (with the child's traceback as
    a note), or ChildError with the message of one that did not travel or of a Died."""
    if isinstance(outcome, Returned):
        return outcome.value
    if isinstance(outcome, Raised):
        if outcome.error is None:
            raise ChildError(outcome.message)
        outcome.error.add_note(f"(in the child process)\n{outcome.traceback.rstrip()}")
        raise outcome.error
    if isinstance(outcome, Died):
        raise ChildError(outcome.why)
    raise TypeError(f"not an outcome: {outcome!r}")


def call(
    fn: Callable,
    args: tuple = (),
    kwargs: dict | None = None,
    *,
    start: Start = "auto",
    memory: int | None = None,
    hard_memory: bool = True,
    time_limit: float | None = None,
    task: str = "child",
    preload: tuple[str, ...] = (),
):
    """fn(*args, **kwargs) in a fresh child process (Child, same settings), waited for: its
    return value, or its exception re-raised (ChildError when it died without one). Its events
    are emitted here as they come."""
    return Child(
        fn,
        args,
        kwargs,
        start=start,
        memory=memory,
        hard_memory=hard_memory,
        time_limit=time_limit,
        task=task,
        preload=preload,
    ).result()


# -- the child's side ---------------------------------------------------------------------------


def _run(conn: Connection, work: _Work, value: tuple = ()) -> None:
    """In the new child: run work (after `value`, a Host's), sending its events on conn as
    they come and then its outcome."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it cancels
    if work.die_with_parent:
        die_with_parent()
        _leave_forkserver()
        if _orphaned(work):  # (its parent ended before the request above could cover it)
            _exit(1)
    _live.clear()  # (the parent's children, copied by a fork: not this process's to end)
    # A child may start children of its own (an experiment's workers, a plan's fork). It runs
    # as a daemonic multiprocessing process where it was started as one, which multiprocessing
    # would forbid; they die with it anyway (die_with_parent, and Cancel kills the tree).
    mp.current_process().daemon = False
    lock = threading.Lock()

    def forward(event: object) -> None:
        with lock:
            try:
                conn.send(event)
            except (BrokenPipeError, ConnectionResetError):  # the parent is gone: so is this
                _exit(1)

    _only(forward)
    try:
        limit_memory(work.memory, hard=work.hard_memory)
        outcome: Outcome = Returned(value=work.fn(*value, *work.args, **work.kwargs))
    except MemoryError:
        outcome = Died(
            cause="memory",
            why=f"the {work.task} process ran out of memory and was stopped; "
            f"{memory_advice(work.memory)}",
        )
    except BaseException as exc:  # noqa: BLE001 - every failure is the parent's to see
        outcome = Raised.of(exc)
        if not isinstance(exc, Exception):  # (SystemExit and the like: as Python shows them)
            print(outcome.traceback, end="", file=sys.stderr)
    with lock:
        _send_outcome(conn, outcome, work.task)
    sys.stdout.flush()
    sys.stderr.flush()


def _orphaned(work: _Work) -> bool:
    """The process that started this child has ended: a bare fork's parent is another, or a
    multiprocessing child's parent sentinel (a pipe the parent holds open) has closed."""
    if work.parent is not None:
        return os.getppid() != work.parent
    parent = mp.parent_process()
    return parent is not None and not parent.is_alive()


def _leave_forkserver() -> None:
    """In a child of the fork server: close its copy of the pipe end whose closing tells the
    server that the process it serves has ended. multiprocessing hands one to every child (so
    that the server outlives its last child); closed, the server ends when the process that
    started it does, and this child with it (die_with_parent). No use of the server is lost: a
    child of the server that asks for one starts its own (it does not know the first one's pid).
    Private attributes of multiprocessing's forkserver (CPython 3.11): nothing public says it."""
    forkserver = sys.modules.get("multiprocessing.forkserver")
    if forkserver is None:  # (not imported here, so not a child of the server: it imports it)
        return
    server = forkserver._forkserver
    if server._forkserver_pid is None and server._forkserver_alive_fd is not None:
        try:
            os.close(server._forkserver_alive_fd)
        except OSError:
            pass
        server._forkserver_alive_fd = None


def _send_outcome(conn: Connection, outcome: Outcome, task: str) -> None:
    try:
        conn.send(outcome)
        return
    except OSError:  # the parent is gone
        return
    except Exception as exc:  # noqa: BLE001 - it does not pickle: say so instead
        if isinstance(outcome, Raised):  # (its traceback, at least, reaches the log)
            print(outcome.traceback, end="", file=sys.stderr)
            outcome = replace(outcome, error=None)
        else:
            outcome = Raised.of(ChildError(f"the {task} process's answer does not pickle: {exc!r}"))
    try:
        conn.send(outcome)
    except OSError:
        pass


def _exit(status: int) -> None:
    """End a bare fork: flush what it printed (os._exit flushes nothing) and exit at once,
    running nothing of the parent's (atexit, finalizers)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(status)


@atexit.register
def _end_children() -> None:
    """A child dies with its parent: what is still running when this process exits is killed
    (before multiprocessing's own exit handler, registered earlier, would wait for it)."""
    for child in list(_live):
        child.cancel()


# -- a host: a long-lived child that forks per job -------------------------------------------------


class Host:
    """A long-lived child of the fork server holding `value`, which forks a fresh child of
    itself for each Child(fn, ..., start=host): fn(value, *args) starts in a few milliseconds,
    where a child of the fork server first has to receive the value. The host itself never runs
    work (so each fork starts from the state the value was received in: no OMPL draw, no PRM
    thread) and has one thread, so a bare fork is safe."""

    def __init__(self, value: object, *, name: str = "roachplan host") -> None:
        self.value = value
        self._conn, end = _FORKSERVER.Pipe(duplex=True)  # (a socket pair: it can carry an fd)
        self._proc = _FORKSERVER.Process(
            target=_host_main, args=(end, value), daemon=True, name=name
        )
        self._proc.start()
        end.close()
        self._lock = threading.Lock()

    @property
    def pid(self) -> int:
        return self._proc.pid

    @property
    def alive(self) -> bool:
        return self._proc.exitcode is None and not self._conn.closed

    def fork(self, work: _Work, end: Connection) -> int:
        """Start work in a fork of the host, sending on `end`; its pid (Child does this)."""
        with self._lock:
            self._conn.send(work)
            reduction.send_handle(self._conn, end.fileno(), self._proc.pid)
            return self._conn.recv()

    def is_parent_of(self, pid: int) -> bool:
        return parent_of(pid) == self._proc.pid

    def close(self) -> None:
        """End the host (the forks it started run on until they finish or are cancelled)."""
        if not self._lock.acquire(timeout=2):  # (a fork request stuck mid-way: end it hard)
            self._proc.kill()
            self._lock.acquire()
        try:
            if not self._conn.closed:
                self._conn.close()  # (its recv ends: it returns)
        finally:
            self._lock.release()
        self._proc.join(timeout=1)
        if self._proc.exitcode is None:
            self._proc.kill()
            self._proc.join(timeout=5)


def _host_main(conn: Connection, value: object) -> None:
    """A Host's process: for each work and writable end received, fork a child that runs
    work(value, ...) on that end, and answer its pid; return when the other end closes."""
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # (the kernel reaps the forks)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()
    _leave_forkserver()
    while True:
        try:
            work = conn.recv()
            fd = reduction.recv_handle(conn)
        except (EOFError, OSError):  # its owner closed its end or died: so does the host
            return
        pid = os.fork()
        if pid == 0:  # the fork: never returns into the loop
            status = 1
            try:
                signal.signal(signal.SIGCHLD, signal.SIG_DFL)  # (it waits for its own children)
                conn.close()
                _run(Connection(fd, readable=False), work, (value,))
                status = 0
            finally:
                _exit(status)
        os.close(fd)
        conn.send(pid)
