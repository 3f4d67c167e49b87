"""Where the sun stands from a time of day: ``TimeOfDay`` on a ``DirectionalLight``'s entity."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pyglm import glm

from components.tracking import ComponentValueError, TrackedComponent, finite, integer, vec3

MAX_HOURS_PER_SECOND = 1e4   # TimeOfDay.hours_per_second: faster is a flicker, not a day
SYNODIC_MONTH = 29.530589     # days from new moon to new moon
DAYS_A_YEAR = 365


@dataclass(eq=False)
class TimeOfDay(TrackedComponent):
    """The sun's place in the sky at a time of day, on a ``DirectionalLight``'s entity: each
    frame the time stage (``systems/time_of_day_system.py``) turns the light to shine from
    where the sun stands at ``hour`` (0 to 24, local solar time: 12 is the sun's highest) on
    ``day`` of the year (1 to 365) at ``latitude`` degrees (north positive), the world's north
    along ``north`` (a horizontal direction; default -Z, so east is +X), and moves ``hour`` on
    by ``hours_per_second`` x the frame's seconds (0, the default, stands still; 24 / 600 a
    day in ten minutes), the day turning at midnight, as Unreal's sun position and the
    day-night cycles of Unity and Godot games do.  Below the horizon the light shines from
    below: an atmosphere ``Skybox`` (``model="atmosphere"``) darkens it there by its air (and
    reddens it as it sets), a game that wants its own night fades the light itself.

    The sun's place is the usual declination and hour angle (the declination -23.44 degrees x
    cos(360 / 365 x (day + 10)); no equation of time, no refraction: within a degree or so of
    an ephemeris), good for a game's day, not for navigation.

    On a moon's light (``DirectionalLight.body`` "moon") it turns the light to where the moon
    stands instead: ``moon_age`` days since the new moon (0 to ``SYNODIC_MONTH``, 29.53;
    default 14.77, full), moving on with the clock.  The moon is taken on the sun's path,
    ``moon_age`` / 29.53 of a turn ahead of it (its elongation): it rises that share of a day
    later and stands where the sun stands that share of a year later (within the 5 degrees the
    moon's orbit leans off the sun's path), so a full moon rises at sunset opposite the sun,
    high in winter, and a first quarter stands due south at sunset.  Give the moon's light the
    same hour, day and speed as the sun's."""

    SHAREABLE = False  # one light's own clock
    hour: float = 12.0
    day: int = 172
    latitude: float = 45.0
    north: Any = field(default_factory=lambda: glm.vec3(0.0, 0.0, -1.0))
    hours_per_second: float = 0.0
    moon_age: float = SYNODIC_MONTH / 2.0

    def _validate(self, name: str, value: Any) -> Any:
        if name == "hour":
            value = finite(self, name, value, low=0.0, high=24.0)
            return 0.0 if value == 24.0 else value
        if name == "day":
            return integer(self, name, value, low=1, high=365)
        if name == "latitude":
            return finite(self, name, value, low=-90.0, high=90.0)
        if name == "north":
            way = vec3(self, name, value, one_number=False)
            flat = glm.vec3(way.x, 0.0, way.z)
            if glm.length(flat) < 1e-6 * max(1.0, glm.length(way)) or not math.isfinite(glm.length(flat)):
                raise ComponentValueError(f"TimeOfDay.north must point somewhere along the ground (its x or z "
                                          f"not 0), got {value!r}")
            return glm.normalize(flat)
        if name == "moon_age":
            value = finite(self, name, value, low=0.0, high=SYNODIC_MONTH)
            return 0.0 if value == SYNODIC_MONTH else value
        if name == "hours_per_second":
            return finite(self, name, value, low=-MAX_HOURS_PER_SECOND, high=MAX_HOURS_PER_SECOND)
        return value


def sun_towards(time: TimeOfDay) -> glm.vec3:
    """The unit way towards the sun at ``time`` (the world's y up)."""
    return _towards(time, time.day, time.hour)


def moon_towards(time: TimeOfDay) -> glm.vec3:
    """The unit way towards the moon at ``time``: on the sun's path, ``moon_age`` /
    ``SYNODIC_MONTH`` of a turn ahead of the sun (that share of a day later in the sky, where
    the sun stands that share of a year on)."""
    turn = time.moon_age / SYNODIC_MONTH
    return _towards(time, time.day + turn * DAYS_A_YEAR, time.hour - 24.0 * turn)


def _towards(time: TimeOfDay, day: float, hour: float) -> glm.vec3:
    """The way towards a body on the sun's path standing where the sun does on ``day`` (a
    number of days, any) at ``hour``, from ``time``'s latitude and north."""
    latitude = math.radians(time.latitude)
    declination = math.radians(-23.44) * math.cos(2.0 * math.pi / 365.0 * (day + 10))
    hour_angle = math.radians(15.0 * (hour - 12.0))
    east = -math.cos(declination) * math.sin(hour_angle)
    north = math.cos(latitude) * math.sin(declination) - math.sin(latitude) * math.cos(declination) \
        * math.cos(hour_angle)
    up = math.sin(latitude) * math.sin(declination) + math.cos(latitude) * math.cos(declination) \
        * math.cos(hour_angle)
    northward = glm.vec3(time.north)
    eastward = glm.cross(northward, glm.vec3(0.0, 1.0, 0.0))
    return glm.normalize(eastward * east + northward * north + glm.vec3(0.0, up, 0.0))
