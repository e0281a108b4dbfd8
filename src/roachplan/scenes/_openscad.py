"""Render OpenSCAD models: confined, time-limited, cached; by the real `openscad` binary or by
openscad-evaluator on Manifold (BACKENDS: by default `auto`, the evaluator where it renders the
model as the binary does, else the binary; render_scad_result says which, and why).

A model may only read files in its own folder. Before OpenSCAD runs, the model and everything it
includes are scanned (scenes/_scad_source.py): `include <f>`, `use <f>` and every file-reading
call (`import`, `surface`, `file = ...` arguments) must name a literal relative path that stays
inside the folder, so a refusal names the file, the line and the offending path. OpenSCAD then
runs in a jail of the operating system (scenes/_scad_sandbox.py, scenes/_jail.py: user, mount
and network namespaces) that holds only the model's folder (read-only), OpenSCAD's own program,
libraries and fonts, and the one folder it writes its mesh to; so a path the scan could not see
(an escape that OpenSCAD decodes, a link) leads nowhere. Each render also runs under limits of
memory, processor time and output size, as a child of roachplan.processes (its wall-time limit,
Running events while it runs, killed with everything it started when cancelled). Where the
system cannot make the jail, rendering is refused unless $ROACHPLAN_UNSAFE_SCAD=1. Backend
manifold's own parts are in scenes/_scad_manifold.py; here: which backend, the cache, the run.
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
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, TypedDict

from roachplan.perception import short_repr
from roachplan.processes import run_program

from . import _jail
from ._errors import SceneError
from ._manifold_main import FACTS_SUFFIX
from ._scad_manifold import (
    MERGED,
    TEXT_DEVIATION,
    flat_stand_in,
    main_digest,
    manifold_argv,
    manifold_differs,
    manifold_input,
    manifold_mesh_problem,
    manifold_problem,
    manifold_version,
    merge_touching,
)
from ._scad_sandbox import (
    JAIL_MODEL,
    JAIL_OUT,
    MAX_TIMEOUT,
    confined,
    jail_wanted,
    limit_hit,
    memory_limit,
    render_failure,
    render_warnings,
    run_confined,
    timeout_problem,
)
from ._scad_source import ScadValue, param_problem, scad_dependencies, scad_literal, scad_variables

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
(scenes/_scad_manifold.py, MANIFOLD_DIFFERS), its solids touching face to face merged as the
binary merges them (merge_touching: procedural terrains, up to 28x faster here); "auto" (the default),
manifold unless the model uses one of those, or the evaluator refuses it, fails on it or
leaves solids touching face to face apart that could not be merged: then the binary
(render_scad_result says which, and why; its progress line, how long it is expected to take:
binary_expectation)."""
DEFAULT_BACKEND: Backend = "auto"


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
    """What `openscad --version` says (part of the render cache's key)."""
    out = run_program([openscad_binary(), "--version"], time_limit=30, output=True)
    return (out.stdout + out.stderr).strip()


def backend_problem(backend: object) -> str:
    """Why backend is not a render backend, or "" if it is."""
    if backend not in BACKENDS:
        return (
            f"expected one of {', '.join(BACKENDS)} (auto: manifold where it renders the model "
            f"as the binary does, else the binary; cgal: the openscad binary, the reference; "
            f"manifold: openscad-evaluator, faster on CSG-heavy models), got {short_repr(backend)}"
        )
    return ""


def _backend_key(backend: str, defines: list[str]) -> bytes:
    """The cache key's part that names who renders, with which overrides."""
    if backend == "cgal":  # the key as before backends existed: cached renders stay valid
        return json.dumps([defines, openscad_version()]).encode()
    return json.dumps([defines, manifold_version(), backend, main_digest(), MERGED]).encode()


def _render_argv(
    backend: str,
    scad_file: Path,
    params: Mapping[str, ScadValue],
    work: Path,
    jail: bool,
    *,
    name: str = "mesh.stl",
) -> tuple[list[str], tuple[dict, dict] | None]:
    """The command line of backend writing work/out/NAME (as the jail shows it when jail) and
    its jail layout (None: the program's own, _jail_layout). NAME's suffix says what is
    written: mesh.stl the render, drawing.svg the evaluator's 2-D drawing, tree.csg the
    binary's CSG tree."""
    target = f"{JAIL_OUT}/{name}" if jail else str(work / "out" / name)
    if backend == "manifold":
        return manifold_argv(manifold_input(scad_file, params, work, jail), target)
    defines = [a for k, v in sorted(params.items()) for a in ("-D", f"{k}={scad_literal(v)}")]
    export = ["--export-format", "binstl"] if name.endswith(".stl") else []
    return [openscad_binary(), *export, "-o", target, *defines, scad_file.name], None


def _side_output(
    backend: str,
    scad_file: Path,
    params: Mapping[str, ScadValue],
    name: str,
    *,
    memory: int,
    timeout: float,
    what: str = "",
) -> str | None:
    """The text of the file NAME backend writes of the model (_render_argv), run in the jail
    beside the cache under the render's limits, or None when it did not write it within
    timeout [s]. what: the model as a progress line names it ("": no progress line)."""
    cache = cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(dir=cache, prefix=".render-"))
    try:
        (work / "out").mkdir()
        jail = jail_wanted()
        argv, layout = _render_argv(backend, scad_file, params, work, jail, name=name)
        cmd = confined(
            argv, scad_file.parent, work, memory=memory, cpu=timeout, jail=jail, layout=layout
        )
        run = run_confined(cmd, model_dir=scad_file.parent, timeout=timeout, what=what)
        out = work / "out" / name
        if run.timed_out or run.status != 0 or not out.is_file():
            return None
        return out.read_text(errors="replace")
    finally:
        shutil.rmtree(work, ignore_errors=True)


NOT_3D = "Current top level object is not a 3D object"
"""What the binary says of a model whose top level is 2-D (and then writes no mesh)."""


def flat_model_problem(scad_file: Path) -> str:
    """The refusal of a model whose top level is 2-D: it names the file, says that it has no
    height and how to give it one."""
    return (
        f"{scad_file}: the model is 2-D: its top level draws only flat shapes (square(), "
        f"circle(), polygon(), text(), projection() ...), which have no height, so it is no "
        f"terrain; extrude what it draws into a solid, e.g. `linear_extrude(height = 0.05) "
        f"square(1);` (a plate 5 cm thick, in metres)"
    )


def _drawn_flat(
    scad_file: Path, params: Mapping[str, ScadValue], *, memory: int, timeout: float
) -> bool:
    """Whether openscad-evaluator draws the model as SVG, which it writes of a 2-D top level
    only (a 3-D one fails: "not a 2D object"): run in the jail, under the render's limits, to
    tell its stand-in for a 2-D model from a solid of the same shape (flat_stand_in)."""
    name = scad_file.name
    svg = _side_output(
        "manifold", scad_file, params, "drawing.svg", memory=memory, timeout=timeout, what=name
    )
    return svg is not None


def _named(why: str, backend: str) -> str:
    """A failure's text naming the program that failed."""
    if backend == "cgal":
        return why
    return why.replace("OpenSCAD failed", f"backend manifold ({manifold_version()}) failed", 1)


# -- what the binary is expected to take ----------------------------------------------------------

BINARY_PACE = (5e-4, 8e-3)
"""How long the binary (OpenSCAD 2021.01's CGAL) takes per triangle of a model's solids, as
its CSG tree lists them before any boolean (csg_size) [s]: the least and the most it is
expected to take. Measured on a shared 2-core machine (docs/openscad.md, "Speed"): procedural
terrains of 64-900 blocks, polyhedron columns or stacked voxels side by side, and 16-144
hull()s of two spheres took 0.9-6.0 ms a triangle (median 2.9; 1.8 s for 768 triangles, 65 s
for 10,800, 350 s for 73,740: the pace grows with the size), and a minkowski() of a box with 7
holes and a sphere 0.95 ms for each of its 175,104 (166 s), which this range holds."""
TREE_TIME = (0.05, 1.0, 10.0)
"""Time the binary is given to write a model's CSG tree, which the expectation counts: this
share of the render's time limit, at least and at most these seconds [-, s, s]. It runs the
model's script without any boolean (0.1-0.2 s for the models above); one whose script alone
takes longer gets no expectation. Not counted in the render's own time limit."""


@dataclass(frozen=True, kw_only=True)
class CsgSize:
    """The size of a model as its CSG tree (the binary's `-o tree.csg`) lists it."""

    solids: int
    """Its solids before any boolean: cube(), sphere(), cylinder(), polyhedron(), surface(),
    import(), and each extrusion of a 2-D shape."""
    booleans: int
    """The booleans joining them: a union, difference, intersection, hull or minkowski of n
    children is n - 1 (a module's or a loop's children are a union too)."""
    triangles: int
    """The triangles of those solids, as the binary makes them ($fn, $fa, $fs); 12 for a
    solid whose triangles are not listed (surface(), import(), an extrusion); a minkowski()
    counts the product of its children's."""


_NODE = re.compile(r"^\s*(\w+)\((.*)\)\s*([;{])\s*$")
_SOLIDS = {"cube", "sphere", "cylinder", "polyhedron", "surface", "import"}
_EXTRUSIONS = {"linear_extrude", "rotate_extrude"}


def csg_size(tree: str) -> CsgSize:
    """The size of a model from its CSG tree (the text the binary writes with -o tree.csg:
    a node a line, `name(arguments) {` or `name(arguments);`, `}` closing). A minkowski()
    counts the product of its children's triangles: CGAL sums each convex part of one with
    the other and joins all those (a non-convex solid and a sphere take it minutes)."""
    solids = booleans = 0
    # Open nodes: (name, its children's triangles, inside an extrusion, its own triangles);
    # the first is the top level, a union too.
    nodes: list[tuple[str, list[int], bool, int]] = [("", [], False, 0)]

    def close() -> int:  # the last open node's triangles
        nonlocal booleans
        name, children, flat, own = nodes.pop()
        if not flat and len(children) > 1:
            booleans += len(children) - 1
        if name in _EXTRUSIONS:
            return own
        if name == "minkowski" and children:
            return math.prod(max(c, 1) for c in children)
        return sum(children)

    for line in tree.splitlines():
        if line.strip() == "}":
            if len(nodes) > 1:
                triangles = close()
                nodes[-1][1].append(triangles)
            continue
        node = _NODE.match(line)
        if node is None:
            continue
        name, args, end = node.groups()
        flat, own = nodes[-1][2], 0
        if not flat and (name in _SOLIDS or name in _EXTRUSIONS):
            solids += 1
            own = _triangles(name, args)
        if end == "{":
            nodes.append((name, [], flat or name in _EXTRUSIONS, own))
        else:
            nodes[-1][1].append(own)
    while len(nodes) > 1:  # (a tree cut short)
        triangles = close()
        nodes[-1][1].append(triangles)
    triangles = close()  # (the top level's booleans counted first)
    return CsgSize(solids=solids, booleans=booleans, triangles=triangles)


def _triangles(name: str, args: str) -> int:
    """The triangles of one solid of a CSG tree as the binary makes it (12 if not known)."""

    def number(key: str, default: float) -> float:
        found = re.search(rf"(?:^|[ ,(]){re.escape(key)} = (-?[\d.e+-]+)", args)
        try:
            return float(found.group(1)) if found else default
        except ValueError:
            return default

    def fragments(r: float) -> int:  # OpenSCAD's get_fragments_from_r
        fn, fa, fs = number("$fn", 0.0), number("$fa", 12.0), number("$fs", 2.0)
        if fn > 0:
            return max(int(fn), 3)
        if r < 1e-10 or fa <= 0 or fs <= 0:
            return 3
        return max(math.ceil(max(min(360.0 / fa, r * 2 * math.pi / fs), 5)), 5)

    if name == "sphere":
        f = fragments(number("r", 1.0))
        return 2 * f * ((f + 1) // 2)
    if name == "cylinder":
        return 4 * fragments(max(number("r1", 1.0), number("r2", 1.0)))
    if name == "polyhedron":
        faces = re.search(r"faces = \[(.*)\]", args)
        if faces is not None:
            return sum(
                max(f.count(",") - 1, 1) for f in re.findall(r"\[([^\[\]]*)\]", faces.group(1))
            )
    return 12


def _csg_tree(
    scad_file: Path, params: Mapping[str, ScadValue], *, memory: int, timeout: float
) -> str | None:
    """The model's CSG tree as the binary writes it (in the jail, under the render's limits),
    or None when it did not write one within timeout [s]."""
    return _side_output("cgal", scad_file, params, "tree.csg", memory=memory, timeout=timeout)


def binary_expectation(
    scad_file: Path, params: Mapping[str, ScadValue], *, memory: int, limit: float
) -> str:
    """How long the binary is expected to take on the model, and why, for the render's
    progress line: e.g. "expected to take 5.4 s to 86 s (an estimate: 900 solids, 899
    booleans, 10,800 triangles in its CSG tree, at 0.5-8 ms a triangle)"; "" when its CSG tree
    could not be written in its time (TREE_TIME). limit: the time the render is given [s]."""
    share, least, most = TREE_TIME
    tree_time = min(most, max(least, share * limit))
    tree = _csg_tree(scad_file, params, memory=memory, timeout=tree_time)
    if tree is None:
        return ""
    size = csg_size(tree)
    lo, hi = (size.triangles * pace for pace in BINARY_PACE)
    span = "under 1 s" if hi < 1 else f"{_duration(lo)} to {_duration(hi)}"
    text = (
        f"expected to take {span} (an estimate: {size.solids:,} solids, "
        f"{size.booleans:,} booleans, {size.triangles:,} triangles in its CSG tree, at "
        f"{BINARY_PACE[0] * 1000:g}-{BINARY_PACE[1] * 1000:g} ms a triangle)"
    )
    if hi > limit:
        text += f", maybe more than its {limit:.0f} s limit"
    return text


def _duration(seconds: float) -> str:
    if seconds < 10:
        return f"{seconds:.1f} s"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 600:
        return f"{seconds / 60:.1f} min"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


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
    warnings: tuple[str, ...] = ()
    """The renderer's own ERROR and WARNING lines, when it made a mesh anyway (a used file it
    could not parse, a module it does not know: the mesh lacks that part)."""
    merged: int = 0
    """On how many planes manifold's mesh had solids touching face to face that were merged
    as the binary merges them (merge_touching), else 0."""

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
            return (
                f"{self.model.name}: rendered with the openscad binary{took}"
                + (f": {why}" if why else "")
                + self._warnings_text()
            )
        text = f"{self.model.name}: rendered with manifold ({manifold_version()}){took}"
        if self.text_size > 0:
            dev = self.text_deviation
            text += (
                f"; text(): glyphs may sit up to {dev:.2g} model units from OpenSCAD's "
                f"({TEXT_DEVIATION:.2%} of their size, up to {self.text_size:.3g} here), "
                f"{dev * scale * 1000:.2g} mm of terrain at scale {scale:g}"
            )
        if self.merged > 0:
            text += (
                f"; solids touching face to face (on {self.merged} "
                f"plane{'s' if self.merged > 1 else ''}) merged as OpenSCAD merges them"
            )
        if self.face_spread > 0:
            text += (
                f"; polyhedron(): a face of more than 4 corners, up to {self.face_spread:.2g} "
                f"model units out of its plane, may be cut into triangles otherwise than by "
                f"OpenSCAD: up to {self.face_spread * scale * 1000:.2g} mm of terrain"
            )
        return text + self._warnings_text()

    def _warnings_text(self) -> str:
        if not self.warnings:
            return ""
        return "; it reported (parts of the model may be missing): " + " | ".join(self.warnings)


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
    defines = [f"{k}={scad_literal(v)}" for k, v in sorted(params.items())]
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
    reason: str = "",
) -> ScadRender:
    """backend's render of the model, from the cache or run now in the jail (raises
    _BackendFailed). timeout: seconds this run may take; limit: the object's time limit, for
    the message when it is hit. reason: why the binary renders it, for its progress line:
    a binary render's Running events name the model, the reason and how long it is expected
    to take (binary_expectation; the name alone when that is not known)."""
    out = _cache_path(backend, scad_file, params, deps)
    if out.is_file():
        # (a render cached before 2-D models were refused may be the evaluator's stand-in)
        if backend == "manifold" and _flat(scad_file, params, out, memory=memory, timeout=timeout):
            raise _BackendFailed(flat_model_problem(scad_file))
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
    what, expected = scad_file.name, ""
    if backend == "cgal":
        expected = binary_expectation(scad_file, params, memory=memory, limit=timeout)
        if expected:
            what += f" with the openscad binary{f' ({reason})' if reason else ''}, {expected}"
    # Render into a fresh folder beside the cache and rename: a killed render leaves no
    # half-written mesh behind under the final name.
    work = Path(tempfile.mkdtemp(dir=out.parent, prefix=".render-"))
    try:
        (work / "out").mkdir()
        jail = jail_wanted()
        argv, layout = _render_argv(backend, scad_file, params, work, jail)
        cmd = confined(
            argv, scad_file.parent, work, memory=memory, cpu=timeout, jail=jail, layout=layout
        )
        t0 = time.monotonic()
        run = run_confined(cmd, model_dir=scad_file.parent, timeout=timeout, what=what)
        if run.timed_out:
            raise _BackendFailed(
                f"{scad_file}: {who} did not finish within its time limit of {limit:g} s "
                f"and was stopped{f'; it was {expected}' if expected else ''}; a slow model "
                f"may take more: give this terrain object "
                f"`timeout: SECONDS` (or --scad-timeout SECONDS), at most {MAX_TIMEOUT:.0f}"
            )
        seconds = time.monotonic() - t0
        mesh = work / "out" / "mesh.stl"
        if run.status != 0 or not mesh.is_file() or mesh.stat().st_size == 0:
            if backend == "cgal" and NOT_3D in run.stderr:
                raise _BackendFailed(flat_model_problem(scad_file))
            why = render_failure(scad_file, run, memory=memory, timeout=limit, jail=jail)
            own = run.status != _jail.SETUP_FAILED and not limit_hit(
                run.status, run.stderr, memory=memory, timeout=limit
            )
            raise _BackendFailed(
                f"{scad_file}: {_named(why, backend)}",
                fallback=own,
                remember=own,
                why=_short_failure(run.stderr, why),
            )
        if backend == "manifold" and _flat(scad_file, params, mesh, memory=memory, timeout=timeout):
            raise _BackendFailed(flat_model_problem(scad_file))
        merged = 0
        if backend == "manifold":
            merged = merge_touching(mesh)
            seconds = time.monotonic() - t0
            problem = manifold_mesh_problem(scad_file, mesh)
            if problem:
                raise _BackendFailed(
                    problem,
                    fallback=True,
                    remember=True,
                    why=problem.split(": ", 1)[1].split(";")[0],
                )
        facts = _read_facts(mesh.with_name(mesh.name + FACTS_SUFFIX))
        facts["seconds"] = round(seconds, 3)
        facts["warnings"] = list(render_warnings(run, jail=jail))
        facts["merged"] = merged
        # The facts first: a mesh under its final name always has them beside it.
        out.with_suffix(_FACTS).write_text(json.dumps(facts))
        mesh.replace(out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return ScadRender(
        model=scad_file, path=out, backend=backend, asked=backend, seconds=seconds, **_found(facts)
    )


def _flat(
    scad_file: Path, params: Mapping[str, ScadValue], mesh: Path, *, memory: int, timeout: float
) -> bool:
    """Whether backend manifold's mesh of the model is the evaluator's stand-in for a 2-D top
    level (a slab 1 unit thick, flat_stand_in, that the evaluator also draws as SVG), which the
    binary refuses: the model is then refused alike, whoever renders it."""
    return flat_stand_in(mesh) and _drawn_flat(scad_file, params, memory=memory, timeout=timeout)


def _read_facts(path: Path) -> dict:
    try:
        facts = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return facts if isinstance(facts, dict) else {}


class _Found(TypedDict):
    """ScadRender's fields of what the render found."""

    text_size: float
    face_spread: float
    warnings: tuple[str, ...]
    merged: int


def _found(facts: dict) -> _Found:
    """ScadRender's fields from what the render found (_manifold_main.FACTS, and the
    renderer's warnings)."""

    def number(key: str) -> float:
        value = facts.get(key, 0.0)
        return float(value) if isinstance(value, int | float) and math.isfinite(value) else 0.0

    warnings = facts.get("warnings", [])
    if not (isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)):
        warnings = []
    return _Found(
        text_size=number("text_size"),
        face_spread=number("face_spread"),
        warnings=tuple(warnings),
        merged=int(number("merged")),
    )


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
        return _render_with(backend, timeout=timeout, reason=f"backend: {backend}", **job)
    return _render_auto(job, timeout)


def _render_auto(job: dict, timeout: float) -> ScadRender:
    """Backend auto (render_scad_result): manifold, else the binary, saying why."""
    why = manifold_differs(job["scad_file"])
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
                assert refused is not None  # (manifold was tried: its cache path was found)
                _write_atomic(refused, why)
        timeout = max(timeout - (time.monotonic() - t0), 1.0)
    # The progress line's reason: why without its details in brackets (file, line, point).
    reason = re.sub(r"\s+\((?:[^()]|\([^()]*\))*\)", "", why)
    reason = reason if len(reason) <= 120 else reason[:117] + "..."
    try:
        binary = _render_with("cgal", timeout=timeout, reason=reason, **job)
    except _BackendFailed as exc:
        # Say why it was the binary's turn: backend manifold was tried first, or passed over.
        raise SceneError(f"{exc}\n(backend auto gave it to the binary because {why})") from None
    return dataclasses.replace(binary, asked="auto", why=why)


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
