"""Things partly through a portal (the visible seam where an object crosses a portal): sliced, with a clone beyond.

A Traveller whose meshes (its own and every one below it: a model's parts, a decal's cut, a
held lamp's bulb; ``TransformTree``, with this frame's new links) straddle an open portal's
rectangle in the box about them all (open as ``engine.rules.frame_rules.open_portal_pairs``
says, the rule travel and the views use: a portal with a disabled, deleted or
Transform-less partner slices nothing), its origin in front of it (a portal is one-way: a
thing pushed into its back is not going through and is drawn whole), has each of those
meshes drawn only in front of that portal (a Slice clip plane), a part already wholly
through too, and a clone of each, carried by the pair transform, draws what went through in
front of the partner.  Clones are made when straddling starts and deleted when it ends, so
entities are not spawned every frame.  It runs before the TransformSystem (on this frame's
poses) so clones get their world matrices this frame.
"""
from __future__ import annotations

from dataclasses import replace

import esper
import numpy as np
from pyglm import glm

from components import (
    Emissive,
    FromDecal,
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
from engine.core.portal_math import decompose_pose, pair_transform, portal_plane
from engine.core.skinning import posed_bounds
from engine.core.transforms import current_world_matrix
from engine.core.world import TransformTree, World
from engine.rules.frame_rules import frame_rules, world_corners

# What a clone copies from its source to look as it does (kept the same while it lasts: a
# decal's cut, FromDecal, is drawn as one); where it is drawn (Visibility) and whether it
# casts shadows (MeshRef) its row reads off the source.
CLONE_LOOKS = (Material, Emissive, Reflective, Refractive, FromDecal)


class PortalSliceSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self.clones: dict[int, int] = {}   # source entity (a traveller or a part below it) -> its clone

    def process(self, dt: float) -> None:
        world = self.world
        portals = self._open_portals()
        tree = world.resources.get(TransformTree)
        changes = (world.changed(Skin), world.changed(Morph), world.changed(MeshRef),
                   [(kind, world.changed(kind)) for kind in CLONE_LOOKS])
        sliced = set()  # the parts cut this frame: they keep their clones
        linked = None  # this frame's parent links (the transform stage, after this one, has not seen them)
        for root, (_, transform) in world.query(Traveller, Transform) if portals else ():
            if linked is None:
                linked = self._linked_now()
            # (a traveller below another that straddles is already cut with it: its parts once)
            parts = [part for part in self._parts(root, transform, tree, linked) if part[0] not in sliced]
            if not parts:
                continue
            straddled = self._straddled(glm.vec3(current_world_matrix(world, transform)[3]), parts, portals)
            if straddled is None:
                continue
            plane, carry, exit_plane, portal = straddled
            for part, mesh_ref, model, skin, morph in parts:
                sliced.add(part)
                self._slice(part, plane)
                clone = self._clone(part, mesh_ref, skin, morph, portal, changes)
                clone_t = world.get(clone, Transform)
                clone_t.position, clone_t.rotation, clone_t.scale = decompose_pose(carry * model)
                self._slice(clone, exit_plane)
        # Out of the portal, deleted, or no longer a traveller's part with a mesh and a place:
        # whole again, and its clone goes.
        for source in [s for s in self.clones if s not in sliced]:
            self._release(source)

    def _linked_now(self) -> dict[int, set[int]]:
        """The children given a parent this frame, by parent (a model spawned this frame: its
        parts), which ``TransformTree`` holds from the transform stage on."""
        world = self.world
        linked: dict[int, set[int]] = {}
        for entity in world.changed(Transform):
            transform = world.try_get(entity, Transform) if world.exists(entity) else None
            if transform is not None and transform.parent is not None:
                linked.setdefault(transform.parent, set()).add(entity)
        return linked

    def _parts(self, root: int, transform: Transform, tree: TransformTree | None,
               linked: dict[int, set[int]]) -> list[tuple]:
        """(entity, MeshRef, world matrix, Skin, Morph) of the traveller ``root`` and of each
        entity below it with a mesh (a model's parts, a decal's cut, a held lamp's bulb): what
        goes through a portal with it, sliced and cloned together.  Skin and Morph only where
        the mesh is posed by them."""
        world = self.world
        found = []
        below = tree.descendants(root, linked) if tree is not None else TransformTree(linked).descendants(root)
        inside = {root}  # the entities found below the root by their parents now (the tree is last frame's links)
        for entity in (root, *below):
            part_t = transform if entity == root else world.try_get(entity, Transform)
            if entity != root:
                if part_t is None or part_t.parent not in inside:
                    continue  # taken from under the root this frame (the tree keeps its old link until the transforms)
                inside.add(entity)
            mesh_ref = world.try_get(entity, MeshRef)
            if mesh_ref is None or part_t is None or not world.exists(entity) or world.has(entity, PortalClone):
                continue
            mesh = mesh_ref.mesh
            found.append((entity, mesh_ref, current_world_matrix(world, part_t),
                          world.try_get(entity, Skin) if mesh.skinned else None,
                          world.try_get(entity, Morph) if mesh.morph_count else None))
        return found

    def _clone(self, part: int, mesh_ref: MeshRef, skin: Skin | None, morph: Morph | None, portal: int,
               changes: tuple) -> int:
        """The part's clone beyond the partner: made when it starts to straddle (again, for a
        new mesh: a level of detail), then kept looking and posed as its source is."""
        world = self.world
        bent, morphs, meshes, restyled = changes
        clone = self.clones.get(part)
        if clone is not None and world.exists(clone) and part in meshes \
                and world.get(clone, MeshRef).mesh is not mesh_ref.mesh:
            world.delete_entity(clone)
        if clone is None or not world.exists(clone):
            clone = self.clones[part] = self._spawn_clone(part, mesh_ref, portal)
            return clone
        for kind, changed in restyled:
            if part in changed:
                self._copy_look(part, clone, kind)
        if skin is not None and part in bent:
            world.get(clone, Skin).joint_matrices = skin.joint_matrices
        if morph is not None and part in morphs:
            world.get(clone, Morph).weights = morph.weights
        return clone

    def _open_portals(self) -> list[tuple[int, Portal, glm.mat4, glm.mat4]]:
        """(portal, its Portal, its world matrix, its partner's) of every open pair."""
        world = self.world
        return [(entity, world.get(entity, Portal), current_world_matrix(world, world.get(entity, Transform)),
                 current_world_matrix(world, world.get(partner, Transform)))
                for entity, partner in frame_rules(world).open_portals.items()]

    @staticmethod
    def _straddled(origin: glm.vec3, parts: list[tuple], portals):
        """(slice plane, carry, partner's plane, portal) of the first portal cutting the box
        about the traveller's parts (each posed mesh's as its Skin and Morph pose it) with the
        traveller's origin in front of it, the point travel carries (or on it): a portal is
        one-way, so a thing pushed into its back is not going through it and is drawn whole,
        with no clone."""
        corners = np.concatenate([
            world_corners(mesh_ref.mesh, model, None if skin is None and morph is None else posed_bounds(
                mesh_ref.mesh, skin.joint_matrices if skin else None, morph.weights if morph else None,
                skin is not None and skin.skinning == "dual_quaternion"))
            for _, mesh_ref, model, skin, morph in parts])
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
