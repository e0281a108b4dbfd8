"""The `roachplan` command line run in a fork of a process that has already imported it: the
tests run it some 450 times (the hostile-input corpus 220), and a fresh interpreter spent most
of each run importing (numpy, Open3D, trimesh: 2-5 s a run on a busy 2-core machine).
conftest.roachplan runs it so; conftest.fresh_roachplan in a new interpreter, for what only a
new one shows (a command's own start-up, Open3D's log).

The server (`python tests/cli_forks.py`, one per test process) imports the command line and
the packages its commands load, then for each request forks a child: its own process with its
standard output and error (the file descriptors, so a C library's printout is caught too) sent
to files, its working directory the repository's, its environment the test's (as a subprocess
inherits it), `roachplan.app.cli.main(argv)` its whole work
and its exit status main's. The server is single-threaded and has run nothing: what a child
inherits is imported modules, as a fresh `python -m roachplan` would have after its imports.
"""

from __future__ import annotations

import atexit
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PRELOAD = (
    "roachplan.app.cli",
    "roachplan.app._perception_cli",
    "roachplan.app._plan_cli",
    "roachplan.app._scene_cli",
    "roachplan.perception",
    "roachplan.scenes",
    "numpy",
    "trimesh",
    "open3d",
)
"""What the server imports before it forks (each child then skips it)."""


def _serve() -> None:
    """Read one JSON request per line ({"argv": [...], "timeout": s, "env": the caller's
    environment}); answer one JSON line
    ({"status": int, "stdout": str, "stderr": str})."""
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    from roachplan.app.cli import main

    out = sys.stdout
    sys.stdout = sys.stderr  # (the protocol's lines alone on the real stdout)
    print("ready", file=out, flush=True)
    for line in sys.stdin:
        request = json.loads(line)
        with tempfile.TemporaryDirectory() as tmp:
            paths = [os.path.join(tmp, "out"), os.path.join(tmp, "err")]
            pid = os.fork()
            if pid == 0:  # the child: the command, its output in the two files
                status = 1
                try:
                    os.setpgid(0, 0)
                    for fd, path in zip((1, 2), paths, strict=True):
                        target = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
                        os.dup2(target, fd)
                        os.close(target)
                    sys.stdout = open(1, "w", closefd=False)  # noqa: SIM115
                    sys.stderr = open(2, "w", closefd=False)  # noqa: SIM115
                    sys.stdin = open(os.devnull)  # noqa: SIM115
                    os.chdir(ROOT)
                    os.environ.clear()  # (the test's environment: a case's settings, its cache)
                    os.environ.update(request["env"])
                    status = main(request["argv"])
                except SystemExit as exc:  # (argparse's usage errors exit)
                    status = exc.code if isinstance(exc.code, int) else 2
                finally:
                    sys.stdout.flush()
                    sys.stderr.flush()
                    os._exit(status)
            status = _wait(pid, request["timeout"])
            texts = [Path(p).read_text(errors="replace") for p in paths]
        answer = {"status": status, "stdout": texts[0], "stderr": texts[1]}
        print(json.dumps(answer), file=out, flush=True)


def _wait(pid: int, timeout: float) -> int:
    """The child's exit status; killed (its process group) at timeout [s]: -9."""
    deadline = time.monotonic() + timeout
    while True:
        done, code = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(code)
        if time.monotonic() > deadline:
            os.killpg(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            return -9
        time.sleep(0.005)


class ForkedCli:
    """A client of one server: run(argv) gives a CompletedProcess as subprocess.run would."""

    def __init__(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, __file__],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        assert self.proc.stdout is not None and self.proc.stdout.readline().strip() == "ready"

    def run(self, argv: list[str], timeout: float) -> subprocess.CompletedProcess:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        request = {"argv": argv, "timeout": timeout, "env": dict(os.environ)}
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        answer = json.loads(self.proc.stdout.readline())
        if answer["status"] == -9:
            raise subprocess.TimeoutExpired(argv, timeout)
        return subprocess.CompletedProcess(
            ["roachplan", *argv], answer["status"], answer["stdout"], answer["stderr"]
        )

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        self.proc.wait(timeout=30)


_SERVERS: list[ForkedCli] = []
"""This test process's fork server (started on first use; again if it has died)."""


def forked_roachplan(argv: list[str], timeout: float) -> subprocess.CompletedProcess:
    """`roachplan ARGV` as a fork of this test process's server, with its own output, working
    directory (the repository's), environment (the test's) and exit status."""
    if not _SERVERS or _SERVERS[-1].proc.poll() is not None:
        _SERVERS.append(ForkedCli())
        atexit.register(_SERVERS[-1].close)
    return _SERVERS[-1].run(argv, timeout)


if __name__ == "__main__":
    _serve()
