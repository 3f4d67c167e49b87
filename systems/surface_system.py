"""Surfaces: every mirror and portal as the view trees see them, worked out once a frame.

After the transform stage, the Mirror and Portal components become ``SurfaceState`` rows
(only what changed: a mirror's plane, outline and composite parameters are worked out
again when it moves or its components change; the few portals are redone every frame, as
they depend on their partner's pose too), published as ``world.resources[Surfaces]``: the
probes stage roots view trees at probe faces with them, the reflect stage at the main view.
A Mirror's plane and normal-map UVs are the mirror rule's (``engine.rules.mirror_rules.mirror_mesh``,
the function the world's invariant refuses a bad mirror with); a Mirror on something that
cannot be a mirror (a mesh changed behind the world's back) is a ``MirrorError`` naming the
entity and the rule's reason.

A Mirror with a ``Water`` component is a water surface: its state carries a ``WaterLook``
(the Fresnel F0, the waves' layers) and the waves' ``WaterFlow``; this stage moves
``Water.offset`` on by the frame's ``dt`` (speed x direction, in normal-map tiles) every
frame and copies it into the flow in place, so the composite reads this frame's offset
without the state being made again.

Each frame it also publishes ``SurfaceMotion``: the surfaces whose carry (the reflection, or
the pair's transform) is not what it was last frame, with last frame's, so temporal AA and
motion blur follow a turning mirror's reflection (``engine/render/mirror_passes.py``).  A
frame of dt 0 (a second presentation, a paused game) keeps the last frame's unless a surface
moved, as the per-object motion does.
"""
from __future__ import annotations

import warnings

import esper
import numpy as np
from pyglm import glm

from components import Material, MeshRef, Mirror, Portal, Transform, Visibility, Water
from components.visibility import DRAWN_EVERYWHERE
from engine.core.errors import MirrorError
from engine.core.portal_math import pair_transform, portal_plane
from engine.core.reflection_math import plane_from_point_normal, reflection_matrix, transform_plane
from engine.core.world import World
from engine.resources import MirrorBumps, SurfaceMotion, Surfaces, SurfaceState, WaterFlow, WaterLook
from engine.rules.frame_rules import frame_rules, world_corners
from engine.rules.mirror_rules import MirrorMeshError, mirror_mesh
from engine.rules.visibility_rules import drawn_code

# A mirror mesh thinner than this fraction of its size composites over its outline quad;
# anything thicker (a mirror plane given explicitly on a solid mesh) over its rectangle.
FLAT_OUTLINE_TOLERANCE = 1e-3


class SurfaceSystem(esper.Processor):
    def __init__(self, world: World) -> None:
        self.world = world
        self.mirrors: dict[int, SurfaceState] = {}
        self.portals: dict[int, SurfaceState] = {}
        self.flows: dict[int, WaterFlow] = {}  # each water mirror's waves, for the entity's life
        self._open_portals: dict[int, int] | None = None  # the pairs the portal states were made for
        self._waiting_water: set[int] = set()  # Waters whose Mirror was removed (warned once)
        self.undersides: dict[int, SurfaceState] = {}  # each water's state seen from below (Surfaces.undersides)

    def process(self, dt: float) -> None:
        before: dict[int, glm.mat4] = {}   # the carries of the surfaces made again, as they were
        changed = self._refresh_mirrors(before)
        self._advance_waves(dt)
        changed |= self._refresh_portals(before)
        if changed or Surfaces not in self.world.resources:
            # A new resource only when a surface changed: the view planner's arrays made
            # from it (``engine.render.surface_table``, on first use) are kept while none does.
            self.world.resources[Surfaces] = Surfaces(dict(self.mirrors), dict(self.portals), dict(self.undersides))
        moved = {}
        for entity, carry in before.items():
            state = self.mirrors.get(entity) or self.portals.get(entity)
            if state is not None and state.carry != carry:
                moved[entity] = carry
        if moved or dt > 0.0 or SurfaceMotion not in self.world.resources:
            self.world.resources[SurfaceMotion] = SurfaceMotion(moved)

    def _refresh_mirrors(self, before: dict[int, glm.mat4]) -> bool:
        """Mirror states redone for what changed (the carries of those that were there into
        ``before``); whether any was."""
        world = self.world
        touched = world.changed(Mirror) | world.changed(MeshRef)
        touched |= {e for e in world.changed(Material) if e in self.mirrors}  # a normal map given or taken
        touched |= {e for e in world.changed(Visibility) if e in self.mirrors or world.exists(e)
                    and world.has(e, Mirror)}
        for entity in world.changed(Water):
            water = world.try_get(entity, Water) if world.exists(entity) else None
            if water is not None and not world.has(entity, Mirror):
                # Refused when given (engine/rules/water_rules.py); here only when the Mirror
                # was taken off later: the Water waits for a Mirror, said once.
                if entity not in self._waiting_water:
                    self._waiting_water.add(entity)
                    warnings.warn(f"entity {entity}: its Water has no Mirror (it was removed), so nothing is "
                                  "drawn as water until a Mirror comes back", stacklevel=2)
                continue
            self._waiting_water.discard(entity)
            look = getattr(self.mirrors.get(entity), "water", None)
            if water is not None and look is not None and (look.f0, look.cross, look.tiling) == \
                    (water.f0, water.cross, water.tiling):
                continue  # only the waves moved (this stage writes Water.offset each frame): the state stands
            touched.add(entity)
        touched |= {e for e in world.frame.moved | world.frame.added if e in self.mirrors or e in touched}
        for entity in touched:
            old = self.mirrors.get(entity)
            if old is not None:
                before[entity] = old.carry
            mirror = world.try_get(entity, Mirror) if world.exists(entity) else None
            if mirror is None:
                self.mirrors.pop(entity, None)
                self.undersides.pop(entity, None)
                self.flows.pop(entity, None)
                continue
            mesh_ref = world.try_get(entity, MeshRef)
            transform = world.try_get(entity, Transform)
            if mesh_ref is None or transform is None:
                raise MirrorError(f"entity {entity}: a Mirror needs a MeshRef and a Transform")
            water = world.try_get(entity, Water)
            flow = None
            if water is None:
                self.flows.pop(entity, None)
            else:
                if mirror.roughness > 0.0:
                    raise MirrorError(f"Water on entity {entity}: a water surface is sharp (its waves break up the "
                                      f"image), so its Mirror.roughness must be 0, got {mirror.roughness}")
                flow = self.flows.setdefault(entity, WaterFlow())
            material = world.try_get(entity, Material)
            self.mirrors[entity] = self._mirror_state(entity, mirror, mesh_ref, transform, material, water, flow,
                                                      drawn_code(world, entity))
            if water is not None:  # (a view under it sees it so: the planner holds both sides)
                self.undersides[entity] = self._mirror_state(entity, mirror, mesh_ref, transform, material, water,
                                                             flow, drawn_code(world, entity), underside=True)
            else:
                self.undersides.pop(entity, None)
        return bool(touched)

    def _advance_waves(self, dt: float) -> None:
        """Every water's waves move on by this frame's ``dt`` at its speed and direction now
        (a change of speed carries on from where the waves are): ``Water.offset`` is written
        (the waves' state is the component's, so a saved level or an exported scene draws
        them where they were) and copied into the ``WaterFlow`` its composite reads."""
        for entity, flow in self.flows.items():
            water = self.world.try_get(entity, Water)
            if water is None:
                continue
            step = water.speed * dt
            if step:
                u, v = water.offset
                water.offset = (u + water.direction[0] * step, v + water.direction[1] * step)
            flow.offset = water.offset

    def _refresh_portals(self, before: dict[int, glm.mat4]) -> bool:
        """Portals depend on their partner's pose too; there are few, so all are redone when
        a portal, its pose or a pairing changed (whether they were; the carries they had into
        ``before``)."""
        world = self.world
        open_portals = frame_rules(world).open_portals  # the rule travel and slicing use too
        frame = world.frame
        moved = frame.moved | frame.added | frame.removed
        if (open_portals == self._open_portals and not world.changed(Portal)
                and not any(e in moved or p in moved for e, p in open_portals.items())
                and not any(e in open_portals for e in world.changed(Visibility) | world.changed(MeshRef))):
            return False
        self._open_portals = dict(open_portals)
        before.update((entity, state.carry) for entity, state in self.portals.items())
        self.portals = {}
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
                portal.max_depth, portal.enabled, layers=portal.layer_mask, priority=portal.priority,
                end_image=portal.end_image, drawn=drawn_code(world, entity), carries_light=portal.carries_light)
        return True

    @staticmethod
    def _mirror_state(entity: int, mirror: Mirror, mesh_ref: MeshRef, transform: Transform,
                      material: Material | None = None, water: Water | None = None,
                      flow: WaterFlow | None = None, drawn: int = DRAWN_EVERYWHERE,
                      underside: bool = False) -> SurfaceState:
        """A mirror's state; ``underside``: a water's seen from below (its plane turned to face
        down, its look ``WaterLook.underside``)."""
        mesh = mesh_ref.mesh
        bumpy = material is not None and material.normal_map is not None
        try:
            shape = mirror_mesh(mirror, mesh, bumpy, bumpy and "normal_map" in material.second_uv_maps)
        except MirrorMeshError as exc:
            raise MirrorError(f"Mirror on entity {entity}: {exc}") from None
        point, normal = shape.point, shape.normal
        model = transform.world
        local_plane = plane_from_point_normal(tuple(float(v) for v in point), tuple(float(v) for v in normal))
        plane = transform_plane(model, local_plane)
        if underside:
            plane = -plane
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
        if bumpy:
            # The UVs as an affine function of world position: the rule's model-space map
            # carried by the inverse model matrix.
            uv_rows = shape.uv_rows @ np.linalg.inv(np.array(model.to_list(), np.float64).T)
            bumps = MirrorBumps(material.normal_map, material.normal_scale, uv_rows, float(plane.w))
        look = None
        if water is not None:
            look = WaterLook(water.f0, water.cross, water.tiling, flow if flow is not None else WaterFlow(), underside)
        return SurfaceState(entity, "mirror", plane, corners, outline,
                            reflection_matrix(plane), plane, entity, mirror.max_depth, mirror.enabled,
                            mirror.color, mirror.reflect_rate, mirror.roughness, mirror.resolution_scale, bumps, look,
                            fade=_fades(mirror), layers=mirror.layer_mask, priority=mirror.priority,
                            end_image=mirror.end_image, drawn=drawn, carries_light=mirror.reflects_light)



def _fades(mirror: Mirror) -> tuple[float, float, float, float] | None:
    """A mirror's fades as the view planner reads them (an unset one never fades)."""
    if mirror.fade_distance is None and mirror.fade_angle is None:
        return None
    return (*(mirror.fade_distance or (NO_FADE, 2.0 * NO_FADE)), *(mirror.fade_angle or (NO_FADE, 2.0 * NO_FADE)))


NO_FADE = 1e30  # a start no distance or angle reaches
