"""The public API is typed: every public function and every public method (constructors
included) of the engine's packages names the types of its parameters and of what it
returns, so an editor says what a function takes before a game calls it wrongly.

Public means reachable without an underscore: a module-level function or class of a module
whose path has no part starting with one, and a class's methods not starting with one
(``__init__`` and ``__call__`` count: they are how the class is used).  Nested helpers and
private names are free."""
from __future__ import annotations

import ast
import typing
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("components", "engine", "systems", "shell")
DUNDERS_IN_THE_API = ("__init__", "__call__")


def public_functions(tree: ast.Module) -> list[tuple[str, ast.FunctionDef | ast.AsyncFunctionDef]]:
    """(qualified name, definition) of the module's public functions and public classes' methods."""
    functions = (ast.FunctionDef, ast.AsyncFunctionDef)
    found = []
    for node in tree.body:
        if isinstance(node, functions) and not node.name.startswith("_"):
            found.append((node.name, node))
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            found += [(f"{node.name}.{item.name}", item) for item in node.body if isinstance(item, functions)
                      and (not item.name.startswith("_") or item.name in DUNDERS_IN_THE_API)]
    return found


def missing_hints(node: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    """The parameters (and "return") of ``node`` without an annotation."""
    args = node.args
    params = [*args.posonlyargs, *args.args, *args.kwonlyargs,
              *(a for a in (args.vararg, args.kwarg) if a is not None)]
    missing = [a.arg for a in params if a.annotation is None and a.arg not in ("self", "cls")]
    if node.returns is None and node.name != "__init__":
        missing.append("return")
    return missing


def package_modules() -> list[Path]:
    return sorted(path for package in PACKAGES for path in (ROOT / package).rglob("*.py")
                  if not any(part.startswith("_") and part != "__init__.py"
                             for part in path.relative_to(ROOT).parts))


def test_every_public_function_and_method_is_typed():
    untyped = []
    for path in package_modules():
        for name, node in public_functions(ast.parse(path.read_text(), str(path))):
            missing = missing_hints(node)
            if missing:
                untyped.append(f"{path.relative_to(ROOT)}:{node.lineno} {name}: {', '.join(missing)}")
    assert not untyped, "public API without type hints:\n" + "\n".join(untyped)


def test_the_check_sees_a_missing_hint():
    """The checker itself: an untyped parameter or return of a public function or method is
    found, and private names, nested helpers and ``self`` are not asked for hints."""
    tree = ast.parse("def spawn(world, position: tuple) -> int:\n    def inner(x): return x\n    return 1\n"
                     "def _private(x): pass\n"
                     "class Thing:\n    def __init__(self, size): pass\n    def grow(self, by: int): pass\n"
                     "    def _helper(self, x): pass\n"
                     "class _Hidden:\n    def open(self, x): pass\n")
    found = {name: missing_hints(node) for name, node in public_functions(tree)}
    assert found == {"spawn": ["world"], "Thing.__init__": ["size"], "Thing.grow": ["return"]}


@pytest.mark.parametrize("module, name", [
    ("engine.core.reflection_math", "reflect_camera"),
    ("engine.rules.raycast", "raycast"),
    ("engine.assets.portals", "spawn_portal_pair"),
    ("engine.assets.models", "spawn_model"),
    ("engine.core.game", "spawn_camera"),
])
def test_a_game_facing_functions_hints_resolve(module, name):
    """The functions a game calls most resolve their hints at run time (``typing.get_type_hints``:
    what an editor or a runtime checker reads), not only in a type checker."""
    hints = typing.get_type_hints(getattr(__import__(module, fromlist=[name]), name))
    assert "return" in hints and len(hints) > 1
