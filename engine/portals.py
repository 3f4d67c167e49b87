"""Spawning portal pairs: two quads whose Portal components name each other."""
from __future__ import annotations

from pyglm import glm

from components import Material, MeshRef, Portal, Transform
from engine.mesh import quad
from engine.world import World


def spawn_portal_pair(world: World, position_a, rotation_a, position_b, rotation_b,
                      size: tuple[float, float] = (2.0, 3.0), max_depth: int = 4) -> tuple[int, int]:
    """Two portals facing their local +Z; looking into either shows the other's front side."""
    mesh = quad(*size, name="portal")
    surface = Material(color=(0.02, 0.02, 0.03), roughness=1.0)
    a = world.spawn(Transform(position=position_a, rotation=rotation_a or glm.quat()), MeshRef(mesh), surface,
                    Portal(size=size, max_depth=max_depth))
    b = world.spawn(Transform(position=position_b, rotation=rotation_b or glm.quat()), MeshRef(mesh),
                    Material(color=(0.02, 0.02, 0.03), roughness=1.0),
                    Portal(partner=a, size=size, max_depth=max_depth))
    world.get(a, Portal).partner = b
    return a, b
