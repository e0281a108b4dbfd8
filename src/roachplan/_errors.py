"""The one base of every error a user's input can cause.

Each package family has its own error (SceneError, CaptureError, PlanningError, SimError,
ExperimentError, OutputError, the command line's UsageError) and each of them is an InputError:
the command line answers every one the same way (exit status 2, one line naming the file, key,
flag or value and what would be accepted), and a script can catch them all with one `except`.
"""

from __future__ import annotations

import reprlib
from typing import Any


class InputError(ValueError):
    """Something the user gave (a file, a key in it, a flag, a value, an argument) is not
    accepted; the message names it and what would be."""


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxtuple, _SHORT.maxdict = 3, 6, 6, 4
_SHORT.maxstring, _SHORT.maxother, _SHORT.maxlong = 60, 60, 40


def short_repr(value: Any, limit: int = 100) -> str:
    """repr(value), shortened (`...`) to at most `limit` characters however large or deep the
    value: what an error message may echo of a value read from a user's file."""
    text = _SHORT.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
