"""Prepare: upload what the extract stage changed, before any view is drawn.

Only the instance rows written this frame go to the GPU, the lights when their block
changes (worked out again only when a light came, went, changed or moved, or the sky
changed), the sky's cube map when the Skybox changes or, for a generated sky whose sun
follows the brightest directional light (``Skybox.sun_direction`` None), when that light
turns or another takes its place (while it turns, the cube up to a degree behind the sky
pass: ``_sky``).

Ambient light (``engine/render/irradiance.py``): the sky's irradiance as nine
spherical-harmonic coefficients in the Lights block, projected from the Skybox's faces when
the Skybox changes; without a Skybox, the ``HemisphereLight``'s (a dim default without one).
Which lights fill the block's slots (``MAX_DIRECTIONAL_LIGHTS`` directional and
``MAX_POINT_LIGHTS`` point lights) is ``engine/rules/light_rules.py``'s rule: point lights by
their importance to the active camera, directional ones by luminance, each kept light in a
stable slot.  It is asked again when a light came, went, changed or moved, or, while the
answer depends on the camera (more point lights than slots), when the camera moved; the
answer is published as ``KeptLights`` for the shadows stage.  Lights left out light
nothing: they are counted in ``RenderStats.lights_cut`` every frame, and a
``LightLimitWarning`` names them when the count goes up; so do the point lights that cast
shadows past the shadow cubes (``LIGHT_LIMITS.point_shadows``; they cast none:
``RenderStats.shadows_cut``).
The probes' influence boxes go to the irradiance table when a probe comes, goes, changes or
moves; their coefficients are projected on the GPU after each capture (the probes stages).
The waters whose waves gather the sun (``Water.caustics``; ``engine/render/caustics.py``: the
four nearest the camera) go to their block every frame their waves move.
"""
from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator

import esper
import numpy as np
from pyglm import glm

from components import (
    CloudLayer,
    ComponentWarning,
    DirectionalLight,
    Fog,
    FogVolume,
    HemisphereLight,
    PointLight,
    ReflectionProbe,
    Skybox,
    Transform,
    Water,
)
from components.ambient import DEFAULT_GROUND, DEFAULT_SKY
from components.limits import MAX_CONTACT_LAMPS, MAX_FOG_VOLUMES, MAX_RECT_LIGHTS, MAX_VOLUMETRIC_LAMPS
from engine.core.errors import CausticLimitWarning, FogLimitWarning, LightLimitWarning, WaterLimitWarning
from engine.core.world import World
from engine.render.caustics import (
    MAX_CAUSTIC_LAMPS,
    MAX_CAUSTIC_WATERS,
    CausticWater,
    caustic_map_size,
    caustic_rows,
    lamps_over,
    nearest_first,
)
from engine.render.clouds import CloudShape, cloud_shape, drift_served, shadows_served
from engine.render.foam import MAX_FOAM_WATERS, FoamWater, foam_frame, foam_rows
from engine.render.fog import volume_rows, water_body_row
from engine.render.irradiance import generated_sky_sh, hemisphere_sh, project_faces
from engine.render.renderer import Renderer
from engine.render.shadows import LIGHT_LIMITS
from engine.render.sky import air_light, is_generated, sky_model, sunlight_tint
from engine.render.views import MAX_DIRECTIONAL_LIGHTS, MAX_POINT_LIGHTS, lights_block
from engine.resources import CloudChanges, ContactLamps, Surfaces, SurfaceState, VolumetricLamps
from engine.rules.frame_rules import frame_rules
from engine.rules.light_rules import (
    ALL_ROUND,
    NO_COOKIE,
    NO_RECTANGLE,
    SAME_SUN_DEGREES,
    SAME_SUN_TINT,
    KeptLights,
    SkySun,
    air_tinted,
    brightest_directional,
    choice_stands,
    choose_lights,
    cube_serves,
    is_panel,
    kept_lamp_places,
    kept_sun_ways,
    lamp_cone,
    lamp_cookie,
    lamp_rectangle,
    sky_sun,
    sphere_radius,
)

# A freed slot no light took yet: black (no light), its range 1 (no division by zero).
_NO_SUN = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
_NO_LAMP = ((0.0, 0.0, 0.0), 1.0, (0.0, 0.0, 0.0), ALL_ROUND, NO_COOKIE, 0.0)


def ambient_sh(world: World, sun: SkySun | None = None, clouds: CloudShape | None = None) -> np.ndarray:
    """The world's sky irradiance coefficients (9, 3): the Skybox's (a generated one's in
    closed form, with ``sun`` where its cube map has it, else ``sky_sun``, and ``clouds``;
    given faces projected), else the lowest entity's HemisphereLight, else the default dim
    hemisphere (``components.ambient.DEFAULT_SKY`` and ``DEFAULT_GROUND``)."""
    skies = world.query_one(Skybox)
    if skies:
        sky = skies[0][1]
        if not is_generated(sky):
            return project_faces(sky.faces)
        return generated_sky_sh(sky_model(sky, sun or sky_sun(world, sky), clouds))
    hemispheres = world.query_one(HemisphereLight)
    if hemispheres:
        light = min(hemispheres, key=lambda pair: pair[0])[1]
        return hemisphere_sh(light.sky.xyz * light.intensity, light.ground.xyz * light.intensity)
    return hemisphere_sh(DEFAULT_SKY, DEFAULT_GROUND)


def _live(world: World, said: set[int]) -> set[int]:
    """The entities of a said-once set ``said`` that are alive: deleted ones are let go when a
    new one is said to (one deleted after ``World.deleted`` was read, by a later stage, too),
    so such a set holds at most the warned entities alive at once, plus one."""
    return {entity for entity in said if world.exists(entity)}


class PrepareSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        self._lights = b""
        self._sky_sh: np.ndarray | None = None
        self._flat_sky = True   # no Skybox: the sky cube is the flat background (lights_block's flat_sky)
        self._cut = (0, 0)   # (directional, point) lights the last block left out
        self._shadows_cut = 0   # point lights casting shadows the last block gave no cube
        self._contact = ContactLamps()   # the lamps with contact shadows the last block gave channels
        self._rect_slots: tuple[int, ...] = ()   # the slots lit as rectangles (lights_block's rect_slots)
        self._rect_cut = 0                       # rectangles past MAX_RECT_LIGHTS, lit as points
        self._fog_cut = 0                        # FogVolumes past MAX_FOG_VOLUMES, left out
        self._fog_entities: tuple[int, ...] = ()   # the FogVolumes' entities, and their packed rows
        self._fog_packed: tuple[float, ...] = ()
        self._bodies: tuple = ()   # the water bodies the rows were packed for (_water_bodies)
        self._unboxed: set[int] = set()   # waters with a fog and no flat outline (said once)
        self._caustic_cut = 0                     # waters with caustics past MAX_CAUSTIC_WATERS, left out
        self._cuts: dict[str, int] = {}           # RenderStats field -> what a limit left out last frame (_say_cut)
        self._caustic_still: set[int] = set()     # waters with caustics and no waves to gather with (said once)
        self._caustic_keys: dict[int, tuple] = {}  # what each held water's rows were packed from (_caustics)
        self._volumetric = VolumetricLamps()   # the lamps the light shafts scatter, by slot
        self._kept: KeptLights | None = None   # the last choice of lights (light_rules)
        self._sun: SkySun | None = None   # where the sky pass draws the sun, and its tint (sky_sun)
        self._cube_sun: SkySun | None = None   # ... and where the sky's cube map and light have it
        self._sun_follows = False   # the generated sky follows the lights (its sun, unless pinned, and its moon)
        self._clouds: CloudShape | None = None        # the world's CloudLayer now (cloud_shape)
        self._cube_clouds: CloudShape | None = None   # ... as the sky's cube map and light have it
        self._pass_clouds: CloudShape | None = None   # ... as the sky pass draws it
        self._probe_clouds: CloudShape | None = None  # ... as the probes were last relit by it (CloudChanges)
        self._cloud_said: set[str] = set()            # what the CloudLayer was told (said once)
        self.fog = True   # the debug overlay's toggle: off, no camera's Fog is drawn
        self.caustics = True   # the debug overlay's toggle: off, no water gathers the sun (Water.caustics)
        # The debug overlay's toggle: off, no surface reflects the light from all round by its
        # material (its environment reflection; a Reflective's reflection stays).
        self.environment_reflections = True
        self._environment_packed = True   # the toggle as the lights block has it

    def process(self, dt: float) -> None:
        world = self.world
        renderer = self.renderer
        self._forget_deleted()
        sky_changed = self._sky()
        if not shadows_served(self._probe_clouds, self._clouds):   # (the probes' captures relit)
            self._probe_clouds = self._clouds
            changes = self.world.resources.get(CloudChanges, CloudChanges())
            self.world.resources[CloudChanges] = CloudChanges(changes.count + 1)
        if not sky_changed and (self._sky_sh is None or world.changed(HemisphereLight)):
            self._sky_sh = ambient_sh(world, self._cube_sun, self._cube_clouds)
            sky_changed = True
        renderer.upload_instances()
        renderer.pose_rows.settle_new()   # (a pose new this frame did not move)
        if renderer.object_motion.upload():   # (the movers' own motion: per-object motion blur)
            renderer.note_scene_change()
        self._probe_boxes()
        kept = self._kept
        if not (self._lights and not sky_changed and not world.changed(Skybox) and choice_stands(world, kept)
                and self._environment_packed == self.environment_reflections):
            kept = self._kept = choose_lights(world, kept, LIGHT_LIMITS)
            self._environment_packed = self.environment_reflections
            if self._cookies(kept):
                renderer.note_scene_change()   # an image in the cookie array changed, or its build
            lamps = [world.get(entity, PointLight) for entity in kept.point if entity is not None]
            spheres = any(sphere_radius(light) > 0.0 for light in lamps)
            # (a tube is lit as a rectangle turned to face each point: rect_lights.glsl)
            rectangles = any(light.rectangle[0] > 0.0 or light.length > 0.0 for light in lamps)
            if (spheres, rectangles) != (renderer.sphere_lights, renderer.rect_lights):
                renderer.sphere_lights = spheres   # the SPHERE_LIGHTS builds, or not
                renderer.rect_lights = rectangles  # the RECT_LIGHTS builds, or not
                if rectangles:
                    renderer.irradiance.write_ltc()   # (their table, once)
                renderer.note_scene_change()
            block = lights_block(self._sky_sh, *self._rows(kept), flat_sky=self._flat_sky,
                                 environment=self.environment_reflections, rect_slots=self._rect_slots)
            if block != self._lights:
                renderer.set_lights(block)
                self._lights = block
            self._count_cut(kept)
        world.resources[KeptLights] = kept   # every frame: what the shadows stage reads
        world.resources[ContactLamps] = self._contact   # ... and the main stage's contact shadows
        world.resources[VolumetricLamps] = self._volumetric   # ... and its light shafts
        renderer.stats.lights_cut = sum(self._cut)
        renderer.stats.contact_lamps_cut = self._contact.cut
        renderer.stats.rect_lights_cut = self._rect_cut
        camera = frame_rules(world).active_camera
        fog = None if camera is None or not self.fog else world.try_get(camera, Fog)
        renderer.fog.shown = self.fog   # (a monitor's camera's own Fog too: MonitorSystem._camera_fog)
        glow = air_light(world) if fog is not None and fog.sun_scatter > 0.0 else None   # (the sun or the moon)
        if renderer.fog.set(fog, None if glow is None else glow.light, self._fog_rows(camera) if self.fog else (),
                            (1.0, 1.0, 1.0) if glow is None else glow.tint):
            renderer.note_scene_change()   # every view's fogged pixels
        renderer.stats.fog_volumes_cut = self._fog_cut
        self._caustics(camera)
        self._foam()

    def _caustics(self, camera: int | None) -> None:
        """Give the caustics' block the waters that gather the sun: of the waters with
        ``caustics`` and waves (a normal map), the ``MAX_CAUSTIC_WATERS`` nearest the active
        camera, in the order of their entities (the rest counted and said when their count
        grows; the same waters nearer or farther keep their slots and maps).  A water's
        rows are packed again when its state, its waves' offset, its fields or the maps'
        layer size changed (every frame while the waves move); the block is written, and the
        views drawn again, only when they changed."""
        renderer = self.renderer
        found = []
        if self.caustics:
            for entity, state, water in self._waters():
                if water.caustics <= 0.0:
                    continue
                if state.bumps is None:   # (no normal map, or one the surface cannot read: no waves)
                    self._say_still(entity)
                    continue
                found.append((entity, state, water))
        cut = max(0, len(found) - MAX_CAUSTIC_WATERS)
        if cut:
            eye = np.zeros(3) if camera is None else np.array(self.world.get(camera, Transform).world[3].xyz)
            kept = set(nearest_first([(entity, state.corners) for entity, state, _ in found], eye)[:MAX_CAUSTIC_WATERS])
            found = [entry for entry in found if entry[0] in kept]
            if cut > self._caustic_cut:
                warnings.warn(CausticLimitWarning(
                    f"{MAX_CAUSTIC_WATERS + cut} waters have caustics: {MAX_CAUSTIC_WATERS} gather the sun at a time "
                    f"(the nearest the active camera, entities {sorted(entry[0] for entry in found)}), so {cut} "
                    "do not (RenderStats.caustic_waters_cut)"), stacklevel=3)
        found.sort(key=lambda entry: entry[0])
        self._caustic_cut = cut
        renderer.stats.caustic_waters_cut = cut
        held = {water.entity: water for water in renderer.caustics.waters}
        width = caustic_map_size([state.bumps.normal_map for _, state, _ in found])[0] if found else 0
        suns, lamps = ((kept_sun_ways(self.world, LIGHT_LIMITS), kept_lamp_places(self.world, LIGHT_LIMITS))
                       if any(state.carries_light for _, state, _ in found) else ((), ()))
        chosen = []
        for entity, state, water in found:
            box = self.renderer.caustics.reach.box(entity, state, water.depth, state.carries_light, suns, lamps)
            key = (state, state.water.flow.offset, water.tiling, water.cross, water.ior, water.caustics, water.depth,
                   width, box)
            kept = held.get(entity)
            if key == self._caustic_keys.get(entity) and kept is not None:
                chosen.append(kept)   # (a still water, as it was: nothing packed)
                continue
            rows = caustic_rows(tuple(state.plane), state.bumps, tiling=water.tiling, cross=water.cross,
                                offset=state.water.flow.offset, ior=water.ior, strength=water.caustics,
                                depth=water.depth, map_width=width)
            self._caustic_keys[entity] = key
            if rows is None:   # (UVs square to the surface: no frame to read the waves in)
                self._say_still(entity)
                continue
            chosen.append(CausticWater(entity, state.bumps.normal_map, rows, box))
        for entity in set(self._caustic_keys) - {entry[0] for entry in found}:
            del self._caustic_keys[entity]
        lamps = self._caustic_lamps(chosen)
        if renderer.caustics.set(chosen, lamps):
            renderer.note_scene_change()   # what every view shows under the waters

    def _foam(self) -> None:
        """Give the foam's block the waters with shore foam (``Water.foam``), the first
        ``MAX_FOAM_WATERS`` by entity (the rest counted and said when their count grows);
        their rows packed again every frame (the pattern drifts with the waves)."""
        renderer = self.renderer
        found = sorted((entry for entry in self._waters() if entry[2].foam > 0.0), key=lambda entry: entry[0])
        cut = max(0, len(found) - MAX_FOAM_WATERS)
        self._say_cut("foam_waters_cut", cut, lambda: WaterLimitWarning(
            f"{len(found)} waters have foam: {MAX_FOAM_WATERS} are drawn with it at a time (the first by entity: "
            f"{[entry[0] for entry in found[:MAX_FOAM_WATERS]]}), so {cut} are not (RenderStats.foam_waters_cut)"))
        waters = [FoamWater(entity, foam_rows(tuple(state.plane),
                                              foam_frame(tuple(state.plane), state.bumps, state.water.flow.offset,
                                                         water.tiling),
                                              water.foam, water.foam_depth, water.foam_scale, water.foam_color))
                  for entity, state, water in found[:MAX_FOAM_WATERS]]
        if renderer.foam.set(waters):
            renderer.note_scene_change()   # what every view shows of the waters

    def _caustic_lamps(self, chosen: list[CausticWater]) -> list[int]:
        """The kept lamps (their Lights block slots) over the held ``chosen`` waters whose light
        the waves gather (``caustics.lamps_over``): the ``MAX_CAUSTIC_LAMPS`` whose light at the
        water is brightest, the rest counted and said when their count grows."""
        kept = self._kept
        if not chosen or kept is None:
            self._say_cut("caustic_lamps_cut", 0, Warning)
            return []
        world = self.world
        lamps = [(slot, np.array(world.get(entity, Transform).world[3].xyz), light.range,
                  light.intensity * max(tuple(light.color)[:3]))
                 for slot, entity in enumerate(kept.point) if entity is not None
                 for light in (world.get(entity, PointLight),)]
        found = lamps_over(chosen, lamps)
        cut = max(0, len(found) - MAX_CAUSTIC_LAMPS)
        self._say_cut("caustic_lamps_cut", cut, lambda: CausticLimitWarning(
            f"{len(found)} lamps stand over waters with caustics: the light of the {MAX_CAUSTIC_LAMPS} brightest there "
            "is gathered "
            f"(entities {[kept.point[slot] for slot in found[:MAX_CAUSTIC_LAMPS]]}), so {cut} light the water's "
            "floor evenly (RenderStats.caustic_lamps_cut)"))
        return found[:MAX_CAUSTIC_LAMPS]

    def _say_cut(self, stat: str, cut: int, warning: Callable[[], Warning]) -> None:
        """Count ``cut`` (what a limit left out this frame) in ``RenderStats.<stat>``, and say
        it (the ``warning`` made) when the count grows past the last frame's."""
        if cut > self._cuts.get(stat, 0):
            warnings.warn(warning(), stacklevel=4)
        self._cuts[stat] = cut
        setattr(self.renderer.stats, stat, cut)

    def _waters(self) -> Iterator[tuple[int, SurfaceState, Water]]:
        """Each water surface this frame: its entity, its published state (the top) and its
        Water (none, and no loop, in a world without water: ``Surfaces.undersides`` holds one a water)."""
        surfaces = self.world.resources.get(Surfaces)
        if surfaces is None or not surfaces.undersides:
            return
        for entity, state in surfaces.mirrors.items():
            if state.water is not None and (water := self.world.try_get(entity, Water)) is not None:
                yield entity, state, water

    def _forget_deleted(self) -> None:
        """The said-once sets (``_caustic_still``, ``_unboxed``) let go of the entities deleted
        since the last frame, so a long run that makes and deletes warned waters holds no more
        (ids are never given twice in a world: a new water is a new id, said to again)."""
        deleted = self.world.deleted()
        if deleted and (self._caustic_still or self._unboxed):
            self._caustic_still -= deleted
            self._unboxed -= deleted

    def _say_still(self, entity: int) -> None:
        """Say, once, that the water on ``entity`` has caustics and no waves to gather with
        (those said to and deleted since, by a system after this stage, let go first)."""
        if entity not in self._caustic_still:
            self._caustic_still = _live(self.world, self._caustic_still)
            self._caustic_still.add(entity)
            warnings.warn(ComponentWarning(
                f"Water on entity {entity}: its caustics are the sun's light gathered by its waves, and it has none "
                "(no Material.normal_map, or a mesh whose UVs do not run along it), so it gathers no light"),
                stacklevel=5)

    def _fog_rows(self, camera: int | None) -> tuple[float, ...]:
        """The Fog block's rows of the ``FogVolume``s (``fog.volume_rows``) and the water bodies
        (``Water.fog_density``: ``fog.water_body_row``), at most ``MAX_FOG_VOLUMES``: past it
        the nearest the active camera (from its eye to each one's centre, less its largest half
        side), the rest counted and said when their count grows.  Made again only when a volume
        or a water's body came, went, changed or moved (or, past the limit, every frame: the
        camera's moves choose): a still world packs nothing."""
        world = self.world
        bodies = self._water_bodies()
        if not self._fog_cut and bodies == self._bodies and not world.changed(FogVolume) and not world.deleted() \
                and not any(entity in world.frame.moved for entity in self._fog_entities):
            return self._fog_packed
        self._bodies = bodies
        found = world.query(FogVolume, Transform)
        self._fog_entities = tuple(entity for entity, _ in found)
        # (row, centre, largest half side) of each: a volume's, then each water body's
        fogs = [(volume_rows([(volume, t.world)]), t.world[3].xyz, 0.5 * max(volume.size))
                for _, (volume, t) in found if volume.density > 0.0]
        fogs += [(row, centre, reach) for _, _, _, row, centre, reach in bodies]
        cut = max(0, len(fogs) - MAX_FOG_VOLUMES)
        if cut:
            eye = world.get(camera, Transform).world[3].xyz if camera is not None else glm.vec3(0.0)
            fogs.sort(key=lambda fog: glm.distance(fog[1], eye) - fog[2])
            fogs = fogs[:MAX_FOG_VOLUMES]
            if cut > self._fog_cut:
                warnings.warn(FogLimitWarning(
                    f"{MAX_FOG_VOLUMES + cut} FogVolumes and water bodies: at most {MAX_FOG_VOLUMES} fog the views "
                    f"at once (the nearest the active camera), so {cut} add no fog (RenderStats.fog_volumes_cut)"),
                    stacklevel=3)
        self._fog_cut = cut
        self._fog_packed = tuple(value for row, _, _ in fogs for value in row)
        return self._fog_packed

    def _water_bodies(self) -> tuple:
        """Each water with a ``fog_density``: (entity, its surface state, its fog fields, its
        block row, the box's centre, its largest half side); the row packed again only for a
        state or a field that changed.  A water whose mesh has no flat outline (the box's top)
        has no body, said once."""
        old = {body[0]: body for body in self._bodies}
        bodies = []
        for entity, state, water in self._waters():
            if water.fog_density <= 0.0:
                continue
            fields = (water.fog_density, tuple(water.fog_color), water.depth, tuple(water.absorption))
            body = old.get(entity)
            if body is not None and body[1] is state and body[2] == fields:
                bodies.append(body)
                continue
            if state.outline is None:
                if entity not in self._unboxed:
                    self._unboxed = _live(self.world, self._unboxed)
                    self._unboxed.add(entity)
                    warnings.warn(ComponentWarning(
                        f"Water on entity {entity}: its fog_density fogs a box under the water's outline, and its "
                        "mesh is not flat (no outline), so its body adds no fog; give the Mirror a flat mesh"),
                        stacklevel=4)
                continue
            down = -glm.vec3(state.plane)  # (the published state is the water's top: Surfaces.undersides)
            centre = glm.vec3(*np.asarray(state.outline, np.float64)[:, :3].mean(axis=0)) + down * (water.depth / 2)
            reach = 0.5 * max(water.depth, float(np.ptp(np.asarray(state.outline)[:, :3], axis=0).max()))
            bodies.append((entity, state, fields, water_body_row(state.outline, down, water.depth, water.fog_color,
                                                                 water.fog_density, water.absorption), centre, reach))
        return tuple(bodies)

    def _sky(self) -> bool:
        """The sky made anew where it changed: the Skybox came, went or changed, or the light a
        generated sky's sun follows turned or recoloured.  While that sun turns the sky pass
        follows it every frame (a few uniforms) and the cube map and the sky's light (a draw
        a face and a mip build; on llvmpipe a few ms of rasterising) only once the sun
        is past what the cube serves (``cube_serves``: a degree) or stands still again (not for a rounding:
        a direction normalised again moves a little).  True when the cube was made."""
        world = self.world
        if world.changed(CloudLayer):
            self._clouds = self._cloud_shape()
        if world.changed(Skybox):
            skies = world.query_one(Skybox)
            sky = skies[0][1] if skies else None
            self._sun_follows = is_generated(sky)   # (a pinned sun's sky still follows its moon)
            self._clouds = self._cloud_shape()      # (is there a sky to draw them in)
            self._make_sky(sky, self._sky_sun())
            return True
        if not self._sun_follows:
            return False
        sky = world.query_one(Skybox)[0][1]
        if self._clouds != self._cube_clouds and not drift_served(self._cube_clouds, self._clouds, sky.face_size):
            self._make_sky(sky, self._sky_sun())   # (the clouds changed, or drifted past what the cube serves)
            return True
        if not (world.changed(DirectionalLight) or self._sun != self._cube_sun):
            if self._clouds != self._pass_clouds:   # drifting: the sky pass follows every frame
                self._show_sky(sky, self._sun)
            return False
        sun = self._sky_sun()
        if cube_serves(self._cube_sun, sun, SAME_SUN_DEGREES, SAME_SUN_TINT):
            if self._sun != self._cube_sun or self._clouds != self._pass_clouds:  # back where the cube has it
                self._show_sky(sky, self._cube_sun)
            return False
        if sun != self._sun and cube_serves(self._cube_sun, sun):  # turning: the cube a moment later
            self._show_sky(sky, sun)
            return False
        self._make_sky(sky, sun)
        return True

    def _show_sky(self, sky: Skybox, sun: SkySun | None) -> None:
        """The sky pass draws ``sky`` with ``sun`` and the clouds now, the cube map kept."""
        self._sun, self._pass_clouds = sun, self._clouds
        self.renderer.set_sky_model(sky_model(sky, sun, self._clouds))

    def _make_sky(self, sky: Skybox | None, sun: SkySun | None) -> None:
        """The sky's cube map, the sky pass's model and the sky's light, of ``sky`` with ``sun``
        and the clouds now."""
        if is_generated(sky):
            self.renderer.set_generated_sky(sky_model(sky, sun, self._clouds), sky.face_size)
        else:
            self.renderer.set_sky_faces(None if sky is None else sky.faces)
        self._sky_sh = ambient_sh(self.world, sun, self._clouds)
        self._flat_sky = sky is None
        self._sun = self._cube_sun = sun
        self._cube_clouds = self._pass_clouds = self._clouds

    def _cloud_shape(self) -> CloudShape | None:
        """The world's CloudLayer (the lowest entity's) as the GPU draws it (``cloud_shape``;
        None: none, or no generated sky to draw it in: said once)."""
        layers = self.world.query_one(CloudLayer)
        if not layers:
            self._cloud_said.clear()
            return None
        entity, layer = min(layers, key=lambda pair: pair[0])
        said = set()
        if len(layers) > 1:
            said.add(f"{len(layers)} entities have a CloudLayer: the world has one sheet of clouds, entity "
                     f"{entity}'s; the others are left out")
        skies = self.world.query_one(Skybox)
        if not skies or not is_generated(skies[0][1]):
            said.add(f"the CloudLayer of entity {entity} draws nothing: "
                     + ("the world has no Skybox" if not skies else "its Skybox is given faces (a photographed "
                        "sky has its own clouds); clouds are drawn over a generated sky (gradient or atmosphere)"))
        for message in said - self._cloud_said:
            warnings.warn(message, ComponentWarning, stacklevel=4)
        self._cloud_said = said
        if not skies or not is_generated(skies[0][1]):
            return None
        return cloud_shape(layer)

    def _air_tint(self, sun: DirectionalLight) -> tuple[float, float, float]:
        """What the world's atmosphere does to ``sun``'s light (the brightest DirectionalLight,
        or a moon: ``engine.render.sky.sunlight_tint``)."""
        skies = self.world.query_one(Skybox)
        return sunlight_tint(skies[0][1] if skies else None, tuple(sun.direction))

    def _sky_sun(self) -> SkySun | None:
        """Where the world's generated sky puts its sun now, and its tint (``sky_sun``; None:
        no Skybox)."""
        skies = self.world.query_one(Skybox)
        return sky_sun(self.world, skies[0][1]) if skies else None

    def _rows(self, kept: KeptLights) -> tuple[list[tuple], list[tuple]]:
        """The Lights block's rows of the kept lights, slot by slot (a freed slot black)."""
        world = self.world
        directional = []
        sun = brightest_directional(world)   # (marked: the camera's contact shadows dim its light)
        for entity in kept.directional:
            if entity is None:
                directional.append(_NO_SUN)
                continue
            light = world.get(entity, DirectionalLight)
            colour = light.color.xyz * light.intensity
            if air_tinted(light, sun):   # (the sun and the moons: an atmosphere's air reddens them)
                colour = colour * glm.vec3(*self._air_tint(light))
            # (marked: 1 the sun, -1 a moon, 0 a fill light: the lights a CloudLayer shades, lights.glsl)
            mark = 1.0 if light is sun else -1.0 if air_tinted(light, sun) else 0.0
            directional.append((light.direction, colour, mark))
        point, contact, cut = [], [], 0
        rect_slots: list[int] = []   # the rectangles lit as rectangles: the first MAX_RECT_LIGHTS by slot
        rect_cut = 0
        scattered: list[tuple[int, float]] = []   # (slot, volumetric) of the lamps the shafts scatter
        volumetric_cut = 0
        for slot, entity in enumerate(kept.point):
            if entity is None:
                point.append(_NO_LAMP)
                continue
            light, t = world.get(entity, PointLight), world.get(entity, Transform)
            if light.volumetric > 0.0 and light.intensity > 0.0:
                if len(scattered) < MAX_VOLUMETRIC_LAMPS:
                    scattered.append((slot, light.volumetric))
                else:
                    volumetric_cut += 1
            channel = 0   # its contact shadows' channel + 1 (0: none), the first MAX_CONTACT_LAMPS by slot
            if light.contact_shadows:
                if len(contact) < MAX_CONTACT_LAMPS:
                    contact.append(tuple(t.world[3].xyz))
                    channel = len(contact)
                else:
                    cut += 1
            layer = self.renderer.spot_cookies.layer(light.cookie)
            rectangle = lamp_rectangle(light, t.world, layer)
            if rectangle != NO_RECTANGLE:
                if len(rect_slots) < MAX_RECT_LIGHTS:
                    rect_slots.append(slot)
                else:
                    rectangle, rect_cut = NO_RECTANGLE, rect_cut + 1   # lit as a point
            point.append((t.world[3].xyz, light.range, light.color.xyz * light.intensity, lamp_cone(light, t.world),
                          lamp_cookie(light, t.world, layer),
                          sphere_radius(light),
                          float(channel), rectangle))
        if cut > self._contact.cut:
            warnings.warn(LightLimitWarning(
                f"{len(contact) + cut} point lights with contact_shadows light the scene: at most {MAX_CONTACT_LAMPS} "
                f"have them at once (the first by the lights' slots: those that matter most to the active camera), "
                f"so {cut} shine without them (RenderStats.contact_lamps_cut)"), stacklevel=3)
        self._contact = ContactLamps(tuple(contact), cut)
        if rect_cut > self._rect_cut:
            warnings.warn(LightLimitWarning(
                f"{len(rect_slots) + rect_cut} rectangle and tube lights light the scene: at most {MAX_RECT_LIGHTS} "
                f"are lit as rectangles at once (the first by the lights' slots: those that matter most to the active "
                f"camera), so {rect_cut} light as points from their centres (RenderStats.rect_lights_cut)"),
                stacklevel=3)
        self._rect_slots, self._rect_cut = tuple(rect_slots), rect_cut
        self._volumetric = VolumetricLamps(tuple(slot for slot, _ in scattered),
                                           tuple(scatter for _, scatter in scattered), volumetric_cut)
        return directional, point

    def _cookies(self, kept: KeptLights) -> bool:
        """The kept spot lights' cookies into the cookie array (``SpotCookies.set``); True
        when its contents changed."""
        lamps = [self.world.get(entity, PointLight) for entity in kept.point if entity is not None]
        names = [f"the PointLight of entity {entity}" for entity in kept.point if entity is not None]
        panels = [is_panel(lamp) for lamp in lamps]
        return self.renderer.spot_cookies.set([lamp.cookie for lamp in lamps], names, panels)

    def _count_cut(self, kept: KeptLights) -> None:
        """Keep how many lights of each kind the block left out, and how many casting point
        lights it gave no shadow cube; warn when one grows."""
        cut = kept.cut
        if cut[0] > self._cut[0] or cut[1] > self._cut[1]:
            directional = cut[0] + sum(entity is not None for entity in kept.directional)
            point = cut[1] + sum(entity is not None for entity in kept.point)
            warnings.warn(LightLimitWarning(
                f"{directional} directional and {point} point lights: at most {MAX_DIRECTIONAL_LIGHTS} directional "
                f"and {MAX_POINT_LIGHTS} point lights light the scene (the point lights that matter most to the "
                f"active camera, the brightest directional ones: engine/rules/light_rules.py), so {cut[0]} "
                f"directional and {cut[1]} point lights light nothing (RenderStats.lights_cut)"), stacklevel=2)
        self._cut = cut
        if kept.shadows_cut > self._shadows_cut:
            cubes = sum(entity is not None for entity in kept.point_shadows)
            warnings.warn(LightLimitWarning(
                f"{cubes + kept.shadows_cut} point lights cast shadows: at most {LIGHT_LIMITS.point_shadows} have "
                f"shadow cubes at once (those that matter most to the active camera among the lit ones: "
                f"engine/rules/light_rules.py), so {kept.shadows_cut} cast none (RenderStats.shadows_cut)"),
                stacklevel=2)
        self._shadows_cut = kept.shadows_cut

    def _probe_boxes(self) -> None:
        """The influence boxes to the irradiance table when a probe came, went, changed or
        moved (a box is where its entity is now, as ``probe_rules.probe_blend`` weighs it)."""
        world = self.world
        probes = world.query(ReflectionProbe, Transform)
        if not world.changed(ReflectionProbe) and not world.deleted() and not any(
                entity in world.frame.moved for entity, _ in probes):
            return
        self.renderer.irradiance.set_boxes(
            (entity, tuple(t.world[3].xyz), tuple(probe.influence), probe.blend_distance)
            for entity, (probe, t) in probes if probe.influence is not None)

