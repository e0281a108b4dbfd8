"""Run openscad-evaluator (backend manifold) as OpenSCAD 2021.01 would render the model.

Run as `python -I -S -B _manifold_main.py SITE_PATHS_JSON MODEL -o OUT ...` by
scenes/_scad_manifold.py, inside the render jail: it imports nothing of roachplan, puts only
the evaluator's site-packages folder on sys.path, and hands the rest of its arguments to the
evaluator's command line.

Four changes to the evaluator. First, its parser (_patch_parser) reads commas repeated between a
vector's elements or a call's arguments, and after a vector's last element, as OpenSCAD 2021.01
does (`[a,, b]`, `[a, b,,]`, `cube(1,, center=true)`; checked against Debian's binary), where
the evaluator saw a syntax error. The binary reads other loose commas too (`cube(, 1)`,
`let(a = 1,, b = 2)`, in a module's parameters): those stay syntax errors here. And a file
other than the model that it cannot parse stops the render as a refusal (auto: the binary
renders it): the evaluator reported a syntax error in a file the model uses (`use <step.scad>`)
and went on without its modules, so the render "succeeded" with parts of the model missing
(seen: a public model staircase rendered as its two side supports, without its steps). A
syntax error in the model itself fails the render as before.

Second, seeded `rands(min, max, n, seed)` draws the numbers OpenSCAD
2021.01 draws, so a model's seeded bumps (double_bridge_rough) land where the reference binary
puts them. The evaluator draws from Python's `random` seeded with int(seed), a different
sequence (measured: rands(0, 1, 4, 0) gives 0.844, 0.758, ... against OpenSCAD's 0.593, 0.844,
...). OpenSCAD 2021.01 seeds a std::mt19937 with the seed converted to a 32-bit unsigned integer
and draws each number with std::uniform_real_distribution, which takes two 32-bit outputs per
number (libstdc++'s generate_canonical<double, 53>); checked against Debian's binary for seeds
0, 1, 42, -3 and 12345, and min > max. A non-integer seed is seeded otherwise there (not found
out), so it is refused with a message that names backend cgal. Unseeded rands() is random in
OpenSCAD too and is left as the evaluator has it.

Then the last two, so that text() and a polyhedron wound the other way render as the binary renders
them (each checked against Debian's binary by tests/test_scad_backend.py):

- text() (_patch_text): the font is the one fontconfig gives OpenSCAD for the same request
  (`fc-match`, OpenSCAD's "Liberation Sans:style=Regular" when none is named), not the
  evaluator's bundled Liberation Sans (where no Liberation font is installed, as here,
  fontconfig gives OpenSCAD DejaVu Sans, whose glyphs are wider); glyphs are placed as OpenSCAD 2021.01 places them, at 1000/1024 of HarfBuzz's
  positions (FreetypeRenderer scales outlines by 1/1000 and positions by 1/64/16), valign
  from the glyph boxes scaled alike; curves are cut into OpenSCAD 2021.01's
  number of segments (max(floor(fragments(size) / 8) + 1, 2)). What is left (FreeType's
  hinting and pixel sizes, which the evaluator does not reproduce) is measured in
  scenes/_scad_manifold.py, TEXT_DEVIATION.
- polyhedron() (_patch_polyhedron): a closed polyhedron whose faces are all wound the other
  way (counter-clockwise seen from outside: inward, a negative volume) has them turned
  round. OpenSCAD's CGAL makes a solid of such a polyhedron in a union or difference (and
  exports a lone one as given, inside out, which roachplan's mesh cleaning turns outward),
  where the evaluator's union with it was an open shell. A polyhedron wound both ways is
  left as it is: OpenSCAD refuses it too ("The given mesh is not closed").
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import random
import re
import shutil
import struct
import subprocess
import sys


def mt19937(seed: int) -> random.Random:
    """A generator whose getrandbits(32) are std::mt19937(seed)'s outputs (init_genrand, not
    Python's own init_by_array seeding)."""
    state = [seed & 0xFFFFFFFF]
    for i in range(1, 624):
        state.append((1812433253 * (state[-1] ^ (state[-1] >> 30)) + i) & 0xFFFFFFFF)
    rng = random.Random()
    rng.setstate((3, (*state, 624), None))
    return rng


REFUSED = 3
"""Exit status of a render stopped for a construct it would not draw as OpenSCAD does."""
SEEDS = (-(1 << 31), 1 << 32)
"""Seeds whose draws are OpenSCAD's [min, max): integers that convert to a 32-bit seed alike."""


def openscad_rands(lo: float, hi: float, n: int, seed: int) -> list[float]:
    """rands(lo, hi, n, seed) as OpenSCAD 2021.01 computes it, for an integer seed in SEEDS."""
    rng = mt19937(seed & 0xFFFFFFFF)
    a, b = min(lo, hi), max(lo, hi)
    out = []
    for _ in range(max(0, int(n))):
        low = rng.getrandbits(32)
        high = rng.getrandbits(32)
        u = (float(low) + float(high) * 4294967296.0) / 18446744073709551616.0
        if u >= 1.0:
            u = math.nextafter(1.0, 0.0)
        out.append(u * (b - a) + a)
    return out


OPENSCAD_COMMAS = (
    # (the evaluator's rule, as OpenSCAD 2021.01's parser.y reads it: optional_commas)
    ('vector_elements: vector_element ("," vector_element)* ","?',
     'vector_elements: vector_element (","+ vector_element)* ","*'),
    ('vector_expr: "[" vector_elements "]"\n    | "[" "]"',
     'vector_expr: "[" vector_elements "]"\n    | "[" ","* "]"'),
    ('arguments: (argument ("," argument)* ","?)?',
     'arguments: (argument (","+ argument)* ","?)?'),
)  # fmt: skip
"""The evaluator's grammar rules that OpenSCAD 2021.01 reads more loosely, and how it reads them."""


def _patch_parser(model: str) -> None:
    """Parse as OpenSCAD 2021.01 reads commas (OPENSCAD_COMMAS), and refuse when a file other
    than the model (its path: model) cannot be parsed."""
    import openscad_lalr_parser as parser_module
    from lark import Lark

    grammar = parser_module._GRAMMAR_PATH.read_text()
    for rule, loose in OPENSCAD_COMMAS:
        if rule not in grammar:
            _refuse(f"backend manifold's parser has changed (no rule {rule!r})")
        grammar = grammar.replace(rule, loose)
    # The library's own cache of its parser for the standard comma mode, which the evaluator
    # runs in here (no --strict-commas), filled with the parser it would build from this grammar.
    parser_module._parser_cache["standard"] = Lark(
        grammar, parser="lalr", propagate_positions=True, maybe_placeholders=False
    )

    parse_ast = parser_module.parse_ast

    def parse_or_refuse(code, origin="<string>", source_map=None):
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):  # (where parse_ast prints a syntax error)
            nodes = parse_ast(code, origin=origin, source_map=source_map)
        text = printed.getvalue()
        found = re.match(r"Syntax error in (.*) at line \d+, column \d+", text)
        if nodes is None and found and os.path.abspath(found[1]) != model:
            # A used or included file: the evaluator would go on without it.
            _refuse(f"{found[0]}: backend manifold could not parse it")
        # The model's own syntax error fails the render as the evaluator has it (with its
        # line and caret): the binary would refuse it too.
        sys.stdout.write(text)
        return nodes

    parser_module.parse_ast = parse_or_refuse


def _patch_rands() -> None:
    from openscad_evaluator.evaluator import Evaluator

    unseeded = Evaluator._builtin_rands

    def _builtin_rands(self, minval, maxval, n, seed=None):
        if seed is None:
            return unseeded(self, minval, maxval, n)
        seed = float(seed)
        if not (seed.is_integer() and SEEDS[0] <= seed < SEEDS[1]):
            # Not an EvalError: the evaluator turns one inside an expression into undef and
            # goes on, and the render would "succeed" with other numbers than OpenSCAD's.
            _refuse(
                f"rands() with the seed {seed:g}: backend manifold draws OpenSCAD's "
                f"numbers for integer seeds only"
            )
        self._rands_call_count += 1  # the evaluator's cache taint, as in its own rands
        return openscad_rands(float(minval), float(maxval), int(n), int(seed))

    Evaluator._builtin_rands = _builtin_rands


# -- text(): OpenSCAD 2021.01's font, placement and curve segments ------------------------------

DEFAULT_FONT = "Liberation Sans:style=Regular"
"""The font OpenSCAD asks fontconfig for when text() names none (FontCache::DEFAULT_FONT)."""
POSITION_SCALE = 1000 / 1024
"""OpenSCAD 2021.01 scales glyph outlines by 1/1000 of FreeType's 26.6 units but HarfBuzz's
advances and offsets, and the glyph boxes valign uses, by 1/64/16 (FreetypeRenderer.cc,
GlyphData): its glyphs stand at 1000/1024 of where their advances put them (measured: "HH" at
size 10, the second H 10.199 apart there, 10.444 in the evaluator; 10.444 * 1000 / 1024 =
10.199)."""
FACTS = {"text_size": 0.0, "face_spread": 0.0}
"""What the render found that its caller reports (written beside the mesh as FACTS_SUFFIX):
the largest size given to text() [model units], 0 without text(); the largest spread across
its plane [model units] of a polyhedron face of more than four corners that is not flat (cut
into triangles otherwise than OpenSCAD may be), 0 if none."""
FACTS_SUFFIX = ".facts.json"


def _fontconfig_font(spec: str) -> tuple[str, int]:
    """(file, index) of the font fontconfig gives OpenSCAD for the font spec, as
    FontCache::find_face_fontconfig asks for it (outline and scalable fonts only)."""
    lookup = spec.strip() or DEFAULT_FONT
    fc_match = shutil.which("fc-match")
    out = None
    if fc_match is not None:
        out = subprocess.run(
            [fc_match, "--format=%{file}:%{index}", f"{lookup}:outline=true:scalable=true"],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
    path, _, index = (out.stdout.strip() if out and out.returncode == 0 else "").rpartition(":")
    if not path or not os.path.isfile(path):
        # Not a guess at another font: glyphs would sit millimetres from OpenSCAD's.
        _refuse(
            f"text() with the font {lookup!r}: fontconfig's fc-match cannot find the font "
            f"OpenSCAD would use here, so backend manifold cannot draw its glyphs alike"
        )
    return path, int(index) if index.isdigit() else 0


def openscad_text_segments(size: float, fn: float, fa: float, fs: float) -> int:
    """Segments per glyph curve in OpenSCAD 2021.01 (text.cc: Calc::get_fragments_from_r(size,
    ...) / 8 + 1, at least 2)."""
    if size < 0.00000095367431640625:  # GRID_FINE
        fragments = 3
    elif fn > 0:
        fragments = int(fn if fn >= 3 else 3)
    else:
        fragments = int(math.ceil(max(min(360.0 / fa, size * 2 * math.pi / fs), 5)))
    return int(max(math.floor(fragments / 8) + 1, 2))


def _patch_text() -> None:
    from openscad_evaluator import evaluator as ev

    fonts: dict[str, dict] = {}

    def resolve_font(spec: str) -> dict:
        if spec not in fonts:
            fonts[spec] = ev._font_tables_from_path(*_fontconfig_font(spec))
        return fonts[spec]

    measure = ev._measure_text

    # The evaluator's own signature, positional arguments included.
    def measure_text(text, size, spacing, font=None, direction="", language="", script=""):  # noqa: PLR0917
        font = font or resolve_font("")
        m = measure(text, size, spacing, font, direction, language, script)
        m["glyphs"] = [(g, x * POSITION_SCALE, y * POSITION_SCALE) for g, x, y in m["glyphs"]]
        m["advance_x"] *= POSITION_SCALE
        m["advance_y"] *= POSITION_SCALE
        if not m["vertical"]:
            # valign's ascent and descent come from the glyph boxes divided by 64 * 16 as well,
            # each at least 0 (measured: valign="bottom" on "Sg" at size 20 sits 0.045 higher
            # without this).
            m["ascent"] = max(0.0, m["ascent"]) * POSITION_SCALE
            m["descent"] = min(0.0, m["descent"]) * POSITION_SCALE
        return m

    resolve = ev.Evaluator._resolve_text

    def _resolve_text(self, node, ctx):
        # The evaluator reads $fn, $fa, $fs through self._fn for its own segment count; listen
        # there (arguments such as text(..., $fn = 8) included) rather than evaluate the call's
        # arguments twice (rands() and echo() in them would run twice).
        seen: dict = {}
        own = self._fn

        def listen(c, r=0.0):
            seen.update(fn=c.dyn.get("$fn", 0), fa=c.dyn.get("$fa", 12.0), fs=c.dyn.get("$fs", 2.0))
            return own(c, r)

        self._fn = listen
        try:
            params = resolve(self, node, ctx)
        finally:
            del self._fn
        font = resolve_font(params["font_spec"])
        size = params["scale"] * font["units_per_em"] * 72 / 100  # the evaluator's size back
        num = lambda v, d: float(v) if isinstance(v, int | float) and v > 0 else d  # noqa: E731
        params["segs"] = openscad_text_segments(
            size, num(seen.get("fn"), 0.0), num(seen.get("fa"), 12.0), num(seen.get("fs"), 2.0)
        )
        if params["glyphs"]:
            FACTS["text_size"] = max(FACTS["text_size"], abs(size))
        return params

    ev._resolve_font = resolve_font
    ev._load_default_font = lambda: resolve_font("")
    ev._measure_text = measure_text
    ev.Evaluator._resolve_text = _resolve_text


# -- polyhedron(): turned outward when wound the other way ----------------------------------------


def outward_faces(verts, tris):
    """tris ((M, 3) vertex indices) turned round when they make a closed surface wound one way
    throughout whose signed volume is negative (every face wound the other way); else as given.
    A closed, consistent winding uses every directed edge once and its reverse once."""
    import numpy as np

    tris = np.asarray(tris)
    if len(tris) == 0:
        return tris
    t = tris.astype(np.int64)
    n = int(t.max()) + 1
    a, b = t.ravel(), t[:, [1, 2, 0]].ravel()
    edges, counts = np.unique(a * n + b, return_counts=True)
    if counts.max() > 1 or not np.isin(b * n + a, edges).all():
        return tris  # open, or wound both ways: as OpenSCAD, not made a solid here
    v = np.asarray(verts, dtype=np.float64)[t]
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6
    return tris[:, [0, 2, 1]] if volume < 0 else tris


def _f32(value: float) -> float:
    """value rounded to a float, as OpenSCAD's tessellation sees it (Vector3f)."""
    return struct.unpack("f", struct.pack("f", value))[0]


def _newell(pts) -> tuple[float, float, float]:
    """The (unnormalised) Newell normal of the polygon pts, right-handed in its order."""
    nx = ny = nz = 0.0
    for (x0, y0, z0), (x1, y1, z1) in zip(pts, pts[1:] + pts[:1]):
        nx += (y0 - y1) * (z0 + z1)
        ny += (z0 - z1) * (x0 + x1)
        nz += (x0 - x1) * (y0 + y1)
    return nx, ny, nz


def _out_of_plane(pts) -> float:
    """How far the polygon's corners spread across its Newell plane [model units]."""
    n = _newell(pts)
    length = math.sqrt(sum(c * c for c in n))
    if not length > 0:
        return 0.0
    d = [sum(c * k for c, k in zip(p, n)) / length for p in pts]
    return max(d) - min(d)


def _libtess_normal(pts) -> list[float]:
    """libtess2's ComputeNormal: on the axis of the longest extent, the first lowest and
    highest corners, and the corner making the largest triangle with them."""
    lo = [min(range(len(pts)), key=lambda k, i=i: (pts[k][i], k)) for i in range(3)]
    hi = [min(range(len(pts)), key=lambda k, i=i: (-pts[k][i], k)) for i in range(3)]
    ext = [pts[hi[i]][i] - pts[lo[i]][i] for i in range(3)]
    i = 0
    i = 1 if ext[1] > ext[0] else i
    i = 2 if ext[2] > ext[i] else i
    v1, v2 = pts[lo[i]], pts[hi[i]]
    d1 = [v1[k] - v2[k] for k in range(3)]
    best, norm = 0.0, [0.0, 0.0, 1.0]
    for q in pts:
        d2 = [q[k] - v2[k] for k in range(3)]
        t = [
            d1[1] * d2[2] - d1[2] * d2[1],
            d1[2] * d2[0] - d1[0] * d2[2],
            d1[0] * d2[1] - d1[1] * d2[0],
        ]
        if t[0] * t[0] + t[1] * t[1] + t[2] * t[2] > best:
            best, norm = t[0] * t[0] + t[1] * t[1] + t[2] * t[2], t
    return norm


DELAUNAY_SLACK = 0.01
"""libtess2's Delaunay refinement keeps a triangle pair unless its two opposite angles add up
to more than pi + 0.01 [rad] (tesedgeIsLocallyDelaunay)."""


def openscad_quad_diagonal(quad) -> tuple[int, int]:
    """The two corners of a quadrilateral polyhedron face (four [x, y, z] in the order of the
    polyhedron() call) that OpenSCAD 2021.01 joins when it cuts the face into triangles:
    libtess2 (GeometryUtils::tessellatePolygonWithHoles, constrained Delaunay) on the face as
    OpenSCAD stores it (reversed), projected along the longest axis of its normal, oriented
    counter-clockwise; the monotone sweep's diagonal, flipped when it is not Delaunay.
    Checked against Debian's binary on 472 random quadrilaterals (corners out of plane by up
    to their own size; convex, concave and self-crossing in projection; near-ties included):
    all alike (tests/test_scad_backend.py keeps a sample)."""
    p = [[_f32(c) for c in q] for q in reversed(quad)]
    n = _libtess_normal(p)
    i = 0
    i = 1 if abs(n[1]) > abs(n[0]) else i
    i = 2 if abs(n[2]) > abs(n[i]) else i
    sign = 1.0 if n[i] > 0 else -1.0
    st = [(q[(i + 1) % 3], q[(i + 2) % 3] * sign) for q in p]
    if sum((st[k][0] - st[k - 3][0]) * (st[k][1] + st[k - 3][1]) for k in range(4)) < 0:
        st = [(s, -t) for s, t in st]  # CheckOrientation: counter-clockwise

    def cross(u, v, w):
        return (st[v][0] - st[u][0]) * (st[w][1] - st[u][1]) - (st[v][1] - st[u][1]) * (
            st[w][0] - st[u][0]
        )

    if any(
        cross(a, b, c) * cross(a, b, d) < 0 and cross(c, d, a) * cross(c, d, b) < 0
        for a, b, c, d in ((0, 1, 2, 3), (1, 2, 3, 0))
    ):
        # So twisted that it crosses itself seen along that axis: the binary then joins the
        # call's first and third corners (measured: a public terrain's cell, each of its
        # corners listed first, and random twisted quads).
        return (0, 2)

    def leq(u, v):  # VertLeq
        return st[u][0] < st[v][0] or (st[u][0] == st[v][0] and st[u][1] <= st[v][1])

    def edge_sign(u, v, w):  # tesedgeSign
        gl, gr = st[v][0] - st[u][0], st[w][0] - st[v][0]
        return (st[v][1] - st[w][1]) * gl + (st[v][1] - st[u][1]) * gr if gl + gr > 0 else 0.0

    # tessMeshTessellateMonoRegion on the ring 0-1-2-3: edge e runs from corner e to e + 1.
    nxt, prv = (lambda e: (e + 1) % 4), (lambda e: (e - 1) % 4)
    up = 0
    for _ in range(4):
        if not leq(nxt(up), up):
            break
        up = prv(up)
    for _ in range(4):
        if not leq(up, nxt(up)):
            break
        up = nxt(up)
    lo, diagonal = prv(up), None
    while diagonal is None and nxt(up) != lo:
        if leq(nxt(up), lo):
            e = nxt(lo)
            if e != up and (leq(nxt(e), e) or edge_sign(lo, nxt(lo), nxt(e)) <= 0):
                diagonal = (nxt(e), lo)
            lo = prv(lo)
        else:
            e = prv(up)
            if nxt(lo) != up and (leq(e, nxt(e)) or edge_sign(nxt(up), up, e) >= 0):
                diagonal = (nxt(up), e)
            up = nxt(up)
    a, b = diagonal if diagonal is not None else (nxt(nxt(lo)), lo)
    c, d = (k for k in range(4) if k not in (a, b))

    def angle(u, v, w):  # calcAngle: at v
        ax, ay, bx, by = (
            st[u][0] - st[v][0],
            st[u][1] - st[v][1],
            st[w][0] - st[v][0],
            st[w][1] - st[v][1],
        )
        den = math.hypot(ax, ay) * math.hypot(bx, by)
        return math.acos(max(-1.0, min(1.0, (ax * bx + ay * by) / den if den > 0 else 0.0)))

    if (
        angle(a, c, b) + angle(a, d, b) >= math.pi + DELAUNAY_SLACK
        and cross(c, d, a) * cross(c, d, b) < 0
    ):
        a, b = c, d
    lo, hi = sorted((3 - a, 3 - b))
    return (lo, hi)  # corners of the reversed face back in the call's order


PLANAR = 1e-9
"""A face whose corners spread across its plane by at most this fraction of its size is flat:
any cut into triangles is the same surface."""


def _patch_polyhedron() -> None:
    from openscad_evaluator import evaluator as ev
    from openscad_evaluator.evaluator import Evaluator

    triangulate = ev._triangulate_face

    def triangulate_face(verts, loop, out):
        pts = [verts[i] for i in loop] if all(0 <= i < len(verts) for i in loop) else None
        if pts is None or len(set(loop)) != len(loop) or len(loop) < 4:
            return triangulate(verts, loop, out)
        size = max(max(p[k] for p in pts) - min(p[k] for p in pts) for k in range(3))
        spread = _out_of_plane(pts)
        if not spread > PLANAR * size:
            return triangulate(verts, loop, out)
        if len(loop) > 4:
            # Cut otherwise than OpenSCAD may be: the two surfaces lie within the spread.
            FACTS["face_spread"] = max(FACTS["face_spread"], spread)
            return triangulate(verts, loop, out)
        a, b = openscad_quad_diagonal(pts)
        c, d = (k for k in range(4) if k not in (a, b))
        for tri in ((a, c, b), (a, b, d)) if (c - a) % 4 == 1 else ((a, d, b), (a, b, c)):
            i, j, k = (loop[t] for t in tri)
            out.append((i, k, j))  # Manifold's winding is the other way round, as the evaluator's
        return None

    ev._triangulate_face = triangulate_face
    resolve = Evaluator._resolve_polyhedron

    def _resolve_polyhedron(self, node, ctx):
        params = resolve(self, node, ctx)
        params["tri_arr"] = outward_faces(params["verts"], params["tri_arr"])
        return params

    Evaluator._resolve_polyhedron = _resolve_polyhedron


def _refuse(why: str) -> None:
    """Stop the render as backend manifold's refusal (exit REFUSED), naming backend cgal."""
    sys.stderr.write(f"ERROR: {why}; render this model with `backend: cgal`\n")
    sys.stderr.flush()
    os._exit(REFUSED)


def main() -> int:
    # Everything on the error stream, as OpenSCAD writes it (echo(), the parser's syntax
    # errors): the renderer keeps that stream's ends for its messages and drops the output one.
    os.dup2(2, 1)
    sys.path[:0] = json.loads(sys.argv[1])
    _patch_parser(os.path.abspath(sys.argv[2]))
    _patch_rands()
    _patch_text()
    _patch_polyhedron()
    from openscad_evaluator.cli import main as evaluate

    args = sys.argv[2:]
    status = evaluate(args)
    if status == 0 and "-o" in args:
        with open(args[args.index("-o") + 1] + FACTS_SUFFIX, "w") as f:
            json.dump(FACTS, f)
    return status


if __name__ == "__main__":
    sys.exit(main())
