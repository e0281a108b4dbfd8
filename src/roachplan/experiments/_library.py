"""The experiment library's folder and names, without loading any scene (`roachplan --help`
lists them and must answer at once)."""

from __future__ import annotations

from pathlib import Path

from roachplan.scenes import library_names

LIBRARY = Path(__file__).parent / "library"


def list_experiments() -> list[str]:
    """Names of the experiments in the library."""
    return library_names(LIBRARY)
