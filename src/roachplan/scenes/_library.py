"""The scene library's folder and names: what the command line needs before any scene is
loaded (`roachplan scene list` and `--help` answer without OMPL or trimesh)."""

from __future__ import annotations

from pathlib import Path

LIBRARY = Path(__file__).parent / "library"


def library_names(library: Path) -> list[str]:
    """Names of the .yaml files in a library folder."""
    return sorted(p.stem for p in library.glob("*.yaml"))


def list_scenes() -> list[str]:
    """Names of the scenes in the library."""
    return library_names(LIBRARY)
