"""Decals in the benchmark ring: what decals cost a frame.

``DecalRing(mirrors, decals)``: the mirror ring (``benchmarks.mirrors.MirrorRing``) with
``decals`` stains thrown down onto its floor, spread over the ring's middle, so some lie
over the ring's boxes and some over the spinning ones (cut again every frame they turn).
``python -m benchmarks ab OLD NEW --scenes decals_8_32`` or ``cpu``'s
``make_scene("decals_8_32")``: against ``mirrors_8`` it is what the decals add (the decals
stage's look at the frame's movers, the cuts of the ones over spinning boxes, and a draw a
decal a view).
"""
from __future__ import annotations

import math

import numpy as np
from pyglm import glm

from benchmarks.mirrors import SEED, MirrorRing
from components import Decal, Transform, look_rotation
from engine import World
from engine.assets.texture_data import puff_texture

DOWN = look_rotation(glm.vec3(0.0, -1.0, 0.0), glm.vec3(0.0, 0.0, -1.0))  # looking at the floor


class DecalRing(MirrorRing):
    """The ring of ``mirrors`` mirrors with ``decals`` stains on its floor and boxes."""

    title = "benchmark: decals"

    def __init__(self, mirrors: int, decals: int) -> None:
        super().__init__(mirrors)
        self.decals = decals

    def build(self, world: World) -> None:
        super().build(world)
        rng = np.random.default_rng(SEED + 1)
        stain = puff_texture(64, 5)
        for _ in range(self.decals):
            radius = 8.0 * math.sqrt(rng.uniform(0.0, 1.0))
            theta = rng.uniform(0.0, 2.0 * math.pi)
            size = float(rng.uniform(1.0, 2.5))
            world.spawn(Transform(position=(radius * math.cos(theta), 0.5, radius * math.sin(theta)),
                                  rotation=glm.angleAxis(float(theta), glm.vec3(0.0, 1.0, 0.0)) * DOWN,
                                  scale=(size, size, 2.5)),
                        Decal(texture=stain, color=(0.1, 0.06, 0.03, 0.8)))
