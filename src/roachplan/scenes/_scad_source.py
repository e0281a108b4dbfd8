"""The static reading of an OpenSCAD model's text: the files it reads (includes, uses and every
file-reading call, recursively), checked to be literal relative paths inside the model's own
folder; its top-level variables (what `-D` / a scene's `params:` may set) and the kind of value
each takes; the first call of a construct. No program runs here: a refusal names the file, the
line and the offending text before OpenSCAD starts.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from roachplan.perception import short_repr

from ._errors import SceneError

ScadValue = float | int | bool | str

# Built-in modules and functions that read a file named by their first positional argument
# (OpenSCAD 2021.01, including the deprecated import_* modules). Any call's `file = ...`
# argument is checked too (dxf_dim, dxf_cross, linear_extrude(file=...), ...).
_FILE_CALLS = ("import", "surface", "import_stl", "import_off", "import_dxf")


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


def first_call(scad_file: Path, names) -> tuple[Path, int, str] | None:
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


def scad_literal(value: ScadValue) -> str:
    """value as OpenSCAD source text: what `-D name=...` and a wrapper's assignment take."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    return json.dumps(value)  # a double-quoted string OpenSCAD accepts
