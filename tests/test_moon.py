"""A moon (``DirectionalLight(body="moon")``): its disc drawn by a generated sky as the CPU's
twin draws it (engine/render/sky.py moon_share: Lommel and Seeliger's ball lit from the sun),
its phases against the lit share of a ball written out here, never the sky's sun, its light
reddened by an atmosphere as the sun's, in the sky's light, where a ``TimeOfDay`` puts it
(a full moon opposite the sun, a first quarter south at sunset), and the Earth's light on its
dark side (earthshine) against the Earth's albedo, size and phase written out here."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, DirectionalLight, Material, MeshRef, Skybox, TimeOfDay, Transform
from components.time_of_day import SYNODIC_MONTH, moon_towards, sun_towards
from engine.assets.mesh import plane
from engine.render.irradiance import generated_sky_sh, project_faces
from engine.render.sky import build_faces, moon_phase, moon_share, sky_model, sky_radiance
from engine.rules.light_rules import SkySun, brightest_directional, sky_sun
from tests.support import look_from, srgb_to_linear
from tests.test_generated_sky import SKY, SUN, _hdr_frame

MOON = glm.normalize(glm.vec3(-0.2, 0.35, -0.9))


def moon_light(towards=MOON, color=(0.9, 0.9, 1.0)) -> DirectionalLight:
    return DirectionalLight(direction=tuple(-towards), color=color, intensity=0.3, body="moon", shadows=False)


def _with_moon(moon=MOON, tint=(0.9, 0.9, 1.0)) -> SkySun:
    """The sky's sun as SKY pins it, with the moon ``moon_light`` makes."""
    return SkySun(tuple(SUN), moon=tuple(moon), moon_tint=tint)


@pytest.mark.parametrize("model", ["gradient", "atmosphere"])
def test_the_moon_is_drawn_as_the_twin_draws_it(scene, model):
    """A 10-degree lens on the moon (the sun pinned 33 degrees from it: a crescent): every
    pixel is the CPU's sky along its ray, the lit part of the disc where the twin puts it."""
    skybox = Skybox(**SKY, model=model, moon_color=(1.2, 1.1, 1.0))

    def build(world):
        world.spawn(moon_light())

    colour, rays, runner = _hdr_frame(scene, skybox, fov=10.0, look=MOON)
    build(runner.world)
    runner.frame()
    from tests.test_generated_sky import _read
    colour, rays = _read(runner)
    want = sky_radiance(skybox, rays, _with_moon())
    np.testing.assert_allclose(colour, want, rtol=6e-3, atol=6e-3)
    plain = sky_radiance(skybox, rays, SkySun(tuple(SUN)))
    lit = (want - plain).max(axis=-1) > 0.1
    assert lit.sum() > 60   # the crescent is in view (the sun 33 degrees from it)


NIGHT_SUN = glm.normalize(glm.vec3(0.6, -0.3, 0.75))   # towards it: 17 degrees below the horizon
NIGHT_MOON = glm.normalize(glm.vec3(-0.5, 0.45, -0.75))


def test_an_atmospheres_air_scatters_the_moons_light_as_the_twin_says(scene):
    """A night under an atmosphere (the sun 17 degrees down), a full moon 27 degrees up: the
    sky pass, 90 degrees wide about the moon (the ground below the horizon too), and the
    sky's cube map are the twin pixel by pixel, the sky-view table drawn a second time at the
    moon's elevation; the air's moonlight is most of the night sky's light (blue, brightest about the moon), and it is
    the moon's light above the air: its disc's colour times its phase's share (a second
    model whose moon is twice as bright sees twice the air's moonlight)."""
    skybox = Skybox(model="atmosphere", sun_direction=tuple(NIGHT_SUN))
    sun = SkySun(tuple(NIGHT_SUN), moon=tuple(NIGHT_MOON), moon_tint=(0.9, 0.9, 1.0))

    def build(world):
        world.spawn(moon_light(NIGHT_MOON))

    colour, rays, runner = _hdr_frame(scene, skybox, fov=90.0, look=NIGHT_MOON)
    build(runner.world)
    runner.frame()
    from tests.test_generated_sky import _read
    colour, rays = _read(runner)
    renderer = runner.engine.renderer
    assert renderer.moon_view is not None and renderer.resource_counts()["moon_view"] == 1
    model = sky_model(skybox, sun)
    assert model.moon_elevation == pytest.approx(math.degrees(math.asin(NIGHT_MOON.y)), abs=0.01)
    want = sky_radiance(skybox, rays, sun)
    np.testing.assert_allclose(colour, want, rtol=6e-3, atol=1e-3)
    runner.frame()   # (the cube map made again a moment after the sky changed)
    from tests.test_generated_sky import _cube_faces
    np.testing.assert_allclose(_cube_faces(runner), build_faces(skybox, sun), rtol=1e-2, atol=2e-3)
    moonless = sky_radiance(skybox, rays, SkySun(tuple(NIGHT_SUN)))
    air = (want - moonless)[..., 2]
    assert np.median(air) > 2.0 * np.median(moonless[..., 2])   # the moon's light is the night sky's most
    assert np.median((want - moonless)[..., 2] / np.maximum((want - moonless)[..., 0], 1e-6)) > 1.5   # blue
    towards = rays @ np.array(NIGHT_MOON)
    assert air[towards > 0.95].mean() > 1.5 * air[(towards < 0.8) & (rays[..., 1] > 0.2)].mean()
    brighter = sky_model(Skybox(model="atmosphere", sun_direction=tuple(NIGHT_SUN), moon_color=(2.0, 2.0, 2.1)), sun)
    np.testing.assert_allclose(brighter.moon_air, 2.0 * np.array(model.moon_air), rtol=1e-5)
    share, _ = moon_phase(np.array(NIGHT_MOON), np.array(NIGHT_SUN))
    np.testing.assert_allclose(model.moon_air, np.array([1.0, 1.0, 1.05]) * (0.9, 0.9, 1.0) * share, rtol=1e-5)
    # The moon gone: its table is let go.
    for entity, light in list(runner.world.query_one(DirectionalLight)):
        if light.body == "moon":
            runner.world.delete_entity(entity)
    runner.frame()
    assert renderer.moon_view is None and renderer.resource_counts()["moon_view"] == 0


def test_a_moon_just_set_still_lights_the_air_over_where_it_went_down(scene):
    """A moon 4 degrees below the horizon has no disc (the air lets none of it through) but
    its light still reaches the air above (the twilight of a set moon): the sky pass builds
    without the disc (``MOON_AIR`` alone) and is the twin's, brighter over where it set."""
    set_moon = glm.normalize(glm.vec3(-0.5, -0.07, -0.75))
    skybox = Skybox(model="atmosphere", sun_direction=tuple(NIGHT_SUN))
    sun = SkySun(tuple(NIGHT_SUN), moon=tuple(set_moon), moon_tint=(0.9, 0.9, 1.0))
    model = sky_model(skybox, sun)
    assert model.moon_lights_air and not model.moon
    _, _, runner = _hdr_frame(scene, skybox, fov=90.0, look=glm.normalize(glm.vec3(-0.5, 0.3, -0.75)))
    runner.world.spawn(moon_light(set_moon))
    runner.frame()
    from tests.test_generated_sky import _read
    colour, rays = _read(runner)
    want = sky_radiance(skybox, rays, sun)
    np.testing.assert_allclose(colour, want, rtol=6e-3, atol=1e-3)
    air = (want - sky_radiance(skybox, rays, SkySun(tuple(NIGHT_SUN))))[..., 2]
    over_it = (rays @ np.array(set_moon) > 0.9) & (rays[..., 1] > 0.0)
    assert air.max() > 5e-4 and air[over_it].mean() > 2.0 * air[rays[..., 1] > 0.6].mean()


def test_the_moons_table_is_drawn_again_only_when_it_climbs_a_step(scene):
    """The moon's table follows its elevation as the sun's does (again past
    ``TABLE_STEP_DEGREES``; not when it only turns about the sky at the same height), the
    sun's table drawn once while the sun stands still."""
    from engine.render.atmosphere import TABLE_STEP_DEGREES

    skybox = Skybox(model="atmosphere", sun_direction=tuple(NIGHT_SUN))
    _, _, runner = _hdr_frame(scene, skybox, fov=60.0, look=NIGHT_MOON)
    moon = moon_light(NIGHT_MOON)
    runner.world.spawn(moon)
    runner.frame()
    renderer = runner.engine.renderer
    sun_draws, moon_draws = renderer.sky_view_pass.draws, renderer.moon_view_pass.draws
    runner.frame()
    assert (renderer.sky_view_pass.draws, renderer.moon_view_pass.draws) == (sun_draws, moon_draws)
    climb = glm.normalize(glm.cross(NIGHT_MOON, glm.vec3(0, 1, 0)))
    for degrees, axis, drawn in ((20.0, glm.vec3(0, 1, 0), 0), (2.0 * TABLE_STEP_DEGREES, climb, 1)):
        way = glm.vec3(glm.rotate(glm.radians(degrees), axis) * glm.vec4(-glm.vec3(*moon.direction), 0.0))
        moon.direction = tuple(-way)
        runner.frame()
        assert renderer.moon_view_pass.draws == moon_draws + drawn
        assert renderer.sky_view_pass.draws == sun_draws
        moon_draws = renderer.moon_view_pass.draws


def ball_share(moon: np.ndarray, sun: np.ndarray, inside: float) -> float:
    """The share of a ball's disc within ``inside`` of its radius (0 to 1) the sun lights:
    a grid of points over that part of the disc, each the ball's point seen there (its normal
    the point and the way back towards the eye), lit where that normal faces the sun."""
    side = np.cross(moon, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, moon)
    grid = np.linspace(-1.0, 1.0, 401)
    a, b = np.meshgrid(grid, grid)
    on = a * a + b * b < 1.0
    a, b = a[on] * inside, b[on] * inside
    normal = a[:, None] * side + b[:, None] * up - np.sqrt(1.0 - a * a - b * b)[:, None] * moon
    return float((normal @ sun > 0.0).mean())


@pytest.mark.parametrize("degrees", [180.0, 120.0, 90.0, 45.0])
def test_a_phase_lights_the_share_of_the_disc_a_ball_shows(scene, degrees):
    """The moon's disc drawn with the sun ``degrees`` from it: the share of its pixels lit is the
    share of a ball's face the sun lights seen from there (3 points), and the full moon's light
    is even across it (no limb darkening: Lommel and Seeliger's law)."""
    moon = np.array([0.0, 0.3, -1.0]) / np.linalg.norm([0.0, 0.3, -1.0])
    side = np.cross(moon, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    angle = math.radians(degrees)
    sun = moon * math.cos(angle) + side * math.sin(angle)
    skybox = Skybox(zenith=(0, 0, 0), horizon=(0, 0, 0), ground=(0, 0, 0), sun_direction=tuple(sun),
                    sun_color=(0.0, 0.0, 0.0), moon_color=(1.0, 1.0, 1.0))

    def build(world):
        world.spawn(moon_light(glm.vec3(*moon), color=(1.0, 1.0, 1.0)))
    colour, rays, runner = _hdr_frame(scene, skybox, fov=8.0, look=glm.vec3(*moon))
    build(runner.world)
    runner.frame()
    from tests.test_generated_sky import _read
    colour, rays = _read(runner)
    inner = 0.99925                     # well inside the disc (its edge at cos 0.9990, its rim 2% of it)
    disc = rays @ moon > inner
    lit = colour[..., 1] - sky_radiance(skybox, rays, SkySun(tuple(sun)))[..., 1] > 0.02   # (above the sun's glow)
    share = float((lit & disc).sum() / disc.sum())
    radius = math.sqrt(1.0 - inner * inner) / math.sqrt(1.0 - 0.9990 ** 2)   # of the disc the phase is drawn on
    assert share == pytest.approx(ball_share(moon, sun, radius), abs=0.03)
    if degrees == 180.0:   # even up to where the disc's ramp begins
        whole = rays @ moon > 0.9995
        assert colour[whole][:, 1].min() > 0.97 and colour[whole][:, 1].max() < 1.03


def lommel_seeliger_phase(degrees: float) -> float:
    """A hard ball of Lommel and Seeliger's dust seen with the sun ``degrees`` from it (the
    phase angle a = 180 - degrees): its light over a full one's, in closed form,
    1 - sin(a/2) tan(a/2) ln cot(a/4)."""
    a = math.radians(180.0 - degrees)
    return 1.0 - math.sin(a / 2.0) * math.tan(a / 2.0) * math.log(1.0 / math.tan(a / 4.0))


@pytest.mark.parametrize("degrees", [90.0, 45.0, 30.0])
def test_a_crescent_sends_the_light_a_hard_balls_phase_leaves_and_its_lit_edge_is_brightest(scene, degrees):
    """The disc drawn full (the sun behind the eye) and then with the sun ``degrees`` from it,
    on a black sky: the crescent's light, summed over its pixels by their solid angle, over
    the full moon's is the closed form's share plus the Earth's light (``moon_phase``, which
    sets the moon's light in the air and on the clouds, says the same); along the lit limb,
    where the eye's cosine is small, each pixel is 2 mu0 / (mu0 + mu) written out here (up
    to 2: brighter than a full moon), the rim anti-aliased over a pixel, not faded over a
    third of the radius."""
    moon = np.array([0.0, 0.3, -1.0]) / np.linalg.norm([0.0, 0.3, -1.0])
    side = np.cross(moon, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    angle = math.radians(degrees)
    sun = moon * math.cos(angle) + side * math.sin(angle)
    black = dict(zenith=(0, 0, 0), horizon=(0, 0, 0), ground=(0, 0, 0), sun_color=(0.0, 0.0, 0.0),
                 moon_color=(1.0, 1.0, 1.0))
    light = {}
    for name, towards in (("full", -moon), ("phase", sun)):
        skybox = Skybox(**black, sun_direction=tuple(towards))
        _, _, runner = _hdr_frame(scene, skybox, fov=7.0, look=glm.vec3(*moon))
        runner.world.spawn(moon_light(glm.vec3(*moon), color=(1.0, 1.0, 1.0)))
        runner.frame()
        from tests.test_generated_sky import _read
        colour, rays = _read(runner)
        glow = sky_radiance(skybox, rays, SkySun(tuple(towards)))[..., 1]   # (the black sky's glow about the sun)
        solid = (rays @ moon) ** 3   # (a pixel's solid angle on a flat screen, the lens on the moon)
        light[name] = float(((colour[..., 1] - glow) * solid)[rays @ moon > 0.998].sum())
    want = lommel_seeliger_phase(degrees) + earthshine_by_hand(degrees)
    assert light["phase"] / light["full"] == pytest.approx(want, rel=0.03)
    assert moon_phase(moon, sun)[0] == pytest.approx(want, rel=0.015)
    radius = math.sqrt(1.0 - 0.9990 ** 2)
    across = (rays - (rays @ moon)[..., None] * moon) / radius
    reach = np.sqrt((across * across).sum(-1))
    mu = np.sqrt(np.maximum(1.0 - reach * reach, 0.0))
    mu0 = (across - mu[..., None] * moon) @ sun
    limb = (reach > 0.9) & (reach < 0.98) & (mu0 > mu)
    assert limb.sum() > 10
    law = 2.0 * mu0 / (mu0 + mu) + earthshine_by_hand(degrees)
    np.testing.assert_allclose(colour[limb][:, 1] - glow[limb], law[limb], rtol=0.02)
    assert colour[limb][:, 1].max() > 1.05   # (brighter than a full moon, whose face is 1 all across)


def earthshine_by_hand(degrees: float) -> float:
    """The Earth's light on the moon over the sun's, the sun ``degrees`` from the moon: the
    Earth's geometric albedo 0.367 x (6371 km / 384,400 km)^2 x a Lambert sphere's phase
    function at the Earth's phase seen from the moon (the same angle)."""
    a = math.radians(degrees)
    return 0.367 * (6371.0 / 384400.0) ** 2 * (math.sin(a) + (math.pi - a) * math.cos(a)) / math.pi


@pytest.mark.parametrize("degrees", [25.0, 60.0, 90.0, 120.0])
def test_the_dark_side_takes_the_earths_light(scene, degrees):
    """The moon's disc with the sun ``degrees`` from it, lit a thousandfold so the Earth's
    light shows in the frame: past the terminator it is the Earth's light by hand (the twin
    says so, and the GPU draws it within 2%), most for a young crescent, none at full."""
    moon = np.array([0.0, 0.3, -1.0]) / np.linalg.norm([0.0, 0.3, -1.0])
    side = np.cross(moon, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    angle = math.radians(degrees)
    sun = moon * math.cos(angle) + side * math.sin(angle)
    bright = 1000.0
    skybox = Skybox(zenith=(0, 0, 0), horizon=(0, 0, 0), ground=(0, 0, 0), sun_direction=tuple(sun),
                    sun_color=(0.0, 0.0, 0.0), moon_color=(bright, bright, bright))
    colour, rays, runner = _hdr_frame(scene, skybox, fov=8.0, look=glm.vec3(*moon))
    runner.world.spawn(moon_light(glm.vec3(*moon), color=(1.0, 1.0, 1.0)))
    runner.frame()
    from tests.test_generated_sky import _read
    colour, rays = _read(runner)
    d = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    share = moon_share(d, moon, sun)
    whole = d @ moon > 0.9995
    dark = whole & (share < 1.5 * earthshine_by_hand(degrees) + 1e-9)   # (past the terminator)
    assert dark.sum() > 20
    want = earthshine_by_hand(degrees)
    np.testing.assert_allclose(share[dark], want, rtol=1e-9)
    plain = sky_radiance(skybox, rays, SkySun(tuple(sun)))[..., 1]   # (the gradient's glow about the sun)
    np.testing.assert_allclose(colour[dark][:, 1] - plain[dark], bright * want, rtol=0.02)
    assert earthshine_by_hand(25.0) > 2.5 * earthshine_by_hand(90.0) > 0.0 and earthshine_by_hand(180.0) < 1e-12


def test_a_moon_is_never_the_skys_sun():
    """Brighter than the sun, a moon is not what the sky follows; with no sun the sky's sun is
    the default and the moon is still the sky's moon."""
    from engine.core.world import World

    world = World()
    sun = world.get(world.spawn(DirectionalLight(direction=(0.0, -1.0, -1.0), intensity=1.0)), DirectionalLight)
    world.spawn(moon_light(color=(1.0, 1.0, 1.0)))
    world.get(world.query_one(DirectionalLight)[1][0], DirectionalLight).intensity = 50.0
    skybox = Skybox()
    assert brightest_directional(world) is sun
    found = sky_sun(world, skybox)
    np.testing.assert_allclose(found.direction, tuple(-glm.normalize(glm.vec3(0.0, -1.0, -1.0))), atol=1e-6)
    np.testing.assert_allclose(found.moon, tuple(MOON), atol=1e-6)
    world.delete_entity(world.query_one(DirectionalLight)[0][0])
    alone = sky_sun(world, skybox)
    assert alone.moon is not None and brightest_directional(world) is None


def test_the_moons_light_is_reddened_by_the_air_as_the_suns(scene):
    """A floor lit only by a low moon: under an atmosphere the red over blue of its direct
    light (the frame less the frame with the moon half as bright: the air's moonlight, which
    does not follow the light's intensity, taken out) is the gradient sky's times the air's
    tint along the moon's way (the sun's rule, sunlight_tint)."""
    from engine.render.sky import sunlight_tint

    low = glm.normalize(glm.vec3(0.0, 0.12, -1.0))

    def floor(model, intensity):
        def build(world):
            look_from(world, (0.0, 3.0, 3.0), (0.0, 0.0, 0.0))
            world.spawn(Skybox(model=model, faces=np.zeros((6, 4, 4, 3), np.float32)) if model == "gradient"
                        else Skybox(model=model))
            world.spawn(DirectionalLight(direction=(0.0, 1.0, 0.2), intensity=1.0))   # a sun long set
            world.spawn(DirectionalLight(direction=tuple(-low), intensity=intensity, body="moon", shadows=False))
            world.spawn(Transform(), MeshRef(plane(6, 6)), Material(color=(0.8, 0.8, 0.8), roughness=1.0,
                                                                      reflectance=0.0, environment_reflection=0.0))
        return build

    frames = {}
    for model in ("gradient", "atmosphere"):
        lit = []
        for intensity in (4.0, 2.0):
            runner = scene(floor(model, intensity), (64, 48))
            runner.frame()
            lit.append(srgb_to_linear(runner.frame()[30:40, 24:40]).reshape(-1, 3).mean(axis=0))
        frames[model] = lit[0] - lit[1]
    tint = np.array(sunlight_tint(Skybox(model="atmosphere"), tuple(-low)))
    assert tint[0] > 1.5 * tint[2]   # (low: red)
    want = (frames["gradient"][0] / frames["gradient"][2]) * tint[0] / tint[2]
    got = frames["atmosphere"][0] / frames["atmosphere"][2]
    assert got == pytest.approx(want, rel=0.08)


@pytest.mark.parametrize("model", ["gradient", "atmosphere"])
def test_the_skys_light_holds_the_moon(model):
    """The sky's light (closed form, the moon's disc by its phase's share) against the
    projection of faces fine enough to sample the disc."""
    skybox = Skybox(**{**SKY, "face_size": 512}, model=model, moon_color=(40.0, 40.0, 40.0))
    sun = _with_moon(MOON, (1.0, 1.0, 1.0))
    with_moon = generated_sky_sh(sky_model(skybox, sun))
    without = generated_sky_sh(sky_model(skybox, SkySun(tuple(SUN))))
    if model == "gradient":
        faces = project_faces(build_faces(skybox, sun)) - project_faces(build_faces(skybox, SkySun(tuple(SUN))))
        np.testing.assert_allclose(with_moon - without, faces, atol=0.04 * np.abs(faces).max())   # (measured 2.3%)
    else:   # the air's moonlight (from the CPU's small table at the moon's elevation) against the full one's faces
        night = Skybox(model="atmosphere", sun_direction=tuple(NIGHT_SUN), face_size=64)
        lit = SkySun(tuple(NIGHT_SUN), moon=tuple(NIGHT_MOON))
        air = generated_sky_sh(sky_model(night, lit)) - generated_sky_sh(sky_model(night, SkySun(tuple(NIGHT_SUN))))
        faces = project_faces(build_faces(night, lit)) - project_faces(build_faces(night, SkySun(tuple(NIGHT_SUN))))
        np.testing.assert_allclose(air, faces, atol=0.04 * np.abs(faces).max())
    assert np.abs(with_moon - without).max() > 1e-3
    share, centre = moon_phase(np.array(MOON), np.array(SUN))
    assert 0.0 < share < 1.0 and float(centre @ np.array(SUN)) > float(np.array(MOON) @ np.array(SUN))


def test_a_time_of_day_puts_the_moon_where_it_stands():
    """On an equinox at 45 degrees north: a full moon at midnight stands due south, 45 degrees
    up, opposite the noon sun's way; a new moon stands with the sun; a first quarter is due
    south at six in the evening; the clock moves its age on."""
    full = TimeOfDay(hour=0.0, day=80, latitude=45.0, moon_age=SYNODIC_MONTH / 2.0)
    way = moon_towards(full)
    assert math.degrees(math.asin(way.y)) == pytest.approx(45.0, abs=1.5)
    assert way.z > 0.99 * math.cos(math.asin(way.y))   # due south (north is -Z)
    noon = sun_towards(TimeOfDay(hour=12.0, day=80, latitude=45.0))
    assert glm.dot(way, noon) == pytest.approx(1.0, abs=0.01)   # the noon sun's place, half a day and year on
    evening = TimeOfDay(hour=18.0, day=172, latitude=45.0, moon_age=0.0)
    np.testing.assert_allclose(tuple(moon_towards(evening)), tuple(sun_towards(evening)), atol=1e-9)
    quarter = TimeOfDay(hour=18.0, day=80, latitude=45.0, moon_age=SYNODIC_MONTH / 4.0)
    at = moon_towards(quarter)
    assert abs(at.x) < 0.05   # on the meridian: neither east nor west


def test_the_clock_turns_a_moons_light_and_ages_it():
    from engine.core.world import World
    from systems.time_of_day_system import TimeOfDaySystem

    world = World()
    entity = world.spawn(DirectionalLight(body="moon"), TimeOfDay(hour=22.0, day=100, moon_age=3.0,
                                                                    hours_per_second=2.4))
    TimeOfDaySystem(world).process(1.0)
    clock, light = world.get(entity, TimeOfDay), world.get(entity, DirectionalLight)
    assert clock.moon_age == pytest.approx(3.1) and clock.hour == pytest.approx(0.4) and clock.day == 101
    np.testing.assert_allclose(tuple(light.direction), tuple(-moon_towards(clock)), atol=1e-6)


@pytest.mark.parametrize("make,match", [(lambda: DirectionalLight(body="star"), "DirectionalLight.body"),
                                        (lambda: TimeOfDay(moon_age=40.0), "TimeOfDay.moon_age"),
                                        (lambda: TimeOfDay(moon_age=-1.0), "TimeOfDay.moon_age"),
                                        (lambda: Skybox(moon_color=(-1.0, 0.0, 0.0)), "Skybox.moon_color")])
def test_bad_moon_values_are_refused(make, match):
    with pytest.raises(ComponentValueError, match=match):
        make()


def test_a_level_file_gives_a_moon(tmp_path):
    from engine.assets.level_read import load_level
    from engine.core.world import World

    level = tmp_path / "night.toml"
    level.write_text('[level]\nname = "night"\n[[entity]]\nname = "moon"\n'
                     'DirectionalLight = { body = "moon", intensity = 0.2 }\n'
                     'TimeOfDay = { hour = 23.0, moon_age = 7.5 }\n'
                     '[[entity]]\nname = "sky"\nSkybox = { model = "atmosphere", moon_color = [1.5, 1.5, 1.6] }\n')
    world = World()
    load_level(level).spawn(world)
    ((_, light),) = world.query_one(DirectionalLight)
    assert light.body == "moon" and world.query_one(TimeOfDay)[0][1].moon_age == pytest.approx(7.5)
    assert glm.vec4(world.query_one(Skybox)[0][1].moon_color).x == pytest.approx(1.5)


def test_the_runners_moon_follows_the_clock(ctx, tmp_path):
    """``--time 23 --moon 14.77`` on a game: a moon light on the sun's clock where the moon
    stands; ``--moon`` without ``--time`` and a bad age are one error line each."""
    from engine import Game, spawn_camera
    from shell.app import Engine
    from tests.support import run_level

    class Open(Game):
        def build(self, world):
            spawn_camera(world, position=(0.0, 1.6, 4.0), pitch=5)
            world.spawn(DirectionalLight(intensity=3.0))

    engine = Engine(Open(), ctx)
    try:
        engine.start_sky("atmosphere", 23.0, 10.0, moon_age=14.77)
        engine.frame(1.0, None)
        moons = [(e, light) for e, light in engine.world.query_one(DirectionalLight) if light.body == "moon"]
        ((entity, light),) = moons
        clock = engine.world.get(entity, TimeOfDay)
        assert clock.moon_age == pytest.approx(14.77 + 24.0 / 600.0 / 24.0)
        np.testing.assert_allclose(tuple(light.direction), tuple(-moon_towards(clock)), atol=1e-6)
        assert not light.shadows
    finally:
        engine.close()
    for bad, words in ((("--moon", "3"), "--moon needs --time"), (("--time", "22", "--moon", "40"), "--moon must be")):
        result = run_level("--headless", "--frames", "1", "--size", "16x12", "--out", str(tmp_path / "bad"), *bad)
        assert result.returncode != 0 and words in result.stderr.splitlines()[-1], result.stderr


def _moon_pixels(scene, skybox, look, size=(96, 72), fov=7.0, mirror=False):
    """Level 0's linear colour (h, w, 3) of ``skybox`` (a moon light along MOON) through a
    ``fov`` lens along ``look``, and each pixel's ray as the sky sees it (reflected in a
    mirror across the view at z = 2 where ``mirror``); whether each pixel is on the mirror."""
    from components import Camera, Mirror, look_rotation
    from engine.assets.mesh import quad
    from tests.support import pixel_rays

    def build(world):
        world.spawn(Transform(rotation=look_rotation(glm.vec3(*look))), Camera(fov_y=fov, near=0.1, far=100.0))
        world.spawn(skybox)
        world.spawn(moon_light(color=(1.0, 1.0, 1.0)))
        if mirror:
            world.spawn(Transform(position=(0.0, 0.0, 2.0), rotation=glm.angleAxis(glm.pi(), glm.vec3(0, 1, 0))),
                        MeshRef(quad(40.0, 40.0)), Material(), Mirror())

    runner = scene(build, size)
    runner.engine.renderer.antialias = "off"
    runner.frame()
    w, h = size
    colour = np.frombuffer(runner.engine.renderer.levels[0].color.read(), np.float16)
    colour = colour.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)
    _, rays = pixel_rays(runner.engine.main_view, size)
    on = rays[..., 2] > 0.05 if mirror else np.ones(rays.shape[:2], bool)
    return colour, (rays * np.array([1.0, 1.0, -1.0]) if mirror else rays), on


@pytest.mark.parametrize("mirror", [False, True], ids=["ahead", "in_a_mirror"])
@pytest.mark.parametrize("degrees", [60.0, 90.0, 135.0])
def test_the_lit_part_of_the_disc_is_the_side_of_a_ball_facing_the_sun(scene, degrees, mirror):
    """The sun ``degrees`` from the moon, off to one side: each pixel of the disc is lit where
    the point of a ball the moon's size seen along its ray (its normal: the ray's offset from
    the centre over the disc's radius, tipped back towards the eye) faces the sun, and dark
    where it faces away, seen straight and in a mirror (the image flipped, the lit side still
    the sun's); and the lit pixels' middle lies towards the sun."""
    moon = np.array(MOON, np.float64)
    side = np.cross(moon, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, moon)
    angle = math.radians(degrees)
    sun = moon * math.cos(angle) + (side * 0.8 + up * 0.6) * math.sin(angle)   # (off the horizontal)
    skybox = Skybox(zenith=(0, 0, 0), horizon=(0, 0, 0), ground=(0, 0, 0), sun_direction=tuple(sun),
                    sun_color=(0.0, 0.0, 0.0), moon_color=(1.0, 1.0, 1.0))
    look = moon * np.array([1.0, 1.0, -1.0]) if mirror else moon
    colour, rays, on = _moon_pixels(scene, skybox, look, mirror=mirror)
    radius = math.sqrt(1.0 - 0.9990 ** 2)   # the disc's edge
    offset = (rays - (rays @ moon)[..., None] * moon) / radius
    inside = on & (rays @ moon > 0.0) & ((offset * offset).sum(-1) < 0.9 ** 2)   # (short of the faded rim)
    normal = offset - np.sqrt(np.maximum(1.0 - (offset * offset).sum(-1), 0.0))[..., None] * moon
    facing = normal @ sun
    lit = colour[..., 1] - sky_radiance(skybox, rays, SkySun(tuple(sun)))[..., 1] > 0.02   # (above the sun's glow)
    assert inside.sum() > 1000 and (inside & (facing > 0.05)).sum() > 100
    assert lit[inside & (facing > 0.05)].all() and not lit[inside & (facing < -0.05)].any()
    middle = rays[inside & lit].mean(axis=0) - moon
    assert middle @ (sun - (sun @ moon) * moon) > 0.0


def _elevation_and_bearing(way) -> tuple[float, float]:
    """Degrees over the horizon, and degrees from north (-Z) towards east (+X)."""
    return math.degrees(math.asin(way.y)), math.degrees(math.atan2(way.x, -way.z)) % 360.0


@pytest.mark.parametrize("day", [172, 355, 80])
def test_a_full_moon_rises_at_sunset_opposite_the_sun_high_in_winter_low_in_summer(day):
    """At 45 north: at sunset (the sunrise equation's hour, cos H = -tan(latitude)
    tan(declination)) a full moon is on the horizon, rising, at the bearing opposite the
    setting sun's (cos A = sin(declination) / cos(latitude)); at midnight it stands due south
    at 90 - 45 - its declination, the opposite of the sun's: high in winter, low in summer."""
    phi = math.radians(45.0)
    declination = math.radians(-23.44) * math.cos(2.0 * math.pi / 365.0 * (day + 10))
    sunset = 12.0 + math.degrees(math.acos(-math.tan(phi) * math.tan(declination))) / 15.0
    setting = 360.0 - math.degrees(math.acos(math.sin(declination) / math.cos(phi)))
    full = SYNODIC_MONTH / 2.0
    elevation, bearing = _elevation_and_bearing(moon_towards(TimeOfDay(hour=sunset, day=day, moon_age=full)))
    assert abs(elevation) < 0.5 and bearing == pytest.approx(setting - 180.0, abs=1.0)
    later = _elevation_and_bearing(moon_towards(TimeOfDay(hour=sunset + 0.5, day=day, moon_age=full)))[0]
    assert later > elevation + 4.0   # (climbing: rising, not setting)
    elevation, bearing = _elevation_and_bearing(moon_towards(TimeOfDay(hour=0.0, day=day, moon_age=full)))
    assert elevation == pytest.approx(90.0 - 45.0 - math.degrees(declination), abs=0.6)
    assert bearing == pytest.approx(180.0, abs=0.5)


def test_the_moon_rises_later_each_day_by_a_lunar_days_step():
    """A moon on a clock run by the time stage an hour a second, six minutes a frame, for 30
    days at 45 north: each moonrise (its elevation crossing 0 upwards) comes more than 24 hours
    after the one before, and on average 24 x 29.53 / 28.53 = 24.84 hours after (the moon a
    turn behind the sun each synodic month: 50 minutes later a day)."""
    from engine.core.world import World
    from systems.time_of_day_system import TimeOfDaySystem

    world = World()
    entity = world.spawn(DirectionalLight(body="moon"), TimeOfDay(hour=0.0, day=1, moon_age=3.0, hours_per_second=1.0))
    stage = TimeOfDaySystem(world)
    light = world.get(entity, DirectionalLight)
    rises, before, step = [], None, 0.1
    for frame in range(30 * 24 * 10):
        stage.process(step)
        height = -light.direction.y
        if before is not None and before < 0.0 <= height:
            rises.append((frame + before / (before - height)) * step)   # (hours since the start)
        before = height
    gaps = np.diff(rises)
    assert len(gaps) >= 27 and gaps.min() > 24.2, gaps
    assert (rises[-1] - rises[0]) / len(gaps) == pytest.approx(24.0 * SYNODIC_MONTH / (SYNODIC_MONTH - 1.0), abs=0.05)
