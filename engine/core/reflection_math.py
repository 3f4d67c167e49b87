"""Math of planar reflections: mirror planes, reflected cameras, oblique near planes.

Planes are glm.vec4 (n.x, n.y, n.z, d) with unit n: a point x is in front when n.x + d > 0.
"""
from __future__ import annotations

from collections.abc import Sequence

from pyglm import glm


def plane_from_point_normal(point: glm.vec3 | Sequence[float], normal: glm.vec3 | Sequence[float]) -> glm.vec4:
    n = glm.normalize(glm.vec3(normal))
    return glm.vec4(n, -glm.dot(n, glm.vec3(point)))


def transform_plane(matrix: glm.mat4, plane: glm.vec4) -> glm.vec4:
    """The plane carried by ``matrix`` (planes transform by the inverse transpose)."""
    p = glm.transpose(glm.inverse(matrix)) * plane
    return p / glm.length(glm.vec3(p))


def signed_distance(plane: glm.vec4, point: glm.vec3 | Sequence[float]) -> float:
    return glm.dot(glm.vec3(plane), glm.vec3(point)) + plane.w


def reflection_matrix(plane: glm.vec4) -> glm.mat4:
    """World-space reflection about ``plane`` (its own inverse)."""
    n = glm.vec3(plane)
    d = plane.w
    m = glm.mat4(1.0)
    for col in range(3):
        for row in range(3):
            m[col][row] -= 2.0 * n[row] * n[col]
    m[3] = glm.vec4(-2.0 * d * n, 1.0)
    return m


def reflect_camera(eye: glm.vec3 | Sequence[float], forward: glm.vec3 | Sequence[float],
                   up: glm.vec3 | Sequence[float], plane: glm.vec4) -> tuple[glm.vec3, glm.vec3, glm.vec3]:
    """The classic planar-mirror virtual camera: reflect its position, its look direction and its up vector.

    The result is an ordinary (right-handed) camera behind the mirror; what it sees is the
    mirrored scene, but the image it makes is left-right swapped compared with the mirror.
    """
    n = glm.vec3(plane)
    eye = glm.vec3(eye)
    reflected_eye = eye - 2.0 * signed_distance(plane, eye) * n
    return reflected_eye, glm.reflect(glm.vec3(forward), n), glm.reflect(glm.vec3(up), n)


MIRROR_X = glm.scale(glm.vec3(-1.0, 1.0, 1.0))


def mirrored_view(view: glm.mat4, plane: glm.vec4) -> glm.mat4:
    """View matrix of the reflection, pixel-aligned with the mirror as seen by ``view``.

    Equal to ``MIRROR_X * lookAt(reflect_camera(...))``: the virtual camera of ``reflect_camera`` with its image
    swapped back, so a mirror pixel reads its reflection at the same screen position.
    Handedness flips, so front faces wind clockwise in this view.
    """
    return view * reflection_matrix(plane)


def oblique_projection(proj: glm.mat4, view_plane: glm.vec4) -> glm.mat4:
    """Lengyel's oblique near plane: replace the near plane of ``proj`` by ``view_plane``.

    ``view_plane`` is in view space and faces what must stay visible (the eye is behind it).
    Rows 1, 2 and 4 of the projection are unchanged; points on the plane map to NDC z = -1.
    """
    def sign(x: float) -> float:
        return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)

    q = glm.inverse(proj) * glm.vec4(sign(view_plane.x), sign(view_plane.y), 1.0, 1.0)
    c = view_plane * (2.0 / glm.dot(view_plane, q))
    result = glm.mat4(proj)
    for col in range(4):
        result[col][2] = c[col] - proj[col][3]
    return result


# Closer to its plane than this many near-plane distances, an oblique frustum loses its depth
# precision (its far plane swings towards the eye): the clip distance alone keeps what is
# behind out.  One rule for the one-at-a-time check below and the view planner's arrays.
OBLIQUE_SAFE_NEARS = 4.0


def oblique_is_safe(eye: glm.vec3 | Sequence[float], plane: glm.vec4, near: float) -> bool:
    """Whether an oblique near plane keeps useful depth precision.

    Close to the plane the oblique frustum degenerates (its far plane swings towards the
    eye); there a clip distance is used instead.
    """
    return abs(signed_distance(plane, eye)) > OBLIQUE_SAFE_NEARS * near
