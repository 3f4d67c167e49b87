"""A 16-bit normal map keeps its 16 bits from the file to the GPU (issue 26 item 5): an
8-bit map steps the slope by 1/127 (terraces on a mirror, the Material docstring says); a
16-bit PNG named as a normal map is read whole and uploaded as normalised RGBA16, while a
colour texture, and any other file format, is 8 bits."""
from __future__ import annotations

import numpy as np
import png

from components import Material, MeshRef, Transform
from engine.assets.level_file import load_level
from engine.assets.mesh import quad
from engine.assets.texture_data import load_texture
from engine.core.world import World
from tests.support import look_from


def write_png16(path, pixels: np.ndarray) -> None:
    """An RGB 16-bit PNG of ``pixels`` (h x w x 3 uint16), rows top first."""
    h, w, _ = pixels.shape
    with open(path, "wb") as file:
        png.Writer(w, h, greyscale=False, bitdepth=16).write(file, pixels.reshape(h, w * 3).tolist())


def gentle_slopes(n: int = 8) -> np.ndarray:
    """Normals whose x steps by less than an 8-bit step (1/255 of the encoded range)."""
    x = 32768 + np.arange(n * n, dtype=np.int64).reshape(n, n) * 37  # 37/65535: a seventh of an 8-bit step
    pixels = np.zeros((n, n, 3), np.uint16)
    pixels[..., 0] = x
    pixels[..., 1] = 32768
    pixels[..., 2] = 65535
    return pixels


def test_a_16_bit_png_normal_map_keeps_its_values_and_a_colour_is_8_bits(tmp_path):
    pixels = gentle_slopes()
    write_png16(tmp_path / "bumps.png", pixels)
    kept = load_texture(tmp_path / "bumps.png", keep_16_bits=True)
    assert kept.pixels.dtype == np.uint16 and np.array_equal(kept.pixels[..., :3], pixels)
    assert (kept.pixels[..., 3] == 65535).all() and not kept.has_alpha
    colour = load_texture(tmp_path / "bumps.png")
    assert colour.pixels.dtype == np.uint8
    assert np.abs(colour.pixels[..., 0].astype(int) - np.rint(pixels[..., 0].astype(np.int64) * 255 / 65535)).max() <= 1
    # A level file loads a normal map's file whole and the same file as a colour in 8 bits.
    (tmp_path / "level.toml").write_text(
        '[level]\nname = "bumps"\n\n[[entity]]\nname = "tile"\n[entity.Transform]\n[entity.MeshRef]\n'
        'mesh = { quad = [1.0, 1.0] }\n[entity.Material]\ntexture = { file = "bumps.png" }\n'
        'normal_map = { file = "bumps.png" }\n')
    world = World("16-bit level")
    try:
        names = load_level(tmp_path / "level.toml").spawn(world)
        material = world.get(names["tile"], Material)
        assert material.normal_map.pixels.dtype == np.uint16 and material.texture.pixels.dtype == np.uint8
    finally:
        world.close()


def test_a_16_bit_normal_map_is_uploaded_with_its_16_bits(scene, tmp_path):
    pixels = gentle_slopes()
    write_png16(tmp_path / "bumps.png", pixels)
    bumps = load_texture(tmp_path / "bumps.png", keep_16_bits=True)

    def build(world):
        look_from(world, (0.0, 0.0, 2.0), target=(0.0, 0.0, 0.0))
        world.spawn(Transform(), MeshRef(quad(1.0, 1.0)), Material(normal_map=bumps))

    runner = scene(build, (32, 32))
    runner.frame()
    gpu = runner.engine.renderer.normal_map_texture(bumps)
    assert gpu is not None and gpu.dtype == "nu2"
    texels = np.frombuffer(gpu.read(), np.uint16).reshape(8, 8, 4)[::-1]  # GL rows bottom first
    assert np.array_equal(texels[..., :3], pixels)  # every 37/65535 step is there, none rounded to 8 bits
