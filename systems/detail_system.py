"""Levels of detail: each ``LevelOfDetail`` entity's mesh chosen by its distance from the
nearest eye, before the extract stage reads the meshes.

The eyes are the active camera's, now, and those of last frame's mirror and portal views
that showed a share of the screen (``light_rules.view_eyes``: the reflect stage publishes
them); the distance is to the centre of the finest mesh's box, placed by the entity's world
matrix.  A level changes only when ``LevelOfDetail.level_at`` says so (further out at once,
finer past the hysteresis band), and only then is ``MeshRef.mesh`` written: the extract stage
moves the entity to its new mesh's batch, and a still frame writes nothing.
"""
from __future__ import annotations

import esper
import numpy as np
from pyglm import glm

from components import MeshRef, Transform
from components.detail import LevelOfDetail
from engine.core.world import World
from engine.rules.frame_rules import frame_rules
from engine.rules.light_rules import view_eyes


class DetailSystem(esper.Processor):
    """Picks each LevelOfDetail entity's mesh."""

    def __init__(self, world: World) -> None:
        super().__init__()
        self.world = world
        self.levels: dict[int, int] = {}  # entity -> the level its MeshRef holds
        self._centres: dict[int, tuple[object, glm.vec3]] = {}  # id(mesh) -> (the mesh, its box's middle)

    def process(self, dt: float) -> None:
        world = self.world
        chosen = world.query(LevelOfDetail, MeshRef)
        if not chosen:
            self.levels.clear()
            return
        eyes = self._eyes()
        changed = world.changed(LevelOfDetail)
        for entity, (detail, mesh_ref) in chosen:
            transform = world.try_get(entity, Transform)
            centre = self._centre(detail.meshes[0])
            where = glm.vec3(transform.world * glm.vec4(centre, 1.0)) if transform is not None else centre
            distance = float(np.sqrt(((eyes - np.array(where)) ** 2).sum(axis=1)).min()) if len(eyes) else 0.0
            current = self.levels.get(entity, 0)
            if entity in changed:  # (new meshes or distances: chosen afresh)
                current = min(current, len(detail.meshes) - 1)
            level = detail.level_at(distance, current)
            if mesh_ref.mesh is not detail.meshes[level]:
                mesh_ref.mesh = detail.meshes[level]
            self.levels[entity] = level
        if len(self.levels) > len(chosen):
            alive = {entity for entity, _ in chosen}
            for entity in [e for e in self.levels if e not in alive]:
                del self.levels[entity]

    def _centre(self, mesh) -> glm.vec3:
        """The middle of ``mesh``'s box (its model space), worked out once a mesh."""
        kept = self._centres.get(id(mesh))
        if kept is None or kept[0] is not mesh:
            low, high = mesh.bounds
            kept = self._centres[id(mesh)] = (mesh, glm.vec3(*((low + high) * 0.5)))
        return kept[1]

    def _eyes(self) -> np.ndarray:
        """The active camera's eye and last frame's mirror and portal views' (n, 3)."""
        world = self.world
        points = [point[:3] for point in view_eyes(world)]
        camera = frame_rules(world).active_camera
        transform = world.try_get(camera, Transform) if camera is not None else None
        if transform is not None:
            points.append(tuple(glm.vec3(transform.world[3])))
        return np.array(points, np.float64).reshape(-1, 3)
