"""The per-pixel passes of planar reflections: preparing a level (reset, then claims with
their visibility queries) and the composite.

Each is a full-screen triangle limited by a scissor rectangle; they read the uint images
of a level (which view drew a pixel, which entity's surface is there).  The claim does the
work of a visibility query and a mask at once: its samples-passed count is the number of
pixels a candidate view owns.  (A mask pass that found each pixel's owner by looping over
a table of the level's views cost ~100 ns a pixel on llvmpipe, the loop's uniform-array
reads; a claim per view costs a few ns a pixel.)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import moderngl
from pyglm import glm

from engine.render.renderer import CAMERA_BINDING, SKY_UNIT, Renderer
from engine.render.targets import RenderTargets

MAX_LEVEL_VIEWS = 32
_PARENT_UNITS = (3, 4)
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


@dataclass(frozen=True)
class Claim:
    """A candidate view of a reflection level: ``surface`` seen from view ``parent`` of the
    level above, drawn as view ``index`` inside ``rect`` (this level's pixels)."""

    parent: int
    surface: int
    index: int
    rect: tuple[int, int, int, int]


class MirrorPasses:
    def __init__(self, renderer: Renderer) -> None:
        self.renderer = renderer
        ctx = renderer.ctx
        self.ctx = ctx
        shaders = renderer.shaders
        self.reset = shaders.program("fullscreen.vert", "mirror_reset.frag")
        self.claim = shaders.program("fullscreen.vert", "mirror_claim.frag")
        self.composite = shaders.program("fullscreen.vert", "mirror_composite.frag")
        self.claim["parent_node_map"].value, self.claim["parent_surface_map"].value = _PARENT_UNITS
        self.composite["Camera"].binding = CAMERA_BINDING
        units = dict(zip(("reflection", "reflection_seen", "reflection_nodes"), _REFLECTION_UNITS, strict=True))
        for name, unit in units.items():
            self.composite[name].value = unit
        self.composite["sky_map"].value = SKY_UNIT
        self._reset_vao = ctx.vertex_array(self.reset, [])
        self._claim_vao = ctx.vertex_array(self.claim, [])
        self._composite_vao = ctx.vertex_array(self.composite, [])

    def prepare_level(self, level: RenderTargets, parent: RenderTargets, claims: list[Claim]) -> list[int]:
        """Write ``level``'s node image and depth mask for the candidate views ``claims`` and
        return, for each, how many pixels it got (0: the surface is hidden there, or off the
        pixels its parent view drew).  Outside the claims' rectangles nothing is written or
        read this frame.  The queries are all issued before any result is read, so the CPU
        waits for the GPU once per level."""
        if not claims:
            return []
        ctx = self.ctx
        level.framebuffer.use()
        ctx.viewport = (0, 0, *level.size)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        ctx.depth_func = "1"  # always: both passes set every depth they touch
        for rect in dict.fromkeys(claim.rect for claim in claims):
            ctx.scissor = rect
            self._reset_vao.render(moderngl.TRIANGLES, vertices=3)
        parent.node.use(_PARENT_UNITS[0])
        parent.surface.use(_PARENT_UNITS[1])
        program = self.claim
        program["to_parent"].value = (parent.size[0] / level.size[0], parent.size[1] / level.size[1])
        queries = _shared_samples_queries(ctx, len(claims))
        for query, claim in zip(queries, claims, strict=False):
            ctx.scissor = claim.rect
            program["parent_node"].value = claim.parent
            program["surface_id"].value = claim.surface
            program["view_index"].value = claim.index
            with query:
                self._claim_vao.render(moderngl.TRIANGLES, vertices=3)
        ctx.depth_func = "<"
        ctx.scissor = None
        return [query.samples for query in queries[: len(claims)]]

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
        for obj in (self._reset_vao, self._claim_vao, self._composite_vao):
            obj.release()
