"""What the shaders write into the HDR colour images stays within a half float's range
(``engine.render.targets.HDR_FORMAT``, ``shaders/include/hdr.glsl``).

Every input that lands in those images is checked to be at most 65504 (components.tracking
HALF_MAX), but sums and products of them are not: a lamp of emissive power 65504 that a light
also falls on, a mirror tinted brighter than 1 reflecting it.  How a half-float image stores a
value past 65504 is the implementation's: llvmpipe saturates it to 65504, a correctly rounded
conversion gives +inf, and a still tree's refill (``StillTree.keep``) blends composites over a
pixel it assumes finite (inf x 0 is NaN).  So these tests widen the colour images to float32,
which keeps what the shaders wrote exactly, and check that no pixel holds more than 65504:
the lamp and its reflections hold 65504 itself (the largest finite half float, where
lighting + emission and tint x lamp, worked out in numpy, are past it).  And the same level
drawn into float32 images refills bit for bit as it draws: a level's copy keeps the level's
own format."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

import engine.render.targets as targets_module
from components import DirectionalLight, Emissive, Material, MeshRef, Mirror, Skybox, Transform
from engine.assets.mesh import box, plane, quad
from engine.assets.texture_data import checker_texture
from tests.support import look_from

SIZE = (64, 40)
LAMP_POWER = 65504.0
LIGHT = 2.0


def _lamp_between_mirrors(world) -> None:
    """A white lamp (emissive 65504) lit by a light from behind the camera, between a facing
    pair of mirrors tinted 4x (faded, so their composites blend over their own pixels and the
    refill copies levels), with end images."""
    world.resources["camera"] = look_from(world, (0.4, 1.6, 1.5), (-0.2, 1.4, -3.0))
    world.spawn(Skybox())
    world.spawn(DirectionalLight(direction=(0.0, -0.2, -1.0), intensity=LIGHT, shadows=False))
    world.spawn(Transform(), MeshRef(plane(20, 20, uv_repeat=8)), Material(texture=checker_texture(64, 8)))
    world.resources["lamp"] = world.spawn(Transform(position=(1.0, 1.3, -1.0), scale=(0.3, 0.3, 0.3)),
                                          MeshRef(box()), Material(color=(1.0, 1.0, 1.0), roughness=0.6),
                                          Emissive(LAMP_POWER))
    for z, turn in ((-3.0, 0.0), (3.0, math.pi)):
        world.spawn(Transform(position=(0.0, 1.5, z), rotation=glm.angleAxis(turn, glm.vec3(0, 1, 0))),
                    MeshRef(quad(4.0, 3.0)), Material(color=(0.15, 0.6, 0.15)),
                    Mirror(max_depth=4, color=(4.0, 4.0, 4.0), reflect_rate=0.9, fade_distance=(20.0, 200.0),
                           end_image=True))


@pytest.fixture
def float32_colour(monkeypatch):
    monkeypatch.setattr(targets_module, "HDR_FORMAT", "f4")


def _hdr(runner) -> np.ndarray:
    """The main image's colour, (h, w, 4), row 0 at the top, in the images' own format."""
    texture = runner.engine.renderer.targets.color
    w, h = runner.size
    return np.flipud(np.frombuffer(texture.read(), np.dtype(texture.dtype)).reshape(h, w, 4)).copy()


def test_a_lamp_past_the_half_float_range_and_its_tinted_reflections_are_stored_at_65504(scene, float32_colour):
    runner = scene(_lamp_between_mirrors, (128, 80))
    runner.frame()
    image = _hdr(runner)
    assert image.dtype == np.float32  # (what the shaders wrote, not rounded to a half float)
    lamp = runner.world.resources["lamp"]
    ids = runner.ids()
    surfaces = runner.engine.renderer.targets.read_surface_ids()
    direct = (surfaces == lamp) & (ids == lamp)
    mirrored = (ids == lamp) & (surfaces != lamp)  # the lamp seen in a mirror
    assert direct.sum() > 50 and mirrored.sum() > 8
    # Worked out apart: the lamp's emission alone is 65504 x white and the light adds to it
    # (the camera sees faces the light falls on), so lighting + emission is past 65504; a
    # mirror tinted 4x shows 4 x that, stored as the largest half float too, and blended at
    # its reflect rate 0.9 over the mirror's own shading (dim: under 10).
    to_light = -glm.vec3(0.0, -0.2, -1.0)
    assert glm.dot(to_light, glm.vec3(0.0, 0.0, 1.0)) > 0.0  # the lamp's +z face, toward the camera, is lit
    assert np.isfinite(image).all(), "a colour image holds inf or NaN"
    assert image[..., :3].max() <= 65504.0, f"a pixel holds {image[..., :3].max()}, past a half float's range"
    assert (image[direct][:, :3] == 65504.0).all()
    seen = image[mirrored][:, :3]
    assert (seen >= np.float32(0.9) * 65504.0 - 0.01).all() and (seen <= 0.9 * 65504.0 + 0.1 * 10.0).all()
    assert np.median(image[~(direct | mirrored)][:, :3]) < 100.0  # the rest is not saturated too
    assert runner.capture.read_rgb().mean() > 20


def test_the_refill_of_a_float32_level_is_the_drawn_frames_bit_for_bit(scene, float32_colour):
    """The still tree refilled in float32 images: every frame the same bytes as the engine
    that draws its whole tree (a level's copy in half floats would round its own pixels)."""
    keeping, drawing = scene(_lamp_between_mirrors, SIZE), scene(_lamp_between_mirrors, SIZE)
    drawing.engine.reflection_system.keep_still_views = False
    kinds = []
    for _ in range(6):
        images = []
        for runner in (keeping, drawing):
            rgb = runner.frame()
            images.append((rgb, _hdr(runner).tobytes(), runner.ids()))
        for name, kept, drawn in zip(("colour", "HDR image", "ids"), images[0], images[1], strict=True):
            assert np.array_equal(kept, drawn), f"the {name} differs from the frame drawn whole"
        kinds.append("refilled" if keeping.stats.reflection_end_refills else "drawn")
    assert kinds == ["drawn", "drawn"] + ["refilled"] * 4
    assert len(keeping.engine.reflection_system.tree.still.copies) > 0
    assert keeping.engine.reflection_system.tree.still.copies._copies[1].textures[0].dtype == "f4"


def test_a_generated_sky_brighter_than_a_half_float_is_stored_at_65504_not_as_inf(scene):
    """A generated sky's colours are each at most 65504, but the sky adds them (the horizon or
    zenith, the sun's glow and its disc): past 65504 the half-float cube held +inf, and the
    frame looking at the sun held NaN where its filtering met it (15 values), with only a
    numpy overflow warning.  The cube keeps the sky within a half float (``upload_cube``):
    where ``sky_radiance`` (numpy, float64) is past 65504 the frame holds 65504 itself."""
    import warnings

    from components import Skybox
    from components.rendering import DEFAULT_SUN_DIRECTION
    from engine.render.sky import sky_radiance

    sky = Skybox(horizon=(65504.0,) * 3, zenith=(65504.0,) * 3, sun_color=(65504.0,) * 3)
    sun = glm.vec3(*DEFAULT_SUN_DIRECTION)  # (no directional light: the sun stands there)

    def build(world) -> None:
        look_from(world, (0.0, 0.0, 0.0), tuple(sun))
        world.spawn(sky)

    runner = scene(build, (48, 32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (an overflow cast is a warning, not a pass)
        runner.frame()
    image = _hdr(runner)
    assert np.isfinite(image).all(), f"{int((~np.isfinite(image)).sum())} values of the frame are not finite"
    assert image[..., :3].max() == 65504.0
    assert sky_radiance(sky, np.array([tuple(sun)])).max() > 65504.0 * 1.5  # (the sun: past a half float)
    assert runner.capture.read_rgb().mean() > 200  # (a white sky, not black)
