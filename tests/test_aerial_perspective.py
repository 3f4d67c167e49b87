"""Aerial perspective (``Fog.aerial_perspective``): the fog's colour taken from the sky along
each ray (its cube map at the 8-texel level) instead of the fog's own.  Under a sky of one
colour C every way's sky is C, so a fog of any colour F with aerial perspective a must draw
exactly what a plain fog of colour F + a (C - F) draws: the floor, a crate, a mirror's view of
them (the composites' fog) and lit particles (their own build), frame against frame.  Under a
gradient sky, the sky in thick fog keeps its own colours with it and turns to the fog's
without."""
from __future__ import annotations

import numpy as np
import pytest

from components import (
    ComponentValueError,
    DirectionalLight,
    Fog,
    Material,
    MeshRef,
    Mirror,
    ParticleEmitter,
    Skybox,
    Transform,
)
from engine.assets.mesh import box, plane, quad
from tests.support import look_from, srgb_to_linear

SKY = np.array([0.9, 0.5, 0.2])       # the one colour of the flat sky
FOG = np.array([0.2, 0.3, 0.6])


def _frame(scene, fog: Fog, sky: Skybox | None = None) -> np.ndarray:
    def build(world):
        camera = look_from(world, (0.0, 2.0, 7.0), (0.0, 0.5, -1.0))
        world.add_component(camera, fog)
        world.spawn(sky or Skybox(faces=np.tile(SKY.astype(np.float32), (6, 4, 4, 1))))
        world.spawn(DirectionalLight(direction=(-0.3, -1.0, -0.5), intensity=1.0, shadows=False))
        world.spawn(Transform(), MeshRef(plane(80, 80)), Material(color=(0.5, 0.5, 0.5), roughness=1.0,
                                                                  environment_reflection=0.0))
        world.spawn(Transform(position=(-1.5, 0.5, 2.0)), MeshRef(box()), Material(color=(0.7, 0.3, 0.2)))
        world.spawn(Transform(position=(2.0, 1.5, -3.0)), MeshRef(quad(3.0, 3.0)), Material(), Mirror())
        world.spawn(Transform(position=(-0.5, 1.0, 3.0)),
                    ParticleEmitter(rate=0.0, burst=40, speed=0.3, lifetime=100.0, size=0.3, lit=True, seed=4))

    runner = scene(build, (160, 100))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return runner.frame().astype(int)


@pytest.mark.parametrize("share", [1.0, 0.5])
def test_under_a_one_colour_sky_aerial_perspective_is_a_fog_of_the_skys_colour(scene, share):
    aerial = _frame(scene, Fog(color=tuple(FOG), density=0.06, aerial_perspective=share))
    plain = _frame(scene, Fog(color=tuple(FOG + share * (SKY - FOG)), density=0.06))
    untouched = _frame(scene, Fog(color=tuple(FOG), density=0.06))
    assert np.abs(aerial - plain).max() <= 1
    assert (np.abs(aerial - untouched).max(axis=-1) > 10).mean() > 0.5   # (the fog did change colour)


def test_a_gradient_sky_in_thick_fog_keeps_its_colours(scene):
    """Fog thick enough that the sky is all fog (``sky_affect`` 1, the same density
    everywhere): without aerial perspective every sky pixel is the fog's colour; with it, the
    sky's own colours blurred (within 0.03 of the clear sky's light, the blur of a smooth
    gradient), its zenith bluer than its horizon as before."""
    sky = Skybox(zenith=(0.1, 0.25, 0.65), horizon=(0.65, 0.75, 0.9), ground=(0.2, 0.15, 0.1),
                 sun_direction=(0.0, -1.0, 0.0))   # (the sun below: no disc in the way)

    def frame(fog):
        return srgb_to_linear(_frame(scene, fog, sky).astype(np.uint8))

    clear = frame(Fog(density=0.0))
    fogged = frame(Fog(color=tuple(FOG), density=2.0))
    aerial = frame(Fog(color=tuple(FOG), density=2.0, aerial_perspective=1.0))
    top = (slice(0, 10), slice(None))
    assert np.abs(fogged[top] - FOG).max() < 0.01
    assert np.abs(aerial[top] - clear[top]).max() < 0.03
    assert aerial[0, :, 2].mean() > aerial[0, :, 0].mean()


@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan")])
def test_bad_shares_are_refused(value):
    with pytest.raises(ComponentValueError, match="Fog.aerial_perspective"):
        Fog(aerial_perspective=value)
