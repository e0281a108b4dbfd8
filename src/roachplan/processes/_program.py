"""Run an external program (OpenSCAD under scenes/_jail.py's limits) as a child: a time limit,
Running events while it runs, its error output kept at both ends, and killed with everything it
started when its time is up or its caller is interrupted."""

from __future__ import annotations

import subprocess
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ._events import Running, emit
from ._tree import kill_tree


@dataclass(frozen=True, kw_only=True)
class ProgramRun:
    """How a program's run ended."""

    status: int
    """Its exit status, or -signal (-9 when killed at its time limit)."""
    stdout: str
    """Its standard output, kept at both ends ("" unless asked for)."""
    stderr: str
    """Its error output: its first and last `keep` bytes, with how much was left out between."""
    seconds: float
    """Wall time from its start to its end [s]."""
    timed_out: bool
    """It was killed at its time limit."""


def run_program(
    argv: Sequence[str],
    *,
    time_limit: float,
    cwd: Path | str | None = None,
    what: str = "",
    output: bool = False,
    keep: int = 1 << 16,
) -> ProgramRun:
    """Run argv in a session of its own (the terminal's Ctrl-C is this process's to handle),
    standard input closed and output discarded (kept with output=True), and its error output
    kept at its two ends, `keep` bytes each: a model's echo() in a loop prints gigabytes, which
    must not fill this process's memory. With `what`, emits Running(what, elapsed, time_limit)
    about twice a second and once when it ends. Past time_limit [s] it is killed with
    everything it started (timed_out); so it is when this process is interrupted meanwhile
    (KeyboardInterrupt is raised on)."""
    proc = subprocess.Popen(
        list(argv),
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE if output else subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    kept: dict[str, str] = {}
    readers = [
        threading.Thread(target=_read_ends, args=(stream, name, kept, keep), daemon=True)
        for name, stream in (("stdout", proc.stdout), ("stderr", proc.stderr))
        if stream is not None
    ]
    for reader in readers:
        reader.start()
    t0, timed_out = time.monotonic(), False
    try:
        while proc.poll() is None:
            elapsed = time.monotonic() - t0
            if elapsed >= time_limit:
                timed_out = True
                kill_tree(proc.pid)
                proc.wait()
                break
            if what:
                emit(Running(what=what, elapsed=elapsed, limit=time_limit))
            try:
                proc.wait(timeout=min(0.5, time_limit - elapsed))
            except subprocess.TimeoutExpired:
                pass
    except BaseException:  # interrupted: it must not run on, unseen, up to its own limits
        kill_tree(proc.pid)
        proc.wait()
        raise
    finally:
        seconds = time.monotonic() - t0
        if what:
            emit(Running(what=what, elapsed=min(seconds, time_limit), limit=time_limit))
        for reader in readers:
            reader.join()
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
    return ProgramRun(
        status=proc.returncode,
        stdout=kept.get("stdout", ""),
        stderr=kept.get("stderr", ""),
        seconds=seconds,
        timed_out=timed_out,
    )


def _read_ends(stream, name: str, kept: dict[str, str], keep: int) -> None:
    """Read stream to its end; kept[name]: its first and last `keep` bytes as text."""
    head, tail, left_out = bytearray(), bytearray(), 0
    for chunk in iter(lambda: stream.read1(1 << 16), b""):
        room = max(keep - len(head), 0)
        head += chunk[:room]
        tail += chunk[room:]
        if len(tail) > keep:
            left_out += len(tail) - keep
            del tail[: len(tail) - keep]
    gap = f"\n... ({left_out} bytes left out) ...\n" if left_out else ""
    kept[name] = head.decode(errors="replace") + gap + tail.decode(errors="replace")
