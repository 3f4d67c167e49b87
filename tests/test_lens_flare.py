"""Lens flare (``LensFlare``): the bloom's image turned about the picture's middle and repeated
along the line through it (Chapman's pseudo lens flare).  The reference is where the geometry
puts each ghost of a small bright light: the k-th of a light at p (the picture's uv) stands at
1 - (p - s k / 2) / (1 - s k), s the spacing; the frame with the flare less the same frame
without it holds a bright blob there and nowhere else."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from components import (
    Bloom,
    ComponentValueError,
    ComponentWarning,
    Emissive,
    LensFlare,
    Material,
    MeshRef,
    Skybox,
    Transform,
)
from engine.assets.mesh import sphere
from tests.support import look_from, srgb_to_linear

SIZE = (240, 180)
LIGHT = (-1.6, 1.0, 0.0)


def flare_frame(scene, flare: LensFlare | None, bloom: bool = True):
    """A dark scene with one small, very bright ball up and to the left of the middle, the
    camera's Bloom (threshold 2: only the ball blooms) and ``flare``: linear luminance, and
    the ball's place (uv, v up)."""
    def build(world):
        camera = look_from(world, (0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60.0)
        if bloom:
            world.add_component(camera, Bloom(intensity=0.2, threshold=2.0))
        if flare is not None:
            world.add_component(camera, flare)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(position=LIGHT), MeshRef(sphere(0.1)), Material(color=(1.0, 1.0, 1.0), unlit=True),
                    Emissive(power=60.0))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    image = srgb_to_linear(runner.frame()) @ np.array([0.2126, 0.7152, 0.0722])
    col, row = runner.project(LIGHT)
    return image, np.array([(col + 0.5) / SIZE[0], 1.0 - (row + 0.5) / SIZE[1]]), runner


def ghost_places(light: np.ndarray, ghosts: int, spacing: float) -> list[np.ndarray]:
    return [1.0 - (light - 0.5 * spacing * k) / (1.0 - spacing * k) for k in range(ghosts)]


def test_each_ghost_stands_where_the_lens_throws_it(scene):
    """Four ghosts at spacing 0.3, no halo: each one inside the picture a bright blob (its
    peak within three pixels of the place the geometry gives, far above the picture's
    median), and the brightest spots of the added light all at those places."""
    flare = LensFlare(intensity=2.0, ghosts=4, ghost_spacing=0.3, halo=0.0, fringe=0.0)
    plain, light, _ = flare_frame(scene, None)
    flared, _, runner = flare_frame(scene, flare)
    added = flared - plain
    places = [p for p in ghost_places(light, 4, 0.3) if np.all((p > 0.03) & (p < 0.97))]
    assert len(places) >= 2, places
    pixels = [(int((1.0 - p[1]) * SIZE[1]), int(p[0] * SIZE[0])) for p in places]   # (row, column)
    for row, col in pixels:
        window = added[max(row - 3, 0):row + 4, max(col - 3, 0):col + 4]
        assert window.max() > 50.0 * max(np.median(added), 1e-4), (row, col, window.max())
        peak = np.unravel_index(np.argmax(added[max(row - 8, 0):row + 9, max(col - 8, 0):col + 9]), (17, 17))
        assert abs(peak[0] - min(row, 8)) <= 3 and abs(peak[1] - min(col, 8)) <= 3, (row, col, peak)
    # Away from every ghost's place (those at the picture's edge too), nothing bright is added.
    rows, cols = np.mgrid[0:SIZE[1], 0:SIZE[0]]
    near = np.zeros(added.shape, bool)
    for p in ghost_places(light, 4, 0.3):
        row, col = (1.0 - p[1]) * SIZE[1], p[0] * SIZE[0]
        near |= (rows - row) ** 2 + (cols - col) ** 2 < 15 ** 2
    strongest = max(added[row, col] for row, col in pixels)
    assert added[~near].max() < 0.35 * strongest, (added[~near].max(), strongest)


def test_the_halo_adds_a_ring_and_the_fringes_split_the_colours(scene):
    """With a halo its light comes on top of the ghosts' (the same frame without it is dimmer
    off the ghosts); without a Bloom a LensFlare adds nothing and says so once."""
    ghosts_only, _, _ = flare_frame(scene, LensFlare(intensity=2.0, halo=0.0))
    with_halo, _, _ = flare_frame(scene, LensFlare(intensity=2.0, halo=0.45, halo_intensity=2.0))
    assert (with_halo - ghosts_only).max() > 0.01
    unbloomed, _, runner = flare_frame(scene, None, bloom=False)
    flare_alone = scene(lambda world: (look_from(world, (0.0, 0.0, 5.0), (0.0, 0.0, 0.0)),
                                       world.add_component(next(e for e, _ in world.query(Transform)), LensFlare())),
                        SIZE)
    with pytest.warns(ComponentWarning, match="no Bloom"):
        flare_alone.frame()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flare_alone.frame()


def test_values_are_checked():
    for field, bad in (("intensity", -1.0), ("ghosts", 9), ("ghosts", 1.5), ("ghost_spacing", 1.5),
                       ("halo", float("nan")), ("fringe", 0.1)):
        with pytest.raises(ComponentValueError, match=f"LensFlare.{field}"):
            LensFlare(**{field: bad})


def test_a_light_seen_only_in_a_mirror_throws_its_ghosts_from_its_reflection(scene):
    """The ball hidden from the camera (``Visibility(direct=False)``) but shown by a mirror:
    the flare is made of the finished picture's bloom, so its ghosts stand where the
    geometry throws them from the ball's reflection (the ball mirrored in the glass's plane
    and projected; the ids there say the ball, on the mirror, its only pixels)."""
    from components import Mirror, Visibility
    from engine.assets.mesh import quad

    ball, image = (1.6, 1.0, 2.0), (1.6, 1.0, -2.0)   # its reflection in the plane z = 0

    def frame(flare):
        ents = {}

        def build(world):
            camera = look_from(world, (0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60.0)
            world.add_component(camera, Bloom(intensity=0.2, threshold=2.0))
            if flare:
                world.add_component(camera, LensFlare(intensity=2.0, ghosts=4, ghost_spacing=0.3, halo=0.0,
                                                      fringe=0.0))
            world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
            ents["mirror"] = world.spawn(Transform(), MeshRef(quad(7.0, 5.0)), Material(), Mirror())
            ents["ball"] = world.spawn(Transform(position=ball), MeshRef(sphere(0.1)),
                                       Material(color=(1.0, 1.0, 1.0), unlit=True), Emissive(power=60.0),
                                       Visibility(direct=False))
        runner = scene(build, SIZE)
        runner.engine.renderer.antialias = "off"
        runner.frame()
        return srgb_to_linear(runner.frame()) @ np.array([0.2126, 0.7152, 0.0722]), runner, ents

    plain, runner, ents = frame(False)
    flared, _, _ = frame(True)
    added = flared - plain
    col, row = runner.project(image)
    assert runner.ids()[row, col] == ents["ball"]
    assert runner.engine.renderer.targets.read_surface_ids()[row, col] == ents["mirror"]
    light = np.array([(col + 0.5) / SIZE[0], 1.0 - (row + 0.5) / SIZE[1]])
    places = [p for p in ghost_places(light, 4, 0.3) if np.all((p > 0.03) & (p < 0.97))]
    assert len(places) >= 2, places
    for p in places:
        row, col = int((1.0 - p[1]) * SIZE[1]), int(p[0] * SIZE[0])
        window = added[max(row - 8, 0):row + 9, max(col - 8, 0):col + 9]
        assert window.max() > 20.0 * max(np.median(added), 1e-4), (row, col, window.max())   # (the glow's wider)
        peak = np.unravel_index(np.argmax(window), window.shape)
        assert abs(peak[0] - min(row, 8)) <= 3 and abs(peak[1] - min(col, 8)) <= 3, (row, col, peak)
    # (what blooms is the reflection only: every pixel of the ball is on the mirror)
    shown = runner.ids() == ents["ball"]
    assert shown.sum() >= 5 and (runner.engine.renderer.targets.read_surface_ids()[shown] == ents["mirror"]).all()
