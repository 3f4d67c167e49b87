"""A glasshouse for the ``cpu`` and ``ab`` suites (``glass_<panes>``): what a level with many
see-through things costs a view.

The mirrors benchmark's ring of 8 mirrors, boxes and orbiting camera
(``benchmarks.mirrors.MirrorRing``), and inside the ring a see-through pond (a mirror whose
material is see-through, 5 x 5 m at the centre, reflect rate 0.7) and ``panes`` glass panes
of 1.2 x 1.2 m standing round it (each its own transparent batch: ``Renderer.batch_for``),
on a circle of radius 5 in two rows, facing out.  Every view that sees the pond orders its
transparent slot against the pond's plane (``slot_order.back_to_front``, ``split_slot``):
panes behind the pond by their centres stand above it, in front of it by its plane, so the
order is not the centres' in most views.  ``glass_0`` is the ring with the pond alone.
"""
from __future__ import annotations

import math

from pyglm import glm

from benchmarks.mirrors import MirrorRing
from components import Emissive, Material, MeshRef, Mirror, Transform, look_rotation
from engine.assets.mesh import quad
from engine.core.world import World

GLASS_MIRRORS = 8
POND_SIZE = 5.0
PANE_SIZE = 1.2
PANE_RADIUS = 5.0
PANE_ROWS = (0.8, 2.1)  # the rows' heights (m)
FLAT = glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))  # a quad turned to lie flat, facing up


class GlassHouse(MirrorRing):
    """The mirror ring with a see-through pond and ``panes`` glass panes round it."""

    title = "benchmark: glass"

    def __init__(self, panes: int, mirrors: int = GLASS_MIRRORS) -> None:
        super().__init__(mirrors)
        self.panes = panes

    def build(self, world: World) -> None:
        super().build(world)
        world.spawn(Transform(position=(0.0, 0.05, 0.0), rotation=FLAT), MeshRef(quad(POND_SIZE, POND_SIZE)),
                    Material(color=(0.2, 0.3, 0.6, 0.6)), Mirror(reflect_rate=0.7))
        pane = quad(PANE_SIZE, PANE_SIZE, name="pane")
        columns = max(1, -(-self.panes // len(PANE_ROWS)))
        for i in range(self.panes):
            row, column = divmod(i, columns)
            a = 2.0 * math.pi * (column + 0.5 * row) / columns
            outward = glm.vec3(math.cos(a), 0.0, math.sin(a))
            world.spawn(Transform(position=PANE_RADIUS * outward + glm.vec3(0.0, PANE_ROWS[row], 0.0),
                                  rotation=look_rotation(-outward)),  # +Z (the front) out
                        MeshRef(pane), Material(color=(0.3 + 0.6 * (i % 3) / 2, 0.8, 0.9, 0.35)), Emissive(0.2))
