"""A physically based sky: sunlight scattered by the air (``Skybox.model = "atmosphere"``).

The sky of a planet's atmosphere seen from its ground, as Unreal's SkyAtmosphere, Unity
HDRP's physically based sky, Godot's PhysicalSkyMaterial and three.js's Sky draw it: blue
overhead at noon, white near the horizon, red and orange round a low sun, dark at night.
The method is Hillaire's ("A Scalable and Production Ready Sky and Atmosphere Rendering
Technique", EGSR 2020), computed here with numpy in three tables:

- **transmittance** (``transmittance_table``): the share of light that crosses the air from
  a point at radius r along a way of cosine mu from the zenith to space, a table over
  (r, mu) in Bruneton and Neyret's parameterisation ("Precomputed Atmospheric Scattering",
  2008: the distance to the top of the air, so rays grazing the horizon get their share of
  rows); a way that meets the ground is dark.
- **multiple scattering** (``multiple_scattering_table``): Hillaire's Psi_ms(h, mu_sun), the
  light scattered twice or more that reaches a point, per unit of sunlight, from the
  second order's isotropic integral over the sphere and the geometric series 1 / (1 - f_ms)
  of the orders after it (the ground's light included, ``Air.ground``).  Without it a low
  sun's sky is too dark and too saturated.
- **sky view** (``sky_view_table``): the radiance the eye ``Air.eye_km`` above the ground sees
  per unit of sunlight along each way above the horizon, by the way's elevation (rows,
  denser near the horizon: the row is sqrt(elevation / 90 degrees)) and its azimuth from the
  sun's (columns, 0 to 180 degrees: the sky is symmetric about the sun's vertical plane).
  Each way is marched to the top of the air in ``VIEW_STEPS`` steps (longer the farther),
  each step's light Rayleigh's and Mie's single scattering of the sun's transmitted light
  plus the multiple scattering, integrated over the step in closed form (the energy-
  conserving step of Hillaire's section 5.3).

The sky pass reads the sky-view table by the same rule (``shaders/include/sky_model.glsl``'s
ATMOSPHERE build; ``air_radiance`` here is its twin, bilinear between texel centres as GL
filters): one lookup a pixel.  The table depends on the sun's elevation alone: the GPU draws
it (``engine/render/sky_view.py``, held to ``sky_view_table`` here) whenever the sun rises or
sets by ``TABLE_STEP_DEGREES``; the disc and the azimuth follow the sun exactly.  What the CPU
needs of the sky (its light as spherical harmonics, the ground's light) comes from a small
table made here once a degree (``coarse_view_table``).  Below the horizon the ground
(``Air.ground`` lit by the sun and the sky) fades in as the gradient sky's does.

The air's constants are Earth's (Hillaire's table 1: Rayleigh scattering of 680, 550 and
440 nm light, Mie scattering and extinction with a Cornette-Shanks phase of g = 0.8, ozone's
absorption in a layer 25 km up); ``Air.rayleigh`` and ``Air.haze`` scale the molecules' and
the aerosols' densities (thicker air: redder sunsets; haze: a whiter sky and a wider glow).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from engine.core.color import LUMINANCE

GROUND_KM = 6360.0     # the planet's radius
TOP_KM = 6460.0        # the top of its air
EYE_KM = 0.2           # how high the eye stands by default (Skybox.altitude's; a level's own heights are nothing to it)
RAYLEIGH_SCATTERING = np.array([5.802, 13.558, 33.1]) * 1e-3   # per km at the ground (680, 550, 440 nm)
RAYLEIGH_HEIGHT_KM = 8.0
MIE_SCATTERING = 3.996e-3
MIE_EXTINCTION = 4.40e-3
MIE_HEIGHT_KM = 1.2
MIE_G = 0.8
OZONE_ABSORPTION = np.array([0.650, 1.881, 0.085]) * 1e-3
OZONE_CENTRE_KM = 25.0
OZONE_HALF_WIDTH_KM = 15.0

TRANSMITTANCE_SIZE = (32, 128)   # (radius rows, mu columns)
TRANSMITTANCE_STEPS = 40
SCATTERING_SIZE = (32, 32)       # multiple scattering: (height rows, sun cosine columns)
SCATTERING_DIRECTIONS = 64
SCATTERING_STEPS = 20
VIEW_SIZE = (48, 96)             # sky view: (elevation rows, azimuth columns)
VIEW_STEPS = 30
COARSE_SIZE = (24, 48)           # the CPU's smaller table (the sky's light, the ground's)
COARSE_STEPS = 20
ELEVATION_STEP_DEGREES = 1.0     # the sun's elevation the CPU's table is made for, rounded to this
TABLE_STEP_DEGREES = 0.02        # ... and the GPU's (a sky's colours move by less than a code value)


@dataclass(frozen=True)
class Air:
    """What an atmosphere is made of: ``rayleigh`` and ``haze`` scale Earth's molecules and
    aerosols (1: a clear day), ``ground`` the ground's albedo (linear RGB: it lights the air
    from below and shows below the horizon), ``multiple`` whether light scattered more than
    once is counted (tests compare the single scattering with its closed form), ``eye_km`` how
    high above the ground the eye stands (``Skybox.altitude``: the air above it thinner)."""

    rayleigh: float = 1.0
    haze: float = 1.0
    ground: tuple[float, float, float] = (0.3, 0.3, 0.3)
    multiple: bool = True
    eye_km: float = EYE_KM

    @property
    def column(self) -> Air:
        """The air without its eye (what the transmittance and multiple-scattering tables
        depend on: the same for every altitude, so a level's altitude makes them once)."""
        return self if self.eye_km == EYE_KM else replace(self, eye_km=EYE_KM)


# --- the air's stuff --------------------------------------------------------------------------
def _densities(air: Air, height: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rayleigh's, Mie's and ozone's densities (relative to the ground's) at ``height`` km."""
    h = np.maximum(height, 0.0)
    rayleigh = air.rayleigh * np.exp(-h / RAYLEIGH_HEIGHT_KM)
    mie = air.haze * np.exp(-h / MIE_HEIGHT_KM)
    ozone = air.rayleigh * np.maximum(0.0, 1.0 - np.abs(h - OZONE_CENTRE_KM) / OZONE_HALF_WIDTH_KM)
    return rayleigh, mie, ozone


def _extinction(air: Air, height: np.ndarray) -> np.ndarray:
    """The air's extinction per km (..., 3) at ``height`` km."""
    rayleigh, mie, ozone = _densities(air, height)
    return (rayleigh[..., None] * RAYLEIGH_SCATTERING + mie[..., None] * MIE_EXTINCTION
            + ozone[..., None] * OZONE_ABSORPTION)


def rayleigh_phase(nu: np.ndarray) -> np.ndarray:
    """Rayleigh's phase function at the cosine ``nu`` of the scattering angle (per sr)."""
    return 3.0 / (16.0 * math.pi) * (1.0 + nu * nu)


def mie_phase(nu: np.ndarray, g: float = MIE_G) -> np.ndarray:
    """Cornette and Shanks' phase function (per sr), Henyey-Greenstein's with Rayleigh's shape."""
    g2 = g * g
    return (3.0 / (8.0 * math.pi) * (1.0 - g2) * (1.0 + nu * nu)
            / ((2.0 + g2) * np.power(np.maximum(1.0 + g2 - 2.0 * g * nu, 1e-6), 1.5)))


def _to_top(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """The distance from radius ``r`` along a way of cosine ``mu`` to the top of the air."""
    return -r * mu + np.sqrt(np.maximum(r * r * (mu * mu - 1.0) + TOP_KM * TOP_KM, 0.0))


def _meets_ground(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    return (mu < 0.0) & (r * r * (mu * mu - 1.0) + GROUND_KM * GROUND_KM >= 0.0)


def _to_ground(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    return -r * mu - np.sqrt(np.maximum(r * r * (mu * mu - 1.0) + GROUND_KM * GROUND_KM, 0.0))


# --- tables -----------------------------------------------------------------------------------
_HORIZON = math.sqrt(TOP_KM * TOP_KM - GROUND_KM * GROUND_KM)   # the top's distance along the ground's tangent


def _bilinear(table: np.ndarray, row: np.ndarray, column: np.ndarray) -> np.ndarray:
    """``table`` (rows, columns, 3) between its entries at fractional ``row`` and ``column``
    in [0, 1] (0 and 1 the first and last entries).  (One flat index and four takes: the
    sky-view table's march spends most of its time here, twice as long with 2-D indexing.)"""
    rows, columns = table.shape[:2]
    y = np.clip(row, 0.0, 1.0) * (rows - 1)
    x = np.clip(column, 0.0, 1.0) * (columns - 1)
    y0 = np.minimum(y.astype(np.intp), rows - 2)
    x0 = np.minimum(x.astype(np.intp), columns - 2)
    fy, fx = (y - y0)[..., None], (x - x0)[..., None]
    flat = table.reshape(-1, table.shape[2])
    at = y0 * columns + x0
    top = np.take(flat, at, axis=0)
    top += (np.take(flat, at + 1, axis=0) - top) * fx
    bottom = np.take(flat, at + columns, axis=0)
    bottom += (np.take(flat, at + columns + 1, axis=0) - bottom) * fx
    top += (bottom - top) * fy
    return top


def transmittance_table(air: Air) -> np.ndarray:
    """Transmittance to space (rows of radius, columns of mu; Bruneton's mapping, 3): what
    ``transmittance`` reads, and the GPU's table (``engine/render/sky_view.py``) is given."""
    return _transmittance_table(air.column)


@functools.lru_cache(maxsize=8)
def _transmittance_table(air: Air) -> np.ndarray:
    rows, columns = TRANSMITTANCE_SIZE
    x_r = np.linspace(0.0, 1.0, rows)[:, None]
    x_mu = np.linspace(0.0, 1.0, columns)[None, :]
    rho = _HORIZON * x_r
    r = np.sqrt(rho * rho + GROUND_KM * GROUND_KM)
    d_min, d_max = TOP_KM - r, rho + _HORIZON
    d = d_min + x_mu * (d_max - d_min)
    mu = np.where(d > 0.0, (_HORIZON ** 2 - rho * rho - d * d) / np.maximum(2.0 * r * d, 1e-9), 1.0)
    mu = np.clip(mu, -1.0, 1.0)
    # Steps finer near the start (t = d u^2, the midpoint rule in u), where a ray from low
    # down crosses the thick air: uniform ones were 1.3% off a sun 8 degrees up.
    u = (np.arange(TRANSMITTANCE_STEPS) + 0.5) / TRANSMITTANCE_STEPS
    along = d[..., None] * u * u                                  # (rows, columns, steps)
    height = np.sqrt(r[..., None] ** 2 + along * along + 2.0 * r[..., None] * mu[..., None] * along) - GROUND_KM
    weights = 2.0 * u / TRANSMITTANCE_STEPS                       # dt / d
    depth = (_extinction(air, height) * weights[:, None]).sum(axis=2) * d[..., None]
    return np.exp(-depth)


def transmittance(air: Air, r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """The share of light (..., 3) crossing the air from radius ``r`` km along a way of
    cosine ``mu`` from the zenith (0 where the way meets the ground)."""
    r = np.clip(np.asarray(r, np.float64), GROUND_KM, TOP_KM)
    mu = np.clip(np.asarray(mu, np.float64), -1.0, 1.0)
    rho = np.sqrt(np.maximum(r * r - GROUND_KM * GROUND_KM, 0.0))
    d_min, d_max = TOP_KM - r, rho + _HORIZON
    x_mu = (_to_top(r, mu) - d_min) / np.maximum(d_max - d_min, 1e-9)
    through = _bilinear(transmittance_table(air), rho / _HORIZON, x_mu)
    return np.where(_meets_ground(r, mu)[..., None], 0.0, through)


def _fibonacci_sphere(count: int) -> np.ndarray:
    """``count`` unit directions spread evenly over the sphere."""
    i = np.arange(count) + 0.5
    y = 1.0 - 2.0 * i / count
    ring = np.sqrt(1.0 - y * y)
    angle = math.pi * (3.0 - math.sqrt(5.0)) * i
    return np.stack([ring * np.cos(angle), y, ring * np.sin(angle)], -1)


def _scattering(air: Air, height: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rayleigh's and Mie's scattering per km (..., 3) at ``height`` km."""
    rayleigh, mie, _ = _densities(air, height)
    return rayleigh[..., None] * RAYLEIGH_SCATTERING, mie[..., None] * np.full(3, MIE_SCATTERING)


def _step(scattered: np.ndarray, extinction: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A step's light and its transmittance: the integral over the step of a constant source
    ``scattered`` dimmed along it by ``extinction`` (Hillaire's section 5.3), and exp(-sigma t)."""
    through = np.exp(-extinction * length)
    return (scattered - scattered * through) / np.maximum(extinction, 1e-12), through


def multiple_scattering_table(air: Air) -> np.ndarray:
    """Hillaire's Psi_ms (rows of height 0..top, columns of the sun's cosine -1..1, 3) per
    unit of sunlight: the second order's isotropic light at a point over 1 - f_ms (given to
    the GPU's table too)."""
    return _multiple_scattering_table(air.column)


@functools.lru_cache(maxsize=8)
def _multiple_scattering_table(air: Air) -> np.ndarray:
    rows, columns = SCATTERING_SIZE
    height = np.linspace(0.0, TOP_KM - GROUND_KM, rows)[:, None, None]
    mu_sun = np.linspace(-1.0, 1.0, columns)[None, :, None]
    r = GROUND_KM + height
    sun = np.stack(np.broadcast_arrays(np.sqrt(1.0 - mu_sun * mu_sun), mu_sun, np.zeros_like(mu_sun)), -1)
    ways = _fibonacci_sphere(SCATTERING_DIRECTIONS)                     # (directions, 3)
    mu = ways[:, 1]
    ground = _meets_ground(r, mu)
    length = np.where(ground, _to_ground(r, mu), _to_top(r, mu))        # (rows, 1, directions)
    isotropic = 1.0 / (4.0 * math.pi)
    light = np.zeros((rows, columns, SCATTERING_DIRECTIONS, 3))
    transfer = np.zeros_like(light)
    through = np.ones_like(light)
    step = length / SCATTERING_STEPS
    for k in range(SCATTERING_STEPS):
        t = (k + 0.5) * step                                            # (rows, 1, directions)
        point = np.array([0.0, 1.0, 0.0]) * r[..., None] + ways * t[..., None]   # eye at (0, r, 0)
        radius = np.linalg.norm(point, axis=-1)
        sun_cos = np.einsum("rcdk,rcdk->rcd", np.broadcast_to(point, (rows, columns, SCATTERING_DIRECTIONS, 3)),
                            np.broadcast_to(sun, (rows, columns, SCATTERING_DIRECTIONS, 3))) / radius
        rayleigh, mie = _scattering(air, radius - GROUND_KM)
        scattering = rayleigh + mie
        sunlit = transmittance(air, np.broadcast_to(radius, sun_cos.shape), sun_cos)
        source, step_through = _step(scattering * sunlit * isotropic, _extinction(air, radius - GROUND_KM),
                                     step[..., None])
        light += through * source
        transfer += through * _step(scattering, _extinction(air, radius - GROUND_KM), step[..., None])[0]
        through = through * step_through
    # The ground where a way meets it: its albedo over pi times the sun's light on it.
    point = np.array([0.0, 1.0, 0.0]) * r[..., None] + ways * length[..., None]
    normal = point / np.linalg.norm(point, axis=-1, keepdims=True)
    sun_cos = np.einsum("rcdk,rcdk->rcd", np.broadcast_to(normal, (rows, columns, SCATTERING_DIRECTIONS, 3)),
                        np.broadcast_to(sun, (rows, columns, SCATTERING_DIRECTIONS, 3)))
    lit = transmittance(air, np.full(sun_cos.shape, GROUND_KM), sun_cos) * np.maximum(sun_cos, 0.0)[..., None]
    light += np.where(ground[..., None], through * lit * np.asarray(air.ground) / math.pi, 0.0)
    second = light.mean(axis=2)            # the integral over the sphere times the isotropic phase
    share = transfer.mean(axis=2)
    return second / np.maximum(1.0 - share, 1e-3)


def _multiple_scattering(air: Air, height: np.ndarray, mu_sun: np.ndarray) -> np.ndarray:
    return _bilinear(multiple_scattering_table(air), height / (TOP_KM - GROUND_KM), mu_sun * 0.5 + 0.5)


def view_directions(sun_elevation: float, size: tuple[int, int] = VIEW_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """The sky-view table's ways (rows, columns, 3) in a frame whose y is up and whose sun
    lies in the x-y plane towards +x, and that sun (3,)."""
    rows, columns = size
    elevation = 0.5 * math.pi * np.linspace(0.0, 1.0, rows) ** 2
    azimuth = math.pi * np.linspace(0.0, 1.0, columns)
    e, a = np.meshgrid(elevation, azimuth, indexing="ij")
    ways = np.stack([np.cos(e) * np.cos(a), np.sin(e), np.cos(e) * np.sin(a)], -1)
    sun = np.array([math.cos(sun_elevation), math.sin(sun_elevation), 0.0])
    return ways, sun


def coarse_view_table(air: Air, sun_elevation_degrees: float) -> np.ndarray:
    """A small sky-view table (``COARSE_SIZE``, ``COARSE_STEPS``) for what the CPU needs of the
    sky: its light (spherical harmonics) and the ground's; the sun's elevation rounded to
    ``ELEVATION_STEP_DEGREES`` (the last few kept: about 7 ms of numpy on the 2-core machine,
    once a degree of a day, as the sky's cube map is made again)."""
    rounded = round(sun_elevation_degrees / ELEVATION_STEP_DEGREES) * ELEVATION_STEP_DEGREES
    return sky_view_table(air, rounded, COARSE_SIZE, COARSE_STEPS)


@functools.lru_cache(maxsize=16)
def sky_view_table(air: Air, sun_elevation_degrees: float, size: tuple[int, int] = VIEW_SIZE,
                   steps: int = VIEW_STEPS) -> np.ndarray:
    """The radiance (rows, columns, 3) float32 the eye sees along each of the table's ways
    (``view_directions``) per unit of sunlight, with the sun ``sun_elevation_degrees`` above
    the horizon, and in a fourth channel the share of light from beyond the air that crosses
    it along the way (green's: what a Skybox's space shows through): the reference the GPU's
    table (``engine/render/sky_view.py``) is held to."""
    ways, sun = view_directions(math.radians(sun_elevation_degrees), size)
    r0 = GROUND_KM + air.eye_km
    length = _to_top(np.float64(r0), ways[..., 1])                      # (rows, columns)
    nu = ways @ sun
    rayleigh_shape, mie_shape = rayleigh_phase(nu)[..., None], mie_phase(nu)[..., None]
    light = np.zeros(ways.shape)
    through = np.ones(ways.shape)
    edges = (np.arange(steps + 1) / steps) ** 2                        # finer near the eye, where the air is thick
    for k in range(steps):
        t = length * 0.5 * (edges[k] + edges[k + 1])
        step = (length * (edges[k + 1] - edges[k]))[..., None]
        point = np.array([0.0, r0, 0.0]) + ways * t[..., None]
        radius = np.linalg.norm(point, axis=-1)
        height = radius - GROUND_KM
        sun_cos = point @ sun / radius
        rayleigh, mie = _scattering(air, height)
        sunlit = transmittance(air, radius, sun_cos)
        source = (rayleigh * rayleigh_shape + mie * mie_shape) * sunlit
        if air.multiple:
            source = source + (rayleigh + mie) * _multiple_scattering(air, height, sun_cos)
        added, step_through = _step(source, _extinction(air, height), step)
        light += through * added
        through *= step_through
    table = np.concatenate([light, through[..., 1:2]], -1).astype(np.float32)
    table.setflags(write=False)
    return table


def glsl_defines() -> dict[str, str]:
    """The air's constants for ``shaders/sky_view.frag`` (one source: this module's)."""
    def vec3(values) -> str:
        return "vec3(" + ", ".join(f"{float(v):.9g}" for v in values) + ")"

    return {"GROUND_KM": f"{GROUND_KM:.9g}", "TOP_KM": f"{TOP_KM:.9g}",
            "RAYLEIGH_SCATTERING": vec3(RAYLEIGH_SCATTERING), "RAYLEIGH_HEIGHT_KM": f"{RAYLEIGH_HEIGHT_KM:.9g}",
            "MIE_SCATTERING": f"{MIE_SCATTERING:.9g}", "MIE_EXTINCTION": f"{MIE_EXTINCTION:.9g}",
            "MIE_HEIGHT_KM": f"{MIE_HEIGHT_KM:.9g}", "MIE_G": f"{MIE_G:.9g}",
            "OZONE_ABSORPTION": vec3(OZONE_ABSORPTION), "OZONE_CENTRE_KM": f"{OZONE_CENTRE_KM:.9g}",
            "OZONE_HALF_WIDTH_KM": f"{OZONE_HALF_WIDTH_KM:.9g}", "VIEW_STEPS": str(VIEW_STEPS),
            "ROWS": str(VIEW_SIZE[0]), "COLUMNS": str(VIEW_SIZE[1])}


# --- reading it, as the sky pass does ---------------------------------------------------------
def view_coordinates(directions: np.ndarray, sun: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the sky-view table holds each unit way (..., 3) under the unit ``sun``: its row
    and column as fractions (0 the first entry, 1 the last), as sky_model.glsl reads them.
    Ways below the horizon read the horizon's row."""
    d = np.asarray(directions, np.float64)
    s = np.asarray(sun, np.float64)
    elevation = np.arcsin(np.clip(d[..., 1], 0.0, 1.0))
    flat = d[..., (0, 2)]
    sun_flat = s[(0, 2),]
    lengths = np.linalg.norm(flat, axis=-1) * np.linalg.norm(sun_flat)
    cos_azimuth = np.where(lengths > 1e-10, (flat @ sun_flat) / np.maximum(lengths, 1e-10), 1.0)
    azimuth = np.arccos(np.clip(cos_azimuth, -1.0, 1.0))
    return np.sqrt(elevation / (0.5 * math.pi)), azimuth / math.pi


def air_radiance(table: np.ndarray, directions: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """The sky-view ``table``'s radiance per unit of sunlight along unit ``directions``
    (..., 3), bilinear between its entries (half floats, as the GPU holds it)."""
    row, column = view_coordinates(directions, sun)
    return _bilinear(np.asarray(table[..., :3], np.float16).astype(np.float64), row, column)


def air_transmittance(table: np.ndarray, directions: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """The sky-view ``table``'s share of light from beyond the air along unit ``directions``
    (..., 1), read as ``air_radiance`` reads its colour."""
    row, column = view_coordinates(directions, sun)
    return _bilinear(np.asarray(table[..., 3:4], np.float16).astype(np.float64), row, column)


# How dark the air must be for what lies beyond it to show (``space_shown``): the luminance of
# its light per unit of sunlight (the sky-view table's) at which half of the space shows.
# The zenith's, a clear Earth sky: 0.0145 at noon, 0.0023 with the sun 2 degrees up, 4.3e-4
# at 2 down, 1e-4 at 4, 3.6e-5 at 5, 8e-6 at 6 (civil dusk), 1.6e-6 at 8: the brightest of
# ``star_faces`` come out about 4 degrees down, most by 8.
SPACE_DARK = 5e-6


def space_shown(air: np.ndarray) -> np.ndarray:
    """The share (..., 1) of what lies beyond the air (an atmosphere's given faces: stars, a
    galaxy) that shows through air whose light per unit of sunlight is ``air`` (..., 3):
    1 / (1 + (L / SPACE_DARK)^2) of its luminance L.  A star is lost in a bright sky although
    its light still crosses the air: the eye sees it against the sky, not its light alone,
    and given faces bright enough to show at night (``star_faces``) outshine a day sky's
    blue by tens of times.  Drawn by sky_model.glsl's SPACE build (``clear_sky``); the moon's
    light in the air is left out (a full moon's sky is far under SPACE_DARK)."""
    lum = np.asarray(air, np.float64) @ LUMINANCE
    return (1.0 / (1.0 + (lum / SPACE_DARK) ** 2))[..., None]


def horizon_sine(air: Air) -> float:
    """The sine of how far the true horizon lies below the level one, seen from the eye
    ``air.eye_km`` up: the ground's tangent from there, acos(R / (R + h)) (0.45 degrees at
    200 m, 1.8 at 3 km, 3.2 at 10 km).  The sky reaches down to it; below it, the ground."""
    ratio = GROUND_KM / (GROUND_KM + max(air.eye_km, 0.0))
    return math.sqrt(max(1.0 - ratio * ratio, 0.0))


def sun_elevation_degrees(sun: np.ndarray) -> float:
    """The unit ``sun``'s elevation over the horizon, degrees."""
    return math.degrees(math.asin(max(-1.0, min(1.0, float(sun[1])))))


def sunlight_share(air: Air, sun: np.ndarray) -> np.ndarray:
    """The share (3,) of the sun's light the air lets reach the eye from the unit ``sun``
    way (0 once it has set)."""
    return transmittance(air, np.float64(GROUND_KM + air.eye_km), np.float64(sun[1]))


def ground_light(air: Air, table: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """The ground's radiance per unit of sunlight (3,): its albedo over pi times the sun's
    light through the air on it and the sky's (the ``table``'s ways, any size, weighed by
    their cosine and solid angle)."""
    rows, columns = table.shape[:2]
    v = np.linspace(0.0, 1.0, rows)
    elevation = 0.5 * math.pi * v * v
    # Each entry's share of the hemisphere: d(elevation) x d(azimuth) x cos(elevation), both
    # sides of the sun's plane (the table holds one), trapezoids between entries.
    d_elevation = np.gradient(elevation)
    d_azimuth = np.full(columns, math.pi / (columns - 1))
    d_azimuth[[0, -1]] *= 0.5
    weight = (np.cos(elevation) * np.sin(elevation) * d_elevation)[:, None] * d_azimuth[None, :] * 2.0
    sky = (np.asarray(table[..., :3], np.float64) * weight[..., None]).sum(axis=(0, 1))
    sun_cos = max(float(sun[1]), 0.0)
    direct = sunlight_share(air, sun) * sun_cos
    return np.asarray(air.ground, np.float64) / math.pi * (direct + sky)
