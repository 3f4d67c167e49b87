"""The Fog uniform block (``shaders/include/fog.glsl``): the active camera's ``Fog``
(``components/fog.py``), written when it changes, bound for every pass that fogs (scene
passes, the sky, the composites).

The scene, sky and composite programs fog only in their ``FOG`` builds (``defines``: while
the fog has a density; ``FOG_FALLOFF`` and ``FOG_GLOW`` add the height falloff's and the sun
glow's terms where it has them), so a frame without fog runs none of it: llvmpipe runs the fog's
exponentials for every pixel a program draws (read on every sky pixel, they made the
640x360 mirror ring's frame 1.03x dearer with no fog at all).
"""
from __future__ import annotations

import moderngl
import numpy as np

from components import DirectionalLight
from components.fog import Fog
from components.tracking import raw_field
from engine.render.bindings import FOG_BINDING, bind_uniform_block

FOG_BLOCK_BYTES = 64   # four vec4s: colour and sky share; density, falloff, base height; the sun's
                       # direction (towards it); its light x the sun scatter
_NO_FOG = (0.0,) * 16


class FogBlock:
    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._values = _NO_FOG
        self.ubo = ctx.buffer(np.zeros(FOG_BLOCK_BYTES // 4, np.float32).tobytes())
        self.ubo.bind_to_uniform_block(FOG_BINDING)   # (no other block uses the point: it stays)
        self.defines: tuple[tuple[str, str], ...] = ()

    def set(self, fog: Fog | None, sun: DirectionalLight | None = None) -> bool:
        """Write ``fog`` (None: no fog), glowing towards ``sun`` (the brightest directional
        light: ``light_rules.brightest_directional``) by its ``sun_scatter``, into the block
        where it differs from what it holds; True when it did (every view's fogged pixels
        change).  Compared as plain floats: the prepare stage asks every frame."""
        if fog is None or fog.density <= 0.0:
            values = _NO_FOG
        else:
            glow = (0.0,) * 8
            if sun is not None and fog.sun_scatter > 0.0:
                color = raw_field(sun, "color")
                k = sun.intensity * fog.sun_scatter
                glow = (-sun.direction.x, -sun.direction.y, -sun.direction.z, 0.0,
                        color.x * k, color.y * k, color.z * k, 0.0)
            values = (fog.color.x, fog.color.y, fog.color.z, fog.sky_affect, fog.density, fog.height_falloff,
                      fog.height, 0.0, *glow)
        if values == self._values:
            return False
        self._values = values
        self.ubo.write(np.array(values, np.float32).tobytes())
        self.defines = () if values[4] <= 0.0 else tuple((name, "1") for name, on in (
            ("FOG", True), ("FOG_FALLOFF", values[5] > 0.0), ("FOG_GLOW", any(values[12:15]))) if on)
        return True

    @property
    def block(self) -> tuple[float, ...]:
        """What the block holds (what a probe face drawn through it is kept for)."""
        return self._values

    def bind(self) -> None:
        bind_uniform_block(self.ctx, self.ubo, FOG_BINDING)

    def release(self) -> None:
        self.ubo.release()
