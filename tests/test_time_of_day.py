"""A time of day (``TimeOfDay`` on a ``DirectionalLight``'s entity): the sun where astronomy
puts it (the noon elevation 90 - |latitude - declination| on the solstices and the equinox,
the morning sun in the east and the afternoon's in the west, the southern hemisphere's noon
sun in the north), the clock moving on and the days turning, the light written only when the
time moved, an atmosphere's sky following, and bad values refused."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from pyglm import glm

from components import ComponentValueError, ComponentWarning, DirectionalLight, MeshRef, Skybox, TimeOfDay, Transform
from components.time_of_day import sun_towards
from engine.assets.mesh import box, plane
from engine.frame_stats import RenderStats
from tests.support import look_from


def elevation_and_bearing(towards: glm.vec3) -> tuple[float, float]:
    """Degrees over the horizon, and degrees from north (-Z) towards east (+X)."""
    return (math.degrees(math.asin(towards.y)), math.degrees(math.atan2(towards.x, -towards.z)) % 360.0)


@pytest.mark.parametrize("latitude, day, noon", [
    (51.5, 172, 90.0 - 51.5 + 23.44),    # London, the June solstice
    (51.5, 355, 90.0 - 51.5 - 23.44),    # ... the December one
    (0.0, 80, 90.0 - 0.6),               # the equator at the March equinox (the declination a little below 0)
    (-33.9, 172, 90.0 - 33.9 - 23.44)])  # Sydney in its winter: the noon sun in the north
def test_the_noon_sun_stands_where_astronomy_puts_it(latitude, day, noon):
    elevation, bearing = elevation_and_bearing(sun_towards(TimeOfDay(hour=12.0, day=day, latitude=latitude)))
    assert elevation == pytest.approx(noon, abs=0.6)
    if abs(latitude) > 1.0:
        assert bearing == pytest.approx(180.0 if latitude > 0 else 0.0, abs=1e-6)   # due south, or due north


def test_the_sun_rises_in_the_east_and_sets_in_the_west():
    """At an equinox at 40 degrees north: up at 6 in the east, down at 18 in the west, its
    elevation symmetric about noon, the afternoon sun west of the meridian."""
    rise = elevation_and_bearing(sun_towards(TimeOfDay(hour=6.0, day=80, latitude=40.0)))
    fall = elevation_and_bearing(sun_towards(TimeOfDay(hour=18.0, day=80, latitude=40.0)))
    assert abs(rise[0]) < 1.0 and abs(fall[0]) < 1.0
    assert rise[1] == pytest.approx(90.0, abs=1.0) and fall[1] == pytest.approx(270.0, abs=1.0)
    for hours in (1.0, 3.5, 5.0):
        before = elevation_and_bearing(sun_towards(TimeOfDay(hour=12.0 - hours, day=80, latitude=40.0)))
        after = elevation_and_bearing(sun_towards(TimeOfDay(hour=12.0 + hours, day=80, latitude=40.0)))
        assert before[0] == pytest.approx(after[0], abs=1e-9) and 90.0 < before[1] < 180.0 < after[1] < 270.0
    turned = sun_towards(TimeOfDay(hour=9.0, day=80, latitude=40.0, north=(1.0, 0.0, 0.0)))   # north along +X
    plain = sun_towards(TimeOfDay(hour=9.0, day=80, latitude=40.0))
    np.testing.assert_allclose(tuple(turned), (-plain.z, plain.y, plain.x), atol=1e-6)   # turned 90 degrees


def _runner(scene, time: TimeOfDay, sky: Skybox | None = None):
    def build(world):
        look_from(world, (0.0, 1.0, 0.0), (0.0, 2.0, -5.0))
        world.spawn(time, DirectionalLight(intensity=2.0))
        if sky is not None:
            world.spawn(sky)

    return scene(build, (64, 48))


def test_the_clock_moves_on_and_the_days_turn(scene):
    time = TimeOfDay(hour=23.0, day=365, latitude=30.0, hours_per_second=1.5)
    runner = _runner(scene, time)
    runner.frame(dt=0.5)
    assert time.hour == pytest.approx(23.75) and time.day == 365
    runner.frame(dt=0.5)
    assert time.hour == pytest.approx(0.5) and time.day == 1   # past midnight on the last day: the first
    light = runner.world.get(next(e for e, _ in runner.world.query_one(TimeOfDay)), DirectionalLight)
    np.testing.assert_allclose(tuple(light.direction), tuple(-sun_towards(time)), atol=1e-6)


def test_a_still_clock_leaves_the_light_and_its_shadow_map_alone(scene):
    """A clock standing still writes the light once: its shadow map is drawn the first frame
    and kept after; turning the light by hand is undone the next frame (the clock rules it)."""
    time = TimeOfDay(hour=10.0)
    runner = _runner(scene, time)
    world = runner.world
    world.spawn(Transform(), MeshRef(box()))
    runner.frame()
    runner.frame()
    assert world.resources[RenderStats].shadow_maps_drawn == 0 and world.resources[RenderStats].shadow_maps_kept > 0
    light = world.get(next(e for e, _ in world.query_one(TimeOfDay)), DirectionalLight)
    light.direction = (0.0, -1.0, 0.0)
    runner.frame()
    np.testing.assert_allclose(tuple(light.direction), tuple(-sun_towards(time)), atol=1e-6)


def test_an_atmosphere_follows_the_clock(scene):
    """The sky's sun (what its pass draws) stands where the clock puts it."""
    time = TimeOfDay(hour=19.0, day=172, latitude=45.0)
    runner = _runner(scene, time, Skybox(model="atmosphere"))
    runner.frame()
    model = runner.engine.renderer.sky_model
    np.testing.assert_allclose(model.sun_direction, tuple(sun_towards(time)), atol=1e-5)
    assert 0.0 < elevation_and_bearing(sun_towards(time))[0] < 10.0


def test_a_clock_without_a_light_is_said_once(scene):
    def build(world):
        look_from(world, (0.0, 1.0, 0.0), (0.0, 2.0, -5.0))
        world.spawn(TimeOfDay(hours_per_second=1.0))

    runner = scene(build, (32, 24))
    with pytest.warns(ComponentWarning, match=r"TimeOfDay on entity \d+, which has no DirectionalLight"):
        runner.frame()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        runner.frame()


@pytest.mark.parametrize("field, value, words", [
    ("hour", 25.0, "hour"), ("hour", float("nan"), "hour"), ("day", 0, "day"), ("day", 1.5, "day"),
    ("latitude", 91.0, "latitude"), ("north", (0.0, 1.0, 0.0), "along the ground"),
    ("hours_per_second", float("inf"), "hours_per_second")])
def test_bad_times_are_refused_when_given(field, value, words):
    with pytest.raises(ComponentValueError, match=words):
        TimeOfDay(**{field: value})


def test_a_level_file_sets_the_clock(tmp_path):
    from engine.assets.level_read import load_level
    from engine.assets.level_save import save_level
    from engine.core.world import World

    level = tmp_path / "day.toml"
    level.write_text('[level]\nname = "day"\n[[entity]]\nname = "sun"\nDirectionalLight = {}\n'
                     'TimeOfDay = { hour = 17.5, day = 200, latitude = -20.0, hours_per_second = 0.01 }\n')
    world = World()
    load_level(level).spawn(world)
    time = world.query_one(TimeOfDay)[0][1]
    assert (time.hour, time.day, time.latitude, time.hours_per_second) == (17.5, 200, -20.0, 0.01)
    save_level(world, tmp_path / "again.toml")
    again = World()
    load_level(tmp_path / "again.toml").spawn(again)
    assert again.query_one(TimeOfDay)[0][1].hour == 17.5


def spencer_declination(day: float) -> float:
    """The sun's declination (radians) on ``day`` by Spencer's Fourier series (1971, within
    0.0006 rad of an ephemeris over the year): not the engine's one-cosine rule."""
    g = 2.0 * math.pi / 365.0 * (day - 1)
    return (0.006918 - 0.399912 * math.cos(g) + 0.070257 * math.sin(g) - 0.006758 * math.cos(2 * g)
            + 0.000907 * math.sin(2 * g) - 0.002697 * math.cos(3 * g) + 0.00148 * math.sin(3 * g))


def sun_by_rotation(latitude: float, declination: float, hour: float, north=(0.0, 0.0, -1.0)) -> np.ndarray:
    """The world way towards the sun, by rotating the Earth rather than by the spherical
    triangle: in the Earth's frame (x towards the observer's meridian on the equator, y east,
    z the pole) the sun stands at (cos d cos h, -cos d sin h, sin d), h the hour angle
    westward; the observer's up, north and east are the latitude's turn of x, z and y."""
    phi, h = math.radians(latitude), math.radians(15.0 * (hour - 12.0))
    sun = np.array([math.cos(declination) * math.cos(h), -math.cos(declination) * math.sin(h), math.sin(declination)])
    up = np.array([math.cos(phi), 0.0, math.sin(phi)])
    north_at, east_at = np.array([-math.sin(phi), 0.0, math.cos(phi)]), np.array([0.0, 1.0, 0.0])
    n = np.array([north[0], 0.0, north[2]]) / math.hypot(north[0], north[2])
    e = np.array([-n[2], 0.0, n[0]])   # north turned a quarter clockwise seen from above (-Z north: +X east)
    return (sun @ north_at) * n + (sun @ east_at) * e + (sun @ up) * np.array([0.0, 1.0, 0.0])


def test_the_sun_stands_within_a_degree_or_so_of_the_solar_position_formulas_all_day_and_year():
    """Latitudes from 60 south to 70 north, every ninth day, every hour and a half: with the
    engine's own declination rule the way is the rotated Earth's (1e-6, a float32's: the geometry exact),
    and with Spencer's declination within 1.5 degrees (the README's "a degree or so")."""
    worst = 0.0
    for latitude in (-60.0, -33.9, 0.0, 20.0, 45.0, 51.5, 70.0):
        for day in range(1, 366, 9):
            own = math.radians(-23.44) * math.cos(2.0 * math.pi / 365.0 * (day + 10))
            for hour in np.arange(0.0, 24.0, 1.5):
                got = np.array(tuple(sun_towards(TimeOfDay(hour=float(hour), day=day, latitude=latitude))))
                np.testing.assert_allclose(got, sun_by_rotation(latitude, own, hour), atol=1e-6)   # (float32)
                ephemeris = sun_by_rotation(latitude, spencer_declination(day), hour)
                worst = max(worst, math.degrees(math.acos(min(1.0, float(got @ ephemeris)))))
    assert 0.1 < worst < 1.5, worst
    turned = (0.6, 0.0, 0.8)
    got = sun_towards(TimeOfDay(hour=15.25, day=300, latitude=-12.0, north=turned))
    own = math.radians(-23.44) * math.cos(2.0 * math.pi / 365.0 * 310)
    np.testing.assert_allclose(tuple(got), sun_by_rotation(-12.0, own, 15.25, turned), atol=1e-6)


@pytest.mark.parametrize("latitude, day", [(51.5, 172), (51.5, 355), (-33.9, 30), (10.0, 250)])
def test_the_sun_rises_and_sets_at_the_hours_of_the_sunrise_equation(latitude, day):
    """cos H = -tan(latitude) tan(declination): at 12 -/+ H / 15 hours the sun is on the
    horizon, a little before under it and a little after over it (and the other way at
    sunset), at the bearing cos A = sin(declination) / cos(latitude) east and west of north."""
    phi = math.radians(latitude)
    declination = math.radians(-23.44) * math.cos(2.0 * math.pi / 365.0 * (day + 10))
    half_day = math.degrees(math.acos(-math.tan(phi) * math.tan(declination))) / 15.0
    bearing = math.degrees(math.acos(math.sin(declination) / math.cos(phi)))
    for hour, sign, way in ((12.0 - half_day, 1.0, bearing), (12.0 + half_day, -1.0, 360.0 - bearing)):
        elevation, towards = elevation_and_bearing(sun_towards(TimeOfDay(hour=hour, day=day, latitude=latitude)))
        assert abs(elevation) < 1e-4 and towards == pytest.approx(way, abs=1e-4)
        for step in (-0.05, 0.05):   # three minutes either side
            moved = elevation_and_bearing(sun_towards(TimeOfDay(hour=hour + step, day=day, latitude=latitude)))[0]
            assert math.copysign(1.0, moved) == math.copysign(1.0, sign * step)
    assert (half_day > 6.0) == (latitude * declination > 0.0)   # (the summer's days longer)


def test_the_midnight_sun_and_the_polar_night():
    """At 70 north the June sun stays up at midnight (at 90 - 70 - 90 + 23.44 = 3.44 degrees,
    due north) and the December sun stays down at noon (at 90 - 70 - 23.44 = -3.44)."""
    midnight = elevation_and_bearing(sun_towards(TimeOfDay(hour=0.0, day=172, latitude=70.0)))
    assert midnight[0] == pytest.approx(3.44, abs=0.01) and min(midnight[1], 360.0 - midnight[1]) < 1e-4
    noon = elevation_and_bearing(sun_towards(TimeOfDay(hour=12.0, day=355, latitude=70.0)))
    assert noon[0] == pytest.approx(-3.44, abs=0.01)
    for hour in np.arange(0.0, 24.0, 0.5):
        assert sun_towards(TimeOfDay(hour=float(hour), day=172, latitude=70.0)).y > 0.0
        assert sun_towards(TimeOfDay(hour=float(hour), day=355, latitude=70.0)).y < 0.0


POST_HEIGHT = 2.0


def _shadow_runner(scene, time: TimeOfDay):
    """A grey floor seen straight down from 12 m (96 x 96, 60 degrees: 0.14 m a pixel), a post
    0.16 m square and ``POST_HEIGHT`` tall at the origin, lit by a light ``time`` turns."""
    from components import Camera, Material, look_rotation

    def build(world):
        world.spawn(Transform(position=(0.0, 12.0, 0.0), rotation=look_rotation(glm.vec3(0.0, -1.0, 0.0),
                                                                                 glm.vec3(0.0, 0.0, -1.0))),
                    Camera(fov_y=60.0, near=0.5, far=50.0))
        world.spawn(time, DirectionalLight(intensity=3.0, shadow_resolution=2048))
        grey = Material(color=(0.6, 0.6, 0.6), roughness=1.0)
        world.spawn(Transform(), MeshRef(plane(40.0, 40.0)), grey)
        world.spawn(Transform(position=(0.0, POST_HEIGHT / 2.0, 0.0)), MeshRef(box((0.16, POST_HEIGHT, 0.16))), grey)

    return scene(build, (96, 96))


def _shadow_points(runner) -> np.ndarray:
    """The floor points (x, z) of the frame's pixels darker than three quarters of the lit
    floor's (the shadow's, lit by the sky alone, are about half)."""
    from tests.support import pixel_rays

    frame = runner.frame(dt=1.0).astype(np.float64).sum(axis=-1)
    eye, rays = pixel_rays(runner.engine.main_view, runner.size)
    floor = eye + rays * (-eye[1] / rays[..., 1:2])
    dark = frame < 0.75 * np.median(frame)
    return floor[dark][:, [0, 2]]


def test_a_posts_shadow_follows_the_sun_round_the_day(scene):
    """A clock moving four hours a (1 s) frame from 3:00 on the June solstice at 45 north, its
    north turned 30 degrees off -Z: at 7:00, 11:00 and 15:00 the post's shadow on the floor
    (the dark pixels' floor points) runs from its foot away from the sun the rotated Earth
    puts there, as long as the post's height over the tangent of the sun's elevation."""
    north = (math.sin(math.radians(30.0)), 0.0, -math.cos(math.radians(30.0)))
    time = TimeOfDay(hour=3.0, day=172, latitude=45.0, north=north, hours_per_second=4.0)
    runner = _shadow_runner(scene, time)
    declination = math.radians(-23.44) * math.cos(2.0 * math.pi / 365.0 * 182)
    for hour in (7.0, 11.0, 15.0):
        points = _shadow_points(runner)
        assert time.hour == pytest.approx(hour)
        sun = sun_by_rotation(45.0, declination, hour, north)
        away = -sun[[0, 2]] / np.linalg.norm(sun[[0, 2]])
        length = POST_HEIGHT * np.linalg.norm(sun[[0, 2]]) / sun[1]
        along, across = points @ away, points @ np.array([-away[1], away[0]])
        assert len(points) > 0.5 * length / 0.14 * (0.16 / 0.14), (hour, len(points))   # (a shadow drawn)
        assert along.max() == pytest.approx(length, abs=0.3), (hour, along.max(), length)
        assert along.min() > -0.3 and np.abs(across).max() < 0.2, (hour, along.min(), np.abs(across).max())
