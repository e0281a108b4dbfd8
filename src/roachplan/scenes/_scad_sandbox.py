"""OpenSCAD's sandbox: the jail a render runs in (scenes/_jail.py: user, mount and network
namespaces holding only the model's folder, read-only, the program with its libraries and
run-time data, and the folder it writes), its limits of memory ($ROACHPLAN_SCAD_MEMORY, parsed by
roachplan.processes), processor time and output size, running it (roachplan.processes.run_program:
the wall-time limit, progress, killed with everything it started), and what its failures mean.
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
import shutil
import signal
import sys
import tempfile
from pathlib import Path

from roachplan.perception import short_repr
from roachplan.processes import (
    SCAD_MEMORY_ENV,
    ChildError,
    ProgramRun,
    memory_setting,
    run_program,
    size_text,
)

from . import _jail
from ._errors import SceneError

MAX_TIMEOUT = 24 * 3600.0
"""Largest render time limit accepted [s]; past it the OS timer overflows, and no render that
long is meant."""
UNSAFE_ENV = "ROACHPLAN_UNSAFE_SCAD"
"""Set to 1 to render without the jail where the system cannot make one (the model can then
read every file the user can)."""
MEMORY_ENV = SCAD_MEMORY_ENV
"""Memory limit of one render, e.g. 16G or 512M (default: roachplan.processes'
default_memory_limit())."""


def timeout_problem(timeout: object) -> str:
    """Why timeout is not a usable render time limit [s], or "" if it is."""
    if (
        isinstance(timeout, bool)
        or not isinstance(timeout, int | float)
        or not 0 < timeout <= MAX_TIMEOUT
    ):
        return (
            f"expected a number of seconds above 0 and at most {MAX_TIMEOUT:.0f} (24 h), "
            f"got {short_repr(timeout)}"
        )
    return ""


JAIL_MODEL, JAIL_OUT = "/model", "/out"
"""Where the model's folder (read-only) and the output folder (writable) appear in the jail."""

# What OpenSCAD 2021.01 reads at run time besides its libraries (found with strace on a text()
# model): the loader's cache, fontconfig's setup, the fonts and their cache, the C library's
# locales and character sets, and its own resource folder (beside its program: ../share/openscad,
# with its fonts/ and libraries/ where installed). The user's own fonts (~/.fonts) stay outside.
RUNTIME_DATA = (
    "/etc/ld.so.cache",
    "/etc/fonts",
    "/usr/share/fontconfig",
    "/usr/share/fonts",
    "/usr/local/share/fonts",
    "/var/cache/fontconfig",
    "/usr/lib/locale",
    "/dev/null",
)
_LIBRARY_DIRS = ("/lib", "/lib64", "/usr/lib", "/usr/lib64")
"""Shown whole when `ldd` cannot list a program's libraries."""


def memory_limit() -> int:
    """The memory limit of a render [bytes]: $ROACHPLAN_SCAD_MEMORY (16G, 512M, 1.5G, or
    bytes; no 0: a render always has one) or default_memory_limit(); SceneError naming a bad
    setting."""
    try:
        return memory_setting(MEMORY_ENV, zero_means_none=False)
    except ChildError as exc:
        raise SceneError(str(exc)) from None


def program_libraries(program: str) -> list[str]:
    """The shared libraries `program` loads (its loader first), as `ldd` lists them; [] when
    ldd cannot tell (not installed, not a dynamic program)."""
    status, found = _ldd([program])
    return found if status == 0 else []


def shared_libraries(files: list[str]) -> set[str]:
    """The shared libraries any of `files` (programs, compiled modules) loads, as `ldd` lists
    them; a file ldd cannot read (not dynamic) adds nothing."""
    found: set[str] = set()
    for start in range(0, len(files), 64):  # one ldd for many files
        found.update(_ldd(files[start : start + 64])[1])
    return found


def _ldd(files: list[str]) -> tuple[int, list[str]]:
    """(ldd's exit status, the library paths it listed, in order); (-1, []) when it could not
    run or did not finish in a minute."""
    try:
        run = run_program(["ldd", *files], time_limit=60, output=True, keep=1 << 24)
    except OSError:
        return -1, []
    if run.timed_out:
        return -1, []
    # "\tlibz.so.1 => /lib/x86_64-linux-gnu/libz.so.1 (0x...)" or "\t/lib64/ld-linux... (0x...)"
    return run.status, re.findall(r"(?:=>\s*|^\s*)(/\S+)\s+\(0x", run.stdout, re.M)


def _show(path: str, ro: dict[str, str], links: dict[str, str], depth: int = 0) -> None:
    """Make `path` lead in the jail where it leads here: every symlink on the way re-created
    (its target as written), the file or folder it ends at bound read-only at the same place."""
    parts = Path(path).parts
    here = "/"
    for i, part in enumerate(parts[1:], start=1):
        step = os.path.join(here, part)
        if os.path.islink(step) and depth < 40:
            target = os.readlink(step)
            links[step] = target
            _show(
                os.path.normpath(os.path.join(here, target, *parts[i + 1 :])), ro, links, depth + 1
            )
            return
        here = step
    if os.path.exists(here):
        ro[here] = here


@functools.cache
def _jail_layout(program: str) -> tuple[dict[str, str], dict[str, str]]:
    """(read-only binds, symlinks) that let `program` run in the jail as it runs here."""
    resources = os.path.join(
        os.path.dirname(os.path.realpath(program)), "..", "share", os.path.basename(program)
    )
    libraries = program_libraries(program)
    wanted = [program, *(libraries or _LIBRARY_DIRS), *RUNTIME_DATA, os.path.normpath(resources)]
    # Character-set modules of the C library, beside it (gconv/).
    wanted += [os.path.join(os.path.dirname(lib), "gconv") for lib in libraries if "/libc." in lib]
    return jail_layout_of(wanted)


def jail_layout_of(paths: list[str]) -> tuple[dict[str, str], dict[str, str]]:
    """(read-only binds, symlinks) that show each of `paths` in the jail where it is here."""
    ro: dict[str, str] = {}
    links: dict[str, str] = {}
    for path in paths:
        _show(path, ro, links)
    folders = [p for p in ro if os.path.isdir(p)]

    def covered(path: str) -> bool:  # inside a folder shown whole: nothing to add
        return any(path != f and path.startswith(f.rstrip("/") + "/") for f in folders)

    return (
        {p: src for p, src in ro.items() if not covered(p)},
        {p: t for p, t in links.items() if not covered(p)},
    )


def confined(
    argv: list[str],
    model_dir: Path,
    work_dir: Path,
    *,
    memory: int | None = None,
    cpu: float = MAX_TIMEOUT,
    jail: bool = True,
    layout: tuple[dict[str, str], dict[str, str]] | None = None,
) -> list[str]:
    """The command that runs argv under the render limits (memory [bytes], default
    memory_limit(); cpu: processor time [s]) and, with jail, in a jail where model_dir is
    JAIL_MODEL (read-only; the working directory) and work_dir/out is JAIL_OUT (writable), and
    nothing else is but argv[0] with its libraries and OpenSCAD's run-time data. Without jail,
    argv runs here in model_dir. If the jail or the limits cannot be made, the command exits
    with _jail.SETUP_FAILED and a line starting with _jail.SETUP_TAG on stderr. layout: the
    jail's (read-only binds, symlinks) when argv[0] needs more than its libraries (the Python
    evaluator of backend manifold: scenes/_scad_manifold.py). The launcher dies with the
    process (thread) that runs the command, which must be this one."""
    program = shutil.which(argv[0]) or argv[0]
    spec: dict = {
        "argv": [program, *argv[1:]],
        "memory": memory_limit() if memory is None else int(memory),
        "cpu": math.ceil(cpu) + 1,
        "env": None,  # this process's; never on the command line, where anyone can read it
        "jail": None,
        "parent": os.getpid(),
    }
    if jail:
        ro, links = layout or _jail_layout(program)
        root = work_dir / "root"
        root.mkdir(exist_ok=True)
        (work_dir / "out").mkdir(exist_ok=True)
        spec["jail"] = {
            "root": str(root),
            "ro": {**ro, JAIL_MODEL: str(model_dir)},
            "rw": {JAIL_OUT: str(work_dir / "out")},
            "links": links,
            "tmpfs": ["/tmp"],
            "cwd": JAIL_MODEL,
        }
        spec["env"] = {"PATH": "/usr/bin:/bin", "HOME": "/tmp", "LANG": "C.UTF-8"}
    return [sys.executable, "-I", "-S", _jail.__file__, json.dumps(spec)]


def jail_wanted() -> bool:
    """Whether renders run in the jail: unless $ROACHPLAN_UNSAFE_SCAD=1."""
    return os.environ.get(UNSAFE_ENV, "").strip() not in ("1", "yes", "true")


@functools.cache
def sandbox_available() -> bool:
    """True if this system can make the jail (unprivileged user, mount and network namespaces)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = confined(["true"], Path(tmp), Path(tmp), memory=1 << 30, cpu=10)
        try:
            probe = run_program(cmd, time_limit=30)
        except OSError:
            return False
    return probe.status == 0 and not probe.timed_out


def run_confined(cmd: list[str], *, model_dir: Path, timeout: float, what: str) -> ProgramRun:
    """Run a command of `confined` as a child (roachplan.processes.run_program): killed with
    everything it started past `timeout` [s] wall time (timed_out), or when this process is
    interrupted; Running(what, ...) events while it runs; the two ends of its error output
    (OpenSCAD writes everything there) kept."""
    return run_program(cmd, cwd=model_dir, time_limit=timeout, what=what)


def limit_hit(returncode: int, err: str, *, memory: int, timeout: float) -> str:
    """Which limit stopped OpenSCAD, with how to raise it; "" if none did."""
    sig = -returncode if returncode < 0 else 0
    raise_memory = f"set {MEMORY_ENV}=SIZE (now {size_text(memory)}; e.g. {MEMORY_ENV}=16G)"
    if sig == signal.SIGXCPU:  # the wall-clock limit comes first unless this process stalled
        return (
            f"OpenSCAD used up its processor-time limit of {timeout:g} s and was stopped; a "
            f"slow model may take more: give this terrain object `timeout: SECONDS` (or "
            f"--scad-timeout SECONDS), at most {MAX_TIMEOUT:.0f}"
        )
    if sig == signal.SIGXFSZ:
        return (
            f"OpenSCAD's mesh grew past the output size limit of {size_text(memory)} (the "
            f"memory limit) and was stopped; to allow more, {raise_memory}"
        )
    if "bad_alloc" in err or "out of memory" in err.lower():
        return (
            f"OpenSCAD ran out of memory at its limit of {size_text(memory)} and was "
            f"stopped; a large model may need more: {raise_memory}"
        )
    if sig:
        name = signal.Signals(sig).name if sig in signal.valid_signals() else f"signal {sig}"
        return (
            f"OpenSCAD was stopped ({name}); a model that needs more than its memory limit "
            f"of {size_text(memory)}, or than the machine has, may end this way: {raise_memory}"
        )
    return ""


def render_failure(
    scad_file: Path,
    run: ProgramRun,
    *,
    memory: int,
    timeout: float,
    jail: bool,
) -> str:
    """Why a render that left no mesh failed, for a SceneError: the jail could not be made, a
    limit was hit, or OpenSCAD's own errors (its jail paths turned back into real ones)."""
    err = run.stderr.replace(f"{JAIL_MODEL}/", f"{scad_file.parent}/") if jail else run.stderr
    if run.status == _jail.SETUP_FAILED and _jail.SETUP_TAG in err:
        why = err.split(_jail.SETUP_TAG, 1)[1].strip().splitlines()[0]
        if not jail:
            return f"cannot start OpenSCAD under its limits: {why}"
        return (
            f"cannot render: OpenSCAD models run in a jail that sees only the model's folder, "
            f"and this system refused to make one ({why}): unprivileged user namespaces are "
            f"off or used up here (sysctl kernel.unprivileged_userns_clone, "
            f"user.max_user_namespaces, AppArmor's kernel.apparmor_restrict_unprivileged_userns, "
            f"or a container's seccomp profile). To render without the jail, "
            f"trusting this model with every file you can read, set {UNSAFE_ENV}=1"
        )
    limit = limit_hit(run.status, err, memory=memory, timeout=timeout)
    if limit:
        return limit
    lines = [line for line in err.splitlines() if "ERROR" in line or "WARNING" in line]
    detail = _bounded(lines)
    if jail and ("couldn't be opened" in err or "Can't open" in err):
        detail += f"\n(a model sees only the files in its own folder, {scad_file.parent})"
    if "Current top level object is empty" in err:
        detail = (detail + "\nthe model produces no geometry").strip()
    return f"OpenSCAD failed:\n{detail.strip() or _bounded(err.strip().splitlines()[-20:])}"


MESH_WARNINGS = ("2-manifold", "WARNING: export:")
"""The renderers' warnings about the mesh they write (the binary's "may not be a valid
2-manifold", the evaluator's "export: removed N zero-area faces"): roachplan's mesh cleaning
repairs such meshes, so they are not the model's own messages."""


def render_warnings(run: ProgramRun, *, jail: bool, count: int = 4) -> tuple[str, ...]:
    """The ERROR and WARNING lines of a render that made a mesh, each once, at most `count`
    (with a last "... and N more lines"), file names as the model's folder sees them. OpenSCAD goes
    on past a used file it cannot parse or a module it does not know, leaving that part out:
    these lines are how a user learns that the mesh lacks it."""
    err = run.stderr.replace(f"{JAIL_MODEL}/", "") if jail else run.stderr
    lines = [
        line.strip()
        for line in err.splitlines()
        if line.lstrip().startswith(("ERROR:", "WARNING:"))
        and not any(mark in line for mark in MESH_WARNINGS)
    ]
    return tuple(_bounded_lines(list(dict.fromkeys(lines)), count, 200))


def _bounded(lines: list[str], count: int = 20, width: int = 300) -> str:
    """_bounded_lines, one a line."""
    return "\n".join(_bounded_lines(lines, count, width))


def _bounded_lines(lines: list[str], count: int, width: int) -> list[str]:
    """At most `count` lines of at most `width` characters, and how many more there were: a
    model's echo() or a flood of warnings must not become megabytes of error text."""
    shown = [line if len(line) <= width else line[: width - 3] + "..." for line in lines[:count]]
    if len(lines) > count:
        shown.append(f"... and {len(lines) - count} more lines")
    return shown
