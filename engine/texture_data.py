"""Image data for textures, kept on the CPU; the renderer uploads it when first drawn."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.errors import AssetError


@dataclass(eq=False)
class TextureData:
    """RGBA8 pixels, sRGB encoded, row 0 at the top (as image files store them)."""

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
