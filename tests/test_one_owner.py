"""One owner per rule (issue 24): each rule several pieces of code must agree on is defined
in one module, and everything else calls it; a second copy is what drifts.  The first test
reads every module's top-level definitions (no import), so a copy made anywhere fails it;
the others check that what is left of a rule outside its owner (a GLSL table, a system's
answer) is the owner's."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from components import Camera, Transform
from engine.core.world import World
from engine.rules.frame_rules import active_camera, active_camera_parts

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("components", "engine", "systems", "shell", "games", "benchmarks")

# rule: (the pattern a top-level function or constant of the rule is named by, its one owner)
OWNERS = {
    "the active camera": (r"_?active_camera(_\w+)?", "engine/rules/frame_rules.py"),
}


def top_level_names(path: Path) -> set[str]:
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names


@pytest.mark.parametrize("rule", sorted(OWNERS))
def test_each_rule_is_defined_in_one_module(rule):
    pattern, owner = OWNERS[rule]
    defined = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            hits = sorted(n for n in top_level_names(path) if re.fullmatch(pattern, n))
            if hits:
                defined[path.relative_to(ROOT).as_posix()] = hits
    assert set(defined) == {owner}, f"{rule}: defined in {defined}, owned by {owner} only"


def test_active_camera_parts_is_the_rules_camera():
    world = World("one owner")
    try:
        assert active_camera_parts(world) is None
        cameras = [world.spawn(Transform(), Camera(active=active)) for active in (False, True, True)]
        entity, camera, transform = active_camera_parts(world)
        assert entity == active_camera(world) == cameras[1]
        assert camera is world.get(entity, Camera) and transform is world.get(entity, Transform)
    finally:
        world.close()
