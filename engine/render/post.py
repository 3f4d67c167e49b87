"""Automatic exposure on the GPU, for a camera's ``Tonemap(auto_exposure=True)``.

Each frame, with no read back to the CPU and so no wait for the GPU:

1. the HDR image's log2 luminance into a 64x64 texture (``shaders/exposure_luminance.frag``:
   four taps a texel, each clamped to the range the exposure limits can correct);
2. the adapted exposure, a 1x1 texture (``shaders/exposure_adapt.frag``): the 64x64
   texture's mean (an exact mean, its own 32x32 bilinear taps at texel corners, not a
   driver's ``glGenerateMipmap`` filter, which the GL spec leaves to the driver) gives the
   target ``log2(key) - mean log2 L`` EV, clamped to ``[min_ev, max_ev]``, and last
   frame's value moves ``1 - exp(-adapt_speed dt)`` of the way to it (two 1x1 textures,
   written in turn, so a pass never reads what it writes).

Two draws: an earlier form reduced 64 -> 16 -> 4 in draws of their own, two more passes
(0.1 ms of the four's 0.4 at 640x360 on llvmpipe, where each pass is a flush and a wait);
the one texel's loop of 1024 taps costs less than either.

The present shader reads the new 1x1 value (``exposure_state``) as 2^EV.  A camera's first
frame (or the first after the active camera changes) starts at its target.  ``adapted_ev``
reads the value back, for tests and the debug overlay (it waits for the GPU: never in a
frame).
"""
from __future__ import annotations

import math

import moderngl
import numpy as np

from components.post import Tonemap
from engine.render.bindings import (
    EXPOSURE_MEAN_UNIT,
    EXPOSURE_UNIT,
    PRESENT_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import release_framebuffer

LUMINANCE_SIDE = 64   # shaders/exposure_adapt.frag SIDE
_PASS = PassState()


def adapt_blend(adapt_speed: float, dt: float) -> float:
    """The share of the way to its target the exposure moves in a frame of ``dt`` seconds."""
    return 1.0 - math.exp(-adapt_speed * max(dt, 0.0))


class AutoExposure:
    """The log-luminance chain and the adapted exposure of the active camera."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self.shaders = shaders
        self._luminance = shaders.fullscreen("exposure_luminance.frag", hdr_image=PRESENT_UNIT)
        self._adapt = shaders.fullscreen("exposure_adapt.frag", mean_source=EXPOSURE_MEAN_UNIT, previous=EXPOSURE_UNIT)
        self._targets: list[tuple[moderngl.Texture, moderngl.Framebuffer]] = []
        self._state: list[tuple[moderngl.Texture, moderngl.Framebuffer]] = []
        self.current: moderngl.Texture | None = None   # the 1x1 exposure written last
        self.camera: int | None = None                  # whose exposure it is
        self._luminance.program["target_texel"].value = (1.0 / LUMINANCE_SIDE, 1.0 / LUMINANCE_SIDE)
        self._written: dict[tuple[int, str], object] = {}   # (vao id, uniform) -> the value last written

    def _set(self, vao: moderngl.VertexArray, name: str, value) -> None:
        """Write a uniform only when its value changes (each write is a GL call)."""
        key = (id(vao), name)
        if self._written.get(key) != value:
            vao.program[name].value = value
            self._written[key] = value

    def _target(self, side: int, data: bytes | None = None) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        texture = self.ctx.texture((side, side), 1, data, dtype="f4")
        # The luminance texture is read by bilinear taps at texel corners (exact 2x2 means).
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR) if side == LUMINANCE_SIDE else (moderngl.NEAREST,
                                                                                            moderngl.NEAREST)
        texture.repeat_x = texture.repeat_y = False
        return texture, self.ctx.framebuffer([texture])

    def _make(self) -> None:
        if self._targets:
            return
        self._targets = [self._target(LUMINANCE_SIDE)]
        zero = np.zeros(1, np.float32).tobytes()   # a defined start (the adapt pass ignores it on a reset)
        self._state = [self._target(1, zero), self._target(1, zero)]

    def draw(self, hdr: moderngl.Texture, tonemap: Tonemap, camera: int | None, dt: float) -> moderngl.Texture:
        """Measure ``hdr`` and adapt; returns the 1x1 texture the present shader reads."""
        self._make()
        reset = camera != self.camera or self.current is None
        self.camera = camera
        key_log2 = math.log2(tonemap.key)
        ctx = self.ctx
        # 1. log2 luminance, clamped to what min_ev..max_ev can bring to the key.
        texture, framebuffer = self._targets[0]
        framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, LUMINANCE_SIDE, LUMINANCE_SIDE))
        bind_texture(self.ctx, hdr, PRESENT_UNIT)
        self._set(self._luminance, "log_range", (key_log2 - tonemap.max_ev, key_log2 - tonemap.min_ev))
        self._luminance.render(moderngl.TRIANGLES, vertices=3)
        # 2. its mean, and adapt: read last frame's 1x1, write the other.
        previous, (state, state_fbo) = self._state
        state_fbo.use()
        apply_pass_state(ctx, _PASS, (0, 0, 1, 1))
        bind_texture(self.ctx, texture, EXPOSURE_MEAN_UNIT)
        bind_texture(self.ctx, previous[0], EXPOSURE_UNIT)
        self._set(self._adapt, "key_log2", key_log2)
        self._set(self._adapt, "ev_range", (tonemap.min_ev, tonemap.max_ev))
        self._set(self._adapt, "blend", 1.0 if reset else adapt_blend(tonemap.adapt_speed, dt))
        self._adapt.render(moderngl.TRIANGLES, vertices=3)
        self._state.reverse()
        self.current = state
        return state

    def passes(self) -> int:
        return 2

    def adapted_ev(self) -> float | None:
        """The exposure last written, in EV (read back: waits for the GPU; tests and the
        overlay only), or None before the first frame."""
        if self.current is None:
            return None
        return float(np.frombuffer(self.current.read(), np.float32)[0])

    def release_targets(self) -> None:
        for texture, framebuffer in (*self._targets, *self._state):
            release_framebuffer(framebuffer)
            texture.release()
        self._targets, self._state = [], []
        self.current, self.camera = None, None

    def release(self) -> None:
        self.release_targets()
        for vao in (self._luminance, self._adapt):
            vao.release()
