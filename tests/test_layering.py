"""Layering: every module imports on its own in a fresh interpreter, and the engine's core
never imports ``systems`` (only the app shell wires systems into a world)."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("components", "engine", "systems", "games", "benchmarks", "shaders")
# The app shell: the one place that may import systems.
SHELL = {"engine.app", "engine.runner", "engine.window"}


def modules() -> list[str]:
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return found


def test_every_module_imports_first_in_a_fresh_interpreter():
    env = {**os.environ, "PYTHONPATH": str(ROOT)}

    def load(name: str) -> tuple[str, int, str]:
        result = subprocess.run([sys.executable, "-c", f"import {name}"], cwd=ROOT, env=env,
                                capture_output=True, text=True, timeout=120)
        return name, result.returncode, result.stderr.strip().splitlines()[-1:]

    with ThreadPoolExecutor(max_workers=4) as pool:
        failed = [(name, err) for name, code, err in pool.map(load, modules()) if code]
    assert not failed, failed


def imported_names(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module)
    return names


def test_the_engine_core_never_imports_systems():
    offenders = []
    for name in modules():
        if not name.startswith("engine") or name in SHELL:
            continue
        path = ROOT / (name.replace(".", "/") + ".py")
        if not path.exists():
            path = ROOT / name.replace(".", "/") / "__init__.py"
        if any(n == "systems" or n.startswith("systems.") for n in imported_names(path)):
            offenders.append(name)
    assert not offenders, f"engine core modules importing systems: {offenders}"
