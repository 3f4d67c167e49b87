"""Light shafts: the sun's light (or by night the moon's: ``sky.air_light``, the brighter
once an atmosphere has dimmed each) scattered by the active camera's fog, shadowed
(``VolumetricFog`` beside its ``Fog``; ``components/fog.py``).

Ray marching through a participating medium, in screen space, as Unreal's, Godot's and
HDRP's volumetric fog and the older "volumetric light scattering" post passes do, without
their froxel grid (no compute in GL 4.1): two full-screen draws in the main view tree's
root, once its mirrors and portals are composited into it and its screen-space reflections
put in, before its glass (``ScenePass.finish_root``):

1. **The march** (``shaders/volumetric_fog.frag``), at half the view's size by default: each
   texel's ray from the near plane to what the view's depth image shows (the sky: the
   component's ``distance`` on) sums, at ``steps`` points, the fog's density there, what of
   the light scattered there reaches the eye (the fog's own transmittance,
   ``shaders/include/fog.glsl``) and whether the sun (or moon) reaches the point (its shadow map, read
   as the scene pass reads it: ``shaders/include/shadows.glsl``; and a ``CloudLayer``'s
   share, ``shaders/include/clouds.glsl``'s ``cloud_shadow``), then scales the sum by the
   sun's light, the Henyey-Greenstein phase function and ``intensity``; and at each point the
   light of each lamp the prepare stage lists (``VolumetricLamps``: ``PointLight.volumetric``),
   its falloff, cone, cookie and shadow, by the phase function of its own angle; and the
   light of either through mirrors and portals (the shadows stage's virtual lights whose light
   is the air's sun or moon or a scattered lamp: ``begin``'s ``image_shares``), where the line
   towards the image comes out of its exit, in its own shadow map.  Each texel's points
   start at another offset (interleaved gradient noise; moved each frame under temporal AA,
   whose history then averages them).
   While nothing the root's march reads moves (``_still_key``: the scene, its shadow maps
   and blocks, the camera, the settings, the lamps) and no temporal AA moves its offsets, its
   image is kept and the march not drawn again: a still view's frame draws the filter alone.
2. **The filter** (``shaders/volumetric_fog_filter.frag``), at the view's size: each pixel
   takes the march's 3 x 3 texels about it, weighed by a Gaussian of their distance and by how
   near their rays' lengths are to its own (a shaft behind a near edge stays behind it), and
   is added to the view's colour (``BLEND_ADD``).

Added to the light the fog's colour and sun glow already give each pixel (the scene pass's
``FOG`` builds).  Glass drawn after blends over it as over the rest (a pane of alpha a
keeps 1 - a of the shafts along its pixels, the air's in front of it too: the march ends at
the opaque depth and does not know where the pane stands).

**Reflection levels** (``VolumetricFog.reflection_depth``, 1 by default): a level of the
main view tree the depth reaches gets the same two draws once its levels below are
composited into it, before its glass (``composite_level``, from ``ScenePass.finish_level``),
once a view over its rectangle (``LEVEL_VIEWS`` builds: that view's pixels and texels only,
its own projection, whose oblique near plane starts each ray on the surface it looks out
of), a ray a pixel.  The air between the eye and the surface is its parent's, and the
composite fogs the level's light as a whole over that stretch, so the shafts a mirror shows
are dimmed as what it shows is.

**Monitors' pictures** (``begin_picture``): a monitor's camera with a ``VolumetricFog`` of its
own gets the same two draws in its picture's root, before its glass, in an image of the
picture's own (kept by monitor), through the fog the picture is drawn through (the camera's
own ``Fog``, or the frame's); never jittered, marched at every drawing (a picture nothing it
shows changed is kept whole); its mirror and portal levels as far as its ``reflection_depth``
reaches (``composite_level``, images of the picture's own; the active camera's put aside
until ``end_picture``).

The images are made the first frame a camera asks (a level's the first frame it is reached)
and let go when none does (a level's when the depth no longer reaches it or the world has
no mirror or portal left: ``release_levels``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import moderngl
import numpy as np
from pyglm import glm

from components.fog import VolumetricFog
from components.limits import MAX_VOLUMETRIC_LAMPS
from engine.render.bindings import (
    BLEND_ADD,
    CAUSTIC_UNIT,
    CAUSTICS_BINDING,
    CLOUDS_BINDING,
    COOKIE_UNIT,
    FOG_BINDING,
    LAMP_SEE_THROUGH_UNIT,
    LIGHTS_BINDING,
    POINT_SHADOW_UNITS,
    RIPPLE_UNIT,
    RIPPLES_BINDING,
    SEE_THROUGH_UNIT,
    SHADOW_ATLAS_UNIT,
    SHADOWS_BINDING,
    SPOT_SHADOW_UNIT,
    VIRTUAL_LIGHTS_BINDING,
    VIRTUAL_SEE_THROUGH_UNIT,
    VIRTUAL_SHADOW_UNIT,
    VOLUMETRIC_DEPTH_UNIT,
    VOLUMETRIC_LIGHT_UNIT,
    VOLUMETRIC_NODE_UNIT,
    PassState,
    apply_pass_state,
    assign_slots,
    bind_sampler,
    bind_texture,
    set_scissor,
)
from engine.render.clouds import cloud_stride
from engine.render.picture_images import PictureImages
from engine.render.targets import RenderTargets, release_framebuffer
from engine.render.views import MAX_DIRECTIONAL_LIGHTS, View
from engine.resources import VolumetricLamps
from engine.rules.shadow_rules import MAX_VIRTUAL_LIGHTS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from engine.render.gpu import Gpu
    from engine.render.shadows import ShadowMaps

_MARCH = PassState()
_ADD = PassState(blend=BLEND_ADD)
# Each frame's offset to the points' starts under temporal AA: the golden ratio's fraction
# steps through [0, 1) as evenly as a sequence can without knowing its length.
_GOLDEN = 0.6180339887498949
_NO_LAMPS = VolumetricLamps()


@dataclass
class _Images:
    """The march's image and the framebuffers of one set of level targets."""

    level: RenderTargets
    light: moderngl.Texture
    light_framebuffer: moderngl.Framebuffer
    output: moderngl.Framebuffer  # the level's colour alone (its depth is read, not attached)
    ratio: int

    def release(self) -> None:
        release_framebuffer(self.light_framebuffer)
        release_framebuffer(self.output)
        self.light.release()


class VolumetricFogPass:
    """The active camera's light shafts: ``begin`` when its view is drawn, ``composite_level``
    before each reflection level's glass and ``composite`` before its own (the module's
    docstring)."""

    def __init__(self, gpu: Gpu, shadows: ShadowMaps) -> None:
        self.gpu = gpu
        self.ctx = gpu.ctx
        self.shadows = shadows
        self._images: _Images | None = None
        self._levels: dict[int, _Images] = {}  # a reflection level's, by its depth
        # This frame's (view, settings, jittered, the lamps it scatters, the share of each light
        # through a mirror or portal, by its slot), from begin to the root's composite.
        self._pending: tuple[View, VolumetricFog, bool, VolumetricLamps, tuple[float, ...]] | None = None
        # The levels this frame's shafts reach (0: the camera's view alone; -1: no shafts): a
        # still tree's refill copies such a level, whose shafts add to what its pixels hold.
        self.reach = -1
        self._programs: dict[tuple, moderngl.VertexArray] = {}
        self._programs_of = -1  # the shader library's reloads when they were made
        self._frame = 0
        self.composites = 0  # drawn so far, the root's and each level's (tests count them)
        self.marches = 0     # the marches among them (a still camera's root keeps its march)
        # What the root's march image was last marched from (``_still_key``): equal, and not
        # jittered, the image stands and only the filter adds it again to the view's new draw.
        self._marched_from: tuple | None = None
        self._sky_light: tuple[int, tuple[float, float, float]] | None = None   # begin's ``sky_light``
        self.cloud_stride = 1   # the march's steps between two reads of the clouds' share (the last march's)
        self.keep_still = True  # False: marched every frame (what the still fuzz compares with)
        # Monitors' pictures' images, and the picture drawn now (``drawing``: its images, its
        # ``begin``'s pending, its sky light), from begin_picture to its root's composite.
        self._pictures: PictureImages[_Images] = PictureImages()
        # Their reflection levels' images, by monitor, then depth; and, while a picture is
        # drawn, the active camera's pending view, levels, sky light and reach put aside
        # (``end_picture``).
        self._picture_levels: dict[int, dict[int, _Images]] = {}
        self._aside: tuple | None = None

    def begin(self, view: View, targets: RenderTargets, settings: VolumetricFog, jittered: bool = False,
              lamps: VolumetricLamps = _NO_LAMPS,
              sky_light: tuple[int, tuple[float, float, float]] | None = None,
              image_shares: tuple[float, ...] = ()) -> None:
        """``view``, drawn into ``targets`` (the main tree's level 0) this frame, gets the
        shafts ``settings`` say, of the sun or the moon (``sky_light``: its slot in the
        Lights block and the unit way towards it, which sets how often the march reads a
        CloudLayer's share: ``clouds.cloud_stride``; ``sky.air_light`` chooses it) and ``lamps``,
        and of the lights through mirrors and portals (``image_shares``: each virtual light's share by
        its slot in the VirtualLights block, 1 for the sun's or moon's image, a lamp's
        ``volumetric`` for its, 0 for one whose light scatters in no air: none scatter, no
        loop is built) (``jittered``: under temporal AA, a new offset each frame); the images are made for the
        targets (again when they or the resolution change)."""
        ratio = 2 if settings.half_resolution else 1
        images = self._images
        if images is None or images.level is not targets or images.ratio != ratio:
            if images is not None:
                images.release()
            images = self._images = self._make(targets, ratio)
            self._marched_from = None
        self._pending = (view, settings, jittered, lamps, image_shares if any(image_shares) else ())
        self._sky_light = sky_light
        self.reach = settings.reflection_depth
        for depth in [depth for depth in self._levels if depth > settings.reflection_depth]:
            self._levels.pop(depth).release()
        self._frame += 1

    def begin_picture(self, monitor: int, view: View, targets: RenderTargets, settings: VolumetricFog,
                      lamps: VolumetricLamps = _NO_LAMPS,
                      sky_light: tuple[int, tuple[float, float, float]] | None = None,
                      image_shares: tuple[float, ...] = ()) -> None:
        """Monitor ``monitor``'s picture, about to be drawn from ``view`` into ``targets`` (its
        level 0), gets its camera's shafts (the arguments as ``begin``'s, never jittered), into
        an image of the picture's own (kept by monitor), marched and added at its root's
        composite (``composite``; ``end_picture`` after the draw); its mirror and portal levels
        too, as far as ``reflection_depth`` reaches (``composite_level``: the active camera's
        pending view, levels, sky light and reach put aside until ``end_picture``, the
        picture's levels' images its own)."""
        ratio = 2 if settings.half_resolution else 1
        images = self._pictures.kept(monitor, lambda kept: kept.level is targets and kept.ratio == ratio,
                                     lambda: self._make(targets, ratio))
        pending = (view, settings, False, lamps, image_shares if any(image_shares) else ())
        self._pictures.drawing = (images, pending, sky_light)
        if self._aside is None:
            self._aside = (self._pending, self._levels, self._sky_light, self.reach)
        levels = self._levels = self._picture_levels.setdefault(monitor, {})
        for depth in [depth for depth in levels if depth > settings.reflection_depth]:
            levels.pop(depth).release()
        self._pending, self._sky_light, self.reach = pending, sky_light, settings.reflection_depth

    def end_picture(self) -> None:
        """The picture ``begin_picture`` began is drawn (its composite drawn, or not reached):
        the active camera's pending view, levels, sky light and reach back."""
        self._pictures.drawing = None
        if self._aside is not None:
            self._pending, self._levels, self._sky_light, self.reach = self._aside
            self._aside = None

    def drop_picture(self, monitor: int) -> None:
        """Let go of monitor ``monitor``'s picture's image (it went, or its camera has no
        shafts), its levels' too."""
        self._pictures.drop(monitor)
        for images in self._picture_levels.pop(monitor, {}).values():
            images.release()

    def _make(self, targets: RenderTargets, ratio: int) -> _Images:
        size = (-(-targets.size[0] // ratio), -(-targets.size[1] // ratio))
        light = self.ctx.texture(size, 4, dtype="f4")  # (the ray's length in metres beside the light)
        light.filter = (moderngl.NEAREST, moderngl.NEAREST)
        return _Images(targets, light, self.ctx.framebuffer([light]), self.ctx.framebuffer([targets.color]), ratio)

    def composite(self, level: RenderTargets) -> None:
        """March and add this frame's shafts into ``level`` (the main tree's level 0, its
        mirrors and portals composited, its glass not yet drawn), if its view was begun
        this frame; nothing otherwise (another tree's root: a probe face's)."""
        picture = self._pictures.drawing
        if picture is not None and picture[0].level is level:   # a monitor's picture's root
            self._pictures.drawing = None
            if self._aside is not None:
                self._pending = None   # (its levels are composited: nothing after the root adds to them)
            images, pending, sky_light = picture
            self._draw(images, [pending[0]], pending, False, True, sky_light)
            return
        images, pending = self._images, self._pending
        if pending is None or images is None or images.level is not level:
            return
        self._pending = None
        view, settings, jittered, lamps, shares = pending
        key = None if jittered else self._still_key(view, images, settings, lamps, shares)
        march = not (self.keep_still and key is not None and key == self._marched_from)
        self._marched_from = key
        self._draw(images, [view], pending, False, march, self._sky_light)

    def composite_level(self, depth: int, views: Sequence[View], level: RenderTargets) -> None:
        """March and add this frame's shafts into reflection level ``depth``'s ``level``
        (``views`` drawn into it, the levels below composited, its glass not yet drawn), where
        the camera's ``reflection_depth`` reaches it; nothing otherwise."""
        pending = self._pending
        if pending is None or depth > pending[1].reflection_depth or not views:
            return
        images = self._levels.get(depth)
        if images is None or images.level is not level:
            if images is not None:
                images.release()
            images = self._levels[depth] = self._make(level, 1)
        self._draw(images, views, pending, True, True, self._sky_light)

    def _still_key(self, view: View, images: _Images, settings: VolumetricFog, lamps: VolumetricLamps,
                   shares: tuple[float, ...]) -> tuple:
        """What the root's march reads: the view's depth (every instance row, batch and
        texture drawn: ``Gpu.scene_version``, which the Lights, Fog, Shadows and VirtualLights
        blocks, the shadow maps and the cookies move on too), the shaders, the view's Camera
        block and size, the images' resolution, the settings, the lamps and the images' shares,
        and the rings of a rippling water whose caustics it reads (``RippleAtlas.version``)."""
        ripples = self.gpu.ripples
        return (self.gpu.scene_version, self.gpu.shaders.reloads, view.camera_block(), images.level.size,
                images.ratio, settings.intensity, tuple(settings.albedo), settings.anisotropy, settings.distance,
                settings.steps, lamps.slots, lamps.scatter, self._sky_light, shares,
                ripples.version if ripples.caustic_defines else -1)

    def _draw(self, images: _Images, views: Sequence[View], pending: tuple, level_views: bool,
              march_again: bool, sky_light: tuple[int, tuple[float, float, float]] | None) -> None:
        """The march into ``images`` (unless not ``march_again``: the image stands) and the
        filter into its level's colour (``pending``: ``begin``'s, ``sky_light`` with it), one
        draw each over the view's pixels, or with ``level_views`` one a view over its rectangle."""
        _, settings, jittered, lamps, shares = pending
        ctx, gpu = self.ctx, self.gpu
        level = images.level
        self.shadows.bind()
        gpu.fog.bind()
        gpu.clouds.bind()   # (another engine on the context binds its own block at the same point)
        gpu.caustics.bind()
        gpu.ripples.bind()   # (the caustics' rings, in their RIPPLES builds)
        if lamps.slots or shares:
            gpu.spot_cookies.bind()
        bind_texture(ctx, level.depth, VOLUMETRIC_DEPTH_UNIT)
        bind_sampler(ctx, gpu.depth_values(), VOLUMETRIC_DEPTH_UNIT)  # (its values, compared with nothing)
        if level_views:
            bind_texture(ctx, level.node, VOLUMETRIC_NODE_UNIT)
        shared = {"depth_size": (float(level.size[0]), float(level.size[1])), "ratio": images.ratio,
                  "max_distance": settings.distance}
        # Each view's values, worked out once for both draws.
        each = [{"inv_view_proj": glm.inverse(view.view_proj).to_bytes(),
                 **({"node": view.node} if level_views else {})} for view in views]
        if march_again:
            march = self._program("volumetric_fog.frag", settings.steps, level_views, len(lamps.slots), bool(shares))
            tiles = np.zeros((MAX_DIRECTIONAL_LIGHTS, 4), np.float32)
            for slot, tile in self.shadows.directional_tiles.items():
                tiles[slot, :3] = tile
            spare = MAX_VOLUMETRIC_LAMPS - len(lamps.slots)
            clouds = gpu.clouds.shape
            self.cloud_stride = 1 if clouds is None or sky_light is None else \
                cloud_stride(clouds, settings.distance / settings.steps, np.array(sky_light[1], np.float64))
            self._write(march.program, {**shared, "scatter": settings.intensity, "albedo": tuple(settings.albedo),
                                        "anisotropy": settings.anisotropy,
                                        "cloud_stride": self.cloud_stride,
                                        "sky_light": -1 if sky_light is None else sky_light[0],
                                        "frame_offset": (self._frame * _GOLDEN) % 1.0 if jittered else 0.0,
                                        "map_tiles": tiles.tobytes(), "lamp_slots": (*lamps.slots, *(0,) * spare),
                                        "lamp_scatter": (*lamps.scatter, *(0.0,) * spare),
                                        "virtual_scatter": _shares_bytes(shares)})
            images.light_framebuffer.use()
            apply_pass_state(ctx, _MARCH, (0, 0, *images.light.size))
            self._each_view(march, views, each, level_views)
            gpu.stats.passes += 1
            gpu.stats.draw_calls += len(views)
            self.marches += 1
        spread = self._program("volumetric_fog_filter.frag", 0, level_views)
        self._write(spread.program, shared)
        bind_texture(ctx, images.light, VOLUMETRIC_LIGHT_UNIT)
        images.output.use()
        apply_pass_state(ctx, _ADD, (0, 0, *level.size))
        self._each_view(spread, views, each, level_views)
        gpu.stats.passes += 1
        gpu.stats.draw_calls += len(views)
        self.composites += 1
        if gpu.debug:
            gpu.checkpoint("volumetric fog" if not level_views else f"volumetric fog ({views[0].name} ...)")

    def _each_view(self, vao: moderngl.VertexArray, views: Sequence[View], each: list[dict],
                   level_views: bool) -> None:
        """``vao``'s full-screen triangle for each of ``views`` (``each``: its values; with
        ``level_views`` over its rectangle's scissor)."""
        for view, values in zip(views, each, strict=True):
            if level_views:
                set_scissor(self.ctx, view.scissor)
            self._write(vao.program, values)
            vao.render(moderngl.TRIANGLES, vertices=3)

    def _program(self, shader: str, steps: int, level_views: bool, lamps: int = 0,
                 images: bool = False) -> moderngl.VertexArray:
        """The march's build for ``steps`` and ``lamps`` lamps, and with ``images`` the lights
        through mirrors and portals (with the shadow lookups and fog terms the scene builds
        have now), or the filter's (``steps`` 0); a reflection level's with ``level_views``."""
        shaders = self.gpu.shaders
        if self._programs_of != shaders.reloads:
            self._release_programs()
            self._programs_of = shaders.reloads
        extra = (self.shadows.program_defines, self.gpu.fog.defines, self.gpu.clouds.shadow_defines,
                 self.gpu.spot_cookies.defines if lamps or images else (), self.gpu.caustics.defines,
                 self.gpu.ripples.caustic_defines if self.gpu.caustics.defines else ()) if steps else ()
        key = (shader, steps, extra, level_views, lamps, images)
        vao = self._programs.get(key)
        if vao is None:
            defines = {"STEPS": str(steps), "VOLUMETRIC_LAMPS": str(lamps)} if steps else {}
            for pairs in extra:
                defines.update(pairs)
            if steps:  # a tap a point (the march's steps and the filter soften the edges)
                defines["SHADOW_SINGLE_TAP"] = "1"
            if level_views:
                defines["LEVEL_VIEWS"] = "1"
            if images:
                defines["VIRTUAL_LIGHTS"] = "1"
            program = shaders.program("fullscreen.vert", shader, defines=defines)
            assign_slots(program, {"depth_map": VOLUMETRIC_DEPTH_UNIT, "light_map": VOLUMETRIC_LIGHT_UNIT,
                                   "node_map": VOLUMETRIC_NODE_UNIT, "shadow_atlas": SHADOW_ATLAS_UNIT,
                                   "point_shadow0": POINT_SHADOW_UNITS[0], "point_shadow1": POINT_SHADOW_UNITS[1],
                                   "spot_atlas": SPOT_SHADOW_UNIT, "spot_cookies": COOKIE_UNIT,
                                   "caustic_maps": CAUSTIC_UNIT, "virtual_atlas": VIRTUAL_SHADOW_UNIT,
                                   "ripple_atlas": RIPPLE_UNIT, "lamp_see_through_atlas": LAMP_SEE_THROUGH_UNIT,
                                   "see_through_atlas": SEE_THROUGH_UNIT,
                                   "virtual_see_through_atlas": VIRTUAL_SEE_THROUGH_UNIT},
                         {"Lights": LIGHTS_BINDING, "Shadows": SHADOWS_BINDING, "Fog": FOG_BINDING,
                          "Clouds": CLOUDS_BINDING, "Caustics": CAUSTICS_BINDING, "Ripples": RIPPLES_BINDING,
                          "VirtualLights": VIRTUAL_LIGHTS_BINDING})
            vao = self._programs[key] = self.ctx.vertex_array(program, [])
        return vao

    def _write(self, program: moderngl.Program, values: dict) -> None:
        """``values`` into ``program``'s uniforms it has, each only where it differs from what
        the library's record says it holds."""
        uniforms = self.gpu.shaders.uniforms
        for name, value in values.items():
            if name in program:
                if isinstance(value, bytes):
                    uniforms.write(program, name, value)
                else:
                    uniforms.set(program, name, value)

    def target_count(self) -> int:
        """Images held now (1 while a camera asks for shafts, and 1 for each reflection level
        they reach and each monitor's picture that has them, else 0)."""
        levels = self._aside[1] if self._aside is not None else self._levels
        return (0 if self._images is None else 1) + len(levels) + len(self._pictures) \
            + sum(len(kept) for kept in self._picture_levels.values())

    def level_key(self) -> tuple | None:
        """What this frame's reflection levels get shafts with, as values (the reflect
        stage's still key: a change draws its levels again)."""
        if self._pending is None:
            return None
        _, settings, _, lamps, shares = self._pending
        return (settings.intensity, tuple(settings.albedo), settings.anisotropy, settings.distance, settings.steps,
                settings.reflection_depth, lamps.slots, lamps.scatter, shares)

    def release_levels(self) -> None:
        """Let the reflection levels' images go (the world has no mirror or portal now)."""
        for images in self._levels.values():
            images.release()
        self._levels.clear()

    def release_targets(self) -> None:
        """Let the images go (no camera asks for shafts), the levels' too."""
        if self._images is not None:
            self._images.release()
            self._images = None
        self.release_levels()
        self._pending = None
        self.reach = -1

    def _release_programs(self) -> None:
        for vao in self._programs.values():
            vao.release()
        self._programs.clear()

    def release(self) -> None:
        self.release_targets()
        for monitor in list(self._picture_levels):
            self.drop_picture(monitor)
        self._pictures.release()
        self._release_programs()


def _shares_bytes(shares: tuple[float, ...]) -> bytes:
    """The march's ``virtual_scatter``: each virtual light's share, by slot, 0 past them."""
    values = np.zeros(MAX_VIRTUAL_LIGHTS, np.float32)
    values[:len(shares)] = shares[:MAX_VIRTUAL_LIGHTS]
    return values.tobytes()
