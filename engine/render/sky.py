"""The sky cube map: generated from a Skybox's colours (nothing is downloaded) or given faces.

``sky_radiance`` is the generated sky as a function of direction; tests use it to know
what colour a reflected ray must show.  The faces are in GL's order, their texels in the
directions of ``engine.core.cube_faces.face_directions`` (GL's cube-map table, kept there).

A generated sky is also drawn as that function (``SkyModel``, evaluated per pixel by
``shaders/include/sky_model.glsl``, the GLSL twin of ``sky_radiance``): the sky pass of every
view shows it at the screen's own resolution, so the sun is a round disc with a smooth edge
however far the view magnifies it, as in the procedural skies of Unity and Bevy.  Sampled
from the cube (a face of 128 texels spans 90 degrees: at 1280x720 a texel covers seven
pixels) the disc was a blocky blob.  Reflections, refraction and probes' irradiance still
read the cube: they sample it blurred by roughness, where its resolution is enough.

A generated sky's cube map is drawn on the GPU from the same function
(``engine/render/sky_bake.py``) and its light comes in closed form
(``engine.render.irradiance.generated_sky_sh``, from the shapes below); ``build_faces`` makes
the faces with numpy: the reference the tests hold the GPU's cube to, and given faces.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import moderngl
import numpy as np

from components.rendering import DEFAULT_SUN_DIRECTION, Skybox
from components.tracking import HALF_MAX, raw_field
from engine.core.cube_faces import face_directions
from engine.render.atmosphere import (
    TABLE_STEP_DEGREES,
    Air,
    air_radiance,
    air_transmittance,
    coarse_view_table,
    ground_light,
    horizon_sine,
    sky_view_table,
    space_shown,
    sun_elevation_degrees,
    sunlight_share,
)
from engine.render.clouds import CloudShape, cloud_cover
from engine.rules.light_rules import SkySun, brightest_directional_entity, luminance

if TYPE_CHECKING:
    from components import DirectionalLight
    from engine.core.world import World

SEAMLESS_CUBE_MAP = 0x884F  # GL_TEXTURE_CUBE_MAP_SEAMLESS, core since 3.2


def sun_of(skybox: Skybox, sun: SkySun | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A generated sky's sun: the unit direction towards it and its disc's linear colour.
    ``sun`` is what the world's lights made of it (``engine.rules.light_rules.sky_sun``);
    None: the Skybox's pinned ``sun_direction``, else ``DEFAULT_SUN_DIRECTION`` (a sky that
    follows no light), untinted."""
    if sun is None:
        sun = SkySun(DEFAULT_SUN_DIRECTION if skybox.sun_direction is None else tuple(skybox.sun_direction))
    direction = np.array(sun.direction, np.float64)
    return direction / np.linalg.norm(direction), np.array(skybox.sun_color)[:3] * np.array(sun.tint, np.float64)


def moon_of(skybox: Skybox, sun: SkySun | None) -> tuple[np.ndarray, np.ndarray] | None:
    """A generated sky's moon (``sun.moon``: the brightest DirectionalLight whose body is
    "moon"): the unit direction towards it and its disc's linear colour lit head on
    (``Skybox.moon_color`` times its light's colour); None: no moon."""
    if sun is None or sun.moon is None:
        return None
    direction = np.array(sun.moon, np.float64)
    return direction / np.linalg.norm(direction), np.array(skybox.moon_color)[:3] * np.array(sun.moon_tint, np.float64)


def sky_radiance(skybox: Skybox, directions: np.ndarray, sun: SkySun | None = None,
                 clouds: CloudShape | None = None) -> np.ndarray:
    """Linear RGB of the generated sky along each unit direction (..., 3), with ``sun``
    (``sun_of``) and ``clouds`` (``engine.render.clouds.cloud_shape`` of a CloudLayer)."""
    d = np.asarray(directions, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    if clouds is not None:
        return model_sky(sky_model(skybox, sun, clouds), d)
    if skybox.model == "atmosphere":
        return model_radiance(sky_model(skybox, sun), d)
    return _gradient(_colours(skybox), d) + _sun_light(skybox, d, sun)


def air_of(skybox: Skybox) -> Air:
    """The air of an atmosphere Skybox (``engine/render/atmosphere.py``): its ``rayleigh`` and
    ``haze``, its ``ground`` colour the ground's albedo, the eye at its ``altitude``."""
    return Air(rayleigh=float(skybox.rayleigh), haze=float(skybox.haze),
               ground=tuple(float(c) for c in tuple(skybox.ground)[:3]), eye_km=float(skybox.altitude) / 1000.0)


def sunlight_tint(skybox: Skybox | None, direction: tuple[float, float, float]) -> tuple[float, float, float]:
    """What an atmosphere ``skybox`` that follows the sun and tints it (``tints_sunlight``)
    does to the light of the sun shining along ``direction`` (the way its light travels): the
    share of it the air lets through on its way down over the share it lets through from
    straight overhead (the light's colour is its colour at noon); white for any other sky.
    The lights' rows (the prepare stage) and the light mirrors throw (the shadows stage) both
    take it."""
    if skybox is None or skybox.model != "atmosphere" or not skybox.tints_sunlight \
            or skybox.sun_direction is not None:
        return (1.0, 1.0, 1.0)
    return _sunlight_tint(air_of(skybox), tuple(float(c) for c in direction))


@functools.lru_cache(maxsize=64)
def _sunlight_tint(air: Air, direction: tuple[float, float, float]) -> tuple[float, float, float]:
    towards = -np.array(direction, np.float64)
    share = sunlight_share(air, towards / np.linalg.norm(towards))
    overhead = sunlight_share(air, np.array([0.0, 1.0, 0.0]))
    return tuple(float(c) for c in share / np.maximum(overhead, 1e-6))


class AirLight(NamedTuple):
    """The sky body whose light a fog's air scatters (``air_light``)."""

    entity: int
    light: DirectionalLight
    tint: tuple[float, float, float]   # what an atmosphere's air leaves of its light (``sunlight_tint``)

    @property
    def towards(self) -> tuple[float, float, float]:
        """The unit way towards it."""
        return tuple(-float(c) for c in raw_field(self.light, "direction"))


def air_light(world: World) -> AirLight | None:
    """The sky body whose light a fog's air scatters (its glow towards it, the light shafts):
    the brighter, by the luminance of its colour x intensity x what an atmosphere leaves of
    it on its way down (``sunlight_tint``), of the world's sun and its moon
    (``brightest_directional``): the sun by day, the moon once the sun has set or wherever
    it outshines the sun.  The light scattered changes smoothly as one takes over from the
    other (equal where they cross); its way turns at once.  None: neither shines."""
    skies = world.query_one(Skybox)
    sky = skies[0][1] if skies else None
    best, brightest = None, 0.0
    for body in ("sun", "moon"):
        found = brightest_directional_entity(world, body)
        if found is None:
            continue
        entity, light = found
        tint = sunlight_tint(sky, tuple(raw_field(light, "direction")))   # (past the in-place watch: a read)
        bright = float(luminance(np.array(raw_field(light, "color").xyz) * light.intensity * np.array(tint)))
        if bright > brightest:
            best, brightest = AirLight(entity, light, tint), bright
    return best


def model_radiance(model: SkyModel, directions: np.ndarray, disc: bool = True, coarse: bool = False) -> np.ndarray:
    """Linear RGB of an atmosphere sky ``model`` along unit ``directions`` (..., 3), as
    sky_model.glsl's ATMOSPHERE build draws it: the sky-view table (``sky_view_table`` at the
    sun's elevation, the one the GPU's is held to; ``coarse``: the CPU's small one) times the
    sunlight above the true horizon (``horizon_sine``: the ways below the level one, down to
    it, read the table's horizon row), the ground fading in below it as the gradient's does, and
    (``disc``) the sun's disc dimmed by the air."""
    d = np.asarray(directions, np.float64)
    towards = np.array(model.sun_direction, np.float64)
    table = model.coarse_table if coarse else sky_view_table(model.air, model.air_elevation)
    air = np.array(model.air_light) * air_radiance(table, d, towards)
    if model.moon_lights_air:   # the moonlight the air scatters: the same table at the moon's elevation
        table = model.moon_coarse_table if coarse else sky_view_table(model.air, model.moon_elevation)
        air = air + np.array(model.moon_air) * air_radiance(table, d, np.array(model.moon_direction, np.float64))
    y = d[..., 1:2] + horizon_sine(model.air)   # (the true horizon, below the level one from up high)
    colour = np.where(y >= 0.0, air, air + (np.array(model.ground) - air) * ground_share(y))
    if disc:
        colour = colour + disc_strength(np.clip(d @ towards, -1.0, 1.0)[..., None]) * np.array(model.sun_color) \
            + moon_light(d, np.array(model.moon_direction), towards, np.array(model.moon_color))
    return colour


def clear_radiance(model: SkyModel, directions: np.ndarray, coarse: bool = False) -> np.ndarray:
    """The generated sky ``model`` along unit ``directions`` (..., 3) without its discs or
    clouds (sky_model.glsl's ``clear_sky``; an atmosphere's space left out, as
    ``model_radiance``)."""
    d = np.asarray(directions, np.float64)
    if model.atmosphere:
        return model_radiance(model, d, disc=False, coarse=coarse)
    cos_sun = np.clip(d @ np.array(model.sun_direction), -1.0, 1.0)[..., None]
    return _gradient((model.zenith, model.horizon, model.ground), d) + glow_strength(cos_sun) * GLOW_COLOR


def disc_radiance(model: SkyModel, directions: np.ndarray) -> np.ndarray:
    """The sun's and the moon's discs of ``model`` along unit ``directions`` (..., 3)."""
    d = np.asarray(directions, np.float64)
    towards = np.array(model.sun_direction)
    return disc_strength(np.clip(d @ towards, -1.0, 1.0)[..., None]) * np.array(model.sun_color) \
        + moon_light(d, np.array(model.moon_direction), towards, np.array(model.moon_color))


def cloud_hidden(model: SkyModel, directions: np.ndarray, coarse: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """What ``model``'s clouds do along unit ``directions`` (..., 3): the share of the sky
    behind them they hide (0 without clouds) and their light (``clouds.cloud_cover``, lit by
    the sun and the clear sky straight up)."""
    d = np.asarray(directions, np.float64)
    if model.clouds is None:
        return np.zeros(d.shape[:-1]), np.zeros(d.shape[:-1] + (3,))
    overhead = clear_radiance(model, np.array([0.0, 1.0, 0.0]), coarse)
    return cloud_cover(model.clouds, d, np.array(model.sun_direction), np.array(model.sun_color), overhead,
                       np.array(model.moon_direction), np.array(model.moon_light))


def model_sky(model: SkyModel, directions: np.ndarray, coarse: bool = False, disc: bool = True) -> np.ndarray:
    """Linear RGB of the generated sky ``model`` along unit ``directions`` (..., 3), as
    sky_model.glsl's ``generated_sky`` draws it: the clear sky and (``disc``) the discs, the
    clouds over both (an atmosphere's space left out: ``build_faces`` adds it)."""
    d = np.asarray(directions, np.float64)
    clear = clear_radiance(model, d, coarse)
    discs = disc_radiance(model, d) if disc else 0.0
    if model.clouds is None:
        return clear + discs
    hidden, light = cloud_hidden(model, d, coarse)
    hidden = hidden[..., None]
    return clear * (1.0 - hidden) + light * hidden + discs * (1.0 - hidden)


def _colours(skybox: Skybox) -> tuple[tuple[float, ...], ...]:
    """The zenith, horizon and ground colours (linear RGB), as a key."""
    colours = (skybox.zenith, skybox.horizon, skybox.ground)
    return tuple(tuple(float(c) for c in tuple(colour)[:3]) for colour in colours)


# The generated sky's shape (``sky_model.glsl`` writes the same numbers): each part is a
# function of the cosine of one angle, the gradient's from straight up, the sun's from the sun.
def zenith_share(y: np.ndarray) -> np.ndarray:
    """Above the horizon, the share of the way from horizon to zenith at height ``y``."""
    return np.clip(y, 0.0, 1.0) ** 0.6


def ground_share(y: np.ndarray) -> np.ndarray:
    """Below it, the share of the way from horizon to ground (all of it 14 degrees down)."""
    return np.clip(-y * 4.0, 0.0, 1.0)


GLOW_COLOR = np.array([1.0, 0.55, 0.25])


def glow_strength(cos_sun: np.ndarray) -> np.ndarray:
    """The warm band around the sun, times ``GLOW_COLOR``: 0.25 cos^4 on the sun's side."""
    facing = np.clip(cos_sun, 0.0, 1.0)
    facing = facing * facing
    return 0.25 * facing * facing


DISC_EDGE = 0.9990   # cos 2.6 degrees from the disc's centre: its light starts ...
DISC_FULL = 0.9995   # ... and at cos 1.8 degrees it is whole


def disc_strength(cos_sun: np.ndarray) -> np.ndarray:
    """The sun's disc, times its colour (and the moon's, times its lit share)."""
    return np.clip((cos_sun - DISC_EDGE) / (DISC_FULL - DISC_EDGE), 0.0, 1.0)


MOON_RADIUS_SINE = float(np.sqrt(1.0 - DISC_EDGE * DISC_EDGE))   # the disc's edge, sin of its angle from the centre
MOON_RIM = 0.02   # the moon's rim fades over this share of its radius, half inside the edge, half out
MOON_LIMB = 0.999   # on the rim further out the law is read here (at the edge a full moon is 0 / 0)
# Earthshine: the sunlight the Earth sends back onto the moon, over the sun's own, with the
# Earth full as seen from the moon: its geometric albedo (0.367) times (its radius over the
# moon's distance, 6371 / 384400 km) squared.
EARTHSHINE = 0.367 * (6371.0 / 384400.0) ** 2


def earthshine(moon: np.ndarray, sun: np.ndarray) -> float:
    """The light the Earth sends the moon's disc, over what the sun gives a point it lights
    head on (``moon_share``'s scale): ``EARTHSHINE`` times a Lambert sphere's phase function
    (sin a + (pi - a) cos a) / pi at the Earth's phase seen from the moon, a the angle between
    the ways towards the sun and the moon (the moon new, the Earth full: the most; the moon
    full: none).  It comes from beside the eye, so Lommel and Seeliger's law gives the disc
    the same light all across (mu0 = mu); the old moon in the new moon's arms."""
    a = float(np.arccos(np.clip(np.dot(moon, sun), -1.0, 1.0)))
    return EARTHSHINE * (np.sin(a) + (np.pi - a) * np.cos(a)) / np.pi


def moon_cover(reach: np.ndarray) -> np.ndarray:
    """How much of a way ``reach`` off the moon's centre (its angle's sine over
    ``MOON_RADIUS_SINE``: the disc's edge at 1) the disc covers: 1 inside, 0 outside, a ramp
    ``MOON_RIM`` of the radius wide centred on the edge, so the rim is anti-aliased as a hard
    disc's coverage is (about a pixel at a 60-degree lens on 1080 rows) and the disc keeps
    its area: a crescent, whose light lies along the rim, keeps the light Lommel and
    Seeliger's law gives a hard disc (the sun's disc, a glow, fades over 29% of its radius;
    the moon's crescent would lose most of its light in such a fade)."""
    return np.clip((1.0 + 0.5 * MOON_RIM - reach) / MOON_RIM, 0.0, 1.0)


def moon_share(d: np.ndarray, moon: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """The moon's disc along unit directions ``d`` (...): its cover (``moon_cover``) times
    the light its ball sends back lit from ``sun`` (towards the sun), by Lommel and
    Seeliger's law for the moon's dust, 2 mu0 / (mu0 + mu) (mu0 the sunlight's cosine at the
    ball's point seen along ``d``, mu the eye's; on the rim past ``MOON_LIMB``, that point's):
    1 across a full moon (no limb darkening, as the real one), a crescent's lit edge brighter
    than its middle (2 at the limb), past the terminator the Earth's light (``earthshine``)."""
    cos_moon = np.clip(d @ moon, -1.0, 1.0)
    across = (d - cos_moon[..., None] * moon) / MOON_RADIUS_SINE   # where on the disc, its edge at 1
    reach = np.sqrt((across * across).sum(-1))
    cover = moon_cover(reach) * (cos_moon > 0.0)
    across = across * (np.minimum(reach, MOON_LIMB) / np.maximum(reach, 1e-30))[..., None]   # (the rim: the limb's)
    facing = np.sqrt(np.maximum(1.0 - (across * across).sum(-1), 0.0))   # mu
    lit = np.maximum((across - moon * facing[..., None]) @ sun, 0.0)      # mu0
    return cover * (2.0 * lit / np.maximum(lit + facing, 1e-4) + earthshine(moon, sun))


def moon_light(d: np.ndarray, moon: np.ndarray, sun: np.ndarray, colour: np.ndarray) -> np.ndarray:
    """The moon's part of the sky along unit directions ``d`` (..., 3): ``moon_share`` times
    its disc's ``colour`` (0: no moon)."""
    if not np.any(colour):
        return np.zeros(d.shape[:-1] + (3,))
    return moon_share(d, moon, sun)[..., None] * colour


def moon_phase(moon: np.ndarray, sun: np.ndarray) -> tuple[float, np.ndarray]:
    """The moon's light as its phase leaves it: the integral of ``moon_share`` over its disc
    against a full one's, and the unit way its light comes from on average (a crescent's lies
    towards the sun).  Integrated in rings about the disc's centre, by the sine of their
    angle (so a ring's ``moon_cover`` is exact): Gauss-Legendre rings inside the rim and
    across it (the rim's light, where a crescent's lies, is its own interval), 96 ways
    round; within 0.1% of a fine grid's sum, and a hard disc's share within 0.2% of
    Lommel and Seeliger's closed form."""
    moon = moon / np.linalg.norm(moon)
    side = np.cross(moon, [0.0, 1.0, 0.0] if abs(moon[1]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, moon)
    reach, weight = _PHASE_RINGS
    turn = (np.arange(_PHASE_WAYS) + 0.5) * (2.0 * np.pi / _PHASE_WAYS)
    sine = reach * MOON_RADIUS_SINE
    d = (np.sqrt(1.0 - sine * sine)[:, None, None] * moon
         + sine[:, None, None] * (np.cos(turn)[None, :, None] * side + np.sin(turn)[None, :, None] * up))
    area = (weight * sine / np.sqrt(1.0 - sine * sine))[:, None]   # solid angle: sin ds dturn / cos
    full = (moon_share(d, moon, -moon) * area).sum()
    lit = moon_share(d, moon, sun) * area
    if full <= 0.0 or lit.sum() <= 0.0:
        return 0.0, moon
    centre = (lit[..., None] * d).sum(axis=(0, 1))
    return float(lit.sum() / full), centre / np.linalg.norm(centre)


def _rings() -> tuple[np.ndarray, np.ndarray]:
    """``moon_phase``'s rings: reach (of the disc's radius) and width, 48 Gauss-Legendre
    nodes inside the rim, 16 across it."""
    inner = 1.0 - 0.5 * MOON_RIM
    parts = []
    for low, high, count in ((0.0, inner, 48), (inner, 1.0 + 0.5 * MOON_RIM, 16)):
        x, w = np.polynomial.legendre.leggauss(count)
        parts.append((low + (x + 1.0) * 0.5 * (high - low), w * 0.5 * (high - low) * MOON_RADIUS_SINE))
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


_PHASE_RINGS = _rings()
_PHASE_WAYS = 96


@functools.lru_cache(maxsize=8)
def _phase_share(moon: tuple[float, float, float], sun: tuple[float, float, float]) -> float:
    """``moon_phase``'s share, kept for the last few ways (a sky's uniforms ask each write)."""
    return moon_phase(np.array(moon, np.float64), np.array(sun, np.float64))[0]


def _gradient(colours: tuple[tuple[float, ...], ...], d: np.ndarray) -> np.ndarray:
    """The sky without its sun along unit directions ``d`` (..., 3): horizon to zenith above,
    horizon to ground below (a function of the height alone)."""
    zenith, horizon, ground = (np.array(colour) for colour in colours)
    y = d[..., 1:2]
    return np.where(y >= 0.0, horizon + (zenith - horizon) * zenith_share(y),
                    horizon + (ground - horizon) * ground_share(y))


def _sun_light(skybox: Skybox, d: np.ndarray, sun: SkySun | None) -> np.ndarray:
    """The sun's part of the sky along unit directions ``d`` (..., 3): a warm band around its
    azimuth, so that left and right of the sky differ, and its disc; and its moon's disc."""
    towards, disc_color = sun_of(skybox, sun)
    cos_sun = np.clip(d @ towards, -1.0, 1.0)[..., None]
    light = glow_strength(cos_sun) * GLOW_COLOR + disc_strength(cos_sun) * disc_color
    moon = moon_of(skybox, sun)
    return light if moon is None else light + moon_light(d, moon[0], towards, moon[1])


@dataclass(frozen=True)
class SkyModel:
    """What ``sky_radiance`` needs of a generated Skybox: linear RGB colours and the unit
    direction towards the sun (``shaders/include/sky_model.glsl``'s uniforms).  An atmosphere
    (``air`` not None: ``engine/render/atmosphere.py``) has no zenith or horizon colour: its
    sky is the sky-view table the GPU draws for ``air`` and the sun's ``air_elevation``
    (degrees; ``engine/render/sky_view.py``) times ``air_light``, the sunlight above the air;
    ``ground`` is the ground's radiance and ``sun_color`` the disc's colour through the air,
    from ``coarse_table`` (the CPU's small table, which the sky's light is projected from);
    ``space`` what lies beyond the air (given faces: stars, a galaxy)."""

    zenith: tuple[float, float, float]
    horizon: tuple[float, float, float]
    ground: tuple[float, float, float]
    sun_direction: tuple[float, float, float]
    sun_color: tuple[float, float, float]
    air_light: tuple[float, float, float] = (0.0, 0.0, 0.0)
    air: Air | None = None
    air_elevation: float = 0.0
    coarse_table: np.ndarray | None = field(default=None, compare=False, repr=False)
    # An atmosphere's space beyond its air (the Skybox's given faces; None: black), seen
    # through the air (the table's fourth channel): ``space_key`` names it for comparing.
    space: np.ndarray | None = field(default=None, compare=False, repr=False)
    # Its moon (``moon_of``): the way towards it and its disc's colour lit head on (an
    # atmosphere's through the air, as the sun's); black: none.
    moon_direction: tuple[float, float, float] = (0.0, 1.0, 0.0)
    moon_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # Its CloudLayer's clouds (``engine/render/clouds.py``; None: a clear sky).
    clouds: CloudShape | None = None
    # An atmosphere's moonlit air: ``moon_air`` the moon's light above the air (its disc's
    # colour lit head on times the share of a full moon's light its phase leaves: the sun's
    # ``air_light`` is its disc's colour likewise), scattered as the sun's is by the sky-view
    # table at the moon's elevation (``moon_elevation``, degrees, the GPU's; ``moon_coarse_table``
    # the CPU's small one); black: no moon, or a gradient sky.
    moon_air: tuple[float, float, float] = (0.0, 0.0, 0.0)
    moon_elevation: float = 0.0
    moon_coarse_table: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def space_key(self) -> int:
        return 0 if self.space is None else id(self.space)

    @property
    def atmosphere(self) -> bool:
        return self.air is not None

    @property
    def moon(self) -> bool:
        """Whether it draws a moon's disc (sky_model.glsl's MOON builds)."""
        return any(self.moon_color)

    @property
    def moon_light(self) -> tuple[float, float, float]:
        """Its moon's light (its disc's colour times the share of a full moon's light its
        phase leaves: what lights the clouds as the sun's disc colour does); black: none."""
        if not self.moon:
            return (0.0, 0.0, 0.0)
        share = _phase_share(self.moon_direction, self.sun_direction)
        return tuple(float(c) * share for c in self.moon_color)

    @property
    def moon_lights_air(self) -> bool:
        """Whether its air scatters a moon's light (sky_model.glsl's MOON_AIR builds)."""
        return self.atmosphere and any(self.moon_air)

    def uniforms(self) -> dict[str, tuple[float, float, float] | float]:
        """The sky pass's uniforms, by name (an atmosphere's build has no zenith or horizon)."""
        moon = {"sky_moon_direction": self.moon_direction, "sky_moon_color": self.moon_color} if self.moon else {}
        if self.moon and self.clouds is not None:   # (what lights the clouds, as the sun's disc colour)
            moon["sky_moon_light"] = self.moon_light
        if self.moon_lights_air:   # (a moon below the horizon: no disc, its light still in the air)
            moon.update(sky_moon_direction=self.moon_direction, moon_air_light=self.moon_air)
        if self.atmosphere:
            return {"sky_light": self.air_light, "sky_ground": self.ground, "sky_horizon_sine": horizon_sine(self.air),
                    "sky_sun_direction": self.sun_direction, "sky_sun_color": self.sun_color, **moon}
        return {"sky_zenith": self.zenith, "sky_horizon": self.horizon, "sky_ground": self.ground,
                "sky_sun_direction": self.sun_direction, "sky_sun_color": self.sun_color, **moon}


def is_generated(skybox: Skybox | None) -> bool:
    """Whether ``skybox`` is drawn from its function (a gradient without given faces, or an
    atmosphere, whose given faces are the space beyond its air) rather than from its faces."""
    return skybox is not None and (skybox.faces is None or skybox.model == "atmosphere")


def sky_model(skybox: Skybox | None, sun: SkySun | None = None, clouds: CloudShape | None = None) -> SkyModel | None:
    """The generated sky of ``skybox`` as the sky pass draws it, with ``sun`` (``sun_of``)
    and ``clouds``; None for a gradient's given faces or no Skybox (the pass samples the cube
    map)."""
    if not is_generated(skybox):
        return None

    def rgb(value) -> tuple[float, float, float]:
        return tuple(float(c) for c in tuple(value)[:3])

    towards, disc_color = sun_of(skybox, sun)
    moon = moon_of(skybox, sun)
    moon_way, moon_color = ((0.0, 1.0, 0.0), np.zeros(3)) if moon is None else moon
    if skybox.model == "atmosphere":
        air = air_of(skybox)
        elevation = sun_elevation_degrees(towards)
        coarse = coarse_view_table(air, elevation)
        elevation = round(elevation / TABLE_STEP_DEGREES) * TABLE_STEP_DEGREES   # the GPU table's
        ground = ground_light(air, coarse, towards) * disc_color
        moon_air, moon_elevation, moon_coarse = np.zeros(3), 0.0, None
        if moon is not None:
            # The air's moonlight: the moon's light above the air (its phase's share of a
            # full moon's), scattered by the table at its elevation as the sun's is by its own.
            moon_air = moon_color * _phase_share(tuple(moon_way), tuple(towards))
            moon_elevation = sun_elevation_degrees(moon_way)
            moon_coarse = coarse_view_table(air, moon_elevation)
            moon_elevation = round(moon_elevation / TABLE_STEP_DEGREES) * TABLE_STEP_DEGREES
            ground = ground + ground_light(air, moon_coarse, moon_way) * moon_air
            moon_color = moon_color * sunlight_share(air, moon_way)   # (its disc dimmed and reddened, as the sun's)
        return SkyModel((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), rgb(ground), rgb(towards),
                        rgb(disc_color * sunlight_share(air, towards)), rgb(disc_color), air, elevation, coarse,
                        skybox.faces, rgb(moon_way), rgb(moon_color), clouds, rgb(moon_air), moon_elevation,
                        moon_coarse)
    return SkyModel(rgb(skybox.zenith), rgb(skybox.horizon), rgb(skybox.ground), rgb(towards), rgb(disc_color),
                    moon_direction=rgb(moon_way), moon_color=rgb(moon_color), clouds=clouds)


def build_faces(skybox: Skybox, sun: SkySun | None = None, clouds: CloudShape | None = None) -> np.ndarray:
    """Six faces (6, size, size, 3) float32 in GL order, from ``skybox.faces`` or generated
    (with ``sun``: ``sun_of``, and ``clouds``).  An atmosphere's space (its given faces) is
    added through the air (and what the clouds leave of it) at its own texels: given at
    ``face_size`` texels a face, as the tests give it, each of the cube's texels is its own."""
    if skybox.model == "atmosphere" and skybox.faces is not None:
        model = sky_model(skybox, sun, clouds)
        n = skybox.face_size
        faces = np.asarray(skybox.faces, np.float64)
        if faces.shape[1] != n:
            raise ValueError(f"build_faces: an atmosphere's space of {faces.shape[1]} texels a face, the cube "
                             f"{n}: give them at one size")
        table, towards = sky_view_table(model.air, model.air_elevation), np.array(model.sun_direction)
        built = []
        for f in range(6):
            ways = face_directions(f, n)
            built.append(model_sky(model, ways) + faces[f] * air_transmittance(table, ways, towards)
                         * space_shown(air_radiance(table, ways, towards))
                         * (ways[..., 1:2] >= -horizon_sine(model.air))
                         * (1.0 - cloud_hidden(model, ways)[0][..., None]))
        return np.stack(built).astype(np.float32)
    if skybox.faces is not None:
        faces = np.asarray(skybox.faces, np.float32)
        if faces.ndim != 4 or faces.shape[0] != 6 or faces.shape[1] != faces.shape[2] or faces.shape[3] != 3:
            raise ValueError(f"Skybox.faces must be six square HxWx3 images, got shape {faces.shape}")
        if not np.isfinite(faces).all() or faces.min() < 0:
            raise ValueError("Skybox.faces must hold finite linear colours >= 0")
        return faces
    n = skybox.face_size
    return np.stack([sky_radiance(skybox, face_directions(f, n), sun, clouds) for f in range(6)]).astype(np.float32)


def upload_cube(ctx: moderngl.Context, faces: np.ndarray) -> moderngl.TextureCube:
    """A mipmapped RGB16F cube map with seamless filtering (reflections sample its mips).
    Its texels are kept within a half float (65504, as the shaders keep what they write:
    shaders/include/hdr.glsl): a generated sky adds colours that are each within it (the
    horizon, the sun's glow and disc), and past it the cast gave +inf, which the cube's
    filtering and mips turned into NaN in the frame."""
    size = faces.shape[1]
    texels = np.minimum(faces, HALF_MAX).astype(np.float16)
    cube = ctx.texture_cube((size, size), 3, texels.tobytes(), dtype="f2")
    cube.build_mipmaps()
    cube.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
    ctx.enable_direct(SEAMLESS_CUBE_MAP)
    return cube


def flat_cube(ctx: moderngl.Context, color: tuple[float, float, float]) -> moderngl.TextureCube:
    """A one-colour cube map: the background of a world without a Skybox."""
    return upload_cube(ctx, np.tile(np.asarray(color, np.float32), (6, 4, 4, 1)))
