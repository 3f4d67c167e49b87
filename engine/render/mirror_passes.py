"""The per-pixel passes of planar reflections: visibility query, level mask, composite.

All three are a full-screen triangle limited by a scissor rectangle; they read the uint
images of a level (which view drew a pixel, which entity's surface is there).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import moderngl
import numpy as np
from pyglm import glm

from engine.render.renderer import CAMERA_BINDING, SKY_UNIT, Renderer
from engine.render.targets import RenderTargets, release_framebuffer

MAX_LEVEL_VIEWS = 32
_SELECT_UNITS = (3, 4)
_REFLECTION_UNITS = (3, 4, 5)


@dataclass
class CompositeParams:
    view_index: int
    tint: glm.vec4
    reflect_rate: float
    roughness: float
    normal: glm.vec3
    portal: bool = False                                       # a plain window: no Fresnel, no tint
    carry: glm.mat3 = field(default_factory=lambda: glm.mat3(1.0))  # turns directions into the view's world


def _shared_samples_queries(ctx: moderngl.Context, count: int) -> list[moderngl.Query]:
    """At least ``count`` samples-passed queries, shared by every engine on the context:
    moderngl 5.13 cannot release a Query, so engines made and closed on one context (tests,
    editors) reuse one pool instead of leaking (it grows to the most candidates a level had)."""
    if not isinstance(ctx.extra, dict):
        ctx.extra = {}
    pool = ctx.extra.setdefault("speculum.samples_queries", [])
    while len(pool) < count:
        pool.append(ctx.query(samples=True))
    return pool


class MirrorPasses:
    def __init__(self, renderer: Renderer) -> None:
        self.renderer = renderer
        ctx = renderer.ctx
        self.ctx = ctx
        shaders = renderer.shaders
        self.select = shaders.program("fullscreen.vert", "mirror_select.frag")
        self.mask = shaders.program("fullscreen.vert", "mirror_mask.frag")
        self.composite = shaders.program("fullscreen.vert", "mirror_composite.frag")
        self.select["parent_node_map"].value, self.select["parent_surface_map"].value = _SELECT_UNITS
        self.mask["parent_node_map"].value, self.mask["parent_surface_map"].value = _SELECT_UNITS
        self.composite["Camera"].binding = CAMERA_BINDING
        units = dict(zip(("reflection", "reflection_seen", "reflection_nodes"), _REFLECTION_UNITS, strict=True))
        for name, unit in units.items():
            self.composite[name].value = unit
        self.composite["sky_map"].value = SKY_UNIT
        self._select_vao = ctx.vertex_array(self.select, [])
        self._mask_vao = ctx.vertex_array(self.mask, [])
        self._composite_vao = ctx.vertex_array(self.composite, [])
        self._query_target: moderngl.Framebuffer | None = None

    def visible_pixels(self, parent: RenderTargets,
                       candidates: list[tuple[int, int, tuple[int, int, int, int]]]) -> list[int]:
        """For each (parent view, surface entity, rect): the pixels inside rect where that
        view of ``parent`` shows that surface.  All queries are issued before any result is
        read, so the CPU waits for the GPU once per level, not once per candidate."""
        if not candidates:
            return []
        ctx = self.ctx
        if self._query_target is None or self._query_target.size != parent.size:
            if self._query_target is not None:
                release_framebuffer(self._query_target)
            self._query_target = ctx.empty_framebuffer(parent.size)  # fragments, no writes
        self._query_target.use()
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        ctx.viewport = (0, 0, *parent.size)
        parent.node.use(_SELECT_UNITS[0])
        parent.surface.use(_SELECT_UNITS[1])
        queries = _shared_samples_queries(ctx, len(candidates))
        for query, (parent_node, surface, rect) in zip(queries, candidates, strict=False):
            ctx.scissor = rect
            self.select["parent_node"].value = parent_node
            self.select["mirror_id"].value = surface
            with query:
                self._select_vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.scissor = None
        return [query.samples for query in queries[: len(candidates)]]

    def prepare_level(self, level: RenderTargets, parent: RenderTargets,
                      views: list[tuple[int, int, int]], rects: list[tuple[int, int, int, int]]) -> None:
        """Write ``level``'s node image and depth mask for views (parent view, mirror, index)
        inside each view's rectangle (nothing outside them is read or drawn this frame)."""
        if len(views) > MAX_LEVEL_VIEWS:
            raise ValueError(f"{len(views)} mirror views in one level; at most {MAX_LEVEL_VIEWS}")
        ctx = self.ctx
        level.framebuffer.use()
        ctx.viewport = (0, 0, *level.size)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        ctx.depth_func = "1"  # always: the mask pass writes every pixel's depth
        parent.node.use(_SELECT_UNITS[0])
        parent.surface.use(_SELECT_UNITS[1])
        table = np.zeros((MAX_LEVEL_VIEWS, 4), np.uint32)
        table[: len(views), :3] = views
        self.mask["views"].write(table.tobytes())
        self.mask["to_parent"].value = (parent.size[0] / level.size[0], parent.size[1] / level.size[1])
        self.mask["view_count"].value = len(views)
        for rect in rects:
            ctx.scissor = rect
            self._mask_vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.depth_func = "<"
        ctx.scissor = None

    def composite_view(self, parent: RenderTargets, level: RenderTargets, params: CompositeParams,
                       rect: tuple[int, int, int, int]) -> None:
        """Blend view ``params.view_index`` of ``level`` into the mirror's pixels of ``parent``.

        The Camera block must hold the parent view (``Renderer.bind_view``).
        """
        ctx = self.ctx
        parent.composite_framebuffer.use()
        ctx.viewport = (0, 0, *parent.size)
        ctx.scissor = rect
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.enable(moderngl.BLEND)
        # Colour: reflection x rate + own x (1 - rate); alpha (coverage) is kept.
        ctx.blend_func = (moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA, moderngl.ZERO, moderngl.ONE)
        for texture, unit in zip((level.color, level.seen, level.node), _REFLECTION_UNITS, strict=True):
            texture.use(unit)
        self.renderer.sky.use(SKY_UNIT)
        program = self.composite
        program["view_index"].value = params.view_index
        program["to_reflection"].value = (level.size[0] / parent.size[0], level.size[1] / parent.size[1])
        program["tint"].value = tuple(params.tint)
        program["reflect_rate"].value = params.reflect_rate
        program["roughness"].value = params.roughness
        program["mirror_normal"].value = tuple(params.normal)
        program["is_portal"].value = params.portal
        program["carry"].write(params.carry.to_bytes())
        self._composite_vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.disable(moderngl.BLEND)
        ctx.blend_func = moderngl.DEFAULT_BLENDING
        ctx.scissor = None

    def release(self) -> None:
        for obj in (self._select_vao, self._mask_vao, self._composite_vao):
            obj.release()
        if self._query_target is not None:
            release_framebuffer(self._query_target)
