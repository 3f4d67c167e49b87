"""Where an irradiance volume's points are captured from: each grid point, or where it is moved
out of a solid thing it lies inside (a wall, a crate, a pillar).

A probe inside a solid object sees that object's back faces, which are not drawn: it sees
through it, the sky or the next room, and lights what stands by the wall with light from
behind it (the leak every probe grid has at walls: Unity's adaptive probe volumes mark such
probes invalid and move them out, "virtual offset"; DDGI moves its probes likewise).  Here a
point inside an object's box (its mesh's own axis-aligned bounds, in the object's frame: a
box exactly, anything else by its bounds), or nearer to it than ``VIRTUAL_OFFSET_MARGIN`` (a
point on a wall's face sees along the wall and past it), is captured from just outside one of
the box's faces instead (the margin past it, at least twice the capture's near plane:
``capture_margin``): of the ways out of the boxes it is in, those towards the volume's centre
first (a point in a wall goes into the room, not out of it), the nearest of those, one that
leaves it in a box counted a margin longer; still in one, it is moved again from there, up to
``PUSH_ROUNDS`` times (a room's corner, in two or three walls: a wall a round).  The grid point
keeps its place: only its capture is taken from elsewhere.

Solid: an object drawn in probe views whose mesh has thickness along all three of its axes
(a plane, a quad or a mirror has none) and whose material lets nothing through (opaque: no
alpha below 1, no cutout, no refraction).
"""
from __future__ import annotations

import numpy as np

from components import Material, MeshRef, Refractive, Transform, Visibility
from engine.core.world import World

VIRTUAL_OFFSET_MARGIN = 0.05  # metres past the face a moved point is captured from (at least twice the near plane)
PUSH_ROUNDS = 4
MIN_THICKNESS = 1e-4          # a mesh's bounds thinner than this along an axis: not solid


def capture_margin(near: float) -> float:
    """How far past a face a moved point is captured from: ``VIRTUAL_OFFSET_MARGIN``, or twice
    the capture's near plane where that is farther (the face would be clipped away)."""
    return max(VIRTUAL_OFFSET_MARGIN, 2.0 * near)


def solid_boxes(world: World, low: np.ndarray, high: np.ndarray,
                margin: float = VIRTUAL_OFFSET_MARGIN) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The solid objects' boxes whose world bounds reach the box ``low``..``high`` (or come
    within ``margin`` of it): their world matrices (M, 4, 4), mesh bounds' lowest (M, 3) and
    highest (M, 3) corners."""
    low, high = np.asarray(low) - margin, np.asarray(high) + margin
    matrices, lows, highs = [], [], []
    for entity, (transform, ref) in world.query(Transform, MeshRef):
        if ref.mesh is None or world.try_get(entity, Refractive) is not None:
            continue
        seen = world.try_get(entity, Visibility)
        if seen is not None and not seen.in_probes:
            continue
        material = world.try_get(entity, Material)
        if material is not None and (material.color[3] < 1.0 or material.alpha_cutoff is not None):
            continue
        mesh_low, mesh_high = ref.mesh.bounds
        if np.min(mesh_high - mesh_low) <= MIN_THICKNESS:
            continue
        matrix = np.array(transform.world.to_list(), np.float64).T  # glm is column-major
        corners = np.array(np.meshgrid(*zip(mesh_low, mesh_high, strict=True), indexing="ij")).reshape(3, -1).T
        world_corners = corners @ matrix[:3, :3].T + matrix[:3, 3]
        if np.any(world_corners.min(axis=0) > high) or np.any(world_corners.max(axis=0) < low):
            continue
        matrices.append(matrix)
        lows.append(mesh_low)
        highs.append(mesh_high)
    if not matrices:
        return np.zeros((0, 4, 4)), np.zeros((0, 3)), np.zeros((0, 3))
    return np.array(matrices), np.array(lows, np.float64), np.array(highs, np.float64)


def pushed_out(points: np.ndarray, matrices: np.ndarray, lows: np.ndarray, highs: np.ndarray,
               toward: np.ndarray, margin: float = VIRTUAL_OFFSET_MARGIN) -> np.ndarray:
    """Where each of ``points`` (N, 3) is captured from: itself, or, inside a box
    (``solid_boxes``), just outside its nearest face (the module docstring)."""
    points = np.array(points, np.float64)
    if not len(matrices):
        return points
    inverse = np.linalg.inv(matrices)
    toward = np.asarray(toward, np.float64)
    # Within the margin of a box counts as in it (a point on a wall's face sees along it).
    reach = margin / np.maximum(np.linalg.norm(matrices[:, :3, :3], axis=1), 1e-12) * 0.999  # (M, 3) local

    def inside(at: np.ndarray) -> np.ndarray:
        """(K, M): whether each of ``at`` (K, 3) is in (or within the margin of) each box."""
        local = np.einsum("mij,nj->nmi", inverse[:, :3, :3], at) + inverse[:, :3, 3]
        return np.all((local > lows - reach) & (local < highs + reach), axis=-1)

    for _ in range(PUSH_ROUNDS):
        held = inside(points)
        stuck = np.flatnonzero(held.any(axis=1))
        if not len(stuck):
            break
        for n in stuck:
            exits = np.concatenate([_exits(points[n], matrices[m], inverse[m], lows[m], highs[m], margin)
                                    for m in np.flatnonzero(held[n])])
            step = exits - points[n]
            inward = step @ (toward - points[n])
            # Towards the volume's centre first, then the nearest, one still in a box a margin longer.
            away, held_again = inward < -1e-12, inside(exits).any(axis=1)
            score = np.linalg.norm(step, axis=1) + 1e6 * away + margin * held_again - 1e-9 * inward
            points[n] = exits[int(np.argmin(score))]
    return points


def _exits(point: np.ndarray, matrix: np.ndarray, inverse: np.ndarray, low: np.ndarray, high: np.ndarray,
           margin: float) -> np.ndarray:
    """(6, 3): ``point`` moved out of the box through each of its faces, ``margin`` metres past it."""
    local = inverse[:3, :3] @ point + inverse[:3, 3]
    scale = np.linalg.norm(matrix[:3, :3], axis=0)  # metres a local unit along each axis
    moved = np.tile(local, (6, 1))
    for axis in range(3):
        moved[2 * axis, axis] = low[axis] - margin / max(scale[axis], 1e-12)
        moved[2 * axis + 1, axis] = high[axis] + margin / max(scale[axis], 1e-12)
    return moved @ matrix[:3, :3].T + matrix[:3, 3]
