"""The command loop: the one thread that owns the app's state.

It takes the page's commands (app/_commands.py) from a queue and runs them one at a time, each by
its handler in the registry (app/_registry.py). A long command runs its work in a child process
and has the loop follow it (`follow`): the page stays live, shows the progress, and Cancel kills
the child at once. A click made meanwhile does what its registry entry says: it runs at once (it
starts or stops background work, or changes only the view), waits its turn (said to whoever
clicked, and listed in the status line) or, for a re-check of the markers, waits once and
silently.

The loop knows nothing of viser: it shows itself through `Shell`, and each handler gets the
`App` the loop was started with (app/_app.py), so a unit test drives it with a fake page and real
jobs (tests/test_loop.py).
"""

from __future__ import annotations

import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Generic, Literal, Protocol, TypeVar

from ._commands import Cmd
from ._said import error_text, is_for_the_user, log_internal

if TYPE_CHECKING:
    from ._app import App


class Followed(Protocol):
    """What `follow` follows: a job in a child (app/_jobs.py Job), or other work that tells its
    progress as events and stops when cancelled (the Robot folder's loop)."""

    def poll(self, timeout: float = 0.0) -> list:
        """The events sent since the last poll, waiting up to timeout [s] for the first."""
        ...

    def cancel(self) -> None:
        """Stop the work now."""
        ...


WhileBusy = Literal["run", "queue", "once"]
"""What a click does while another command runs: "run" at once, "queue" (wait its turn, said to
whoever clicked), "once" (wait silently, the latest of its kind; kept when Cancel drops the rest)."""
FollowEnd = Literal["done", "cancelled", "stopped"]
"""How a followed job ended: it finished, Cancel killed it, or it ran past its hard stop."""

C = TypeVar("C", bound=Cmd)


@dataclass(frozen=True, kw_only=True)
class Command(Generic[C]):
    """One kind of command, as the registry lists it."""

    handler: Callable[[App, C], None]
    """Runs the command on the loop thread: handler(app, command). What it raises becomes a
    notification to whoever clicked, and the loop goes on."""
    name: str
    """How the page names it: "Plan queued", "Queued: Plan, Drive", "Plan not run"."""
    while_busy: WhileBusy | Callable[[App, C], WhileBusy] = "queue"
    """What a click on it does while another command runs (WhileBusy), or a function of the app
    and the command that says so when the click arrives."""


class Shell(Protocol):
    """What the loop needs of the app around it: the viser shell (app/_server.py), or a unit
    test's fake."""

    def set_status(self, text: str) -> None:
        """The status line at the top of the panel."""
        ...

    def notify(self, client_id: int | None, title: str, body: str, *, error: bool = False) -> None:
        """A notification to one browser (none for None)."""
        ...

    def public(self, text: str) -> str:
        """A message in the page's words (no server paths)."""
        ...

    def show_job(self, running: bool) -> None:
        """Show (at 0 %) or hide the Cancel button and the progress bar of a followed job."""
        ...

    def set_job_progress(self, percent: float) -> None:
        """The followed job's progress bar [%]."""
        ...

    def between(self, *, idle: bool) -> None:
        """Follow the background work (a batch, a scene load) between commands and while a
        job runs; idle: no command runs or waits."""
        ...

    def command_done(self) -> None:
        """After each command (the page's controls that follow the state)."""
        ...


class CommandLoop:
    """The command queue and the thread that drains it; `follow` for handlers whose work runs in
    a child process."""

    def __init__(self, registry: Mapping[type[Cmd], Command[Any]], shell: Shell) -> None:
        self.registry = registry
        self.shell = shell
        self.commands: queue.Queue[Cmd] = queue.Queue()
        """What the callbacks put (`put`)."""
        self.waiting: deque[Cmd] = deque()
        """Commands clicked while another ran, in order."""
        self.running: str | None = None
        """The name of the command whose job is followed now."""
        self.job: Followed | None = None
        """That job."""
        self._cancel = False
        self._stop = threading.Event()
        self._app: App | None = None
        self._thread: threading.Thread | None = None

    def put(self, cmd: Cmd) -> None:
        """Queue a command (any thread: a viser callback)."""
        self.commands.put(cmd)

    def start(self, app: App, *, setup: Callable[[], None] | None = None) -> None:
        """Serve commands on a thread of the loop's own, each handled with app; setup() runs
        first on that thread (commands wait for it)."""
        self._app = app
        self._thread = threading.Thread(
            target=self._serve, args=(setup,), name="roachplan-loop", daemon=True
        )
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop serving (a followed job is cancelled) and wait for the thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout)

    def cancel(self) -> None:
        """Cancel the followed job (killed at once) and drop what waits behind it; nothing when
        no job is followed."""
        self._cancel = self.running is not None

    # -- for handlers ---------------------------------------------------------------------------

    def follow(
        self,
        job: Followed,
        name: str,
        step: Callable[[list], bool],
        *,
        hard_stop: float | None = None,
    ) -> FollowEnd:
        """Keep the page live while job runs: step(messages) shows its progress and returns
        True when the work is complete. Meanwhile clicks are taken in (`_intake`) and the
        background work followed. hard_stop: a time.monotonic() [s] past which the job is
        killed. The job's child is gone when this returns."""
        self.running, self.job, self._cancel = name, job, False
        self.shell.show_job(True)
        try:
            while True:
                if step(job.poll(timeout=1 / 60)):
                    return "done"
                self._intake()
                if self._cancel or self._stop.is_set():
                    job.cancel()
                    self._drop_waiting(name)
                    return "cancelled"
                if hard_stop is not None and time.monotonic() > hard_stop:
                    job.cancel()
                    return "stopped"
                self.shell.between(idle=False)
        finally:
            job.cancel()  # (nothing when it finished; a failed step leaves no child behind)
            self.running = self.job = None
            self.shell.show_job(False)

    def progress(self, fraction: float | None, text: str) -> None:
        """The followed job's status line and progress bar (fraction 0-1; None: unknown), with
        the commands queued behind it."""
        if fraction is not None:
            self.shell.set_job_progress(round(100.0 * min(max(fraction, 0.0), 1.0), 1))
        names = [self._entry(c).name for c in self.waiting if not self._silent(c)]
        if names:
            text += f"  \nQueued: {', '.join(names)}"
        self.shell.set_status(text)

    # -- the loop -------------------------------------------------------------------------------

    def _serve(self, setup: Callable[[], None] | None) -> None:
        if setup is not None:
            setup()
        while not self._stop.is_set():
            self.shell.between(idle=not self.waiting)
            if self.waiting:
                cmd = self.waiting.popleft()
            else:
                try:
                    cmd = self.commands.get(timeout=0.05)
                except queue.Empty:
                    continue
            # The buttons stay enabled while a command runs: viser drops a click on a disabled
            # button, so another browser's click would be lost; clicks queue here instead.
            self._run(cmd)

    def _run(self, cmd: Cmd) -> None:
        try:
            self._entry(cmd).handler(self._handed(), cmd)
        except Exception as exc:  # keep serving whatever went wrong in one command
            # The user reads a sentence: an exception's own text only where it was written for
            # them (app/_said.py); a fault of the app is named, its traceback logged.
            entry = self.registry.get(type(cmd))
            name = entry.name if entry is not None else type(cmd).__name__
            if not is_for_the_user(exc):
                log_internal(exc, where=name)
            text = self.shell.public(error_text(exc))
            self.shell.notify(cmd.client_id, f"{name} failed", text, error=True)
            self.shell.set_status(f"{name} failed: {text}")
        finally:
            self.shell.command_done()

    def _intake(self) -> None:
        """While a job is followed: run what the registry says runs at once; queue the rest,
        saying so to whoever clicked."""
        while True:
            try:
                cmd = self.commands.get_nowait()
            except queue.Empty:
                return
            entry = self.registry.get(type(cmd))
            if entry is None:  # (it fails now, as a notification)
                self._run(cmd)
                continue
            how = entry.while_busy
            if callable(how):
                how = how(self._handed(), cmd)
            if how == "run":
                self._run(cmd)
            elif how == "once":  # (the latest of its kind, in the first one's place)
                same = [k for k, c in enumerate(self.waiting) if type(c) is type(cmd)]
                if same:
                    self.waiting[same[0]] = cmd
                else:
                    self.waiting.append(cmd)
            else:
                self.waiting.append(cmd)
                self.shell.notify(
                    cmd.client_id,
                    f"{entry.name} queued",
                    f"It runs when {self.running} ends; Cancel (at the top) stops "
                    f"{self.running} and drops what is queued.",
                )

    def _drop_waiting(self, name: str) -> None:
        """Cancel: the commands queued behind the cancelled one are not run (each said so to
        whoever clicked); a silent re-check ("once") stays, as it re-checks what is shown."""
        kept: deque[Cmd] = deque()
        while self.waiting:
            cmd = self.waiting.popleft()
            if self._silent(cmd):
                kept.append(cmd)
            else:
                self.shell.notify(
                    cmd.client_id,
                    f"{self._entry(cmd).name} not run",
                    f"{name} was cancelled, and what was queued behind it dropped.",
                )
        self.waiting = kept

    def _handed(self) -> App:
        """The app the handlers get."""
        if self._app is None:
            raise RuntimeError("the command loop serves only once started (start)")
        return self._app

    def _entry(self, cmd: Cmd) -> Command[Any]:
        entry = self.registry.get(type(cmd))
        if entry is None:
            raise TypeError(f"{type(cmd).__name__}: no handler in the command registry")
        return entry

    def _silent(self, cmd: Cmd) -> bool:
        entry = self.registry.get(type(cmd))
        return entry is not None and entry.while_busy == "once"
