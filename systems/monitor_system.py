"""Stage "monitors": each ``Monitor``'s picture drawn from its camera (``components/monitor.py``,
``engine/render/monitors.py``).

After the probes and the irradiance volume (the pictures' views sample them as any view
does), before the main view (which shows the screens with this frame's pictures).  What is
decided here:

- which monitors are due: a monitor is drawn on the frame it comes and then every
  ``every`` frames; at most ``MAX_MONITORS`` drawn a frame, those that have waited longest
  first (then by entity): the rest keep their pictures a frame more and are drawn first the
  next (counted in ``RenderStats.monitors_cut``, said when the count grows; a picture kept,
  below, is not drawn and not counted);
- whether it can be seen, for a ``Monitor.update`` "when_seen" (``_seen``): its screen
  reached by this frame's main view, its first level of mirror and portal views
  (``_first_level``, conservatively), last frame's deeper ones (``ViewEyes``), the
  probes' faces recaptured after this frame's present (``ProbeSchedule``) or the last
  drawing's views of a monitor itself seen, or shown on a ``ScreenPanel``; unseen,
  it is not drawn and stays due (``RenderStats.monitors_unseen``);
- each one's view: its camera entity's ``Camera`` (field of view or orthographic height,
  near, far, layers) from its ``Transform``, at the picture's size and aspect; a camera that
  is missing (no entity, no ``Camera`` or no ``Transform`` on it) is said once, and the
  picture kept as it is (black at first); the camera's own ``Fog`` (``_camera_fog``), and
  its ``AmbientOcclusion`` and ``ContactShadows``, found for the picture before its root is
  drawn (``_occlusion``: ``ScreenOcclusion.draw_picture``), its ``ScreenReflections``
  (``ScreenReflectionPass.begin_picture``) and its ``VolumetricFog`` (``_shafts``:
  ``VolumetricFogPass.begin_picture``);
- whether its mirrors and portals get views: to ``Monitor.depth`` levels, planned with the
  frame's surfaces as a probe face's tree is, outside the frame's ``ViewBudget``
  (``outside_the_budget``: the monitors' own limits bound them, and drawn before the main
  view they would take the budget the frame's reflections share first).

A due monitor whose picture would come out as it is is kept, not drawn (dirty flags, as a
still camera's mirror views are kept: ``keep_still_pictures``; ``RenderStats.monitors_kept``
counts them).  "As it is" is one comparison with its last drawing (``_still_key``): the
scene's version less the pictures' (``MonitorPictures.scene_version``: every upload or
redraw of what a view shows but a picture), what every view's drawing depends on
(``Renderer.drawing_settings``), its camera's view, size, layers and depth, the waters' waves,
the surfaces' table and blends as the same objects, and no component of the world written,
added or removed since; besides, its drawing read nothing from the frame before
(``MonitorPictures.repeatable``: no end view, no level drawn on the last drawing's counts),
and each picture it showed (a screen its views may have drawn) is the one it showed.  A
picture still but drawn on predicted counts (a GPU's "auto") is drawn once more with exact
ones (the CPU waits for the GPU once a level, that once), and kept from then on.  So a
camera that sees its own screen draws every time it is due (its picture moved on, a picture
in a picture a level deeper each time), and one that sees another's draws again after the
other's changes; a flat one-sided screen a view sees from behind shows it nothing
(``_screen_faces``).  Kept, a picture moves no version on: a still camera's mirrors that show
it keep their views too.

The reflection probes' captures are followed probe by probe: a picture is drawn again after
a capture only of a probe its last drawing may have sampled (``MonitorPictures.probes_read``:
a probe of a batch its views reach, or one with an influence box), else it is kept.  Were
every capture an input (``ProbeCaptures.moved_on``), an ``every_frame`` probe that sees the
screen would draw the picture again after each capture, and the face that shows it would see
a new picture each frame: a face and a picture drawn every frame of a still scene.  Where the
camera does see that probe's reflection (a chrome ball before the screen), the picture shows
it, the probe shows the picture: an ``every_frame`` probe and the picture draw each other
every frame, each showing the other's last, as a camera that sees its own screen does.

A picture drawn is published (``PicturesDrawn``) for the probes' scheduler, whose
``on_change`` probes recapture the faces that see its screen (and ``once`` and ``scripted``
probes those that showed it black, before its first drawing); not one drawn again for
nothing but captures since of probes it samples: a probe that recaptured the screen would
draw it again, and that drawing recapture the probe, forever in a still scene.  So an
``on_change`` probe shows a screen whose picture shows that probe's own reflection as it was
a capture before.

The pictures of monitors gone (or deleted) are let go here; the extract stage makes a
screen's picture when it first draws the screen (its emissive map is the picture)."""
from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import fields

import esper
import numpy as np
from pyglm import glm

from components import (
    AmbientOcclusion,
    Bloom,
    Camera,
    ChromaticAberration,
    ColorGrading,
    ComponentWarning,
    ContactShadows,
    DepthOfField,
    FilmGrain,
    Fog,
    LensFlare,
    Material,
    MeshRef,
    Monitor,
    Morph,
    MotionBlur,
    ScreenPanel,
    ScreenReflections,
    Skin,
    Tonemap,
    Transform,
    Vignette,
    VolumetricFog,
)
from engine.core.errors import MonitorLimitWarning
from engine.core.frame_io import Output
from engine.core.world import World
from engine.frame_stats import BudgetLedger
from engine.render.monitors import MAX_MONITORS, PictureShafts
from engine.render.renderer import Renderer
from engine.render.sky import air_light
from engine.render.surface_table import NO_BLENDS, SurfaceBlends, surface_table
from engine.render.view_plan import SurfaceTable
from engine.render.views import View, camera_view
from engine.resources import ContactLamps, PicturesDrawn, Surfaces, SurfaceState
from engine.rules.frame_rules import active_camera_parts
from engine.rules.light_rules import PictureEyes, ViewEyes, brightest_directional
from engine.rules.probe_rules import pose_bounds
from engine.rules.probe_schedule import ProbeSchedule, ProbeStates
from engine.rules.screen_rects import projected_rects, view_matrix
from engine.rules.shadow_rules import ShadowCasters
from systems.camera_shafts import camera_shafts
from systems.shadow_rings import PictureRings

# A camera's components that shape the frame after its views are drawn (the tone curve and
# exposure, the grade, the lens's effects): a monitor's picture has none of its own (the
# frame's apply to it as to any light; a picture panel is graded as the frame under it).
PICTURE_SKIPS = (Tonemap, ColorGrading, Bloom, LensFlare, Vignette, ChromaticAberration, FilmGrain, DepthOfField,
                 MotionBlur)


class MonitorSystem(esper.Processor):
    """Draws the due monitors' pictures, from their cameras."""

    def __init__(self, world: World, renderer: Renderer) -> None:
        super().__init__()
        self.world = world
        self.renderer = renderer
        self.drawn: dict[int, int] = {}         # monitor -> the frame its picture was last drawn (or kept)
        self._said: set[tuple[int, int | None]] = set()  # (monitor, the camera it named) said once
        self._said_post: set[tuple[int, int, tuple[str, ...]]] = set()  # (monitor, camera, kinds): _say_post
        self._said_no_light: ContactShadows | None = None  # a camera's contact shadows that darken nothing, said
        self._said_no_shafts: tuple | None = None  # (a camera's VolumetricFog, why it adds nothing), said
        self._cut = 0
        self._keep_still_pictures = True
        self._rings = PictureRings()   # each monitor's camera's suns' cascades about it (_cascades)
        self._eyes_from: tuple | None = None   # what the PictureEyes published were made from
        self._keys: dict[int, tuple[tuple, tuple]] = {}   # monitor -> _still_key at its last drawing
        self._world_version = 0   # moved on by every change to the world's components (World.change_count)
        self._changes_seen = 0    # World.change_count when this stage last looked
        self._flat: dict[int, tuple | bool] = {}   # mesh id -> its one face (point, normal), or False
        self._surfaces_of: Surfaces | None = None   # what _surface_arrays' rows were made from
        self._surface_rows: tuple[list[SurfaceState], np.ndarray, np.ndarray] = ([], np.zeros((0, 8, 4)),
                                                                                  np.zeros((0, 4)))

    @property
    def keep_still_pictures(self) -> bool:
        """Keep a due monitor's picture when nothing it shows changed since it was drawn (the
        module docstring); False: draw every due picture (what the tests compare with)."""
        return self._keep_still_pictures

    @keep_still_pictures.setter
    def keep_still_pictures(self, value: bool) -> None:
        if not isinstance(value, bool):
            raise TypeError(f"MonitorSystem.keep_still_pictures must be True or False, got {value!r}")
        self._keep_still_pictures = value

    def process(self, dt: float) -> None:
        world = self.world
        pictures = self.renderer.monitors
        stats = self.renderer.stats
        monitors = sorted(world.query_one(Monitor), key=lambda pair: pair[0])
        if not monitors and not self.drawn and not pictures.entities:
            self._cut = 0   # (no monitor, none kept: nothing to look at; a new one is drawn first and keyed then)
            return
        present = {entity for entity, _ in monitors}
        for gone in pictures.entities - present:
            pictures.drop(gone)
            self.renderer.occlusion.drop_picture(gone)   # (its camera's occlusion images: the pass's own)
        for gone in set(self.drawn) - present:
            del self.drawn[gone]
        self._rings.keep({monitor.camera for _, monitor in monitors})
        for gone in set(self._keys) - present:
            del self._keys[gone]
        # Changes since the last look: after this stage in the last frame, and before it in this one.
        changes = world.change_count()
        self._world_version += world.last_step_changes - self._changes_seen + changes
        self._changes_seen = changes
        self._said = {(entity, camera) for entity, camera in self._said if entity in present}
        self._said_post = {said for said in self._said_post if said[0] in present}
        frame = world.frame_index
        # The longest waiting first (a new one first of all), then by entity: past MAX_MONITORS
        # drawn, those left wait a frame and are drawn first the next (a kept one costs none).
        due = sorted(((entity, monitor) for entity, monitor in monitors
                      if entity not in self.drawn or frame - self.drawn[entity] >= monitor.every),
                     key=lambda pair: (self.drawn.get(pair[0], -1), pair[0]))
        surfaces: Surfaces | None = world.resources.get(Surfaces)
        table = surface_table(world.resources, surfaces) if due and surfaces is not None and \
            (surfaces.mirrors or surfaces.portals) else None
        blends = world.resources.get(SurfaceBlends, NO_BLENDS)
        drawn = cut = 0
        screens: set[int] = set()   # the monitors whose pictures are drawn now
        first: set[int] = set()     # ... of those, the ones drawn for the first time
        faces = None   # (the screens' planes, found when a picture is first drawn this frame)
        seen = None    # (the screens some view sees, found when a "when_seen" one is first due)
        for entity, monitor in due:
            parts = self._camera(entity, monitor)
            if parts is None:   # (its picture kept as it is; its camera's screen effects' images let go)
                pictures.drop_effects(entity)
                self.renderer.occlusion.drop_picture(entity)
                continue
            if monitor.update == "when_seen":
                if faces is None:
                    faces = self._screen_faces(monitors)
                if seen is None:
                    seen = self._seen(faces)
                if entity not in seen:   # (it stays due: drawn the first frame a view sees it)
                    stats.monitors_unseen += 1
                    continue
            camera, transform = parts
            pictures.picture(entity, monitor.size)   # (made here too for a monitor with no screen yet)
            view = camera_view(transform.world, camera.fov_y, camera.near, camera.far, monitor.size,
                               name=f"monitor {entity}",
                               ortho_height=camera.ortho_height if camera.projection == "orthographic" else None)
            view.layers = camera.layer_mask
            key = self._still_key(monitor, view, table, blends)
            kept = self._keys.get(entity)
            # As it was but for the captures since of the reflection probes its last drawing may
            # have sampled (``alike``): drawn again, it is not published as a new look of its
            # screen (the probes that see the screen would recapture it, moving the version on
            # that drew it: a loop in a still scene).  A capture of a probe it could not sample
            # leaves it still (``MonitorPictures.probes_read``).
            alike = kept is not None and _same(key, kept) and pictures.shown_unchanged(entity)
            still = self.keep_still_pictures and alike and pictures.probes_unchanged(entity, self.renderer.probes)
            if still and pictures.repeatable(entity):
                stats.monitors_kept += 1
                self.drawn[entity] = frame
                continue
            if drawn == MAX_MONITORS:
                cut += 1
                continue
            trees = monitor.depth > 0 and table is not None
            if faces is None:
                faces = self._screen_faces(monitors)
            with outside_the_budget(stats), self._camera_fog(monitor.camera), \
                    self._cascades(monitor.camera, transform.world[3]):
                occluded = self._occlusion(entity, monitor.camera, view)
                try:
                    reflections = self.world.try_get(monitor.camera, ScreenReflections) \
                        if self.renderer.screen_reflections.shown and monitor.camera is not None \
                        and self.world.exists(monitor.camera) else None
                    shafts = self._shafts(entity, monitor.camera)
                    # (still, but drawn on predicted counts: once more exactly, to keep)
                    views = pictures.draw(entity, view, table if trees else None, monitor.depth, blends,
                                          exact=still, faces=faces, occluded=occluded, reflections=reflections,
                                          shafts=shafts, captures=self.renderer.probes)
                finally:   # (the active camera's images back, whatever the picture's draw raised)
                    if occluded:
                        self.renderer.occlusion.end_picture()
            stats.monitor_views += views
            drawn += 1
            if not alike:
                screens.add(entity)
            if kept is None:
                first.add(entity)
            self.drawn[entity] = frame
            self._keys[entity] = key
        # (a still frame: what they were made from is as it was, the same snapshot again)
        output, views = world.resources.get(Output), world.resources.get(ViewEyes)
        if views is not None and not any(node.level > 0 for node in views.views):
            views = None   # (no mirror or portal view: nothing of it weighs a screen)
        eyes_from = (self._world_version, views, None if output is None else output.size, frozenset(pictures.entities))
        if self._eyes_from is None or not _same_eyes_from(eyes_from, self._eyes_from):
            world.resources[PictureEyes] = self._picture_eyes(monitors)
            self._eyes_from = eyes_from
        if screens:
            published = world.resources.get(PicturesDrawn, PicturesDrawn())
            world.resources[PicturesDrawn] = PicturesDrawn(published.count + 1, frozenset(screens),
                                                          frozenset(first))
        if cut > self._cut:
            warnings.warn(MonitorLimitWarning(
                f"{drawn + cut} monitors were to be drawn this frame: {MAX_MONITORS} are drawn a frame (those "
                f"waiting longest), so {cut} keep their pictures a frame more (RenderStats.monitors_cut)"),
                stacklevel=2)
        self._cut = stats.monitors_cut = cut

    def _seen(self, faces: dict[int, tuple[glm.vec3, glm.vec3]]) -> set[int]:
        """The monitors whose screens a view may see: this frame's main view (the active
        camera's, at the output's aspect) and its first level of mirror and portal views
        (``_first_level``), last frame's mirror and portal views (``ViewEyes``) or the
        probes' faces recaptured after this frame's present (the schedule's undrawn faces: a
        chrome ball's reflection of the screen) or captured first this frame (their faces are
        asked for again once the picture is: ``PicturesDrawn``) may see them, or they are on a
        ``ScreenPanel``; then, over and over, those the last drawings of the pictures seen may
        see."""
        world = self.world
        views = []
        main = self._main_view()
        if main is not None:
            views.append(main)
            views += self._first_level(main)
        eyes = world.resources.get(ViewEyes)
        if eyes is not None:
            views += [node.view for node in eyes.views if node.level > 0]
        schedule, probes = world.resources.get(ProbeSchedule), world.resources.get(ProbeStates)
        if schedule is not None and probes:
            # (A first capture was drawn in the probes stage, before this one: seen there, the
            # picture drawn now is published, and the scheduler asks for the faces again.)
            for due in [due for due in schedule.due.values() if due.first or not due.drawn]:
                state = probes.get(due.owner)
                if state is not None and due.faces:
                    views += self.renderer.probes.face_views(due.owner, due.faces, state.position,
                                                             state.settings).values()
        pictures = self.renderer.monitors
        seen = pictures.screens_reaching(views, faces) | {entity for entity, _ in world.query(Monitor, ScreenPanel)}
        # ... and what the pictures seen show, and so on: a screen seen only by its own camera,
        # or by monitors nobody sees, is not seen.
        found = seen
        while found:
            found = pictures.screens_reaching(pictures.last_views(found), faces) - seen
            seen = seen | found
        return seen

    def _main_view(self) -> View | None:
        """This frame's main view: the active camera's, at the output's aspect (None: no
        camera or no output)."""
        output, camera = self.world.resources.get(Output), active_camera_parts(self.world)
        if output is None or camera is None or output.size[0] <= 0 or output.size[1] <= 0:
            return None
        _, cam, cam_t = camera
        return camera_view(cam_t.world, cam.fov_y, cam.near, cam.far, output.size,
                           ortho_height=cam.ortho_height if cam.projection == "orthographic" else None)

    def _picture_eyes(self, monitors: list[tuple[int, Monitor]]) -> PictureEyes:
        """What the next frame's lights and levels of detail need to weigh each picture's
        camera as a mirror's view's eye (``light_rules.PictureEyes``, worked out only if asked):
        its eye, its screen's box as placed (and posed, by its Skin and Morph), its
        ``ScreenPanel``'s share of the frame, this frame's main view and last frame's mirror
        and portal views."""
        world = self.world
        pictures = self.renderer.monitors.entities
        output = world.resources.get(Output)
        if output is None or output.size[0] * output.size[1] <= 0:
            return PictureEyes()
        screens = []
        for entity, monitor in monitors:
            lens = world.try_get(monitor.camera, Transform) \
                if entity in pictures and monitor.camera is not None and world.exists(monitor.camera) else None
            if lens is None:
                continue
            panel = world.try_get(entity, ScreenPanel)
            mesh, placed = world.try_get(entity, MeshRef), world.try_get(entity, Transform)
            eye = lens.world[3]
            screens.append(((float(eye.x), float(eye.y), float(eye.z)),
                            None if mesh is None or placed is None else
                            (mesh.mesh, glm.mat4(placed.world), pose_bounds(world, entity, mesh.mesh)),
                            0.0 if panel is None else float(panel.size.x * panel.size.y)))
        if not screens:
            return PictureEyes()
        main = self._main_view()
        return PictureEyes(tuple(screens), tuple(output.size), None if main is None else view_matrix(main),
                           world.resources.get(ViewEyes))

    def _first_level(self, main: View) -> list[View]:
        """This frame's first level of mirror and portal views below ``main`` (the active
        camera's), as the reflect stage will plan them, conservatively: for each mirror or
        portal (a water's top or underside) whose front the eye is before and whose corners
        fall on the screen, the camera carried through it (``SurfaceState.carry``), looking
        out of its exit plane, over the screen's rectangle the corners cover (all of it where
        one lies behind the eye).  A screen first seen in a mirror is so drawn that frame;
        deeper levels are last frame's (``ViewEyes``)."""
        surfaces = self.world.resources.get(Surfaces)
        if surfaces is None:
            return []
        states, corners, planes = self._surface_arrays(surfaces)
        if not states:
            return []
        width, height = main.size
        eye = main.eye
        # (off, or its back to the eye: not seen)
        facing = planes[:, :3] @ (eye.x, eye.y, eye.z) + planes[:, 3] > 0.0
        low, high, behind, off = projected_rects(corners[facing], view_matrix(main), np.array(main.size))
        views = []
        for at, row in enumerate(np.flatnonzero(facing).tolist()):
            if behind[at]:
                rect = (0, 0, width, height)     # (a corner behind the eye: all of the screen)
            elif off[at]:
                continue   # (off the screen)
            else:
                rect = (int(low[at, 0]), int(low[at, 1]), int(high[at, 0] - low[at, 0]),
                        int(high[at, 1] - low[at, 1]))
            state = states[row]
            carry = state.carry
            views.append(View(view=main.view * glm.inverse(carry), proj=main.proj,
                              eye=glm.vec3(carry * glm.vec4(eye, 1.0)), size=main.size,
                              name=f"{state.kind} {state.entity} (seen first)", clip_plane=state.exit_plane,
                              mirrored=state.kind == "mirror", scissor=rect, layers=state.layers))
        return views

    def _surface_arrays(self, surfaces: Surfaces) -> tuple[list[SurfaceState], np.ndarray, np.ndarray]:
        """The enabled mirrors, portals and waters' undersides of ``surfaces`` with their
        corners (S, 8, 4: a portal's four twice over) and planes (S, 4), for ``_first_level``;
        kept while the surfaces stage publishes no new ``Surfaces`` (none changed)."""
        if self._surfaces_of is not surfaces:
            states = [state for state in (*surfaces.mirrors.values(), *surfaces.portals.values(),
                                          *surfaces.undersides.values()) if state.enabled]
            corners = np.array([np.asarray(state.corners, np.float64)[np.arange(8) % len(state.corners)]
                                for state in states], np.float64).reshape(len(states), 8, 4)
            planes = np.array([tuple(state.plane) for state in states], np.float64).reshape(len(states), 4)
            self._surfaces_of, self._surface_rows = surfaces, (states, corners, planes)
        return self._surface_rows

    def _screen_faces(self, monitors: list[tuple[int, Monitor]]) -> dict[int, tuple[glm.vec3, glm.vec3]]:
        """Each screen that shows its picture on one side only, as (a point, its front's unit
        normal) in the world: a flat mesh (every triangle wound to face one way) that is not
        double-sided, skinned or morphed.  A view whose eye is behind that plane cannot draw
        the picture (its faces are culled), so the picture is not an input of the view's."""
        world = self.world
        faces = {}
        flat, self._flat = self._flat, {}   # (kept for the screens there now only: a gone screen's mesh let go)
        for entity, _ in monitors:
            mesh_ref, transform = world.try_get(entity, MeshRef), world.try_get(entity, Transform)
            material = world.try_get(entity, Material)
            if mesh_ref is None or transform is None or (material is not None and material.double_sided) \
                    or world.try_get(entity, Skin) is not None or world.try_get(entity, Morph) is not None:
                continue
            local = flat.get(mesh_ref.mesh.id)
            if local is None:
                local = flat_face(mesh_ref.mesh.positions, mesh_ref.mesh.indices)
            self._flat[mesh_ref.mesh.id] = local
            if local is False:
                continue
            matrix = transform.world
            # The front is where the local normal goes under the inverse transpose: a mirroring
            # matrix turns the winding, and its batch's front face is turned with it.
            normal = glm.transpose(glm.inverse(glm.mat3(matrix))) * glm.vec3(*local[1])
            if glm.length(normal) > 0.0:
                faces[entity] = (glm.vec3(matrix * glm.vec4(*local[0], 1.0)), glm.normalize(normal))
        return faces

    def _still_key(self, monitor: Monitor, view: View, table: SurfaceTable | None,
                   blends: SurfaceBlends) -> tuple[tuple, tuple]:
        """What a monitor's picture shows, as (values compared equal, objects compared as the
        same object): the module docstring's list, less the pictures' and the reflection
        probes' captures (``MonitorPictures.probes_unchanged`` follows those it may sample)."""
        flows = () if table is None else tuple(state.water.flow.offset for state in table.states
                                               if state.water is not None)
        captures = self.renderer.probes.moved_on   # (every probe's: those it samples are followed apart)
        values = (self.renderer.monitors.scene_version - captures, self.renderer.drawing_settings(),
                  view.camera_block(), view.layers, monitor.size, monitor.depth, flows, self._world_version,
                  self.renderer.occlusion.shown, self.renderer.screen_reflections.shown)
        return values, (table, blends.by_surface)

    @contextmanager
    def _cascades(self, camera: int, eye: glm.vec4) -> Iterator[None]:
        """While a picture from ``camera`` (at ``eye``) is drawn, the suns' cascades about the
        camera are read in place of the active camera's (``systems/shadow_rings.py``): put
        back after, whatever the draw raised."""
        casters = self.world.resources.get(ShadowCasters)
        cascades = None if casters is None else casters.cascades
        rows = {} if cascades is None else self._rings.rows(
            camera, (float(eye.x), float(eye.y), float(eye.z)), cascades, self.renderer.shadows, self.renderer.stats)
        aside = self.renderer.shadows.swap_ring_rows(rows) if rows else None
        try:
            yield
        finally:
            if aside is not None:
                self.renderer.shadows.swap_ring_rows(aside)

    def _camera_fog(self, camera: int | None) -> AbstractContextManager[None]:
        """The fog a picture from ``camera`` is drawn through: the camera's own ``Fog`` where it
        has one (the frame's given back after), else the frame's, the active camera's (none
        while the frame draws none: the overlay's toggle, ``FogBlock.shown``)."""
        fog = self.renderer.fog
        own = self.world.try_get(camera, Fog) if camera is not None and fog.shown and self.world.exists(camera) \
            else None
        if own is None:
            return nullcontext()
        glow = air_light(self.world) if own.sun_scatter > 0.0 else None
        return fog.camera_fog(own, None if glow is None else glow.light, (1.0, 1.0, 1.0) if glow is None else glow.tint)

    def _occlusion(self, monitor: int, camera: int | None, view: View) -> bool:
        """Find the ambient occlusion and contact shadows of ``monitor``'s picture, where its
        ``camera`` has them (``ScreenOcclusion.draw_picture``; none while the overlay's toggle
        is off, ``ScreenOcclusion.shown``); returns whether its draw reads them."""
        world, occlusion = self.world, self.renderer.occlusion
        own = occlusion.shown and camera is not None and world.exists(camera)
        settings = world.try_get(camera, AmbientOcclusion) if own else None
        contact = world.try_get(camera, ContactShadows) if own else None
        if settings is None and contact is None:
            occlusion.drop_picture(monitor)
            return False
        sun = brightest_directional(world) if contact is not None else None
        lamps = world.resources.get(ContactLamps, ContactLamps()).positions if contact is not None else ()
        if contact is not None and sun is None and not lamps and self._said_no_light is not contact:
            self._said_no_light = contact   # (once for each component: the active camera's is said by the main view)
            warnings.warn(ComponentWarning(
                f"ContactShadows on entity {camera}, the camera of monitor {monitor}: the world has no "
                "DirectionalLight that shines (a sun) and no PointLight with contact_shadows, and contact shadows "
                "darken only those lights, so they darken nothing in its picture"), stacklevel=3)
        return occlusion.draw_picture(monitor, view, settings, contact, None if sun is None else -sun.direction, lamps)

    def _shafts(self, monitor: int, camera: int | None) -> PictureShafts | None:
        """The light shafts of ``monitor``'s picture: its ``camera``'s ``VolumetricFog``, through
        the fog its picture is drawn through (the camera's own ``Fog``, else the active
        camera's; ``camera_shafts``); None where it has none, or it adds nothing (said
        once for each component and reason, as the active camera's is)."""
        world = self.world
        if camera is None or not world.exists(camera) or not world.has(camera, VolumetricFog):
            return None
        fog = world.try_get(camera, Fog)
        if fog is None:
            active = active_camera_parts(world)
            fog = world.try_get(active[0], Fog) if active is not None else None
        found, why = camera_shafts(world, self.renderer, camera, fog)
        if why is not None:
            said = (world.get(camera, VolumetricFog), why)
            if self._said_no_shafts != said:
                self._said_no_shafts = said
                warnings.warn(ComponentWarning(
                    f"VolumetricFog on entity {camera}, the camera of monitor {monitor}, {why}, so it adds nothing "
                    "to its picture"), stacklevel=3)
        if found is None:
            return None
        return found.settings, found.lamps, found.sky_light, found.image_shares

    def _say_post(self, entity: int, camera: int) -> None:
        """Say once, for each monitor, camera and set of them, the components of
        ``PICTURE_SKIPS`` on the camera ``entity``'s monitor shows, while it is not the active
        camera: they do nothing in the picture (made the active camera, it uses them)."""
        kinds = _post_kinds(self.world, camera)
        if not kinds or (entity, camera, kinds) in self._said_post:
            return
        active = active_camera_parts(self.world)
        if active is not None and active[0] == camera:
            return
        self._said_post.add((entity, camera, kinds))
        warnings.warn(ComponentWarning(
            f"{', '.join(kinds)} on entity {camera}, the camera of the Monitor on entity {entity}: a monitor's "
            f"picture has no {'tone curve, grade or lens effects' if len(kinds) > 1 else 'such effect'} of its "
            f"own (the frame's apply to it as to any light), so {'they do' if len(kinds) > 1 else 'it does'} "
            "nothing there (it works while that camera is the active one)"), stacklevel=3)

    def _camera(self, entity: int, monitor: Monitor) -> tuple[Camera, Transform] | None:
        """The Camera and Transform of the entity ``monitor`` shows, or None, said once for each
        entity it names that is not a camera."""
        world = self.world
        camera = monitor.camera
        if camera is None or not world.exists(camera):
            why = "names no camera (Monitor.camera is None)" if camera is None else \
                f"names entity {camera}, which does not exist"
        elif world.try_get(camera, Camera) is None or world.try_get(camera, Transform) is None:
            lacking = "Camera" if world.try_get(camera, Camera) is None else "Transform"
            why = f"names entity {camera}, which has no {lacking}"
        else:
            self._say_post(entity, camera)
            return world.get(camera, Camera), world.get(camera, Transform)
        if (entity, camera) not in self._said:   # (said once for each camera it names)
            self._said.add((entity, camera))
            warnings.warn(ComponentWarning(f"Monitor on entity {entity} {why}: its picture is not drawn (it keeps "
                                           "what it showed, black at first)"), stacklevel=3)
        return None


def _post_kinds(world: World, camera: int) -> tuple[str, ...]:
    """The components on ``camera``'s entity that shape the frame after its views are drawn
    (``PICTURE_SKIPS``), by name."""
    return tuple(kind.__name__ for kind in PICTURE_SKIPS if world.try_get(camera, kind) is not None)


def _same_eyes_from(key: tuple, other: tuple) -> bool:
    """Two ``PictureEyes`` sources agree: the world's version, the output's size and the
    pictures held equal, last frame's mirror and portal views the same object."""
    return key[0] == other[0] and key[1] is other[1] and key[2] == other[2] and key[3] == other[3]


def _same(key: tuple[tuple, tuple], other: tuple[tuple, tuple]) -> bool:
    """Two ``_still_key``s agree: values equal, objects the same."""
    return key[0] == other[0] and all(a is b for a, b in zip(key[1], other[1], strict=True))


@contextmanager
def outside_the_budget(ledger: BudgetLedger) -> Iterator[None]:
    """Within the block the view trees drawn see no ``ViewBudget`` (no view, pixel or
    smallest-view limit) and what they spend is not kept: a monitor's picture has limits of
    its own (its size and depth, ``every``, ``MAX_MONITORS``), and drawn before the main
    view it would otherwise take the budget the frame's reflections share first."""
    kept = {field.name: getattr(ledger, field.name) for field in fields(BudgetLedger)}
    ledger.view_budget = ledger.pixel_budget = ledger.min_view_pixels = None
    try:
        yield
    finally:
        for name, value in kept.items():
            setattr(ledger, name, value)


def flat_face(positions: np.ndarray, indices: np.ndarray) -> tuple[tuple, tuple] | bool:
    """(A point, the unit normal its triangles' winding faces) of a mesh whose triangles all
    lie in one plane and face one way (a quad, a disc), else False."""
    corners = positions[indices]                         # [triangle, corner, xyz]
    crossed = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    lengths = np.linalg.norm(crossed, axis=1)
    if not len(lengths) or lengths.max() <= 0.0:
        return False
    normal = crossed[lengths.argmax()] / lengths.max()
    size = max(float(np.abs(positions).max()), 1e-6)
    facing = crossed @ normal   # (each triangle's doubled area along the normal: >= 0 for the one way)
    off_plane = np.abs((positions - positions[0]) @ normal)
    if facing.min() < -1e-9 * size * size or off_plane.max() > 1e-6 * size:
        return False
    return tuple(map(float, positions[0])), tuple(map(float, normal))
