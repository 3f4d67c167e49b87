"""Prepare: upload what the extract stage changed, before any view is drawn.

Only the instance rows written this frame go to the GPU, the lights when their block
changes (worked out again only when a light came, went, changed or moved), the sky's cube
map when the Skybox changes.
"""
from __future__ import annotations

import esper

from components import DirectionalLight, PointLight, Skybox, Transform
from engine.core.world import World
from engine.render.renderer import Renderer
from engine.render.sky import build_faces
from engine.render.views import lights_block

AMBIENT = (0.03, 0.03, 0.035)


class PrepareSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self._lights = b""

    def process(self, dt: float) -> None:
        world = self.world
        renderer = self.renderer
        if world.changed(Skybox):
            skies = world.query_one(Skybox)
            renderer.set_sky_faces(build_faces(skies[0][1]) if skies else None)
        renderer.upload_instances()
        if self._lights and self._lights_stand_still():
            return
        directional = [(light.direction, light.color.xyz * light.intensity)
                       for _, light in world.query_one(DirectionalLight)]
        point = [(t.world[3].xyz, light.range, light.color.xyz * light.intensity)
                 for _, (light, t) in world.query(PointLight, Transform)]
        block = lights_block(AMBIENT, directional, point)
        if block != self._lights:
            renderer.set_lights(block)
            self._lights = block

    def _lights_stand_still(self) -> bool:
        """No light came, went or changed, and no point light moved (its own Transform or a
        parent's: the transform stage lists both in ``frame.moved``): last frame's block holds."""
        world = self.world
        if world.changed(DirectionalLight) or world.changed(PointLight):
            return False
        moved = world.frame.moved
        return not moved or not any(entity in moved for entity, _ in world.query_one(PointLight))
