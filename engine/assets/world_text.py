"""Text placed in the world: a label on a quad that is seen directly, in mirrors and through
portals like any other object (a sign, a name over a door).  Screen text
(``components/screen.py``: ``ScreenText``) is drawn over the finished picture and is never in
a mirror; this is the way to ask for text that is.

The label is Pillow's built-in font (the one the screen text's atlas is made from) rendered
once into a texture: the colour where the glyphs are, transparent around them.  Its
material's alpha is just under 1, which puts it in the scene pass's transparent slot, so the
glyphs are blended over what lies behind and the space between them shows it; it glows a
little (``Emissive``) so it reads in a dark corner.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pyglm import glm

from components import Emissive, Material, MeshRef, Transform
from engine.assets.mesh import quad
from engine.assets.texture_data import TextureData, pillow_image_module
from engine.core.errors import AssetError
from engine.core.world import World

LABEL_PIXELS = 48        # the font's size in the label's texture (texels a line)
MAX_LABEL_CHARACTERS = 200
SEE_THROUGH = 0.999      # the material's alpha: the transparent slot (see the module's docstring)


def text_texture(text: str, color: Sequence[int] = (255, 255, 255), pixels: int = LABEL_PIXELS) -> TextureData:
    """``text`` in Pillow's built-in font, ``pixels`` texels a line: RGBA, ``color`` (sRGB
    bytes) where the glyphs cover, alpha their coverage."""
    if not isinstance(text, str) or not text.strip() or len(text) > MAX_LABEL_CHARACTERS or "\n" in text:
        raise AssetError(f"world text must be one line of 1 to {MAX_LABEL_CHARACTERS} characters, got {text!r}")
    pillow_image_module()  # says plainly when Pillow is missing
    from PIL import Image, ImageDraw, ImageFont

    try:
        font = ImageFont.load_default(size=pixels)
    except (TypeError, OSError, ImportError):  # Pillow without FreeType: its bitmap font
        font = ImageFont.load_default()
    left, top, right, bottom = font.getbbox(text)
    margin = max(2, pixels // 8)
    width, height = int(right - left) + 2 * margin, int(bottom - top) + 2 * margin
    coverage = Image.new("L", (width, height), 0)
    ImageDraw.Draw(coverage).text((margin - left, margin - top), text, font=font, fill=255)
    alpha = np.asarray(coverage, np.uint8)
    rgba = np.empty(alpha.shape + (4,), np.uint8)
    rgba[..., :3] = np.asarray(color, np.uint8)[:3]
    rgba[..., 3] = alpha
    return TextureData(rgba, name=f"text {text[:24]!r}")


def spawn_world_text(world: World, text: str, position: glm.vec3 | Sequence[float],
                     rotation: glm.quat | Sequence[float] | None = None, height: float = 0.3,
                     color: Sequence[float] = (1.0, 1.0, 1.0), glow: float = 0.6) -> int:
    """A label reading ``text`` at ``position``, ``height`` metres a line, facing its local +Z
    (``rotation``: as a Transform takes it), ``color`` linear; returns its entity."""
    if not isinstance(height, (int, float)) or not 0.0 < height < 1e4:
        raise AssetError(f"world text height must be a number of metres above 0, got {height!r}")
    texture = text_texture(text)
    w, h = texture.size
    transform = Transform(position=position) if rotation is None else Transform(position=position, rotation=rotation)
    return world.spawn(transform, MeshRef(quad(height * w / h, height, name="world text")),
                       Material(color=(*tuple(color)[:3], SEE_THROUGH), texture=texture, roughness=1.0),
                       Emissive(glow))
