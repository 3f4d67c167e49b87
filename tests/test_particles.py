"""Particles drawn (``ParticleEmitter``; ``engine/render/particle_draw.py``): one still particle
against the round spot's formula worked out pixel by pixel (added, and covering by its
alpha), an alpha emitter's particles farthest first in the main view and in a mirror's (where
the order turns round), cut at the mirror's plane, hidden behind walls, no ids written, a
Visibility honoured, fogged by the air's transmittance, lit as the scene pass lights a thin
sheet letting light through (a second path), its shadow, a flipbook's frames the right way
up, and every GPU resource let go with the emitter."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Fog,
    HemisphereLight,
    Material,
    MeshRef,
    Mirror,
    ParticleEmitter,
    PointLight,
    Skybox,
    Transform,
    Visibility,
    look_rotation,
)
from engine.assets.mesh import box, quad
from engine.assets.texture_data import TextureData
from engine.core.color import srgb_to_linear
from engine.core.particle_cloud import ROW_FRAME, ROW_SIZE
from tests.support import drawn_over_near_depth, look_from

SIZE = (96, 72)
EYE = glm.vec3(0.0, 0.0, 4.0)
FOV = 40.0
WALL = (0.2, 0.2, 0.2)


def still(**fields) -> ParticleEmitter:
    """One particle that stays where it is born, upright, for as long as a test runs."""
    return ParticleEmitter(**{"rate": 0.0, "burst": 1, "speed": 0.0, "lifetime": 1000.0, "angle": (0.0, 0.0),
                              **fields})


def backdrop(world, color=WALL) -> int:
    """An unlit wall filling the view 3 m behind the origin: a known colour behind everything."""
    return world.spawn(Transform(position=glm.vec3(0.0, 0.0, -3.0)), MeshRef(quad(40.0, 40.0)),
                       Material(color=(*color, 1.0), unlit=True))


def render(scene, build, frames: int = 2, size=SIZE):
    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    for _ in range(frames):
        image = runner.frame()
    return runner, srgb_to_linear(image.astype(np.float64) / 255.0)


def spot_alpha(size: float, centre=(0.0, 0.0, 0.0), shape=SIZE) -> np.ndarray:
    """The round spot's alpha at each pixel's centre, (1 - r^2)^2 with r the distance from the
    particle's centre over its half-size, for a square facing the camera at EYE looking down -z."""
    w, h = shape
    centre = glm.vec3(centre)
    half_h = math.tan(math.radians(FOV / 2.0))
    x = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * half_h * (w / h)
    y = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * half_h
    depth = EYE.z - centre.z
    qx, qy = np.meshgrid(x * depth + EYE.x, y * depth + EYE.y)
    r2 = ((qx - centre.x) ** 2 + (qy - centre.y) ** 2) / (size / 2.0) ** 2
    return np.maximum(1.0 - r2, 0.0) ** 2


def test_an_additive_particle_adds_its_colour_by_the_round_spot(scene):
    colour = np.array((0.5, 0.3, 0.1))

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(), still(size=1.2, color=(*colour, 1.0)))
    runner, image = render(scene, build)
    expected = np.array(WALL) + spot_alpha(1.2)[..., None] * colour
    assert (spot_alpha(1.2) > 0.5).sum() > 150  # (a spot of some size: the test can see it)
    np.testing.assert_allclose(image, expected, atol=0.012)
    assert runner.stats.particles == 1


def test_an_alpha_particle_covers_by_its_alpha(scene):
    colour, alpha = np.array((0.9, 0.1, 0.1)), 0.8

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(), still(size=1.2, color=(*colour, alpha), end_color=(*colour, alpha), blend="alpha"))
    _, image = render(scene, build)
    a = alpha * spot_alpha(1.2)[..., None]
    np.testing.assert_allclose(image, colour * a + np.array(WALL) * (1.0 - a), atol=0.012)


def stream(**fields) -> ParticleEmitter:
    """A particle every 0.5 s flying towards +z at 1 m/s, red when born and blue at 4 s, solid
    (a white texture: alpha 1 over its square): the older are nearer the camera and bluer."""
    white = TextureData(np.full((4, 4, 4), 255, np.uint8), name="white")
    return ParticleEmitter(**{"rate": 2.0, "speed": 1.0, "spread": 0.0, "direction": (0.0, 0.0, 1.0),
                              "lifetime": 4.0, "size": 0.5, "color": (1.0, 0.0, 0.0, 1.0),
                              "end_color": (0.0, 0.0, 1.0, 1.0), "blend": "alpha", "texture": white,
                              "angle": (0.0, 0.0), **fields})


def test_alpha_particles_are_drawn_farthest_first_in_each_view(scene):
    """Seen from the camera the oldest (nearest, bluest) covers the rest; in a mirror behind them
    the youngest (nearest the mirror: nearest its image camera, reddest) does."""
    at = glm.vec3(-1.0, 0.0, -1.0)

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(4.0, 3.0)), Mirror())
        world.spawn(Transform(position=at), stream())
    runner, image = render(scene, build, frames=100)  # 1.67 s: particles aged 0.17 to 1.5 s on the line
    cloud = runner.engine.stages["particles"].clouds
    (entity, (particles, _)), = cloud.items()
    assert particles.count == 3
    col, row = runner.project(at + glm.vec3(0.0, 0.0, particles.age.max()))  # the oldest's centre
    oldest_t, youngest_t = particles.age.max() / 4.0, particles.age.min() / 4.0
    np.testing.assert_allclose(image[row, col], [1.0 - oldest_t, 0.0, oldest_t], atol=0.02)
    # The mirror's image of the youngest's centre (the plane z = -2.5).
    young = at + glm.vec3(0.0, 0.0, particles.age.min())
    col, row = runner.project(glm.vec3(young.x, young.y, -5.0 - young.z))
    pixel = image[row, col]
    assert pixel[0] > 0.5 and pixel[0] > 3.0 * pixel[2], pixel  # red: the youngest's ~(0.9, 0, 0.1)
    np.testing.assert_allclose(pixel / pixel.sum(), np.array([1.0 - youngest_t, 0.0, youngest_t]), atol=0.03)


def test_a_mirror_shows_particles_in_front_and_cuts_those_behind_it(scene):
    """A particle in front of a mirror at its mirrored place; one behind the mirror's plane
    (seen by nothing but the mirror's view, were it not cut) adds nothing there."""
    front, behind = glm.vec3(-0.6, 0.3, -1.0), glm.vec3(0.6, -0.3, -3.3)

    def build(with_particles):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            backdrop(world)
            world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(4.0, 3.0)), Mirror())
            if with_particles:
                for place in (front, behind):
                    world.spawn(Transform(position=place), still(size=0.4, color=(3.0, 3.0, 3.0, 1.0)))
        return make
    runner, lit = render(scene, build(True))
    _, plain = render(scene, build(False))
    col, row = runner.project(glm.vec3(front.x, front.y, -5.0 - front.z))
    assert (lit[row, col] - plain[row, col]).min() > 0.3  # the front particle's image
    col, row = runner.project(glm.vec3(behind.x, behind.y, -5.0 - behind.z))
    np.testing.assert_allclose(lit[row - 2:row + 3, col - 2:col + 3], plain[row - 2:row + 3, col - 2:col + 3],
                               atol=0.01)


def test_depth_hides_a_particle_behind_a_wall_and_no_id_is_written(scene):
    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        world.wall = backdrop(world)
        world.spawn(Transform(position=glm.vec3(0.6, 0.0, 1.0)), MeshRef(box((0.6, 0.6, 0.1))),
                    Material(color=(0.0, 0.6, 0.0, 1.0), unlit=True))
        world.spawn(Transform(position=glm.vec3(0.6, 0.0, 0.0)), still(size=0.5, color=(3.0, 3.0, 3.0, 1.0)))
        world.spawn(Transform(position=glm.vec3(-0.6, 0.0, 0.0)), still(size=0.5, color=(3.0, 3.0, 3.0, 1.0)))
    runner, image = render(scene, build)
    col, row = runner.project(glm.vec3(0.6, 0.0, 1.0))
    np.testing.assert_allclose(image[row, col], [0.0, 0.6, 0.0], atol=0.01)  # the box, not the particle
    col, row = runner.project(glm.vec3(-0.6, 0.0, 0.0))
    assert image[row, col].min() > 0.9  # the one in the open
    assert runner.ids()[::-1][row, col] == runner.world.wall  # its pixels keep the wall's id


def test_a_visibility_hides_an_emitter_in_mirrors(scene):
    place = glm.vec3(-0.6, 0.3, -1.0)

    def build(hidden):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            backdrop(world)
            world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(4.0, 3.0)), Mirror())
            parts = [Transform(position=place), still(size=0.4, color=(3.0, 3.0, 3.0, 1.0))]
            if hidden:
                parts.append(Visibility(in_mirrors=False))
            world.spawn(*parts)
        return make
    runner, shown = render(scene, build(False))
    _, hidden = render(scene, build(True))
    col, row = runner.project(place)
    assert shown[row, col].min() > 0.9 and hidden[row, col].min() > 0.9  # seen directly both times
    col, row = runner.project(glm.vec3(place.x, place.y, -5.0 - place.z))
    assert shown[row, col].min() > hidden[row, col].max() + 0.3


def test_fog_keeps_the_airs_transmittance_of_an_additive_particles_light(scene):
    density = 0.15

    def build(fog, particle):
        def make(world):
            camera = look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            if fog:
                world.add_component(camera, Fog(density=density, sky_affect=0.0))
            backdrop(world)
            if particle:
                world.spawn(Transform(), still(size=1.2, color=(0.6, 0.6, 0.6, 1.0)))
        return make
    added = {}
    for fog in (False, True):
        _, lit = render(scene, build(fog, True))
        _, plain = render(scene, build(fog, False))
        added[fog] = (lit - plain)[32:40, 44:52].mean()
    assert added[False] > 0.4
    assert added[True] / added[False] == pytest.approx(math.exp(-density * 4.0), rel=0.03)


def solid(value=255) -> TextureData:
    return TextureData(np.full((4, 4, 4), value, np.uint8), name="solid")


ALBEDO = (0.6, 0.5, 0.4)


def lit_scene(particle: bool, sun: glm.vec3, lamp: bool = False, blocker: bool = False, sun_on: bool = True,
              image: str | None = None, clouds=None, pane: float | None = None):
    """A 1 m lit particle facing the camera (a solid sprite: alpha 1 all over), or in its place
    a quad of the same albedo letting the same share of light through (diffuse transmission,
    its transmission's colour the albedo), lit by a sun (or a lamp the way the sun comes from)
    and a hemisphere; ``blocker``: a box in the sun's way; ``image``: the lamp with an amber
    cookie wrapped about it ("cookie"), a panel facing the particle with an amber picture
    ("picture"), one colour all over, or the same panel amber itself ("amber panel"); ``clouds``:
    a CloudLayer over a gradient sky; ``pane``: a see-through pane of that alpha in the way
    (the lamp casting: its see-through map; a negative alpha: the pane casting nothing)."""
    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        if clouds is not None:
            world.spawn(Skybox(sun_direction=(0.0, 1.0, 0.0)), clouds)   # (pinned: the same sky, sun on or off)
        world.spawn(HemisphereLight(sky=(0.3, 0.35, 0.5), ground=(0.2, 0.15, 0.1), intensity=1.0))
        if lamp:
            amber = TextureData(np.full((4, 4, 4), (255, 140, 30, 255), np.uint8), name="amber")
            shape = {"rectangle": (0.6, 0.4)} if image in ("picture", "amber panel") else {}
            colour = (*srgb_to_linear(np.array([255, 140, 30]) / 255.0), 1.0) if image == "amber panel" else (1.0,) * 4
            world.spawn(Transform(position=-sun * 1.5, rotation=look_rotation(sun)),
                        PointLight(color=colour, intensity=5.0 if sun_on else 0.0, range=20.0,
                                   cookie=amber if image in ("cookie", "picture") else None, shadows=pane is not None,
                                   **shape))
        else:
            world.spawn(DirectionalLight(direction=sun, intensity=3.0 if sun_on else 0.0))
        if particle:
            world.spawn(Transform(), still(size=1.0, color=(*ALBEDO, 1.0), end_color=(*ALBEDO, 1.0), lit=True,
                                           translucency=0.3, blend="alpha", texture=solid()))
        else:
            world.spawn(Transform(), MeshRef(quad(1.0, 1.0)),
                        Material(color=(*ALBEDO, 1.0), reflectance=0.0, roughness=1.0, environment_reflection=0.0,
                                 diffuse_transmission=0.3, diffuse_transmission_color=ALBEDO))
        if blocker:
            world.spawn(Transform(position=-sun * 1.2), MeshRef(box((0.8, 0.8, 0.8))),
                        Material(color=(0.1, 0.1, 0.1, 1.0)))
        if pane is not None:
            world.spawn(Transform(position=-sun * 1.2, rotation=look_rotation(sun)),
                        MeshRef(quad(0.8, 0.8), casts_shadows=pane >= 0.0),
                        Material(color=(0.1, 0.1, 0.1, abs(pane)), double_sided=True))
    return build


@pytest.mark.parametrize("sun, lamp", [
    (glm.normalize(glm.vec3(0.4, -0.3, -1.0)), False),   # from in front
    (glm.normalize(glm.vec3(-0.3, -0.2, 1.0)), False),   # from behind: through it
    (glm.normalize(glm.vec3(0.3, -0.4, -1.0)), True),    # a lamp in front
])
def test_a_lit_particle_is_lit_as_a_thin_sheet_letting_light_through(scene, sun, lamp):
    _, particle = render(scene, lit_scene(True, sun, lamp))
    _, sheet = render(scene, lit_scene(False, sun, lamp))
    middle = (slice(33, 39), slice(45, 51))
    assert particle[middle].mean() > 0.05
    np.testing.assert_allclose(particle[middle].mean(axis=(0, 1)), sheet[middle].mean(axis=(0, 1)), rtol=0.04,
                               atol=0.004)


@pytest.mark.parametrize("image", ["cookie", "picture"])
def test_a_lit_particle_takes_a_lamps_cookie_and_a_panels_picture_as_a_thin_sheet_does(scene, image):
    """The lamp in front with an amber image, one colour all over: a cookie wrapped about it
    (the particle's middle is the thin quad's there, whose pixels read the image as the scene's
    surfaces do), or the picture on a panel's face (its mean colour at the particle's centre:
    the particle as under the same panel amber itself; a panel's light on a particle is its
    centre's, not the surface's form factor); amber, not the lamp's white."""
    sun = glm.normalize(glm.vec3(0.3, -0.4, -1.0))
    _, particle = render(scene, lit_scene(True, sun, lamp=True, image=image))
    _, sheet = render(scene, lit_scene(image == "picture", sun, lamp=True,
                                       image="amber panel" if image == "picture" else image))
    _, white = render(scene, lit_scene(True, sun, lamp=True))
    middle = (slice(33, 39), slice(45, 51))
    np.testing.assert_allclose(particle[middle].mean(axis=(0, 1)), sheet[middle].mean(axis=(0, 1)), rtol=0.04,
                               atol=0.004)
    tint = particle[middle].mean(axis=(0, 1)) / white[middle].mean(axis=(0, 1))
    assert tint[2] < 0.6 * tint[0], tint


def through_a_mirror(particle: bool, reflects: bool):
    """lit_scene's particle (or thin quad) with a lamp to the right and a mirror to
    the right in front turned to it, throwing the lamp's light back onto its front
    (``reflects``: Mirror.reflects_light) from the lamp's image."""
    base = lit_scene(particle, glm.vec3(0.0, -1.0, 0.0), sun_on=False)

    def make(world):
        base(world)
        world.spawn(Transform(position=glm.vec3(2.0, 0.0, 1.0)), PointLight(intensity=40.0, range=30.0))
        world.spawn(Transform(position=glm.vec3(2.5, 0.0, 2.5), rotation=look_rotation(glm.vec3(1.0, 0.0, 1.0))),
                    MeshRef(quad(3.0, 3.0)), Mirror(reflects_light=reflects))
    return make


@pytest.mark.parametrize("reflects", [True, False])
def test_a_lit_particle_is_lit_through_a_mirror_as_a_thin_sheet_is(scene, reflects):
    """The particle's middle is the thin quad's there (the scene's light through mirrors, a
    second path), and with the mirror reflecting light brighter than without."""
    _, particle = render(scene, through_a_mirror(True, reflects))
    _, sheet = render(scene, through_a_mirror(False, reflects))
    middle = (slice(33, 39), slice(45, 51))
    np.testing.assert_allclose(particle[middle].mean(axis=(0, 1)), sheet[middle].mean(axis=(0, 1)), rtol=0.04,
                               atol=0.004)
    if reflects:
        _, without = render(scene, through_a_mirror(True, False))
        assert particle[middle].mean() > without[middle].mean() + 0.05, (particle[middle].mean(),
                                                                         without[middle].mean())


def test_a_lit_particle_behind_a_see_through_pane_in_a_mirrors_light_takes_the_share_it_lets_through(scene):
    """through_a_mirror's particle with a see-through pane (alpha 0.6, 0.5 m by 1 m) across the
    line from it to the lamp's image (4, 0, 3), 0.1 m past the lamp's own depth along that
    line (off the lamp's straight way to the particle and its way to the glass): the light the
    mirror adds to the particle (less the frame whose mirror reflects none) is 0.4 of what it
    adds with the pane casting nothing (the virtual light's see-through map, read by the
    particles' lighting), and the particle's middle is the thin quad's there (the scene's
    path: tests/test_virtual_lights.py)."""
    way = glm.vec3(0.8, 0.0, 0.6)   # towards the lamp's image in the mirror

    def build(particle: bool, pane: float, reflects: bool = True):
        base = through_a_mirror(particle, reflects)

        def make(world):
            base(world)
            world.spawn(Transform(position=way * 2.3, rotation=look_rotation(way)),
                        MeshRef(quad(0.5, 1.0), casts_shadows=pane >= 0.0),
                        Material(color=(0.1, 0.1, 0.1, abs(pane)), double_sided=True))
        return make

    runner, through = render(scene, build(True, 0.6))
    assert runner.engine.renderer.shadows.virtual_see_through_atlas is not None
    _, open_pane = render(scene, build(True, -0.6))
    _, dark = render(scene, build(True, -0.6, reflects=False))
    _, sheet = render(scene, build(False, 0.6))
    middle = (slice(33, 39), slice(45, 51))
    mirror_light = (open_pane - dark)[middle].mean(axis=(0, 1))
    assert mirror_light.min() > 0.05, mirror_light
    np.testing.assert_allclose((through - dark)[middle].mean(axis=(0, 1)) / mirror_light, 0.4, rtol=0.05)
    np.testing.assert_allclose(through[middle].mean(axis=(0, 1)), sheet[middle].mean(axis=(0, 1)), rtol=0.04,
                               atol=0.004)


@pytest.mark.parametrize("light", ["sun", "lamp", "mirror"])
def test_a_lit_particle_in_a_waters_body_is_lit_through_it_as_a_thin_sheet_is(scene, light):
    """The particle and the camera a metre under a tinted pond (red taken four times faster
    than blue), the light coming down through the water (``mirror``: through_a_mirror's lamp
    and its image in the mirror, every way under water): the particle's middle is the thin
    quad's there (the scene's path: fog.glsl water_light and water_skylight,
    virtual_light_ways.glsl virtual_water), and bluer than the same particle with the water
    clear."""
    import warnings

    from components import Water, yaw_pitch_rotation

    sun = glm.normalize(glm.vec3(0.3, -0.8, -0.5))

    def under_water(particle: bool, density: float):
        base = through_a_mirror(particle, True) if light == "mirror" else lit_scene(particle, sun, light == "lamp")

        def build(world):
            base(world)
            world.spawn(Transform(position=(0.0, 1.0, 0.0), rotation=yaw_pitch_rotation(0.0, -90.0)),
                        MeshRef(quad(30.0, 30.0)), Material(color=(0.1, 0.3, 0.35, 0.2)), Mirror(max_depth=1),
                        Water(fog_density=density, fog_color=(0.05, 0.2, 0.25), depth=6.0, absorption=(2.0, 1.0, 0.5)))
        return build

    middle = (slice(33, 39), slice(45, 51))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (a still water: no waves, said)
        _, particle = render(scene, under_water(True, 0.4))
        _, sheet = render(scene, under_water(False, 0.4))
        _, clear = render(scene, under_water(True, 0.0))
    assert particle[middle].mean() > 0.02
    np.testing.assert_allclose(particle[middle].mean(axis=(0, 1)), sheet[middle].mean(axis=(0, 1)), rtol=0.04,
                               atol=0.004)
    tint = particle[middle].mean(axis=(0, 1)) / clear[middle].mean(axis=(0, 1))
    assert tint[2] > 1.3 * tint[0], tint


def test_a_lit_particle_under_a_clouds_shadow_gets_the_suns_share_the_twin_says(scene):
    """Clouds 5 km across over a low sun: the particle's sunlight (the frame less the sunless
    one) with the clouds' shadows over the same without is the twin's share at its centre
    (about a half here), and it is lit as the thin sheet is under them (the scene's path)."""
    from components import CloudLayer
    from engine.render.clouds import cloud_shadow, cloud_shape

    sun = glm.normalize(glm.vec3(0.4, -0.3, -1.0))
    values = dict(coverage=0.6, scale=5000.0, height=1500.0, wind=(0.0, 0.0), drift=(5371.0, 0.0))
    middle = (slice(34, 38), slice(46, 50))
    light = {}
    for shadows in (True, False):
        clouds = CloudLayer(**values, shadows=shadows)
        _, lit = render(scene, lit_scene(True, sun, clouds=clouds))
        _, dark = render(scene, lit_scene(True, sun, sun_on=False, clouds=clouds))
        light[shadows] = (lit - dark)[middle].mean(axis=(0, 1))
        if shadows:
            _, sheet = render(scene, lit_scene(False, sun, clouds=clouds))
            np.testing.assert_allclose(lit[middle].mean(axis=(0, 1)), sheet[middle].mean(axis=(0, 1)), rtol=0.04,
                                       atol=0.004)
    want = float(cloud_shadow(cloud_shape(CloudLayer(**values)), np.zeros(3), -np.array(tuple(sun), np.float64)))
    assert 0.3 < want < 0.7
    assert light[False].min() > 0.05
    np.testing.assert_allclose(light[True] / light[False], want, rtol=0.03)


def test_a_lit_particle_in_a_shadow_keeps_only_the_light_from_all_round(scene):
    sun = glm.normalize(glm.vec3(0.7, -0.3, -0.6))  # (from the left and in front: the box off the camera's line)
    _, shaded = render(scene, lit_scene(True, sun, blocker=True))
    _, unlit_sun = render(scene, lit_scene(True, sun, sun_on=False))
    _, open_sun = render(scene, lit_scene(True, sun))
    middle = (slice(34, 38), slice(46, 50))
    np.testing.assert_allclose(shaded[middle].mean(axis=(0, 1)), unlit_sun[middle].mean(axis=(0, 1)), rtol=0.05,
                               atol=0.005)
    assert open_sun[middle].mean() > shaded[middle].mean() + 0.1


@pytest.mark.parametrize("lamp", [True, False])
def test_a_lit_particle_behind_a_see_through_pane_takes_the_lights_share_it_lets_through(scene, lamp):
    """A casting lamp (or the sun) and a see-through pane (alpha 0.6) between it and the
    particle: the light's light on the particle (less what it has with the light dark) is 0.4
    of what it is with the pane casting nothing (the lights' see-through maps, read by the
    particles' lighting as by the scene pass)."""
    sun = glm.normalize(glm.vec3(0.7, -0.3, -0.6))  # (as the shadow's test: the pane off the camera's line)
    _, through = render(scene, lit_scene(True, sun, lamp=lamp, pane=0.6))
    _, open_lamp = render(scene, lit_scene(True, sun, lamp=lamp, pane=-0.6))
    _, dark = render(scene, lit_scene(True, sun, lamp=lamp, pane=-0.6, sun_on=False))
    middle = (slice(34, 38), slice(46, 50))
    lamp_light = (open_lamp - dark)[middle].mean(axis=(0, 1))
    assert lamp_light.min() > 0.05
    np.testing.assert_allclose((through - dark)[middle].mean(axis=(0, 1)) / lamp_light, 0.4, rtol=0.05)


def test_a_flipbooks_frames_play_over_its_life_the_right_way_up(scene):
    """A 2 x 1 sheet: frame 0's cell green above red, frame 1's all blue; each particle upright."""
    pixels = np.zeros((8, 16, 4), np.uint8)
    pixels[..., 3] = 255
    pixels[:4, :8, 1] = 255   # frame 0's top half: green (row 0 is the image's top)
    pixels[4:, :8, 0] = 255   # its bottom half: red
    pixels[:, 8:, 2] = 255    # frame 1: blue
    sheet = TextureData(pixels, name="sheet")

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world, (0.0, 0.0, 0.0))
        world.spawn(Transform(position=glm.vec3(-0.7, 0.0, 0.0)),
                    still(size=1.0, texture=sheet, sheet=(2, 1), lifetime=1000.0, color=(1, 1, 1, 1),
                          end_color=(1, 1, 1, 1)))
        world.spawn(Transform(position=glm.vec3(0.7, 0.0, 0.0)),
                    still(size=1.0, texture=sheet, sheet=(2, 1), lifetime=0.2, color=(1, 1, 1, 1),
                          end_color=(1, 1, 1, 1)))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    runner.frame(1.0 / 60.0)
    image = srgb_to_linear(runner.frame(0.12).astype(np.float64) / 255.0)  # the short-lived past half its life
    top, bottom = runner.project(glm.vec3(-0.7, 0.25, 0.0)), runner.project(glm.vec3(-0.7, -0.25, 0.0))
    np.testing.assert_allclose(image[top[1], top[0]], [0.0, 1.0, 0.0], atol=0.02)
    np.testing.assert_allclose(image[bottom[1], bottom[0]], [1.0, 0.0, 0.0], atol=0.02)
    col, row = runner.project(glm.vec3(0.7, 0.0, 0.0))
    np.testing.assert_allclose(image[row, col], [0.0, 0.0, 1.0], atol=0.02)


def test_an_emitter_gone_lets_its_buffer_and_texture_go(scene):
    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.emitter = world.spawn(Transform(), ParticleEmitter(rate=300.0, texture=solid(200), size=0.3))
    runner = scene(build, SIZE)
    renderer = runner.engine.renderer
    textures = len(renderer._textures)
    for _ in range(3):
        runner.frame()
    draw = renderer.scene_pass.particle_draw
    record = draw.emitters[runner.world.emitter]
    assert len(renderer._textures) == textures + 1 and record.particles > 0
    buffer = record.buffer
    runner.world.delete_entity(runner.world.emitter)
    runner.frame()
    assert draw.emitters == {} and len(renderer._textures) == textures
    assert renderer.resource_counts()["particle_buffers"] == 0
    assert buffer.mglo.__class__.__name__ == "InvalidObject" or buffer.glo == 0  # released
    assert runner.stats.particles == 0


LEVEL = """
[level]
name = "sparks"

[[entity]]
name = "camera"
[entity.Transform]
position = [0.0, 0.0, 4.0]
[entity.Camera]

[[entity]]
name = "torch"
[entity.Transform]
position = [0.0, -0.5, 0.0]
[entity.ParticleEmitter]
rate = 40.0
lifetime = [0.5, 1.5]
speed = [1.0, 2.0]
direction = [0.0, 1.0, 0.0]
spread = 20.0
gravity = [0.0, -2.0, 0.0]
size = [0.2, 0.05]
color = [4.0, 1.5, 0.3, 1.0]
end_color = [1.0, 0.2, 0.0, 0.0]
sheet = [2, 2]
texture = { checker = [16, 2] }
blend = "additive"
"""


def test_an_emitter_loads_saves_and_loads_again_from_a_level_file(tmp_path, ctx):
    from engine.assets.level_file import LevelError, load_level, save_level
    from engine.core.world import World

    path = tmp_path / "sparks.toml"
    path.write_text(LEVEL)
    world = World("sparks")
    names = load_level(path).spawn(world)
    emitter = world.get(names["torch"], ParticleEmitter)
    assert emitter.lifetime == (0.5, 1.5) and emitter.sheet == (2, 2) and emitter.texture is not None
    assert tuple(emitter.end_color) == pytest.approx((1.0, 0.2, 0.0, 0.0)) and emitter.blend == "additive"
    saved = save_level(world, tmp_path / "saved.toml", names, name="sparks")
    again = World("again")
    emitter_again = again.get(load_level(saved).spawn(again)["torch"], ParticleEmitter)
    for field in ("rate", "lifetime", "speed", "spread", "size", "sheet", "blend", "max_particles", "seed"):
        assert getattr(emitter_again, field) == getattr(emitter, field), field
    for field in ("direction", "gravity", "color", "end_color"):
        np.testing.assert_allclose(tuple(getattr(emitter_again, field)), tuple(getattr(emitter, field)), rtol=1e-6)
    np.testing.assert_array_equal(emitter_again.texture.pixels, emitter.texture.pixels)
    path.write_text(LEVEL.replace("lifetime = [0.5, 1.5]", "lifetime = [1.5, 0.5]"))
    with pytest.raises(LevelError, match=r"sparks\.toml:\d+: entity 'torch': ParticleEmitter\.lifetime.*least <= most"):
        load_level(path).spawn(World("bad"))


def test_the_editor_adds_an_emitter_and_edits_its_fields(scene):
    """An emitter added to a selected entity in the editor draws next frame; its texture is
    typed as a level file writes it, its sheet dragged as numbers, its end colour pinned from
    the one in use (its colour faded) and handed back; a bad value is refused with the
    component's words and undone edits come back."""
    from shell.editor import EditError, Editor

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spot = world.spawn(Transform())
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    editor = Editor(runner.world)
    spot = runner.world.spot
    before = runner.frame()
    assert "ParticleEmitter" in editor.addable(spot)
    editor.add_component(spot, "ParticleEmitter", rate=0.0, burst=1, speed=0.0, lifetime=1000.0, size=1.0,
                         color=(2.0, 2.0, 2.0, 1.0))
    runner.frame()
    after = runner.frame()
    assert after[36, 48].min() > before[36, 48].max() + 100
    editor.set_texture(spot, "texture", "checker = [16, 2]", "ParticleEmitter")
    assert editor.texture_text(spot, "texture", "ParticleEmitter") == "checker = [16, 2]"
    editor.set_field(spot, "ParticleEmitter", "sheet", (2.0, 2.0))
    emitter = runner.world.get(spot, ParticleEmitter)
    assert emitter.sheet == (2, 2)
    assert tuple(editor.automatic(spot, "ParticleEmitter", "end_color")) == (2.0, 2.0, 2.0, 0.0)
    editor.set_field(spot, "ParticleEmitter", "end_color", editor.switched_on(spot, "ParticleEmitter", "end_color"))
    assert tuple(emitter.end_color) == (2.0, 2.0, 2.0, 0.0)
    with pytest.raises(ComponentValueError, match="ParticleEmitter.lifetime"):
        editor.set_field(spot, "ParticleEmitter", "lifetime", (3.0, 1.0))
    with pytest.raises(EditError, match="ParticleEmitter.texture"):
        editor.set_texture(spot, "texture", "checker = [16", "ParticleEmitter")
    editor.set_field(spot, "ParticleEmitter", "end_color", None)
    assert emitter.end_color is None and editor.undo() and tuple(emitter.end_color) == (2.0, 2.0, 2.0, 0.0)
    runner.frame()
    assert runner.stats.particles == 1


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_both_reflection_paths_draw_particles_in_a_mirror(scene, path):
    place = glm.vec3(-0.6, 0.3, -1.0)

    def build(with_particles):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            backdrop(world)
            world.spawn(Transform(position=glm.vec3(-1.0, 0.0, -2.5)), MeshRef(quad(2.0, 3.0)), Mirror())
            world.spawn(Transform(position=glm.vec3(1.0, 0.0, -2.5)), MeshRef(quad(2.0, 3.0)), Mirror())
            if with_particles:
                world.spawn(Transform(position=place), still(size=0.4, color=(3.0, 3.0, 3.0, 1.0)))
        return make
    shown = {}
    for with_particles in (False, True):
        runner = scene(build(with_particles), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        runner.frame()
        shown[with_particles] = srgb_to_linear(runner.frame().astype(np.float64) / 255.0)
        assert runner.stats.reflection_path == path
    col, row = runner.project(glm.vec3(place.x, place.y, -5.0 - place.z))
    assert shown[True][row, col].min() > shown[False][row, col].max() + 0.3


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_both_reflection_paths_draw_particles_through_a_portal(scene, path):
    """A bright particle beyond portal B (20 m off, turned a quarter), where the view through
    A puts it 1.2 m behind A's plane: it shows through A at that point's pixel (the camera's
    projection of where the portal's view sees it) and not beside it."""
    from engine.assets.portals import spawn_portal_pair
    from engine.core.portal_math import pair_transform

    a_at, b_at = glm.vec3(0.0, 0.0, -2.5), glm.vec3(20.0, 0.0, 0.0)
    turn = glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))
    carry = pair_transform(glm.translate(a_at), glm.translate(b_at) * glm.mat4_cast(turn))
    seen_at = glm.vec3(-0.4, 0.3, -3.7)   # as the view through A sees it

    def build(with_particles):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            spawn_portal_pair(world, a_at, None, b_at, turn, size=(2.5, 2.0))
            world.spawn(Transform(position=glm.vec3(carry * glm.vec4(0.0, 0.0, -5.0, 1.0)),
                                  rotation=glm.quat_cast(carry)),
                        MeshRef(quad(40.0, 40.0)), Material(color=(*WALL, 1.0), unlit=True))   # (a wall beyond B)
            if with_particles:
                world.spawn(Transform(position=glm.vec3(carry * glm.vec4(seen_at, 1.0))),
                            still(size=0.3, color=(3.0, 3.0, 3.0, 1.0)))
        return make
    shown = {}
    for with_particles in (False, True):
        runner = scene(build(with_particles), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        runner.frame()
        shown[with_particles] = srgb_to_linear(runner.frame().astype(np.float64) / 255.0)
        assert runner.stats.reflection_views >= 1 and runner.stats.reflection_path == path
    col, row = runner.project(seen_at)
    assert shown[True][row, col].min() > shown[False][row, col].max() + 0.3
    col, row = runner.project(seen_at + glm.vec3(0.5, 0.0, 0.0))   # (beside it: the wall as it was)
    np.testing.assert_allclose(shown[True][row, col], shown[False][row, col], atol=0.01)


PORTAL_A, PORTAL_B = glm.vec3(0.0, 0.0, -2.5), glm.vec3(20.0, 0.0, 0.0)
PORTAL_TURN = glm.angleAxis(glm.radians(90.0), glm.vec3(0, 1, 0))
PORTAL_SIZE = (2.5, 2.0)


def pair_carry() -> glm.mat4:
    """The transform of the portal pair ``through_a_portal_and_from_its_eye`` spawns, A's side to B's."""
    from engine.core.portal_math import pair_transform

    return pair_transform(glm.translate(PORTAL_A), glm.translate(PORTAL_B) * glm.mat4_cast(PORTAL_TURN))


def through_a_portal_and_from_its_eye(scene, content, *, path="per_mirror", frames=2, size=SIZE, eye=EYE,
                                      target=(0.0, 0.0, 0.0), fov=FOV, step=None, margin=3):
    """What ``content(world, carry)`` spawns beyond portal B (20 m off, turned a quarter; ``carry``
    the pair's transform, A's side to B's) rendered twice: through portal A from ``eye``
    (``path`` the reflection path), and directly from the eye the portal carries (the camera
    carried by ``carry``: its eye, its target) in a world with no portals; linear images, and
    the pixels at least ``margin`` in from the edges of A's opening (by the main view's rays),
    where the two must agree.  ``step(runner, k)`` runs before each frame ``k``."""
    from engine.assets.portals import spawn_portal_pair
    from tests.support import pixel_rays

    carry = pair_carry()
    images, runners = {}, {}
    for through in (True, False):
        def build(world, through=through):
            if through:
                look_from(world, eye, target, fov=fov)
                spawn_portal_pair(world, PORTAL_A, None, PORTAL_B, PORTAL_TURN, size=PORTAL_SIZE)
            else:
                look_from(world, glm.vec3(carry * glm.vec4(glm.vec3(eye), 1.0)),
                          glm.vec3(carry * glm.vec4(glm.vec3(target), 1.0)), fov=fov)
            content(world, carry)
        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        for k in range(frames):
            if step is not None:
                step(runner, k)
            image = runner.frame(1.0 / 60.0 if k < frames - 1 else 0.0)
        images[through], runners[through] = srgb_to_linear(image.astype(np.float64) / 255.0), runner
    assert runners[True].stats.reflection_views >= 1 and runners[True].stats.reflection_path == path
    origin, rays = pixel_rays(runners[True].engine.main_view, size)
    hit = origin + rays * ((PORTAL_A.z - origin[2]) / rays[..., 2])[..., None]
    pixel = 2.0 * math.tan(math.radians(fov / 2.0)) * abs(PORTAL_A.z - origin[2]) / size[1]
    opening = (np.abs(hit[..., 0] - PORTAL_A.x) < PORTAL_SIZE[0] / 2 - margin * pixel) \
        & (np.abs(hit[..., 1] - PORTAL_A.y) < PORTAL_SIZE[1] / 2 - margin * pixel)
    return images[True], images[False], opening, runners


def test_a_paused_cloud_keeps_the_mirrors_views_and_a_moving_one_does_not(scene):
    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(4.0, 3.0)), Mirror())
        world.spawn(Transform(position=glm.vec3(-0.6, 0.0, -1.0)),
                    ParticleEmitter(rate=30.0, speed=0.5, size=0.2, color=(3.0, 3.0, 3.0, 1.0)))
    runner = scene(build, SIZE)
    kept = []
    for dt in (1 / 60,) * 4 + (0.0,) * 4 + (1 / 60,) * 2:
        runner.frame(dt)
        kept.append(runner.stats.reflection_views_kept)
    assert kept[:4] == [0] * 4 and kept[-2:] == [0, 0]  # moving: drawn every frame
    assert kept[6:8] == [1, 1]  # paused: nothing a view shows changed (the first still frame draws)


def test_a_probe_capture_leaves_particles_out(scene):
    """A chrome ball's probe would see a bright cloud behind the camera in the ball's middle;
    it is left out of the capture (a probe redrawn on its schedule would hold a still frame of it)."""
    from components import Reflective, Skybox
    from engine.assets.mesh import sphere

    def build(with_particles):
        def make(world):
            world.spawn(Skybox())
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            world.spawn(Transform(), MeshRef(sphere(0.6, 48, 24)),
                        Material(color=(1, 1, 1), metallic=1.0, roughness=0.0), Reflective("cube"))
            if with_particles:
                world.spawn(Transform(position=glm.vec3(0.0, 0.0, 6.0)), still(size=3.0, color=(5.0, 5.0, 5.0, 1.0)))
        return make
    middle = {}
    for with_particles in (False, True):
        runner = scene(build(with_particles), SIZE)
        runner.engine.renderer.antialias = "off"
        for _ in range(3):
            image = runner.frame()
        assert runner.engine.renderer.scene_pass.particle_draw.particles == int(with_particles)
        middle[with_particles] = image[33:39, 45:51].astype(int)
    np.testing.assert_array_equal(middle[True], middle[False])


def test_a_stretched_particle_is_a_streak_trailing_its_flight(scene):
    """0.5 m/s along +x, stretch 2 s, size 0.2: a 0.2 m band from 1.1 m behind its centre to
    0.1 m ahead of it (its speed x stretch behind, half its size each way)."""
    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world, (0.0, 0.0, 0.0))
        world.spawn(Transform(position=glm.vec3(-0.5, 0.0, 0.0)),
                    still(speed=0.5, spread=0.0, direction=(1.0, 0.0, 0.0), size=0.2, stretch=2.0, texture=solid(),
                          color=(1.0, 1.0, 1.0, 1.0), end_color=(1.0, 1.0, 1.0, 1.0)))
    runner, image = render(scene, build, frames=30)
    (particles, _), = runner.engine.stages["particles"].clouds.values()
    centre = float(particles.position[0, 0])
    lit = image.mean(axis=2) > 0.5
    rows, cols = np.nonzero(lit)
    left, top = runner.project(glm.vec3(centre - 1.1, 0.1, 0.0))
    right, bottom = runner.project(glm.vec3(centre + 0.1, -0.1, 0.0))
    assert abs(cols.min() - left) <= 1 and abs(cols.max() + 1 - right) <= 1
    assert abs(rows.min() - top) <= 1 and abs(rows.max() + 1 - bottom) <= 1


@pytest.mark.parametrize("gap, softness", [(0.1, 0.4), (0.3, 0.4), (0.1, 0.0), (0.6, 0.4)])
def test_a_soft_particle_fades_by_the_room_behind_it(scene, gap, softness):
    """A solid additive square ``gap`` in front of an unlit wall: at its middle it adds its
    colour times the room to the wall (along the ray, about the gap there) over its softness,
    held at 1; a hard one (softness 0) all of it."""
    colour = 0.5

    def build(particle):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            world.spawn(Transform(position=glm.vec3(0.0, 0.0, -gap)), MeshRef(quad(6.0, 6.0)),
                        Material(color=(*WALL, 1.0), unlit=True))
            if particle:
                world.spawn(Transform(), still(size=1.0, texture=solid(), softness=softness,
                                               color=(colour, colour, colour, 1.0), end_color=(colour,) * 3 + (1.0,)))
        return make
    _, lit = render(scene, build(True))
    _, plain = render(scene, build(False))
    middle = (slice(34, 38), slice(46, 50))
    added = (lit - plain)[middle].mean()
    expected = colour * (min(gap / softness, 1.0) if softness else 1.0)
    assert added == pytest.approx(expected, rel=0.04, abs=0.01)


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_a_soft_particle_in_a_mirror_fades_by_the_room_behind_it_in_the_mirrors_view(scene, path):
    """A solid additive square out of the camera's sight (beside and just in front of it) and
    an unlit wall behind the camera, both seen only in the mirrors the camera faces: a
    mirror's view (one of a level's two) reads its own level's depth, so the square's image
    adds its colour times the room from it to the wall along the image camera's ray over its
    softness (the ray from the eye's image through its centre), against the same square hard
    (softness 0)."""
    centre, wall_z, mirror_z, softness = glm.vec3(1.0, 0.0, 3.5), 5.5, -2.5, 4.0

    def build(softness_now):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            for x in (-1.0, 1.0):   # (two mirrors: a level of two views, each drawn where its node is)
                world.spawn(Transform(position=glm.vec3(x, 0.0, mirror_z)), MeshRef(quad(2.0, 3.0)), Mirror())
            turned = glm.angleAxis(math.pi, glm.vec3(0.0, 1.0, 0.0))   # (facing the mirror)
            world.spawn(Transform(position=glm.vec3(0.0, 0.0, wall_z), rotation=turned), MeshRef(quad(40.0, 40.0)),
                        Material(color=(*WALL, 1.0), unlit=True))
            if softness_now is not None:
                world.spawn(Transform(position=centre),
                            still(size=1.2, texture=solid(), softness=softness_now, color=(0.5, 0.5, 0.5, 1.0),
                                  end_color=(0.5, 0.5, 0.5, 1.0)))
        return make
    shown = {}
    for softness_now in (None, 0.0, softness):
        runner = scene(build(softness_now), SIZE)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        runner.frame()
        shown[softness_now] = srgb_to_linear(runner.frame().astype(np.float64) / 255.0)
        assert runner.stats.reflection_path == path
    col, row = runner.project(glm.vec3(centre.x, centre.y, 2.0 * mirror_z - centre.z))   # its image's centre
    assert not (0 <= runner.project(centre)[0] < SIZE[0])   # (the square itself is out of the camera's sight)
    patch = (slice(row - 1, row + 2), slice(col - 1, col + 2), slice(None))
    hard = (shown[0.0] - shown[None])[patch].mean()
    soft = (shown[softness] - shown[None])[patch].mean()
    assert hard > 0.3, hard
    # The room along the image camera's ray: from the eye's image through the centre to the wall.
    image_eye = np.array([EYE.x, EYE.y, 2.0 * mirror_z - EYE.z])
    ray = np.array(centre) - image_eye
    room = (wall_z - centre.z) * np.linalg.norm(ray) / ray[2]
    assert soft / hard == pytest.approx(room / softness, abs=0.03), (soft / hard, room / softness)


def test_emitters_are_drawn_farthest_first_in_each_view(scene):
    """Two solid alpha squares, a red one nearer the camera, a green one behind it, made in
    the other order: the red covers the green where they overlap; in a mirror behind them the
    green (nearer the mirror's image camera) covers the red."""
    near, far = glm.vec3(-1.0, 0.0, 0.5), glm.vec3(-1.0, 0.0, -1.0)

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(4.0, 3.0)), Mirror())
        for place, colour in ((far, (0.0, 1.0, 0.0, 1.0)), (near, (1.0, 0.0, 0.0, 1.0))):
            world.spawn(Transform(position=place), still(size=0.6, texture=solid(), blend="alpha", color=colour,
                                                         end_color=colour))
    runner, image = render(scene, build)
    col, row = runner.project(near)
    np.testing.assert_allclose(image[row, col], [1.0, 0.0, 0.0], atol=0.02)
    col, row = runner.project(glm.vec3(far.x, far.y, -5.0 - far.z))
    pixel = image[row, col]
    assert pixel[1] > 0.5 and pixel[1] > 3.0 * pixel[0], pixel


@pytest.mark.parametrize("path", ["per_mirror", "batched"])
def test_particles_are_drawn_among_the_glass_by_distance(scene, path):
    """A half-clear pane in front of a spark, a mirror behind both: seen directly the spark is
    behind the pane (its light through it: 1 - alpha of it); in the mirror the spark is
    nearer the mirror's image camera than the pane, so the mirror's view adds it whole, and
    the camera sees that reflection through the pane once (1 - alpha again, not twice)."""
    spark, alpha = glm.vec3(-1.0, 0.0, -1.0), 0.5

    def build(glass, particle):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            backdrop(world, (0.05, 0.05, 0.05))
            world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(6.0, 4.0)), Mirror())
            if glass:
                world.spawn(Transform(position=glm.vec3(-1.0, 0.0, 0.0)), MeshRef(quad(1.5, 1.5)),
                            Material(color=(0.2, 0.3, 0.8, alpha), unlit=True))
            if particle:
                world.spawn(Transform(position=spark), still(size=0.3, texture=solid(), color=(0.6, 0.6, 0.6, 1.0),
                                                             end_color=(0.6, 0.6, 0.6, 1.0)))
        return make
    added = {}
    for glass in (False, True):
        images = []
        for particle in (False, True):
            runner = scene(build(glass, particle), SIZE)
            runner.engine.renderer.antialias = "off"
            runner.engine.reflection_system.path = path
            runner.frame()
            images.append(srgb_to_linear(runner.frame().astype(np.float64) / 255.0))
        col, row = runner.project(spark)
        ref_col, ref_row = runner.project(glm.vec3(spark.x, spark.y, -5.0 - spark.z))
        added[glass] = ((images[1] - images[0])[row - 1:row + 2, col - 1:col + 2].mean(),
                        (images[1] - images[0])[ref_row - 1:ref_row + 2, ref_col - 1:ref_col + 2].mean())
    assert added[False][0] > 0.3 and added[False][1] > 0.1
    assert added[True][0] / added[False][0] == pytest.approx(1.0 - alpha, abs=0.05)  # behind the pane
    assert added[True][1] / added[False][1] == pytest.approx(1.0 - alpha, abs=0.05)  # the pane once, in front


def test_world_space_particles_go_through_open_portals(scene):
    """Portal A at the origin and its partner B 10 m along x, both facing +z: a particle flying
    into A's rectangle comes out of B, carried as a traveller is (mirrored across, flying out of
    B's front); one flying past A's edge, and a local-space one, are not carried."""
    from engine.assets.portals import spawn_portal_pair

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0), fov=FOV)
        spawn_portal_pair(world, (0.0, 1.0, 0.0), None, (10.0, 1.0, 0.0), None, size=(2.0, 3.0))
        flight = dict(rate=0.0, burst=1, speed=2.0, spread=0.0, direction=(0.0, 0.0, -1.0), lifetime=100.0)
        world.into = world.spawn(Transform(position=glm.vec3(0.2, 1.1, 1.0)), ParticleEmitter(**flight))
        world.past = world.spawn(Transform(position=glm.vec3(3.0, 1.1, 1.0)), ParticleEmitter(**flight))
        world.local = world.spawn(Transform(position=glm.vec3(-0.2, 1.1, 1.0)),
                                  ParticleEmitter(**flight, space="local"))
    runner = scene(build, (64, 48))
    for _ in range(61):  # born at the first frame's end, then 60 frames: 1 s of flight
        runner.frame(1.0 / 60.0)
    clouds = runner.engine.stages["particles"].clouds
    into, past, local = (clouds[getattr(runner.world, name)][0] for name in ("into", "past", "local"))
    # Unwrapped it would be at (0.2, 1.1, -1): 1 m behind A; carried, 1 m in front of B, x mirrored.
    np.testing.assert_allclose(into.position[0], [10.0 - 0.2, 1.1, 1.0], atol=1e-4)
    np.testing.assert_allclose(into.velocity[0], [0.0, 0.0, 2.0], atol=1e-5)
    np.testing.assert_allclose(past.position[0], [3.0, 1.1, -1.0], atol=1e-4)
    np.testing.assert_allclose(local.position[0], [0.0, 0.0, -2.0], atol=1e-4)  # (its own frame: not carried)
    # Each counts the portals it went through: a ribbon's rows carry the count (its frame's
    # place), so the band breaks between a point carried and one not.
    assert list(into.crossed) == [1.0] and list(past.crossed) == [0.0]
    emitter = runner.world.get(runner.world.into, ParticleEmitter)
    emitter.ribbon = True
    assert into.rows(emitter, glm.mat4(1.0))[0, ROW_FRAME] == 1.0


def test_particles_through_a_pair_of_two_scales_fly_on_at_the_speed_its_view_showed(scene):
    """B scaled 2 by its Transform: the view through A shows B's side at half size, so a
    particle carried comes out twice as far from B's centre, twice as fast and drawn twice
    as big, as a traveller does.  Wherever in the frame it crossed, 1 s of flight (0.5 s to A at 2 m/s, the rest at
    4 m/s, its overshoot doubled) ends 2 m in front of B."""
    from engine.assets.portals import spawn_portal_pair

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0), fov=FOV)
        _, b = spawn_portal_pair(world, (0.0, 1.0, 0.0), None, (10.0, 1.0, 0.0), None, size=(2.0, 3.0))
        world.get(b, Transform).scale = glm.vec3(2.0)
        flight = dict(rate=0.0, burst=1, speed=2.0, spread=0.0, direction=(0.0, 0.0, -1.0), lifetime=100.0)
        world.into = world.spawn(Transform(position=glm.vec3(0.2, 1.1, 1.0)), ParticleEmitter(**flight))
        world.past = world.spawn(Transform(position=glm.vec3(3.0, 1.1, 1.0)), ParticleEmitter(**flight))
    runner = scene(build, (64, 48))
    for _ in range(61):
        runner.frame(1.0 / 60.0)
    clouds = runner.engine.stages["particles"].clouds
    into, past = (clouds[getattr(runner.world, name)][0] for name in ("into", "past"))
    # A-local (0.2, 0.1) comes out mirrored and doubled about B: (10 - 0.4, 1 + 0.2).
    np.testing.assert_allclose(into.position[0], [10.0 - 0.4, 1.2, 2.0], atol=1e-4)
    np.testing.assert_allclose(into.velocity[0], [0.0, 0.0, 4.0], atol=1e-5)
    # Drawn twice the size of its twin that flew past A's edge (the same age, the same emitter).
    emitter = runner.world.get(runner.world.into, ParticleEmitter)
    sizes = [cloud.rows(emitter, glm.mat4(1.0))[0, ROW_SIZE] for cloud in (into, past)]
    assert sizes[1] > 0.0 and sizes[0] == pytest.approx(2.0 * sizes[1], rel=1e-6)


def test_a_portal_sliding_over_hanging_particles_swallows_those_in_its_rectangle(scene):
    """Particles hanging still (no speed, no gravity) in front of portal A, one inside its
    rectangle's reach and one beside it: A slides forwards over both, 0.25 m a frame (a slide,
    engine.rules.portal_gates), and takes in the one it passes over, as it takes a traveller:
    carried to B (half a metre behind A then, half a metre in front of B, x mirrored), counted
    as crossed; the one beside it stays where it hangs."""
    from engine.assets.portals import spawn_portal_pair

    def build(world):
        look_from(world, (0.0, 1.0, 6.0), (0.0, 1.0, 0.0), fov=FOV)
        world.a, _ = spawn_portal_pair(world, (0.0, 1.0, 0.0), None, (10.0, 1.0, 0.0), None, size=(2.0, 3.0))
        hang = dict(rate=0.0, burst=1, speed=0.0, spread=0.0, gravity=0.0, lifetime=100.0)
        world.inside = world.spawn(Transform(position=glm.vec3(0.3, 1.2, 0.5)), ParticleEmitter(**hang))
        world.beside = world.spawn(Transform(position=glm.vec3(1.6, 1.2, 0.5)), ParticleEmitter(**hang))
    runner = scene(build, (64, 48))
    runner.frame(1.0 / 60.0)
    runner.frame(1.0 / 60.0)  # born
    door = runner.world.get(runner.world.a, Transform)
    for step in range(1, 5):  # A at z 0.25, 0.5, 0.75, 1.0: past the particles at 0.5
        door.position = glm.vec3(0.0, 1.0, 0.25 * step)
        runner.frame(1.0 / 60.0)
    clouds = runner.engine.stages["particles"].clouds
    inside, beside = (clouds[getattr(runner.world, name)][0] for name in ("inside", "beside"))
    # Carried when A stood at 0.75: 0.25 m behind it, A-local (0.3, 0.2, -0.25), so 0.25 m in
    # front of B with x mirrored.
    np.testing.assert_allclose(inside.position[0], [10.0 - 0.3, 1.2, 0.25], atol=1e-4)
    assert list(inside.crossed) == [1.0]
    np.testing.assert_allclose(beside.position[0], [1.6, 1.2, 0.5], atol=1e-5)
    assert list(beside.crossed) == [0.0]


@pytest.mark.parametrize("drag", [0.0, 0.5])
def test_the_editors_outline_is_the_launch_cone_as_far_as_a_particle_flies(drag):
    """``reach_outline`` of a selected emitter (shell/handles.py): a cone from the emitter
    about its direction turned as the entity is, its rim ``spread`` from the axis, as long as
    the fastest particle flies in its longest life (speed x life; with drag, speed / k x
    (1 - e^-k life))."""
    from engine.core.world import World
    from shell.handles import reach_outline

    world = World("outline")
    turn = glm.angleAxis(glm.radians(90.0), glm.vec3(0.0, 0.0, 1.0))  # the emitter's +y to -x
    entity = world.spawn(Transform(position=glm.vec3(1.0, 2.0, 3.0), rotation=turn),
                         ParticleEmitter(speed=(1.0, 2.0), lifetime=(0.5, 1.5), spread=25.0, drag=drag))
    eye = glm.lookAt(glm.vec3(1.0, 2.0, 10.0), glm.vec3(1.0, 2.0, 3.0), glm.vec3(0.0, 1.0, 0.0))
    outline = reach_outline(world, entity, glm.perspective(glm.radians(60.0), 1.0, 0.1, 100.0) * eye, (400, 400))
    reach = 2.0 * 1.5 if drag == 0.0 else 2.0 / drag * (1.0 - math.exp(-drag * 1.5))
    apex, axis = glm.vec3(1.0, 2.0, 3.0), glm.vec3(-1.0, 0.0, 0.0)
    rim = outline.world[0]
    for point in rim:
        arm = point - apex
        assert glm.length(arm) == pytest.approx(reach, rel=1e-5)
        assert math.degrees(math.acos(glm.dot(glm.normalize(arm), axis))) == pytest.approx(25.0, abs=1e-3)
    assert all(edge[0] == apex for edge in outline.world[1:])


@pytest.mark.parametrize("distance", [3.0, 12.0])
def test_an_orthographic_view_draws_a_particle_its_size_at_any_distance(scene, distance):
    """Seen by an orthographic camera 4 m tall, a 1 m particle's round spot spans a quarter of
    the view's height wherever it stands along the axis (its alpha the spot's formula, by the
    pixels' offsets across the view, not by any eye)."""
    from components import Camera, look_rotation

    height, colour = 4.0, np.array((0.5, 0.3, 0.1))

    def build(world):
        eye = glm.vec3(0.0, 0.0, distance)
        world.spawn(Transform(position=eye, rotation=look_rotation(-eye)),
                    Camera(projection="orthographic", ortho_height=height, near=0.1, far=40.0))
        backdrop(world)
        world.spawn(Transform(), still(size=1.0, color=(*colour, 1.0)))
    _, image = render(scene, build)
    w, h = SIZE
    x = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * (height / 2.0) * (w / h)
    y = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * (height / 2.0)
    qx, qy = np.meshgrid(x, y)
    spot = np.maximum(1.0 - (qx ** 2 + qy ** 2) / 0.25, 0.0) ** 2
    np.testing.assert_allclose(image, np.array(WALL) + spot[..., None] * colour, atol=0.012)


def test_a_puff_texture_is_a_soft_lumpy_disc_a_level_file_names(tmp_path):
    """``puff_texture``: white, its alpha zero outside the inscribed circle and at most the
    round spot's falloff inside, not flat (lumps), the same for the same seed and not for
    another; a level file names one as ``{ puff = [size, seed] }`` and saves it so."""
    from engine.assets.level_file import load_level, save_level
    from engine.assets.texture_data import puff_texture
    from engine.core.world import World

    puff = puff_texture(64, 3)
    alpha = puff.pixels[..., 3].astype(float) / 255.0
    centres = (np.arange(64) + 0.5) / 64 - 0.5
    r2 = 4.0 * (centres[None, :] ** 2 + centres[:, None] ** 2)
    falloff = np.maximum(1.0 - r2, 0.0) ** 2
    assert (puff.pixels[..., :3] == 255).all() and (alpha[r2 >= 1.0] == 0.0).all()
    assert (alpha <= falloff + 1.0 / 255.0).all()
    inner = alpha[r2 < 0.25] / falloff[r2 < 0.25]
    assert inner.std() > 0.05  # lumpy, not the plain spot
    np.testing.assert_array_equal(puff_texture(64, 3).pixels, puff.pixels)
    assert not np.array_equal(puff_texture(64, 4).pixels, puff.pixels)
    path = tmp_path / "smoke.toml"
    path.write_text(LEVEL.replace("texture = { checker = [16, 2] }", "texture = { puff = [64, 3] }"))
    world = World("smoke")
    names = load_level(path).spawn(world)
    np.testing.assert_array_equal(world.get(names["torch"], ParticleEmitter).texture.pixels, puff.pixels)
    saved = save_level(world, tmp_path / "saved.toml", names, name="sparks")
    assert "texture = { puff = [64, 3] }" in saved.read_text()


def test_culling_an_alpha_clouds_particles_per_view_changes_no_pixel(scene, monkeypatch):
    """A wide alpha cloud about a mirror, partly out of the camera's and the mirror's views:
    each view draws only the particles that can reach it (``in_view``), and the picture is the
    same, pixel for pixel, as with every particle drawn in every view; some were left out."""
    import engine.render.particle_draw as particle_draw

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(position=glm.vec3(0.0, 0.0, -2.5)), MeshRef(quad(2.0, 1.5)), Mirror())
        world.spawn(Transform(), ParticleEmitter(rate=0.0, burst=400, shape="box", extent=(6.0, 3.0, 3.0),
                                                 speed=0.0, lifetime=100.0, size=0.3, blend="alpha",
                                                 color=(0.9, 0.5, 0.2, 0.6), end_color=(0.9, 0.5, 0.2, 0.6)))
    kept = []
    real = particle_draw.in_view

    def counting(rows, view):
        found = real(rows, view)
        kept.append((int(found.sum()), len(rows)))
        return found
    monkeypatch.setattr(particle_draw, "in_view", counting)
    _, culled = render(scene, build)
    assert kept and any(k < n for k, n in kept)  # (some views left some out)
    monkeypatch.setattr(particle_draw, "in_view", lambda rows, view: np.ones(len(rows), bool))
    _, whole = render(scene, build)
    np.testing.assert_array_equal(culled, whole)


def test_a_still_alpha_cloud_is_not_sorted_and_written_again_for_the_same_view(scene, monkeypatch):
    """Paused (dt 0) and seen by the same one view, an alpha emitter's buffer already holds its
    rows in that view's order: no cull, sort or write again; moving on, it is done again."""
    import engine.render.particle_draw as particle_draw

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.spawn(Transform(), ParticleEmitter(rate=300.0, speed=0.5, spread=60.0, blend="alpha", size=0.3))
    calls = []
    real = particle_draw.in_view
    monkeypatch.setattr(particle_draw, "in_view", lambda rows, view: calls.append(1) or real(rows, view))
    runner = scene(build, SIZE)
    for _ in range(4):
        runner.frame(1.0 / 60.0)
    moving = len(calls)
    assert moving == 4  # (one view: once a frame while it moves)
    paused = runner.frame(0.0), runner.frame(0.0)
    assert len(calls) == moving  # the rows and the view the buffer was sorted for, both unchanged
    np.testing.assert_array_equal(paused[0], paused[1])
    runner.frame(1.0 / 60.0)
    assert len(calls) == moving + 1


def ribbon_band(half_width: float, x_range: tuple[float, float], shape=SIZE) -> np.ndarray:
    """A straight untextured ribbon's alpha at each pixel's centre: the round spot's falloff
    across it, (1 - (d / half_width)^2)^2 with d the distance from its line (y = 0, z = 0),
    within ``x_range`` along it (None outside: not compared), for the camera at EYE looking down -z."""
    w, h = shape
    half_h = math.tan(math.radians(FOV / 2.0))
    x = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) * half_h * (w / h) * EYE.z
    y = (1.0 - (np.arange(h) + 0.5) / h * 2.0) * half_h * EYE.z
    qx, qy = np.meshgrid(x, y)
    band = np.maximum(1.0 - (qy / half_width) ** 2, 0.0) ** 2
    return np.where((qx >= x_range[0]) & (qx <= x_range[1]), band, np.nan)


def test_a_ribbon_joins_its_particles_into_a_band_facing_the_view(scene):
    """An emitter swept along x leaves still points on a line; joined (``ribbon``), they are a
    band as wide as their size, soft across as the round spot (its formula across the line,
    pixel by pixel, away from its ends), added to the wall."""
    colour = np.array((0.5, 0.3, 0.1))

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        backdrop(world)
        world.emitter = world.spawn(Transform(position=glm.vec3(-1.6, 0.0, 0.0)), ParticleEmitter(
            rate=60.0, speed=0.0, lifetime=1000.0, size=0.5, color=(*colour, 1.0), end_color=(*colour, 1.0),
            ribbon=True))
    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    for step in range(33):
        runner.world.get(runner.world.emitter, Transform).position = glm.vec3(-1.6 + 0.1 * step, 0.0, 0.0)
        runner.frame(1.0 / 60.0)
    image = srgb_to_linear(runner.frame(0.0).astype(np.float64) / 255.0)
    band = ribbon_band(0.25, (-1.3, 1.3))
    inside = ~np.isnan(band)
    assert (band[inside] > 0.5).sum() > 150  # (a band the test can see)
    expected = np.array(WALL) + np.nan_to_num(band)[..., None] * colour
    np.testing.assert_allclose(image[inside], expected[inside], atol=0.012)
    assert runner.stats.particles == 33


def test_a_ribbon_bends_through_its_points_with_no_gap_and_shows_in_a_mirror(scene):
    """Swept round a circle, the band's middle line is lit all the way round what it drew
    (its segments meet at each point: no crack at a bend), and a mirror beside it shows it
    (its pixels there differ from the same scene's without the emitter)."""
    def build(with_ribbon):
        def make(world):
            look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
            backdrop(world)
            world.spawn(Transform(position=glm.vec3(-1.7, 0.0, -0.3),  # to the left, turned towards the ring
                                  rotation=glm.angleAxis(glm.radians(50.0), glm.vec3(0, 1, 0))),
                        MeshRef(quad(1.0, 2.0)), Mirror())
            world.emitter = world.spawn(Transform(position=glm.vec3(0.8, 0.0, 0.0)), ParticleEmitter(
                rate=60.0, speed=0.0, lifetime=1000.0, size=0.12, color=(3.0, 3.0, 3.0, 1.0),
                end_color=(3.0, 3.0, 3.0, 1.0), ribbon=True, playing=with_ribbon))
        return make

    images = {}
    for with_ribbon in (True, False):
        runner = scene(build(with_ribbon), (192, 144))
        runner.engine.renderer.antialias = "off"
        for step in range(48):  # three quarters of a turn
            a = 2.0 * math.pi * step / 64.0
            runner.world.get(runner.world.emitter, Transform).position = glm.vec3(0.8 * math.cos(a),
                                                                                  0.8 * math.sin(a), 0.0)
            runner.frame(1.0 / 60.0)
        images[with_ribbon] = runner.frame(0.0).astype(int)
    image = images[True]
    for k in range(1, 94):  # the middle line, between the drawn points
        a = 2.0 * math.pi * 47.0 / 64.0 * k / 94.0
        x, y = runner.project((0.8 * math.cos(a), 0.8 * math.sin(a), 0.0))
        assert image[y, x].min() > 200, (k, image[y, x])
    mx, my = runner.project(glm.vec3(-1.7, 0.0, -0.3))
    mirror_region = (slice(max(my - 40, 0), my + 40), slice(max(mx - 12, 0), mx + 12))
    assert (np.abs(images[True][mirror_region] - images[False][mirror_region]).max(axis=2) > 40).sum() > 20



def beyond_b(carry, x, y, z) -> glm.vec3:
    """The point beyond portal B that the view through A sees at (x, y, z)."""
    return glm.vec3(carry * glm.vec4(x, y, z, 1.0))


PORTAL_KINDS = {
    "lit": dict(size=0.8, color=(*ALBEDO, 1.0), end_color=(*ALBEDO, 1.0), lit=True, translucency=0.3, blend="alpha",
                texture=solid()),
    "ribbon": dict(size=0.3, color=(0.5, 0.3, 0.1, 1.0), end_color=(0.5, 0.3, 0.1, 1.0), lit=True, ribbon=True,
                   rate=60.0, burst=0),
    "soft": dict(size=1.2, color=(0.5, 0.5, 0.5, 1.0), end_color=(0.5, 0.5, 0.5, 1.0), texture=solid(), softness=1.0),
}


@pytest.mark.parametrize("kind, path", [("lit", "per_mirror"), ("lit", "batched"), ("ribbon", "per_mirror"),
                                        ("ribbon", "batched"), ("soft", "per_mirror")])
def test_a_lit_particle_a_ribbon_and_a_soft_particle_show_through_a_portal_as_from_the_eye_it_carries(scene, kind,
                                                                                                       path):
    """What lies beyond portal B (a wall, a lamp, and a lit particle, a lit ribbon swept along
    a line, or a soft particle 0.4 m in front of the wall) rendered through portal A, and the
    same world without portals rendered directly from the eye the pair carries the camera's
    to: inside A's opening the two are the same pixels (the portal's view lights the particle
    by the world's lights, faces the ribbon to its own eye, fades the soft particle by its own
    depth); and the particle is there (the opening differs from the same world without it)."""
    def content(emitter):
        def make(world, carry):
            turn = glm.quat_cast(carry)
            world.spawn(Transform(position=beyond_b(carry, 0.0, 0.0, -5.0 if kind == "soft" else -6.0),
                                  rotation=turn), MeshRef(quad(40.0, 40.0)), Material(color=(0.4, 0.4, 0.4, 1.0)))
            world.spawn(HemisphereLight(sky=(0.3, 0.35, 0.5), ground=(0.2, 0.15, 0.1), intensity=1.0))
            world.spawn(Transform(position=beyond_b(carry, 1.0, 1.0, -2.5)), PointLight(intensity=12.0, range=20.0))
            if emitter:
                world.emitter = world.spawn(Transform(position=beyond_b(carry, -0.2, 0.1, -4.6 if kind == "soft"
                                                                        else -3.3), rotation=turn),
                                            still(**PORTAL_KINDS[kind]))
        return make

    def sweep(runner, k):   # (a ribbon's emitter swept along x, as seen through A, leaving its points)
        if kind == "ribbon":
            carry = pair_carry()
            runner.world.get(runner.world.emitter, Transform).position = beyond_b(carry, -0.9 + 0.06 * k,
                                                                                  -0.2 + 0.03 * k, -3.3)
    frames = 30 if kind == "ribbon" else 2
    through, direct, opening, _ = through_a_portal_and_from_its_eye(scene, content(True), path=path, frames=frames,
                                                                    step=sweep)
    without, _, _, _ = through_a_portal_and_from_its_eye(scene, content(False), path=path)
    shown = np.abs(through - without).max(axis=-1)[opening]
    assert (shown > 0.05).sum() > 40, (shown > 0.05).sum()   # (the particle is there)
    apart = np.abs(through - direct).max(axis=-1)[opening]
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.04, (np.quantile(apart, 0.99), apart.max())


MIRROR_AT = glm.vec3(0.0, 0.0, -2.5)
MIRROR_TURN = glm.angleAxis(glm.radians(30.0), glm.vec3(0.0, 1.0, 0.0))   # (its view 60 degrees off the camera's)
MIRROR_SIZE = (3.0, 2.4)
MIRROR_EYE = glm.vec3(0.0, 0.0, 1.0)   # (3.5 m before the mirror, looking at its middle)


def mirrored_point(point) -> glm.vec3:
    """``point``'s image in the plane of ``in_a_mirror_and_from_its_eye``'s mirror."""
    normal = MIRROR_TURN * glm.vec3(0.0, 0.0, 1.0)
    point = glm.vec3(point)
    return point - normal * (2.0 * glm.dot(point - MIRROR_AT, normal))


def in_a_mirror_and_from_its_eye(scene, content, *, path="per_mirror", frames=2, size=(128, 96), step=None,
                                 margin=3):
    """What ``content(world)`` spawns in front of a mirror (at MIRROR_AT, turned MIRROR_TURN
    about y: it shows the room off to the camera's right, out of the camera's own sight)
    rendered twice: in the mirror from MIRROR_EYE (``path`` the reflection path), and directly from
    the eye's image in the mirror's plane (looking at the target's image; the mirror upright,
    so up stays up) in a world with no mirror, that picture turned left for right (the mirror
    view's right is the image camera's left); linear images, and the pixels at least
    ``margin`` in from the edges of the mirror (by the main view's rays), where the two must
    agree.  ``step(runner, k)`` runs before each frame ``k``."""
    from tests.support import pixel_rays

    images, runners = {}, {}
    for mirrored in (True, False):
        def build(world, mirrored=mirrored):
            if mirrored:
                look_from(world, MIRROR_EYE, MIRROR_AT, fov=FOV)
                world.mirror = world.spawn(Transform(position=MIRROR_AT, rotation=MIRROR_TURN),
                                           MeshRef(quad(*MIRROR_SIZE)), Mirror())
            else:
                look_from(world, mirrored_point(MIRROR_EYE), mirrored_point(MIRROR_AT), fov=FOV)
            content(world)
        runner = scene(build, size)
        runner.engine.renderer.antialias = "off"
        runner.engine.reflection_system.path = path
        for k in range(frames):
            if step is not None:
                step(runner, k)
            image = runner.frame(1.0 / 60.0 if k < frames - 1 else 0.0)
        images[mirrored], runners[mirrored] = srgb_to_linear(image.astype(np.float64) / 255.0), runner
    assert runners[True].stats.reflection_views >= 1 and runners[True].stats.reflection_path == path
    origin, rays = pixel_rays(runners[True].engine.main_view, size)
    to_mirror = np.linalg.inv(np.array(glm.mat4_cast(MIRROR_TURN).to_list(), np.float64).T[:3, :3])
    local_origin, local_rays = to_mirror @ (origin - np.array(MIRROR_AT)), rays @ to_mirror.T
    hit = local_origin + local_rays * (-local_origin[2] / local_rays[..., 2])[..., None]
    pixel = 2.0 * math.tan(math.radians(FOV / 2.0)) * float(np.linalg.norm(origin - np.array(MIRROR_AT))) / size[1]
    inside = (np.abs(hit[..., 0]) < MIRROR_SIZE[0] / 2 - margin * pixel) \
        & (np.abs(hit[..., 1]) < MIRROR_SIZE[1] / 2 - margin * pixel)
    surface = runners[True].engine.renderer.targets.read_surface_ids()
    assert (surface[inside] == runners[True].world.mirror).all()   # (the rays' mirror is the engine's)
    return images[True], images[False][:, ::-1], inside, runners


MIRROR_KINDS = {
    "billboard": dict(size=0.9, color=(0.8, 0.6, 0.3, 1.0), end_color=(0.8, 0.6, 0.3, 1.0)),
    "lit": dict(size=0.9, color=(*ALBEDO, 1.0), end_color=(*ALBEDO, 1.0), lit=True, translucency=0.3, blend="alpha",
                texture=solid()),
    "ribbon": dict(size=0.3, color=(0.5, 0.3, 0.1, 1.0), end_color=(0.5, 0.3, 0.1, 1.0), lit=True, ribbon=True,
                   rate=60.0, burst=0),
}
# Off to the camera's right, out of its sight, where the mirror's view looks (60 degrees off
# the camera's way: a particle facing the camera is seen there at half its width).
MIRROR_SEEN = glm.vec3(2.2, 0.1, -1.3)


@pytest.mark.parametrize("kind, path", [("billboard", "per_mirror"), ("lit", "per_mirror"), ("lit", "batched"),
                                        ("ribbon", "per_mirror"), ("ribbon", "batched")])
def test_a_billboard_a_lit_particle_and_a_ribbon_show_in_a_mirror_as_from_the_eyes_image(scene, kind, path):
    """What stands off to the camera's right (a lit wall, a hemisphere and a lamp on the
    mirror's side, and a round spot, a lit particle, or a lit ribbon swept up and across),
    seen only in a mirror turned 30 degrees, and the same world without the mirror rendered
    directly from the eye's image in the mirror's plane, turned left for right: inside the
    mirror the two are the same pixels (the mirror's view turns the spot to its own eye, lights
    the particle's side that eye sees, faces the ribbon to it); and the particle is there (the
    mirror differs from the same world without it), out of the camera's own sight."""
    towards = glm.normalize(mirrored_point(MIRROR_EYE) - MIRROR_SEEN)   # (the way to the eye's image)
    facing = look_rotation(-towards)   # (the wall behind, facing the eye's image)

    def content(emitter):
        def make(world):
            world.spawn(Transform(position=MIRROR_SEEN - towards * 3.0, rotation=facing), MeshRef(quad(40.0, 40.0)),
                        Material(color=(0.15, 0.15, 0.15, 1.0)))
            world.spawn(HemisphereLight(sky=(0.3, 0.35, 0.5), ground=(0.2, 0.15, 0.1), intensity=1.0))
            world.spawn(Transform(position=MIRROR_SEEN + towards * 1.8 + glm.vec3(0.0, 0.8, 0.0)),
                        PointLight(intensity=10.0, range=20.0))
            if emitter:
                world.emitter = world.spawn(Transform(position=MIRROR_SEEN), still(**MIRROR_KINDS[kind]))
        return make

    def sweep(runner, k):   # (a ribbon's emitter swept across the way to the eye's image and up)
        if kind == "ribbon":
            across = glm.normalize(glm.cross(towards, glm.vec3(0.0, 1.0, 0.0)))
            runner.world.get(runner.world.emitter, Transform).position = \
                MIRROR_SEEN + across * (-0.8 + 0.055 * k) + glm.vec3(0.0, -0.3 + 0.02 * k, 0.0)
    frames = 30 if kind == "ribbon" else 2
    shown, direct, inside, runners = in_a_mirror_and_from_its_eye(scene, content(True), path=path, frames=frames,
                                                                  step=sweep)
    without, _, _, _ = in_a_mirror_and_from_its_eye(scene, content(False), path=path)
    assert not (0 <= runners[True].project(MIRROR_SEEN)[0] < runners[True].size[0])   # (out of the camera's own sight)
    there = np.abs(shown - without).max(axis=-1)[inside]
    assert (there > 0.05).sum() > 40, (there > 0.05).sum()   # (the particle is there)
    apart = np.abs(shown - direct).max(axis=-1)[inside]
    assert np.quantile(apart, 0.99) <= 0.01 and apart.max() <= 0.04, (np.quantile(apart, 0.99), apart.max())


@pytest.mark.parametrize("blend", ["alpha", "additive"])
def test_a_particle_casts_no_shadow_where_a_card_its_size_does(scene, blend):
    """A solid white particle 0.8 m across, 1.5 m over a floor under a sun slanting along +x:
    the floor where its shadow would fall (1.5 x 0.5 m along x from under it, well away from
    where the camera sees the particle itself) is as bright as with no particle; a card of
    its size lying there (the test's control) darkens those same pixels."""
    white = TextureData(np.full((4, 4, 4), 255, np.uint8), name="white")
    centre = glm.vec3(0.0, 1.5, 0.0)
    sun = glm.vec3(0.5, -1.0, 0.0)
    under = centre + sun * 1.5   # where the sun's ray through its centre meets the floor

    def build(thing):
        def make(world):
            look_from(world, (-2.0, 3.0, 4.0), (0.5, 0.5, 0.0), fov=50.0)
            world.spawn(DirectionalLight(direction=tuple(sun), intensity=2.0))
            world.spawn(Transform(position=(0.0, -0.05, 0.0)), MeshRef(box((8.0, 0.1, 8.0))),
                        Material(color=(0.6, 0.6, 0.6, 1.0)))   # (its top at y = 0)
            if thing == "particle":
                world.spawn(Transform(position=centre), still(size=0.8, color=(1.0, 1.0, 1.0, 1.0),
                                                              end_color=(1.0, 1.0, 1.0, 1.0), blend=blend,
                                                              texture=white))
            elif thing == "card":
                world.spawn(Transform(position=centre, rotation=glm.angleAxis(-math.pi / 2, glm.vec3(1, 0, 0))),
                            MeshRef(quad(0.8, 0.8)), Material(color=(1.0, 1.0, 1.0, 1.0)))
        return make

    shown = {}
    for thing in ("none", "particle", "card"):
        runner, shown[thing] = render(scene, build(thing))
    col, row = runner.project(under)
    patch = np.s_[row - 2:row + 3, col - 2:col + 3]
    np.testing.assert_allclose(shown["particle"][patch], shown["none"][patch], atol=0.004)
    assert (shown["card"][patch] < shown["none"][patch] - 0.1).all()   # (a caster there darkens it)
    col, row = runner.project(centre)
    assert shown["particle"][row, col].min() > shown["none"][row, col].max() + 0.1   # (the particle is drawn)


def test_a_monitors_picture_shows_a_particle_where_its_camera_projects_it(scene):
    """A bright particle before a monitor's camera (the studio of tests/test_monitors.py: a
    black world, the lens looking down -z, its screen behind it): the picture is bright at the
    pixel the lens's own projection puts the particle's centre on, and unchanged half a metre
    beside it, against the same studio without the particle."""
    from components import Monitor
    from engine.render.views import camera_view
    from tests.test_monitors import LENS_AT, LENS_FOV, PICTURE, picture, run, studio

    at = glm.vec3(0.6, 1.3, -4.0)
    shown = {}
    for with_particle in (False, True):
        build, held = studio(Monitor(size=PICTURE), box_at=(0.0, -20.0, 0.0))   # (the studio's box out of sight)

        def made(world, build=build, with_particle=with_particle):
            build(world)
            if with_particle:
                world.spawn(Transform(position=at), still(size=0.5, color=(0.8, 0.8, 0.8, 1.0)))
        runner, _ = run(scene, made, 2)
        shown[with_particle] = picture(runner, held)[..., :3]
    view = camera_view(glm.translate(glm.vec3(LENS_AT)), LENS_FOV, 0.1, 100.0, PICTURE)

    def pixel(point):
        clip = view.view_proj * glm.vec4(point, 1.0)
        return (int((clip.x / clip.w * 0.5 + 0.5) * PICTURE[0]), int((0.5 - clip.y / clip.w * 0.5) * PICTURE[1]))

    col, row = pixel(at)
    assert shown[True][row, col].min() > shown[False][row, col].max() + 0.5
    col, row = pixel(at - glm.vec3(0.5, 0.0, 0.0))
    np.testing.assert_allclose(shown[True][row, col], shown[False][row, col], atol=0.01)


def test_a_lit_particle_past_the_suns_map_is_lit_whatever_its_atlas_holds_there(scene):
    """The sun's map is fitted to the opaque things (``Renderer.level_bounds``): a small box
    beside it.  A particle (not in that box) past the map's square has no caster between it and
    the sun, and is lit as with the sun casting no shadow: its lookup reads nothing of the
    atlas, where the next tile lies (another sun's map, a ring's, or texels no draw wrote: the
    test clears the whole atlas to the near depth before the map is drawn again, as such
    texels may hold)."""
    sun = glm.normalize(glm.vec3(0.4, -0.3, -1.0))

    def build(world):
        look_from(world, EYE, (0.0, 0.0, 0.0), fov=FOV)
        world.resources["sun"] = world.spawn(DirectionalLight(direction=sun, intensity=3.0))
        world.spawn(HemisphereLight(sky=(0.3, 0.35, 0.5), ground=(0.2, 0.15, 0.1), intensity=1.0))
        world.spawn(Transform(), still(size=1.0, color=(*ALBEDO, 1.0), end_color=(*ALBEDO, 1.0), lit=True,
                                       translucency=0.3, blend="alpha", texture=solid()))
        world.spawn(Transform(position=glm.vec3(-1.5, -1.5, -0.5)), MeshRef(box((1.0, 1.0, 1.0))), Material())

    runner = scene(build, SIZE)
    runner.engine.renderer.antialias = "off"
    light = runner.world.get(runner.world.resources["sun"], DirectionalLight)
    light.shadows = False
    runner.frame()
    no_shadow = runner.frame()
    light.shadows = True
    runner.frame()   # (the atlas made)
    maps = runner.engine.renderer.shadows
    shadowed = drawn_over_near_depth(runner, maps.atlas, lambda on: setattr(light, "shadows", on))
    # The particle's middle lies past the map's square, on the side of the next tile.
    matrix = np.array(maps.block[:16], np.float64).reshape(4, 4)   # (glm's columns: numpy rows)
    uv = (np.array([0.0, 0.0, 0.0, 1.0]) @ matrix)[:2]
    corner, side = np.array(maps.directional_tiles[0][:2]), maps.directional_tiles[0][2]
    assert (uv > corner + side).any() and (uv < 1.0).all(), (uv, corner, side)
    middle = (slice(34, 38), slice(46, 50))
    assert shadowed[middle].mean() > 120   # (8-bit: the sunlit particle, not a dark frame)
    np.testing.assert_array_equal(shadowed, no_shadow)
