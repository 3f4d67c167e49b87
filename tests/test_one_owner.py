"""One owner per rule (issue 24): each rule several pieces of code must agree on is defined
in one module, and everything else calls it; a second copy is what drifts.  The first test
reads every module's top-level definitions (no import), so a copy made anywhere fails it;
the others check that what is left of a rule outside its owner (a GLSL table, a system's
answer) is the owner's."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from pyglm import glm

from components import Camera, Transform
from engine.core.transforms import current_world_matrix
from engine.core.world import World
from engine.rules.frame_rules import active_camera, active_camera_parts
from systems.transform_system import TransformSystem

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("components", "engine", "systems", "shell", "games", "benchmarks")

# rule: (the pattern a top-level function or constant of the rule is named by, its one owner)
OWNERS = {
    "the active camera": (r"_?active_camera(_\w+)?", "engine/rules/frame_rules.py"),
    "the world matrix": (r"_?current_world_matrix", "engine/core/transforms.py"),
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


def test_current_world_matrix_is_the_transform_stages_matrix():
    """Worked out before the transform stage, the matrix is the one the stage then writes,
    through a chain with a parent that has no Transform and one that was deleted."""
    world = World("one owner")
    try:
        turn = glm.angleAxis(0.7, glm.vec3(0.0, 1.0, 0.0))
        root = world.spawn(Transform(position=(1.0, 2.0, 3.0), rotation=turn, scale=(2.0, 2.0, 2.0)))
        child = world.spawn(Transform(position=(0.5, 0.0, -1.0), parent=root))
        grandchild = world.spawn(Transform(position=(0.0, 1.0, 0.0), rotation=turn, parent=child))
        bare = world.spawn(Camera(active=False))             # an entity with no Transform
        under_bare = world.spawn(Transform(position=(4.0, 0.0, 0.0), parent=bare))
        gone = world.spawn(Transform(position=(9.0, 9.0, 9.0)))
        under_gone = world.spawn(Transform(position=(0.0, 0.0, 5.0), parent=gone))
        world.delete_entity(gone)
        entities = (root, child, grandchild, under_bare, under_gone)
        before = {e: current_world_matrix(world, world.get(e, Transform)) for e in entities}
        TransformSystem(world).process(0.0)
        for entity in entities:
            written = world.get(entity, Transform).world
            np.testing.assert_allclose(before[entity].to_list(), written.to_list(), atol=1e-6, err_msg=str(entity))
        assert before[under_bare][3] == glm.vec4(4.0, 0.0, 0.0, 1.0)
        assert before[under_gone][3] == glm.vec4(0.0, 0.0, 5.0, 1.0)
    finally:
        world.close()
