"""Depth of field for a camera's ``DepthOfField`` (``components/post.py``): the finished HDR
image blurred as a thin lens focused at one distance would blur it, before bloom, exposure and
the tone curve (a bright out-of-focus lamp spreads into a disc first, then glows).

What it knows of each pixel's distance is the length of the light's way to what the pixel
shows, carried up the view tree beside its entity (the main view's seen image:
``shaders/include/way.glsl``), so a reflection is blurred by the distance of its image, not
of the glass, and autofocus on a mirror focuses on what it shows.

Four draws at full size (six at half size, below), none read back (no wait for the GPU):

1. **focus** (``shaders/dof_focus.frag``): the focus distance into a 1x1 texture: the
   component's, or (autofocus) the way at the focus point, followed from last frame's in
   dioptres (``lens_rules.focus_step``; two 1x1 textures written in turn, as exposure's);
2. **prepare** (``shaders/dof_prepare.frag``): each pixel's colour and the signed radius of
   its disc (``lens_rules.blur_radius``);
3. **tiles** (``shaders/dof_tiles.frag``): the largest radius of what lies nearer than the
   focus in each tile of pixels (a tile at least that radius wide), so a pixel knows how far
   a blurred foreground beside it reaches;
4. **gather** (``shaders/dof_gather.frag``): each pixel gathers the discs that cover it
   (scatter as gather, a golden-angle spiral of taps), what lies behind it no wider than its
   own disc, what lies in front laid over it by the share of its light it covers.

At half size (``DepthOfField.half_resolution``, the default, as Unity's and Unreal's run it)
steps 3 and 4 run on a half-size image (**downsample**, ``shaders/dof_downsample.frag``: the
mean colour of four pixels and the nearest one's radius), the gather writing its two layers
apart, and a **compose** (``shaders/dof_compose.frag``) puts each full-size pixel's own sharp
colour behind where its disc is narrow, the half-size layer where it is wide, and lays the
layer in front over it.  The gather takes as many taps as the disc reaching a pixel needs,
about one a square pixel of it (8 to ``SAMPLES``, 48, in its shader); a pixel whose tiles hold
none returns at once.  Measured at 640x360 on llvmpipe (``focus_0`` against ``mirrors_0``,
interleaved; the README's What a frame costs): the half-size path adds about half the frame,
the full-size one about 1.3 times it; 48 taps for every disc, whatever its size, cost the
half-size gather 8 ms where the taps by size cost 3.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import moderngl
import numpy as np

from components.post import DepthOfField
from engine.render.bindings import (
    DOF_BACK_UNIT,
    DOF_FOCUS_UNIT,
    DOF_FRONT_UNIT,
    DOF_PREPARED_UNIT,
    DOF_SEEN_UNIT,
    DOF_TILES_UNIT,
    PRESENT_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
)
from engine.render.post import adapt_blend
from engine.render.shader_library import ShaderLibrary
from engine.render.targets import release_framebuffer
from engine.rules.lens_rules import focal_length, lens_scale, max_blur_radius

MIN_TILE = 8   # pixels a side of the nearer-blur tiles (more when the largest radius is more)
_PASS = PassState()


def tile_size(max_radius: float) -> int:
    """A tile's side in pixels: at least the largest radius, so the 3x3 tiles about a pixel
    hold every disc that can reach it."""
    return max(MIN_TILE, math.ceil(max_radius))


def bokeh_shape(blades: int, rotation: float) -> tuple[float, float, float]:
    """The POLYGON_BOKEH gather's ``bokeh``: the blades, their turn in radians, and the
    polygon's area over its circle's (its light spread over less: each tap brings more)."""
    return float(blades), math.radians(rotation), blades / (2.0 * math.pi) * math.sin(2.0 * math.pi / blades)


def focus_pixel(point: Sequence[float], size: tuple[int, int]) -> tuple[int, int]:
    """The pixel (GL's: row 0 at the bottom) of ``DepthOfField.focus_point`` (shares of the
    width and height from the top-left) in a picture of ``size``."""
    w, h = size
    return min(int(point[0] * w), w - 1), min(int((1.0 - point[1]) * h), h - 1)


class DepthOfFieldPass:
    """The active camera's depth of field: ``draw`` returns the blurred HDR image."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderLibrary) -> None:
        self.ctx = ctx
        self.shaders = shaders
        self._focus = shaders.fullscreen("dof_focus.frag", seen_image=DOF_SEEN_UNIT, previous=DOF_FOCUS_UNIT)
        self._prepare = shaders.fullscreen("dof_prepare.frag", hdr_image=PRESENT_UNIT, seen_image=DOF_SEEN_UNIT,
                                           focus_state=DOF_FOCUS_UNIT)
        self._tiles = shaders.fullscreen("dof_tiles.frag", prepared=DOF_PREPARED_UNIT)
        # The gathers, by (at half size: its two layers apart; a polygon's bokeh), made on first use.
        self._gathers: dict[tuple[bool, bool], moderngl.VertexArray] = {}
        self._half: tuple[moderngl.VertexArray, ...] | None = None   # downsample, compose (first use)
        self._images: dict[str, tuple[moderngl.Texture, moderngl.Framebuffer]] = {}
        self._size: tuple[int, int, int, bool] | None = None   # (width, height, tile, half) the images were made for
        self._state: list[tuple[moderngl.Texture, moderngl.Framebuffer]] = []
        self.current: moderngl.Texture | None = None      # the 1x1 focus written last
        self.camera: int | None = None                     # whose focus it is
        self._written: dict[tuple[int, str], object] = {}  # (vao id, uniform) -> the value last written
        self.passes = 0   # draws in the last frame's depth of field

    def _set(self, vao: moderngl.VertexArray, name: str, value) -> None:
        """Write a uniform only when its value changes (each write is a GL call)."""
        key = (id(vao), name)
        if self._written.get(key) != value:
            vao.program[name].value = value
            self._written[key] = value

    def _image(self, size: tuple[int, int], components: int, dtype: str,
               linear: bool = False) -> tuple[moderngl.Texture, moderngl.Framebuffer]:
        texture = self.ctx.texture(size, components, dtype=dtype)
        texture.filter = (moderngl.LINEAR, moderngl.LINEAR) if linear else (moderngl.NEAREST, moderngl.NEAREST)
        texture.repeat_x = texture.repeat_y = False
        return texture, self.ctx.framebuffer([texture])

    def _half_programs(self) -> tuple[moderngl.VertexArray, ...]:
        if self._half is None:
            fullscreen = self.shaders.fullscreen
            self._half = (fullscreen("dof_downsample.frag", prepared=DOF_PREPARED_UNIT),
                          fullscreen("dof_compose.frag", prepared=DOF_PREPARED_UNIT, back_layer=DOF_BACK_UNIT,
                                     front_layer=DOF_FRONT_UNIT))
        return self._half

    def _gather_program(self, half: bool, blades: int) -> moderngl.VertexArray:
        """The gather for the full or half-size path, of a round or a polygon's bokeh."""
        key = (half, blades > 0)
        vao = self._gathers.get(key)
        if vao is None:
            defines = {**({"SPLIT_LAYERS": "1"} if half else {}), **({"POLYGON_BOKEH": "1"} if blades else {})}
            vao = self._gathers[key] = self.shaders.fullscreen("dof_gather.frag", defines,
                                                               prepared=DOF_PREPARED_UNIT, near_tiles=DOF_TILES_UNIT)
        return vao

    def _make(self, size: tuple[int, int], tile: int, half: bool) -> None:
        if self._size != (*size, tile, half):
            self._release_images()
            w, h = size
            gathered = (-(-w // 2), -(-h // 2)) if half else size
            self._images = {"prepared": self._image(size, 4, "f2"),
                            "tiles": self._image((-(-gathered[0] // tile), -(-gathered[1] // tile)), 1, "f2"),
                            "result": self._image(size, 4, "f2", linear=True)}  # (bloom reads it bilinear)
            if half:
                self._images["half"] = self._image(gathered, 4, "f2")
                back = self.ctx.texture(gathered, 4, dtype="f2")
                front = self.ctx.texture(gathered, 4, dtype="f2")
                for texture in (back, front):   # (the compose reads them bilinear)
                    texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
                    texture.repeat_x = texture.repeat_y = False
                layers = self.ctx.framebuffer([back, front])
                self._images["back"], self._images["front"] = (back, layers), (front, layers)
            self._size = (*size, tile, half)
        if not self._state:
            zero = np.zeros(1, np.float32).tobytes()   # defined (the first frame starts over, whatever it holds)
            self._state = []
            for _ in range(2):
                texture = self.ctx.texture((1, 1), 1, zero, dtype="f4")
                texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
                self._state.append((texture, self.ctx.framebuffer([texture])))

    def draw(self, hdr: moderngl.Texture, seen: moderngl.Texture, settings: DepthOfField, fov_y: float | None,
             camera: int | None, dt: float) -> moderngl.Texture:
        """Blur ``hdr`` (the finished image) by the lens ``settings`` describes, each pixel's
        distance the way in ``seen`` (the same level's seen pair); ``fov_y`` is the camera's
        vertical field of view in degrees (None: orthographic), ``camera`` whose image it is
        (autofocus starts over when it changes) and ``dt`` the frame's time step (autofocus
        follows by it; 0: not at all).  Returns the blurred image (kept until the next draw)."""
        size = hdr.size
        height = size[1]
        f = focal_length(fov_y, settings.focal_length)
        max_radius = max_blur_radius(settings.max_blur, height)
        half = settings.half_resolution
        tile = tile_size(max_radius * 0.5 if half else max_radius)
        self._make(size, tile, half)
        reset = camera != self.camera or self.current is None
        self.camera = camera
        ctx = self.ctx
        bind_texture(ctx, seen, DOF_SEEN_UNIT)
        # 1. The focus: read last frame's 1x1, write the other.
        previous, (state, state_framebuffer) = self._state
        state_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, 1, 1))
        bind_texture(ctx, previous[0], DOF_FOCUS_UNIT)
        manual = not settings.autofocus
        self._set(self._focus, "manual_focus", settings.focus_distance if manual else 0.0)
        self._set(self._focus, "focus_pixel", focus_pixel(settings.focus_point, seen.size))
        self._set(self._focus, "blend", 1.0 if manual or reset else adapt_blend(settings.focus_speed, dt))
        self._focus.render(moderngl.TRIANGLES, vertices=3)
        self._state.reverse()
        self.current = state
        # 2. Each pixel's colour and signed radius.
        prepared, prepared_framebuffer = self._images["prepared"]
        prepared_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, *size))
        bind_texture(ctx, hdr, PRESENT_UNIT)
        bind_texture(ctx, state, DOF_FOCUS_UNIT)
        self._set(self._prepare, "lens", (f, lens_scale(f, settings.f_stop, height), max_radius))
        self._prepare.render(moderngl.TRIANGLES, vertices=3)
        source = prepared
        gather = self._gather_program(half, settings.blades)
        if settings.blades:
            self._set(gather, "bokeh", bokeh_shape(settings.blades, settings.blade_rotation))
        if half:  # (the half-size image the tiles and the gather read)
            downsample, compose = self._half_programs()
            source, half_framebuffer = self._images["half"]
            half_framebuffer.use()
            apply_pass_state(ctx, _PASS, (0, 0, *source.size))
            bind_texture(ctx, prepared, DOF_PREPARED_UNIT)
            downsample.render(moderngl.TRIANGLES, vertices=3)
        # 3. The tiles' nearer reach.
        tiles, tiles_framebuffer = self._images["tiles"]
        tiles_framebuffer.use()
        apply_pass_state(ctx, _PASS, (0, 0, *tiles.size))
        bind_texture(ctx, source, DOF_PREPARED_UNIT)
        self._set(self._tiles, "tile", tile)
        self._tiles.render(moderngl.TRIANGLES, vertices=3)
        # 4. The gather: the picture, or at half size its two layers.
        result, result_framebuffer = self._images["result"]
        (self._images["back"][1] if half else result_framebuffer).use()
        apply_pass_state(ctx, _PASS, (0, 0, *source.size))
        bind_texture(ctx, tiles, DOF_TILES_UNIT)
        self._set(gather, "tile", tile)
        gather.render(moderngl.TRIANGLES, vertices=3)
        if half:  # 5. Each full-size pixel's own colour behind where its disc is narrow, the layers over it.
            result_framebuffer.use()
            apply_pass_state(ctx, _PASS, (0, 0, *size))
            bind_texture(ctx, prepared, DOF_PREPARED_UNIT)
            bind_texture(ctx, self._images["back"][0], DOF_BACK_UNIT)
            bind_texture(ctx, self._images["front"][0], DOF_FRONT_UNIT)
            compose.render(moderngl.TRIANGLES, vertices=3)
        self.passes = 6 if half else 4
        return result

    def focused(self) -> float | None:
        """The focus distance last written, in metres (read back: waits for the GPU; tests and
        the overlay only), or None before the first frame."""
        if self.current is None:
            return None
        return float(np.frombuffer(self.current.read(), np.float32)[0])

    def prepared_radii(self) -> np.ndarray | None:
        """Each pixel's signed blur radius from the last draw, float32 (height, width), row 0
        at the top (read back: tests only)."""
        image = self._images.get("prepared")
        if image is None:
            return None
        texture = image[0]
        w, h = texture.size
        data = np.frombuffer(texture.read(), np.float16).reshape(h, w, 4)
        return np.flipud(data[..., 3]).astype(np.float32)

    def _release_images(self) -> None:
        framebuffers = {id(framebuffer): framebuffer for _, framebuffer in self._images.values()}
        for framebuffer in framebuffers.values():   # (the two layers share one)
            release_framebuffer(framebuffer)
        for texture, _ in self._images.values():
            texture.release()
        self._images, self._size = {}, None

    def release_targets(self) -> None:
        """Let go of the images and the focus (the camera has no DepthOfField now)."""
        self._release_images()
        for texture, framebuffer in self._state:
            release_framebuffer(framebuffer)
            texture.release()
        self._state = []
        self.current, self.camera = None, None

    def target_count(self) -> int:
        return len(self._images) + len(self._state)

    def release(self) -> None:
        self.release_targets()
        for vao in (self._focus, self._prepare, self._tiles, *self._gathers.values(), *(self._half or ())):
            vao.release()
        self._gathers.clear()
        self._half = None
