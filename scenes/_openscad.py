"""Render OpenSCAD models with the real `openscad` binary: confined, time-limited, cached.

A model may only read files in its own folder. Before OpenSCAD runs, the model and everything it
includes are scanned: `include <f>`, `use <f>` and every file-reading call (`import`, `surface`,
`file = ...` arguments) must name a literal relative path that stays inside the folder, so a
refusal names the file, the line and the offending path. Where the kernel allows unprivileged
user namespaces, OpenSCAD then also runs with the home, work and temporary folders hidden, so a
path the scan could not see is still not readable.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from ._errors import SceneError

ScadValue = float | int | bool | str

DEFAULT_TIMEOUT = 600.0
"""Wall-time limit of one OpenSCAD render [s] unless a scene sets its own: ordinary public
models (text(), includes, a few hundred CSG operations) take 2-4 minutes in OpenSCAD 2021.01's
CGAL, so a minute stopped most of them."""
MAX_TIMEOUT = 24 * 3600.0
"""Largest render time limit accepted [s]; past it the OS timer overflows, and no render that
long is meant."""

# Built-in modules and functions that read a file named by their first positional argument
# (OpenSCAD 2021.01, including the deprecated import_* modules). Any call's `file = ...`
# argument is checked too (dxf_dim, dxf_cross, linear_extrude(file=...), ...).
_FILE_CALLS = ("import", "surface", "import_stl", "import_off", "import_dxf")
_HIDDEN_DIRS = ("/home", "/root", "/tmp", "/var/tmp", "/work", "/srv", "/opt", "/media")


def cache_dir() -> Path:
    """Where rendered meshes are kept: $ROACHPLAN_CACHE or ~/.cache/roachplan."""
    root = os.environ.get("ROACHPLAN_CACHE") or Path.home() / ".cache" / "roachplan"
    return Path(root) / "openscad"


def openscad_binary() -> str:
    exe = shutil.which("openscad")
    if exe is None:
        raise SceneError(
            "the `openscad` program is not installed; `make run` / `make test` install it "
            "(Debian: apt-get install openscad)"
        )
    return exe


@functools.cache
def openscad_version() -> str:
    out = subprocess.run(
        [openscad_binary(), "--version"], capture_output=True, text=True, timeout=30, check=False
    )
    return (out.stdout + out.stderr).strip()


# -- static scan of a model's file references ------------------------------------------------


@dataclass(frozen=True)
class ScadSource:
    """A model's text with comments blanked (strings and line numbers kept)."""

    path: Path
    code: str

    @staticmethod
    def read(path: Path) -> ScadSource:
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            raise SceneError(f"{path}: not a text file (an OpenSCAD model is UTF-8 text)") from None
        return ScadSource(path, _blank_comments(text))

    def line_of(self, offset: int) -> int:
        return self.code.count("\n", 0, offset) + 1


def _blank_comments(text: str) -> str:
    """Replace // and /* */ comments by spaces, keeping newlines and string literals."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(text[i : j + 1])
            i = j + 1
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def _call_arguments(code: str, open_paren: int) -> list[str]:
    """The top-level comma-separated arguments of the call whose '(' is at open_paren."""
    args, depth, start, i = [], 0, open_paren + 1, open_paren
    while i < len(code):
        c = code[i]
        if c == '"':
            i += 1
            while i < len(code) and code[i] != '"':
                i += 2 if code[i] == "\\" else 1
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
            if depth == 0:
                args.append(code[start:i])
                break
        elif c == "," and depth == 1:
            args.append(code[start:i])
            start = i + 1
        i += 1
    return [a.strip() for a in args if a.strip()]


_STRING = re.compile(r'"((?:[^"\\]|\\.)*)"')


def _file_references(src: ScadSource) -> list[tuple[str, int, str]]:
    """(kind, line, argument text) for every include/use and file-reading argument."""
    refs = [
        (m.group(1), src.line_of(m.start()), m.group(2))
        for m in re.finditer(r"\b(include|use)\s*<([^>]*)>", src.code)
    ]
    for m in re.finditer(r"\b(\w+)\s*\(", src.code):
        args = _call_arguments(src.code, m.end() - 1)
        for k, arg in enumerate(args):
            named = re.match(r"file\s*=(?!=)\s*(.*)$", arg, re.S)
            if named:
                refs.append((m.group(1), src.line_of(m.start()), named.group(1).strip()))
            elif k == 0 and m.group(1) in _FILE_CALLS and not re.match(r"\w+\s*=(?!=)", arg):
                refs.append((m.group(1), src.line_of(m.start()), arg))
    return refs


def scad_dependencies(scad_file: Path) -> list[Path]:
    """Every file a model reads (its includes, uses, imports and height maps, recursively).

    Raises SceneError, naming file, line and path, for a reference that is not a literal
    relative path inside the model's own folder, or that does not exist.
    """
    scad_file = Path(scad_file).resolve()
    root = scad_file.parent
    deps: list[Path] = []
    todo, seen = [scad_file], {scad_file}
    while todo:
        src = ScadSource.read(todo.pop())
        for kind, line, arg in _file_references(src):
            where = f"{src.path}, line {line}: {kind}"
            if kind in ("include", "use"):
                name = arg
            else:
                lit = _STRING.fullmatch(arg)
                if lit is None:
                    raise SceneError(
                        f'{where}: the file must be a literal string such as "terrain.dat" '
                        f"(got `{arg}`), so it can be checked to stay in the model's folder"
                    )
                name = lit.group(1)
            rel = Path(name)
            if not name or rel.is_absolute() or name.startswith("~") or ".." in rel.parts:
                raise SceneError(
                    f"{where} {name!r}: a model may only read files in its own folder "
                    f"({root}); use a relative path without '..'"
                )
            target = (src.path.parent / rel).resolve()
            if not target.is_relative_to(root):
                raise SceneError(f"{where} {name!r} leads outside the model's folder {root}")
            if not target.is_file():
                hint = (
                    " (library includes such as MCAD are not allowed)"
                    if kind in ("include", "use")
                    else ""
                )
                raise SceneError(f"{where} {name!r}: no such file in {src.path.parent}{hint}")
            if target not in seen:
                seen.add(target)
                deps.append(target)
                if kind in ("include", "use"):
                    todo.append(target)
    return deps


def scad_variables(scad_file: Path) -> dict[str, str]:
    """The variables `-D` can override: name -> source text of its default value, for every
    assignment at the top level of the model and of the files it `include`s (in file order, the
    last assignment winning, as in OpenSCAD).

    Module and function parameters, call arguments and assignments inside modules, functions
    and blocks are not variables of the model: `-D` leaves them unchanged.
    """
    return dict(_top_level_assignments(Path(scad_file).resolve(), set()))


def _top_level_assignments(path: Path, seen: set[Path]) -> list[tuple[str, str]]:
    seen.add(path)
    code = ScadSource.read(path).code
    out: list[tuple[str, str]] = []
    depth, i, n, statement_start = 0, 0, len(code), True
    while i < n:
        c = code[i]
        if c.isspace():
            i += 1
            continue
        if statement_start and depth == 0:
            inc = _INCLUDE.match(code, i)
            if inc:
                # An include pastes the file's text here; a file the dependency scan will
                # refuse (outside the folder, missing) is left to it, with its better message.
                target = (path.parent / inc.group(2)).resolve()
                if (
                    inc.group(1) == "include"
                    and target.is_relative_to(path.parent)
                    and target.is_file()
                    and target not in seen
                ):
                    out += _top_level_assignments(target, seen)
                i = inc.end()
                continue
            assign = _ASSIGNMENT.match(code, i)
            if assign:
                end = _statement_end(code, assign.end())
                out.append((assign.group(1), code[assign.end() : end].strip()))
                i = end + 1
                continue
        statement_start = False
        if c == '"':
            i = _string_end(code, i)
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth = max(depth - 1, 0)
            statement_start = depth == 0 and c == "}"  # a module body or a block at the top
        elif c == ";" and depth == 0:
            statement_start = True
        i += 1
    return out


_INCLUDE = re.compile(r"(include|use)\s*<([^>]*)>")
_ASSIGNMENT = re.compile(r"([A-Za-z_$][\w$]*)\s*=(?!=)")


def _string_end(code: str, start: int) -> int:
    """Index of the closing quote of the string literal opening at start."""
    j = start + 1
    while j < len(code) and code[j] != '"':
        j += 2 if code[j] == "\\" else 1
    return j


def _statement_end(code: str, start: int) -> int:
    """Index of the `;` ending the statement that continues at start (len(code) if none)."""
    depth, i = 0, start
    while i < len(code):
        c = code[i]
        if c == '"':
            i = _string_end(code, i)
        elif c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == ";" and depth <= 0:
            return i
        i += 1
    return len(code)


_NUMBER = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def scad_value_kind(expr: str) -> str | None:
    """"number", "string" or "bool" for a default value whose type can be read off its text
    (a literal, or arithmetic on number literals); None for any other expression."""
    expr = expr.strip()
    if expr in ("true", "false"):
        return "bool"
    if _STRING.fullmatch(expr):
        return "string"
    bare = _NUMBER.sub("0", expr)
    if "0" in bare and re.fullmatch(r"[0\s+\-*/%()]+", bare):
        return "number"
    return None


def _kind_of(value: ScadValue) -> str:
    if isinstance(value, bool):
        return "bool"
    return "string" if isinstance(value, str) else "number"


_KIND_NAMES = {"number": "a number", "string": "a string", "bool": "a boolean (true or false)"}


def param_problem(name: str, value: ScadValue, variables: Mapping[str, str], model: str) -> str:
    """Why `-D name=value` would not do what a user means on a model with these variables
    (scad_variables), or "" if it would: no such top-level variable, or a value of another type
    than the default's (OpenSCAD would take "wide" for a width without a word)."""
    if name not in variables:
        return (
            f"{name!r} is not a variable of the model; its variables: "
            f"{', '.join(sorted(variables)) or '(none)'} (the top-level assignments of {model}; "
            f"module and function parameters cannot be set)"
        )
    default = variables[name]
    kind = scad_value_kind(default)
    if kind is not None and kind != _kind_of(value):
        return (
            f"{name!r} defaults to {default} in {model}, so it takes {_KIND_NAMES[kind]}; "
            f"got {value!r}, {_KIND_NAMES[_kind_of(value)]}"
        )
    return ""


def timeout_problem(timeout: object) -> str:
    """Why timeout is not a usable render time limit [s], or "" if it is."""
    if (
        isinstance(timeout, bool)
        or not isinstance(timeout, int | float)
        or not 0 < timeout <= MAX_TIMEOUT
    ):
        return (
            f"expected a number of seconds above 0 and at most {MAX_TIMEOUT:.0f} (24 h), "
            f"got {timeout!r}"
        )
    return ""


# -- running OpenSCAD --------------------------------------------------------------------------


def _scad_literal(value: ScadValue) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(value)  # a double-quoted string OpenSCAD accepts


# Inside a fresh user + mount namespace: show the model's folder at /mnt/model and the output
# folder at /mnt/out, hide the folders where people keep files, then become OpenSCAD (exec, so
# the time limit's kill reaches it).
_SANDBOX_SCRIPT = """
set -e
mount --bind "$1" "$2/model"
mount --rbind "$2" /mnt
for d in {hidden}; do [ -d "$d" ] && mount -t tmpfs -o size=16m none "$d" || true; done
cd /mnt/model
shift 2
exec "$@"
""".format(hidden=" ".join(_HIDDEN_DIRS))


@functools.cache
def _sandbox_available() -> bool:
    """True if unprivileged user + mount namespaces work here (`unshare -r -m`)."""
    if shutil.which("unshare") is None:
        return False
    try:
        probe = subprocess.run(
            ["unshare", "-r", "-m", "sh", "-c", "mount -t tmpfs none /mnt"],
            capture_output=True, timeout=10, check=False,
        )  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


def confined(argv: list[str], model_dir: Path, work_dir: Path) -> list[str]:
    """argv wrapped to run with model_dir as its working directory (seen as /mnt/model) and
    work_dir as /mnt (write results to /mnt/out), and the home, work and temporary folders
    hidden — when user namespaces are available; otherwise argv unchanged, run in model_dir."""
    if not _sandbox_available():
        return argv
    (work_dir / "model").mkdir(exist_ok=True)
    return ["unshare", "-r", "-m", "sh", "-c", _SANDBOX_SCRIPT, "sh", str(model_dir),
            str(work_dir), *argv]  # fmt: skip


def _run(cmd: list[str], *, cwd: Path, timeout: float) -> subprocess.CompletedProcess:
    """Run cmd in its own process group; kill the whole group past the time limit."""
    proc = subprocess.Popen(
        cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def render_scad(
    scad_file: Path,
    params: Mapping[str, ScadValue] | None = None,
    *,
    timeout: float = DEFAULT_TIMEOUT,
) -> Path:
    """Render scad_file with `-D name=value` overrides to an STL and return its cached path.

    The cache key covers the model text, the files it reads, the overrides and the OpenSCAD
    version, so a changed parameter or height map renders again and an unchanged model never
    does. A render past `timeout` seconds is killed. OpenSCAD's own error text is passed
    through when the model is wrong.
    """
    scad_file = Path(scad_file).resolve()
    if not scad_file.is_file():
        raise SceneError(f"{scad_file}: no such OpenSCAD file")
    problem = timeout_problem(timeout)
    if problem:
        raise SceneError(f"{scad_file}: render time limit: {problem}")
    params = dict(params or {})
    known = scad_variables(scad_file)
    for name, value in params.items():
        problem = param_problem(name, value, known, scad_file.name)
        if problem:
            raise SceneError(f"{scad_file}: parameter {problem}")
    deps = scad_dependencies(scad_file)
    root = scad_file.parent
    defines = [f"{k}={_scad_literal(v)}" for k, v in sorted(params.items())]
    digest = hashlib.sha256()
    for f in (scad_file, *deps):
        digest.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    digest.update(json.dumps([defines, openscad_version()]).encode())
    out = cache_dir() / f"{scad_file.stem}-{digest.hexdigest()[:32]}.stl"
    if out.is_file():
        return out
    out.parent.mkdir(parents=True, exist_ok=True)
    # Render into a fresh folder beside the cache and rename: a killed render leaves no
    # half-written mesh behind under the final name.
    work = Path(tempfile.mkdtemp(dir=out.parent, prefix=".render-"))
    try:
        (work / "out").mkdir()
        target = "/mnt/out/mesh.stl" if _sandbox_available() else str(work / "out" / "mesh.stl")
        openscad = [openscad_binary(), "--export-format", "binstl", "-o", target]
        openscad += [a for d in defines for a in ("-D", d)]
        cmd = confined([*openscad, scad_file.name], root, work)
        try:
            proc = _run(cmd, cwd=root, timeout=timeout)
        except subprocess.TimeoutExpired:
            raise SceneError(
                f"{scad_file}: OpenSCAD did not finish within its time limit of {timeout:g} s "
                f"and was stopped; a slow model may take more: give this terrain object "
                f"`timeout: SECONDS` (or --scad-timeout SECONDS), at most {MAX_TIMEOUT:.0f}"
            ) from None
        mesh = work / "out" / "mesh.stl"
        if proc.returncode != 0 or not mesh.is_file() or mesh.stat().st_size == 0:
            lines = proc.stderr.splitlines()
            detail = "\n".join(line for line in lines if "ERROR" in line or "WARNING" in line)
            if "Current top level object is empty" in proc.stderr:
                detail = (detail + "\nthe model produces no geometry").strip()
            raise SceneError(f"{scad_file}: OpenSCAD failed:\n{detail or proc.stderr.strip()}")
        mesh.replace(out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out
