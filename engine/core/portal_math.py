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


RIGID = 1e-6  # a pair transform whose axes are all this close to unit length carries no scale


def carries_scale(carry: glm.mat4) -> bool:
    """Whether a pair transform changes sizes: its portals' world scales differ (a portal
    twice its partner's size by its Transform), so what goes through grows or shrinks."""
    m = glm.mat3(carry)
    return any(abs(glm.length(m[i]) - 1.0) > RIGID for i in range(3))


def even_scale(carry: glm.mat4) -> float | None:
    """The one factor a pair transform scales every length by (1 for a pair of one size), or
    None where it scales its axes unevenly (portals scaled unevenly by their Transforms).
    Read to seven significant digits (about what float32's carry holds): a designer's 2 is 2,
    not 1.9999998, and its way back 0.5, so a thing crossing there and back is its own size again."""
    m = glm.mat3(carry)
    lengths = [glm.length(m[i]) for i in range(3)]
    k = lengths[0]
    return float(f"{k:.6e}") if all(abs(length - k) <= RIGID * k for length in lengths) else None


def carried_velocity(carry: glm.mat4, turn: glm.quat, velocity: glm.vec3) -> glm.vec3:
    """A velocity (or any direction with a length) through a pair transform ``carry`` whose
    rotation is ``turn``: turned, then times the pair's one factor (``even_scale``), as
    ``carried_pose`` scales a size, so 2 and its way back 0.5 are exact (through the carry's
    float32 matrix a speed lost 2.4e-7 of itself each time there and back); a pair scaled
    unevenly: the carry's matrix."""
    k = even_scale(carry)
    return turn * velocity * k if k is not None else glm.mat3(carry) * velocity


def decompose_pose(matrix: glm.mat4) -> tuple[glm.vec3, glm.quat, glm.vec3]:
    """Position, rotation and scale of a model matrix (``glm.decompose``; a shear, which a
    pair of unevenly scaled portals can give a turned thing, is dropped)."""
    scale, rotation, translation = glm.vec3(), glm.quat(), glm.vec3()
    glm.decompose(matrix, scale, rotation, translation, glm.vec3(), glm.vec4())
    return translation, rotation, scale


def carried_pose(carry: glm.mat4, turn: glm.quat, position: glm.vec3, rotation: glm.quat,
                 scale: glm.vec3) -> tuple[glm.vec3, glm.quat, glm.vec3]:
    """A root pose carried through a portal pair: ``carry`` applied to its model matrix, the
    pose the partner's view showed it at.  A pair that scales evenly (one size, or a portal
    k times its partner) turns it by ``turn`` (the carry's rotation) and multiplies its scale
    by k, so crossing back and forth never drifts it; an uneven one is decomposed."""
    moved = glm.vec3(carry * glm.vec4(position, 1.0))
    if not carries_scale(carry):
        return moved, glm.normalize(turn * rotation), glm.vec3(scale)
    k = even_scale(carry)
    if k is not None:
        return moved, glm.normalize(turn * rotation), glm.vec3(scale) * k
    model = glm.translate(position) * glm.mat4_cast(rotation) * glm.scale(scale)
    _, rotation, scale = decompose_pose(carry * model)
    return moved, glm.normalize(rotation), scale


def near_plane_corners(position: glm.vec3 | Sequence[float], rotation: glm.quat, fov_y_deg: float, near: float,
                       aspect: float, ortho_height: float | None = None) -> list[glm.vec3]:
    """World corners of a camera's near-plane rectangle (the camera looks down its -Z;
    ``ortho_height``: an orthographic camera's, its rectangle that tall whatever ``near``)."""
    half_h = near * glm.tan(glm.radians(fov_y_deg) / 2.0) if ortho_height is None else ortho_height / 2.0
    half_w = half_h * aspect
    eye = glm.vec3(position)
    return [eye + rotation * glm.vec3(sx * half_w, sy * half_h, -near)
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
