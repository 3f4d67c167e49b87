"""Render scale and sharpening: the main view drawn at fewer (or more) pixels than the
output, and the picture brought to the output's size at the end (``Renderer.render_scale``,
``Renderer.sharpness``).

A GPU host whose frame is bound by its pixels (shading, the reflection levels, the
post-processing, all sized from the main view) draws ``render_scale`` squared of them: the
main view tree's levels are ``render_size(output, scale)``, and so is every image the
present pass makes before its last pass.  The picture is brought to the output's size one of
two ways, as Unreal's screen percentage and Godot's 3D scaling do:

- with temporal AA (``engine/render/temporal_aa.py``): by the resolve itself (temporal
  upsampling: each frame's jittered samples land in different output pixels, and the
  history, kept at the output's size, gathers them), and the passes after it (depth of
  field, motion blur, bloom, the encoding) run at the output's size;
- otherwise by this module's last pass (``shaders/resample.frag``): the encoded picture,
  after FXAA, read through a Catmull-Rom spline (spatial upscaling).

Above 1 it is supersampling (SSAA, Unreal's screen percentage over 100, Unity's render scale
over 1, Godot's 3D scaling over 1): every level and image that many times larger, up to
``MAX_RENDER_SCALE`` (4 x the pixels at 2), and the picture brought down by this module's last
pass as an area box filter in linear light (each output pixel the mean of the light under
it), after FXAA or temporal AA, which then run at the drawn size: the reference anti-aliasing
for still images, geometry, mirror and portal edges and shading alike, at 4 x the pixels'
cost.

Sharpening (contrast-adaptive, the same last pass) runs on the output's pixels whenever
``sharpness`` is above 0, at any scale: it gives back some of what an upscale or temporal
AA's resampling softens.  At scale 1 with no sharpening no pass is added.
"""
from __future__ import annotations

import math

import moderngl
import numpy as np

from engine.core.budget import MIN_RENDER_SCALE_RANGE
from engine.render.bindings import FXAA_UNIT, PassState, apply_pass_state, bind_texture
from engine.render.shader_library import ShaderLibrary

# Below a quarter the picture is too coarse to bring back (the core's floor, which dynamic
# resolution's shares); above 2 a supersampled frame's box would take more than 3 x 3 texels a
# pixel, and its levels 4 x the memory already.
MAX_RENDER_SCALE = 2.0
RENDER_SCALE_RANGE = (MIN_RENDER_SCALE_RANGE[0], MAX_RENDER_SCALE)
_PASS = PassState()


def check_render_scale(value: float) -> float:
    """``value`` as a render scale, or a ValueError naming why not."""
    lo, hi = RENDER_SCALE_RANGE
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or not lo <= value <= hi:
        raise ValueError(f"Renderer.render_scale must be a number in [{lo:g}, {hi:g}] (the share of the output's "
                         f"width and height the main view is drawn at), got {value!r}")
    return float(value)


def check_sharpness(value: float) -> float:
    """``value`` as a sharpness, or a ValueError naming why not."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not math.isfinite(value) or not 0.0 <= value <= 1.0:
        raise ValueError(f"Renderer.sharpness must be a number in [0, 1] (0: no sharpening), got {value!r}")
    return float(value)


def render_size(size: tuple[int, int], scale: float) -> tuple[int, int]:
    """The main view's size for an output of ``size`` at render scale ``scale``: each side
    rounded, at least 1."""
    if scale == 1.0:
        return size
    return max(1, round(size[0] * scale)), max(1, round(size[1] * scale))


class ResamplePass:
    """The last pass: ``draw`` resamples an encoded picture into the output."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self._shaders = shaders
        self._builds: dict[tuple[str, bool], moderngl.VertexArray] = {}   # by (scaling, sharpen)

    def _build(self, scaling: str, sharpen: bool) -> moderngl.VertexArray:
        key = (scaling, sharpen)
        vao = self._builds.get(key)
        if vao is None:
            defines = {name: "1" for name, on in (("UPSCALE", scaling == "up"), ("DOWNSCALE", scaling == "down"),
                                                  ("SHARPEN", sharpen)) if on}
            vao = self._builds[key] = self._shaders.fullscreen("resample.frag", defines, frame=FXAA_UNIT)
        return vao

    def draw(self, picture: moderngl.Texture, output: moderngl.Framebuffer, size: tuple[int, int],
             sharpness: float) -> None:
        """``picture`` (encoded, linear-filtered) into ``output`` at ``size``: upscaled where it is
        smaller, box-filtered down where it is larger, sharpened by ``sharpness`` (0: not)."""
        scaling = "same" if picture.size == size else \
            "down" if picture.size[0] >= size[0] and picture.size[1] >= size[1] else "up"
        vao = self._build(scaling, sharpness > 0.0)
        program = vao.program
        if "output_size" in program:
            program["output_size"].value = (float(size[0]), float(size[1]))
        if "sharpness" in program:
            program["sharpness"].value = sharpness
        output.use()
        apply_pass_state(self.ctx, _PASS, (0, 0, *size))
        bind_texture(self.ctx, picture, FXAA_UNIT)
        vao.render(moderngl.TRIANGLES, vertices=3)

    def release(self) -> None:
        for vao in self._builds.values():
            vao.release()
        self._builds.clear()
