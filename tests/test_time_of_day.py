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
from engine.assets.mesh import box
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
