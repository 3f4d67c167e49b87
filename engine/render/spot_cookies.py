"""Spot light cookies (``PointLight.cookie``): the images the kept spot lights project, one
layer each of a texture array the scene shader reads (``shaders/include/spot_cookie.glsl``).

Each image is drawn from a ``COOKIE_SIZE`` square copy, made once when a kept light first
brings it: decoded from sRGB to linear light on the CPU and resampled there (Lanczos, in
linear light, so a gobo's edge keeps its brightness), stored as half floats with a mip chain
(a cookie thrown on a far wall is minified as any texture is; moderngl 5.13 makes no sRGB
texture array, and eight linear bits would band its dark gradients).  A non-square image is
stretched to the square.  The array holds a layer for each distinct image among the kept
lights (at most ``MAX_POINT_LIGHTS``), grows by doubling when more come and is released when
none is left, so a level without cookies holds nothing and its programs have no
``SPOT_COOKIES`` build (``defines``).  A rectangle light's cookie is the picture on its face
(``shaders/include/rect_lights.glsl`` ``rect_face``), a layer of the same array read by the
``PANEL_PICTURES`` builds: a level whose only cookies are panels' pictures pays for no
projection (on llvmpipe, which runs a branch's body for every pixel, the projection's
lookups cost a frame lit by a pictured panel a third more).

The array is one sampler more for the scene programs: their fullest build already reads 16,
GL 4.1's least ``GL_MAX_TEXTURE_IMAGE_UNITS`` (macOS's).  On a context with no more than 16,
cookies are left out (``supported`` False): the lights shine without them and a
``GLLimitWarning`` says so once.
"""
from __future__ import annotations

import warnings

import moderngl
import numpy as np

from engine.assets.texture_data import TextureData, pillow_image_module
from engine.core.color import srgb_to_linear
from engine.core.errors import GLLimitWarning
from engine.render.bindings import COOKIE_UNIT, bind_texture
from engine.render.views import MAX_POINT_LIGHTS

COOKIE_SIZE = 512   # texels a side of each cookie's copy
SCENE_SAMPLERS = 16  # the scene programs' fullest build without cookies (engine/render/bindings.py)
_SRGB_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)   # an 8-bit code's linear value


def cookie_texels(texture: TextureData, size: int = COOKIE_SIZE) -> np.ndarray:
    """``texture``'s colour as the cookie array holds it: (size, size, 3) float32 linear light,
    resampled in linear light (Lanczos), row 0 at the bottom (GL's)."""
    Image = pillow_image_module()
    linear = _SRGB_TO_LINEAR[texture.as_8_bits()[..., :3]]
    channels = []
    for c in range(3):
        image = Image.fromarray(np.ascontiguousarray(linear[..., c]), mode="F")
        channels.append(np.asarray(image.resize((size, size), Image.Resampling.LANCZOS), np.float32))
    return np.clip(np.stack(channels, axis=-1), 0.0, 1.0)[::-1]


class SpotCookies:
    """The cookie array and which image is in which layer.  Images are known by ``id``; each
    one with a layer is held (``_images``) so no other image can take its id meanwhile."""

    def __init__(self, ctx: moderngl.Context, texture_units: int, anisotropy: float = 1.0,
                 software: bool = False) -> None:
        self.ctx = ctx
        # Trilinear on a GPU; on a software rasteriser the nearer mip level, filtered
        # bilinearly (it reads the image for every pixel a SPOT_COOKIES build shades: the
        # gobo example's frame at 640x360 cost 1.27x one without cookies trilinear, 1.17x so).
        self.filter = (moderngl.LINEAR_MIPMAP_NEAREST if software else moderngl.LINEAR_MIPMAP_LINEAR,
                       moderngl.LINEAR)
        self.supported = texture_units > SCENE_SAMPLERS
        self.texture_units = texture_units
        self.anisotropy = anisotropy
        self.array: moderngl.TextureArray | None = None
        self._layers: dict[int, int] = {}        # id(TextureData) -> its layer
        self._images: dict[int, TextureData] = {}  # ... and the image (kept while it has a layer)
        self._kinds: tuple[bool, bool] = (False, False)   # (a light projects one, a panel shows one)
        self._warned = False

    @property
    def defines(self) -> tuple[tuple[str, str], ...]:
        """The scene programs' builds while a kept light has a cookie: ``SPOT_COOKIES`` while one
        projects its image, ``PANEL_PICTURES`` while a rectangle shows one on its face."""
        projected, pictured = self._kinds
        return ((("SPOT_COOKIES", "1"),) if projected else ()) + ((("PANEL_PICTURES", "1"),) if pictured else ())

    def layer(self, cookie: TextureData | None) -> int:
        """The layer ``cookie`` is in (``set`` made it one), -1 for none (no cookie, or none drawn)."""
        return -1 if cookie is None else self._layers.get(id(cookie), -1)

    def set(self, cookies: list[TextureData | None], names: list[str], panels: list[bool] | None = None) -> bool:
        """Give each distinct image of ``cookies`` (the kept point lights' ``cookie``, None
        where a light has none; ``names``: the lights, for the warning; ``panels``: which of
        them show theirs on a rectangle's face, ``light_rules.is_panel``, none when not given)
        a layer, keeping the layers of those already there; release the array when none is
        left.  True when the array's contents or the builds changed (what every view shows
        changes)."""
        panels = panels if panels is not None else [False] * len(cookies)
        wanted = {id(c): c for c in cookies if c is not None}
        if wanted and not self.supported:
            if not self._warned:
                self._warned = True
                lit = [name for name, c in zip(names, cookies, strict=True) if c is not None]
                warnings.warn(GLLimitWarning(
                    f"{', '.join(lit)}: spot light cookies need {SCENE_SAMPLERS + 1} texture units in the fragment "
                    f"stage and this OpenGL has {self.texture_units} (GL_MAX_TEXTURE_IMAGE_UNITS): the lights "
                    "shine without their cookies"), stacklevel=3)
            wanted = {}
        kinds = (any(c is not None and not panel for c, panel in zip(cookies, panels, strict=True)) and bool(wanted),
                 any(c is not None and panel for c, panel in zip(cookies, panels, strict=True)) and bool(wanted))
        kinds_changed, self._kinds = kinds != self._kinds, kinds
        if wanted.keys() == self._layers.keys():
            return kinds_changed
        kept = {key: layer for key, layer in self._layers.items() if key in wanted}
        free = sorted(set(range(len(wanted))) - set(kept.values()))
        fresh = [key for key in wanted if key not in kept]
        if kept and max(kept.values()) >= len(wanted):  # packed again from 0: no gaps past the count
            kept, fresh = {}, list(wanted)
            free = list(range(len(wanted)))
        layers = {**kept, **dict(zip(fresh, free, strict=False))}
        self._images = {key: wanted[key] for key in layers}
        need = len(layers)
        capacity = 0 if self.array is None else self.array.size[2]
        if need == 0:
            self._release_array()
        elif need > capacity or capacity > 2 * max(need, 1) and capacity > 1:
            self._release_array()
            self.array = self.ctx.texture_array((COOKIE_SIZE, COOKIE_SIZE, _capacity(need)), 3, dtype="f2")
            fresh = list(layers)   # a new array: every layer written
        for key in fresh:
            self.array.write(cookie_texels(self._images[key]).astype(np.float16).tobytes(),
                             viewport=(0, 0, layers[key], COOKIE_SIZE, COOKIE_SIZE, 1))
        if self.array is not None and fresh:
            self.array.build_mipmaps()
            self.array.filter = self.filter
            self.array.anisotropy = self.anisotropy
            # u wraps (an all-round light's image goes round it); a spot's square is never left
            # inside its cone
            self.array.repeat_x, self.array.repeat_y = True, False
        self._layers = layers
        return True

    def bind(self) -> None:
        """Bind the array for a scene pass (while there is one)."""
        if self.array is not None:
            bind_texture(self.ctx, self.array, COOKIE_UNIT)

    def count(self) -> int:
        """Cookie arrays held (0 or 1: ``Renderer.resource_counts``)."""
        return int(self.array is not None)

    def _release_array(self) -> None:
        if self.array is not None:
            self.array.release()
            self.array = None

    def release(self) -> None:
        self._release_array()
        self._layers.clear()
        self._images.clear()
        self._kinds = (False, False)


def _capacity(need: int) -> int:
    """Layers to make for ``need`` images: the power of two at or above it, at most
    ``MAX_POINT_LIGHTS`` (every kept light its own image)."""
    return min(1 << max(0, need - 1).bit_length(), MAX_POINT_LIGHTS)
