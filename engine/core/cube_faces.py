"""GL's cube-map face table, the one copy: which way each face of a cube map looks and how
its texture axes run.  A probe face's view (``engine/render/probes.py``), the sky's texel
directions (``engine/render/sky.py``) and the GLSL ``cube_face_direction``
(``shaders/include/cube_faces.glsl``, through the ``CUBE_FACE_*`` defines the shader
library gives every program) are all made from it.

Face i (``FACE_NAMES``: +X, -X, +Y, -Y, +Z, -Z) has a major axis ``forward`` and texture
axes ``s_axis`` and ``t_axis``: the direction through texture coordinates (s, t) in
[-1, 1] is ``forward + s * s_axis + t * t_axis`` (the OpenGL spec's cube-map face
selection table, read backwards; the faces are left-handed).  Drawn as a view looking
along ``forward`` with up ``t_axis`` (its right is then ``s_axis``), a face rendered the
usual way, bottom row first, is the face's texture rows in order.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

Axis = tuple[float, float, float]


class CubeFace(NamedTuple):
    forward: Axis  # the face's major axis: the direction through its centre
    s_axis: Axis   # the texture's s (columns) in world space: the face view's right
    t_axis: Axis   # the texture's t (rows): the face view's up


FACE_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
CUBE_FACES = (
    CubeFace((1.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, -1.0, 0.0)),
    CubeFace((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)),
    CubeFace((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    CubeFace((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
    CubeFace((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (0.0, -1.0, 0.0)),
    CubeFace((0.0, 0.0, -1.0), (-1.0, 0.0, 0.0), (0.0, -1.0, 0.0)),
)


def face_directions(face: int, size: int) -> np.ndarray:
    """Unit directions of the texel centres of one face, shape (size, size, 3), row = t."""
    c = (np.arange(size, dtype=np.float64) + 0.5) / size * 2.0 - 1.0
    t, s = np.meshgrid(c, c, indexing="ij")
    forward, s_axis, t_axis = (np.array(axis, np.float64) for axis in CUBE_FACES[face])
    v = forward + s[..., None] * s_axis + t[..., None] * t_axis
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def face_texels(directions: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The face, row (t) and column (s) of the texel of a ``size``-texel cube map that each
    unit direction (n, 3) falls in: the inverse of ``face_directions`` (GL's face selection:
    the largest component's axis, ties to x before y before z)."""
    d = np.asarray(directions, np.float64)
    axis = np.argmax(np.abs(d), axis=1)
    face = axis * 2 + (d[np.arange(len(d)), axis] < 0.0)
    table = np.array(CUBE_FACES, np.float64)[face]           # (n, 3 axes, 3)
    major = np.abs(np.einsum("nk,nk->n", d, table[:, 0]))
    s = np.einsum("nk,nk->n", d, table[:, 1]) / major
    t = np.einsum("nk,nk->n", d, table[:, 2]) / major
    column = np.clip(((s + 1.0) * 0.5 * size).astype(int), 0, size - 1)
    row = np.clip(((t + 1.0) * 0.5 * size).astype(int), 0, size - 1)
    return face, row, column


def glsl_defines() -> dict[str, str]:
    """``CUBE_FACE_FORWARD``, ``CUBE_FACE_S`` and ``CUBE_FACE_T``: the table's three columns
    as GLSL ``vec3[6]`` constructors, indexed by face."""
    def column(index: int) -> str:
        return "vec3[6](" + ", ".join(
            "vec3(" + ", ".join(f"{float(c):.1f}" for c in face[index]) + ")" for face in CUBE_FACES) + ")"

    return {"CUBE_FACE_FORWARD": column(0), "CUBE_FACE_S": column(1), "CUBE_FACE_T": column(2)}
