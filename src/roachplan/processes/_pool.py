"""A pool of long-lived worker processes, each a Child: set up once, then serving calls, each
call's result an event of the worker's stream."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait

from ._child import _FORKSERVER, Child, Start, unwrap
from ._errors import WorkerDied
from ._events import Died, Raised, Returned, emit


@dataclass(frozen=True)
class _Request:
    """One call sent to a worker."""

    ticket: int
    call: object


@dataclass(frozen=True, kw_only=True)
class CallDone:
    """A worker finished one call (a worker's event)."""

    ticket: int
    outcome: Returned | Raised


def _serve(requests: Connection, setup: Callable, setup_args: tuple, handle: Callable) -> None:
    """A worker's life: state = setup(*setup_args), then handle(state, call) for each request,
    until the pool closes its end; then state.close(), if it has one."""
    state = setup(*setup_args)
    while True:
        try:
            request: _Request = requests.recv()
        except (EOFError, OSError):
            break
        try:
            outcome: Returned | Raised = Returned(value=handle(state, request.call))
        except Exception as exc:  # noqa: BLE001 - the caller's to see, as the call's result
            outcome = Raised.of(exc)
        emit(CallDone(ticket=request.ticket, outcome=outcome))
    close = getattr(state, "close", None)
    if close is not None:
        close()


class Pool:
    """`workers` worker processes, each a Child (its limits, dying with this process) that
    runs state = setup(*setup_args) once and then handle(state, call) for each call; `run`
    yields results as they finish. setup and handle must be module-level (they are pickled).

    Spawned by default (fresh interpreters, children of this process): forking a process that
    may hold threads is unsafe. A worker asks to die with the thread that made the pool: make
    and close it in one thread.
    """

    def __init__(
        self,
        workers: int,
        setup: Callable,
        setup_args: tuple = (),
        *,
        handle: Callable,
        start: Start = "spawn",
        memory: int | None = None,
        task: str = "worker",
    ) -> None:
        self.workers = workers
        self.task = task
        self._children: list[Child] = []
        self._requests: list[Connection] = []
        self._load: list[int] = []
        """Calls sent to each worker and not yet answered."""
        self._tickets: dict[int, int] = {}
        """Ticket -> worker, of every call not yet answered (of this run or an abandoned one)."""
        self._next = 0
        try:
            for _ in range(workers):
                theirs, ours = _FORKSERVER.Pipe(duplex=False)
                try:
                    child = Child(
                        _serve,
                        (theirs, setup, tuple(setup_args), handle),
                        start=start,
                        memory=memory,
                        task=task,
                    )
                finally:
                    theirs.close()
                self._children.append(child)
                self._requests.append(ours)
                self._load.append(0)
        except BaseException:
            self.terminate()
            self.close()
            raise

    def run(self, calls: Iterable) -> Iterator:
        """Each call's result (what handle returned) as it finishes, in any order; a call's
        exception is raised here. At most 2 calls per worker are queued, so an interrupted run
        leaves little in flight (what was is dropped, not yielded by a later run). WorkerDied
        when a worker ends (killed: terminate, or crashed) while calls are left."""
        todo = iter(calls)
        mine: set[int] = set()
        more = True
        while True:
            while more:
                k = min(range(self.workers), key=self._load.__getitem__)
                if self._load[k] >= 2:
                    break
                call = next(todo, _END)
                if call is _END:
                    more = False
                    break
                mine.add(self._send(k, call))
            if not mine:
                return
            busy = sorted({self._tickets[t] for t in mine})
            wait([self._children[k]._conn for k in busy])
            for k in busy:
                for done in self._collect(k):
                    if done.ticket in mine:
                        mine.discard(done.ticket)
                        yield unwrap(done.outcome)
                child = self._children[k]
                if child.done:
                    raise WorkerDied(f"a worker ended with calls left: {_why(child)}")

    def _send(self, k: int, call: object) -> int:
        ticket, self._next = self._next, self._next + 1
        self._requests[k].send(_Request(ticket, call))
        self._tickets[ticket] = k
        self._load[k] += 1
        return ticket

    def _collect(self, k: int) -> list[CallDone]:
        """Worker k's answers since the last look (other events, such as an OpenSCAD render's
        Running while it sets up, are not the pool's to show)."""
        out = []
        for event in self._children[k].poll():
            if isinstance(event, CallDone) and self._tickets.pop(event.ticket, None) is not None:
                self._load[k] -= 1
                out.append(event)
        return out

    def close(self) -> None:
        """Let every worker finish what it was sent, then end it (and reap it)."""
        for conn in self._requests:
            conn.close()  # (its worker's recv ends: it returns)
        for child in self._children:
            child.wait(on_event=lambda _: None)

    def terminate(self) -> None:
        """Kill every worker (and what it started) now: the calls in flight are lost. Safe from
        another thread than the one iterating `run`, which then raises WorkerDied."""
        for child in list(self._children):
            child.kill()


_END = object()


def _why(child: Child) -> str:
    outcome = child.outcome
    if isinstance(outcome, Died):
        return outcome.why
    if isinstance(outcome, Raised):
        return f"it could not set up: {outcome.message}"
    return "it returned"
