"""Spawning entities from mesh files: one entity per mesh part, under one root entity."""
from __future__ import annotations

from pathlib import Path

import glm

from components import Emissive, Material, MeshRef, Reflective, Transform
from engine.mesh import load_model
from engine.world import World


def spawn_model(world: World, path: str | Path, position=(0.0, 0.0, 0.0), rotation=None,
                scale=(1.0, 1.0, 1.0)) -> int:
    """Load ``path`` and spawn it; returns the root entity.

    The file's material decides the components (seed 002): an emissive colour gives
    Emissive(emissive / diffuse); reflectivity > 0 gives Reflective.  The file is fully
    loaded before anything is spawned, so a bad file leaves the world untouched.
    """
    parts = load_model(path)
    root = world.spawn(Transform(position=position, rotation=rotation or glm.quat(), scale=scale))
    for part in parts:
        scale_v, rotation_q, translation, _skew, _persp = glm.vec3(), glm.quat(), glm.vec3(), glm.vec3(), glm.vec4()
        glm.decompose(part.local, scale_v, rotation_q, translation, _skew, _persp)
        components = [
            Transform(position=translation, rotation=rotation_q, scale=scale_v, parent=root),
            MeshRef(part.mesh),
            Material(color=part.color, texture=part.texture, metallic=part.metallic, roughness=part.roughness),
        ]
        if part.emissive_factor > 0.0:
            components.append(Emissive(part.emissive_factor))
        if part.reflectivity > 0.0:
            components.append(Reflective(mode="skybox", mix=part.reflectivity))
        world.spawn(*components)
    return root
