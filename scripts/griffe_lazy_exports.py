"""A Griffe extension for the API reference (mkdocs.yml): each subpackage's public names are
the keys of its `lazy_exports(__name__, {...})` call (roachplan/_lazy.py), which is its
`__all__` at run time; Griffe reads source without running it, so this tells it the same."""

from __future__ import annotations

import ast
from typing import Any

import griffe


class LazyExports(griffe.Extension):
    def on_module_members(
        self, *, node: ast.AST | griffe.ObjectNode, mod: griffe.Module, **kwargs: Any
    ) -> None:
        if not isinstance(node, ast.Module):
            return
        for stmt in node.body:
            call = getattr(stmt, "value", None)
            if not (
                isinstance(call, ast.Call)
                and isinstance(call.func, ast.Name)
                and call.func.id == "lazy_exports"
                and len(call.args) == 2
            ):
                continue
            where = call.args[1]
            if isinstance(where, ast.Dict):
                mod.exports = _strings(where.keys)
            elif isinstance(where, ast.DictComp):  # {name: "._api" for name in (...)}
                names = where.generators[0].iter
                if isinstance(names, ast.Tuple | ast.List):
                    mod.exports = _strings(names.elts)


def _strings(nodes: list[ast.expr | None] | list[ast.expr]) -> list[str | griffe.ExprName]:
    """The string literals among nodes, in order."""
    found: list[str | griffe.ExprName] = []
    for node in nodes:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            found.append(node.value)
    return found
