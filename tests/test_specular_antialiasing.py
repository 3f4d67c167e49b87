"""Geometric specular anti-aliasing (scene.frag ``filtered_roughness``): a tight highlight on a
small curved object, drawn one sample a pixel, lands on one pixel or none and swings in
brightness as the object moves by less than a pixel.  The reference is the same frame drawn
at 8 x 8 samples a pixel and averaged in linear light: with the lobe widened by the normal's
variance over each pixel, the highlights' energy follows the reference at every sub-pixel
offset and their pixels stay as near it as one sample's are."""
from __future__ import annotations

import numpy as np
import pytest

from components import DirectionalLight, Material, MeshRef, Skybox, Transform
from engine.assets.mesh import plane, sphere
from tests.support import green_and_rays, linear_to_srgb8, look_from, srgb_to_linear

SIZE = (64, 48)
SUPER = 8
# Sub-pixel shifts of the spheres (a pixel is about 0.2 m at their distance).
SHIFTS = np.linspace(0.0, 0.1, 4)


def spheres(shift: float, mesh):
    """Four small black dielectric balls (only their GGX highlight shows) under a sun, moved
    ``shift`` metres sideways."""
    def build(world):
        look_from(world, (0.0, 0.0, 10.0), (0.0, 0.0, 0.0), fov=30.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(DirectionalLight(direction=(-0.3, -0.4, -1.0), intensity=2.0, shadows=False))
        for x in np.linspace(-1.5, 1.5, 4):
            world.spawn(Transform(position=(x + shift, 0.0, 0.0)), MeshRef(mesh),
                        Material(color=(0.0, 0.0, 0.0, 1.0), roughness=0.3, environment_reflection=0.0))
    return build


def linear_frame(scene, build, size) -> np.ndarray:
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())[..., 1]


def test_small_highlights_keep_the_supersampled_energy_as_they_move(scene):
    mesh = sphere(0.5)
    energy, reference, error = [], [], []
    for shift in SHIFTS:
        one = linear_frame(scene, spheres(shift, mesh), SIZE)
        many = linear_frame(scene, spheres(shift, mesh), (SIZE[0] * SUPER, SIZE[1] * SUPER))
        truth = many.reshape(SIZE[1], SUPER, SIZE[0], SUPER).mean(axis=(1, 3))
        energy.append(one.sum())
        reference.append(truth.sum())
        error.append(np.abs(one - truth).sum() / truth.sum())
    energy, reference = np.array(energy), np.array(reference)
    assert reference.min() > 1.0   # (highlights to measure: the balls are black but for them)
    ratio = energy / reference
    # Within 10% of the reference at every offset, and steady as the balls move (one sample a
    # pixel: 14-28% low, swinging by 14%).
    assert np.abs(ratio - 1.0).max() < 0.1, ratio
    assert ratio.max() - ratio.min() < 0.1, ratio
    # Not bought by blurring them: each pixel about as near the reference as one sample's are
    # (0.24-0.30 of the energy; Filament's variance 0.15 made it 0.53-0.57).
    assert max(error) < 0.35, error


def test_a_flat_surface_keeps_its_highlight(scene):
    """Where the normal does not turn across a pixel (a flat floor, no normal map) the lobe is
    not widened: each pixel of the sun's highlight on a smooth black floor is single-scattering
    GGX at the floor's own roughness, written out in float64 (with its energy compensation,
    1 + f0 (1 / (A + B) - 1), A + B by quadrature), times the sun."""
    from tests.test_environment_specular import ggx_highlight, quadrature_brdf

    sun = np.array([0.0, -0.35, 1.0])
    roughness, intensity = 0.25, 0.05

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 0.0, 0.0), fov=40.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(DirectionalLight(direction=tuple(sun), intensity=intensity, shadows=False))
        world.spawn(Transform(), MeshRef(plane(40.0, 40.0)),
                    Material(color=(0.0, 0.0, 0.0, 1.0), roughness=roughness, environment_reflection=0.0))
    shown, _, rays = green_and_rays(scene, build, SIZE)
    floor = rays[:, 1] < -0.05
    view = -rays[floor]
    normal = np.tile([0.0, 1.0, 0.0], (len(view), 1))
    to_sun = -sun / np.linalg.norm(sun)
    single = ggx_highlight(normal, view, to_sun, np.array([0.04, 0.04, 0.04]), roughness)[:, 1]
    nv = view[:, 1]
    samples = np.linspace(0.02, 1.0, 25)
    table = np.array([sum(quadrature_brdf(roughness, n, n=200)) for n in samples])
    expected = single * (1.0 + 0.04 * (1.0 / np.interp(nv, samples, table) - 1.0)) * intensity
    assert expected.max() > 0.2 and expected.max() < 0.9   # a highlight, not clipped
    bright = expected > 0.02
    assert bright.sum() > 50
    step = np.abs(srgb_to_linear(np.clip(np.round(linear_to_srgb8(expected[bright])) + 1.5, 0, 255)) - expected[bright])
    assert np.abs(shown[floor][bright] - expected[bright]).max() <= step.max() + 0.01


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_small_balls_highlight_in_a_mirror_and_through_a_portal_is_from_that_views_eye(scene, way):
    """A small glossy black ball off to the camera's right, seen only in a mirror (or through a
    portal): its tight highlight (its roughness widened by the normal's change over each of the
    view's own pixels) is the frame a camera at the mirror's image eye (the eye carried through
    the portal) draws, turned left for right for the mirror (tests/test_clearcoat.py's
    assert_shown_as_from_its_eye); and the highlight is there (the unreflecting ball's differs)."""
    from tests.test_clearcoat import assert_shown_as_from_its_eye
    base = dict(color=(0.0, 0.0, 0.0, 1.0), roughness=0.35, environment_reflection=0.0)
    assert_shown_as_from_its_eye(scene, base, dict(base, reflectance=0.0), way, mesh=sphere(0.4, 24, 12), changed=5,
                                 by=0.01)
