"""Screen-space reflections of the active camera's view (``ScreenReflections`` on the camera):
a surface that reflects the sky or a probe shows what the view itself drew along its
reflected ray, where the ray finds it.

Speculum draws forward, so the reflection is put in after shading, where the rest of the
pixel's colour is known, by what the scene pass wrote beside it:

1. **The main view's draw** (``begin``): its opaque batches that reflect the sky or a probe
   (``scene_programs.reflects_environment``; the others first, into the view's own framebuffer)
   draw with the ``SCREEN_REFLECTION`` builds of ``scene.frag`` into the level's images and
   three more (``framebuffer``): ``W``, the share of a radiance along the reflected ray that reaches
   the pixel (the reflect slot's mix, tint, Fresnel and occlusion, or with no reflect slot
   the environment reflection's split-sum share, scaled by what follows it: a metallic map's
   share, a refracting surface's alpha, the fog), with the roughness;
   ``W`` x the sky's or probe's radiance it reflected; and the shading normal.  A pixel's
   colour is its other light plus ``W`` x that radiance, so the composite can take the one
   reflection out and put another in.  The entity's id (22 bits, in the two spare channels)
   says whose surface the three were written for.
2. **The composite** (``composite``), once the view tree has composited the mirrors and
   portals into the view and before it draws the glass (``ScenePass.finish_root``):
   the view's colour is copied (with a mip chain, for rough surfaces) and each pixel with a
   ``W`` marches its reflected ray across the view's depth image
   (``shaders/include/screen_march.glsl``: McGuire and Mara's perspective-correct screen-space
   march, at most ``QUALITY_STEPS`` steps a ray, then the hit refined by halving;
   ``shaders/screen_reflection.frag`` the composite); where it hits, the pixel becomes
   ``colour + c (W x found - W x radiance)``, with ``c`` the confidence (faded at the
   screen's edges, at the end of ``max_distance``, by how far behind the drawn surface the
   ray was found and towards ``max_roughness``).  A polished floor so reflects what a
   mirror beside it shows; glass drawn after keeps its own look over it.

With ``half_resolution`` the rays are marched in a pass of their own at half the view's size
(``shaders/screen_reflection_trace.frag``: a ray a 2 x 2 block, the first of its pixels that
reflects), and the composite takes, at each pixel, the four found about it by bilinear weight
times how near their surfaces' depths are to its own: a quarter of the march.

**Reflection levels** (``ScreenReflections.reflection_depth``: the levels of mirror and
portal views below the camera's that reflect too, 1 by default): the main view tree's level
draws its reflecting surfaces into images of its own the same way (``begin_level``: its
views drawn one by one, masked, with the ``SCREEN_REFLECTION`` builds), and once the levels
below are composited into it, before its glass, ``composite_level`` copies its colour and
draws the composite once a view over its rectangle (``LEVEL_VIEWS`` builds: that view's
pixels only, its own projection, a ray that comes to another view's pixels found nothing).
A level's rays are marched a pixel each (``half_resolution`` is the camera's view's alone).

**Monitors' pictures** (``begin_picture``): a monitor's camera with ``ScreenReflections`` of
its own reflects in its picture as the active camera's view does, into images of the
picture's own (kept by monitor), the composite drawn in its root's ``ScenePass.finish_root``;
its mirror and portal levels reflect nothing.

A pixel is left as it was where the ray leaves the screen (or its view), passes behind what
is drawn by more than ``thickness``, meets a surface from behind, or reaches the sky; where
glass or a see-through surface was drawn over it after its weights (the surface id there is
another entity's); and in probe views, which show the probes' and the sky's reflections.

The images are made at the first frame a camera asks for reflections, for the level's size
(a reflection level's at the first frame it reflects), and released when no camera does
(``release_targets``), a level's when the camera's depth no longer reaches it."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import moderngl
from pyglm import glm

from components.screen_reflections import REFLECTION_QUALITIES, ScreenReflections
from engine.render.bindings import (
    REFLECTION_ADDED_UNIT,
    REFLECTION_COLOR_UNIT,
    REFLECTION_DEPTH_UNIT,
    REFLECTION_HITS_UNIT,
    REFLECTION_NODE_UNIT,
    REFLECTION_NORMAL_UNIT,
    REFLECTION_SURFACE_UNIT,
    REFLECTION_WEIGHT_UNIT,
    PassState,
    apply_pass_state,
    bind_sampler,
    bind_texture,
    set_scissor,
)
from engine.render.picture_images import PictureImages
from engine.render.targets import HDR_FORMAT, RenderTargets, release_framebuffer
from engine.render.views import View

if TYPE_CHECKING:
    from collections.abc import Sequence

if TYPE_CHECKING:
    from engine.render.gpu import Gpu

# ScreenReflections.quality -> (steps a ray across the screen at most, halvings of the hit
# step): shaders/include/screen_march.glsl's STEPS and REFINE.
QUALITY_STEPS = dict(zip(REFLECTION_QUALITIES, ((16, 4), (32, 5), (64, 6)), strict=True))
# A step where the ray went behind the plane the last two steps' ends showed, yet is in
# front at its end (that surface ended within the step), is walked again in at most this
# many parts (a pixel each, where the step is that long): the corner of a surface the ray
# meets only between two steps' ends (a box's top edge) is found (SUBSTEPS).
SILHOUETTE_STEPS = 8
# The colour's mip chain for rough surfaces: at most this many levels above the image (a
# cone 64 pixels wide; a surface rough enough to spread wider keeps the probe's reflection
# by max_roughness long before).
MAX_COLOR_LOD = 6
_PASS = PassState()


@dataclass
class _Targets:
    """The images that go with one set of the main view's level targets."""

    level: RenderTargets
    weight: moderngl.Texture
    added: moderngl.Texture
    normal: moderngl.Texture
    framebuffer: moderngl.Framebuffer      # the level's images and the three: the main view's draw
    color: moderngl.Texture                # the view's colour, copied for the composite, with mips
    color_framebuffer: moderngl.Framebuffer
    output: moderngl.Framebuffer           # the level's colour alone: the composite's target
    hits: moderngl.Texture | None = None   # the rays marched at half size (made on first use)
    hits_framebuffer: moderngl.Framebuffer | None = None
    clear: moderngl.Framebuffer | None = None  # a reflection level's three images alone (cleared each draw)
    # A reflection level's stand-in for its node image among the framebuffer's images: its
    # masked draws read the node image, so it must not be one they draw into (a feedback
    # loop, undefined in GL), and the scene builds write their node to the fourth image.
    node_sink: moderngl.Texture | None = None

    def release(self) -> None:
        for framebuffer in (self.framebuffer, self.color_framebuffer, self.output, self.hits_framebuffer,
                            self.clear):
            if framebuffer is not None:
                release_framebuffer(framebuffer)
        for texture in (self.weight, self.added, self.normal, self.color, self.hits, self.node_sink):
            if texture is not None:
                texture.release()

    def count(self) -> int:
        return 4 + (self.hits is not None) + (self.node_sink is not None)


class ScreenReflectionPass:
    """The active camera's screen-space reflections: ``begin`` before its view is drawn (the
    draw then goes into ``framebuffer``), ``composite`` before its glass is."""

    def __init__(self, gpu: Gpu) -> None:
        self.gpu = gpu
        self.ctx = gpu.ctx
        self._targets: _Targets | None = None
        # By (shader, quality, half, found only): the composite's builds and the half-size march's.
        self._programs: dict[tuple[str, str, bool, bool], moderngl.VertexArray] = {}
        self._programs_of = -1  # the shader library's reloads when they were made
        # program -> the uniform values last written to it (GL keeps them: a still camera's
        # frame writes none)
        self._written: dict[int, dict[str, object]] = {}
        # This frame's: (the view, its settings), from begin until composite (None: nothing to do).
        self._pending: tuple[View, ScreenReflections] | None = None
        self._levels: dict[int, _Targets] = {}  # a reflection level's images, by its depth
        self._drawing: _Targets | None = None    # the level drawn now (begin_level until end_level)
        # Monitors' pictures' images, and the picture drawn now (``drawing``: its images, view
        # and settings, from begin_picture until its composite or end_picture).
        self._pictures: PictureImages[_Targets] = PictureImages()
        # Their reflection levels' images, by monitor, then depth; and, while a picture is
        # drawn, the active camera's pending view and levels put aside (``end_picture``).
        self._picture_levels: dict[int, dict[int, _Targets]] = {}
        self._aside: tuple | None = None
        # The debug overlay's toggle (``MainViewSystem.reflections``): off, no camera's
        # reflections are drawn, the active camera's or a monitor's.
        self.shown = True
        self.composites = 0  # composites drawn so far (tests count them)
        # The debug overlay's "SSR only": the composite writes what the screen gave (the colour
        # found times the confidence, black where nothing was) in place of the picture; the
        # glass is drawn over it as ever.
        self.show_found = False

    @property
    def framebuffer(self) -> moderngl.Framebuffer | None:
        """The framebuffer the main view's reflecting surfaces draw into this frame
        (``SceneOptions.reflections``; None: none)."""
        if self._drawing is not None:
            return self._drawing.framebuffer
        if self._pictures.drawing is not None:
            return self._pictures.drawing[0].framebuffer
        return None if self._pending is None or self._targets is None else self._targets.framebuffer

    def begin(self, view: View, targets: RenderTargets, settings: ScreenReflections) -> None:
        """The main view, about to be drawn into ``targets`` (the main tree's level 0), will
        be reflected as ``settings`` say: its images are made (once for the targets) and the
        framebuffer its reflecting surfaces draw into is ``framebuffer``; the scene pass
        clears them all."""
        kept = self._targets
        if kept is None or kept.level is not targets:
            self.release_targets()
            kept = self._targets = self._make(targets)
        self._fit_hits(kept, settings)
        self._pending = (view, settings)
        for depth in [depth for depth in self._levels if depth > settings.reflection_depth]:
            self._levels.pop(depth).release()

    def _fit_hits(self, images: _Targets, settings: ScreenReflections) -> None:
        """The half-size march's image for ``images`` where ``settings`` march at half size
        (made once), let go where they do not."""
        if settings.half_resolution and images.hits is None:
            size = ((images.level.size[0] + 1) // 2, (images.level.size[1] + 1) // 2)
            images.hits = self.ctx.texture(size, 4, dtype="f4")  # (found pixels past 2048 need more than half floats)
            images.hits.filter = (moderngl.NEAREST, moderngl.NEAREST)
            images.hits_framebuffer = self.ctx.framebuffer([images.hits])
        elif not settings.half_resolution and images.hits is not None:
            release_framebuffer(images.hits_framebuffer)
            images.hits.release()
            images.hits, images.hits_framebuffer = None, None

    def begin_picture(self, monitor: int, view: View, targets: RenderTargets, settings: ScreenReflections) -> None:
        """Monitor ``monitor``'s picture, about to be drawn from ``view`` into ``targets`` (its
        level 0), reflects as its camera's ``settings`` say: as ``begin``, with images of the
        picture's own (kept by monitor), until its root's composite (``composite``) or
        ``end_picture``; its mirror and portal levels too, as far as ``reflection_depth``
        reaches (``begin_level``, ``composite_level``: the active camera's pending view and
        levels put aside until ``end_picture``, the picture's levels' images its own)."""
        images = self._pictures.kept(monitor, lambda kept: kept.level is targets, lambda: self._make(targets))
        self._fit_hits(images, settings)
        self._pictures.drawing = (images, view, settings)
        if self._aside is None:
            self._aside = (self._pending, self._levels)
        levels = self._levels = self._picture_levels.setdefault(monitor, {})
        for depth in [depth for depth in levels if depth > settings.reflection_depth]:
            levels.pop(depth).release()
        self._pending = (view, settings)

    def end_picture(self) -> None:
        """The picture ``begin_picture`` began is drawn (its composite drawn, or not reached):
        the active camera's pending view and levels back."""
        self._pictures.drawing = None
        if self._aside is not None:
            self._pending, self._levels = self._aside
            self._aside = None

    def drop_picture(self, monitor: int) -> None:
        """Let go of monitor ``monitor``'s picture's images (it went, or its camera reflects
        nothing), its levels' too."""
        self._pictures.drop(monitor)
        for images in self._picture_levels.pop(monitor, {}).values():
            images.release()

    def begin_level(self, depth: int, targets: RenderTargets) -> bool:
        """Reflection level ``depth``, about to be drawn into ``targets`` (its claims made),
        reflects where the camera's ``reflection_depth`` reaches it this frame: its images are
        made (once for the targets) and cleared, and ``framebuffer`` is theirs until
        ``end_level``.  False: the level is drawn without."""
        if self._pending is None or depth > self._pending[1].reflection_depth:
            return False
        images = self._levels.get(depth)
        if images is None or images.level is not targets:
            if images is not None:
                images.release()
            sink = self.ctx.texture(targets.size, 1, dtype="u4")
            images = self._levels[depth] = self._make(targets, sink)
            images.node_sink = sink
            images.clear = self.ctx.framebuffer([images.weight, images.added, images.normal])
        images.clear.use()
        apply_pass_state(self.ctx, _PASS, (0, 0, *targets.size))
        images.clear.clear()  # (nothing reflected: the pixels its views do not draw keep it)
        self._drawing = images
        return True

    def end_level(self) -> None:
        """The level ``begin_level`` began is drawn: ``framebuffer`` is the camera's view's again."""
        self._drawing = None

    def _make(self, level: RenderTargets, node: moderngl.Texture | None = None) -> _Targets:
        """The images for ``level``'s targets; the framebuffer's fourth image is ``node`` (a
        reflection level's stand-in) or the level's node image (the root's, which it clears)."""
        ctx = self.ctx
        size = level.size
        weight = ctx.texture(size, 4, dtype=HDR_FORMAT)
        added = ctx.texture(size, 4, dtype=HDR_FORMAT)
        normal = ctx.texture(size, 4, dtype=HDR_FORMAT)
        color = ctx.texture(size, 4, dtype=HDR_FORMAT)
        for texture in (weight, added, normal):
            texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        color.repeat_x = color.repeat_y = False
        color.build_mipmaps(0, self._top_lod(size))  # (the chain's storage; rebuilt each composite)
        color.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        framebuffer = ctx.framebuffer([level.color, level.surface, level.seen, level.node if node is None else node,
                                       weight, added, normal], level.depth)
        return _Targets(level, weight, added, normal, framebuffer, color, ctx.framebuffer([color]),
                        ctx.framebuffer([level.color]))

    @staticmethod
    def _top_lod(size: tuple[int, int]) -> int:
        return max(0, min(MAX_COLOR_LOD, max(size).bit_length() - 1))

    def _program(self, shader: str, quality: str, half: bool, found_only: bool = False,
                 level: bool = False) -> moderngl.VertexArray:
        shaders = self.gpu.shaders
        if self._programs_of != shaders.reloads:
            self._release_programs()
            self._programs_of = shaders.reloads
        key = (shader, quality, half, found_only, level)
        vao = self._programs.get(key)
        if vao is None:
            steps, refine = QUALITY_STEPS[quality]
            defines = {"STEPS": str(steps), "REFINE": str(refine), "SUBSTEPS": str(SILHOUETTE_STEPS)}
            if half:
                defines["HALF_RESOLUTION"] = "1"
            if found_only:
                defines["SHOW_FOUND"] = "1"
            if level:  # a reflection level's: a draw a view (composite_level)
                defines["LEVEL_VIEWS"] = "1"
            program = shaders.program("fullscreen.vert", shader, defines=defines)
            for name, unit in (("scene_color", REFLECTION_COLOR_UNIT), ("depth_map", REFLECTION_DEPTH_UNIT),
                               ("weight_map", REFLECTION_WEIGHT_UNIT), ("added_map", REFLECTION_ADDED_UNIT),
                               ("normal_map", REFLECTION_NORMAL_UNIT), ("surface_map", REFLECTION_SURFACE_UNIT),
                               ("hits_map", REFLECTION_HITS_UNIT), ("node_map", REFLECTION_NODE_UNIT)):
                if name in program:
                    program[name].value = unit
            vao = self._programs[key] = self.ctx.vertex_array(program, [])
        return vao

    def composite(self, level: RenderTargets) -> None:
        """Put the screen's reflections into ``level`` (the main tree's level 0, its mirrors
        and portals composited, its glass not yet drawn), if the main view was drawn for
        them this frame (``begin``); nothing otherwise."""
        picture = self._pictures.drawing
        if picture is not None and picture[0].level is level:   # a monitor's picture's root
            self._pictures.drawing = None
            if self._aside is not None:
                self._pending = None   # (its levels are composited: nothing after the root draws for them)
            images, view, settings = picture
            self._composite(images, [view], view, settings, False)
            return
        targets, pending = self._targets, self._pending
        if pending is None or targets is None or targets.level is not level:
            return  # (another tree's root: a probe face's)
        self._pending = None
        view, settings = pending
        self._composite(targets, [view], view, settings, False)

    def composite_level(self, depth: int, views: Sequence[View], level: RenderTargets) -> None:
        """Put each of ``views``' reflections into reflection level ``depth``'s ``level`` (the
        levels below composited into it, its glass not yet drawn), if it was drawn for them
        (``begin_level``: a level the camera's depth reaches is, every frame it is drawn; a
        kept tree's levels stand as they were drawn); nothing otherwise."""
        images, pending = self._levels.get(depth), self._pending
        if images is None or images.level is not level or pending is None or not views:
            return
        self._composite(images, views, pending[0], pending[1], True)

    def _composite(self, targets: _Targets, views: Sequence[View], root: View, settings: ScreenReflections,
                   level_views: bool) -> None:
        """The composite of ``targets``' level: its colour copied with its mips, then (the
        rays marched at half size first, the root's with ``half_resolution``) a draw over
        the view's pixels, or with ``level_views`` one a view over its rectangle.  The near
        plane a ray is cut at is the camera's (``root``)."""
        gpu, ctx = self.gpu, self.ctx
        level = targets.level
        size = level.size
        viewport = (0, 0, *size)
        # The colour as it stands, with its mip chain (a blit obeys the scissor: none).
        apply_pass_state(ctx, _PASS, viewport)
        ctx.copy_framebuffer(targets.color_framebuffer, level.color_framebuffer)
        top = self._top_lod(size)
        targets.color.build_mipmaps(0, top)
        near = float(root.proj[3][2]) / (float(root.proj[2][2]) - 1.0)
        shared = {"depth_size": (float(size[0]), float(size[1])), "near_plane": near,
                  "max_distance": settings.max_distance, "thickness": settings.thickness,
                  "max_roughness": settings.max_roughness, "edge_fade": settings.edge_fade, "top_lod": float(top)}
        for texture, unit in ((targets.color, REFLECTION_COLOR_UNIT), (level.depth, REFLECTION_DEPTH_UNIT),
                              (targets.weight, REFLECTION_WEIGHT_UNIT), (targets.added, REFLECTION_ADDED_UNIT),
                              (targets.normal, REFLECTION_NORMAL_UNIT), (level.surface, REFLECTION_SURFACE_UNIT)):
            bind_texture(ctx, texture, unit)
        if level_views:
            bind_texture(ctx, level.node, REFLECTION_NODE_UNIT)
        bind_sampler(ctx, gpu.depth_values(), REFLECTION_DEPTH_UNIT)  # (as distances, compared with nothing)
        half = not level_views and settings.half_resolution and targets.hits is not None
        if half:  # the rays marched at half size first
            trace = self._program("screen_reflection_trace.frag", settings.quality, False)
            self._write(trace.program, {**shared, **_view_values(root)})
            targets.hits_framebuffer.use()
            apply_pass_state(ctx, _PASS, (0, 0, *targets.hits.size))
            trace.render(moderngl.TRIANGLES, vertices=3)
            bind_texture(ctx, targets.hits, REFLECTION_HITS_UNIT)
            gpu.stats.passes += 1
            gpu.stats.draw_calls += 1
        vao = self._program("screen_reflection.frag", settings.quality, half, self.show_found, level_views)
        targets.output.use()
        apply_pass_state(ctx, _PASS, viewport)
        self._write(vao.program, shared)
        for view in views:
            values = _view_values(view)
            if level_views:
                values["node"] = view.node
                set_scissor(ctx, view.scissor)
            self._write(vao.program, values)
            vao.render(moderngl.TRIANGLES, vertices=3)
        gpu.stats.passes += 1
        gpu.stats.draw_calls += len(views)
        self.composites += 1
        if gpu.debug:
            gpu.checkpoint("screen reflections" if not level_views else f"screen reflections ({views[0].name} ...)")

    def _write(self, program: moderngl.Program, values: dict) -> None:
        """``values`` into ``program``'s uniforms of those names it has (a build drops what
        it does not read), each only when it differs from what was last written there."""
        written = self._written.setdefault(program.glo, {})
        for name, value in values.items():
            if written.get(name) != value and name in program:
                if isinstance(value, bytes):
                    program[name].write(value)
                else:
                    program[name].value = value
                written[name] = value

    def target_count(self) -> int:
        """Images held now (4 while a camera asks for reflections, 5 at half resolution, and
        4 for each reflection level that reflects and each monitor's picture that does (5 at
        half resolution), else 0)."""
        levels = self._aside[1] if self._aside is not None else self._levels
        pictures = [images for kept in self._picture_levels.values() for images in kept.values()]
        return (0 if self._targets is None else self._targets.count()) + sum(
            images.count() for images in (*levels.values(), *self._pictures, *pictures))

    def level_key(self) -> tuple | None:
        """What this frame's reflection levels reflect with, as values (the reflect stage's
        still key: a change draws its levels again)."""
        if self._pending is None:
            return None
        settings = self._pending[1]
        return (settings.max_distance, settings.thickness, settings.max_roughness, settings.edge_fade,
                settings.quality, settings.reflection_depth, self.show_found)

    def release_levels(self) -> None:
        """Let the reflection levels' images go (the world has no mirror or portal now)."""
        for images in self._levels.values():
            images.release()
        self._levels.clear()
        self._drawing = None

    def release_targets(self) -> None:
        """Let the images go (no camera asks for reflections, or the level was made again),
        the levels' too."""
        if self._targets is not None:
            self._targets.release()
            self._targets = None
        self.release_levels()
        self._pending = None
        self._drawing = None

    def _release_programs(self) -> None:
        for vao in self._programs.values():
            vao.release()
        self._programs.clear()
        self._written.clear()

    def release(self) -> None:
        self.release_targets()
        for monitor in list(self._picture_levels):
            self.drop_picture(monitor)
        self._pictures.release()
        self._release_programs()


def _view_values(view: View) -> dict[str, object]:
    """What the march reads of the view it marches: its projection, the turn from world to
    its space, and the constants that put a depth texel back in that space (view_depth.glsl)."""
    proj = view.proj
    x, y = float(proj[0][2]) / float(proj[0][0]), float(proj[1][2]) / float(proj[1][1])  # (0: no oblique near plane)
    return {"projection": proj.to_bytes(), "view_rotation": glm.mat3(view.view).to_bytes(),
            "unproject": (float(proj[0][0]), float(proj[1][1]), float(proj[2][0]), float(proj[2][1])),
            "unproject_z": (float(proj[2][2]), float(proj[3][2])),
            "oblique": (x, y, x * float(proj[2][0]) + y * float(proj[2][1]))}
