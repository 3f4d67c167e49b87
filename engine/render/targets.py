"""Render targets of the main view: linear HDR colour, entity ids, depth."""
from __future__ import annotations

import moderngl
import numpy as np


def release_framebuffer(framebuffer: moderngl.Framebuffer) -> None:
    """Release a framebuffer, first binding framebuffer 0 if it is the bound one: moderngl
    re-binds its remembered framebuffer after creating another, and binding a deleted
    name is GL_INVALID_OPERATION."""
    ctx = framebuffer.ctx
    if ctx.fbo is framebuffer:
        ctx.detect_framebuffer(0).use()
    framebuffer.release()


class RenderTargets:
    """HDR colour (RGBA16F), entity id (R32UI) and depth of one size."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.size = size
        self.color = ctx.texture(size, 4, dtype="f2")
        self.color.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.ids = ctx.texture(size, 1, dtype="u4")
        self.ids.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_texture(size)
        self.framebuffer = ctx.framebuffer([self.color, self.ids], self.depth)

    def read_ids(self) -> np.ndarray:
        """Entity ids as uint32 (height, width), row 0 at the top like the PNG."""
        w, h = self.size
        data = np.frombuffer(self.framebuffer.read(attachment=1, components=1, dtype="u4"), np.uint32)
        return np.flipud(data.reshape(h, w)).copy()

    def release(self) -> None:
        release_framebuffer(self.framebuffer)
        for texture in (self.color, self.ids, self.depth):
            texture.release()


class CaptureTarget:
    """An RGBA8 target the present pass writes to when there is no window (headless runs)."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        self.size = size
        self.texture = ctx.texture(size, 4)
        self.framebuffer = ctx.framebuffer([self.texture])

    def read_rgb(self) -> np.ndarray:
        """sRGB uint8 (height, width, 3), row 0 at the top."""
        w, h = self.size
        data = np.frombuffer(self.framebuffer.read(components=3), np.uint8).reshape(h, w, 3)
        return np.flipud(data).copy()

    def release(self) -> None:
        release_framebuffer(self.framebuffer)
        self.texture.release()
