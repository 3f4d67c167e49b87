"""Extract: the instance records of entities whose mesh, material or transform changed.

The first render stage of a frame.  It reads the ECS through the world's change sets (a
frame where nothing changed touches nothing), chooses each instance's material variants
(``material_dispatch``) and writes the rows the GPU batches upload in the prepare stage:
the rows of entities that moved or whose look changed (``probe_rules.LookChanges``, the
kinds in ``LOOK_KINDS``), with the probes each one samples (``probe_rules.probe_blend``).
A posed entity (a ``Skin`` bends its mesh, or it wears a ``Morph``) gets a batch of its own,
its joint matrices and morph weights written to its row of the pose texture
(``engine/render/pose_rows.py``) and the box holding the pose given to its batch.
Where a water gathers the sun (``Water.caustics``), a row whose box reaches into its body
goes to a batch of its own (``BatchKey.caustic_waters``): the CAUSTICS builds cost every
pixel of a batch on a software rasteriser, and a mesh's rows across a level (the boxes of a
hall) would all pay for a pond's; a mover is re-keyed as it goes in or out.
It also publishes which probes each mirror and portal shows where it gets no view
(``SurfaceBlends``, ``probe_rules.surface_blend``), which the view trees' fallbacks draw.
Nothing here writes game state.
"""
from __future__ import annotations

import weakref
from collections.abc import Callable

import esper
import numpy as np
from pyglm import glm

from components import (
    Emissive,
    FromDecal,
    Material,
    MeshRef,
    Mirror,
    Monitor,
    Morph,
    Portal,
    PortalClone,
    Reflective,
    Refractive,
    Skin,
    Slice,
    Transform,
    Visibility,
    Water,
)
from components.rendering import second_uv_mask
from components.transform import mirroring_seen
from engine.assets.mesh import Mesh
from engine.core.errors import GLLimitError
from engine.core.skinning import posed_bounds
from engine.core.world import World
from engine.render.caustics import Box, caustic_waters_of, placed_box
from engine.render.instances import PROBE_WEIGHTS, TINT_VISIBILITY, InstanceBatch
from engine.render.renderer import Renderer
from engine.render.shadows import LIGHT_LIMITS
from engine.render.surface_table import SurfaceBlends
from engine.resources import PortalCrossings, Surfaces, ViewBudget
from engine.rules.light_rules import kept_lamp_places, kept_sun_ways, lights_this_frame
from engine.rules.probe_rules import APPEARANCE_KINDS, POSE_KINDS, LookChanges, SurfaceProbes, probe_blend
from engine.rules.visibility_rules import entity_code
from systems.material_dispatch import choose_material, layer_uniforms

NO_SLICE = (0.0, 0.0, 0.0, 1.0)


def _mirrors(world_matrix) -> bool:
    """Whether a model matrix mirrors what it places (a negative determinant: an odd number
    of negative scales along its chain), so its front faces wind the other way on screen."""
    return glm.determinant(glm.mat3(world_matrix)) < 0.0


_STRAYED_ON_ARRAYS = 40   # a batch's movers from which ExtractSystem._strayed checks them on arrays


class ExtractSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self._batch_of: dict[int, InstanceBatch] = {}
        self._looks = LookChanges()  # what changes a look, and which probe each object samples
        self._joined: set[int] = set()
        self._surface_probes = SurfaceProbes()  # each mirror's and portal's fallback probes
        self._see_through: dict[int, InstanceBatch] = {}  # see-through mirrors' and portals' batches (water)
        self._layout = 0  # counts changes of _batch_of (an entity given, moved to or taken from a batch)
        # (layout, the entities, them by batch) of the last frame's movers (process).
        self._moved_groups: tuple[int, set[int], dict[InstanceBatch, list[int]]] | None = None
        # The bodies of the waters that gather the sun (_caustic_bodies), and each mesh's model box.
        self._bodies: tuple[tuple[int, Box], ...] = ()
        self._mesh_boxes: weakref.WeakKeyDictionary[Mesh, Box] = weakref.WeakKeyDictionary()

    def process(self, dt: float) -> None:
        world = self.world
        renderer = self.renderer
        budget = ViewBudget.of(world.resources)
        if budget is not None and budget.frame_ms is not None:   # (the frame's GL work starts here: timed)
            renderer.frame_timer.require()
            renderer.frame_timer.begin()
        # Per-object motion blur: on while the camera's last presented motion blur streaked
        # moving things (the first frame of a motion blur has no last frame to streak from).
        # Temporal AA reprojects by it too.
        renderer.begin_object_motion(renderer.present_pass.streaks_objects or renderer.antialias == "taa", dt,
                                     world.resources.get(PortalCrossings, ()))
        motion = renderer.object_motion if renderer.object_motion.on else None
        # A component of probe_rules.LOOK_KINDS changed, or the probe the entity samples did (a
        # probe came, went, changed or moved, or the entity moved into or out of an influence box).
        touched = self._looks.entities(world)
        shown = world.changed(Visibility)
        if shown:  # a portal clone is drawn where its source is (its row reads the source's Visibility)
            touched |= {entity for entity, clone in world.query_one(PortalClone) if clone.source in shown}
        if world.changed(Skin) or world.changed(Morph):
            touched = self._posed_only(touched)
        bodies = self._caustic_bodies()
        if bodies != self._bodies:   # a water that gathers the sun came, went, moved or changed
            self._bodies = bodies
            touched = touched | self._keyed_apart_wrongly(bodies)
        joined = self._joined = set()  # entities given a row by a refresh: their transform is written below
        for entity in touched:
            self._refresh_instance(entity)
        # What each mirror and portal shows where it has no view: the probes whose influence
        # boxes hold it (probe_rules.surface_blend), for the view trees' composites.
        surfaces = world.resources.get(Surfaces)
        world.resources[SurfaceBlends] = SurfaceBlends(self._surface_probes.update(
            world, (*surfaces.mirrors.values(), *surfaces.portals.values()) if surfaces is not None else ()))
        for entity, batch in self._see_through.items():  # the planes the transparent slot is ordered around
            state = None if surfaces is None else surfaces.mirrors.get(entity) or surfaces.portals.get(entity)
            batch.plane = None if state is None else state.plane
        # The transform of every moved entity, touched or not, and of every entity a refresh
        # gave a new row (a Slice removed in the frame it moved leaves it in another batch),
        # grouped by batch: each batch writes its rows in one go (InstanceBatch.write_transforms).
        frame = world.frame
        component = esper.component_for_entity if esper.current_world == world.name else world.get
        if mirroring_seen():
            # An instance whose model matrix turned mirrored (or back) by moving (a scale or a
            # parent's scale changed sign) goes to the batch drawn with its winding.
            for entity in frame.moved - touched:
                batch = self._batch_of.get(entity)
                if batch is not None and batch.mirrored != _mirrors(component(entity, Transform).world):
                    self._refresh_instance(entity)
        worlds = frame.worlds  # the matrices the transform stage wrote (the others: their Transform's)
        if bodies:
            # A mover that went into a caustic water's body (or came out) goes to the batch drawn
            # with (or without) the CAUSTICS builds.
            for entity in self._strayed(frame.moved - touched, worlds, component):
                self._refresh_instance(entity)
        # The movers by batch: last frame's grouping again when the same entities moved and no
        # entity changed batch since (a game's movers are mostly the same every frame: a
        # thousand batch look-ups saved, and each batch finds the same list, InstanceBatch.write_transforms).
        moved = frame.moved
        kept = self._moved_groups
        if kept is not None and kept[0] == self._layout and kept[1] == moved:
            groups = kept[2]
        else:
            groups = self._by_batch(moved)
            self._moved_groups = (self._layout, set(moved), groups) if moved else None
        for entities, moving in ((groups, True), (self._by_batch((frame.added | joined) - moved), False)):
            for batch, group in entities.items():
                models = [worlds[entity] if entity in worlds else component(entity, Transform).world
                          for entity in group]
                batch.write_transforms(group, models, moving, motion)

    def _caustic_bodies(self) -> tuple[tuple[int, Box], ...]:
        """Each of this frame's waters that gather the sun (a ``Water`` with ``caustics`` and
        waves: the prepare stage's candidates, before it picks the nearest) and the world box of
        its body, by entity; none, and no loop, in a world without water."""
        surfaces = self.world.resources.get(Surfaces)
        if surfaces is None or not surfaces.undersides:
            return ()
        bodies = []
        suns = lamps = None
        for entity, state in surfaces.mirrors.items():
            if state.water is None or state.bumps is None:
                continue
            water = self.world.try_get(entity, Water)
            if water is not None and water.caustics > 0.0:
                if state.carries_light and suns is None:   # (the prepare stage's choice, made ahead)
                    now = lights_this_frame(self.world, LIGHT_LIMITS)
                    suns = kept_sun_ways(self.world, LIGHT_LIMITS, now)
                    lamps = kept_lamp_places(self.world, LIGHT_LIMITS, now)
                box = self.renderer.caustics.reach.box(entity, state, water.depth, state.carries_light, suns or (),
                                                       lamps or ())
                bodies.append((entity, box))
        return tuple(sorted(bodies))

    def _keyed_apart_wrongly(self, bodies: tuple[tuple[int, Box], ...]) -> set[int]:
        """The entities whose rows' boxes (``InstanceBatch.row_boxes``: each batch's at once)
        reach into other ``bodies`` than their batch is keyed under, and those whose rows were
        never measured: the rows to key again when the caustic waters change (a tide rising
        moves its body every frame: not every row)."""
        found: set[int] = set()
        present = {entity for entity, _ in bodies}
        for batch in set(self._batch_of.values()):
            boxes = batch.row_boxes   # (as of the last upload: a mover this frame is looked at below)
            if not len(boxes):
                continue
            lo, hi = boxes[:, 0], boxes[:, 1]
            wrong = np.isnan(lo).any(axis=1)
            for entity, (body_lo, body_hi) in bodies:
                reach = ~((hi < body_lo).any(axis=1) | (lo > body_hi).any(axis=1))
                wrong |= reach != (entity in batch.caustic_waters)
            if not present.issuperset(batch.caustic_waters):
                wrong[:] = True   # (keyed under a water that no longer gathers the sun)
            found.update(batch.entity_at[row] for row in np.flatnonzero(wrong).tolist())
        return found

    def _strayed(self, movers: set[int], worlds: dict, component: Callable) -> list[int]:
        """The ``movers`` whose mesh, where it is now, reaches into other caustic waters' bodies
        than their batch is keyed under.  A batch's few movers one by one (``_caustic_waters``:
        about 6 microseconds a mover); its many (``_STRAYED_ON_ARRAYS``) at once on arrays,
        their boxes as ``caustics.placed_box`` sums them, term by term in the same order, so
        both find the same (measured, ``_caustic_waters`` against this, one process: 1,000
        movers 8.0 against 1.9 ms, 50 about even, 5 0.03 against 0.11)."""
        bodies = self._bodies
        body_lo = np.array([lo for _, (lo, _) in bodies])[None]
        body_hi = np.array([hi for _, (_, hi) in bodies])[None]
        strayed: list[int] = []
        for batch, group in self._by_batch(movers).items():
            if len(group) < _STRAYED_ON_ARRAYS:
                strayed += [entity for entity in group if batch.caustic_waters != self._caustic_waters(entity)]
                continue
            models = [worlds[entity] if entity in worlds else component(entity, Transform).world for entity in group]
            m = np.frombuffer(glm.array(models).to_bytes(), np.float32).reshape(-1, 4, 4).astype(np.float64)
            boxes = np.array([self._mesh_box(component(entity, MeshRef).mesh) for entity in group])  # [n, lo/hi, 3]
            low, high = m[:, 3, :3].copy(), m[:, 3, :3].copy()   # (m[i, c, r]: model axis c's world axis r)
            for c in range(3):
                p, q = m[:, c, :3] * boxes[:, 0, c:c + 1], m[:, c, :3] * boxes[:, 1, c:c + 1]
                low += np.minimum(p, q)
                high += np.maximum(p, q)
            reach = ~((high[:, None] < body_lo).any(axis=2) | (low[:, None] > body_hi).any(axis=2))
            keyed = np.array([entity in batch.caustic_waters for entity, _ in bodies])
            strayed += [group[i] for i in np.flatnonzero((reach != keyed).any(axis=1)).tolist()]
        return strayed

    def _mesh_box(self, mesh: Mesh) -> Box:
        """``mesh``'s model box as Python floats, kept a mesh."""
        box = self._mesh_boxes.get(mesh)
        if box is None:
            lo, hi = mesh.bounds
            box = self._mesh_boxes[mesh] = (tuple(float(v) for v in lo), tuple(float(v) for v in hi))
        return box

    def _caustic_waters(self, entity: int, pose_box: Box | None = None) -> tuple[int, ...]:
        """The caustic waters whose bodies ``entity``'s mesh, where its Transform places it,
        reaches into (``caustics.caustic_waters_of``): its model box kept a mesh, or, posed,
        the box holding its pose (``pose_box``, else its own batch's: a bent arm or a morph
        may reach into a water its mesh as modelled does not)."""
        if pose_box is None:
            batch = self._batch_of.get(entity)
            posed = batch is not None and (batch.skinned or batch.morphed)
            pose_box = (batch.box_lo, batch.box_hi) if posed else self._mesh_box(self.world.get(entity, MeshRef).mesh)
        return caustic_waters_of(placed_box(self.world.get(entity, Transform).world, *pose_box), self._bodies)

    def _by_batch(self, entities: set[int]) -> dict[InstanceBatch, list[int]]:
        """``entities`` that have a row, by their batch."""
        batch_of = self._batch_of
        groups: dict[InstanceBatch, list[int]] = {}
        for entity in entities:
            batch = batch_of.get(entity)
            if batch is not None:
                group = groups.get(batch)
                if group is None:
                    groups[batch] = [entity]
                else:
                    group.append(entity)
        return groups

    def _refresh_instance(self, entity: int) -> None:
        world = self.world
        mesh_ref = world.try_get(entity, MeshRef) if world.exists(entity) else None
        transform = world.try_get(entity, Transform) if mesh_ref is not None else None
        old = self._batch_of.get(entity)
        if mesh_ref is None or transform is None or not mesh_ref.visible:
            if old is not None:
                self._remove_instance(entity, old)
            return
        material = world.try_get(entity, Material)
        # Water is seen from below too (a view under it sees its underside: Surfaces.undersides).
        water = world.has(entity, Water)
        blend = probe_blend(world, entity)  # the probes it samples, and their weights
        probe = blend.probes[0] if blend.probes else 0
        second = blend.probes[1] if len(blend.probes) > 1 else 0
        # A material whose alpha is below 1 is see-through: blended in the transparent slot
        # (glass, whose alpha weighs the refracted view, stays opaque).
        # A cutout (Material.alpha_cutoff) is opaque where it is drawn at all.
        # A decal's cut mesh (FromDecal) blends whatever its alpha: its image's alpha is its shape.
        refractive = world.try_get(entity, Refractive)
        cut = world.try_get(entity, FromDecal)
        decal = cut is not None
        transparent = material is not None and (material.color.w < 1.0 or decal) and material.alpha_cutoff is None \
            and refractive is None
        # A generated shape is drawn as its unit mesh, its size in its row; not a mirror's or a
        # portal's, whose batch of surfaces alone the unlit-mirror pass keeps (unlit_mirrors).
        surface = world.has(entity, Mirror) or world.has(entity, Portal)
        drawn = mesh_ref.mesh if surface else mesh_ref.mesh.unit or mesh_ref.mesh
        # A skinned mesh bent by a Skin, or one wearing a Morph: a batch of its own (its pose
        # its own); one without is drawn as modelled.
        skin = world.try_get(entity, Skin) if drawn.skinned else None
        morph = world.try_get(entity, Morph) if drawn.morph_count else None
        posed = (entity, skin.skinning if skin is not None else "", morph is not None) \
            if skin is not None or morph is not None else (0, "", False)
        pose_box = self._pose_box(drawn, skin, morph) if posed[0] else None
        # A Monitor's screen gives off its picture (engine/render/monitors.py: the picture's
        # stand-in is its emissive map, the monitor's brightness its emission).
        monitor = world.try_get(entity, Monitor)
        emissive_map = self.renderer.monitors.picture(entity, monitor.size) if monitor is not None \
            else material.emissive_map if material else None
        try:
            batch = self.renderer.batch_for(drawn, material.texture if material else None, probe,
                                            entity if transparent else 0, material.normal_map if material else None,
                                            emissive_map,
                                            material.metallic_roughness_map if material else None,
                                            second_probe=second, probe_blend=blend.blended, rest_probe=blend.rest,
                                            mirrored=mirroring_seen() and _mirrors(transform.world),
                                            alpha_cutoff=material.alpha_cutoff if material else None,
                                            occlusion_map=material.occlusion_map if material else None,
                                            occlusion_strength=material.occlusion_strength if material else 1.0,
                                            lightmap=material.lightmap if material else None,
                                            lightmap_intensity=material.lightmap_intensity if material else 1.0,
                                            double_sided=water or (material.double_sided if material else False),
                                            keeps_specular=material is not None and material.blend == "transparent",
                                            unlit=material is not None and material.unlit,
                                            posed=posed, second_uv_maps=second_uv_mask(material), decal=decal,
                                            decal_order=cut.order if cut is not None else 0,
                                            caustic_waters=self._caustic_waters(entity, pose_box) if self._bodies
                                            else (),
                                            **layer_uniforms(material, refractive))
        except GLLimitError as exc:
            raise GLLimitError(f"entity {entity}{f' (the cut of the Decal on entity {cut.decal})' if cut else ''}: "
                               f"{exc}") from None
        if transparent:  # a see-through mirror or portal (water): drawn before the view trees' claims
            batch.surface = world.has(entity, Mirror) or world.has(entity, Portal)
        if transparent and batch.surface:
            self._see_through[entity] = batch
        else:
            self._see_through.pop(entity, None)
        if old is not batch:
            if old is not None:
                self._remove_instance(entity, old)
            row = batch.add(entity)
            self._batch_of[entity] = batch
            self._layout += 1
            self._joined.add(entity)
        else:
            row = batch.row(entity)
        if posed[0]:
            self._pose(entity, batch, drawn, skin, morph, pose_box)
        if batch.set_size(entity, None if drawn is mesh_ref.mesh else mesh_ref.mesh.unit_scale):
            self._joined.add(entity)  # its model matrix is written again below, with its size
        casting_before = batch.shadow_fields(row) if old is batch else None
        emissive = Emissive(power=monitor.brightness) if monitor is not None else world.try_get(entity, Emissive)
        choice = choose_material(material, emissive, world.try_get(entity, Reflective),
                                 world.try_get(entity, Refractive), world.try_get(entity, Mirror),
                                 world.try_get(entity, Portal), probe=bool(probe))
        row["color"] = choice.color
        row["surface"] = choice.surface
        row["reflect"] = choice.reflect_params
        row["reflect"][PROBE_WEIGHTS] = (*blend.weights, 0.0, 0.0)[:2]  # each probe's weight (the PROBE_BLEND build)
        clone = world.try_get(entity, PortalClone)
        drawn_as = clone.source if clone else entity  # a clone stands in for its source past a portal
        row["tint"] = choice.tint
        # Where it is drawn: the views it is hidden in and its reflection layers (the scene
        # shaders leave it out of views of a hidden kind or sharing none of its layers).
        # And whether it casts and receives shadows (a clone as its source).
        visibility = world.try_get(drawn_as, Visibility) if world.exists(drawn_as) else None
        source_mesh = world.try_get(drawn_as, MeshRef) if world.exists(drawn_as) else None
        shown = source_mesh or mesh_ref
        portal = world.try_get(entity, Portal)
        row["tint"][TINT_VISIBILITY] = entity_code(visibility, casts_shadows=shown.casts_shadows,
                                                   receives_shadows=shown.receives_shadows,
                                                   opening_carries=portal is not None and portal.carries_light)
        slice_ = world.try_get(entity, Slice)
        row["slice"] = slice_.plane if slice_ is not None else NO_SLICE
        row["slots"] = (choice.emissive, choice.refract, choice.reflect, drawn_as)
        if casting_before is not None and batch.shadow_fields(row) != casting_before:
            batch.note_shadow_change(entity)  # it stopped or started casting where it stands: maps drawn again
        batch.note_row_casts(entity, row)  # one that casts nothing: its moves change no shadow
        batch.variants_changed()

    def _posed_only(self, touched: set[int]) -> set[int]:
        """Pose the entities of ``touched`` whose only change is a new pose (its Skin or Morph
        written, nothing else of its look, the probes it samples the same, its batch posed as
        it is: ``_pose``, not its whole row again, as an animated character each frame); the
        rest of ``touched``, to refresh."""
        world = self.world
        posed = world.changed_any(POSE_KINDS) & touched
        posed -= world.changed_any(APPEARANCE_KINDS)
        posed -= self._looks.last_resampled
        done = set()
        for entity in posed:
            batch = self._batch_of.get(entity)
            if batch is None or not world.exists(entity):
                continue
            skin, morph = world.try_get(entity, Skin), world.try_get(entity, Morph)
            skinning = skin.skinning if skin is not None else ""
            if (skin is not None or morph is not None) and batch.skinned == skinning \
                    and batch.morphed == (morph is not None):
                self._pose(entity, batch, world.get(entity, MeshRef).mesh, skin, morph)
                if not self._bodies or batch.caustic_waters == self._caustic_waters(entity):
                    done.add(entity)   # (else the pose reached into a caustic water, or left one: keyed again)
        return touched - done if done else touched

    @staticmethod
    def _pose_box(mesh: Mesh, skin: Skin | None, morph: Morph | None) -> Box:
        """The model box holding ``mesh`` as ``skin`` and ``morph`` pose it (``skinning.posed_bounds``)."""
        joints = skin.joint_matrices if skin is not None else None
        weights = morph.weights if morph is not None else None
        lo, hi = posed_bounds(mesh, joints, weights, skin is not None and skin.skinning == "dual_quaternion")
        return tuple(float(v) for v in lo), tuple(float(v) for v in hi)

    def _pose(self, entity: int, batch: InstanceBatch, mesh: Mesh, skin: Skin | None, morph: Morph | None,
              box: Box | None = None) -> None:
        """Write ``entity``'s joint matrices and morph weights to its row of the pose texture
        (its batch's draws read that row) and give its batch the box holding the pose
        (``_pose_box``, or ``box`` where it is known)."""
        joints = skin.joint_matrices if skin is not None else None
        weights = morph.weights if morph is not None else None
        batch.pose_row = self.renderer.pose_rows.write(entity, joints, weights)  # (a limit names it)
        batch.set_local_box(*(box or self._pose_box(mesh, skin, morph)))
        self.renderer.note_scene_change()

    def _remove_instance(self, entity: int, batch: InstanceBatch) -> None:
        self._see_through.pop(entity, None)
        if batch.skinned or batch.morphed:
            self.renderer.pose_rows.free(entity)
        batch.remove(entity)
        del self._batch_of[entity]
        self._layout += 1
        self.renderer.drop_batch_if_empty(batch)

    def close(self) -> None:
        for entity, batch in list(self._batch_of.items()):
            self._remove_instance(entity, batch)

