"""Lens dirt (``Bloom.dirt``): the lens's smudges lit by the bloom's light where it falls.  The
reference is the bloom's own light, taken from the frames themselves (an additive bloom's
frame less the same frame without bloom): with dirt, the frame gains that light times the
dirt image's linear colour times ``dirt_intensity``, pixel by pixel (in linear light, no tone
curve, in the glow around a bright ball, off the ball itself)."""
from __future__ import annotations

import numpy as np
import pytest

from components import Bloom, ComponentValueError, Emissive, Material, MeshRef, Skybox, Tonemap, Transform
from engine.assets.mesh import sphere
from engine.assets.texture_data import TextureData
from tests.support import look_from, srgb_to_linear

SIZE = (160, 120)


def dirt_image() -> TextureData:
    """White on the picture's left half, a dim orange on its right (row 0 the top)."""
    pixels = np.zeros((32, 32, 4), np.uint8)
    pixels[..., 3] = 255
    pixels[:, :16, :3] = 255
    pixels[:, 16:, :3] = (128, 64, 0)
    return TextureData(pixels, name="smudges")


def frame(scene, bloom: Bloom | None) -> np.ndarray:
    def build(world):
        camera = look_from(world, (0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60.0)
        world.add_component(camera, Tonemap(curve="none"))
        if bloom is not None:
            world.add_component(camera, bloom)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(sphere(0.15)), Material(color=(1.0, 1.0, 1.0), unlit=True),
                    Emissive(power=6.0))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())


def test_the_dirt_shows_where_the_blooms_light_falls_in_its_colour(scene):
    plain = frame(scene, None)
    bloomed = frame(scene, Bloom(intensity=0.3, composite="additive"))
    dirty = frame(scene, Bloom(intensity=0.3, composite="additive", dirt=dirt_image(), dirt_intensity=1.5))
    glow = bloomed - plain
    rows, cols = np.mgrid[0:SIZE[1], 0:SIZE[0]]
    ring = (np.hypot(rows - SIZE[1] / 2, cols - SIZE[0] / 2) > 12) & (glow[..., 1] > 0.01) \
        & (bloomed.max(axis=-1) < 0.95)
    assert ring.sum() > 300
    dirt = np.where((cols < SIZE[0] / 2)[..., None], 1.0, srgb_to_linear(np.array([128, 64, 0])))
    # (a column's width either side of the middle: the dirt's mip filtering blends its halves)
    clear = ring & (np.abs(cols - SIZE[0] / 2) > 3)
    expected = bloomed + glow * dirt * 1.5
    np.testing.assert_allclose(dirty[clear], np.minimum(expected[clear], 1.0), atol=0.012)
    assert (dirty - bloomed)[clear & (cols < SIZE[0] / 2)][:, 2].mean() > 0.02   # (the white side lit)
    assert np.abs((dirty - bloomed)[clear & (cols > SIZE[0] / 2)][:, 2]).max() < 0.01   # (the orange side: no blue)


def test_values_are_checked():
    with pytest.raises(ComponentValueError, match="Bloom.dirt"):
        Bloom(dirt="smudges.png")
    with pytest.raises(ComponentValueError, match="Bloom.dirt_intensity"):
        Bloom(dirt_intensity=-1.0)


def test_a_level_file_names_the_dirt(tmp_path):
    from PIL import Image

    from tests.support import camera_level_round_trip

    Image.fromarray(dirt_image().pixels).save(tmp_path / "smudges.png")
    world, camera = camera_level_round_trip(
        tmp_path, '[entity.Bloom]\nintensity = 0.2\ndirt = { file = "smudges.png" }\ndirt_intensity = 2.0\n',
        ("dirt_intensity = 2.0", "dirt_intensity = -2.0"), "dirt_intensity")
    bloom = world.get(camera, Bloom)
    assert bloom.dirt.pixels.shape == (32, 32, 4) and bloom.dirt_intensity == pytest.approx(2.0)
