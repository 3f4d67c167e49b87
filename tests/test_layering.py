"""Layering: every module imports on its own in a fresh interpreter; imports run only down
the floors of the house (components, then the engine's core, assets, the frame's data, rules
and render, then systems, the app shell, games and benchmarks), transitively; no two modules
import each other, however far round."""
from __future__ import annotations

import ast
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("components", "engine", "systems", "shell", "games", "benchmarks", "shaders")
# The floors, lowest first: a module may import its own floor and the ones below.
FLOORS = ("shaders", "components", "engine.core", "engine.assets", "engine.frame_stats", "engine.resources",
          "engine.rules", "engine.render", "engine", "systems", "shell", "games", "benchmarks")


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
#
# The modules come in groups, lowest floors first: the engine and what it stands on, then
# systems, the shell, games, benchmarks.  Before a group's children the parent imports the
# groups below it: every import runs down the floors (test_imports_run_only_down_the_floors_
# transitively proves it from the source), so nothing of a lower group can take part in a
# cycle or an order that breaks a higher module, and each child then imports only its own
# floor's modules (a benchmark's child no longer loads the whole engine: the test's time
# halved).  The parent checks that its preloading brought in nothing of the group it tests.
FORK_EACH = r"""
import importlib, json, os, sys, traceback
import esper, moderngl, moderngl_window, numpy, PIL.Image
from pyglm import glm

project = set(sys.argv[1].split(","))
loaded = sorted(m for m in sys.modules if m.split(".")[0] in project)
assert not loaded, f"the parent imported project modules: {loaded}"
groups, failed, running = json.loads(sys.argv[2]), {}, {}

def reap():
    pid, status = os.wait()
    name, read = running.pop(pid)
    message = os.read(read, 65536).decode()
    os.close(read)
    if status:
        failed[name] = message or f"exit status {status}"

for index, names in enumerate(groups):
    if index:   # the group below, imported here (its __main__ modules run programs: not those)
        for name in groups[index - 1]:
            if not name.endswith("__main__"):
                try:
                    importlib.import_module(name)
                except BaseException:
                    pass   # (its own child reported it)
        early = sorted(set(names) & set(sys.modules))
        if early:
            failed["(preloading)"] = f"importing the floors below brought in {early}"
            break
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
GROUPS = (("shaders", "components", "engine"), ("systems",), ("shell",), ("games",), ("benchmarks",))


def grouped(names: list[str]) -> list[list[str]]:
    """``names`` in ``GROUPS``' order, a list a group (by their top package)."""
    return [[name for name in names if name.split(".")[0] in group] for group in GROUPS]


def test_every_module_imports_first_in_a_fresh_interpreter():
    names = modules()
    assert len(names) > 40 and "systems" in names and "engine.render.renderer" in names
    groups = grouped(names)
    assert sum(map(len, groups)) == len(names), "a package no group holds"
    result = subprocess.run([sys.executable, "-c", FORK_EACH, ",".join(PACKAGES), json.dumps(groups)], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    failed = json.loads(result.stdout.strip().splitlines()[-1])
    if importlib.util.find_spec("imgui_bundle") is None:  # the overlay's and editor panels' own dependency,
        failed = {name: error for name, error in failed.items()  # not installed on this machine (a GPU host's)
                  if error != "ModuleNotFoundError: No module named 'imgui_bundle'"}
    assert not failed, failed


def test_import_systems_first_in_a_truly_fresh_interpreter():
    """The case that used to fail (a cycle through engine/__init__), without any preloading."""
    result = subprocess.run([sys.executable, "-c", "import systems"], cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]


def floor_of(module: str) -> int:
    """The floor of ``module``: its longest FLOORS prefix."""
    best = max((f for f in FLOORS if module == f or module.startswith(f + ".")), key=len)
    return FLOORS.index(best)


def module_path(name: str) -> Path:
    path = ROOT / (name.replace(".", "/") + ".py")
    return path if path.exists() else ROOT / name.replace(".", "/") / "__init__.py"


def imported_modules(name: str, known: set[str], typing_too: bool = False) -> set[str]:
    """The project modules ``name`` imports at run time, at its top or inside a function (an
    ``if TYPE_CHECKING:`` block is for type checkers only: counted with ``typing_too``);
    ``from a import b`` counts a.b where that is a module, else a."""
    tree = ast.parse(module_path(name).read_text())
    typing_only = set() if typing_too else {
        id(node) for block in ast.walk(tree) if isinstance(block, ast.If)
        and getattr(block.test, "id", None) == "TYPE_CHECKING" for node in ast.walk(block)}
    found = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.update(f"{node.module}.{alias.name}" if f"{node.module}.{alias.name}" in known else node.module
                         for alias in node.names)
    return {m for m in found if m in known and m != name}


def import_graph(typing_too: bool = False) -> dict[str, set[str]]:
    known = set(modules())
    return {name: imported_modules(name, known, typing_too) for name in known}


def test_imports_run_only_down_the_floors_transitively():
    graph = import_graph()
    offenders = []
    for name in graph:
        seen, stack = set(), list(graph[name])
        while stack:
            other = stack.pop()
            if other in seen:
                continue
            seen.add(other)
            stack.extend(graph[other])
        above = sorted(m for m in seen if floor_of(m) > floor_of(name) and not name.endswith("__main__"))
        if above:
            offenders.append(f"{name} (floor {FLOORS[floor_of(name)]}) reaches {above}")
    assert not offenders, "\n".join(offenders)


def test_no_two_modules_import_each_other():
    """No import circle of any length (Tarjan's strongly connected components), type-only
    imports included: a module that names another's type for its hints depends on it as
    much as one that calls it (a pass takes the ``Gpu`` below it, not the ``Renderer``
    above it that makes it)."""
    graph = import_graph(typing_too=True)
    index, low, on_stack, stack, circles, counter = {}, {}, set(), [], [], [0]

    def visit(node: str) -> None:
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                other = stack.pop()
                on_stack.discard(other)
                component.append(other)
                if other == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    assert not circles, circles


def loaded_by(module: str, prefixes: tuple[str, ...]) -> list[str]:
    """The modules whose names start with one of ``prefixes`` that importing ``module`` loads
    in a fresh interpreter (the layering of the imports, as Python runs them)."""
    probe = (f"import json, sys, {module}; "
             f"print(json.dumps(sorted(m for m in sys.modules if m.startswith({prefixes!r}))))")
    result = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout)


def test_loading_a_level_file_imports_no_system_and_no_shell():
    """The level-file loader (an asset) loads no system, shell module or game."""
    assert loaded_by("engine.assets.level_file", ("systems", "shell", "games")) == []


def test_the_frame_data_imports_no_render_code_and_no_gl():
    """``engine.resources`` (what games read) is plain data: importing it loads nothing of
    ``engine/render`` and no GL library."""
    assert loaded_by("engine.resources", ("engine.render", "moderngl", "glcontext")) == []
