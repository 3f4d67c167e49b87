"""ARCHITECTURE.md stays true: its stage table is ``FRAME_STAGES`` in order, every path it
names exists, and every module of the engine, the systems and the shell is on its map (a
new module is placed in the doc when it is made; a moved one is moved there too)."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "ARCHITECTURE.md").read_text()
MAPPED = ("engine", "systems", "shell")


def stage_table() -> list[tuple[str, str]]:
    """(stage, code cell) of each row of the table under the "| stage |" header."""
    rows, inside = [], False
    for line in DOC.splitlines():
        if line.startswith("| stage |"):
            inside = True
            continue
        if inside:
            if not line.startswith("|"):
                break
            cells = [cell.strip() for cell in line.strip("|").split("|")]
            if set(cells[0]) <= {"-", " "}:
                continue
            rows.append((cells[0].strip("`"), cells[-1]))
    return rows


def test_the_stage_table_is_the_frame_stages_in_order():
    from shell.app import FRAME_STAGES

    assert [stage for stage, _ in stage_table()] == [name for name, _ in FRAME_STAGES]


def test_every_path_the_doc_names_exists():
    named = set(re.findall(r"`((?:engine|systems|shell|components|shaders|games|tests|benchmarks|docs)"
                           r"/[\w./*]*)`", DOC))
    assert named, "the doc names no paths"
    missing = sorted(p for p in named if "*" not in p and not (ROOT / p.rstrip("/")).exists())
    assert not missing, f"ARCHITECTURE.md names paths that do not exist: {missing}"


def test_every_engine_system_and_shell_module_is_on_the_map():
    modules = sorted(str(path.relative_to(ROOT)) for package in MAPPED for path in (ROOT / package).rglob("*.py")
                     if path.name != "__init__.py")
    absent = [m for m in modules if f"`{m}`" not in DOC]
    assert not absent, f"modules ARCHITECTURE.md does not place: {absent}"
