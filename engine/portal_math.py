"""Math of paired portals: the transform that carries things from one portal to its partner."""
from __future__ import annotations

import glm

from engine.reflection_math import plane_from_point_normal

HALF_TURN = glm.rotate(glm.pi(), glm.vec3(0.0, 1.0, 0.0))


def pair_transform(look_in: glm.mat4, look_out: glm.mat4) -> glm.mat4:
    """Seed 001: into the look-in portal's local space, a half turn about its up, out of the
    look-out portal.  Carries points (and cameras) at ``look_in`` to ``look_out``."""
    return look_out * HALF_TURN * glm.inverse(look_in)


def portal_view(view: glm.mat4, look_in: glm.mat4, look_out: glm.mat4) -> glm.mat4:
    """The view seen through the look-in portal: the camera carried to the look-out side."""
    return view * glm.inverse(pair_transform(look_in, look_out))


def portal_plane(world: glm.mat4) -> glm.vec4:
    """World plane of a portal (local XY plane, normal local +Z = its front)."""
    normal = glm.normalize(glm.vec3(glm.transpose(glm.inverse(glm.mat3(world))) * glm.vec3(0, 0, 1)))
    return plane_from_point_normal(glm.vec3(world[3]), normal)


def inside_rectangle(world: glm.mat4, size: tuple[float, float], point) -> bool:
    """Whether ``point`` (on or near the portal plane) lies within its rectangle."""
    local = glm.vec3(glm.inverse(world) * glm.vec4(glm.vec3(point), 1.0))
    return abs(local.x) <= size[0] / 2 and abs(local.y) <= size[1] / 2
