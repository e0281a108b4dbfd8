"""Each package's public names are listed twice in its __init__.py: the lazy table that imports
them on first use (roachplan._lazy), and the TYPE_CHECKING block that type checkers and editors
read (the table's __getattr__ is hidden from them, so that pyright reports an import of a name
the package does not export). The two lists must be one list."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parent.parent / "src" / "roachplan"
PACKAGES = ["roachplan", *(f"roachplan.{p.parent.name}" for p in sorted(SRC.glob("*/__init__.py")))]


def _init(package: str) -> ast.Module:
    parts = package.split(".")[1:]
    return ast.parse((SRC.joinpath(*parts) / "__init__.py").read_text())


def _strings(nodes: list[ast.expr]) -> set[str]:
    return {n.value for n in nodes if isinstance(n, ast.Constant) and isinstance(n.value, str)}


def _lazy_names(tree: ast.Module) -> set[str] | None:
    """The keys of the module's lazy_exports(__name__, {...}) call; None without one."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "lazy_exports":
            found: set[str] = set()
            table = node.args[1]
            assert isinstance(table, ast.Dict)
            for key, value in zip(table.keys, table.values, strict=True):
                if key is None:  # **{name: "._api" for name in (...)}, spread into the table
                    assert isinstance(value, ast.DictComp)
                    names = value.generators[0].iter
                    assert isinstance(names, ast.Tuple)
                    found |= _strings(names.elts)
                else:
                    found |= _strings([key])
            return found
    return None


def _checked_names(tree: ast.Module) -> set[str]:
    """The names the module's `if TYPE_CHECKING:` block imports."""
    found: set[str] = set()
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for stmt in node.body:
                if isinstance(stmt, ast.ImportFrom):
                    found |= {a.asname or a.name for a in stmt.names}
    return found


@pytest.mark.parametrize("package", PACKAGES)
def test_the_lazy_table_and_the_type_checkers_names_are_the_same(package):
    tree = _init(package)
    lazy = _lazy_names(tree)
    if lazy is None:
        pytest.skip(f"{package} imports its names eagerly")
    checked = _checked_names(tree)
    assert lazy - checked == set(), f"{package}: in the lazy table only (pyright does not see)"
    assert checked - lazy == set(), f"{package}: for type checkers only (not there at run time)"


@pytest.mark.parametrize("package", PACKAGES)
def test_every_public_name_imports(package):
    module = importlib.import_module(package)
    for name in getattr(module, "__all__", ()):
        getattr(module, name)  # (AttributeError or ImportError: the table names a wrong module)
