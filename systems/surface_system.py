"""Surfaces: every mirror and portal as the view trees see them, worked out once a frame.

After the transform stage, the Mirror and Portal components become ``SurfaceState`` rows
(only what changed: a mirror's plane, outline and composite parameters are worked out
again when it moves or its components change; the few portals are redone every frame, as
they depend on their partner's pose too), published as ``world.resources[Surfaces]``: the
probes stage roots view trees at probe faces with them, the reflect stage at the main view.
A Mirror on something that cannot be a mirror is a ``MirrorError`` naming the entity.
"""
from __future__ import annotations

import esper
import numpy as np

from components import Material, MeshRef, Mirror, Portal, Transform
from engine.assets.mesh import flat_plane, planar_uv_map
from engine.core.errors import SpeculumError
from engine.core.portal_math import pair_transform, portal_plane
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix, transform_plane
from engine.core.world import World
from engine.render.mirror_passes import MirrorBumps
from engine.render.view_tree import Surfaces, SurfaceState
from engine.rules.frame_rules import frame_rules, world_corners

# A mirror mesh thinner than this fraction of its size composites over its outline quad;
# anything thicker (a mirror plane given explicitly on a solid mesh) over its rectangle.
FLAT_OUTLINE_TOLERANCE = 1e-3


class MirrorError(SpeculumError, ValueError):
    """A Mirror component on something that cannot be a mirror."""


class SurfaceSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self.mirrors: dict[int, SurfaceState] = {}
        self.portals: dict[int, SurfaceState] = {}

    def process(self, dt: float) -> None:
        self._refresh_mirrors()
        self._refresh_portals()
        self.world.resources[Surfaces] = Surfaces(dict(self.mirrors), dict(self.portals))

    def _refresh_mirrors(self) -> None:
        world = self.world
        touched = world.changed(Mirror) | world.changed(MeshRef)
        touched |= {e for e in world.changed(Material) if e in self.mirrors}  # a normal map given or taken
        touched |= {e for e in world.frame.moved | world.frame.added if e in self.mirrors or e in touched}
        for entity in touched:
            mirror = world.try_get(entity, Mirror) if world.exists(entity) else None
            if mirror is None:
                self.mirrors.pop(entity, None)
                continue
            mesh_ref = world.try_get(entity, MeshRef)
            transform = world.try_get(entity, Transform)
            if mesh_ref is None or transform is None:
                raise MirrorError(f"entity {entity}: a Mirror needs a MeshRef and a Transform")
            self.mirrors[entity] = self._mirror_state(entity, mirror, mesh_ref, transform,
                                                      world.try_get(entity, Material))

    def _refresh_portals(self) -> None:
        """Portals depend on their partner's pose too; there are few, so all are redone."""
        world = self.world
        self.portals = {}
        open_portals = frame_rules(world).open_portals  # the rule travel and slicing use too
        for entity, (portal, transform) in world.query(Portal, Transform):
            partner = open_portals.get(entity)
            if partner is None:
                continue  # closed: the scene shader shows its closed colour
            out = world.get(partner, Transform)
            w, h = portal.size
            corners = np.array([(x, y, 0.0, 1.0) for x in (-w / 2, w / 2) for y in (-h / 2, h / 2)])
            corners = corners @ np.array(transform.world.to_list(), np.float64)
            self.portals[entity] = SurfaceState(
                entity, "portal", portal_plane(transform.world), corners, corners,
                pair_transform(transform.world, out.world), portal_plane(out.world), partner,
                portal.max_depth, portal.enabled)

    @staticmethod
    def _mirror_state(entity: int, mirror: Mirror, mesh_ref: MeshRef, transform: Transform,
                      material: Material | None = None) -> SurfaceState:
        mesh = mesh_ref.mesh
        if mirror.plane_normal is not None:
            point = np.array(mirror.plane_point if mirror.plane_point is not None else (0.0, 0.0, 0.0))
            normal = np.array(mirror.plane_normal)
        else:
            found = flat_plane(mesh)
            if found is None:
                lo, hi = mesh.bounds
                raise MirrorError(
                    f"entity {entity}: Mirror on mesh {mesh.name!r} which is not flat (model-space "
                    f"extents {np.round(hi - lo, 4).tolist()}); give the mirror a flat mesh or plane_normal")
            point, normal = found
        model = transform.world
        local_plane = plane_from_point_normal(tuple(float(v) for v in point), tuple(float(v) for v in normal))
        plane = transform_plane(model, local_plane)
        lo, hi = mesh.bounds
        corners = world_corners(mesh, model)  # x, then y, then z: the outline below picks by bit
        # A flat mesh's box has its corners in pairs across the flat axis: one of each pair is
        # the mesh's outline on its plane (what the composite covers instead of the rectangle).
        extents = hi - lo
        flat_axis = int(np.argmin(extents))
        outline = None
        if extents[flat_axis] <= FLAT_OUTLINE_TOLERANCE * max(float(extents.max()), 1e-9):
            outline = corners[[i for i in range(8) if not (i >> (2 - flat_axis)) & 1]]
        bumps = None
        if material is not None and material.normal_map is not None:
            bumps = MirrorBumps(material.normal_map, material.normal_scale,
                                _uv_rows(entity, mesh, np.array(model.to_list(), np.float64).T), float(plane.w))
        return SurfaceState(entity, "mirror", plane, corners, outline,
                            reflection_matrix(plane), plane, entity, mirror.max_depth, mirror.enabled,
                            mirror.color, mirror.reflect_rate, mirror.roughness, mirror.resolution_scale, bumps)


def _uv_rows(entity: int, mesh, model: np.ndarray) -> np.ndarray:
    """The mirror's UVs as an affine function of world position, (2, 4) rows: the mesh's
    plane map (``engine.assets.mesh.planar_uv_map``) carried to world space by the inverse model
    matrix.  The world refuses a mesh without one when the map is given; this is the
    backstop for a mesh replaced by other means."""
    rows, why = planar_uv_map(mesh)
    if rows is None:
        raise MirrorError(f"entity {entity}: Material.normal_map on a Mirror needs UVs that vary linearly over the "
                          f"mirror (mesh {mesh.name!r}: {why}); use a flat mesh with planar UVs, such as a quad")
    return rows @ np.linalg.inv(model)
