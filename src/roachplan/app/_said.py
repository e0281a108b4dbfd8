"""What the page says when something fails, and how much of it a notification can show.

An error written for the user (an InputError: SceneError, PlanningError, CaptureError, ...; a
child process's ChildError; an OSError's own words) is said as it is. Any other exception is a
fault of the app: its text ("index 0 is out of bounds for axis 0 with size 0") means nothing to
the user, so the page says that an internal error happened, and of what kind, and the server's
log gets the traceback.
"""

from __future__ import annotations

import re
import sys
import traceback

from roachplan import InputError
from roachplan.processes import ChildError

INTERNAL = "an internal error ({kind}); the server log has the details"
"""What the page says of an exception that is not written for the user."""
INTERNAL_LEAD = INTERNAL.split(" (", maxsplit=1)[0]
"""How such a message starts."""


def is_for_the_user(exc: BaseException) -> bool:
    """Whether an exception's text is a sentence for the user (what went wrong with what they
    gave, or what stopped a process and what to change), not a fault of the app."""
    return isinstance(exc, InputError | ChildError | OSError | MemoryError)


def error_text(exc: BaseException) -> str:
    """The page's words for an exception: its own text when it is written for the user (an
    OSError by its reason, without its errno), else INTERNAL naming its class."""
    if isinstance(exc, MemoryError):
        return "the server ran out of memory"
    if isinstance(exc, OSError) and not isinstance(exc, ChildError) and exc.strerror:
        return exc.strerror[0].lower() + exc.strerror[1:]
    if is_for_the_user(exc) and str(exc):
        return str(exc)
    return INTERNAL.format(kind=type(exc).__name__)


def raised_text(error: BaseException | None, message: str, trace: str) -> str:
    """The page's words for an exception raised in a child process (processes.Raised: the
    exception when it survived pickling, its text, its traceback), as error_text; one that did
    not survive pickling is known by the class its traceback's last line names."""
    if error is not None:
        return error_text(error)
    last = trace.strip().splitlines()[-1] if trace.strip() else ""
    kind = re.match(r"^([\w.]+)(?::|$)", last)
    name = kind.group(1).rsplit(".", 1)[-1] if kind else "unknown"
    if message and name in _user_error_names():
        return message
    return INTERNAL.format(kind=name)


def _user_error_names() -> set[str]:
    """The class names of every exception is_for_the_user accepts (as loaded now)."""
    names, todo = set(), [InputError, ChildError, OSError, MemoryError]
    while todo:
        cls = todo.pop()
        if cls.__name__ not in names:
            names.add(cls.__name__)
            todo.extend(cls.__subclasses__())
    return names


def log_internal(exc: BaseException | None, trace: str = "", *, where: str) -> None:
    """Print an internal error's traceback to the server's log (its stderr), saying where it
    happened (the command, the child's task)."""
    text = trace or (
        "".join(traceback.format_exception(exc)) if exc is not None else "(no traceback)"
    )
    print(f"roachplan: internal error in {where}:\n{text.rstrip()}", file=sys.stderr, flush=True)


NOTE_WIDTH = 26
"""Characters a line of a notification holds (viser's notifications are 20em wide; measured in
headless Chromium: 23 to 30 characters of its 14 px text a line)."""
NOTE_LINES = 7
"""Lines of text a notification shows, its title's included: viser cuts a notification at
200 px (its text centred, so a longer one loses its first and last lines, title included),
and a line is 19 px."""
NOTE_MORE = " (the whole message is at the top of the panel)"
"""What a cut notification ends with: the status line holds all of it."""


def note_lines(text: str, width: int = NOTE_WIDTH) -> int:
    """Lines text wraps to at width characters a line (by words, each paragraph anew; a word
    longer than a line breaks anywhere)."""
    lines = 0
    for paragraph in text.split("\n"):
        n, line = 1, 0
        for word in paragraph.split():
            if line and line + 1 + len(word) > width:
                n, line = n + 1, 0
            line += (1 if line else 0) + len(word)
            while line > width:
                n, line = n + 1, line - width
        lines += n
    return lines


def fits_a_note(title: str, body: str) -> bool:
    """Whether a notification of this title and body shows whole (NOTE_LINES)."""
    return note_lines(title) + (note_lines(body) if body else 0) <= NOTE_LINES


def note_body(title: str, body: str) -> tuple[str, bool]:
    """(the body a notification shows, whether it was cut): the body itself when it fits
    (fits_a_note); else its first words that fit with NOTE_MORE after them, cut after a
    sentence or clause where one ends, else after a word, with an ellipsis."""
    if fits_a_note(title, body):
        return body, False
    words = body.split()
    shown = ""
    for k in range(len(words), 0, -1):
        lead = " ".join(words[:k])
        if fits_a_note(title, f"{lead}…{NOTE_MORE}"):
            shown = lead
            break
    # Prefer the end of a sentence or clause within it, when that keeps half of it.
    ends = [m.end() for m in re.finditer(r"[.;:](?=\s)", shown + " ")]
    if ends and ends[-1] >= len(shown) / 2:
        shown = shown[: ends[-1]].rstrip(".;:")
    return f"{shown}…{NOTE_MORE}" if shown else NOTE_MORE.strip(" ()").capitalize(), True
