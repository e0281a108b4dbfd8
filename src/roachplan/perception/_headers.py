"""Capture file headers (PCD, PLY, netpbm, PNG), parsed from a file's first bytes and checked
against the file's real size before anything is allocated: a small file can claim any size in
its header (issue 15). Pure functions: bytes in, a frozen header out; anything else raises a
CaptureError that names the file, the field and value, and what is accepted."""

from __future__ import annotations

import dataclasses
import math
import struct
from dataclasses import dataclass
from typing import Literal, cast

from ._errors import CaptureError

MAX_CLOUD_POINTS = 100_000_000
"""Largest point cloud read [points]: as (N, 3) float64 that is 2.4 GB. A header claiming more
is damaged, or crafted to fill the memory."""
MAX_DEPTH_PIXELS = 100_000_000
"""Largest depth image read [pixels], checked on the header before decoding: a small file can
claim (PNG's compression, a netpbm header that lies) an image that would fill the memory."""
HEAD_BYTES = 65_536
"""How much of a file a header may take [bytes]; callers pass this much of the file (or all of
a shorter one) as `head`."""
LZF_MAX_RATIO = 88
"""liblzf's largest expansion: a 3-byte back reference copies at most 264 bytes, so a block
that claims more than 88 times its compressed size cannot be LZF."""


def _show(token: bytes | str, n: int = 24) -> str:
    """A value from a file, bounded, for a message."""
    text = token.decode("latin-1") if isinstance(token, bytes) else token
    return repr(text[:n] + ("..." if len(text) > n else ""))


def _uint(source: str, what: str, token: str) -> int:
    """A whole number >= 0 written in decimal (at most 12 digits: no header needs more)."""
    if not (token.isascii() and token.isdigit() and len(token) <= 12):
        raise CaptureError(f"{source}: {what} {_show(token)}: expected a whole number >= 0")
    return int(token)


def _header_lines(head: bytes, end: bytes, source: str, kind: str) -> tuple[list[str], int]:
    """The text lines of a header that ends with the line `end`, and the offset after it."""
    stop = head.find(b"\n" + end)
    if stop < 0:
        raise CaptureError(
            f"{source}: the {kind} header has no {end.decode()!r} line within its first "
            f"{min(len(head), HEAD_BYTES)} bytes: the file is truncated or not a {kind} file"
        )
    eol = head.find(b"\n", stop + 1)
    if eol < 0:  # the end line is the file's last, without a newline: no data follows it
        eol = len(head) - 1
    raw = head[: eol + 1]
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise CaptureError(
            f"{source}: the {kind} header has a non-text byte on line {line}; a {kind} header "
            f"is ASCII text"
        ) from None
    return text.splitlines(), eol + 1


# -- PCD ------------------------------------------------------------------------------------

PcdEncoding = Literal["ascii", "binary", "binary_compressed"]
PCD_KEYS = (
    "VERSION",
    "FIELDS",
    "SIZE",
    "TYPE",
    "COUNT",
    "WIDTH",
    "HEIGHT",
    "VIEWPOINT",
    "POINTS",
    "DATA",
)
PCD_TYPES: dict[Literal["F", "I", "U"], tuple[int, ...]] = {
    "F": (4, 8),
    "I": (1, 2, 4, 8),
    "U": (1, 2, 4, 8),
}
"""TYPE letter -> the SIZEs PCL writes for it [bytes]."""


@dataclass(frozen=True, kw_only=True)
class PcdField:
    name: str
    size: int
    """Bytes per value."""
    type: Literal["F", "I", "U"]
    count: int
    """Values per point."""

    @property
    def dtype(self) -> str:
        """The numpy dtype of one value, little-endian (PCL writes its host's order, x86)."""
        return "<" + {"F": "f", "I": "i", "U": "u"}[self.type] + str(self.size)


@dataclass(frozen=True, kw_only=True)
class PcdHeader:
    """A PCL .pcd header, checked against the file's size."""

    fields: tuple[PcdField, ...]
    width: int
    height: int
    points: int
    """width * height."""
    viewpoint: tuple[float, ...]
    """tx ty tz qw qx qy qz: the sensor's pose in the points' frame [m]."""
    data: PcdEncoding
    data_offset: int
    """Where the data starts [bytes from the file's start]."""
    compressed_size: int = 0
    """binary_compressed: bytes of LZF data after the 8-byte sizes [bytes]."""

    @property
    def point_step(self) -> int:
        """Bytes per point in binary data."""
        return sum(f.size * f.count for f in self.fields)

    @property
    def values_per_point(self) -> int:
        return sum(f.count for f in self.fields)

    def field(self, name: str) -> PcdField:
        return next(f for f in self.fields if f.name == name)

    def byte_offset(self, name: str) -> int:
        """Offset of a field within a binary point [bytes]; in binary_compressed data, its
        block (all points' values of one field) starts at points times this."""
        i = [f.name for f in self.fields].index(name)
        return sum(f.size * f.count for f in self.fields[:i])

    def column(self, name: str) -> int:
        """Index of a field's first value within an ascii row."""
        i = [f.name for f in self.fields].index(name)
        return sum(f.count for f in self.fields[:i])


def parse_pcd_header(head: bytes, file_size: int, source: str) -> PcdHeader:
    """A .pcd file's first min(file_size, HEAD_BYTES) bytes -> its header, checked: FIELDS,
    SIZE, TYPE and COUNT agree; POINTS is WIDTH x HEIGHT and at most MAX_CLOUD_POINTS; x, y, z
    are present; and the data the header describes fits in the file (ascii: at least a digit
    and a separator per value; binary: POINTS x the point's bytes; binary_compressed: its LZF
    block, whose decoded size must be exactly that)."""
    first = next((ln.split() for ln in head[:4096].splitlines() if ln.strip()), [b""])[0]
    if not (first.startswith(b"#") or first.upper() in (b"VERSION", b"FIELDS")):
        raise CaptureError(f"{source}: not a PCD file (no PCD header; starts with {head[:16]!r})")
    lines, offset = _header_lines(head[:HEAD_BYTES], b"DATA", source, "PCD")
    values = _pcd_keywords(lines, source)
    fields = _pcd_fields(values, source)
    width, height = _pcd_size(values, source)
    viewpoint = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    if "VIEWPOINT" in values:
        try:
            viewpoint = tuple(float(v) for v in values["VIEWPOINT"])
        except ValueError:
            viewpoint = ()
        if len(viewpoint) != 7 or not all(map(math.isfinite, viewpoint)):
            raise CaptureError(
                f"{source}: PCD VIEWPOINT {_show(' '.join(values['VIEWPOINT']), 60)}: expected 7 "
                f"finite numbers, tx ty tz qw qx qy qz"
            )
    data = values["DATA"][0].lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise CaptureError(
            f"{source}: PCD DATA {_show(values['DATA'][0])}; accepted: ascii, binary, "
            f"binary_compressed"
        )
    header = PcdHeader(
        fields=fields,
        width=width,
        height=height,
        points=width * height,
        viewpoint=viewpoint,
        data=data,
        data_offset=offset,
    )
    return _check_pcd_size(header, head, file_size, source)


def _pcd_keywords(lines: list[str], source: str) -> dict[str, list[str]]:
    """Header lines -> {KEYWORD: its words}; every keyword known, none twice, the needed ones
    there."""
    values: dict[str, list[str]] = {}
    for n, line in enumerate(lines, 1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        key = words[0].upper()
        if key not in PCD_KEYS:
            raise CaptureError(
                f"{source}: PCD header line {n}: unknown keyword {_show(words[0])}; accepted: "
                f"{', '.join(PCD_KEYS)}"
            )
        if key in values:
            raise CaptureError(f"{source}: PCD header line {n}: {key} is given twice")
        values[key] = words[1:]
    for key in ("FIELDS", "SIZE", "TYPE", "WIDTH", "DATA"):
        if not values.get(key):
            raise CaptureError(f"{source}: the PCD header has no {key} line (or it is empty)")
    return values


def _pcd_fields(values: dict[str, list[str]], source: str) -> tuple[PcdField, ...]:
    """FIELDS with their SIZE, TYPE and COUNT, checked against each other; x, y, z present."""
    names = values["FIELDS"]
    n = len(names)
    counts = values.get("COUNT") or ["1"] * n  # PCD 0.6 has no COUNT: one value per field
    for key, given in (("SIZE", values["SIZE"]), ("TYPE", values["TYPE"]), ("COUNT", counts)):
        if len(given) != n:
            raise CaptureError(
                f"{source}: the PCD header's {key} has {len(given)} "
                f"entr{'y' if len(given) == 1 else 'ies'} but FIELDS names "
                f"{n} ({' '.join(names)[:80]}): each field needs one SIZE, TYPE and COUNT"
            )
    fields = []
    for name, size_s, type_s, count_s in zip(
        names, values["SIZE"], values["TYPE"], counts, strict=True
    ):
        size = _uint(source, f"SIZE of {name}", size_s)
        count = _uint(source, f"COUNT of {name}", count_s)
        kind = type_s.upper()
        if kind not in PCD_TYPES or size not in PCD_TYPES[kind]:
            raise CaptureError(
                f"{source}: PCD field {_show(name)}: TYPE {_show(type_s)} with SIZE {size} is not "
                f"a PCD type; accepted: F 4|8 (float), I 1|2|4|8 (signed), U 1|2|4|8 (unsigned)"
            )
        if count < 1:
            raise CaptureError(f"{source}: PCD field {_show(name)}: COUNT {count}; expected >= 1")
        fields.append(PcdField(name=name, size=size, type=kind, count=count))
    taken = [f.name for f in fields if f.name != "_"]  # PCL names padding "_", maybe repeatedly
    if len(set(taken)) != len(taken):
        raise CaptureError(
            f"{source}: the PCD header names a field twice: FIELDS {' '.join(names)[:80]}"
        )
    if not {"x", "y", "z"} <= set(taken):
        raise CaptureError(f"{source}: the PCD has fields {tuple(names)[:12]}; it needs x, y and z")
    if any(f.count != 1 for f in fields if f.name in ("x", "y", "z")):
        raise CaptureError(
            f"{source}: a PCD field x, y or z has COUNT > 1; they hold one value each"
        )
    return tuple(fields)


def _pcd_size(values: dict[str, list[str]], source: str) -> tuple[int, int]:
    """(WIDTH, HEIGHT), which POINTS (if given) must agree with, of 1 to MAX_CLOUD_POINTS
    points."""
    width = _uint(source, "PCD WIDTH", values["WIDTH"][0])
    height = _uint(source, "PCD HEIGHT", values["HEIGHT"][0]) if values.get("HEIGHT") else 1
    points = width * height
    if values.get("POINTS"):
        claimed = _uint(source, "PCD POINTS", values["POINTS"][0])
        if claimed != points:
            raise CaptureError(
                f"{source}: the PCD header says POINTS {claimed} but WIDTH x HEIGHT is "
                f"{width} x {height} = {points}; they must agree"
            )
    if points > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"{source}: the PCD header says {points} points (WIDTH {width} x HEIGHT {height}); "
            f"clouds of at most {MAX_CLOUD_POINTS // 1_000_000} million points are read (a "
            f"larger one is damaged, or crafted to fill the memory)"
        )
    if points == 0:
        raise CaptureError(
            f"{source}: the PCD header says 0 points (WIDTH {width}, HEIGHT {height}): no "
            f"points to read"
        )
    return width, height


def _check_pcd_size(h: PcdHeader, head: bytes, file_size: int, source: str) -> PcdHeader:
    available = max(file_size - h.data_offset, 0)
    says = f"the PCD header says {h.points} points of {h.point_step} bytes"
    wrong = "the file is truncated or its header (WIDTH, HEIGHT, SIZE, COUNT) is wrong"
    if h.data == "binary":
        need = h.points * h.point_step
        if available < need:
            raise CaptureError(
                f"{source}: {says} ({need} bytes of binary data), but {available} bytes follow "
                f"the header: {wrong}"
            )
        return h
    if h.data == "ascii":
        need = 2 * h.points * h.values_per_point - 1  # a digit and a separator per value
        if available < need:
            raise CaptureError(
                f"{source}: the PCD header says {h.points} points of {h.values_per_point} values, "
                f"which need {need} bytes or more of ascii data, but {available} bytes follow the "
                f"header: {wrong}"
            )
        return h
    sizes = head[h.data_offset : h.data_offset + 8]
    if len(sizes) < 8 or available < 8:
        raise CaptureError(
            f"{source}: binary_compressed PCD data starts with its compressed and uncompressed "
            f"sizes (8 bytes), but {min(available, len(sizes))} bytes follow the header: {wrong}"
        )
    compressed, uncompressed = struct.unpack("<II", sizes)
    need = h.points * h.point_step
    if uncompressed != need:
        raise CaptureError(
            f"{source}: {says} ({need} bytes), but its compressed block says it decodes to "
            f"{uncompressed} bytes: the header or the data is damaged"
        )
    if compressed > available - 8:
        raise CaptureError(
            f"{source}: the compressed block is {compressed} bytes, but {available - 8} follow "
            f"its sizes: the file is truncated"
        )
    if uncompressed > LZF_MAX_RATIO * compressed:
        raise CaptureError(
            f"{source}: {compressed} bytes of LZF data cannot decode to {uncompressed} bytes "
            f"(at most {LZF_MAX_RATIO} times as many): the header or the data is damaged"
        )
    return dataclasses.replace(h, compressed_size=compressed)


# -- PLY ------------------------------------------------------------------------------------

PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
"""PLY property type -> numpy kind and size (without byte order)."""
PlyFormat = Literal["ascii", "binary_little_endian", "binary_big_endian"]


@dataclass(frozen=True, kw_only=True)
class PlyProperty:
    name: str
    type: str
    """numpy kind and size, e.g. "f4" (PLY_TYPES); a list's item type."""
    list_count: str | None = None
    """A list property's count type ("u1" ...), None for a scalar."""


@dataclass(frozen=True, kw_only=True)
class PlyElement:
    name: str
    count: int
    properties: tuple[PlyProperty, ...]

    @property
    def fixed(self) -> bool:
        """Every entry has the same size (no list properties)."""
        return all(p.list_count is None for p in self.properties)

    @property
    def min_bytes(self) -> int:
        """Bytes of one binary entry at least (lists empty)."""
        return sum(int((p.list_count or p.type)[1]) for p in self.properties)


@dataclass(frozen=True, kw_only=True)
class PlyHeader:
    """A .ply header, checked against the file's size."""

    format: PlyFormat
    elements: tuple[PlyElement, ...]
    data_offset: int
    """Where the data starts [bytes from the file's start]."""

    @property
    def vertex(self) -> PlyElement:
        return next(e for e in self.elements if e.name == "vertex")

    @property
    def endian(self) -> str:
        return ">" if self.format == "binary_big_endian" else "<"


def parse_ply_header(head: bytes, file_size: int, source: str) -> PlyHeader:
    """A .ply file's first min(file_size, HEAD_BYTES) bytes -> its header, checked: one format
    line (ascii or binary, version 1.0), elements with whole-number counts and at least one
    property each, properties of PLY's types, a vertex element with scalar x, y, z and at most
    MAX_CLOUD_POINTS entries, and data that fits in the file (every entry at its smallest)."""
    if not (head.startswith(b"ply\n") or head.startswith(b"ply\r\n")):
        raise CaptureError(f"{source}: not a PLY file (it starts with {head[:16]!r})")
    lines, offset = _header_lines(head[:HEAD_BYTES], b"end_header", source, "PLY")
    if lines[-1].strip() != "end_header":
        raise CaptureError(
            f"{source}: PLY header line {len(lines)}: expected end_header, got "
            f"{_show(lines[-1], 40)}"
        )
    fmt, elements = _ply_lines(lines[1:-1], source)
    header = PlyHeader(
        format=fmt,
        data_offset=offset,
        elements=_ply_elements(elements, source),
    )
    available = max(file_size - offset, 0)
    if fmt == "ascii":  # a digit and a separator per value, a list at least its count
        need = sum(2 * e.count * len(e.properties) for e in header.elements) - 1
    else:
        need = sum(e.count * e.min_bytes for e in header.elements)
    if available < need:
        counts = ", ".join(f"{e.count} {e.name}" for e in header.elements)[:120]
        raise CaptureError(
            f"{source}: the PLY header says {counts}, which need {need} bytes or more of "
            f"{fmt} data, but {available} bytes follow the header: the file is truncated or its "
            f"header is wrong"
        )
    return header


def _ply_lines(lines: list[str], source: str) -> tuple[PlyFormat, list]:
    """The header's lines between `ply` and `end_header` -> (format, [(element name, count,
    [properties])])."""
    fmt: PlyFormat | None = None
    elements: list[tuple[str, int, list[PlyProperty]]] = []
    for n, line in enumerate(lines, 2):
        words = line.split()
        where = f"{source}: PLY header line {n}"
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if fmt is not None or elements:
                raise CaptureError(f"{where}: a second format line, or one after an element")
            fmt = _ply_format(words, where)
        elif words[0] == "element":
            if len(words) != 3:
                raise CaptureError(f"{where}: expected 'element NAME COUNT', got {_show(line, 60)}")
            count = _uint(source, f"PLY element {_show(words[1])} count", words[2])
            elements.append((words[1], count, []))
        elif words[0] == "property":
            if not elements:
                raise CaptureError(f"{where}: a property before any element")
            prop = _ply_property(words, where)
            if any(p.name == prop.name for p in elements[-1][2]):
                raise CaptureError(f"{where}: property {_show(prop.name)} is given twice")
            elements[-1][2].append(prop)
        else:
            raise CaptureError(
                f"{where}: unknown keyword {_show(words[0])}; accepted: format, element, "
                f"property, comment, obj_info, end_header"
            )
    if fmt is None:
        raise CaptureError(f"{source}: the PLY header has no format line")
    return fmt, elements


def _ply_format(words: list[str], where: str) -> PlyFormat:
    if (
        len(words) != 3
        or words[2] != "1.0"
        or words[1] not in ("ascii", "binary_little_endian", "binary_big_endian")
    ):
        raise CaptureError(
            f"{where}: format {_show(' '.join(words[1:]), 40)}; accepted: ascii, "
            f"binary_little_endian or binary_big_endian, version 1.0"
        )
    return cast(PlyFormat, words[1])  # (one of its values: checked above)


def _ply_property(words: list[str], where: str) -> PlyProperty:
    """`property TYPE NAME` or `property list COUNT_TYPE TYPE NAME`."""
    if len(words) == 5 and words[1] == "list":
        count_t, item_t, name = words[2], words[3], words[4]
    elif len(words) == 3:
        count_t, item_t, name = None, words[1], words[2]
    else:
        raise CaptureError(
            f"{where}: expected 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME', "
            f"got {_show(' '.join(words), 60)}"
        )
    for t in (count_t, item_t):
        if t is not None and t not in PLY_TYPES:
            raise CaptureError(
                f"{where}: property type {_show(t)}; accepted: {', '.join(PLY_TYPES)}"
            )
    if count_t is not None and PLY_TYPES[count_t][0] == "f":
        raise CaptureError(f"{where}: a list's count type must be an integer type, not {count_t}")
    return PlyProperty(
        name=name, type=PLY_TYPES[item_t], list_count=PLY_TYPES[count_t] if count_t else None
    )


def _ply_elements(
    elements: list[tuple[str, int, list[PlyProperty]]], source: str
) -> tuple[PlyElement, ...]:
    """The elements, checked: named once, each with a property, a vertex element of scalar x,
    y, z with 1 to MAX_CLOUD_POINTS entries."""
    if len({name for name, _, _ in elements}) != len(elements):
        raise CaptureError(f"{source}: the PLY header names an element twice")
    empty = next((name for name, _, props in elements if not props), None)
    if empty is not None:  # its entries would take no bytes: any count would fit any file
        raise CaptureError(f"{source}: the PLY element {_show(empty)} has no properties")
    els = tuple(
        PlyElement(name=name, count=count, properties=tuple(props))
        for name, count, props in elements
    )
    vertex = next((e for e in els if e.name == "vertex"), None)
    if vertex is None:
        raise CaptureError(
            f"{source}: the PLY has no vertex element (elements: "
            f"{', '.join(e.name for e in els)[:80] or 'none'}); a point cloud's points are its "
            f"vertices"
        )
    if not {"x", "y", "z"} <= {p.name for p in vertex.properties if p.list_count is None}:
        raise CaptureError(
            f"{source}: the PLY's vertices have properties "
            f"{', '.join(p.name for p in vertex.properties)[:80] or 'none'}; they need x, y and z"
        )
    if vertex.count > MAX_CLOUD_POINTS:
        raise CaptureError(
            f"{source}: the PLY header says {vertex.count} vertices; clouds of at most "
            f"{MAX_CLOUD_POINTS // 1_000_000} million points are read (a larger one is damaged, "
            f"or crafted to fill the memory)"
        )
    if vertex.count == 0:
        raise CaptureError(f"{source}: the PLY header says 0 vertices: no points to read")
    return els


# -- netpbm and PNG -------------------------------------------------------------------------

NETPBM = {b"P2": (1, False), b"P5": (1, True), b"P3": (3, False), b"P6": (3, True)}
"""Magic -> (channels, binary)."""


@dataclass(frozen=True, kw_only=True)
class NetpbmHeader:
    channels: int
    binary: bool
    width: int
    height: int
    maxval: int
    data_offset: int
    """Where the samples start [bytes from the file's start]."""

    @property
    def samples(self) -> int:
        return self.width * self.height * self.channels


def check_pixels(source: str, width: int, height: int) -> None:
    """A depth image's size from its header: at least 1x1, at most MAX_DEPTH_PIXELS."""
    if width * height > MAX_DEPTH_PIXELS:
        raise CaptureError(
            f"{source}: the header says {width}x{height} pixels ({width * height / 1e6:.0f} "
            f"megapixels); depth images of at most {MAX_DEPTH_PIXELS / 1e6:.0f} megapixels are "
            f"read (a larger one is damaged, or crafted to fill the memory)"
        )
    if min(width, height) < 1:
        raise CaptureError(f"{source}: the header says {width}x{height} pixels: an empty image")


def parse_netpbm_header(head: bytes, file_size: int, source: str) -> NetpbmHeader:
    """A netpbm file's first bytes (4096 are plenty) -> its header, checked: a PGM (P5 binary,
    P2 ASCII) or PPM (P6, P3) of 16 bits per sample (maxval > 255) within MAX_DEPTH_PIXELS
    whose samples fit in the file (binary: 2 bytes each; ASCII: a digit and a separator)."""
    if head[:2] not in NETPBM:
        raise CaptureError(
            f"{source}: not a netpbm image (it starts with {head[:16]!r}; accepted: P5/P2 "
            f"greymaps and P6/P3 pixmaps)"
        )
    channels, binary = NETPBM[head[:2]]
    numbers, pos = [], 2
    while len(numbers) < 3:  # width, height, maxval, between whitespace and # comments
        while pos < len(head) and (head[pos : pos + 1].isspace() or head[pos] == ord("#")):
            if head[pos] == ord("#"):
                end = head.find(b"\n", pos)
                pos = len(head) if end < 0 else end + 1
            else:
                pos += 1
        start = pos
        while pos < len(head) and head[pos : pos + 1].isdigit() and pos - start < 10:
            pos += 1
        if pos >= len(head):
            raise CaptureError(
                f"{source}: bad netpbm header: it ends (or its comments run past "
                f"{len(head)} bytes) before width, height and maxval are all given"
            )
        if pos == start or not head[pos : pos + 1].isspace():
            raise CaptureError(
                f"{source}: bad netpbm header: expected width, height and maxval (decimal "
                f"numbers between whitespace) after {head[:2].decode()}, found "
                f"{head[start : start + 16]!r}"
            )
        numbers.append(int(head[start:pos]))
    width, height, maxval = numbers
    pos += 1  # the single whitespace character that ends the header
    if min(width, height) < 1 or not 1 <= maxval <= 65535:
        raise CaptureError(
            f"{source}: bad netpbm header: width {width}, height {height}, maxval {maxval} "
            f"(expected width, height >= 1 and maxval 1-65535)"
        )
    if maxval <= 255:
        raise CaptureError(
            f"{source}: an 8-bit netpbm image (maxval {maxval}) has no depth in it; a depth "
            f"image has maxval > 255 (16 bits per sample)"
        )
    check_pixels(source, width, height)
    h = NetpbmHeader(
        channels=channels, binary=binary, width=width, height=height, maxval=maxval, data_offset=pos
    )
    available = file_size - pos
    # binary: 2 bytes per sample; ASCII: at least a digit and a separator per sample
    needed = 2 * h.samples if binary else 2 * h.samples - 1
    if available < needed:
        raise CaptureError(
            f"{source}: the netpbm header says {width}x{height}x{channels} 16-bit samples, "
            f"which need {needed} bytes{'' if binary else ' or more'}, but {max(available, 0)} "
            f"follow the header: the file is truncated or its header is wrong"
        )
    return h


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_COLOURS = {0: "greyscale", 2: "RGB", 3: "palette", 4: "greyscale+alpha", 6: "RGBA"}


@dataclass(frozen=True, kw_only=True)
class PngHeader:
    width: int
    height: int
    bit_depth: int
    colour_type: int


def parse_png_header(head: bytes, source: str) -> PngHeader:
    """A PNG's first 26 bytes or more -> its IHDR chunk (always the first), checked: a 16-bit
    greyscale image (the only PNG that holds depth) within MAX_DEPTH_PIXELS."""
    if not head.startswith(PNG_SIGNATURE):
        raise CaptureError(f"{source}: not a PNG file (it starts with {head[:16]!r})")
    if len(head) < 26 or head[12:16] != b"IHDR" or head[8:12] != struct.pack(">I", 13):
        raise CaptureError(f"{source}: a damaged PNG (its first chunk is not a 13-byte IHDR)")
    width, height, depth, colour = struct.unpack(">IIBB", head[16:26])
    check_pixels(source, width, height)
    if (depth, colour) != (16, 0):
        kind = _PNG_COLOURS.get(colour, f"colour type {colour}")
        raise CaptureError(
            f"{source}: a depth PNG must be 16-bit greyscale (mode I;16), this one is "
            f"{depth}-bit {kind} - an 8-bit or colour image has no depth in it"
        )
    return PngHeader(width=width, height=height, bit_depth=depth, colour_type=colour)
