"""A decal's mesh: the triangles of the surfaces in its box, cut to the box (mesh decals,
as the Source engine and Unity's mesh-decal tools make them, rather than a deferred
renderer's projected boxes: this engine shades forward, and a mesh is drawn by the scene
pass every view already draws, lit and shadowed as the surface under it).

Everything here is in the decal's box space, where the box is the cube [-0.5, 0.5]^3 and
the image is thrown along -z.  Triangles are cut by each of the box's six planes in turn
(Sutherland-Hodgman on a whole soup at once: a triangle with one vertex inside becomes one
triangle, with two a quad of two, each case a handful of array operations for every
triangle it applies to), with the attributes interpolated along the cut edges; where the
decal fades towards the box's ends, the triangles are split at the fade's inner planes too,
so the fade, carried as each vertex's alpha, is exactly linear across each piece.

A vertex carries its position, its normal in box space (what the part's normal matrix turns
back into the surface's own world normal) and ``facing``: the cosine between the surface's
world normal and the direction the decal comes from.  Its UVs and alpha come from where it
ends up: UV from x and y (``region`` of the image), alpha from the angle fade (by
``facing``) times the depth fade (by z).  No GL here."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Attributes of a vertex in the soup: position (3), box-space normal (3), facing (1).
_POSITION, _NORMAL, _FACING = slice(0, 3), slice(3, 6), 6
_ATTRIBUTES = 7
# A piece whose area (in box space) is below this is dropped: a sliver a cut left along an edge.
_SLIVER = 1e-12


@dataclass(frozen=True)
class DecalGeometry:
    """A decal's triangles, unindexed (three vertices a triangle), in box space."""

    positions: np.ndarray  # (V, 3) float32
    normals: np.ndarray    # (V, 3) float32, unit
    uvs: np.ndarray        # (V, 2) float32
    alphas: np.ndarray     # (V,) float32 in [0, 1]: the fades

    @property
    def triangle_count(self) -> int:
        return len(self.positions) // 3


def join_geometry(pieces: list[DecalGeometry]) -> DecalGeometry | None:
    """Pieces cut from several surfaces as one geometry (None for none)."""
    if not pieces:
        return None
    if len(pieces) == 1:
        return pieces[0]
    return DecalGeometry(*(np.concatenate([getattr(p, name) for p in pieces])
                           for name in ("positions", "normals", "uvs", "alphas")))


def soup(positions: np.ndarray, normals: np.ndarray, facing: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """The triangles of a mesh as a soup, (T, 3, 7): ``positions`` and ``normals`` (V, 3) in
    box space, ``facing`` (V,), ``indices`` (T, 3)."""
    vertices = np.concatenate([positions, normals, facing[:, None]], axis=1).astype(np.float64)
    return vertices[indices]


def in_box(triangles: np.ndarray) -> np.ndarray:
    """Which triangles of a soup may reach into the box (their vertices' bounds meet it)."""
    p = triangles[:, :, _POSITION]
    return (p.min(axis=1) <= 0.5).all(axis=1) & (p.max(axis=1) >= -0.5).all(axis=1)


def clip_plane(triangles: np.ndarray, axis: int, side: float, offset: float) -> np.ndarray:
    """The parts of a soup's triangles where ``side * p[axis] <= offset``, as a soup, each
    triangle's winding kept."""
    if not len(triangles):
        return triangles
    d = side * triangles[:, :, axis] - offset  # <= 0: inside
    inside = d <= 0.0
    if inside.all():  # (the usual case past the first planes: nothing to cut)
        return triangles
    count = inside.sum(axis=1)
    whole = triangles[count == 3]
    pieces = [whole]
    for kept, lone_inside in ((1, True), (2, False)):
        chosen = count == kept
        if not chosen.any():
            continue
        tri, dist, inn = triangles[chosen], d[chosen], inside[chosen]
        # Turn each triangle (keeping its winding) so its lone vertex (the one inside, or the
        # one outside) comes first.
        lone = np.argmax(inn if lone_inside else ~inn, axis=1)
        order = (lone[:, None] + np.arange(3)[None, :]) % 3
        rows = np.arange(len(tri))[:, None]
        tri, dist = tri[rows, order], dist[rows, order]
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        da, db, dc = dist[:, 0:1], dist[:, 1:2], dist[:, 2:3]
        ab = a + (b - a) * (da / (da - db))  # where edge a-b crosses the plane
        ac = a + (c - a) * (da / (da - dc))
        if lone_inside:  # a inside: the corner a, ab, ac
            pieces.append(np.stack([a, ab, ac], axis=1))
        else:            # a outside: the quad ab, b, c, ac
            pieces.append(np.stack([ab, b, c], axis=1))
            pieces.append(np.stack([ab, c, ac], axis=1))
    return np.concatenate(pieces) if len(pieces) > 1 else whole


def split_plane(triangles: np.ndarray, axis: int, value: float) -> np.ndarray:
    """A soup with every triangle crossing the plane ``p[axis] = value`` cut in two along it."""
    return np.concatenate([clip_plane(triangles, axis, 1.0, value), clip_plane(triangles, axis, -1.0, -value)])


def clip_to_box(triangles: np.ndarray, depth_fade: float = 0.0) -> np.ndarray:
    """A soup cut to the box's six planes; with ``depth_fade`` > 0, split at z = +-(0.5 -
    depth_fade) as well (where the fade ends)."""
    triangles = triangles[in_box(triangles)]
    for axis in range(3):
        for side in (1.0, -1.0):
            triangles = clip_plane(triangles, axis, side, 0.5)
    if 0.0 < depth_fade < 0.5:
        for value in (0.5 - depth_fade, depth_fade - 0.5):
            triangles = split_plane(triangles, 2, value)
    return triangles


def angle_fade(facing: np.ndarray, start: float, end: float) -> np.ndarray:
    """1 where a surface faces the decal within ``start`` degrees, 0 past ``end``, linear in
    the angle between."""
    angle = np.degrees(np.arccos(np.clip(facing, -1.0, 1.0)))
    if end <= start:
        return (angle <= end).astype(np.float64)
    return np.clip((end - angle) / (end - start), 0.0, 1.0)


def depth_fade_of(z: np.ndarray, depth_fade: float) -> np.ndarray:
    """1 inside the box's depth, falling linearly to 0 over ``depth_fade`` of it at each end."""
    if depth_fade <= 0.0:
        return np.ones_like(z)
    return np.clip((0.5 - np.abs(z)) / depth_fade, 0.0, 1.0)


def decal_geometry(triangles: np.ndarray, angle_range: tuple[float, float], depth_fade: float,
                   region: tuple[float, float, float, float]) -> DecalGeometry | None:
    """A soup (``soup``) cut to the box, with UVs and fades: the decal's geometry, or None
    where nothing of it is left (no surface in the box faces it, or every piece faded out)."""
    # Triangles turned away past the fade's end at every vertex take none of it: left out
    # before any cut.
    least = math.cos(math.radians(angle_range[1]))
    triangles = triangles[(triangles[:, :, _FACING] > least).any(axis=1)]
    triangles = clip_to_box(triangles, depth_fade)
    if not len(triangles):
        return None
    p = triangles[:, :, _POSITION]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    triangles = triangles[area > _SLIVER]
    vertices = triangles.reshape(-1, _ATTRIBUTES)
    alphas = angle_fade(vertices[:, _FACING], *angle_range) * depth_fade_of(vertices[:, 2], depth_fade)
    kept = (alphas.reshape(-1, 3) > 0.0).any(axis=1)  # a piece with none of it at any corner: dropped
    if not kept.any():
        return None
    vertices = triangles[kept].reshape(-1, _ATTRIBUTES)
    alphas = alphas.reshape(-1, 3)[kept].reshape(-1)
    normals = vertices[:, _NORMAL]
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.maximum(lengths, 1e-30)
    u0, v0, u1, v1 = region
    uvs = np.stack([u0 + (vertices[:, 0] + 0.5) * (u1 - u0), v0 + (vertices[:, 1] + 0.5) * (v1 - v0)], axis=1)
    return DecalGeometry(np.ascontiguousarray(vertices[:, _POSITION], np.float32),
                         np.ascontiguousarray(normals, np.float32), np.ascontiguousarray(uvs, np.float32),
                         np.ascontiguousarray(alphas, np.float32))
