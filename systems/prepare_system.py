"""Prepare: upload what the extract stage changed, before any view is drawn.

Only the instance rows written this frame go to the GPU, the lights when their block
changes (worked out again only when a light came, went, changed or moved, or the sky
changed), the sky's cube map when the Skybox changes.

Ambient light (``engine/render/irradiance.py``): the sky's irradiance as nine
spherical-harmonic coefficients in the Lights block, projected from the Skybox's faces when
the Skybox changes; without a Skybox, the ``HemisphereLight``'s (a dim default without one).
Lights past the block's slots (``MAX_DIRECTIONAL_LIGHTS`` directional and
``MAX_POINT_LIGHTS`` point lights: the first made of each kind are kept) light nothing: they
are counted in ``RenderStats.lights_cut`` every frame, and a ``LightLimitWarning`` names
them when the count goes up.
The probes' influence boxes go to the irradiance table when a probe comes, goes, changes or
moves; their coefficients are projected on the GPU after each capture (the probes stages).
"""
from __future__ import annotations

import warnings

import esper
import numpy as np

from components import DirectionalLight, HemisphereLight, PointLight, ReflectionProbe, Skybox, Transform
from components.ambient import DEFAULT_GROUND, DEFAULT_SKY
from engine.core.errors import LightLimitWarning
from engine.core.world import World
from engine.render.irradiance import hemisphere_sh, project_faces
from engine.render.renderer import Renderer
from engine.render.sky import build_faces
from engine.render.views import MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS, lights_block


def ambient_sh(world: World, faces: np.ndarray | None = None) -> np.ndarray:
    """The world's sky irradiance coefficients (9, 3): the Skybox's, the one the sky pass
    draws (``faces``: its built faces, if at hand), else the lowest entity's HemisphereLight, else the default dim
    hemisphere (``components.ambient.DEFAULT_SKY`` and ``DEFAULT_GROUND``)."""
    skies = world.query_one(Skybox)
    if skies:
        return project_faces(build_faces(skies[0][1]) if faces is None else faces)
    hemispheres = world.query_one(HemisphereLight)
    if hemispheres:
        light = min(hemispheres, key=lambda pair: pair[0])[1]
        return hemisphere_sh(light.sky.xyz * light.intensity, light.ground.xyz * light.intensity)
    return hemisphere_sh(DEFAULT_SKY, DEFAULT_GROUND)


class PrepareSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self._lights = b""
        self._sky_sh: np.ndarray | None = None
        self._cut = (0, 0)   # (directional, point) lights the last block left out

    def process(self, dt: float) -> None:
        world = self.world
        renderer = self.renderer
        sky_changed = world.changed(Skybox)
        if sky_changed:
            skies = world.query_one(Skybox)
            faces = build_faces(skies[0][1]) if skies else None
            renderer.set_sky_faces(faces)
            self._sky_sh = ambient_sh(world, faces)
        elif self._sky_sh is None or world.changed(HemisphereLight):
            self._sky_sh = ambient_sh(world)
            sky_changed = True
        renderer.upload_instances()
        self._probe_boxes()
        if not (self._lights and not sky_changed and self._lights_stand_still()):
            directional = [(light.direction, light.color.xyz * light.intensity)
                           for _, light in world.query_one(DirectionalLight)]
            point = [(t.world[3].xyz, light.range, light.color.xyz * light.intensity)
                     for _, (light, t) in world.query(PointLight, Transform)]
            block = lights_block(self._sky_sh, directional, point)
            if block != self._lights:
                renderer.set_lights(block)
                self._lights = block
            self._count_cut(len(directional), len(point))
        renderer.stats.lights_cut = sum(self._cut)

    def _count_cut(self, directional: int, point: int) -> None:
        """Keep how many lights of each kind the block left out; warn when either grows."""
        cut = (max(directional - MAX_DIRECTIONAL_LIGHTS, 0), max(point - MAX_POINT_LIGHTS, 0))
        if cut[0] > self._cut[0] or cut[1] > self._cut[1]:
            warnings.warn(LightLimitWarning(
                f"{directional} directional and {point} point lights: at most {MAX_DIRECTIONAL_LIGHTS} directional "
                f"and {MAX_POINT_LIGHTS} point lights light the scene (the first made of each kind), so {cut[0]} "
                f"directional and {cut[1]} point lights light nothing (RenderStats.lights_cut)"), stacklevel=2)
        self._cut = cut

    def _probe_boxes(self) -> None:
        """The influence boxes to the irradiance table when a probe came, went, changed or
        moved (a box is where its entity is now, as ``probe_rules.probe_blend`` weighs it)."""
        world = self.world
        probes = world.query(ReflectionProbe, Transform)
        if not world.changed(ReflectionProbe) and not world.deleted() and not any(
                entity in world.frame.moved for entity, _ in probes):
            return
        self.renderer.irradiance.set_boxes(
            (entity, tuple(t.world[3].xyz), tuple(probe.influence), probe.blend_distance)
            for entity, (probe, t) in probes if probe.influence is not None)

    def _lights_stand_still(self) -> bool:
        """No light came, went or changed, and no point light moved (its own Transform or a
        parent's: the transform stage lists both in ``frame.moved``): last frame's block holds."""
        world = self.world
        if world.changed(DirectionalLight) or world.changed(PointLight):
            return False
        moved = world.frame.moved
        return not moved or not any(entity in moved for entity, _ in world.query_one(PointLight))
