"""The hostile-input corpus's common parts (issue 15): each tests/test_hostile_*.py holds a
table of Cases, each a malformed or hostile input made by the test (or by a real writer) and
what the CLI must answer: its exit status, key words of its message, never a traceback; and,
where a file could be lost, that the user's files are byte-identical afterwards."""

from __future__ import annotations

import hashlib
import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from conftest import fresh_roachplan, roachplan


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
