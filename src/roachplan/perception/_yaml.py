"""The one reader of every YAML file a user gives us: scenes, experiment specs, uploads, camera
calibrations. It lives here, in the package every other one may import, because camera
calibrations are YAML too.

PyYAML's `safe_load` is safe against code, not against size: a "billion laughs" file (aliases of
aliases) is a few hundred bytes that stand for 10^9 values, and anything that walks them (a
validator, an error message's repr) never ends; a document nested 5,000 deep overflows Python's
stack. So this loader refuses, with the line and column, a document nested more than
MAX_YAML_DEPTH levels or of more than MAX_YAML_VALUES values counting each alias as the values it
repeats, and an alias inside its own anchor (a recursive structure).

Numbers are read as a person means them: YAML 1.1 (PyYAML) reads `1e6` and `1.0e6` as text (its
floats need a dot and a signed exponent), `017` as 15 (octal) and `1:30` as 90 (base 60). Here
`1e6`, `1E-3`, `1.0e6`, `.5` and `+5` are numbers, `017` is 17, and `1:30` is text; `0x1F` and
`0o17` keep their prefixes' meaning. Dates stay text. A key given twice in one mapping is refused
(YAML would keep the last one without a word).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import Any

import yaml
from yaml.composer import ComposerError
from yaml.constructor import ConstructorError
from yaml.nodes import MappingNode, ScalarNode, SequenceNode
from yaml.reader import ReaderError

from roachplan._errors import short_repr

MAX_YAML_BYTES = 2_000_000
"""Largest YAML text read as one document [bytes]: a scene or spec is a few kB, and PyYAML's pure
Python parser takes about a second a megabyte."""
MAX_YAML_DEPTH = 64
"""Deepest nesting of lists and mappings accepted (a scene needs 5)."""
MAX_YAML_VALUES = 100_000
"""Most values (scalars, lists and mappings) one document may stand for, each alias counted as
the values it repeats."""

_INT = "tag:yaml.org,2002:int"
_FLOAT = "tag:yaml.org,2002:float"
_TIMESTAMP = "tag:yaml.org,2002:timestamp"
_MERGE = "tag:yaml.org,2002:merge"
_INT_RE = re.compile(r"[-+]?(?:[0-9][0-9_]*|0x[0-9a-fA-F_]+|0o[0-7_]+)\Z")
_FLOAT_RE = re.compile(
    r"[-+]?(?:(?:[0-9][0-9_]*\.[0-9_]*|\.[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)?"
    r"|[0-9][0-9_]*[eE][-+]?[0-9]+"
    r"|\.(?:inf|Inf|INF))\Z"
    r"|\.(?:nan|NaN|NAN)\Z"
)
_DECIMAL_RE = re.compile(r"[-+]?[0-9]+\Z")  # `!!float 5`
_LONGEST_NUMBER = 100
"""Characters of the longest number read [-]: Python refuses int() of more than 4300 digits, and
no setting needs 100."""


class _Loader(yaml.SafeLoader):
    """SafeLoader with person-minded numbers and bounded depth, size and aliases (see above)."""

    def __init__(self, stream: str | bytes) -> None:
        super().__init__(stream)
        self._depth = 0
        self._values: dict[int, int] = {}  # id(node) -> values it stands for, aliases expanded
        self._dup_checked: set[int] = set()  # id(node) of mappings checked for repeated keys

    def compose_document(self) -> Any:
        # Node ids are unique while one document's nodes live, not across documents.
        self._values.clear()
        self._dup_checked.clear()
        return super().compose_document()

    def compose_node(self, parent: Any, index: Any) -> Any:
        mark = self.peek_event().start_mark
        alias = self.check_event(yaml.AliasEvent)
        self._depth += 1
        try:
            if self._depth > MAX_YAML_DEPTH:
                raise ComposerError(
                    None, None, f"nested more than {MAX_YAML_DEPTH} levels deep", mark
                )
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if alias:
            if id(node) not in self._values:
                raise ComposerError(
                    None, None, "an alias inside its own anchor (a recursive structure)", mark
                )
            count = self._values[id(node)]
        else:
            count = 1
            if isinstance(node, SequenceNode):
                count += sum(self._values[id(child)] for child in node.value)
            elif isinstance(node, MappingNode):
                count += sum(self._values[id(k)] + self._values[id(v)] for k, v in node.value)
            self._values[id(node)] = count
        if count > MAX_YAML_VALUES:
            raise ComposerError(
                None,
                None,
                f"more than {MAX_YAML_VALUES} values, counting each alias (*name) as the values "
                f"it repeats",
                mark,
            )
        return node

    def flatten_mapping(self, node: MappingNode) -> None:
        # Checked here, before PyYAML merges `<<: *base` entries into node.value (a merged key
        # may be given again on purpose); a node is flattened first by whichever mapping is
        # constructed first, itself or one merging it.
        if id(node) not in self._dup_checked:
            self._dup_checked.add(id(node))
            seen = set()
            for key_node, _ in node.value:
                if isinstance(key_node, ScalarNode) and key_node.tag != _MERGE:
                    key = self.construct_object(key_node)
                    if key in seen:
                        raise ConstructorError(
                            None,
                            None,
                            f"key {short_repr(key)} is given twice in one mapping (YAML would "
                            f"keep the last without a word)",
                            key_node.start_mark,
                        )
                    seen.add(key)
        super().flatten_mapping(node)

    def construct_person_int(self, node: ScalarNode) -> int:
        text = _number_text(node)
        sign = -1 if text.startswith("-") else 1
        digits = text.lstrip("+-")
        if digits[:2] in ("0x", "0o"):
            return sign * int(digits[2:], 16 if digits[1] == "x" else 8)
        return sign * int(digits, 10)

    def construct_person_float(self, node: ScalarNode) -> float:
        text = _number_text(node).lower()
        if text.lstrip("+-") == ".inf":
            return float("-inf") if text.startswith("-") else float("inf")
        if text == ".nan":
            return float("nan")
        return float(text)


def _number_text(node: ScalarNode) -> str:
    """The scalar's text without `_` separators; ConstructorError if it is no number (an
    explicit `!!int` or `!!float` tag on text) or absurdly long."""
    text = str(node.value).replace("_", "")
    ok = (
        _INT_RE.match(text)
        if node.tag == _INT
        else (_FLOAT_RE.match(text) or _DECIMAL_RE.match(text))
    )
    if len(text) > _LONGEST_NUMBER or not ok or text.lstrip("+-") in ("0x", "0o"):
        raise ConstructorError(
            None,
            None,
            f"{short_repr(node.value)} is not a number of at most {_LONGEST_NUMBER} characters",
            node.start_mark,
        )
    return text


# YAML 1.1's int, float and timestamp resolvers are replaced by the ones above.
_Loader.yaml_implicit_resolvers = {
    first: [(tag, rx) for tag, rx in resolvers if tag not in (_INT, _FLOAT, _TIMESTAMP)]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(_INT, _INT_RE, list("-+0123456789"))
_Loader.add_implicit_resolver(_FLOAT, _FLOAT_RE, list("-+0123456789."))
_Loader.add_constructor(_INT, _Loader.construct_person_int)
_Loader.add_constructor(_FLOAT, _Loader.construct_person_float)
_Loader.add_constructor(_TIMESTAMP, yaml.SafeLoader.construct_yaml_str)


def load_yaml(text: str | bytes, where: str, error: type[Exception] = ValueError) -> Any:
    """The one document in text (a YAML file's content: str, or bytes in UTF-8/16), read as
    described above; `error` naming `where` (a file) and the line when it is not valid YAML,
    too large, too deep, or repeats too much."""
    if len(text) > MAX_YAML_BYTES:
        raise error(
            f"{where}: {len(text)} bytes is too large for a YAML settings file "
            f"(at most {MAX_YAML_BYTES})"
        )
    loader = _checked(lambda: _Loader(text), where, error)  # reads the encoding mark
    try:
        return _checked(loader.get_single_data, where, error)
    finally:
        loader.dispose()


def load_yaml_documents(
    text: str | bytes, where: str, error: type[Exception] = ValueError
) -> Iterator[Any]:
    """Each document in text in turn (a `rostopic echo` dump holds many), each read and bounded
    as load_yaml reads one; only the documents taken are parsed."""
    loader = _checked(lambda: _Loader(text), where, error)
    try:
        while _checked(loader.check_data, where, error):
            yield _checked(loader.get_data, where, error)
    finally:
        loader.dispose()


def _checked(read, where: str, error: type[Exception]) -> Any:
    """read() with every way a hostile text can make PyYAML fail turned into `error`."""
    try:
        return read()
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f", line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = " ".join(str(p) for p in (exc.context, exc.problem) if p)
        raise error(f"{where}{at}: not valid YAML: {_clip(what)}") from None
    except ReaderError as exc:
        what = (
            f"character U+{exc.character:04X} at position {exc.position} is a control character"
            if exc.encoding == "unicode"
            else f"byte 0x{exc.character:02x} at position {exc.position} is not {exc.encoding}"
        )
        raise error(f"{where}: not YAML text: {what}; a YAML file is UTF-8 text") from None
    except (yaml.YAMLError, ValueError, TypeError, OverflowError, RecursionError) as exc:
        # A tag's own constructor (!!binary, !!set, ...) failing in a way PyYAML does not mark.
        raise error(f"{where}: not valid YAML: {_clip(str(exc))}") from None


def _clip(text: str, limit: int = 300) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."
