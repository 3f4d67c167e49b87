"""Layering: every module imports on its own in a fresh interpreter, and the engine's core
never imports ``systems`` (only the app shell wires systems into a world)."""
from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
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


# One interpreter loads the third-party libraries every module needs (never a module of the
# project: checked), then forks a child per module that imports just that module.  Each
# child starts with none of the project imported, as a fresh ``python -c "import X"`` does,
# so an import cycle or a missing import shows; the fork skips the interpreter start and the
# library loading, which made one subprocess per module cost ~6 s on two cores.
FORK_EACH = r"""
import importlib, json, os, sys, traceback
import esper, moderngl, moderngl_window, numpy, PIL.Image
from pyglm import glm

project = set(sys.argv[1].split(","))
loaded = sorted(m for m in sys.modules if m.split(".")[0] in project)
assert not loaded, f"the parent imported project modules: {loaded}"
names, failed, running = sys.argv[2:], {}, {}

def reap():
    pid, status = os.wait()
    name, read = running.pop(pid)
    message = os.read(read, 65536).decode()
    os.close(read)
    if status:
        failed[name] = message or f"exit status {status}"

for name in names:
    while len(running) >= max(2, os.cpu_count() or 2):
        reap()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        os.dup2(os.open(os.devnull, os.O_WRONLY), 1)  # a program's --help, not the report
        # A package's __main__ runs its program when imported: ask it for --help, which
        # still imports everything it uses and exits 0.
        sys.argv = [name, "--help"] if name.endswith("__main__") else [name]
        try:
            importlib.import_module(name)
        except SystemExit as exc:
            if exc.code not in (0, None):
                os.write(write, f"SystemExit: {exc.code}".encode())
                os._exit(1)
        except BaseException:
            os.write(write, traceback.format_exc().strip().splitlines()[-1].encode())
            os._exit(1)
        os._exit(0)
    os.close(write)
    running[pid] = (name, read)
while running:
    reap()
print(json.dumps(failed))
"""


def test_every_module_imports_first_in_a_fresh_interpreter():
    names = modules()
    assert len(names) > 40 and "systems" in names and "engine.render.renderer" in names
    result = subprocess.run([sys.executable, "-c", FORK_EACH, ",".join(PACKAGES), *names], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    failed = json.loads(result.stdout.strip().splitlines()[-1])
    assert not failed, failed


def test_import_systems_first_in_a_truly_fresh_interpreter():
    """The case that used to fail (a cycle through engine/__init__), without any preloading."""
    result = subprocess.run([sys.executable, "-c", "import systems"], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]


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
