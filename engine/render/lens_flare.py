"""Lens flare (``LensFlare``): the bloom's image turned about the picture's middle and its
ghosts along the line through it, drawn at the bloom image's size into a texture of its own
(``shaders/lens_flare.frag``), which the present draw reads with one tap a pixel.

Drawn small because every ghost is three reads of the bloom's image (its red, green and
blue a fringe apart) and the halo three more: read by the present draw at every pixel, four
ghosts and a halo made llvmpipe's 640x360 frame 1.43 x the bloomed frame's; at the bloom
image's size (a quarter of the picture a side on a software rasteriser, half on a GPU) the
same ghosts are a sixteenth (a quarter) of the reads, and the bloom's image holds nothing
finer to lose.  The target is made for the bloom image's size and released when no camera
asks for a flare.
"""
from __future__ import annotations

import moderngl

from components.post import LensFlare
from engine.render.bindings import BLOOM_UNIT, PassState, apply_pass_state, bind_texture
from engine.render.bloom import LEVEL_DTYPE
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import release_target

_FLARE = PassState()   # (no depth, no blending: every texel written)


class LensFlarePass:
    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self.shaders = shaders
        self._vaos: dict[int, moderngl.VertexArray] = {}   # by ghost count (the build's loop)
        self._written: dict[int, tuple] = {}   # each build's uniforms as last written
        self.texture: moderngl.Texture | None = None
        self._framebuffer: moderngl.Framebuffer | None = None

    def draw(self, bloomed: moderngl.Texture, flare: LensFlare) -> moderngl.Texture:
        """``flare``'s ghosts and halo of ``bloomed`` (the bloom chain's sum, bound on
        ``BLOOM_UNIT``), into the flare texture (its size); returned."""
        if self.texture is None or self.texture.size != bloomed.size:
            self.release_targets()
            self.texture = self.ctx.texture(bloomed.size, 4, dtype=LEVEL_DTYPE)
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = False
            self._framebuffer = self.ctx.framebuffer([self.texture])
        vao = self._vaos.get(flare.ghosts)
        if vao is None:
            program = self.shaders.program("present.vert", "lens_flare.frag",
                                           defines={"FLARE_GHOSTS": str(flare.ghosts)})
            program["bloom_image"].value = BLOOM_UNIT
            vao = self._vaos[flare.ghosts] = self.ctx.vertex_array(program, [])
        settings = ((flare.intensity, flare.ghost_spacing, flare.halo, flare.halo_intensity), flare.fringe)
        if self._written.get(flare.ghosts) != settings:   # (a uniform write is a GL call: only on a change)
            vao.program["flare"].value, vao.program["flare_fringe"].value = settings
            self._written[flare.ghosts] = settings
        self._framebuffer.use()
        apply_pass_state(self.ctx, _FLARE, (0, 0, *bloomed.size))
        bind_texture(self.ctx, bloomed, BLOOM_UNIT)
        vao.render(moderngl.TRIANGLES, vertices=3)
        return self.texture

    def target_count(self) -> int:
        return int(self.texture is not None)

    def release_targets(self) -> None:
        if self._framebuffer is not None:   # (its one colour attachment is ``texture``)
            release_target(self._framebuffer)
            self._framebuffer = self.texture = None

    def release(self) -> None:
        self.release_targets()
        for vao in self._vaos.values():
            vao.release()
        self._vaos.clear()
        self._written.clear()
