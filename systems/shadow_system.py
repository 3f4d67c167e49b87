"""Shadows: which lights' shadow maps are drawn this frame, and drawing them.

A map is made once a frame at most, before any view is drawn, and every view samples it
(main, mirror, portal, probe face), so a shadow looks the same directly, in a mirror and
through a portal.  Maps are cached like probe faces: a directional light's map is drawn
again only when the light changed or a caster changed (an instance row was written: it
moved, came, went or changed its look; the map covers the whole level, so every caster is in
its reach); a point light's only when the light changed or moved, or a caster whose old or
new box reaches into its range changed.  A still scene draws no shadow pass.  When the
changed casters lie inside the level's box, a directional map is drawn again only under
where they were and are (``shadow_rules.changed_region``: the rectangle holding each
changed box's footprint in the map, the casters' draws scissored there, the same depths a
whole redraw writes).  A sun's cascades (rings about the active camera,
``shadow_rules.ring_fit``) are kept the same way, and drawn whole again when the camera
strays a grid step from a ring's centre (``shadow_rules.ring_cell``).  A sun's map is
fitted to the level's box with slack (``shadow_rules.level_fit_box``): a thing moving out
past the level's edge fits it anew a few times, not every frame.  Virtual lights (``shadow_rules.virtual_lights``:
lights through mirrors and portals) get their maps here too, each a view of the frame's
``ViewBudget``, at most ``MAX_VIRTUAL_LIGHTS`` (the rest: ``RenderStats.virtual_lights_cut``).

Which lights have maps, and in which slot, is ``engine/rules/light_rules.py``'s choice, the
one the prepare stage filled the Lights block with (``KeptLights``): a directional map's
slot is its light's slot in the block, and the point lights' cubes go to the kept lights the
rule gives them to (the most important to the camera that cast), each kept in its cube while
it stays chosen; a light left out of the block casts nothing (``RenderStats.shadows_cut``).
A light's own entity's mesh casts none of its shadow (``Shadows._draw_casters``); a closed
caster made apart round a casting point light, small beside its range (a bulb beside its
lamp's entity, which leaves all the lamp reaches dark), is named once in a ComponentWarning
(``ShadowSystem._say_enclosed``).

It publishes ``ShadowCasters`` (``engine/rules/shadow_rules.py``): the lights casting this
frame, so the probes' scheduler can recapture a face where a moved caster's shadow falls.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import esper
import numpy as np
from pyglm import glm

from components import (
    DirectionalLight,
    Material,
    MeshRef,
    Morph,
    PointLight,
    Portal,
    Refractive,
    Skin,
    Skybox,
    Transform,
    Visibility,
)
from components.tracking import raw_field, warn_component
from engine.core.cube_faces import CUBE_FACES
from engine.core.transforms import current_world_matrix
from engine.core.world import World
from engine.render.clouds import cloud_shadow
from engine.render.gpu import layered_target
from engine.render.renderer import Renderer
from engine.render.shadows import LIGHT_LIMITS, VIRTUAL_RESOLUTION
from engine.render.sky import sunlight_tint
from engine.render.views import MAX_DIRECTIONAL_LIGHTS
from engine.resources import RenderStats, Surfaces
from engine.rules.frame_rules import active_camera_parts
from engine.rules.light_rules import (
    KeptLights,
    air_tinted,
    brightest_directional,
    cube_faces_lit,
    kept_lights,
    lamp_cone,
    lamp_cookie,
    lamp_rectangle,
    light_size,
    sphere_radius,
    spot_cone,
    spot_map_half_width,
)
from engine.rules.probe_rules import pose_bounds, world_bounds
from engine.rules.shadow_rules import (
    ENCLOSING_SHARE,
    MAX_VIRTUAL_LIGHTS,
    CascadeRing,
    Cascades,
    DirectionalFit,
    ShadowCasters,
    VirtualLight,
    boxes_in_reach,
    changed_region,
    directional_fit,
    holds_point,
    level_fit_box,
    level_on_grid,
    rank_virtual_lights,
    reflected_caustic_water,
    ring_cell,
    ring_fit,
    ring_radii,
    virtual_lights,
    virtual_shadow_camera,
)
from engine.rules.visibility_rules import ShadowCasting
from systems.shadow_rings import ring_to_draw

# What decides whether, and what shape, a thing casts.
_LOOKS = (MeshRef, Material, Visibility, Refractive, Portal, Skin, Morph)


class ShadowSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self.enabled = True   # the debug overlay's toggle: off, no light casts
        self._directional: dict[int, tuple] = {}   # slot -> what its map was drawn from
        self._fits: dict[int, DirectionalFit] = {}  # slot -> its map's camera
        self._rings: dict[int, tuple] = {}          # ring -> (what its map was drawn from, its camera)
        self._ring_cells_kept: dict[tuple, tuple[int, int]] = {}  # (slot, radius) -> its cell (ring_cell's kept)
        self._virtual: dict[int, tuple] = {}        # virtual light slot -> what its map was drawn from
        # The view tree's depth cap (a light goes no deeper through mirrors than a view does):
        # the engine ties it to the reflect stage's ``max_depth_cap``; a number or a callable.
        self.depth_cap: int | Callable[[], int] = 8
        self._point: dict[int, tuple] = {}         # cube slot -> what its cube was drawn from
        self._casters_seen = -1
        self._bounds: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # entity -> world box (point lights only)
        self._enclosed_said: set[tuple[int, int]] = set()   # (light, mesh entity) pairs warned of (_say_enclosed)
        self._enclosure_asked: set[int] = set()   # the casting point lights asked about every mesh (_say_enclosed)
        self._uploaded = b""
        self._points_clear = False  # no point light cast since the slots and cubes were last cleared
        self._level_seen: tuple = (None, (b"", b""))  # (level box, its bytes): _level_bytes
        self._level: tuple[np.ndarray, np.ndarray] | None = None  # the level's box as last asked (process)
        # The box the suns' maps are fitted to (``level_fit_box``) and the level's box it was worked from.
        self._fitted: tuple[np.ndarray, np.ndarray] | None = None
        self._fitted_from: tuple[np.ndarray, np.ndarray] | None = None
        # What the directional maps were last made or kept from: (level box, the lights, (atlas
        # tile, filter, enabled), the casting lights' directions as published); None: look again.
        self._still: tuple | None = None
        # The light rule's choice last read, and its directional lights slot by slot.
        self._kept: tuple[KeptLights | None, list[DirectionalLight | None]] = (None, [])
        # The active camera's rings and the atlas's free squares, for the pictures' (``_draw_rings``).
        self._cascades: Cascades | None = None
        self._cascade_stamp = 0   # the frames casters changed in (Cascades.stamp)
        world.resources[ShadowCasters] = ShadowCasters()

    def process(self, dt: float) -> None:
        renderer = self.renderer
        maps = renderer.shadows
        world = self.world
        casters_changed = renderer.casters_version != self._casters_seen
        self._casters_seen = renderer.casters_version
        changed_box, changed_parts = renderer.take_changes()
        # The level's box only where a map is fitted to it (a sun that casts, a surface that
        # carries light): a world of 100,000 instances and no such light pays nothing for it.
        surfaces = world.resources.get(Surfaces)
        carrying = surfaces is not None and any(s.carries_light for s in (*surfaces.mirrors.values(),
                                                                         *surfaces.portals.values()))
        kept = kept_lights(world, LIGHT_LIMITS)
        if kept is not self._kept[0]:   # a new choice (a light came, went, changed or moved)
            self._kept = (kept, [None if entity is None else world.get(entity, DirectionalLight)
                                 for entity in kept.directional])
        suns = self._kept[1]
        needed = self.enabled and (carrying or any(light is not None and light.shadows for light in suns))
        if not needed:
            level = self._level = None
        elif casters_changed or changed_box is not None or self._level is None:
            # A batch's box changes only with an upload that writes rows (which moves
            # ``casters_version`` on) or a row or batch gone (a changed box): else last frame's.
            bounds = renderer.level_bounds()
            level = self._level = None if bounds is None else level_on_grid(bounds)
        else:
            level = self._level
        published = ShadowCasters(level=level)
        # The suns' maps are fitted to the level's box with slack (``level_fit_box``): a thing
        # moving out past the level's edge does not fit them anew every frame.
        fitted = self._fitted = None if level is None else \
            self._fitted if level is self._fitted_from else level_fit_box(self._fitted, level)
        self._fitted_from = level
        # (A batch's last row gone writes no row, so ``casters_version`` stays: its box says it.)
        self._directional_maps(suns, casters_changed or changed_box is not None, (changed_box, changed_parts),
                               fitted, published)
        self._point_maps(kept, published)
        # A virtual light's map is drawn whole: again only when what casts changed (the
        # changed box: a row that casts moved, came, went or started or stopped casting).
        published.virtual = self._virtual_maps(kept, changed_box is not None, fitted, carrying)
        changed = casters_changed or changed_box is not None
        self._cascade_stamp += changed
        if self._cascades is not None and level is not None and self.enabled:
            published.cascades = replace(self._cascades, casters_changed=changed, changes=(changed_box, changed_parts),
                                         stamp=self._cascade_stamp)
        world.resources[ShadowCasters] = published
        block = maps.block.tobytes() + maps.virtual_block.tobytes()
        if block != self._uploaded:
            maps.upload()
            self._uploaded = block

    def _level_bytes(self, level: tuple[np.ndarray, np.ndarray]) -> tuple[bytes, bytes]:
        """The level's box as bytes, for the maps' keys (made again only for another box:
        ``Renderer.level_bounds`` gives the same one while no batch's union changed)."""
        seen = self._level_seen
        if seen[0] is not level:
            seen = self._level_seen = (level, (level[0].tobytes(), level[1].tobytes()))
        return seen[1]

    # --- directional lights -------------------------------------------------------------------
    def _directional_maps(self, lights: list[DirectionalLight | None], casters_changed: bool, changes, level,
                          published: ShadowCasters) -> None:
        """Each of ``lights`` (the kept ones, slot by slot as in the Lights block; None: a
        freed slot) that casts, fitted to the box ``level`` (``level_fit_box``'s; None: no
        level) (``changes``: the renderer's changed box and its parts):
        its map kept, drawn again where casters changed, or drawn whole for a new fit; a slot
        that stopped casting cleared."""
        maps = self.renderer.shadows
        stats: RenderStats = self.world.resources[RenderStats]
        changed_box, changed_parts = changes
        # A still frame: no caster changed, the same level box and lights, none of them
        # written (the prepare stage's test for the Lights block), the same atlas and filter:
        # every casting light's map is kept as it was.
        lights = tuple(lights)
        still = self._still
        eye = self._eye() if any(light is not None and light.shadow_cascades > 1 for light in lights) else None
        cells = self._ring_cells(lights, eye)
        if (still is not None and not casters_changed and changed_box is None and still[0] is level
                and still[1] == lights and still[2] == (maps.tile, maps.filter, self.enabled)
                and still[4] == cells and not self.world.changed(DirectionalLight)):
            published.directional.extend(still[3])
            stats.shadow_maps_kept += len(still[3]) + len(self._rings)
            stats.shadow_cascades_cut += still[5]
            return
        self._still = None
        kept = self._directional
        casting = [(slot, light) for slot, light in enumerate(lights) if light is not None and light.shadows] \
            if self.enabled and level is not None else []
        if len(kept) != len(casting) or any(slot not in kept for slot, _ in casting):
            for slot in [slot for slot in kept if slot not in dict(casting)]:
                del kept[slot]
                maps.clear_directional(slot)
        if not casting:
            maps.fit_see_through(False)
            self._draw_rings([], eye, casters_changed, changes)
            self._still = (level, lights, (maps.tile, maps.filter, self.enabled), (), cells, 0)
            return
        tile = max(light.shadow_resolution for _, light in casting) if len(casting) > 1 else \
            casting[0][1].shadow_resolution
        if tile != maps.tile:
            maps.fit_atlas(tile)
        if maps.fit_see_through(bool(self.renderer.see_through_casters())):
            self._directional.clear()   # (each sun's map drawn whole again, its see-through tile with it)
        level_bytes = self._level_bytes(level)
        for slot, light in casting:
            direction = raw_field(light, "direction")  # past the in-place watch: a read, not a game's edit
            facing = tuple(direction)
            published.directional.append(facing)
            maps.set_sun_size(slot, light.angular_diameter, f"the DirectionalLight in slot {slot}")
            key = (facing, light.shadow_resolution, light.shadow_softness, maps.tile, maps.filter, level_bytes)
            same = key == self._directional.get(slot)
            if same and not casters_changed:
                stats.shadow_maps_kept += 1
                continue
            region = None
            if same:
                # Only casters changed, within the level's box (the fit is the same): only the
                # texels under where they were and are are drawn again.
                fit = self._fits[slot]
                region = changed_region(fit, changed_box, changed_parts, light.shadow_resolution)
                if region is not None and region[2] * region[3] == 0:
                    stats.shadow_maps_kept += 1   # what changed casts nothing here (or is glass)
                    continue
            else:
                fit = self._fits[slot] = directional_fit(direction, level[0], level[1], light.shadow_resolution)
            stats.shadow_texels_drawn += maps.draw_directional(slot, fit, light.shadow_resolution,
                                                               light.shadow_softness, region)
            self._directional[slot] = key
            stats.shadow_maps_drawn += 1
        cut = self._draw_rings(casting, eye, casters_changed, changes)
        self._still = (level, lights, (maps.tile, maps.filter, self.enabled), tuple(published.directional),
                       self._ring_cells(lights, eye), cut)

    # --- cascades: rings about the camera -----------------------------------------------------
    def _eye(self) -> tuple[float, float, float] | None:
        """Where the active camera stands (the rings' centre), or None with no camera."""
        parts = active_camera_parts(self.world)
        if parts is None:
            return None
        m = current_world_matrix(self.world, parts[2])
        return float(m[3].x), float(m[3].y), float(m[3].z)

    def _ring_cells(self, lights: tuple, eye) -> tuple:
        """Each casting light's rings' grid cells about ``eye`` by its present fit (what a
        still frame compares: the camera moved into another cell, a ring is drawn again)."""
        if eye is None:
            return ()
        return tuple((slot, ring_cell(self._fits[slot], eye, radius, light.shadow_resolution,
                                      self._ring_cells_kept.get((slot, radius))))
                     for slot, light in enumerate(lights)
                     if light is not None and light.shadows and light.shadow_cascades > 1 and slot in self._fits
                     for radius in ring_radii(light.shadow_distance, light.shadow_cascades - 1))

    def _draw_rings(self, casting: list, eye, casters_changed: bool, changes) -> int:
        """Each casting light's rings (``DirectionalLight.shadow_cascades`` - 1 of them, about
        the camera at ``eye``) into the atlas tiles no light's level map takes, in slot order,
        outermost first: kept, drawn again under changed casters, or drawn whole in a new
        cell (``shadow_rings.ring_to_draw``).  The rings that find no tile are counted in
        ``shadow_cascades_cut`` (returned).  What the monitors' pictures need to draw the same
        rings about their cameras is kept for ``ShadowCasters.cascades`` (``_cascades``)."""
        maps = self.renderer.shadows
        stats: RenderStats = self.world.resources[RenderStats]
        free = [tile for tile in range(MAX_DIRECTIONAL_LIGHTS) if tile not in {slot for slot, _ in casting}]
        ring = cut = 0
        cells: dict[tuple, tuple[int, int]] = {}   # the rings' cells now (only these are kept)
        rings: list[CascadeRing] = []
        for slot, light in casting:
            if light.shadow_cascades < 2 or eye is None:
                continue
            level = self._fits[slot]
            for radius in ring_radii(light.shadow_distance, light.shadow_cascades - 1):
                if not free:
                    cut += 1
                    continue
                tile = free.pop(0)
                maps.set_ring_blend(ring, light.shadow_cascade_blend)
                cell = cells[slot, radius] = ring_cell(level, eye, radius, light.shadow_resolution,
                                                       self._ring_cells_kept.get((slot, radius)))
                key = (self._directional[slot], tile, radius, cell)
                todo = ring_to_draw(self._rings.get(ring), key, casters_changed, changes, light.shadow_resolution)
                if todo is None:
                    stats.shadow_maps_kept += 1
                else:
                    fit = todo[0] or ring_fit(level, cell, radius, light.shadow_resolution)
                    stats.shadow_texels_drawn += maps.draw_ring(ring, tile, slot, fit, light.shadow_resolution,
                                                                light.shadow_softness, todo[1])
                    stats.shadow_maps_drawn += 1
                    self._rings[ring] = (key, fit)
                rings.append(CascadeRing(ring, slot, radius, light.shadow_resolution, light.shadow_softness))
                ring += 1
        for stale in [r for r in self._rings if r >= ring]:
            del self._rings[stale]
        self._ring_cells_kept = cells
        maps.clear_rings(ring)
        stats.shadow_cascades_cut += cut
        half = maps.tile // 2
        self._cascades = None if not rings else Cascades(
            tuple(rings), {slot: self._fits[slot] for slot, _ in casting}, dict(self._directional),
            tuple((x + dx, y + dy) for x, y in map(maps.tile_origin, free) for dy in (0, half) for dx in (0, half)),
            half, maps.atlases_made)
        return cut

    # --- point lights -------------------------------------------------------------------------
    def _point_maps(self, kept: KeptLights, published: ShadowCasters) -> None:
        """The cube of each point light the rule gives one (``KeptLights.point_shadows``: cube
        slot -> light), read at the light's slot of the Lights block; kept while the light,
        its range and the casters in its reach stand still."""
        world = self.world
        maps = self.renderer.shadows
        stats: RenderStats = self.world.resources[RenderStats]
        casting = [(slot, kept.point_slot(entity), entity, world.get(entity, PointLight), world.get(entity, Transform))
                   for slot, entity in enumerate(kept.point_shadows) if entity is not None] if self.enabled else []
        if self.enabled:
            stats.shadows_cut += kept.shadows_cut   # left out of the block, or kept past the cubes
        if not casting:
            if not self._points_clear:  # cleared once when the last one stops casting
                maps.clear_points()
                self._point.clear()
                self._bounds.clear()
                self._enclosure_asked.clear()
                maps.drop_unused_cubes(set())
                maps.fit_spot_atlas(0)
                maps.fit_lamp_see_through(False, 0)
                self._points_clear = True
            return
        maps.clear_points()
        self._points_clear = False
        # See-through things dim the lamps too (their see-through tiles, drawn with each map):
        # a new atlas draws every map again.
        if maps.fit_lamp_see_through(bool(self.renderer.see_through_casters()),
                                     max(light.shadow_resolution for _, _, _, light, _ in casting)):
            self._point.clear()
        changed_lo, changed_hi = self._changed_boxes(glass_casts=maps.lamp_see_through_atlas is not None)
        layered = layered_target(self.renderer.path_checks)  # (into the cube, or an array copied into it)
        spots = {slot: half_width for slot, _, _, light, _ in casting
                 if (half_width := spot_map_half_width(light)) is not None}
        maps.fit_spot_atlas(max((light.shadow_resolution for slot, _, _, light, _ in casting if slot in spots),
                                default=0))
        for slot, index, entity, light, transform in casting:
            world_matrix = transform.world
            position = world_matrix[3].xyz
            published.points.append((tuple(position), light.range))
            half_width = spots.get(slot)
            if half_width is None:   # a cube: the faces the cone (or all round, every face) meets
                axes = [face.forward for face in CUBE_FACES]
                how = cube_faces_lit(lamp_cone(light, world_matrix), axes)
                if light.rectangle[0] > 0.0:   # a rectangle lights the half space before it: the face behind is not
                    front = -glm.normalize(world_matrix[2].xyz)
                    ahead = cube_faces_lit(spot_cone(tuple(front), 90.0, 0.0), axes)
                    how = tuple(lit and before for lit, before in zip(how, ahead, strict=True))
            else:                    # a spot's map: along its axis (-Z), in its atlas
                how = (tuple(-glm.normalize(world_matrix[2].xyz)), half_width, maps.spot_tile)
            size = light_size(light, world_matrix)
            key = (entity, tuple(position), light.range, light.shadow_resolution, light.shadow_softness, maps.filter,
                   how, size)
            reached = len(changed_lo) and boxes_in_reach(changed_lo, changed_hi, np.array(position), light.range).any()
            if key == self._point.get(slot) and not reached:
                maps.keep_point(slot, index)
                stats.shadow_maps_kept += 1
                continue
            if half_width is None:
                stats.shadow_path = maps.draw_point(slot, index, position, light.range, light.shadow_resolution,
                                                    light.shadow_softness, layered, how, size, entity)
            else:
                stats.shadow_path = maps.draw_spot(slot, index, position, glm.vec3(how[0]), half_width, light.range,
                                                   light.shadow_resolution, light.shadow_softness, entity)
            self._point[slot] = key
            stats.shadow_maps_drawn += 1
        self._say_enclosed([(entity, transform.world[3].xyz, light.range)
                            for _, _, entity, light, transform in casting])
        maps.drop_unused_cubes({row[0] for row in casting if row[0] not in spots})
        used = {row[0] for row in casting}
        for slot in [s for s in self._point if s not in used]:
            del self._point[slot]

    def _say_enclosed(self, casting: list[tuple[int, glm.vec3, float]]) -> None:
        """Warn, once a pair, where a casting point light (``casting``: entity, position,
        range) stands inside another entity's mesh that casts, closes round it
        (``shadow_rules.holds_point``) and is small beside its range (``ENCLOSING_SHARE``): a
        bulb made apart from its light, whose shadow leaves all the light reaches outside it
        dark.  (A light's own mesh casts none of its shadow: ``Shadows._draw_casters``.)  A
        light is asked about every mesh when it starts to cast, and each mesh that came this
        frame about every casting light (the world boxes ``_changed_boxes`` keeps): a still
        scene, and one whose things only move, asks nothing.  A bent, cut-out or see-through
        mesh (glass too: ``ShadowCasting``) is not asked about: it lets light out."""
        fresh = {entity for entity, _, _ in casting if entity not in self._enclosure_asked}
        self._enclosure_asked = {entity for entity, _, _ in casting}
        added = [entity for entity in self.world.frame.added if entity in self._bounds]
        if not fresh and not added:
            return
        world = self.world
        judge: ShadowCasting | None = None
        for light, position, light_range in casting:
            point = tuple(position)
            for entity in (self._bounds if light in fresh else added):
                lo, hi = self._bounds[entity]
                if entity == light or (light, entity) in self._enclosed_said \
                        or not all(a <= p <= b for a, p, b in zip(lo.tolist(), point, hi.tolist(), strict=True)) \
                        or max((hi - lo).tolist()) > ENCLOSING_SHARE * light_range:
                    continue
                mesh_ref, transform = world.try_get(entity, MeshRef), world.try_get(entity, Transform)
                if mesh_ref is None or transform is None:
                    continue
                mesh, material = mesh_ref.mesh, world.try_get(entity, Material)
                if mesh.skinned or mesh.morph_count or (material is not None and material.alpha_cutoff is not None) \
                        or (material is not None and material.color.w < 1.0):   # (see-through: it lets its share out)
                    continue
                judge = judge or ShadowCasting(world)
                if not judge.casts(entity, mesh_ref, world.try_get(entity, Visibility)):
                    continue
                local = glm.inverse(transform.world) * glm.vec4(position, 1.0)
                if holds_point(mesh.positions, mesh.indices, tuple(glm.vec3(local))):
                    self._enclosed_said.add((light, entity))
                    warn_component(
                        f"PointLight on entity {light} casts shadows from inside the mesh of entity {entity} "
                        f"({mesh.name!r}), which closes round it and casts shadows too: the light reaches "
                        f"nothing outside that mesh. If it is the light's bulb, put the PointLight on entity "
                        f"{entity} (a light's own mesh casts none of its shadow) or give it "
                        f"MeshRef(casts_shadows=False)")

    def _changed_boxes(self, glass_casts: bool) -> tuple[np.ndarray, np.ndarray]:
        """The old and new world boxes of every drawable that moved, came, went or changed
        its look this frame (all boxes are measured the first time: every cube is new then),
        but for one that only moved and casts no shadow (``ShadowCasting``: its look as
        before, it cast none where it was either; ``glass_casts``: glass dims the lamps, in
        their see-through maps)."""
        world = self.world
        frame = world.frame
        if not self._bounds:
            self._bounds = {entity: world_bounds(mesh_ref.mesh, transform.world,
                                                 pose_bounds(world, entity, mesh_ref.mesh))
                            for entity, (mesh_ref, transform) in world.query(MeshRef, Transform)}
            return np.zeros((0, 3)), np.zeros((0, 3))
        gone = frame.removed | world.deleted()
        looks = set().union(*(world.changed(kind) for kind in _LOOKS))
        boxes = []
        casting: ShadowCasting | None = None
        for entity in frame.moved | frame.added | gone | looks:
            old = self._bounds.pop(entity, None)
            new = None
            if world.exists(entity):
                mesh_ref, transform = world.try_get(entity, MeshRef), world.try_get(entity, Transform)
                if mesh_ref is not None and transform is not None:
                    new = self._bounds[entity] = world_bounds(mesh_ref.mesh, transform.world,
                                                              pose_bounds(world, entity, mesh_ref.mesh))
            if entity not in looks and entity not in frame.added and entity not in gone and new is not None:
                casting = casting or ShadowCasting(world, glass_casts)
                if not casting.casts(entity, mesh_ref, world.try_get(entity, Visibility)):
                    continue  # moved alone, casting nothing here nor where it was
            boxes.extend(box for box in (old, new) if box is not None)
        if not boxes:
            return np.zeros((0, 3)), np.zeros((0, 3))
        return np.array([lo for lo, _ in boxes]), np.array([hi for _, hi in boxes])

    # --- lights through mirrors and portals ---------------------------------------------------
    def _virtual_maps(self, kept: KeptLights, shadows_changed: bool, level, carrying: bool) -> list[VirtualLight]:
        """Each kept light's image through the mirrors and portals that carry light
        (``shadow_rules.virtual_lights``), brightest and highest priority first, at most
        ``MAX_VIRTUAL_LIGHTS``: a map each, drawn when it or a caster changed, a view of the
        frame's ``ViewBudget`` each time it is drawn; one the limit or the budget leaves out
        lights nothing and is counted in ``RenderStats.virtual_lights_cut``.  ``level``: the box the
        suns' maps are fitted to (``level_fit_box``'s), which each map holds."""
        world = self.world
        renderer = self.renderer
        maps = renderer.shadows
        stats: RenderStats = world.resources[RenderStats]
        surfaces = world.resources.get(Surfaces)
        found: list[VirtualLight] = []
        if self.enabled and level is not None and carrying:  # no surface carries light: no list to make
            suns = [(entity, world.get(entity, DirectionalLight)) for entity in kept.directional if entity is not None]
            lamps = [(entity, (world.get(entity, PointLight), world.get(entity, Transform)))
                     for entity in kept.point if entity is not None]
            sun = brightest_directional(world)   # (an atmosphere reddens it and the moons as they set: sunlight_tint)
            skies = world.query_one(Skybox)
            sky = skies[0][1] if skies else None
            directional = [(entity, raw_field(light, "direction"), raw_field(light, "color").xyz * light.intensity
                            * (glm.vec3(*sunlight_tint(sky, tuple(light.direction))) if air_tinted(light, sun)
                               else glm.vec3(1.0)))
                           for entity, light in suns]
            cookies = renderer.spot_cookies
            points = [(entity, transform.world[3].xyz, light.range, raw_field(light, "color").xyz * light.intensity,
                       lamp_cone(light, transform.world),
                       lamp_cookie(light, transform.world, cookies.layer(light.cookie)), sphere_radius(light),
                       lamp_rectangle(light, transform.world, cookies.layer(light.cookie)))
                      for entity, (light, transform) in lamps]
            bounces = {entity: light.bounces for entity, light in suns}
            bounces.update({entity: light.bounces for entity, (light, _) in lamps})
            cap = self.depth_cap() if callable(self.depth_cap) else self.depth_cap
            found = rank_virtual_lights(virtual_lights(directional, points, surfaces, bounces, cap))
        if not found and not self._virtual and not maps.virtual_shining:
            maps.fit_virtual_see_through(False)
            stats.virtual_lights = 0   # none shines, none did: nothing to draw, clear or count
            return []
        # See-through things dim them too (a see-through tile beside each map): a new atlas
        # draws every map again.
        if maps.fit_virtual_see_through(bool(found) and bool(renderer.see_through_casters())):
            self._virtual.clear()
        drawn = 0
        shining: list[VirtualLight] = []
        caustic_slots = {water.entity: slot for slot, water in enumerate(renderer.caustics.waters)}
        for light in found:
            slot = drawn
            if slot == MAX_VIRTUAL_LIGHTS:
                stats.virtual_lights_cut += 1
                continue
            # (its edges filtered as its light's own: shadow_softness texels of the map holding them)
            softness = world.get(light.light, DirectionalLight if light.kind == "directional" else PointLight
                                 ).shadow_softness
            key = (light.light, light.path, light.kind, light.position, light.color, light.light_range, light.cone,
                   light.cookie, light.radius, light.rectangle, softness,
                   light.exit_plane, light.aperture, light.apertures,
                   tuple((leg.carry.to_bytes(), tuple(p.to_bytes() for p in leg.planes), leg.skip)
                         for leg in light.legs),
                   *self._level_bytes(level), maps.filter)
            if key != self._virtual.get(slot) or shadows_changed:
                left = stats.views_left()
                if left is not None and left <= 0:
                    stats.virtual_lights_cut += 1
                    self._virtual.pop(slot, None)
                    continue
                lo, hi = level
                if light.kind == "directional":
                    for leg in light.legs[1:]:
                        lo, hi = _with_image(lo, hi, leg.carry, *level)
                maps.draw_virtual(slot, light, virtual_shadow_camera(light, lo, hi, VIRTUAL_RESOLUTION), softness)
                self._virtual[slot] = key
                stats.views_spent += 1
                stats.shadow_maps_drawn += 1
            else:
                stats.shadow_maps_kept += 1
            through = _through_clouds_at(light, world, renderer, surfaces)
            if through != 1.0:
                light = replace(light, color=tuple(c * through for c in light.color))
            maps.set_virtual_color(slot, light.color, light.light_range)
            maps.set_virtual_caustic(slot, caustic_slots.get(reflected_caustic_water(light), -1))
            shining.append(light)
            drawn += 1
        for slot in [s for s in self._virtual if s >= drawn]:
            del self._virtual[slot]
        stats.virtual_lights = drawn
        maps.set_virtual_count(drawn)  # the scene pass builds the virtual lights' loop while any shine
        return shining


def _through_clouds_at(light: VirtualLight, world: World, renderer: Renderer, surfaces: Surfaces | None) -> float:
    """The share of a directional ``light``'s light a CloudLayer lets reach the first mirror or
    portal on its way (``cloud_shadow`` at that surface's middle, towards the light): 1 for a
    lamp's image, a fill light's (only the sun and the moons are under the clouds:
    ``air_tinted``) and without clouds that shade.  One share a light (taken at one point: a
    mirror is small beside a cloud)."""
    shape = renderer.clouds.shape
    if shape is None or not shape.shadows or light.kind != "directional" or surfaces is None:
        return 1.0
    real = world.try_get(light.light, DirectionalLight)
    first = surfaces.mirrors.get(light.path[0]) or surfaces.portals.get(light.path[0]) if light.path else None
    if real is None or first is None or first.outline is None or not air_tinted(real, brightest_directional(world)):
        return 1.0
    middle = np.asarray(first.outline, np.float64).reshape(-1, np.shape(first.outline)[-1])[:, :3].mean(axis=0)
    return float(cloud_shadow(shape, middle, -np.array(tuple(real.direction), np.float64)))


def _with_image(lo: np.ndarray, hi: np.ndarray, carry, level_lo: np.ndarray,
                level_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box [lo, hi] grown to hold the level's box [level_lo, level_hi] under ``carry``
    (a virtual light's map holds the scene and its image on each stretch of the way)."""
    corners = np.array([[x, y, z, 1.0] for x in (level_lo[0], level_hi[0]) for y in (level_lo[1], level_hi[1])
                        for z in (level_lo[2], level_hi[2])])
    image = corners @ np.array(carry.to_list(), np.float64)
    return np.minimum(lo, image[:, :3].min(axis=0)), np.maximum(hi, image[:, :3].max(axis=0))
