"""A batch of trials from the page: N trials on W worker processes (the experiment's workers),
fed by a thread of its own so that the page stays usable; each finished trial is handed to the
app's loop through a queue. Cancel kills the workers at once (the trials in flight are lost).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from dataclasses import dataclass, field

from roachplan.experiments import ExperimentSpec, LocalPool

from ._app import App
from ._commands import CancelBatchCmd, RunTrialsCmd
from ._said import error_text, is_for_the_user, log_internal


@dataclass(eq=False)
class Batch:
    """A running batch of trials."""

    total: int
    done: int = 0
    successes: int = 0
    started: float = field(default_factory=time.monotonic)
    """When it started (time.monotonic) [s]."""
    results: queue.Queue = field(default_factory=queue.Queue)
    """("trial", record) per finished trial, then ("done", how it ended)."""
    cancelled: threading.Event = field(default_factory=threading.Event)
    pool: LocalPool | None = None

    @property
    def elapsed(self) -> float:
        return time.monotonic() - self.started

    def progress(self) -> str:
        """What the panel says while it runs."""
        eta = self.elapsed / max(self.done, 1) * (self.total - self.done)
        return (
            f"{self.done}/{self.total} trials, {self.successes} successes, ETA {eta:.0f} s "
            f"({self.elapsed:.0f} s so far)"
        )

    def cancel(self) -> None:
        """Stop now: no more trials are recorded; the workers are killed."""
        self.cancelled.set()
        if self.pool is not None:
            self.pool.terminate()


def start_batch(spec: ExperimentSpec, calls: list, workers: int) -> Batch:
    """Run the calls on a pool of workers in a thread; returns the batch to follow."""
    batch = Batch(total=len(calls))
    threading.Thread(
        target=_feed, args=(batch, spec, calls, workers), name="roachplan-batch", daemon=True
    ).start()
    return batch


def _feed(batch: Batch, spec: ExperimentSpec, calls: list, workers: int) -> None:
    """Feeds the worker pool and passes each finished trial on."""
    try:
        batch.pool = LocalPool(spec, workers)
        if batch.cancelled.is_set():  # cancelled while the pool was starting
            batch.pool.terminate()
        try:
            for rec in batch.pool.run(calls):
                if batch.cancelled.is_set():
                    break
                batch.results.put(("trial", rec))
        finally:
            batch.pool.close()
        batch.results.put(("done", "cancelled" if batch.cancelled.is_set() else "finished"))
    except Exception as exc:  # noqa: BLE001 - reported in the panel, in the page's words
        if not is_for_the_user(exc):
            log_internal(exc, where="the batch of trials")
        how = "cancelled" if batch.cancelled.is_set() else f"failed: {error_text(exc)}"
        batch.results.put(("done", how))


class BatchPanel:
    """The Batch of trials folder: N, workers, Run trials, Cancel batch, a progress bar and
    line."""

    def __init__(self, gui, put) -> None:
        self.batch: Batch | None = None
        with gui.add_folder("Batch of trials"):
            self.n = gui.add_number("Trials (N)", 20, min=1, max=1000, step=1)
            self.workers = gui.add_number("Workers", os.cpu_count() or 1, min=1, max=64, step=1)
            self.run_button = gui.add_button("Run trials")
            self.cancel_button = gui.add_button("Cancel batch", disabled=True)
            self.progress = gui.add_progress_bar(0.0)
            self.status = gui.add_markdown("")
        self.run_button.on_click(lambda ev: put(RunTrialsCmd(ev.client_id)))
        self.cancel_button.on_click(lambda ev: put(CancelBatchCmd(ev.client_id)))

    def start(self, spec: ExperimentSpec, start, goal) -> None:
        """spec.trials_per_route trials from spec.seed on, between these poses."""
        n, workers = spec.trials_per_route, int(self.workers.value)
        calls = [
            ("trial", (k, spec.seed + k, "", None), {"start": start, "goal": goal})
            for k in range(n)
        ]
        self.batch = start_batch(spec, calls, workers)
        self.run_button.disabled, self.cancel_button.disabled = True, False
        self.progress.value = 0.0
        self.status.content = f"Starting {n} trials on {workers} workers ..."

    def drain(self, record) -> None:
        """Pass each finished trial's record to record(trial) (App.record: whether it was
        recorded); show the progress."""
        b = self.batch
        if b is None:
            return
        while True:
            try:
                kind, payload = b.results.get_nowait()
            except queue.Empty:
                break
            if kind != "trial":
                self.end(payload)
                return
            b.done += 1
            trial = {k: v for k, v in payload.items() if k not in ("kind", "index", "target_route")}
            # (record refuses a "success" without a drive: not counted either)
            b.successes += bool(record(trial)) and trial["outcome"] == "success"
            self.progress.value = 100.0 * b.done / b.total
        text = b.progress()
        if b.done and self.status.content != text:  # (before the first: "Starting ...")
            self.status.content = text

    def cancel(self) -> None:
        """Stop the batch now (its workers are killed)."""
        if self.batch is not None:
            self.batch.cancel()
            self.end("cancelled")

    def end(self, how: str) -> None:
        b, self.batch = self.batch, None
        assert b is not None  # (drain and cancel end a running batch)
        self.status.content = (
            f"Batch {how}: {b.done}/{b.total} trials, {b.successes} successes, {b.elapsed:.1f} s."
        )
        self.run_button.disabled, self.cancel_button.disabled = False, True


def do_run_trials(app: App, cmd: RunTrialsCmd) -> None:
    """N trials between the markers, from the next seeds, with the page's planner settings."""
    panel = app.page.batch_panel
    if panel.batch is not None:
        app.page.notify(cmd.client_id, "Busy", "A batch is already running.", error=True)
        return
    start, goal = app.page.markers.valid_poses(app.world)
    scene, n = app.world.scene, int(panel.n.value)
    spec = ExperimentSpec(
        name="app",
        path=scene.path,
        scene=scene.path,
        planner=app.planner(app.page.plan_settings()),
        sim=scene.sim,
        driver=scene.driver,
        trials_per_route=n,
        seed=app.next_seed,
    )
    app.next_seed += n
    panel.start(spec, start, goal)


def do_cancel_batch(app: App, cmd: CancelBatchCmd) -> None:
    """Stop the batch now (its workers are killed)."""
    app.page.batch_panel.cancel()
