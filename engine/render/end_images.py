"""Recursion that ends in an image: at the depth limit a mirror or portal shows its image from
the previous frame, reprojected, instead of its closed look (Valve's Portal fills the end of
the line; Unity3DPortals reprojects the previous frame past its depth limit).

The main view tree keeps its finished root image each frame (``keep``: one blit into a
history texture) with that frame's view-projection and the surfaces that had a view.  Next
frame, a view the depth limits cut (``view_plan.SurfaceTable.plan(..., ends=True)``) of a
surface with an end image, seen last frame, gets an "end view": claimed like any view, then
filled by ``shaders/end_image.frag`` instead of the scene pass and composited like any view
(tint, fades).  What it shows is what the last view through the same surface up its chain
showed, shrunk onto this footprint: each pixel's ray meets the surface at x, and the view
that saw the surface there before (two levels up for a facing pair) shows, around x, the
levels beyond it in the previous frame's image.  So each frame the image holds a few more
levels, and a still camera sees it converge to the deep recursion.  The first frame, a
surface not seen last frame, and a surface not seen before up its chain show the fallback
(the probe's or the sky's reflection: ``MirrorPasses.draw_fallbacks``), and so does each
pixel whose point last frame's image does not hold (off its edge, or behind its camera, as
after a quick turn): the end view marks it (``NO_END_IMAGE``,
``shaders/include/end_image.glsl``), the composite leaves it alone (stretching the image's
edge over it drew streaks) and the fallback fills it.
Probe faces' trees draw none (their image is not the main view's).

So a still view's image changes a little every frame for a while, and its tree may not be
kept as it was drawn until it settles: ``keep(..., compare=True)`` (a frame whose views show
what the last frame's showed) first counts the pixels where the finished image differs
from the one kept (``shaders/history_same.frag`` in a samples query, ``settled``: read at
the next frame, nothing waits now); none, and the next frame's tree would repeat this one's.
Until then each such frame changes only what depends on the end images: every view's scene
pass draws what it drew the frame before.  So the tree drawn on the first still frame copies
its levels before their composites (``engine/render/level_copies.py``), and the frames after
keep it, filling its end views from the new image and doing each level's composites again
over its copy, up to the root (``StillTree.keep``), then keep and compare the image again.
"""
from __future__ import annotations

import moderngl
from pyglm import glm

from engine.render.bindings import HISTORY_UNIT, NODE_UNIT, SETTLE_IMAGE_UNIT, PassState, apply_pass_state, bind_texture
from engine.render.gpu import Gpu
from engine.render.mirror_passes import give_samples_queries, take_samples_queries
from engine.render.targets import RenderTargets, release_framebuffer
from engine.render.views import View

_END = PassState()  # no depth test, no blending: each pixel of a claim is written once


class EndImages:
    """The previous frame's main image and the pass that fills end views from it."""

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx
        self.program = renderer.shaders.program("fullscreen.vert", "end_image.frag")
        self.program["history"].value = HISTORY_UNIT
        self.program["node_map"].value = NODE_UNIT
        self.vao = self.ctx.vertex_array(self.program, [])
        self.uniforms = renderer.shaders.uniforms  # what the program holds (written where it differs)
        self.history: moderngl.Texture | None = None
        self._history_fbo: moderngl.Framebuffer | None = None
        self.view_proj: glm.mat4 | None = None   # the previous frame's main view-projection
        self.seen: frozenset[int] = frozenset()  # surfaces with a view (or end view) last frame
        # The settle check (keep(compare=True)): its program, a depth-only target of the
        # image's size to run it in (nothing is written), and its query (None: not made yet).
        self._same: tuple[moderngl.VertexArray, moderngl.Query] | None = None
        self._same_target: tuple[moderngl.Renderbuffer, moderngl.Framebuffer] | None = None
        self.compared: moderngl.Query | None = None  # the last keep's count (None: it compared nothing)

    def ready(self, size: tuple[int, int]) -> bool:
        """Whether a previous frame of this size is kept."""
        return self.history is not None and self.history.size == size and self.view_proj is not None

    def draw(self, views: list[View], surfaces: list[int], to_ancestors: list[glm.mat4], targets: RenderTargets,
             root: View) -> None:
        """Fill each end view (its claim already made in ``targets``) from the history:
        ``surfaces[i]`` is the entity ``views[i]`` looks into, ``to_ancestors[i]`` takes its
        exit plane to the eye space of the view that saw that surface last up its chain."""
        ctx, renderer = self.ctx, self.renderer
        targets.view_framebuffer.use()
        apply_pass_state(ctx, _END, (0, 0, *targets.size))
        bind_texture(self.ctx, targets.node, NODE_UNIT)
        bind_texture(self.ctx, self.history, HISTORY_UNIT)
        program = self.program
        uniforms = self.uniforms
        uniforms.write(program, "reproject", (self.view_proj * glm.inverse(root.view)).to_bytes())
        uniforms.set(program, "level_size", targets.size)
        renderer.upload_views(views)  # every view's Camera block in one write; each binds its range
        for at, (view, entity, matrix) in enumerate(zip(views, surfaces, to_ancestors, strict=True)):
            ctx.scissor = view.scissor
            renderer.bind_view_at(at)
            uniforms.set(program, "view_index", view.node)
            uniforms.set(program, "surface", entity)
            uniforms.write(program, "to_ancestor", matrix.to_bytes())
            self.vao.render(moderngl.TRIANGLES, vertices=3)
            renderer.stats.draw_calls += 1
        renderer.stats.passes += 1
        renderer.checkpoint("end images")

    def keep(self, root_targets: RenderTargets, root: View, seen: frozenset[int], compare: bool = False) -> None:
        """This frame's finished main image (after every composite), its view-projection and
        the surfaces that had a view: what the next frame's end views read.  With
        ``compare``, where the image kept is of the same size, camera and surfaces, first
        count the pixels where this one differs from it (``compared``, ``settled``)."""
        size = root_targets.size
        self.compared = None
        if compare and self.compares(root, seen):
            self._compare(root_targets)
        if self.history is None or self.history.size != size:
            self._release_history()
            self.history = self.ctx.texture(size, 4, dtype="f2")
            self.history.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self._history_fbo = self.ctx.framebuffer([self.history])
        self.ctx.copy_framebuffer(self._history_fbo, root_targets.color_framebuffer)  # its one attachment: colour
        self.view_proj = root.view_proj
        self.seen = seen

    def compares(self, root: View, seen: frozenset[int]) -> bool:
        """Whether ``keep(..., compare=True)`` of ``root``'s image showing ``seen`` would
        count its differences: the image kept is of its size, camera and surfaces."""
        return self.ready(root.size) and self.view_proj == root.view_proj and self.seen == seen

    def _compare(self, root_targets: RenderTargets) -> None:
        """The pixels of ``root_targets``' colour that differ from the history, counted in
        the settle query (a full-screen pass into a depth-only target, no depth test)."""
        ctx = self.ctx
        if self._same is None:
            program = self.renderer.shaders.program("fullscreen.vert", "history_same.frag")
            self._same = (ctx.vertex_array(program, []), take_samples_queries(ctx, 1)[0])
        vao, query = self._same
        size = root_targets.size
        if self._same_target is None or self._same_target[0].size != size:
            if self._same_target is not None:
                release_framebuffer(self._same_target[1])
                self._same_target[0].release()
            depth = ctx.depth_renderbuffer(size)
            self._same_target = (depth, ctx.framebuffer(depth_attachment=depth))
        self._same_target[1].use()
        apply_pass_state(ctx, _END, (0, 0, *size))
        bind_texture(ctx, root_targets.color, SETTLE_IMAGE_UNIT)
        bind_texture(ctx, self.history, HISTORY_UNIT)
        program = vao.program
        self.uniforms.set(program, "image", SETTLE_IMAGE_UNIT)
        self.uniforms.set(program, "history", HISTORY_UNIT)
        with query:
            vao.render(moderngl.TRIANGLES, vertices=3)
        self.compared = query
        self.renderer.checkpoint("end images' settle check")

    @staticmethod
    def settled(query: moderngl.Query) -> bool:
        """Whether a compare (``compared``, of an earlier frame: the GPU has drawn it) found
        no pixel that differs."""
        return query.samples == 0

    def forget(self) -> None:
        """No previous frame (a tree without end views this frame): the next starts closed."""
        self.view_proj = None
        self.seen = frozenset()

    def let_go(self) -> None:
        """No frame draws this tree now (``StillTree.let_go``): the history image, which would
        be stale when a frame comes again, is released, and the next frame starts closed."""
        self.forget()
        self._release_history()

    def _release_history(self) -> None:
        if self._history_fbo is not None:
            release_framebuffer(self._history_fbo)
            self.history.release()
        self.history, self._history_fbo = None, None

    def release(self) -> None:
        self._release_history()
        self.vao.release()
        if self._same is not None:
            self._same[0].release()
            give_samples_queries(self.ctx, [self._same[1]])  # (moderngl cannot release a query)
            self._same = None
        if self._same_target is not None:
            release_framebuffer(self._same_target[1])
            self._same_target[0].release()
            self._same_target = None
