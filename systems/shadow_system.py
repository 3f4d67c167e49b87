"""Shadows: which lights' shadow maps are drawn this frame, and drawing them.

A map is made once a frame at most, before any view is drawn, and every view samples it
(main, mirror, portal, probe face), so a shadow looks the same directly, in a mirror and
through a portal.  Maps are cached like probe faces: a directional light's map is drawn
again only when the light changed or a caster changed (an instance row was written: it
moved, came, went or changed its look; the map covers the whole level, so every caster is in
its reach); a point light's only when the light changed or moved, or a caster whose old or
new box reaches into its range changed.  A still scene draws no shadow pass.

It publishes ``ShadowCasters`` (``engine/rules/shadow_rules.py``): the lights casting this
frame, so the probes' scheduler can recapture a face where a moved caster's shadow falls.
"""
from __future__ import annotations

import esper
import numpy as np

from components import DirectionalLight, Material, MeshRef, PointLight, Refractive, Transform, Visibility
from engine.core.world import World
from engine.render.renderer import Renderer
from engine.render.shadows import MAX_POINT_SHADOWS
from engine.render.views import MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS
from engine.rules.probe_rules import world_bounds
from engine.rules.shadow_rules import ShadowCasters, boxes_in_reach, directional_fit

_LOOKS = (MeshRef, Material, Visibility, Refractive)  # what decides whether, and what shape, a thing casts


class ShadowSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.enabled = True   # the debug overlay's toggle: off, no light casts
        self._directional: dict[int, tuple] = {}   # slot -> what its map was drawn from
        self._point: dict[int, tuple] = {}         # cube slot -> what its cube was drawn from
        self._casters_seen = -1
        self._bounds: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # entity -> world box (point lights only)
        self._uploaded = b""
        world.resources[ShadowCasters] = ShadowCasters()

    def process(self, dt: float) -> None:
        renderer = self.renderer
        maps = renderer.shadows
        casters_changed = renderer.casters_version != self._casters_seen
        self._casters_seen = renderer.casters_version
        level = renderer.level_bounds()
        published = ShadowCasters(level=level)
        self._directional_maps(casters_changed, level, published)
        self._point_maps(published)
        self.world.resources[ShadowCasters] = published
        block = maps.block.tobytes()
        if block != self._uploaded:
            maps.upload()
            self._uploaded = block

    # --- directional lights -------------------------------------------------------------------
    def _directional_maps(self, casters_changed: bool, level, published: ShadowCasters) -> None:
        maps = self.renderer.shadows
        stats = self.renderer.stats
        lights = [light for _, light in self.world.query_one(DirectionalLight)][:MAX_DIRECTIONAL_LIGHTS]
        casting = {slot: light for slot, light in enumerate(lights)
                   if self.enabled and light.shadows and level is not None}
        tile = max((light.shadow_resolution for light in casting.values()), default=0)
        if tile:
            maps.fit_atlas(tile)
        for slot in range(MAX_DIRECTIONAL_LIGHTS):
            light = casting.get(slot)
            if light is None:
                if self._directional.pop(slot, None) is not None:
                    maps.clear_directional(slot)
                continue
            published.directional.append(tuple(light.direction))
            key = (tuple(light.direction), light.shadow_resolution, light.shadow_softness, maps.tile, maps.filter,
                   level[0].tobytes(), level[1].tobytes())
            if key == self._directional.get(slot) and not casters_changed:
                stats.shadow_maps_kept += 1
                continue
            fit = directional_fit(light.direction, level[0], level[1], light.shadow_resolution)
            maps.draw_directional(slot, fit, light.shadow_resolution, light.shadow_softness)
            self._directional[slot] = key
            stats.shadow_maps_drawn += 1

    # --- point lights -------------------------------------------------------------------------
    def _point_maps(self, published: ShadowCasters) -> None:
        world = self.world
        maps = self.renderer.shadows
        stats = self.renderer.stats
        lights = [(entity, light, transform) for entity, (light, transform) in world.query(PointLight, Transform)]
        casting = [(index, entity, light, transform) for index, (entity, light, transform) in enumerate(lights)
                   if self.enabled and light.shadows]
        beyond = [row for row in casting if row[0] >= MAX_POINT_LIGHTS]  # not lit at all: the Lights block's limit
        casting = [row for row in casting if row[0] < MAX_POINT_LIGHTS]
        stats.shadows_cut += len(casting[MAX_POINT_SHADOWS:]) + len(beyond)
        casting = casting[:MAX_POINT_SHADOWS]
        maps.clear_points()
        if not casting:
            self._point.clear()
            self._bounds.clear()
            maps.drop_unused_cubes(set())
            return
        changed_lo, changed_hi = self._changed_boxes()
        layered = self.renderer.path_checks.trusted("layered_capture")
        for slot, (index, entity, light, transform) in enumerate(casting):
            position = transform.world[3].xyz
            published.points.append((tuple(position), light.range))
            key = (entity, tuple(position), light.range, light.shadow_resolution, light.shadow_softness, maps.filter)
            reached = len(changed_lo) and boxes_in_reach(changed_lo, changed_hi, np.array(position), light.range).any()
            if key == self._point.get(slot) and not reached:
                maps.keep_point(slot, index)
                stats.shadow_maps_kept += 1
                continue
            stats.shadow_path = maps.draw_point(slot, index, position, light.range, light.shadow_resolution,
                                                light.shadow_softness, layered)
            self._point[slot] = key
            stats.shadow_maps_drawn += 1
        maps.drop_unused_cubes(set(range(len(casting))))
        for slot in [s for s in self._point if s >= len(casting)]:
            del self._point[slot]

    def _changed_boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """The old and new world boxes of every drawable that moved, came, went or changed
        its look this frame (all boxes are measured the first time: every cube is new then)."""
        world = self.world
        frame = world.frame
        if not self._bounds:
            self._bounds = {entity: world_bounds(mesh_ref.mesh, transform.world)
                            for entity, (mesh_ref, transform) in world.query(MeshRef, Transform)}
            return np.zeros((0, 3)), np.zeros((0, 3))
        entities = frame.moved | frame.added | frame.removed | world.deleted()
        for kind in _LOOKS:
            entities |= world.changed(kind)
        boxes = []
        for entity in entities:
            old = self._bounds.pop(entity, None)
            if old is not None:
                boxes.append(old)
            if world.exists(entity):
                mesh_ref, transform = world.try_get(entity, MeshRef), world.try_get(entity, Transform)
                if mesh_ref is not None and transform is not None:
                    new = self._bounds[entity] = world_bounds(mesh_ref.mesh, transform.world)
                    boxes.append(new)
        if not boxes:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return np.array([lo for lo, _ in boxes]), np.array([hi for _, hi in boxes])
