"""The scene pass: the one function that draws the world for a set of views into a target.

Every view goes through it: the main camera, each mirror and portal view of a reflection
level, and (next) each face of a cube-map probe.  For each view it draws

  1. the opaque batches, one instanced draw per (mesh, texture), smallest first, so big
     surfaces behind small things fail the depth test before they are shaded;
  2. the sky behind them (a full-screen triangle at the far plane, depth test <=);
  3. the transparent slot: batches marked transparent, farthest first, blended over what
     is there.  No material is transparent yet; refraction (glass) fills this slot.

``SceneOptions`` says how: clear the target first (a root view) or keep the depth mask a
reflection level's claims wrote; draw only the pixels the target's node image gives each
view (the claimed-pixels mask); draw the sky or leave it to the composite; write the node
image or only colour and ids; and whether a level's views are drawn each with their own
draws or all at once through the geometry shader (``batched``: each triangle is emitted
once per view that can see it, seed "Multiple Mirrors"' one-draw path; at most
``MAX_BATCHED_VIEWS`` views a draw, more are drawn in groups of that many).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import moderngl
from pyglm import glm

from engine.render.batched_mirrors import MAX_BATCHED_VIEWS, VIEWS_BLOCK_BYTES, VIEWS_PER_INVOCATION, views_block
from engine.render.bindings import (
    ALBEDO_UNIT,
    BATCHED_SCENE_CLIPS,
    CAMERA_BINDING,
    LIGHTS_BINDING,
    NODE_UNIT,
    SCENE_CLIPS,
    SKY_UNIT,
    VIEWS_BINDING,
    PassState,
    apply_pass_state,
)
from engine.render.targets import RenderTargets
from engine.render.views import View, union_rect


@dataclass(frozen=True)
class SceneOptions:
    """How ``ScenePass.draw`` draws its views (defaults: a root view such as the main camera)."""

    clear: bool = True          # clear colour, ids and depth first; False keeps a level's claim mask
    masked: bool = False        # only pixels whose node image names the view (the claimed pixels)
    sky: bool = True            # the sky behind; reflection views leave it to their composite
    write_node: bool = True     # also write the node image (a masked pass reads it instead)
    batched: bool = False       # all views in one draw per batch (the geometry-shader path)
    reflection_filter: bool = False  # albedo filtered as reflections are (Renderer.reflection_anisotropy)


ROOT_VIEW = SceneOptions()
REFLECTION_LEVEL = SceneOptions(clear=False, masked=True, sky=False, write_node=False, reflection_filter=True)
_SCENE = PassState(depth_func="<", cull=True, clips=SCENE_CLIPS)
_BATCHED_SCENE = PassState(depth_func="<", cull=True, clips=BATCHED_SCENE_CLIPS)
_SKY = PassState(depth_func="<=", clips=SCENE_CLIPS)
_TRANSPARENT = PassState(depth_func="<", cull=True, clips=SCENE_CLIPS,
                         blend=(moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ZERO, moderngl.ONE))


class ScenePass:
    """The scene programs (plain and batched) and the one ``draw`` every view goes through."""

    def __init__(self, renderer) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        shaders = renderer.shaders
        self.program = shaders.program("scene.vert", "scene.frag")
        self.sky_program = shaders.program("sky.vert", "sky.frag")
        for program in (self.program, self.sky_program):
            program["Camera"].binding = CAMERA_BINDING
            program["sky_map"].value = SKY_UNIT
        self._setup_scene_program(self.program)
        self._sky = self.ctx.vertex_array(self.sky_program, [])
        self._batched: dict[int, moderngl.Program] = {}  # by geometry-shader invocations
        self._views_ubo: moderngl.Buffer | None = None
        self._reflection_sampler: moderngl.Sampler | None = None

    @staticmethod
    def _setup_scene_program(program: moderngl.Program) -> None:
        program["Lights"].binding = LIGHTS_BINDING
        program["albedo_map"].value = ALBEDO_UNIT
        program["sky_map"].value = SKY_UNIT
        program["node_map"].value = NODE_UNIT

    # --- the pass ------------------------------------------------------------------------------
    def draw(self, views: Sequence[View], targets: RenderTargets, options: SceneOptions = ROOT_VIEW) -> None:
        """Draw the scene for each of ``views`` into ``targets`` (all of one size)."""
        if not views:
            return
        renderer = self.renderer
        framebuffer = targets.framebuffer if options.write_node else targets.view_framebuffer
        framebuffer.use()
        viewport = (0, 0, *targets.size)
        apply_pass_state(self.ctx, _BATCHED_SCENE if options.batched else _SCENE, viewport)
        if options.clear:
            framebuffer.clear(depth=1.0)
        if options.masked:
            targets.node.use(NODE_UNIT)
        renderer.lights_ubo.bind_to_uniform_block(LIGHTS_BINDING)
        renderer.sky.use(SKY_UNIT)
        sampler = self._reflection_filter() if options.reflection_filter else None
        if sampler is not None:
            sampler.use(ALBEDO_UNIT)  # a bound sampler object overrides the textures' own filter
        try:
            if options.batched:
                for first in range(0, len(views), MAX_BATCHED_VIEWS):
                    self._draw_batched(views[first:first + MAX_BATCHED_VIEWS], options)
            else:
                self._draw_each(views, viewport, options)
        finally:
            if sampler is not None:
                sampler.clear(ALBEDO_UNIT)

    def _draw_each(self, views: Sequence[View], viewport: tuple[int, int, int, int], options: SceneOptions) -> None:
        """Each view its own draws: state shared by the views is set once; per view there is
        a scissor, a winding, a camera and the draws (on llvmpipe the Python and driver cost
        per view is on the frame's critical path)."""
        ctx = self.ctx
        renderer = self.renderer
        program = self.program
        program["masked"].value = options.masked
        program["sky_face_size"].value = renderer.sky.size[0]
        node_index = program["node_index"]
        transparent = renderer.transparent_batches()
        for view in views:
            ctx.scissor = view.scissor
            ctx.front_face = "cw" if view.mirrored else "ccw"
            node_index.value = view.node
            renderer.bind_view(view)
            renderer.draw_batches(program, renderer.opaque_batches())
            if options.sky:
                apply_pass_state(ctx, _SKY, viewport, view.scissor)
                self._sky.render(moderngl.TRIANGLES, vertices=3)
                renderer.stats.draw_calls += 1
            if transparent:
                apply_pass_state(ctx, _TRANSPARENT, viewport, view.scissor)
                ctx.front_face = "cw" if view.mirrored else "ccw"
                renderer.draw_batches(program, _back_to_front(transparent, view.eye))
            if options.sky or transparent:
                apply_pass_state(ctx, _SCENE, viewport)
            renderer.stats.passes += 1

    def _draw_batched(self, views: Sequence[View], options: SceneOptions) -> None:
        """Every batch once for all ``views`` (at most MAX_BATCHED_VIEWS): the geometry
        shader emits each triangle for each view that can see it, clipped to the view's
        rectangle by clip distances 1-4 (the per-view scissor of ``_draw_each``)."""
        renderer = self.renderer
        ctx = self.ctx
        program = self.batched_program(len(views))
        program["masked"].value = options.masked
        program["sky_face_size"].value = renderer.sky.size[0]
        self._views_ubo.write(views_block(views))
        self._views_ubo.bind_to_uniform_block(VIEWS_BINDING)
        ctx.scissor = union_rect([v.scissor or (0, 0, *v.size) for v in views])
        ctx.front_face = "ccw"  # mirrored views reverse their vertices in the geometry shader
        renderer.draw_batches(program, renderer.opaque_batches())
        renderer.stats.passes += 1

    def batched_program(self, view_count: int) -> moderngl.Program:
        """The batched scene program for ``view_count`` views, built on first use.  Its
        geometry shader runs ceil(view_count / VIEWS_PER_INVOCATION) invocations rounded up
        to a power of two: invocations with no view still cost a pass over the triangles."""
        needed = -(-view_count // VIEWS_PER_INVOCATION)
        invocations = min(1 << max(0, needed - 1).bit_length(), -(-MAX_BATCHED_VIEWS // VIEWS_PER_INVOCATION))
        program = self._batched.get(invocations)
        if program is None:
            program = self.renderer.shaders.program("scene.vert", "scene.frag", "scene_batched.geom", defines={
                "BATCHED_VIEWS": "1",
                "MAX_LEVEL_VIEWS": str(MAX_BATCHED_VIEWS),
                "VIEWS_PER_INVOCATION": str(VIEWS_PER_INVOCATION),
                "GS_INVOCATIONS": str(invocations),
                "GS_MAX_VERTICES": str(3 * VIEWS_PER_INVOCATION),
            })
            program["Views"].binding = VIEWS_BINDING
            if "Camera" in program:  # the batched stages read their cameras from Views
                program["Camera"].binding = CAMERA_BINDING
            self._setup_scene_program(program)
            self._batched[invocations] = program
        if self._views_ubo is None:
            self._views_ubo = self.ctx.buffer(reserve=VIEWS_BLOCK_BYTES)
        return program

    def _reflection_filter(self) -> moderngl.Sampler | None:
        """The albedo sampler of reflection views, or None when they filter like the main view."""
        renderer = self.renderer
        if renderer.reflection_anisotropy == renderer.texture_anisotropy:
            return None
        sampler = self._reflection_sampler
        if sampler is None or sampler.anisotropy != renderer.reflection_anisotropy:
            if sampler is not None:
                sampler.release()
            sampler = self._reflection_sampler = self.ctx.sampler(
                filter=(moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR), anisotropy=renderer.reflection_anisotropy)
        return sampler

    def release(self) -> None:
        for obj in (self._sky, self._views_ubo, self._reflection_sampler):
            if obj is not None:
                obj.release()
        self._views_ubo = self._reflection_sampler = None
        self._batched.clear()  # the shader library owns and releases the programs


def _back_to_front(batches, eye: glm.vec3) -> list:
    """Transparent batches, the farthest (by its instances' centre) first."""
    return sorted(batches, key=lambda batch: -glm.distance(batch.centre(), eye))
