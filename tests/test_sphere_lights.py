"""Sphere lights (``PointLight.radius``): a lamp the size of a bulb.  Its highlight on a smooth
floor is the sphere's mirror image, a disc, and on rough floors a wider, dimmer lobe, its
energy kept.  The reference is the sphere's light integrated over the floor's GGX lobe by
importance sampling in float64 (each sample a direction the lobe reflects, counted where it
meets the sphere), the sphere's radiance such that, seen small, it lights as the point light
of the same intensity and falloff does; each floor pixel found by casting its ray."""
from __future__ import annotations

import math

import numpy as np
import pytest

from components import ComponentValueError, Material, MeshRef, PointLight, Skybox, Transform
from engine.assets.mesh import plane, quad
from tests.support import green_and_rays, look_from, split_sum

SIZE = (96, 72)
LIGHT = np.array([0.0, 1.2, -1.0])
RANGE = 30.0
SAMPLES = 512


def hammersley(n: int) -> tuple[np.ndarray, np.ndarray]:
    i = np.arange(n)
    return (i + 0.5) / n, np.array([int(f"{k:032b}"[::-1], 2) / 2 ** 32 for k in i])


def sphere_light_reference(points: np.ndarray, view: np.ndarray, roughness: float, radius: float) -> np.ndarray:
    """The sphere's light reflected towards ``view`` by a white metal floor (normal +y) at
    ``points``, for intensity 1: the sphere's radiance (the point light's falloff at its centre
    over the solid angle it fills) times the GGX lobe's weight of the directions meeting it,
    the lobe sampled by its half vectors (Walter et al. 2007), times the engine's energy
    compensation 1 / (A + B) (a white metal)."""
    a2 = max(roughness * roughness, 1e-4) ** 2
    to_light = LIGHT - points
    d = np.linalg.norm(to_light, axis=1)
    fade = np.clip(1.0 - (d / RANGE) ** 4, 0.0, 1.0)
    solid_angle = 2.0 * math.pi * (1.0 - np.sqrt(1.0 - (radius / d) ** 2))
    radiance = fade ** 2 / (d ** 2 + 1.0) / solid_angle
    u1, u2 = hammersley(SAMPLES)
    cos_t = np.sqrt((1.0 - u1) / (1.0 + (a2 - 1.0) * u1))
    sin_t = np.sqrt(1.0 - cos_t ** 2)
    half = np.stack([sin_t * np.cos(2 * math.pi * u2), cos_t, sin_t * np.sin(2 * math.pi * u2)], axis=-1)
    out = np.zeros(len(points))
    for start in range(0, len(points), 256):
        v, p = view[start:start + 256], points[start:start + 256]
        vh = np.einsum("pk,nk->pn", v, half)
        light = 2.0 * vh[..., None] * half[None] - v[:, None, :]
        nl, nv, nh = light[..., 1], v[:, 1:2], half[None, :, 1]
        nl_ = np.maximum(nl, 1e-4)
        vis = 1.0 / ((nl_ + np.sqrt(a2 + (1 - a2) * nl_ ** 2)) * (nv + np.sqrt(a2 + (1 - a2) * nv ** 2)))
        weight = vis * 4.0 * np.maximum(nl, 0.0) * np.maximum(vh, 0.0) / nh
        from_light = p - LIGHT
        b = np.einsum("pnk,pk->pn", light, from_light)
        c = (from_light ** 2).sum(axis=1)[:, None] - radius ** 2
        meets = (b * b > c) & (b < 0.0)
        out[start:start + 256] = (weight * meets).mean(axis=1)
    return out * radiance / split_sum(roughness, view[:, 1]).sum(axis=-1)


def floor_frame(scene, roughness: float, radius: float, intensity: float):
    def build(world):
        look_from(world, (0.0, 1.0, 3.0), (0.0, 0.0, -1.0), fov=50.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(30.0, 30.0)),
                    Material(color=(1.0, 1.0, 1.0, 1.0), metallic=1.0, roughness=roughness, environment_reflection=0.0))
        world.spawn(Transform(position=tuple(LIGHT)), PointLight(intensity=intensity, range=RANGE, radius=radius))
    shown, eye, rays = green_and_rays(scene, build, SIZE)
    t = -eye[1] / rays[:, 1]
    on_floor = (t > 0) & (t < 12.0)
    return shown[on_floor], (eye + rays * t[:, None])[on_floor], -rays[on_floor]


@pytest.mark.parametrize("roughness", [0.05, 0.2, 0.5])
def test_a_sphere_lights_highlight_keeps_the_spheres_light(scene, roughness):
    """A sphere of 0.3 m, 2.5 m away, over a white metal floor from mirror-smooth to rough: the
    highlight's energy within 12% of the sphere's light the lobe gathers, each pixel of it
    near its own (medians within 25%: the representative point is an approximation of the
    lobe's shape, not of its energy)."""
    radius = 0.3
    _, points, view = floor_frame(scene, roughness, radius, 1.0)
    reference = sphere_light_reference(points, view, roughness, radius)
    intensity = 0.6 / reference.max()   # the brightest pixel at 0.6: nothing clips
    shown, _, _ = floor_frame(scene, roughness, radius, intensity)
    reference *= intensity
    lit = reference > 0.05
    assert lit.sum() > 40
    assert abs(shown.sum() / reference.sum() - 1.0) < 0.12, shown.sum() / reference.sum()
    assert abs(np.median(shown[lit] / reference[lit]) - 1.0) < 0.25


def test_a_smooth_floor_shows_the_spheres_disc_not_a_point(scene):
    """Polished (roughness 0.02, where float32 GGX written as n.h^2 (a^2 - 1) + 1 lost two
    thirds of the peak to one unit in the last place of n.h: ggx.glsl): the pixels whose
    mirrored ray meets the sphere (well inside its outline) are lit, at the sphere's radiance
    within 10%; those whose ray passes well clear are dark.  The same light as a point
    (radius 0) lights a handful of pixels."""
    radius, roughness = 0.3, 0.02
    _, points, view = floor_frame(scene, roughness, radius, 1.0)
    d = np.linalg.norm(LIGHT - points, axis=1)
    radiance = (1.0 - (d / RANGE) ** 4) ** 2 / (d ** 2 + 1.0) / (2 * math.pi * (1 - np.sqrt(1 - (radius / d) ** 2)))
    intensity = 0.6 / radiance.max()
    shown, _, _ = floor_frame(scene, roughness, radius, intensity)
    mirrored = view * np.array([-1.0, 1.0, -1.0])   # the eye ray reflected about +y
    from_light = points - LIGHT
    b = (mirrored * from_light).sum(axis=1)
    miss = np.sqrt(np.maximum((from_light ** 2).sum(axis=1) - b * b, 0.0))   # the ray's closest approach
    inside, clear = (miss < 0.8 * radius) & (b < 0), (miss > 1.3 * radius) | (b > 0)
    assert inside.sum() > 30
    expected = radiance * intensity / split_sum(roughness, view[:, 1]).sum(axis=-1)
    np.testing.assert_allclose(shown[inside], expected[inside], rtol=0.1)
    assert shown[clear].max() < 0.05
    point, _, _ = floor_frame(scene, roughness, 0.0, intensity)
    assert (point > 0.05).sum() < inside.sum() / 5


def test_radius_is_checked():
    for bad in (-0.1, 10.5, float("nan")):
        with pytest.raises(ComponentValueError, match="PointLight.radius"):
            PointLight(radius=bad)
    assert PointLight(radius=0.05).radius == 0.05


def test_a_sphere_whose_radius_reaches_its_range_is_warned_as_either_is_given(scene):
    """A sphere light's range is measured from its centre, so one whose radius reaches its
    range lights nothing outside itself: said once when the second of the two is given (at
    construction or written later), naming both; and so it is: a floor 1.5 m below a
    sphere of 1.4 m with range 1.4 stays black, where range 3 lights it."""
    from components import ComponentWarning
    with pytest.warns(ComponentWarning, match=r"PointLight.radius = 1.4 reaches its range = 1.4"):
        PointLight(range=1.4, radius=1.4)
    light = PointLight(range=3.0, radius=1.4)
    with pytest.warns(ComponentWarning, match=r"PointLight.radius = 1.4 reaches its range = 1"):
        light.range = 1.0
    light = PointLight(range=3.0)
    with pytest.warns(ComponentWarning, match=r"PointLight.radius = 5 reaches its range = 3"):
        light.radius = 5.0
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        PointLight(range=1.5, radius=1.4)
        PointLight(range=0.5)

    def frame(reach):
        def build(world):
            look_from(world, (0.0, 1.0, 3.0), (0.0, 0.0, -1.0), fov=50.0)
            world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
            world.spawn(Transform(), MeshRef(plane(30.0, 30.0)), Material(roughness=0.6, environment_reflection=0.0))
            world.spawn(Transform(position=(0.0, 1.5, -1.0)), PointLight(intensity=3.0, range=reach, radius=1.4))
        shown, eye, rays = green_and_rays(scene, build, SIZE)
        return shown[(-eye[1] / rays[:, 1] > 0.0)]
    with pytest.warns(ComponentWarning):
        short = frame(1.4)
    assert short.max() < 1e-3 and (frame(3.0) > 0.05).sum() > 500


def test_a_sphere_lights_image_in_a_mirror_keeps_its_radius(scene):
    """Through a mirror that carries light the light's image is a sphere of the same radius
    (a mirror keeps lengths): the VirtualLights block's row gives it to the scene shader,
    whose highlights draw it as the light's own."""
    from components import Mirror
    from engine.render.shadows import VIRTUAL_FIELDS
    from engine.rules.shadow_rules import MAX_VIRTUAL_LIGHTS

    def build(world):
        look_from(world, (0.0, 1.0, 3.0), (0.0, 0.0, -1.0), fov=50.0)
        world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
        world.spawn(Transform(), MeshRef(plane(30.0, 30.0)), Material(roughness=0.05))
        world.spawn(Transform(position=(0.0, 1.5, -3.0)), MeshRef(quad(4.0, 3.0)), Material(),
                    Mirror(reflects_light=True))
        world.spawn(Transform(position=tuple(LIGHT)), PointLight(intensity=2.0, range=RANGE, radius=0.25))
    runner = scene(build, SIZE)
    runner.frame()
    assert runner.engine.renderer.stats.virtual_lights == 1
    block = runner.engine.renderer.shadows.virtual_block
    at = 4 + 16 * MAX_VIRTUAL_LIGHTS + 4 * (VIRTUAL_FIELDS.index("cookie_v") * MAX_VIRTUAL_LIGHTS + 0)
    assert block[at + 3] == pytest.approx(0.25, rel=1e-6)
    # The sphere's builds only while a kept light is one.
    renderer = runner.engine.renderer
    assert renderer.sphere_lights
    runner.world.get(runner.world.query_one(PointLight)[0][0], PointLight).radius = 0.0
    runner.frame()
    assert not renderer.sphere_lights and block[at + 3] == 0.0


def test_a_sphere_lights_diffuse_light_is_a_points(scene):
    """A sphere of 0.5 m, 1.2 m over a rough floor: its diffuse light (the white floor's frame
    less a black floor's: the highlight is the same in both) is the point light's, the
    sphere's closed form where all of it stands above the floor's horizon (its form factor
    cos theta (R / d)^2 and radiance I / (pi R^2): I cos theta / d^2, the inverse square kept
    finite at the light, 1 / (d^2 + 1), as a point's), albedo / pi x that, within 2% in the
    median and 4% at the 90th percentile: the sphere's size changes its highlight only."""
    radius, intensity = 0.5, 3.0

    def build_with(albedo):
        def build(world):
            look_from(world, (0.0, 1.0, 3.0), (0.0, 0.0, -1.0), fov=50.0)
            world.spawn(Skybox(faces=np.zeros((6, 4, 4, 3), np.float32)))
            world.spawn(Transform(), MeshRef(plane(30.0, 30.0)),
                        Material(color=(albedo, albedo, albedo, 1.0), roughness=0.5, environment_reflection=0.0))
            world.spawn(Transform(position=tuple(LIGHT)), PointLight(intensity=intensity, range=RANGE, radius=radius))
        return build
    white, eye, rays = green_and_rays(scene, build_with(1.0), SIZE)
    black, _, _ = green_and_rays(scene, build_with(0.0), SIZE)
    t = -eye[1] / rays[:, 1]
    on_floor = (t > 0) & (t < 12.0)
    points = (eye + rays * t[:, None])[on_floor]
    diffuse = (white - black)[on_floor]
    to_light = LIGHT - points
    d = np.linalg.norm(to_light, axis=1)
    cosine = to_light[:, 1] / d
    above = cosine > radius / d   # (the sphere's whole disc above the horizon)
    fade = np.clip(1.0 - (d / RANGE) ** 4, 0.0, 1.0) ** 2
    expected = intensity * cosine * fade / (d ** 2 + 1.0) / math.pi
    lit = above & (expected > 0.03) & (expected < 0.95)
    assert lit.sum() > 1500 and black[on_floor].max() > 0.05   # (the highlight there, taken out)
    error = np.abs(diffuse[lit] / expected[lit] - 1.0)
    assert np.median(error) < 0.02 and np.percentile(error, 90) < 0.04, (np.median(error), np.percentile(error, 90))
