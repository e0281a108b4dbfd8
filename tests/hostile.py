"""The hostile-input corpus's common parts (issue 15): each tests/test_hostile_*.py holds a
table of Cases, each a malformed or hostile input made by the test (or by a real writer) and
what the CLI must answer: its exit status, key words of its message, never a traceback; and,
where a file could be lost, that the user's files are byte-identical afterwards."""

from __future__ import annotations

import atexit
import hashlib
import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from cli_forks import ForkedCli
from conftest import roachplan as fresh_roachplan

_SERVERS: list[ForkedCli] = []
"""This test process's fork server (started on first use)."""


def roachplan(*argv: str, timeout: float) -> subprocess.CompletedProcess:
    """`roachplan ARGV` as a fork of a process that has imported the command line (cli_forks:
    the corpus's 220 runs spent most of their time importing), with its own output, working
    directory and exit status."""
    if not _SERVERS or _SERVERS[-1].proc.poll() is not None:
        _SERVERS.append(ForkedCli())
        atexit.register(_SERVERS[-1].close)
    return _SERVERS[-1].run(list(argv), timeout)


@dataclass(frozen=True)
class Case:
    """One hostile input. make(tmp_path) writes what it needs and returns the CLI's argv;
    the run must exit with `status` (2: bad input, 1: a run that failed) and print every one
    of `words` (case-insensitive) on stderr+stdout."""

    name: str
    make: Callable[[Path], list[str]]
    words: tuple[str, ...]
    status: int = 2
    timeout: float = 120.0
    keep: tuple[str, ...] = field(default=())
    """Files (relative to tmp_path) that must be byte-identical after the run."""
    fork: bool = True
    """Run as a fork of a process that imported the command line (cli_forks); False: a
    fresh interpreter, for a case whose answer quotes Open3D's log (a fork's child prints that
    log after the reader's capture of it has ended: only Open3D's own state differs)."""


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run_case(case: Case, tmp_path: Path) -> subprocess.CompletedProcess:
    """Run one case and assert what every case must hold; returns the process for extra checks."""
    argv = case.make(tmp_path)
    before = {name: digest(tmp_path / name) for name in case.keep}
    proc = (roachplan if case.fork else fresh_roachplan)(*argv, timeout=case.timeout)
    out = proc.stdout + proc.stderr
    assert "Traceback" not in out, f"{case.name}: traceback:\n{out[-3000:]}"
    assert proc.returncode == case.status, (
        f"{case.name}: exit {proc.returncode}, expected {case.status}:\n{out[-2000:]}"
    )
    for word in case.words:
        assert word.lower() in out.lower(), f"{case.name}: {word!r} not in:\n{out[-2000:]}"
    assert len(out) < 20_000, f"{case.name}: {len(out)} characters of output"
    for name, before_digest in before.items():
        assert digest(tmp_path / name) == before_digest, f"{case.name}: {name} was changed"
    return proc
