"""Which reflection probe an object samples: worked out from components alone (no GL), so
the extract stage (which builds instance rows) and the probes stage (which captures) agree.

An object with ``Reflective("cube")`` or ``Refractive`` (glass refracts what the probe
saw behind it) samples:
  - its own probe, when it has a ``ReflectionProbe`` component;
  - else, when its mesh is not flat, a probe of its own at its bounding box's centre (made
    by the probes stage; the chrome-sphere case: material detection as in the OpenGL 4
    course chapter "Texture Effects": a flat reflective mesh is a planar mirror, any other
    a cube map);
  - else the probe whose influence box holds its position (the nearest centre if several);
  - else nothing: it reflects the sky.
A probe is known by the entity that owns it (the ReflectionProbe's, or the object's own).
"""
from __future__ import annotations

import numpy as np
from pyglm import glm

from components import MeshRef, ReflectionProbe, Reflective, Refractive, Transform
from engine.frame_rules import world_corners
from engine.mesh import Mesh, flat_plane
from engine.world import World

_FLAT: dict[int, bool] = {}  # mesh id -> flat (meshes do not change once made)


def is_flat(mesh: Mesh) -> bool:
    flat = _FLAT.get(mesh.id)
    if flat is None:
        flat = _FLAT[mesh.id] = flat_plane(mesh) is not None
    return flat


def samples_a_probe(world: World, entity: int) -> bool:
    """Cube-reflective or refractive: what looks up a probe when one serves it."""
    reflective = world.try_get(entity, Reflective)
    return (reflective is not None and reflective.mode == "cube") or world.has(entity, Refractive)


def has_own_probe(world: World, entity: int) -> bool:
    """An automatic probe: a non-flat mesh that samples a probe and has no ReflectionProbe."""
    mesh_ref = world.try_get(entity, MeshRef)
    return (mesh_ref is not None and samples_a_probe(world, entity) and not world.has(entity, ReflectionProbe)
            and not is_flat(mesh_ref.mesh))


def world_bounds(mesh: Mesh, model: glm.mat4) -> tuple[np.ndarray, np.ndarray]:
    """The world AABB of ``mesh`` placed by ``model`` (from ``frame_rules.world_corners``)."""
    world = world_corners(mesh, model)
    return world[:, :3].min(axis=0), world[:, :3].max(axis=0)


def probe_for(world: World, entity: int) -> int:
    """The entity owning the probe ``entity`` samples, or 0 (the sky)."""
    if not samples_a_probe(world, entity):
        return 0
    if world.has(entity, ReflectionProbe) or has_own_probe(world, entity):
        return entity
    transform = world.try_get(entity, Transform)
    if transform is None:
        return 0
    position = np.array(transform.world[3].xyz)
    best, best_distance = 0, np.inf
    for owner, (probe, probe_t) in world.query(ReflectionProbe, Transform):
        if probe.influence is None:
            continue
        centre = np.array(probe_t.world[3].xyz)
        if (np.abs(position - centre) <= np.array(probe.influence) / 2.0).all():
            distance = float(np.linalg.norm(position - centre))
            if distance < best_distance:
                best, best_distance = owner, distance
    return best
