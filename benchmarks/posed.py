"""Posed meshes in the benchmark ring: what animated skinned and morphed meshes cost a frame.

``PosedRing(mirrors, posed)``: the mirror ring (``benchmarks.mirrors.MirrorRing``) with
``posed`` tentacles round its centre, each a 4-joint skinned tube with one morph target,
posed every frame by the game's update (a wave up its joints, its bulb breathing), as a
game's animated characters are.  ``python -m benchmarks ab OLD NEW --scenes posed_8_4`` or
``cpu``'s ``make_scene("posed_8_4")``: against ``mirrors_8`` it is what four animated meshes
add (their poses written to the pose texture, their rows and boxes each frame, their shadows
redrawn, their own batches drawn in every view).
"""
from __future__ import annotations

import math

import numpy as np

from benchmarks.mirrors import MirrorRing
from components import Material, MeshRef, Morph, Skin, Transform
from engine import World
from engine.assets.mesh import Mesh

JOINTS, SPACING = 4, 0.5


def tentacle(rings: int = 24, sides: int = 12) -> Mesh:
    """A 2 m tube narrowing to a point, each vertex following the two joints about it; one
    morph target swells a bulb below its tip."""
    y = np.repeat(np.linspace(0.0, 2.0, rings + 1), sides)
    angle = np.tile(np.linspace(0.0, 2 * math.pi, sides, endpoint=False), rings + 1)
    normals = np.stack([np.cos(angle), np.zeros_like(y), np.sin(angle)], axis=1)
    positions = normals * (0.16 * (1.0 - (y / 2.0) ** 2))[:, None] + np.stack([0 * y, y, 0 * y], axis=1)
    quads = [(r * sides + s, r * sides + (s + 1) % sides) for r in range(rings) for s in range(sides)]
    triangles = [t for a, b in quads for t in ((a, b + sides, b), (a, a + sides, b + sides))]
    along = np.minimum(y / SPACING, JOINTS - 1.0001)
    below = np.floor(along).astype(int)
    swell = normals * (0.14 * np.exp(-(((y - 1.6) / 0.18) ** 2)))[:, None]
    return Mesh(positions, normals, np.stack([angle / (2 * math.pi), y / 2.0], axis=1), triangles,
                name="tentacle", joints=np.stack([below, below + 1], axis=1),
                weights=np.stack([1.0 - (along - below), along - below], axis=1), morph_positions=swell[None])


def pose(angles: list[float]) -> np.ndarray:
    """Each joint's matrix: its place down the chain (each turned about z on top of the one
    below) times its inverse bind matrix."""
    matrices, placed = [], np.eye(4)
    for k, angle in enumerate(angles):
        c, s = math.cos(angle), math.sin(angle)
        placed = placed @ np.array([[c, -s, 0, 0], [s, c, 0, SPACING if k else 0.0], [0, 0, 1, 0], [0, 0, 0, 1]])
        back = np.eye(4)
        back[1, 3] = -SPACING * k
        matrices.append(placed @ back)
    return np.stack(matrices)


class PosedRing(MirrorRing):
    """The ring of ``mirrors`` mirrors with ``posed`` animated tentacles about its centre."""

    title = "benchmark: posed meshes"

    def __init__(self, mirrors: int, posed: int, skinning: str = "linear") -> None:
        super().__init__(mirrors)
        self.posed = posed
        self.skinning = skinning   # Skin.skinning: "dual_quaternion" for posed_<m>_<n>_dq
        self.tentacles: list[tuple[Skin, Morph, float]] = []

    def build(self, world: World) -> None:
        super().build(world)
        mesh = tentacle()
        for i in range(self.posed):
            a = 2.0 * math.pi * i / max(self.posed, 1)
            skin, morph = Skin(pose([0.0] * JOINTS), skinning=self.skinning), Morph((0.0,))
            world.spawn(Transform(position=(2.5 * math.cos(a), 0.0, 2.5 * math.sin(a))), MeshRef(mesh),
                        Material(color=(0.55, 0.2, 0.6)), skin, morph)
            self.tentacles.append((skin, morph, float(i)))

    def update(self, world: World, dt: float) -> None:
        super().update(world, dt)
        for skin, morph, phase in self.tentacles:
            skin.joint_matrices = pose([0.45 * math.sin(1.8 * self.time + phase - 0.9 * k) for k in range(JOINTS)])
            morph.weights = (0.5 + 0.5 * math.sin(3.0 * self.time + phase),)
