"""Lazy re-exports for the subpackages' `__init__`: `from roachplan.scenes import SceneError`
imports only the module that defines it, so `roachplan --help` answers without loading OMPL,
Open3D, trimesh, matplotlib or Ray (PEP 562 module `__getattr__`)."""

from __future__ import annotations

import importlib


def lazy_exports(package: str, where: dict[str, str]):
    """(__getattr__, __dir__, __all__) for a package whose public names live in its private
    modules: where maps each name to the module that defines it (relative, "._scene", or the
    package top's, "roachplan._settings")."""

    def __getattr__(name: str):
        if name not in where:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(where[name], package), name)
        globals_of_package = importlib.import_module(package).__dict__
        globals_of_package[name] = value  # later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(importlib.import_module(package).__dict__) | set(where))

    return __getattr__, __dir__, sorted(where)
