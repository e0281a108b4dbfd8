"""Render OpenSCAD models: confined, time-limited, cached; by the real `openscad` binary or by
openscad-evaluator on Manifold (BACKENDS: by default `auto`, the evaluator where it renders the
model as the binary does, else the binary; render_scad_result says which, and why).

A model may only read files in its own folder. Before OpenSCAD runs, the model and everything it
includes are scanned: `include <f>`, `use <f>` and every file-reading call (`import`, `surface`,
`file = ...` arguments) must name a literal relative path that stays inside the folder, so a
refusal names the file, the line and the offending path. OpenSCAD then runs in a jail of the
operating system (scenes/_jail.py: user, mount and network namespaces) that holds only the
model's folder (read-only), OpenSCAD's own program, libraries and fonts, and the one folder it
writes its mesh to; so a path the scan could not see (an escape that OpenSCAD decodes, a link)
leads nowhere. Each render also runs under limits of memory, processor time and output size.
Where the system cannot make the jail, rendering is refused unless $ROACHPLAN_UNSAFE_SCAD=1.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from roachplan.perception import short_repr

from . import _jail
from ._errors import SceneError
from ._manifold_main import FACTS_SUFFIX

RENDER_PROGRESS: ContextVar[Callable[[str, float, float], None] | None] = ContextVar(
    "RENDER_PROGRESS", default=None
)
"""Who hears of a render while it runs: called about twice a second with (the model's file
name, seconds elapsed, the time limit [s]) and once more when it ends. The command line sets it
for its progress bars; a render deep inside build_world needs no argument passed down for it."""

ScadValue = float | int | bool | str

DEFAULT_TIMEOUT = 600.0
"""Wall-time limit of one OpenSCAD render [s] unless a scene sets its own: ordinary public
models (text(), includes, a few hundred CSG operations) take 2-4 minutes in OpenSCAD 2021.01's
CGAL, so a minute stopped most of them."""
Backend = Literal["auto", "cgal", "manifold"]
BACKENDS: tuple[Backend, ...] = ("auto", "cgal", "manifold")
"""Who renders a model: "cgal", the real `openscad` binary (Debian's 2021.01, CGAL: the
reference); "manifold", the Python evaluator `openscad-evaluator` on the Manifold library
(scenes/_manifold_main.py), 3-11x faster on CSG-heavy and text() models
(benchmarks/bench_openscad.py) and refused on the constructs where its mesh differs
(MANIFOLD_DIFFERS); "auto" (the default), manifold unless the model uses one of those, or the
evaluator refuses it, fails on it or leaves solids touching face to face apart: then the
binary (render_scad_result says which, and why)."""
DEFAULT_BACKEND: Backend = "auto"
MANIFOLD_DIFFERS = {
    "surface": "its base is at z = 0, not 1 below the lowest height as in OpenSCAD",
}
"""Constructs whose mesh under backend manifold differs from the reference binary's, measured
by benchmarks/bench_openscad.py (construct -> how): a model calling one renders with the
binary under auto, and is refused under manifold."""
MANIFOLD_CHECKED = {
    "polyhedron": "a polyhedron that is open, or wound both ways, is no solid there, while "
    "the binary may still export it as it is",
}
"""Constructs that differ only sometimes: allowed, but a model calling one must come out
closed and outward (a polyhedron wound either way throughout agrees: _manifold_main.py turns
one wound the other way outward). Found by the scan, not evaluated: a model whose polyhedra
are all solid but that also makes open geometry (touching solids) fails the check too, and
renders with the binary (auto) or is refused (manifold)."""
TEXT_DEVIATION = 1.5e-3
"""How far a text() glyph drawn by backend manifold may sit from the binary's, per unit of
the size given to text() [model units per model unit]. Measured: benchmarks/bench_openscad.py
--text (2 strings of 15 and 54 glyphs, sizes 1 to 100, every halign and valign, DejaVu Sans -
fontconfig's answer to OpenSCAD's Liberation Sans here - and stand-ins for DejaVu Sans Mono
Bold, Futura Bold and Liberation Serif): at most 1.01e-3 x size (0.10 at size 100), not growing
with the string's length; a public tile's labels (size 3, spacing 1.1, a bold stand-in),
1.1e-3 x size; the limit leaves a third more. What is left is FreeType's hinting in the
binary, which the evaluator does not reproduce; before _manifold_main.py's text patch (the
evaluator's own Liberation Sans, HarfBuzz's positions unscaled) 14 glyphs at size 10 sat up to
2.5 apart, more the longer the string."""
MAX_TIMEOUT = 24 * 3600.0
"""Largest render time limit accepted [s]; past it the OS timer overflows, and no render that
long is meant."""

# Built-in modules and functions that read a file named by their first positional argument
# (OpenSCAD 2021.01, including the deprecated import_* modules). Any call's `file = ...`
# argument is checked too (dxf_dim, dxf_cross, linear_extrude(file=...), ...).
_FILE_CALLS = ("import", "surface", "import_stl", "import_off", "import_dxf")
UNSAFE_ENV = "ROACHPLAN_UNSAFE_SCAD"
"""Set to 1 to render without the jail where the system cannot make one (the model can then
read every file the user can)."""
MEMORY_ENV = "ROACHPLAN_SCAD_MEMORY"
"""Memory limit of one render, e.g. 16G or 512M (default: default_memory_limit())."""


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
_ESCAPE = re.compile(r"\\(x[0-7][0-9a-fA-F]|u[0-9a-fA-F]{4}|U[0-9a-fA-F]{6}|.)", re.S)


def _unescape(body: str) -> str:
    """A string literal's text as OpenSCAD 2021.01 decodes it: \\n \\t \\r, \\x00-\\x7F
    (\\x00 is a space), \\uXXXX and \\UXXXXXX; any other backslash is dropped. So
    "\\x2fetc" is the absolute path /etc, whatever file name it spells undecoded."""

    def one(m: re.Match) -> str:
        e = m.group(1)
        if len(e) > 1:  # a numbered character
            code = int(e[1:], 16)
            if code == 0:
                return " "
            return chr(code) if code <= 0x10FFFF and not 0xD800 <= code <= 0xDFFF else "\ufffd"
        return {"n": "\n", "t": "\t", "r": "\r"}.get(e, e)

    return _ESCAPE.sub(one, body)


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
                name = _unescape(lit.group(1))  # the path OpenSCAD will open
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


_TOKEN = re.compile(
    r'\s*(?:(?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<string>"(?:[^"\\]|\\.)*")'
    r"|(?P<name>[A-Za-z_$][\w$]*)|(?P<op>&&|\|\||==|!=|<=|>=|[-+*/%^()<>!?:,\[\]]))"
)
# OpenSCAD 2021.01's built-in functions that return a number whatever their arguments.
_NUMBER_FUNCTIONS = frozenset(
    "abs sign sin cos tan acos asin atan atan2 floor round ceil ln log pow sqrt exp min max norm "
    "len".split()
)
_COMPARISONS = frozenset(("&&", "||", "==", "!=", "<=", ">=", "<", ">", "!"))


def scad_value_kind(expr: str, variables: Mapping[str, str] | None = None) -> str | None:
    """ "number", "string", "bool" or "vector" for a default value whose type can be read off
    its text: a literal, a list `[...]`, a comparison, or arithmetic on numbers, built-in
    numeric functions and the model's variables (scad_variables) that are numbers themselves
    (`size = 2 * unit;`); None for any other expression (a condition `c ? a : b`, a call of a
    function of the model's)."""
    return _value_kind(expr, variables or {}, frozenset())


def _value_kind(expr: str, variables: Mapping[str, str], seen: frozenset[str]) -> str | None:
    expr = expr.strip()
    if expr in ("true", "false"):
        return "bool"
    if _STRING.fullmatch(expr):
        return "string"
    if expr in variables and expr not in seen:  # `b = a;`: a's kind
        return _value_kind(variables[expr], variables, seen | {expr})
    tokens, i = [], 0
    while i < len(expr):
        m = _TOKEN.match(expr, i)
        if m is None:
            return None  # a character that is no part of these expressions
        tokens.append((m.lastgroup, m.group(m.lastgroup)))
        i = m.end()
    if tokens and tokens[0] == ("op", "[") and tokens[-1] == ("op", "]"):
        return "vector"
    return _tokens_kind(tokens, variables, seen)


def _tokens_kind(tokens: list, variables: Mapping[str, str], seen: frozenset[str]) -> str | None:
    ops = {text for kind, text in tokens if kind == "op"}
    if ops & {"?", ":", "[", "]"} or any(kind == "string" for kind, _ in tokens):
        return None  # a condition, a vector or range inside, text: not read here
    if ops & _COMPARISONS:
        return "bool"
    operands = 0
    for k, (kind, text) in enumerate(tokens):
        if kind != "name":
            operands += kind == "number"
            continue
        calls = k + 1 < len(tokens) and tokens[k + 1] == ("op", "(")
        if calls and text in _NUMBER_FUNCTIONS or not calls and text == "PI":
            operands += 1
        elif not calls and text in variables and text not in seen:
            if _value_kind(variables[text], variables, seen | {text}) != "number":
                return None
            operands += 1
        else:
            return None  # a function of the model's, undef, a special $variable
    return "number" if operands else None


def _kind_of(value: ScadValue) -> str:
    if isinstance(value, bool):
        return "bool"
    return "string" if isinstance(value, str) else "number"


_KIND_NAMES = {
    "number": "a number",
    "string": "a string",
    "bool": "a boolean (true or false)",
    "vector": "a vector (here: a number, as OpenSCAD's cube() and scale() take)",
}


def param_problem(name: str, value: ScadValue, variables: Mapping[str, str], model: str) -> str:
    """Why `-D name=value` would not do what a user means on a model with these variables
    (scad_variables), or "" if it would: no such top-level variable, or a value of another type
    than the default's (OpenSCAD would take "wide" for a width without a word)."""
    if name not in variables:
        if not variables:
            return (
                f"{short_repr(name)} is not a variable of the model: {model} has no top-level "
                f"variables, so it takes no params (module and function parameters cannot be "
                f"set); remove `params`, or give the model a top-level `{_shown_name(name)} = ...;`"
            )
        names = sorted(variables)
        listed = ", ".join(names[:40]) + (f" and {len(names) - 40} more" if len(names) > 40 else "")
        return (
            f"{short_repr(name)} is not a variable of the model; its variables: {listed} (the "
            f"top-level assignments of {model}; module and function parameters cannot be set)"
        )
    default = variables[name]
    kind = scad_value_kind(default, variables)
    given = _kind_of(value)
    if kind is not None and kind != given and not (kind == "vector" and given == "number"):
        shown = default if len(default) <= 80 else default[:77] + "..."
        return (
            f"{short_repr(name)} defaults to {shown} in {model}, so it takes "
            f"{_KIND_NAMES[kind]}; got {short_repr(value)}, {_KIND_NAMES[given]}"
        )
    return ""


def _shown_name(name: object) -> str:
    return name if isinstance(name, str) and len(name) <= 40 else "name"


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


# -- running OpenSCAD --------------------------------------------------------------------------


def _scad_literal(value: ScadValue) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(value)  # a double-quoted string OpenSCAD accepts


# -- the jail and the limits ---------------------------------------------------------------------

JAIL_MODEL, JAIL_OUT = "/model", "/out"
"""Where the model's folder (read-only) and the output folder (writable) appear in the jail."""

# What OpenSCAD 2021.01 reads at run time besides its libraries (found with strace on a text()
# model): the loader's cache, fontconfig's setup, the fonts and their cache, the C library's
# locales and character sets, and its own resource folder (beside its program: ../share/openscad,
# with its fonts/ and libraries/ where installed). The user's own fonts (~/.fonts) stay outside.
_RUNTIME_DATA = (
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


def default_memory_limit() -> int:
    """Memory limit of one render unless $ROACHPLAN_SCAD_MEMORY sets one [bytes]: 8 GiB, or
    three quarters of the machine's memory if that is less. Large CGAL renders need a few GiB."""
    try:
        ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError):
        ram = 0
    return min(8 << 30, ram * 3 // 4) if ram > 0 else 8 << 30


_SIZE = re.compile(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([kmgt]?)(?:i?b)?\s*", re.I)


def memory_limit() -> int:
    """The memory limit of a render [bytes]: $ROACHPLAN_SCAD_MEMORY (16G, 512M, 1.5G, or
    bytes) or default_memory_limit()."""
    text = os.environ.get(MEMORY_ENV, "").strip()
    if not text:
        return default_memory_limit()
    m = _SIZE.fullmatch(text)
    size = float(m.group(1)) * 1024 ** " kmgt".index(m.group(2).lower() or " ") if m else 0.0
    if not 64 << 20 <= size <= 1 << 50:
        raise SceneError(
            f"{MEMORY_ENV}={text!r}: expected a memory size from 64M up, such as 16G or 512M"
        )
    return int(size)


def _size_text(size: int) -> str:
    return f"{size / (1 << 30):.3g} GiB" if size >= 1 << 30 else f"{size / (1 << 20):.3g} MiB"


def _program_libraries(program: str) -> list[str]:
    """The shared libraries `program` loads (its loader first), as `ldd` lists them; [] when
    ldd cannot tell (not installed, not a dynamic program)."""
    try:
        out = subprocess.run(
            ["ldd", program], capture_output=True, text=True, timeout=30, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return []
    if out.returncode != 0:
        return []
    # "\tlibz.so.1 => /lib/x86_64-linux-gnu/libz.so.1 (0x...)" or "\t/lib64/ld-linux... (0x...)"
    return re.findall(r"(?:=>\s*|^\s*)(/\S+)\s+\(0x", out.stdout, re.M)


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
    libraries = _program_libraries(program)
    wanted = [program, *(libraries or _LIBRARY_DIRS), *_RUNTIME_DATA, os.path.normpath(resources)]
    # Character-set modules of the C library, beside it (gconv/).
    wanted += [os.path.join(os.path.dirname(lib), "gconv") for lib in libraries if "/libc." in lib]
    ro: dict[str, str] = {}
    links: dict[str, str] = {}
    for path in wanted:
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
    evaluator of backend manifold: _manifold_layout)."""
    program = shutil.which(argv[0]) or argv[0]
    spec: dict = {
        "argv": [program, *argv[1:]],
        "memory": memory_limit() if memory is None else int(memory),
        "cpu": math.ceil(cpu) + 1,
        "env": None,  # this process's; never on the command line, where anyone can read it
        "jail": None,
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


def _jail_wanted() -> bool:
    return os.environ.get(UNSAFE_ENV, "").strip() not in ("1", "yes", "true")


@functools.cache
def _sandbox_available() -> bool:
    """True if this system can make the jail (unprivileged user, mount and network namespaces)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = confined(["true"], Path(tmp), Path(tmp), memory=1 << 30, cpu=10)
        try:
            probe = subprocess.run(cmd, capture_output=True, timeout=30, check=False)
        except (OSError, subprocess.TimeoutExpired):
            return False
    return probe.returncode == 0


def _run(
    cmd: list[str], *, cwd: Path, timeout: float, name: str = ""
) -> subprocess.CompletedProcess:
    """Run cmd in its own process group; kill the whole group past the time limit. Only the
    two ends of its error output are kept (OpenSCAD writes everything there): a model's echo()
    in a loop prints gigabytes, which must not fill this process's memory. RENDER_PROGRESS,
    when set, hears of it (as `name`) while it runs."""
    proc = subprocess.Popen(
        cmd,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    kept: list[str] = []
    reader = threading.Thread(target=_read_ends, args=(proc.stderr, kept), daemon=True)
    reader.start()
    hear = RENDER_PROGRESS.get()
    t0 = time.monotonic()
    try:
        if hear is None:
            proc.wait(timeout=timeout)
        else:
            while proc.poll() is None:
                elapsed = time.monotonic() - t0
                if elapsed >= timeout:
                    raise subprocess.TimeoutExpired(cmd, timeout)
                hear(name, elapsed, timeout)
                try:
                    proc.wait(timeout=min(0.5, timeout - elapsed))
                except subprocess.TimeoutExpired:
                    pass
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
    finally:
        if hear is not None:
            hear(name, time.monotonic() - t0, timeout)
        reader.join()
        proc.stderr.close()
    return subprocess.CompletedProcess(cmd, proc.returncode, "", kept[0] if kept else "")


def _read_ends(stream, kept: list[str], keep: int = 1 << 16) -> None:
    """Read stream to its end; append its first and last `keep` bytes as text to kept."""
    head, tail, left_out = bytearray(), bytearray(), 0
    for chunk in iter(lambda: stream.read1(1 << 16), b""):
        room = max(keep - len(head), 0)
        head += chunk[:room]
        tail += chunk[room:]
        if len(tail) > keep:
            left_out += len(tail) - keep
            del tail[: len(tail) - keep]
    gap = f"\n... ({left_out} bytes left out) ...\n" if left_out else ""
    kept.append(head.decode(errors="replace") + gap + tail.decode(errors="replace"))


def _limit_hit(returncode: int, err: str, *, memory: int, timeout: float) -> str:
    """Which limit stopped OpenSCAD, with how to raise it; "" if none did."""
    sig = -returncode if returncode < 0 else 0
    raise_memory = f"set {MEMORY_ENV}=SIZE (now {_size_text(memory)}; e.g. {MEMORY_ENV}=16G)"
    if sig == signal.SIGXCPU:  # the wall-clock limit comes first unless this process stalled
        return (
            f"OpenSCAD used up its processor-time limit of {timeout:g} s and was stopped; a "
            f"slow model may take more: give this terrain object `timeout: SECONDS` (or "
            f"--scad-timeout SECONDS), at most {MAX_TIMEOUT:.0f}"
        )
    if sig == signal.SIGXFSZ:
        return (
            f"OpenSCAD's mesh grew past the output size limit of {_size_text(memory)} (the "
            f"memory limit) and was stopped; to allow more, {raise_memory}"
        )
    if "bad_alloc" in err or "out of memory" in err.lower():
        return (
            f"OpenSCAD ran out of memory at its limit of {_size_text(memory)} and was "
            f"stopped; a large model may need more: {raise_memory}"
        )
    if sig:
        name = signal.Signals(sig).name if sig in signal.valid_signals() else f"signal {sig}"
        return (
            f"OpenSCAD was stopped ({name}); a model that needs more than its memory limit "
            f"of {_size_text(memory)}, or than the machine has, may end this way: {raise_memory}"
        )
    return ""


def _failure(
    scad_file: Path,
    proc: subprocess.CompletedProcess,
    *,
    memory: int,
    timeout: float,
    jail: bool,
) -> str:
    """Why a render that left no mesh failed, for a SceneError: the jail could not be made, a
    limit was hit, or OpenSCAD's own errors (its jail paths turned back into real ones)."""
    err = proc.stderr.replace(f"{JAIL_MODEL}/", f"{scad_file.parent}/") if jail else proc.stderr
    if proc.returncode == _jail.SETUP_FAILED and _jail.SETUP_TAG in err:
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
    limit = _limit_hit(proc.returncode, err, memory=memory, timeout=timeout)
    if limit:
        return limit
    lines = [line for line in err.splitlines() if "ERROR" in line or "WARNING" in line]
    detail = _bounded(lines)
    if jail and ("couldn't be opened" in err or "Can't open" in err):
        detail += f"\n(a model sees only the files in its own folder, {scad_file.parent})"
    if "Current top level object is empty" in err:
        detail = (detail + "\nthe model produces no geometry").strip()
    return f"OpenSCAD failed:\n{detail.strip() or _bounded(err.strip().splitlines()[-20:])}"


def _bounded(lines: list[str], count: int = 20, width: int = 300) -> str:
    """At most `count` lines of at most `width` characters: a model's echo() or a flood of
    warnings must not become megabytes of error text."""
    shown = [line if len(line) <= width else line[: width - 3] + "..." for line in lines[:count]]
    if len(lines) > count:
        shown.append(f"... and {len(lines) - count} more lines")
    return "\n".join(shown)


# -- backend manifold: openscad-evaluator on Manifold, in the same jail ----------------------------

MANIFOLD_PACKAGES = ("openscad-evaluator", "manifold3d")
"""The distributions backend manifold runs (with what they require)."""
_MANIFOLD_MAIN = Path(__file__).with_name("_manifold_main.py")
"""The evaluator's entry point in the jail (standard library only until it imports it)."""


def backend_problem(backend: object) -> str:
    """Why backend is not a render backend, or "" if it is."""
    if backend not in BACKENDS:
        return (
            f"expected one of {', '.join(BACKENDS)} (auto: manifold where it renders the model "
            f"as the binary does, else the binary; cgal: the openscad binary, the reference; "
            f"manifold: openscad-evaluator, faster on CSG-heavy models), got {short_repr(backend)}"
        )
    return ""


def _first_call(scad_file: Path, names) -> tuple[Path, int, str] | None:
    """(file, line, name) of the first call of one of names in the model or a file it includes
    or uses (the dependency scan's files; strings blanked, so echo("text(") is no call)."""
    scad_file = Path(scad_file).resolve()
    sources = [scad_file, *(d for d in scad_dependencies(scad_file) if d.suffix == ".scad")]
    pattern = re.compile(r"\b(" + "|".join(names) + r")\s*\(")
    for path in sources:
        src = ScadSource.read(path)
        m = pattern.search(_STRING.sub(lambda s: " " * len(s.group(0)), src.code))
        if m:
            return path, src.line_of(m.start()), m.group(1)
    return None


def _manifold_differs(scad_file: Path) -> str:
    """What in the model (or a file it includes or uses) backend manifold renders differently
    from the binary (MANIFOLD_DIFFERS), where and how; "" if nothing."""
    found = _first_call(scad_file, MANIFOLD_DIFFERS)
    if found is None:
        return ""
    path, line, name = found
    return (
        f"{name}() ({path.name}, line {line}) is rendered differently by manifold "
        f"({MANIFOLD_DIFFERS[name]})"
    )


def manifold_problem(scad_file: Path) -> str:
    """Why backend manifold must not render this model, or "" if it may: the model, or a file
    it includes or uses, calls a construct of MANIFOLD_DIFFERS."""
    found = _first_call(scad_file, MANIFOLD_DIFFERS)
    if found is None:
        return ""
    path, line, name = found
    return (
        f"{path}, line {line}: {name}() is not rendered alike by backend manifold "
        f"({MANIFOLD_DIFFERS[name]}); render this model with `backend: cgal` "
        f"(--scad-backend cgal), the openscad binary, or `backend: auto`, which picks it"
    )


def _manifold_mesh_problem(scad_file: Path, mesh: Path) -> str:
    """Why the evaluator's mesh of the model cannot stand for the binary's, or "" if it can:
    solids that touch face to face kept apart (Manifold treats touching as not overlapping,
    so two walls stay back to back inside the solid; the binary's CGAL merges them: on
    plywood_bridge, whose blocks, plank and ramps touch, 151 of 20,000 surface samples lay on
    such walls, up to 6.7 cm from the binary's surface); and, for a model calling a
    MANIFOLD_CHECKED construct, a mesh that is not closed and outward. Openness alone is not
    checked elsewhere: the binary's own mesh of solids touching along an edge is open too
    (voxel_wall)."""
    import trimesh

    m = trimesh.load(mesh, force="mesh")
    where = _touching_walls(m)
    if where is not None:
        x, y, z = (f"{c:.4g}" for c in where)
        return (
            f"{scad_file}: solids that touch face to face (near [{x}, {y}, {z}]) stay apart "
            f"in backend manifold, walls inside the solid, where the binary merges them; "
            f"render this model with `backend: cgal` (--scad-backend cgal), the openscad "
            f"binary, or `backend: auto`, which picks it"
        )
    found = _first_call(scad_file, MANIFOLD_CHECKED)
    if found is None or (m.is_watertight and m.is_winding_consistent and m.volume > 0):
        return ""
    path, line, name = found
    return (
        f"{path}, line {line}: {name}(): backend manifold made an open or inside-out mesh "
        f"({MANIFOLD_CHECKED[name]}); render this model with `backend: cgal` "
        f"(--scad-backend cgal), the openscad binary, or `backend: auto`, which picks it"
    )


def _touching_walls(mesh) -> tuple[float, float, float] | None:
    """A point [model units] where faces of mesh lie on one another back to back over some
    area (solids touching face to face, kept apart), or None if none do.
    Faces are grouped by their plane (normal and offset, rounded); a plane met from both
    sides is checked for overlap in 2D. Faces merely meeting at an edge do not count."""
    import numpy as np

    if len(mesh.faces) == 0:
        return None
    size = float(max(mesh.extents)) or 1.0
    n, c = mesh.face_normals, mesh.triangles_center
    d = np.einsum("ij,ij->i", n, c)
    keys = np.column_stack([np.round(n * 1e4), np.round(d / (1e-6 * size))]).astype(np.int64)
    groups: dict[tuple, list[int]] = {}
    for k, key in enumerate(map(tuple, keys)):
        groups.setdefault(key, []).append(k)
    for key, faces in groups.items():
        other = groups.get(tuple(-v for v in key))
        if other is None or key < tuple(-v for v in key):
            continue
        where = _overlap(mesh, n[faces[0]], faces, other, min_area=1e-8 * size * size)
        if where is not None:
            return where
    return None


def _overlap(mesh, normal, faces: list[int], other: list[int], min_area: float):
    """Where two sets of coplanar faces overlap by more than min_area [model units^2], in 3D,
    or None."""
    import numpy as np
    from shapely import Polygon, unary_union

    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)

    def region(ids):
        tris = mesh.triangles[ids]
        return unary_union([Polygon(np.column_stack([t @ u, t @ w])).buffer(0) for t in tris])

    common = region(faces).intersection(region(other))
    if common.area <= min_area:
        return None
    p = common.representative_point()
    offset = float(mesh.triangles[faces[0]][0] @ normal)
    return tuple(float(v) for v in p.x * u + p.y * w + offset * np.asarray(normal))


def _manifold_distributions() -> list:
    """The installed distributions of MANIFOLD_PACKAGES and everything they require."""
    from importlib import metadata

    found, todo, seen = [], list(MANIFOLD_PACKAGES), set()
    while todo:
        name = todo.pop()
        key = re.sub(r"[-_.]+", "-", name).lower()
        if key in seen:
            continue
        seen.add(key)
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            raise SceneError(
                f"backend manifold needs the Python package {name!r}, which is not installed "
                f"(pip install openscad-evaluator manifold3d, or reinstall roachplan); or use "
                f"`backend: cgal`, the openscad binary"
            ) from None
        found.append(dist)
        for req in dist.requires or []:
            if "extra ==" not in req:
                todo.append(re.match(r"[A-Za-z0-9._-]+", req).group())
    return found


@functools.cache
def manifold_version() -> str:
    """The versions of the evaluator and of Manifold, for the cache key and messages."""
    dists = {
        re.sub(r"[-_.]+", "-", d.metadata["Name"]).lower(): d.version
        for d in _manifold_distributions()
    }
    return f"openscad-evaluator {dists['openscad-evaluator']}, manifold3d {dists['manifold3d']}"


@functools.cache
def _manifold_layout() -> tuple[str, list[str], dict[str, str], dict[str, str]]:
    """(interpreter, its sys.path in the jail, read-only binds, symlinks) that run the
    evaluator in the jail: the base Python program (not the venv's link to it) with its
    libraries and standard library, and, of site-packages, only the files of the evaluator's
    distributions (each package folder or module, read-only) and the system libraries their
    compiled modules load; and, for text(), fontconfig's `fc-match` with its libraries and
    the fonts and font settings the binary's jail shows (_RUNTIME_DATA), so that the evaluator
    asks for a font where the binary does and gets the same one (_manifold_main.py)."""
    python = os.path.realpath(getattr(sys, "_base_executable", sys.executable))
    # The base interpreter's standard library (its lib-dynload inside), not a venv's folders.
    stdlib = os.path.realpath(os.path.dirname(os.__file__))
    shown: set[str] = set()
    for dist in _manifold_distributions():
        for f in dist.files or []:
            # Top-level entries of site-packages; `..` leads to scripts in bin/, not needed.
            if f.parts[0] not in ("..", "__pycache__"):
                shown.add(os.path.normpath(str(dist.locate_file(f.parts[0]))))
    paths = sorted({os.path.dirname(p) for p in shown})
    compiled = [
        os.path.join(root, f)
        for top in shown
        if os.path.isdir(top)
        for root, _, files in os.walk(top)
        for f in files
        if ".so" in f
    ] + [p for p in shown if p.endswith(".so")]
    libraries = set(_program_libraries(python))
    for start in range(0, len(compiled), 64):  # one ldd for many files
        try:
            out = subprocess.run(
                ["ldd", *compiled[start : start + 64]],
                capture_output=True,
                text=True,
                timeout=60,
                check=False,
            ).stdout
        except (OSError, subprocess.TimeoutExpired):
            out = ""
        # A module that ldd cannot read (not dynamic) only makes it exit 1; the rest is listed.
        libraries |= set(re.findall(r"(?:=>\s*|^\s*)(/\S+)\s+\(0x", out, re.M))
    fc_match = shutil.which("fc-match")
    fonts = [fc_match, *_program_libraries(fc_match), *_RUNTIME_DATA] if fc_match else []
    ro: dict[str, str] = {}
    links: dict[str, str] = {}
    for path in [
        python,
        *sorted(libraries),
        stdlib,
        *sorted(shown),
        str(_MANIFOLD_MAIN),
        "/dev/null",
        "/etc/ld.so.cache",
        *fonts,
    ]:
        _show(path, ro, links)
    folders = [p for p in ro if os.path.isdir(p)]

    def covered(path: str) -> bool:
        return any(path != f and path.startswith(f.rstrip("/") + "/") for f in folders)

    return (
        python,
        paths,
        {p: src for p, src in ro.items() if not covered(p)},
        {p: t for p, t in links.items() if not covered(p)},
    )


def _manifold_argv(model: str, target: str) -> tuple[list[str], tuple[dict, dict]]:
    """The evaluator's command line rendering model (a path as the jail shows it) to the binary
    STL target, and the jail layout it needs."""
    python, paths, ro, links = _manifold_layout()
    # -I -S: no site, no .pth files, no user packages; only `paths` come on sys.path, and the
    # jail shows only the evaluator's own packages there.
    return [
        python,
        "-I",
        "-S",
        "-B",
        str(_MANIFOLD_MAIN),
        json.dumps(paths),
        model,
        "-o",
        target,
        "--export-format",
        "binstl",
    ], (ro, links)


def _main_digest() -> str:
    """A digest of the evaluator's entry point, whose patches shape its meshes: a changed
    patch renders again rather than reuse a mesh the old one made."""
    return hashlib.sha256(_MANIFOLD_MAIN.read_bytes()).hexdigest()[:16]


def _backend_key(backend: str, defines: list[str]) -> bytes:
    """The cache key's part that names who renders, with which overrides."""
    if backend == "cgal":  # the key as before backends existed: cached renders stay valid
        return json.dumps([defines, openscad_version()]).encode()
    return json.dumps([defines, manifold_version(), backend, _main_digest()]).encode()


def _render_argv(
    backend: str, scad_file: Path, params: Mapping[str, ScadValue], work: Path, jail: bool
) -> tuple[list[str], tuple[dict, dict] | None]:
    """The render's command line (writing work/out/mesh.stl, as the jail shows it when jail)
    and its jail layout (None: the program's own, _jail_layout)."""
    target = f"{JAIL_OUT}/mesh.stl" if jail else str(work / "out" / "mesh.stl")
    if backend == "manifold":
        return _manifold_argv(_manifold_input(scad_file, params, work, jail), target)
    defines = [a for k, v in sorted(params.items()) for a in ("-D", f"{k}={_scad_literal(v)}")]
    return [
        openscad_binary(),
        "--export-format",
        "binstl",
        "-o",
        target,
        *defines,
        scad_file.name,
    ], None


def _named(why: str, backend: str) -> str:
    """A failure's text naming the program that failed."""
    if backend == "cgal":
        return why
    return why.replace("OpenSCAD failed", f"backend manifold ({manifold_version()}) failed", 1)


def _manifold_input(
    scad_file: Path, params: Mapping[str, ScadValue], work: Path, jail: bool
) -> str:
    """The file the evaluator is given, as its process sees it: the model itself, or, with
    params, a wrapper in the output folder that includes the model and then assigns them. That
    is what `-D` does (the evaluator has no -D): an assignment after the model's own, the last
    one winning. The model's own relative paths still resolve from its folder."""
    model = f"{JAIL_MODEL}/{scad_file.name}" if jail else str(scad_file)
    if not params:
        return model
    wrapper = work / "out" / "_params.scad"
    wrapper.write_text(
        f"include <{model}>\n"
        + "".join(f"{k} = {_scad_literal(v)};\n" for k, v in sorted(params.items()))
    )
    return f"{JAIL_OUT}/{wrapper.name}" if jail else str(wrapper)


# -- rendering: one backend, or auto -------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class ScadRender:
    """One render of an OpenSCAD model: its mesh and who made it, for the note a user reads."""

    model: Path
    """The .scad file rendered."""
    path: Path
    """The rendered mesh in the render cache: a binary STL [model units]."""
    backend: Literal["cgal", "manifold"]
    """Who rendered it: the openscad binary or openscad-evaluator."""
    asked: Backend
    """The backend asked for ("auto" chooses one of the two)."""
    why: str = ""
    """Why auto left manifold for the binary ("" otherwise)."""
    seconds: float | None = None
    """Wall time of the render [s], process start included; None if not recorded."""
    cached: bool = False
    """Taken from the render cache (seconds is then the first render's)."""
    text_size: float = 0.0
    """Largest size given to text() [model units] when manifold drew text, else 0 (a model
    that scale()s its text moves glyphs by that much more than text_deviation says)."""
    face_spread: float = 0.0
    """Largest spread across its plane [model units] of a polyhedron face of more than four
    corners that is not flat, when manifold cut it into triangles (maybe otherwise than the
    binary: the two surfaces lie within it), else 0."""

    @property
    def text_deviation(self) -> float:
        """How far a glyph may sit from the binary's [model units] (TEXT_DEVIATION)."""
        return TEXT_DEVIATION * self.text_size if self.backend == "manifold" else 0.0

    def note(self, scale: float = 1.0) -> str:
        """Who rendered the model, why, in how long, and what that may change: e.g.
        "tile.scad: rendered with manifold (openscad-evaluator 1.8.1, manifold3d 3.5.4) in
        12 s". scale: the object's largest scale factor [m per model unit], to say a text()
        deviation in metres of terrain."""
        took = "" if self.seconds is None else f" in {_seconds_text(self.seconds)}"
        took += " (cached)" if self.cached else ""
        if self.backend == "cgal":
            why = self.why or ("backend: cgal asked for" if self.asked == "cgal" else "")
            return f"{self.model.name}: rendered with the openscad binary{took}" + (
                f": {why}" if why else ""
            )
        text = f"{self.model.name}: rendered with manifold ({manifold_version()}){took}"
        if self.text_size > 0:
            dev = self.text_deviation
            text += (
                f"; text(): glyphs may sit up to {dev:.2g} model units from OpenSCAD's "
                f"({TEXT_DEVIATION:.2%} of their size, up to {self.text_size:.3g} here), "
                f"{dev * scale * 1000:.2g} mm of terrain at scale {scale:g}"
            )
        if self.face_spread > 0:
            text += (
                f"; polyhedron(): a face of more than 4 corners, up to {self.face_spread:.2g} "
                f"model units out of its plane, may be cut into triangles otherwise than by "
                f"OpenSCAD: up to {self.face_spread * scale * 1000:.2g} mm of terrain"
            )
        return text


def _seconds_text(seconds: float) -> str:
    return f"{seconds:.1f} s" if seconds < 10 else f"{seconds:.0f} s"


class _BackendFailed(SceneError):
    """A render that left no usable mesh. fallback: auto may let the binary try after backend
    manifold (the evaluator refused the model, failed on it or made a mesh unlike the
    binary's), not after the time limit (nothing left of it) or when no jail can be made (the
    binary needs one too). remember: the failure is the model's own, so auto goes straight to
    the binary next time (until the model, its files or the evaluator change). why: the short
    reason auto's note gives."""

    def __init__(
        self, message: str, *, fallback: bool = False, remember: bool = False, why: str = ""
    ) -> None:
        super().__init__(message)
        self.fallback, self.remember, self.why = fallback, remember, why


def _cache_path(
    backend: str, scad_file: Path, params: Mapping[str, ScadValue], deps: list[Path]
) -> Path:
    """Where backend's mesh of the model is cached: a key made of the model's text, every file
    it reads, the overrides and who renders (program and versions)."""
    root = scad_file.parent
    defines = [f"{k}={_scad_literal(v)}" for k, v in sorted(params.items())]
    digest = hashlib.sha256()
    for f in (scad_file, *deps):
        digest.update(str(f.relative_to(root)).encode() + b"\0" + f.read_bytes() + b"\0")
    digest.update(_backend_key(backend, defines))
    tag = "" if backend == "cgal" else f"-{backend}"
    return cache_dir() / f"{scad_file.stem}{tag}-{digest.hexdigest()[:32]}.stl"


_FACTS = ".json"
"""Beside a cached mesh: how long its render took and what it found (_manifold_main.FACTS)."""
_REFUSED = ".refused"
"""Beside where backend manifold's mesh would be cached: why it could not render the model,
so that auto goes straight to the binary."""


def _render_with(
    backend: Literal["cgal", "manifold"],
    scad_file: Path,
    params: Mapping[str, ScadValue],
    deps: list[Path],
    *,
    timeout: float,
    memory: int,
    limit: float,
) -> ScadRender:
    """backend's render of the model, from the cache or run now in the jail (raises
    _BackendFailed). timeout: seconds this run may take; limit: the object's time limit, for
    the message when it is hit."""
    out = _cache_path(backend, scad_file, params, deps)
    if out.is_file():
        facts = _read_facts(out.with_suffix(_FACTS))
        return ScadRender(
            model=scad_file,
            path=out,
            backend=backend,
            asked=backend,
            seconds=facts.get("seconds"),
            cached=True,
            **_found(facts),
        )
    out.parent.mkdir(parents=True, exist_ok=True)
    who = "OpenSCAD" if backend == "cgal" else "backend manifold"
    # Render into a fresh folder beside the cache and rename: a killed render leaves no
    # half-written mesh behind under the final name.
    work = Path(tempfile.mkdtemp(dir=out.parent, prefix=".render-"))
    try:
        (work / "out").mkdir()
        jail = _jail_wanted()
        argv, layout = _render_argv(backend, scad_file, params, work, jail)
        cmd = confined(
            argv, scad_file.parent, work, memory=memory, cpu=timeout, jail=jail, layout=layout
        )
        t0 = time.monotonic()
        try:
            proc = _run(cmd, cwd=scad_file.parent, timeout=timeout, name=scad_file.name)
        except subprocess.TimeoutExpired:
            raise _BackendFailed(
                f"{scad_file}: {who} did not finish within its time limit of {limit:g} s "
                f"and was stopped; a slow model may take more: give this terrain object "
                f"`timeout: SECONDS` (or --scad-timeout SECONDS), at most {MAX_TIMEOUT:.0f}"
            ) from None
        seconds = time.monotonic() - t0
        mesh = work / "out" / "mesh.stl"
        if proc.returncode != 0 or not mesh.is_file() or mesh.stat().st_size == 0:
            why = _failure(scad_file, proc, memory=memory, timeout=limit, jail=jail)
            own = proc.returncode != _jail.SETUP_FAILED and not _limit_hit(
                proc.returncode, proc.stderr, memory=memory, timeout=limit
            )
            raise _BackendFailed(
                f"{scad_file}: {_named(why, backend)}",
                fallback=own,
                remember=own,
                why=_short_failure(proc.stderr, why),
            )
        if backend == "manifold":
            problem = _manifold_mesh_problem(scad_file, mesh)
            if problem:
                raise _BackendFailed(
                    problem,
                    fallback=True,
                    remember=True,
                    why=problem.split(": ", 1)[1].split(";")[0],
                )
        facts = _read_facts(mesh.with_name(mesh.name + FACTS_SUFFIX))
        facts["seconds"] = round(seconds, 3)
        # The facts first: a mesh under its final name always has them beside it.
        out.with_suffix(_FACTS).write_text(json.dumps(facts))
        mesh.replace(out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return ScadRender(
        model=scad_file, path=out, backend=backend, asked=backend, seconds=seconds, **_found(facts)
    )


def _read_facts(path: Path) -> dict:
    try:
        facts = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return facts if isinstance(facts, dict) else {}


def _found(facts: dict) -> dict[str, float]:
    """ScadRender's fields from what the evaluator found (_manifold_main.FACTS)."""
    out = {}
    for key in ("text_size", "face_spread"):
        value = facts.get(key, 0.0)
        out[key] = float(value) if isinstance(value, int | float) and math.isfinite(value) else 0.0
    return out


def _short_failure(stderr: str, why: str) -> str:
    """The first error line of a failed render, without its advice, for auto's note."""
    lines = [line for line in stderr.splitlines() if "ERROR" in line] or why.splitlines()[-1:]
    line = re.sub(r"^.*?ERROR:\s*", "", lines[0] if lines else "it failed")
    line = line.split("; render this")[0].replace(f"{JAIL_MODEL}/", "")
    return line if len(line) <= 200 else line[:197] + "..."


def render_scad_result(
    scad_file: Path,
    params: Mapping[str, ScadValue] | None = None,
    *,
    timeout: float = DEFAULT_TIMEOUT,
    memory: int | None = None,
    backend: Backend = DEFAULT_BACKEND,
) -> ScadRender:
    """Render scad_file with `-D name=value` overrides to an STL (cached) and say who did it.

    The cache key covers the model text, the files it reads, the overrides and the program that
    renders (backend and versions), so a changed parameter or height map renders again and an
    unchanged model never does. Every render runs in the jail (module docstring); one past
    `timeout` seconds, or past `memory` bytes of memory (default: memory_limit()), is stopped
    with a SceneError that says how to allow more. OpenSCAD's own error text is passed through
    when the model is wrong.

    backend (BACKENDS): "cgal" runs the openscad binary; "manifold" runs openscad-evaluator in
    the same jail, under the same limits, and refuses a model that uses a construct it renders
    differently (manifold_problem); "auto" runs manifold unless the model uses such a
    construct, and the binary then, or when the evaluator refuses the model, fails on it or
    makes a mesh unlike the binary's (the binary gets what is left of the time limit); a model
    the evaluator could not render goes straight to the binary next time. Only the time limit
    and a missing jail are not retried with the binary.
    """
    scad_file = Path(scad_file).resolve()
    if not scad_file.is_file():
        raise SceneError(f"{scad_file}: no such OpenSCAD file")
    problem = timeout_problem(timeout)
    if problem:
        raise SceneError(f"{scad_file}: render time limit: {problem}")
    if backend_problem(backend):
        raise SceneError(f"{scad_file}: backend: {backend_problem(backend)}")
    memory = memory_limit() if memory is None else memory
    params = dict(params or {})
    known = scad_variables(scad_file)
    for name, value in params.items():
        problem = param_problem(name, value, known, scad_file.name)
        if problem:
            raise SceneError(f"{scad_file}: parameter {problem}")
    deps = scad_dependencies(scad_file)
    if backend == "manifold" and manifold_problem(scad_file):
        raise SceneError(manifold_problem(scad_file))
    job = {
        "scad_file": scad_file,
        "params": params,
        "deps": deps,
        "memory": memory,
        "limit": timeout,
    }
    if backend != "auto":
        return _render_with(backend, timeout=timeout, **job)
    return _render_auto(job, timeout)


def _render_auto(job: dict, timeout: float) -> ScadRender:
    """Backend auto (render_scad_result): manifold, else the binary, saying why."""
    why = _manifold_differs(job["scad_file"])
    refused = None
    if not why:
        try:
            refused = _cache_path("manifold", job["scad_file"], job["params"], job["deps"])
        except SceneError as exc:  # the evaluator's packages are not installed
            why = f"backend manifold is not available ({exc})"
    if refused is not None:
        refused = refused.with_suffix(_REFUSED)
        if refused.is_file():
            why = refused.read_text().strip() or "backend manifold could not render it before"
    if not why:
        t0 = time.monotonic()
        try:
            return dataclasses.replace(
                _render_with("manifold", timeout=timeout, **job), asked="auto"
            )
        except _BackendFailed as exc:
            if not exc.fallback:
                raise
            why = f"backend manifold could not render it alike: {exc.why}"
            if exc.remember:
                _write_atomic(refused, why)
        timeout = max(timeout - (time.monotonic() - t0), 1.0)
    return dataclasses.replace(_render_with("cgal", timeout=timeout, **job), asked="auto", why=why)


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}")
    tmp.write_text(text)
    tmp.replace(path)


def render_scad(
    scad_file: Path,
    params: Mapping[str, ScadValue] | None = None,
    *,
    timeout: float = DEFAULT_TIMEOUT,
    memory: int | None = None,
    backend: Backend = DEFAULT_BACKEND,
) -> Path:
    """The cached STL of render_scad_result (same arguments): the mesh alone."""
    return render_scad_result(
        scad_file, params, timeout=timeout, memory=memory, backend=backend
    ).path
