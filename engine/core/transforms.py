"""The world matrix of a Transform as the components say it is now, for code that cannot
wait for the transform stage: ``Transform.world`` is written by the TransformSystem
(``systems/transform_system.py``) and is last frame's until it runs this frame (identity
for a new entity).  One rule for the parent chain, used by the transform stage's callers
before it (travel, slicing) and by ray casts in the game stage.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from pyglm import glm

from components import Transform

if TYPE_CHECKING:
    from engine.core.world import World

MAX_PARENT_HOPS = 64  # a chain longer than this (or a cycle, which the transform stage refuses) stops here


def current_world_matrix(world: World, transform: Transform, max_hops: int = MAX_PARENT_HOPS) -> glm.mat4:
    """``transform``'s model-to-world matrix from its parent chain's local poses now.

    The chain follows the rules of the transform stage: a parent that does not exist, or has
    no Transform, is no parent (the entity is a root)."""
    matrix = transform.local_matrix()
    parent = transform.parent
    for _ in range(max_hops):
        if parent is None or not world.exists(parent):
            break
        parent_t = world.try_get(parent, Transform)
        if parent_t is None:
            break
        matrix = parent_t.local_matrix() * matrix
        parent = parent_t.parent
    return matrix
