"""Settings: one validator per setting, run whenever a config is made.

Every config of the project (PlannerConfig, ValidityConfig, SimConfig, DriverConfig,
TurningCurve, UncertaintyConfig, MeshingConfig, CaptureSettings, ChooseConfig, an
ExperimentSpec, a scene's TerrainObject) is a frozen dataclass whose fields declare their
validator beside their docstring, `time_limit: float = setting(20.0, positive("s", 3600))`, and
whose `__post_init__` calls `check_settings(self)`. So no config exists with a value out of
range, however it was made: from a scene or spec file, a command-line flag, the page, a
`dataclasses.replace`, a script. The places values come from only say where they came from:

- a YAML file (`from_mapping`, then SettingError.within): "scene.yaml: planner.time_limit:
  <what is accepted>, got -1.0";
- the command line (app/_flags.py): "--time-limit -1: <what is accepted>";

with the same words for what is accepted, which are the validator's.

Importable without numpy, OMPL, Open3D or trimesh: the command line checks its flags with these
validators before it loads anything.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Callable, Mapping
from typing import Any

from ._errors import InputError, short_repr

MAX_SEED = 2**31 - 2
"""Largest seed accepted: OMPL's generator takes seed % (2^31 - 1) + 1 (planning/_ompl.py), so
seeds 0..MAX_SEED are its seeds 1..2^31 - 1, each a different one."""
MAX_SETTING_INT = 2**31 - 1
"""Largest integer setting (iterations, batch sizes): what a C int holds (PyBullet, OMPL)."""

Check = Callable[[Any], "str | None"]
"""A setting's validator: None when the value is accepted, else what would be (the words that
follow the key or the flag in the message: "must be positive (above 0) [s]"). A text that starts
with "one of " names the choices: the message says "'x' is not one of a, b"."""


class SettingError(InputError):
    """A setting's value is not accepted. key: where it sits in its config ("time_limit",
    "validity.max_slope_deg", "orientation[2]"; "" for the config itself); value: as given;
    expected: what would be accepted (the validator's words); problem: the message after the
    key (expected and the value given, or another account of what is wrong)."""

    def __init__(self, key: str, value: Any, expected: str, problem: str | None = None) -> None:
        self.key, self.value, self.expected = key, value, expected
        self.problem = problem if problem is not None else _problem(value, expected)
        super().__init__(f"{_shown_key(key)}: {self.problem}" if key else self.problem)

    def within(self, prefix: str) -> SettingError:
        """The same error, its key under `prefix` (the block it was read from: "planner",
        "terrain[0].perception")."""
        if not prefix:
            return self
        key = self.key if not self.key else (self.key if self.key[0] == "[" else f".{self.key}")
        return SettingError(f"{prefix}{key}", self.value, self.expected, self.problem)


def _shown_key(key: str) -> str:
    """A key may be a user's own name (an unknown key, a route): shortened like a value."""
    return key if len(key) <= 120 else key[:117] + "..."


def _problem(value: Any, expected: str) -> str:
    shown = short_repr(_as_data(value))
    return (
        f"{shown} is not {expected}"
        if expected.startswith("one of ")
        else f"{expected}, got {shown}"
    )


def _as_data(value: Any) -> Any:
    """A config's tuples as the lists a file writes them."""
    return [_as_data(v) for v in value] if isinstance(value, tuple) else value


def accepted(expected: str) -> str:
    """`expected` as it reads after a flag and its value (`--method x: expected one of ...`)."""
    return f"expected {expected}" if expected.startswith("one of ") else expected


# -- validators ---------------------------------------------------------------------------------


def _unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""


def is_number(value: Any) -> bool:
    """An int or float (not a bool, which Python counts as an int)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def finite(unit: str = "") -> Check:
    """Any finite number."""
    expected = f"expected a finite number{_unit(unit)}"
    return lambda v: None if is_number(v) and math.isfinite(v) else expected


def positive(unit: str = "", at_most: float | None = None) -> Check:
    """A number above 0 (and at most `at_most`)."""
    if at_most is None:
        expected = f"must be positive (above 0){_unit(unit)}"
        return lambda v: None if is_number(v) and 0 < v < math.inf else expected
    bounded = f"expected a number above 0 and at most {at_most:g}{_unit(unit)}"

    def check(v: Any) -> str | None:
        if is_number(v) and 0 < v <= at_most:
            return None
        return f"{bounded} (it is not positive)" if is_number(v) and v <= 0 else bounded

    return check


def non_negative(unit: str = "") -> Check:
    """A number of 0 or more (0: that part off)."""
    expected = f"expected a finite number of 0 or more{_unit(unit)}"
    return lambda v: None if is_number(v) and 0 <= v < math.inf else expected


def between(lo: float, hi: float, unit: str = "", *, high_included: bool = True) -> Check:
    """A number from lo to hi (hi itself only if high_included)."""
    upper = f"{hi:g}" if high_included else f"below {hi:g}"
    expected = f"expected a number from {lo:g} to {upper}{_unit(unit)}"

    def check(v: Any) -> str | None:
        if not is_number(v):
            return f"expected a finite number{_unit(unit)}"
        inside = lo <= v <= hi if high_included else lo <= v < hi
        return None if inside else expected

    return check


def integer(lo: int, hi: int | None = MAX_SETTING_INT, *, noun: str = "an integer") -> Check:
    """A whole number from lo to hi (hi None: no upper end)."""
    expected = f"expected {noun} " + (f"from {lo} to {hi}" if hi is not None else f"{lo} or more")

    def check(v: Any) -> str | None:
        whole = isinstance(v, int) and not isinstance(v, bool)
        return None if whole and lo <= v and (hi is None or v <= hi) else expected

    return check


def seed() -> Check:
    """A seed: what OMPL's generator takes (and so every other generator of ours)."""
    expected = f"expected a non-negative integer from 0 to {MAX_SEED} (what OMPL's generator takes)"

    def check(v: Any) -> str | None:
        whole = isinstance(v, int) and not isinstance(v, bool)
        return None if whole and 0 <= v <= MAX_SEED else expected

    return check


def one_of(options: tuple[str, ...] | list[str]) -> Check:
    """One of the named choices."""
    expected = f"one of {', '.join(map(str, options))}"
    return lambda v: None if isinstance(v, str) and v in options else expected


def boolean() -> Check:
    return lambda v: None if isinstance(v, bool) else "expected true or false"


def optional(check: Check) -> Check:
    """check, or None (what None means is the setting's docstring's to say)."""
    return lambda v: None if v is None else check(v)


def numbers(n: int, what: str, element: Callable[[float], bool] = math.isfinite) -> Check:
    """n numbers, each passing `element` (default: finite), as a tuple or list; `what` says what
    they are ("x, y, z [m]")."""
    expected = f"expected {n} finite numbers {what}"

    def check(v: Any) -> str | None:
        ok = (
            isinstance(v, tuple | list)
            and len(v) == n
            and all(is_number(x) and math.isfinite(x) and element(x) for x in v)
        )
        return None if ok else expected

    return check


# -- declaring, checking and reading settings ------------------------------------------------------


def setting(default: Any = dataclasses.MISSING, check: Check | None = None, **field_args) -> Any:
    """A config's field with its validator: dataclasses.field(default, ...) that
    check_settings runs on every config made."""
    return dataclasses.field(default=default, metadata={"check": check}, **field_args)


def check_settings(config: Any) -> None:
    """SettingError for the first field of `config` whose validator refuses its value (a
    config's `__post_init__` calls this; nested configs checked themselves when made)."""
    for f in dataclasses.fields(config):
        check = f.metadata.get("check")
        if check is None:
            continue
        value = getattr(config, f.name)
        expected = check(value)
        if expected is not None:
            raise SettingError(f.name, value, expected)


def validator(cls: type, name: str) -> Check:
    """The validator of field `name` of config class cls."""
    for f in dataclasses.fields(cls):
        if f.name == name and f.metadata.get("check") is not None:
            return f.metadata["check"]
    raise KeyError(f"{cls.__name__}.{name} has no validator")


def setting_problem(cls: type, name: str, value: Any) -> str | None:
    """What config class cls accepts for setting `name` when it refuses `value`, else None: a
    flag or a page's box checked before anything is made of it."""
    return validator(cls, name)(value)


def check_value(cls: type, name: str, value: Any) -> None:
    """SettingError(name, value, ...) unless cls accepts value for setting `name`."""
    expected = setting_problem(cls, name, value)
    if expected is not None:
        raise SettingError(name, value, expected)


def from_mapping(cls: type, data: Any, *, base: Any = None) -> Any:
    """A config of class cls from plain data (a YAML block, a manifest's JSON): the fields it
    names over `base`'s (default: cls's defaults), nested configs merged field by field,
    numbers as written (an int where a float goes, a whole float where an int goes: `1e5`),
    lists as tuples. SettingError (key within the mapping) for a key cls has no field of, a
    mapping that is not one, or a value its validator refuses."""
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    if not isinstance(data, Mapping):
        raise SettingError("", data, f"expected a mapping with keys {', '.join(fields)}")
    for k in data:
        if k not in fields:
            name = k if isinstance(k, str) else short_repr(k)
            raise SettingError(
                name, data[k], "", f"unknown key; accepted keys: {', '.join(fields)}"
            )
    hints = typing.get_type_hints(cls)
    values = {}
    for k, v in data.items():
        hint = hints[k]
        if dataclasses.is_dataclass(hint) and isinstance(hint, type):
            try:
                values[k] = from_mapping(hint, v, base=getattr(base, k, None))
            except SettingError as exc:
                raise exc.within(k) from None
        else:
            values[k] = as_written(hint, v)
    if base is not None:
        return dataclasses.replace(base, **values)
    return cls(**values)


def as_written(hint: Any, value: Any) -> Any:
    """value as the field of type `hint` holds it, where plain data writes it otherwise (lists
    for tuples, 20 for 20.0, 1e5 for 100000); anything else unchanged, for the validator."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, type(int | None)):
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is not None and len(members) == 1:
            value = as_written(members[0], value)
    elif origin is tuple and isinstance(value, list | tuple):
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            args = (args[0],) * len(value)
        same = len(args) == len(value)
        value = (
            tuple(as_written(a, v) for a, v in zip(args, value, strict=True))
            if same
            else tuple(value)
        )
    elif hint is float and is_number(value):
        value = float(value)
    elif hint is int and isinstance(value, float) and value.is_integer():
        value = int(value)
    return value
