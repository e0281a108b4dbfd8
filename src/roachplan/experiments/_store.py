"""The results store: one JSON object per line, appended and synced as each trial finishes.

Only the experiment's main process writes. A kill can at worst cut the last line short; reading
drops that torn line (and `open_for_append` trims it off the file), so a resumed run appends
after the last whole record. Records are keyed by (kind, index): a resumed run skips keys
already present, and reading keeps the first record of a key should one ever repeat.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ._errors import ExperimentError

TRIAL = "trial"
"""A planned-and-driven trial; index = the trial number K."""
REDRIVE = "best_path"
"""A re-drive of the best path; index = the repeat number."""


class ResultStore:
    """Append-only JSON Lines file of trial records."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._fd: int | None = None

    def records(self) -> list[dict]:
        """Every whole record, in file order, the first of each (kind, index) key."""
        return _read(self.path)[0]

    def keys(self) -> set[tuple[str, int]]:
        return {(r["kind"], r["index"]) for r in self.records()}

    def append(self, record: dict) -> None:
        """Write one record ({"kind", "index", ...}) and sync it to disk before returning."""
        fd = self._fd if self._fd is not None else self._open()
        line = (json.dumps(record, separators=(",", ":")) + "\n").encode()
        os.write(fd, line)  # one write of the whole line
        os.fsync(fd)

    def _open(self) -> int:
        """Open the file to append to (its torn last line dropped); its descriptor."""
        _, good_bytes = _read(self.path)
        if self.path.exists() and self.path.stat().st_size > good_bytes:
            os.truncate(self.path, good_bytes)  # drop a line torn by a kill
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        return self._fd

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _read(path: Path) -> tuple[list[dict], int]:
    """(records, bytes of the file up to the end of the last whole line)."""
    if not path.exists():
        return [], 0
    data = path.read_bytes()
    good = data.rfind(b"\n") + 1  # a last line without its newline was torn by a kill
    out, seen = [], set()
    for n, line in enumerate(data[:good].splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
            key = (rec["kind"], rec["index"])
        except (ValueError, KeyError, TypeError) as exc:
            raise ExperimentError(
                f"{path}:{n}: not a trial record ({exc}); the store is damaged"
            ) from None
        if key not in seen:
            seen.add(key)
            out.append(rec)
    return out, good
