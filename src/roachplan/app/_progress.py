"""Progress bars of the long command-line commands, in the experiment's style (tqdm on stderr):
an OpenSCAD render (seconds of its time limit), meshing a capture (its stages), planning many
paths (paths found), choosing (share of the race). Shown when stderr is a terminal, or with
ROACHPLAN_PROGRESS=1 (what a log or a test sets); never on stdout, which `--json` owns."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tqdm import tqdm


LOG_FIRST = 10.0
"""Seconds a render runs before a log line says it is rendering (no bar: not a terminal)."""
LOG_EVERY = 60.0
"""Seconds between such lines."""


def wanted() -> bool:
    """Whether to draw progress bars: on a terminal, or when asked for."""
    return os.environ.get("ROACHPLAN_PROGRESS") == "1" or sys.stderr.isatty()


def bar(
    total: float | None, what: str, *, unit: str, enabled: bool | None = None, **kw
) -> tqdm[Any]:
    """A tqdm bar on stderr in the experiment's style (experiments/_runner._bar)."""
    from tqdm import tqdm

    # No monitor thread: a thread that fails to start under a child's memory limit leaves
    # Thread.start() waiting forever (the bars refresh on update instead).
    tqdm.monitor_interval = 0
    return tqdm(
        total=total,
        desc=what,
        unit=unit,
        file=sys.stderr,
        mininterval=0.5,
        smoothing=0.1,
        disable=not (wanted() if enabled is None else enabled),
        **kw,
    )


@contextmanager
def render_progress(enabled: bool | None = None) -> Iterator[None]:
    """While inside, every OpenSCAD render shows a bar: seconds elapsed of its time limit (the
    Running events of roachplan.processes, from this process or a child it waits for).
    Without a bar (stderr not a terminal: a log, a script) a render that takes long still
    says so, in a line after LOG_FIRST seconds and every LOG_EVERY seconds after."""
    from roachplan.processes import Running, listening

    if not (wanted() if enabled is None else enabled):
        said: dict[str, float] = {}

        def log(event: object) -> None:
            if not isinstance(event, Running) or event.elapsed < LOG_FIRST:
                return
            last = said.get(event.what)
            if last is not None and event.elapsed < last:
                last = None  # a new render of the same model (auto's binary after manifold)
            if last is None or event.elapsed - last >= LOG_EVERY:
                said[event.what] = event.elapsed
                print(
                    f"roachplan: OpenSCAD {event.what}: rendering, {event.elapsed:.0f} s of "
                    f"its {event.limit:.0f} s limit",
                    file=sys.stderr,
                    flush=True,
                )

        with listening(log):
            yield
        return

    bars: dict[str, tqdm[Any]] = {}

    def hear(event: object) -> None:
        if not isinstance(event, Running):
            return
        b = bars.get(event.what)
        if b is None:
            b = bars[event.what] = bar(
                round(event.limit),
                f"OpenSCAD {event.what}",
                unit="s",
                enabled=True,
                bar_format="{desc}: {n:.0f} of {total} s limit |{bar}| {elapsed}",
            )
        b.n = min(event.elapsed, event.limit)
        b.refresh()

    try:
        with listening(hear):
            yield
    finally:
        for b in bars.values():
            b.close()


def stage_progress(stages: tuple[str, ...], what: str) -> tuple[tqdm[Any], Callable[[str], None]]:
    """(bar, on_stage): a bar over a pipeline's named stages; on_stage(name) marks one done."""
    b = bar(len(stages), what, unit=" stage")

    def on_stage(name: str) -> None:
        b.set_postfix_str(name, refresh=False)
        b.update(1)

    return b, on_stage
