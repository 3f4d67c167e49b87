"""Math of paired portals: the transform that carries things from one portal to its partner."""
from __future__ import annotations

from collections.abc import Sequence

from pyglm import glm

from engine.core.reflection_math import plane_from_point_normal

HALF_TURN = glm.rotate(glm.pi(), glm.vec3(0.0, 1.0, 0.0))


def pair_transform(look_in: glm.mat4, look_out: glm.mat4) -> glm.mat4:
    """The portal pair transform: into the look-in portal's local space, a half turn about its up, out of the
    look-out portal.  Carries points (and cameras) at ``look_in`` to ``look_out``."""
    return look_out * HALF_TURN * glm.inverse(look_in)


def portal_plane(world: glm.mat4) -> glm.vec4:
    """World plane of a portal (local XY plane, normal local +Z = its front)."""
    normal = glm.normalize(glm.vec3(glm.transpose(glm.inverse(glm.mat3(world))) * glm.vec3(0, 0, 1)))
    return plane_from_point_normal(glm.vec3(world[3]), normal)


def pair_rotation(carry: glm.mat4) -> glm.quat:
    """The rotation part of a pair transform (columns normalised, so scaled portals work)."""
    m = glm.mat3(carry)
    return glm.normalize(glm.quat_cast(glm.mat3(glm.normalize(m[0]), glm.normalize(m[1]), glm.normalize(m[2]))))


def near_plane_corners(position: glm.vec3 | Sequence[float], rotation: glm.quat, fov_y_deg: float, near: float,
                       aspect: float, ortho_height: float | None = None) -> list[glm.vec3]:
    """World corners of a camera's near-plane rectangle (the camera looks down its -Z;
    ``ortho_height``: an orthographic camera's, its rectangle that tall whatever ``near``)."""
    half_h = near * glm.tan(glm.radians(fov_y_deg) / 2.0) if ortho_height is None else ortho_height / 2.0
    half_w = half_h * aspect
    eye = glm.vec3(position)
    return [eye + rotation * glm.vec3(sx * half_w, sy * half_h, -near)
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
