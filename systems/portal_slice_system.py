"""Things partly through a portal (the visible seam where an object crosses a portal): sliced, with a clone beyond.

A Traveller whose bounds straddle an open portal's rectangle (open as
``engine.rules.frame_rules.open_portal_pairs`` says, the rule travel and the views use: a portal
with a disabled, deleted or Transform-less partner slices nothing), its origin in front of it
(a portal is one-way: a thing pushed into its back is not going through and is drawn whole),
is drawn only in front of that portal (a Slice clip plane), and a clone, carried by the
pair transform, draws the part that went through in front of the partner.  Clones are made when straddling starts
and deleted when it ends, so entities are not spawned every frame.  It runs before the
TransformSystem (on this frame's poses) so clones get their world matrices this frame.
"""
from __future__ import annotations

from dataclasses import replace

import esper
import numpy as np
from pyglm import glm

from components import (
    Emissive,
    Material,
    MeshRef,
    Morph,
    Portal,
    PortalClone,
    Reflective,
    Refractive,
    Skin,
    Slice,
    Transform,
    Traveller,
)
from engine.core.portal_math import pair_transform, portal_plane
from engine.core.skinning import posed_bounds
from engine.core.transforms import current_world_matrix
from engine.core.world import World
from engine.rules.frame_rules import frame_rules, world_corners

# What a clone copies from its source to look as it does (kept the same while it lasts); where
# it is drawn (Visibility) and whether it casts shadows (MeshRef) its row reads off the source.
CLONE_LOOKS = (Material, Emissive, Reflective, Refractive)


class PortalSliceSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self.clones: dict[int, int] = {}   # source entity -> its clone

    def process(self, dt: float) -> None:
        world = self.world
        portals = self._open_portals()
        bent, morphs, meshes = world.changed(Skin), world.changed(Morph), world.changed(MeshRef)
        restyled = [(kind, world.changed(kind)) for kind in CLONE_LOOKS]
        travelling = set()
        for entity, (_, mesh_ref, transform) in world.query(Traveller, MeshRef, Transform):
            travelling.add(entity)
            skin = world.try_get(entity, Skin) if mesh_ref.mesh.skinned else None
            morph = world.try_get(entity, Morph) if mesh_ref.mesh.morph_count else None
            straddled = self._straddled(mesh_ref, current_world_matrix(world, transform), portals, skin, morph) \
                if portals else None
            if straddled is None:
                self._release(entity)
                continue
            plane, carry, exit_plane, portal = straddled
            self._slice(entity, plane)
            clone = self.clones.get(entity)
            if clone is not None and world.exists(clone) and entity in meshes \
                    and world.get(clone, MeshRef).mesh is not mesh_ref.mesh:  # a new mesh (a level of detail)
                world.delete_entity(clone)
            if clone is None or not world.exists(clone):
                clone = self.clones[entity] = self._spawn_clone(entity, mesh_ref, portal)
            else:  # looks and is posed as its source does, this frame
                for kind, changed in restyled:
                    if entity in changed:
                        self._copy_look(entity, clone, kind)
                if skin is not None and entity in bent:
                    world.get(clone, Skin).joint_matrices = skin.joint_matrices
                if morph is not None and entity in morphs:
                    world.get(clone, Morph).weights = morph.weights
            clone_t = world.get(clone, Transform)
            position, rotation, scale = _decompose(carry * current_world_matrix(world, transform))
            clone_t.position, clone_t.rotation, clone_t.scale = position, rotation, scale
            self._slice(clone, exit_plane)
        # Deleted, or no longer a Traveller with a mesh and a place: its clone goes too.
        for source in [s for s in self.clones if s not in travelling]:
            self._release(source)

    def _open_portals(self) -> list[tuple[int, Portal, glm.mat4, glm.mat4]]:
        """(portal, its Portal, its world matrix, its partner's) of every open pair."""
        world = self.world
        return [(entity, world.get(entity, Portal), current_world_matrix(world, world.get(entity, Transform)),
                 current_world_matrix(world, world.get(partner, Transform)))
                for entity, partner in frame_rules(world).open_portals.items()]

    @staticmethod
    def _straddled(mesh_ref: MeshRef, model: glm.mat4, portals, skin: Skin | None = None, morph: Morph | None = None):
        """(slice plane, carry, partner's plane, portal) of the first portal cutting the bounds
        (a posed mesh's as its ``skin`` and ``morph`` pose it) with the entity's origin in
        front of it, the point travel carries (or on it): a portal is one-way, so a thing
        pushed into its back is not going through it and is drawn whole, with no clone."""
        mesh = mesh_ref.mesh
        bounds = None if skin is None and morph is None else \
            posed_bounds(mesh, skin.joint_matrices if skin else None, morph.weights if morph else None,
                         skin is not None and skin.skinning == "dual_quaternion")
        corners = world_corners(mesh, model, bounds)
        origin = glm.vec3(model[3])
        for entity, portal, in_world, out_world in portals:
            plane = portal_plane(in_world)
            if glm.dot(glm.vec3(plane), origin) + plane.w < 0.0:
                continue  # behind the portal: it came in by the back, which carries nothing
            distances = corners[:, :3] @ np.array(glm.vec3(plane)) + plane.w
            if distances.min() >= 0.0 or distances.max() <= 0.0:
                continue
            local = corners @ np.array(glm.inverse(in_world).to_list(), np.float64)
            w, h = portal.size
            if local[:, 0].max() < -w / 2 or local[:, 0].min() > w / 2 or local[:, 1].max() < -h / 2 \
                    or local[:, 1].min() > h / 2:
                continue  # passes beside the rectangle, not through it
            return plane, pair_transform(in_world, out_world), portal_plane(out_world), entity
        return None

    def _slice(self, entity: int, plane: glm.vec4) -> None:
        current = self.world.try_get(entity, Slice)
        if current is None:
            self.world.add_component(entity, Slice(plane))
        elif current.plane != plane:
            current.plane = plane

    def _spawn_clone(self, source: int, mesh_ref: MeshRef, portal: int) -> int:
        world = self.world
        components = [Transform(), MeshRef(mesh_ref.mesh), PortalClone(source=source, portal=portal)]
        for kind in CLONE_LOOKS:
            look = world.try_get(source, kind)
            if look is not None:
                components.append(replace(look))  # its own copy: components belong to one entity
        skin = world.try_get(source, Skin) if mesh_ref.mesh.skinned else None
        if skin is not None:  # bent as its source is (kept so each frame its source's pose changes)
            components.append(Skin(skin.joint_matrices))
        morph = world.try_get(source, Morph) if mesh_ref.mesh.morph_count else None
        if morph is not None:
            components.append(Morph(morph.weights))
        return world.spawn(*components)

    def _copy_look(self, source: int, clone: int, kind: type) -> None:
        """The clone's ``kind`` made its source's again (a copy), or taken off with it."""
        world = self.world
        if world.has(clone, kind):
            world.remove_component(clone, kind)
        look = world.try_get(source, kind)
        if look is not None:
            world.add_component(clone, replace(look))

    def _release(self, source: int) -> None:
        world = self.world
        clone = self.clones.pop(source, None)
        if clone is not None and world.exists(clone):
            world.delete_entity(clone)
        if world.exists(source) and world.has(source, Slice):
            world.remove_component(source, Slice)

    def close(self) -> None:
        self.clones.clear()


def _decompose(matrix: glm.mat4) -> tuple[glm.vec3, glm.quat, glm.vec3]:
    scale, rotation, translation = glm.vec3(), glm.quat(), glm.vec3()
    glm.decompose(matrix, scale, rotation, translation, glm.vec3(), glm.vec4())
    return translation, rotation, scale
