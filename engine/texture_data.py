"""Image data for textures, kept on the CPU; the renderer uploads it when first drawn."""
from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.errors import AssetError


@dataclass(eq=False)
class TextureData:
    """RGBA8 pixels, row 0 at the top (as image files store them): sRGB encoded colour for
    ``Material.texture``, linear data for ``Material.normal_map`` (the renderer reads each as
    its field says)."""

    pixels: np.ndarray
    name: str = "texture"
    source: dict | None = None  # how it was made, as a level file writes it (None: from arrays)

    def __post_init__(self) -> None:
        p = np.asarray(self.pixels)
        if p.ndim != 3 or p.shape[2] not in (3, 4) or p.shape[0] < 1 or p.shape[1] < 1:
            raise AssetError(f"texture {self.name!r}: pixels must be HxWx3 or HxWx4, got shape {p.shape}")
        if p.dtype != np.uint8:
            raise AssetError(f"texture {self.name!r}: pixels must be uint8, got {p.dtype}")
        if p.shape[2] == 3:
            p = np.concatenate([p, np.full(p.shape[:2] + (1,), 255, np.uint8)], axis=2)
        self.pixels = np.ascontiguousarray(p)

    @property
    def size(self) -> tuple[int, int]:
        return self.pixels.shape[1], self.pixels.shape[0]

    @property
    def has_alpha(self) -> bool:
        return bool((self.pixels[..., 3] < 255).any())


def load_texture(path: str | Path) -> TextureData:
    """Read an image file (PNG, JPEG, ...) with Pillow."""
    from PIL import Image, UnidentifiedImageError

    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise AssetError(f"texture file path must be a str or pathlib.Path, got {type(path).__name__} {path!r}")
    path = Path(path)
    if not path.is_file():
        raise AssetError(f"texture file {str(path)!r}: no such file")
    try:
        with Image.open(path) as image:
            pixels = np.asarray(image.convert("RGBA"))
    except (UnidentifiedImageError, OSError) as exc:
        raise AssetError(f"texture file {str(path)!r}: cannot be read as an image ({exc})") from exc
    return TextureData(pixels, name=path.name, source={"file": str(path.resolve())})


MAX_GENERATED_SIZE = 16384  # texels along a side of a generated texture (GL's limit is checked at upload)


def checker_texture(size: int = 256, squares: int = 8, a: tuple[int, int, int] = (230, 230, 230),
                    b: tuple[int, int, int] = (40, 40, 48), name: str = "checker") -> TextureData:
    """A procedural checkerboard (the benchmark ground and the samples use it)."""
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_GENERATED_SIZE:
        raise AssetError(f"checker texture {name!r}: size must be an int in [1, {MAX_GENERATED_SIZE}], got {size!r}")
    if isinstance(squares, bool) or not isinstance(squares, int) or not 1 <= squares <= size:
        raise AssetError(f"checker texture {name!r}: squares must be an int in [1, size={size}], got {squares!r}")
    cell = max(1, size // squares)
    yy, xx = np.mgrid[0:size, 0:size]
    mask = ((xx // cell + yy // cell) % 2).astype(bool)
    pixels = np.empty((size, size, 3), np.uint8)
    pixels[~mask] = a
    pixels[mask] = b
    source = {"checker": [int(size), int(squares)], **({} if tuple(a) == (230, 230, 230) else {"a": list(a)}),
              **({} if tuple(b) == (40, 40, 48) else {"b": list(b)}), **({} if name == "checker" else {"name": name})}
    return TextureData(pixels, name=name, source=source)


MAX_RIPPLE_SLOPE = 100.0  # the steepest ripple then leans 89.4 degrees: past it, all edge-on


def ripple_normal_map(size: int = 256, rings: int = 6, slope: float = 0.5, name: str = "ripples") -> TextureData:
    """A tangent-space normal map of concentric ripples about the texture's centre: a sample
    and test map for ``Material.normal_map`` whose every texel has a known normal.

    The height is ``h(r) = cos(2 pi rings r) / (2 pi rings)`` (``r``: distance from the
    centre ``(0.5, 0.5)`` in UV units), so ``|dh/dr| <= 1``: ``slope`` is the steepest
    gradient of the bumps (``slope = 1`` tilts the normal 45 degrees at the steepest,
    whatever ``rings`` and ``size``), and the centre is a smooth crest whose normal is +Z.
    Each texel holds, at its centre, ``n = normalize(-slope dh/du, -slope dh/dv, 1)`` from the
    analytic gradient (no finite differences), encoded the OpenGL way: RGB = ``n * 0.5 + 0.5``
    (red +U, green +V, blue out of the surface), alpha 255, read linearly. Row 0 is the top
    of the image (``v = 1 - (row + 0.5) / size``), so green grows upwards in the image.
    """
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_GENERATED_SIZE:
        raise AssetError(f"ripples normal map {name!r}: size must be an int in [1, {MAX_GENERATED_SIZE}], "
                         f"got {size!r}")
    if isinstance(rings, bool) or not isinstance(rings, int) or not 1 <= rings <= size:
        raise AssetError(f"ripples normal map {name!r}: rings must be an int in [1, size={size}], got {rings!r}")
    if isinstance(slope, bool) or not isinstance(slope, numbers.Real) or not 0 <= slope <= MAX_RIPPLE_SLOPE:
        raise AssetError(f"ripples normal map {name!r}: slope must be a number in [0, {MAX_RIPPLE_SLOPE:g}], "
                         f"got {slope!r}")
    if not isinstance(name, str):
        raise AssetError(f"ripples normal map: name must be a string, got {name!r}")
    centres = (np.arange(size, dtype=np.float64) + 0.5) / size
    du = centres[np.newaxis, :] - 0.5           # columns: u grows to the right
    dv = (1.0 - centres)[:, np.newaxis] - 0.5   # rows: row 0 is the top, v = 1 at the top edge
    pixels = np.full((size, size, 4), 255, np.uint8)
    block = max(1, (1 << 20) // size)           # rows at a time: the float work stays small at any size
    for top in range(0, size, block):
        rows = dv[top:top + block]
        r = np.hypot(du, rows)
        # -slope dh/du = -slope (dh/dr) (u - 0.5) / r, dh/dr = -sin(2 pi rings r), and
        # sin(2 pi k r) / r = 2 pi k sinc(2 k r): no 0/0 at the centre.
        tilt = float(slope) * 2.0 * math.pi * rings * np.sinc(2.0 * rings * r)
        n = np.stack([tilt * du, tilt * rows, np.ones_like(r)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        pixels[top:top + block, :, :3] = np.clip(np.rint(n * 127.5 + 127.5), 0, 255).astype(np.uint8)
    source = {"ripples": [int(size), int(rings)], **({} if float(slope) == 0.5 else {"slope": float(slope)}),
              **({} if name == "ripples" else {"name": name})}
    return TextureData(pixels, name=name, source=source)
