"""Spawning portal pairs: two quads whose Portal components name each other."""
from __future__ import annotations

from collections.abc import Sequence

from pyglm import glm

from components import ComponentValueError, Material, MeshRef, Portal, Transform
from components.transform import rotation as to_rotation
from engine.assets.mesh import quad
from engine.core.world import World


def spawn_portal_pair(world: World, position_a: glm.vec3 | Sequence[float],
                      rotation_a: glm.quat | Sequence[float] | None, position_b: glm.vec3 | Sequence[float],
                      rotation_b: glm.quat | Sequence[float] | None,
                      size: tuple[float, float] = (2.0, 3.0), max_depth: int = 4) -> tuple[int, int]:
    """Two portals facing their local +Z; looking into either shows the other's front side.

    Rotations are quaternions (glm.quat or (w, x, y, z)) or None; angles go through
    ``euler_rotation`` / ``yaw_pitch_rotation`` / ``look_rotation`` first, so a plain
    3-tuple is refused here, naming the argument, rather than read as radians.  Both
    portals are spawned or neither.
    """
    rotations = []
    for name, value in (("rotation_a", rotation_a), ("rotation_b", rotation_b)):
        try:
            rotations.append(glm.quat() if value is None else to_rotation(value))
        except ComponentValueError as exc:
            raise ComponentValueError(f"spawn_portal_pair {name}: {exc}") from None
    mesh = quad(*size, name="portal")
    surface = Material(color=(0.02, 0.02, 0.03), roughness=1.0)
    a = world.spawn(Transform(position=position_a, rotation=rotations[0]), MeshRef(mesh), surface,
                    Portal(size=size, max_depth=max_depth))
    try:
        b = world.spawn(Transform(position=position_b, rotation=rotations[1]), MeshRef(mesh),
                        Material(color=(0.02, 0.02, 0.03), roughness=1.0),
                        Portal(partner=a, size=size, max_depth=max_depth))
    except BaseException:
        world.delete_entity(a)
        raise
    world.get(a, Portal).partner = b
    return a, b
