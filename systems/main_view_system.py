"""Main: the active camera's view, drawn by the scene pass into the main view tree's level 0
(all but its transparent slot, which the reflect stage's tree draws over the reflections),
after its ambient occlusion and contact shadows where the camera has an ``AmbientOcclusion``
or ``ContactShadows`` (``engine/render/screen_occlusion.py``; the contact shadows towards the
brightest directional light), and with what its screen-space reflections need where
it has ``ScreenReflections`` (``engine/render/screen_reflections.py``: the reflect stage's
tree composites them before the view's glass).

It publishes the view and the targets it drew into as ``world.resources[FrameViews]``
(``main`` None when there is no active camera or the output has no pixels, a minimised
window): the reflect stage roots its view tree there and the present stage presents it.
"""
from __future__ import annotations

import operator
import warnings
from collections.abc import Callable
from dataclasses import replace

import esper

from components.ambient import AmbientOcclusion, ContactShadows
from components.fog import Fog, VolumetricFog
from components.limits import MAX_VOLUMETRIC_LAMPS
from components.screen_reflections import ScreenReflections
from components.tracking import ComponentWarning
from engine.core.errors import LightLimitWarning, NoCameraWarning
from engine.core.frame_io import Output
from engine.core.world import World
from engine.render.frame_views import FrameViews
from engine.render.renderer import Renderer
from engine.render.resample import render_size
from engine.render.scene_options import TREE_ROOT, SceneOptions
from engine.render.scene_programs import reflects_environment
from engine.render.targets import RenderTargets
from engine.render.temporal_aa import jittered
from engine.render.unlit_mirrors import shading_replaced
from engine.render.views import View, camera_view
from engine.resources import ContactLamps, Surfaces, ViewBudget
from engine.rules.frame_rules import active_camera_parts
from engine.rules.light_rules import brightest_directional
from systems.camera_shafts import camera_shafts

_NO_LAMPS = ContactLamps()


class MainViewSystem(esper.Processor):
    def __init__(self, world: World, renderer: Renderer) -> None:
        self.world = world
        self.renderer = renderer
        world.resources[FrameViews] = FrameViews()
        self._said_no_camera = False
        # The depth cap of the view tree the reflect stage roots here (the Engine sets it):
        # with it, mirrors the tree paints over entirely are drawn unlit
        # (unlit_mirrors.shading_replaced, whatever the cap: a view it cuts shows its end view
        # or fallback at weight 1 too); None: every mirror is shaded.
        self.depth_cap: Callable[[], int] | None = None
        self._options: tuple[tuple, SceneOptions] = (((), ()), TREE_ROOT)  # (what it was made from, the options)
        self.occluded: AmbientOcclusion | None = None  # the one drawn this frame (the overlay's line)
        self.contact_shadowed: ContactShadows | None = None  # the contact shadows drawn this frame (the same)
        self.contact_lamps = 0  # ... and the lamps they darken besides the sun
        # (the root's options, occlusion, reflections, the options drawn with): the last made
        self._screen_options: tuple[SceneOptions | None, bool, bool, SceneOptions] = (None, False, False, TREE_ROOT)
        self.reflected: ScreenReflections | None = None  # the one drawn this frame (the overlay's line)
        self._said_nothing_reflects: ScreenReflections | None = None  # the one warned about (once)
        self._said_no_sun: ContactShadows | None = None  # the contact shadows warned about having no sun (once)
        self._looked_at: list | None = None  # the batch list last looked through for a reflecting one
        self.shafts: VolumetricFog | None = None  # the light shafts drawn this frame
        self._said_no_shafts: tuple[VolumetricFog, str] | None = None  # (the one warned about, why: once)
        self._said_lamps_cut = 0  # the lamps past MAX_VOLUMETRIC_LAMPS last said

    @property
    def occlusion(self) -> bool:
        """The debug overlay's toggle: off, no camera's ``AmbientOcclusion`` or ``ContactShadows``
        is drawn, the active camera's or a monitor's (``ScreenOcclusion.shown``)."""
        return self.renderer.occlusion.shown

    @occlusion.setter
    def occlusion(self, value: bool) -> None:
        if not isinstance(value, bool):
            raise TypeError(f"MainViewSystem.occlusion must be True or False, got {value!r}")
        self.renderer.occlusion.shown = value

    @property
    def reflections(self) -> bool:
        """The debug overlay's toggle: off, no camera's ``ScreenReflections`` is drawn, the active
        camera's or a monitor's (``ScreenReflectionPass.shown``)."""
        return self.renderer.screen_reflections.shown

    @reflections.setter
    def reflections(self, value: bool) -> None:
        if not isinstance(value, bool):
            raise TypeError(f"MainViewSystem.reflections must be True or False, got {value!r}")
        self.renderer.screen_reflections.shown = value

    def process(self, dt: float) -> None:
        world = self.world
        views = world.resources[FrameViews] = FrameViews()
        self.occluded = self.reflected = self.shafts = None
        self.renderer.scene_pass.particle_draw.reactive = None   # (set again below while TAA is on)
        output: Output | None = world.resources.get(Output)
        camera = active_camera_parts(world)
        if camera is None and output is not None and not self._said_no_camera:
            # A black frame with no word is the worst answer to a forgotten camera.
            warnings.warn(NoCameraWarning(
                f"frame {world.frame_index + 1}: the world has no active camera (a Camera with a Transform and "
                "active=True; engine.spawn_camera makes one): frames show nothing until there is one"), stacklevel=2)
        self._said_no_camera = camera is None
        if output is None or camera is None or output.size[0] <= 0 or output.size[1] <= 0:
            if camera is None:  # its camera went: its images go too
                if self.renderer.screen_occlusion is not None:
                    self.renderer.occlusion.release_targets()
                self.renderer.screen_reflections.release_targets()
                self.renderer.volumetric_fog.release_targets()
            return  # minimised window or nothing to look through
        _, cam, cam_t = camera
        levels = self.renderer.levels  # the main view tree's targets (the renderer owns them)
        # The output's size, or fewer pixels: the render scale, or dynamic resolution's under
        # a ViewBudget's frame_ms (the GPU's frame time, measured).
        scale = self.renderer.main_scale(ViewBudget.of(world.resources))
        stats = self.renderer.stats
        stats.render_scale, stats.gpu_frame_ms = scale, self.renderer.frame_timer.latest_ms
        size = render_size(output.size, scale)
        targets = levels.get(0, size)
        views.levels = levels
        views.main = camera_view(cam_t.world, cam.fov_y, cam.near, cam.far, size,
                                 ortho_height=cam.ortho_height if cam.projection == "orthographic" else None,
                                 aspect=output.size[0] / output.size[1])
        views.main.layers = cam.layer_mask  # its culling mask (Camera.shows_layers / hides_layers)
        particles = self.renderer.scene_pass.particle_draw
        if self.renderer.antialias == "taa":   # (its sub-pixel offset this frame: temporal AA)
            temporal = self.renderer.present_pass.temporal
            jittered(views.main, temporal.offset(size, output.size))
            if any(record.particles for record in particles.emitters.values()):
                # Its particles drawn again into the reactive mask (they carry no motion).
                particles.reactive = (targets, temporal.begin_reactive(targets), views.levels)
        views.options = self._root_options()
        occlusion = self.world.try_get(camera[0], AmbientOcclusion) if self.occlusion else None
        contact = self.world.try_get(camera[0], ContactShadows) if self.occlusion else None
        sun = brightest_directional(self.world) if contact is not None else None
        flagged = self.world.resources.get(ContactLamps, _NO_LAMPS).positions if contact is not None else ()
        lamps = self.renderer.occlusion.usable_lamps(flagged)   # (none where the context lacks their unit)
        if contact is not None and sun is None and not lamps:   # (they darken the sun's light and such lamps')
            if self._said_no_sun is not contact and not flagged:
                self._said_no_sun = contact
                warnings.warn(ComponentWarning(
                    f"ContactShadows on entity {camera[0]}: the world has no DirectionalLight that shines (a sun) and "
                    "no PointLight with contact_shadows, and contact shadows darken only those lights, so they darken "
                    "nothing"), stacklevel=2)
            contact = None
        self.occluded, self.contact_shadowed = occlusion, contact
        self.contact_lamps = len(lamps) if contact is not None else 0
        if occlusion is not None or contact is not None:  # found before the view is drawn: its shading reads it
            self.renderer.occlusion.draw(views.main, occlusion, contact, None if sun is None else -sun.direction,
                                         lamps)
        elif self.renderer.screen_occlusion is not None:
            self.renderer.occlusion.release_targets()  # no camera asks for it now
        reflections = self.world.try_get(camera[0], ScreenReflections) if self.reflections else None
        self.reflected = reflections
        if reflections is not None:  # the view draws what their composite reads (the reflect stage's)
            self.renderer.screen_reflections.begin(views.main, targets, reflections)
            self._check_reflecting(camera[0], reflections)
        else:
            self.renderer.screen_reflections.release_targets()  # no camera asks for them now
        if occlusion is not None or contact is not None or reflections is not None:
            views.options = self._screen(views.options, occlusion is not None or contact is not None,
                                         reflections is not None)
        self.renderer.scene_pass.draw([views.main], targets, views.options)
        self._shafts(camera[0], views.main, targets)

    def _shafts(self, camera: int, view: View, targets: RenderTargets) -> None:
        """The camera's ``VolumetricFog``, begun for this frame's ``view`` (drawn into
        ``targets``) where its Fog has air and the world a sun or a lamp that lights it
        (``camera_shafts``); said once where not."""
        fog = self.world.try_get(camera, Fog)
        found, why = camera_shafts(self.world, self.renderer, camera, fog)
        if why is not None:
            shafts = self.world.get(camera, VolumetricFog)
            if self._said_no_shafts != (shafts, why):
                self._said_no_shafts = (shafts, why)
                warnings.warn(ComponentWarning(f"VolumetricFog on entity {camera} {why}, so it adds nothing"),
                              stacklevel=3)
        self.shafts = None if found is None else found.settings
        if found is None:
            self.renderer.volumetric_fog.release_targets()
            self._said_lamps_cut = 0
            return
        lamps = found.lamps
        self.renderer.stats.volumetric_lamps_cut = lamps.cut
        if lamps.cut > self._said_lamps_cut:   # (said again only when more are cut)
            warnings.warn(LightLimitWarning(
                f"{len(lamps.slots) + lamps.cut} point lights with volumetric > 0 light the scene: the light shafts "
                f"scatter at most {MAX_VOLUMETRIC_LAMPS} at once (the first by the lights' slots), so {lamps.cut} "
                "light no air (RenderStats.volumetric_lamps_cut)"), stacklevel=3)
        self._said_lamps_cut = lamps.cut
        self.renderer.volumetric_fog.begin(view, targets, found.settings, self.renderer.antialias == "taa", lamps,
                                           found.sky_light, found.image_shares)

    def _check_reflecting(self, camera: int, reflections: ScreenReflections) -> None:
        """Say once, for a camera's ``ScreenReflections``, when nothing the world draws reflects
        the sky or a probe (every surface a mirror or a portal, whose views are exact): screen
        reflections replace only those reflections, so they would show nothing."""
        batches = self.renderer.opaque_batches()  # (a new list whenever the batches change)
        if self._said_nothing_reflects is reflections or self._looked_at is batches:
            return
        self._looked_at = batches  # (not each frame: only when the batches changed)
        if batches and not any(map(reflects_environment, batches)):
            self._said_nothing_reflects = reflections
            warnings.warn(ComponentWarning(
                f"ScreenReflections on entity {camera}: nothing in the world reflects the sky or a probe "
                "(every surface drawn is a mirror or a portal, whose reflections are exact views), and screen "
                "reflections replace only those reflections, so they show nothing"), stacklevel=2)

    def _screen(self, options: SceneOptions, occlusion: bool, reflections: bool) -> SceneOptions:
        """The root's ``options`` with ambient occlusion and screen reflections as asked:
        made again only when one of them changes (a frame's options are compared by identity downstream)."""
        base, occluded, reflected, made = self._screen_options
        if base is not options or occluded != occlusion or reflected != reflections:
            made = replace(options, occlusion=occlusion, reflections=reflections)
            self._screen_options = (options, occlusion, reflections, made)
        return made

    def _root_options(self) -> SceneOptions:
        """The main view's scene options: the root of the reflect stage's tree, which draws
        its transparent slot after compositing the reflections into it
        (``SceneOptions.transparent``), with the mirrors that tree paints over entirely
        drawn unlit, worked out again only when a surface or the pixel budget changed."""
        surfaces = self.world.resources.get(Surfaces)
        if self.depth_cap is None or surfaces is None or not surfaces.mirrors:
            self._options = (((), ()), TREE_ROOT)   # (the gone mirrors' states let go)
            return TREE_ROOT
        budget = ViewBudget.of(self.world.resources)
        pixel_budget = budget is not None and budget.pixels is not None
        states = tuple(surfaces.mirrors.values())  # a state object stands while its surface is unchanged
        limits = pixel_budget
        (kept_limits, kept_states), options = self._options
        if kept_limits != limits or len(kept_states) != len(states) or any(map(operator.is_not, kept_states, states)):
            unlit = shading_replaced(states, pixel_budget)
            options = SceneOptions(unlit=unlit, transparent=False) if unlit else TREE_ROOT
            self._options = ((limits, states), options)
        return options
