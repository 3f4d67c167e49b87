"""The present pass: the main view's finished HDR image (reflections composited in), times
exposure, encoded to sRGB into the output; with anti-aliasing on, encoded into an RGBA8
image (luma in alpha) that an FXAA pass (``shaders/fxaa.frag``) filters into the output.

FXAA runs once on the final colour: ids are never touched, and mirror and portal images,
already composited, get no seam at their edges.  Its walk along an edge (long nearly level
edges become ramps) is ``search_steps`` long: 8 on a GPU; 0 on a software rasteriser,
where each step costs ~4% of a mirrorless frame (every fetch is CPU time there), so it
blends only the pixels that stand out at an edge (the stair steps).
"""
from __future__ import annotations

import moderngl

from engine.render.bindings import PRESENT_UNIT, PassState, apply_pass_state
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import CaptureTarget

ANTIALIAS_MODES = ("fxaa", "off")
MAX_SEARCH_STEPS = 8   # the length of fxaa.frag's SEARCH table
GPU_SEARCH_STEPS = 8
_PRESENT = PassState()


class PresentPass:
    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary, software: bool) -> None:
        self.ctx = ctx
        self.shaders = shaders
        self._encode = self._fullscreen("present.frag")
        self._encode_luma = self._fullscreen("present.frag", LUMA_IN_ALPHA="1")
        for encode in (self._encode, self._encode_luma):
            encode.program["hdr_image"].value = PRESENT_UNIT
        self._fxaa: moderngl.VertexArray | None = None
        self._encoded: CaptureTarget | None = None   # what FXAA reads, made at the output's size
        self.search_steps = 0 if software else GPU_SEARCH_STEPS

    @property
    def search_steps(self) -> int:
        """How far FXAA walks along an edge (0: no walk, only the small-feature blend)."""
        return self._search_steps

    @search_steps.setter
    def search_steps(self, steps: int) -> None:
        if not isinstance(steps, int) or not 0 <= steps <= MAX_SEARCH_STEPS:
            raise ValueError(f"FXAA search_steps must be an int from 0 to {MAX_SEARCH_STEPS}, got {steps!r}")
        if self._fxaa is not None:
            self._fxaa.release()
        self._fxaa = self._fullscreen("fxaa.frag", SEARCH_STEPS=str(steps))
        self._fxaa.program["frame"].value = PRESENT_UNIT
        self._search_steps = steps

    def _fullscreen(self, fragment: str, **defines: str) -> moderngl.VertexArray:
        program = self.shaders.program("present.vert", fragment, defines=defines or None)
        return self.ctx.vertex_array(program, [])

    def draw(self, hdr: moderngl.Texture, exposure: float, antialias: str, output: moderngl.Framebuffer,
             size: tuple[int, int]) -> None:
        fxaa = antialias == "fxaa"
        if fxaa and (self._encoded is None or self._encoded.size != size):
            if self._encoded is not None:
                self._encoded.release()
            self._encoded = CaptureTarget(self.ctx, size)
        encode = self._encode_luma if fxaa else self._encode
        (self._encoded.framebuffer if fxaa else output).use()
        apply_pass_state(self.ctx, _PRESENT, (0, 0, *size))
        hdr.use(PRESENT_UNIT)
        encode.program["exposure"].value = exposure
        encode.render(moderngl.TRIANGLES, vertices=3)
        if fxaa:
            output.use()
            # Its own pass: a framebuffer's use() brings back the viewport last set while
            # moderngl took it for bound, which raw-GL passes may have left at any size.
            apply_pass_state(self.ctx, _PRESENT, (0, 0, *size))
            self._encoded.texture.use(PRESENT_UNIT)
            self._fxaa.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        if self._encoded is not None:
            self._encoded.release()
            self._encoded = None
        for vao in (self._encode, self._encode_luma, self._fxaa):
            vao.release()
