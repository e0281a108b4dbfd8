"""The scene library's folder and names, and the seed range: what the command line needs
before any scene is loaded (`roachplan scene list` and `--help` answer without OMPL or trimesh)."""

from __future__ import annotations

from pathlib import Path

LIBRARY = Path(__file__).parent / "library"
MAX_SEED = 2**31 - 2
"""Largest seed accepted: OMPL's generator takes seed % (2^31 - 1) + 1 (planning/_ompl.py), so
seeds 0..MAX_SEED are its seeds 1..2^31 - 1, each a different one."""


def library_names(library: Path) -> list[str]:
    """Names of the .yaml files in a library folder."""
    return sorted(p.stem for p in library.glob("*.yaml"))


def list_scenes() -> list[str]:
    """Names of the scenes in the library."""
    return library_names(LIBRARY)
