"""A CloudLayer's clouds as functions (the CPU twin of ``shaders/include/clouds.glsl``, which
owns nothing: the rules are here), and the uniform block the sky and scene programs read.

The layer is a sheet ``height`` metres up on a sphere the Earth's size around the world's
origin (``layer_distance``: a way from a point meets it at a finite distance, even along the
horizon, where the clouds crowd and fade into the haze).  Its cloud at each place is fractal
value noise (``CLOUD_OCTAVES`` octaves of a lattice hash that wraps every ``NOISE_PERIOD``
cells, so the wind's drift wraps too), its first octave ``scale`` metres across, thresholded
to the ``coverage`` share (``coverage_threshold``, from the noise's own distribution) with a
soft edge.  Far off, an octave whose cells the eye sees under ``LOD_ANGLE`` fades to its mean
(the noise's own level of detail: a distant cloud's small puffs would shimmer from pixel to
pixel, and the cube map's texels would alias them), the same rule in the sky pass, the cube
map and the sky's light.

Seen along a way the cloud's optical depth tau is ``density`` x its thickness at the place
over the cosine at which the way crosses the sheet; it hides 1 - exp(-tau) of the sky behind
it (``cloud_cover``, less with the haze's distance) and shows its own light: the sun's (the
sky's disc colour, its unit of sunlight) over pi, through the upper half of the sheet (its
thickness there and at two places beside it towards the sun, the coarse octaves, the sheet's
depth apart; a two-term multiple-scattering falloff, Wrenninge's octaves as Hillaire's clouds
use them, so a thick cloud's shaded side is grey, not black), times a Henyey-Greenstein
silver lining round the sun, plus the clear sky overhead, times the albedo.

A point's cloud shadow (``cloud_shadow``) is the share of the sun the cloud on its way to the
sun lets through: exp(-optical depth), the same field at full detail.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import moderngl
import numpy as np

from components.clouds import CloudLayer
from engine.render.bindings import CLOUDS_BINDING, bind_uniform_block

EARTH_RADIUS = 6.36e6     # metres: the sphere the sheet curves with (atmosphere.py's ground)
NOISE_PERIOD = 64         # the first octave's lattice cells before the pattern repeats
CLOUD_OCTAVES = 5         # octaves of the cloud's thickness, each half the last one's size
SUN_OCTAVES = 2           # ... of which the sunlight's way through the cloud beside reads
EDGE_SOFTNESS = 0.03      # the noise's range over which a cloud's edge fades in
EDGE_ENDS_POWER = 5       # the threshold moved by the edge's width times (1 - 2 coverage)^this
LOD_ANGLE = 0.005         # radians: an octave seen under twice this fades to its mean by once it
HAZE_DISTANCE = 60000.0   # metres: a cloud's share of the sky falls by 1/e each (into the horizon's haze)
SILVER_LINING = 0.6       # Henyey-Greenstein's g of the light scattered towards the eye
MIN_CROSSING = 0.05       # the cosine a way crosses the sheet at, at least (20 x its depth at most)
_HASH = (0x8DA6B343, 0xD8163841, 0x2C1B3C6D, 0x297A2D39)   # the lattice hash's odd multipliers


@dataclass(frozen=True)
class CloudShape:
    """What the GPU needs of a CloudLayer (``cloud_shape``): the noise's threshold for its
    coverage, the optical depth, the sheet's height, the first octave's size and the sheet's
    depth in metres, the drift in first-octave cells (wrapped to the period), the albedo, the
    pattern's seed and whether it shades the world."""

    threshold: float
    coverage: float
    density: float
    height: float
    scale: float
    thickness: float
    offset: tuple[float, float]
    albedo: tuple[float, float, float]
    seed: int
    shadows: bool

    def block(self) -> bytes:
        """The ``Clouds`` uniform block (``clouds.glsl``): four vec4s."""
        return np.array([self.threshold, EDGE_SOFTNESS, self.density, float(self.seed),
                         self.height, self.scale, self.thickness, self.coverage,
                         self.offset[0], self.offset[1], 0.0, 0.0,
                         *self.albedo, 0.0], np.float32).tobytes()


def cloud_shape(layer: CloudLayer) -> CloudShape | None:
    """The CloudShape of a ``components.clouds.CloudLayer`` (None: no cloud to draw, its
    coverage or density 0)."""
    if layer.coverage <= 0.0 or layer.density <= 0.0:
        return None
    scale = float(layer.scale)
    x, z = layer.drift
    offset = (float(np.mod(-x / scale, NOISE_PERIOD)), float(np.mod(-z / scale, NOISE_PERIOD)))
    return CloudShape(coverage_threshold(float(layer.coverage)), float(layer.coverage), float(layer.density),
                      float(layer.height), scale, float(layer.thickness), offset,
                      tuple(float(c) for c in tuple(layer.color)[:3]), int(layer.seed), bool(layer.shadows))


CUBE_DRIFT_TEXELS = 2.0   # the drift a sky cube map serves: its texels straight up


def drift_served(baked: CloudShape | None, now: CloudShape | None, face_size: int) -> bool:
    """Whether the sky's cube map and light, made with the clouds ``baked``, still serve the
    clouds ``now``: the same clouds, drifted by at most ``CUBE_DRIFT_TEXELS`` of the cube's
    texels seen straight up (a face's 90 degrees over ``face_size``, at the sheet's height).
    The sky pass draws them where they are every frame; what reflects them, a little late."""
    if baked is None or now is None:
        return baked is now
    return _drifted_within(baked, now, CUBE_DRIFT_TEXELS * (np.pi / 2.0) / face_size * now.height / now.scale)


def _drifted_within(before: CloudShape, now: CloudShape, cells: float) -> bool:
    """Whether ``now`` is the clouds ``before``, drifted by at most ``cells`` first-octave
    cells (the shortest way round the pattern's period)."""
    if before == now:
        return True
    if dataclasses.replace(before, offset=now.offset) != now:
        return False
    apart = (np.array(now.offset) - np.array(before.offset) + NOISE_PERIOD / 2.0) % NOISE_PERIOD - NOISE_PERIOD / 2.0
    return bool(np.hypot(*apart) <= cells)


SHADOW_DRIFT_SHARE = 8   # a capture serves clouds drifted by 1/this of the finest octave's cell


def shadows_served(captured: CloudShape | None, now: CloudShape | None) -> bool:
    """Whether what a reflection probe captured under the clouds ``captured`` (their shadows
    on its surroundings, and its sky) still serves the clouds ``now``: the same clouds,
    drifted by at most 1/``SHADOW_DRIFT_SHARE`` of the finest octave's cell (the sheet's
    ``scale`` over 2^(octaves - 1)): the shadows' finest edges a few metres off at most."""
    if captured is None or now is None:
        return captured is now
    return _drifted_within(captured, now, 1.0 / (SHADOW_DRIFT_SHARE * 2.0 ** (CLOUD_OCTAVES - 1)))


def layer_distance(points: np.ndarray, ways: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray]:
    """How far along unit ``ways`` (..., 3) from ``points`` (..., 3; below the sheet) the
    sheet ``height`` metres up is met, and the cosine between the way and the sheet's normal
    there.  With q the point from the Earth's centre, b = q.way and c = (R + h)^2 - |q|^2 (> 0
    inside), the distance is sqrt(b^2 + c) - b, taken as c / (b + sqrt(b^2 + c)) where b > 0:
    the difference of two numbers near 6 million is no float's to take."""
    p = np.asarray(points, np.float64)
    w = np.asarray(ways, np.float64)
    b = (p * w).sum(-1) + EARTH_RADIUS * w[..., 1]
    c = (height - p[..., 1]) * (2.0 * EARTH_RADIUS + height + p[..., 1]) - p[..., 0] ** 2 - p[..., 2] ** 2
    root = np.sqrt(b * b + np.maximum(c, 0.0))
    t = np.where(b > 0.0, np.maximum(c, 0.0) / np.maximum(b + root, 1e-30), root - b)
    return t, (b + t) / (EARTH_RADIUS + height)


def lattice_value(ix: np.ndarray, iy: np.ndarray, salt: np.ndarray) -> np.ndarray:
    """The value in [0, 1) at integer lattice points (uint32 arithmetic, as the GLSL's)."""
    with np.errstate(over="ignore"):
        h = (ix.astype(np.uint32) * np.uint32(_HASH[0])) ^ (iy.astype(np.uint32) * np.uint32(_HASH[1])) \
            ^ np.asarray(salt, np.uint32)
        h = (h ^ (h >> np.uint32(15))) * np.uint32(_HASH[2])
        h = (h ^ (h >> np.uint32(12))) * np.uint32(_HASH[3])
        h = h ^ (h >> np.uint32(15))
    return (h >> np.uint32(8)).astype(np.float64) / 16777216.0


def value_noise(u: np.ndarray, period: int, salt: int) -> np.ndarray:
    """Value noise at ``u`` (..., 2), the lattice wrapping every ``period`` cells (a power of
    two): the four corners' values blended by the quintic fade."""
    u = np.asarray(u, np.float64)
    cell = np.floor(u)
    f = u - cell
    i = cell.astype(np.int64)
    mask = period - 1
    x0, y0 = i[..., 0] & mask, i[..., 1] & mask
    x1, y1 = (x0 + 1) & mask, (y0 + 1) & mask
    s = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    salts = np.uint32(salt)
    a, b = lattice_value(x0, y0, salts), lattice_value(x1, y0, salts)
    c, d = lattice_value(x0, y1, salts), lattice_value(x1, y1, salts)
    low = a + (b - a) * s[..., 0]
    high = c + (d - c) * s[..., 0]
    return low + (high - low) * s[..., 1]


_AMPLITUDE_SUM = sum(0.5 ** k for k in range(CLOUD_OCTAVES))


def cloud_noise(u: np.ndarray, seed: int, detail: np.ndarray | float = np.inf,
                octaves: int = CLOUD_OCTAVES) -> np.ndarray:
    """The fractal noise (mean 1/2) at first-octave cells ``u`` (..., 2): ``octaves`` of
    value noise, octave k at 2^k times the frequency and 2^-k the weight, each faded to its
    mean as ``detail`` (the first octave's cell over the distance it is seen from, times the
    square root of the crossing's cosine: the angle it spans, foreshortened one way only)
    falls below twice ``LOD_ANGLE`` x 2^k."""
    u = np.asarray(u, np.float64)
    detail = np.asarray(detail, np.float64)
    total = np.zeros(u.shape[:-1])
    for k in range(octaves):
        frequency = float(1 << k)
        weight = np.clip(detail / (frequency * LOD_ANGLE) - 1.0, 0.0, 1.0)
        total = total + (0.5 ** k) * weight * (value_noise(u * frequency, NOISE_PERIOD << k, seed * 16 + k) - 0.5)
    return 0.5 + total / _AMPLITUDE_SUM


def cloud_thickness(shape: CloudShape, noise: np.ndarray, detail: np.ndarray | float = np.inf) -> np.ndarray:
    """The cloud's thickness (0 to 1) where the fractal noise is ``noise``: a smoothstep over
    ``EDGE_SOFTNESS`` either side of the coverage's threshold; where even the first octave
    fades (``detail``: ``cloud_noise``'s) it fades to the sheet's mean, its coverage (a far
    field of clouds is a band as cloudy as the sheet, not the noise's middle)."""
    x = np.clip((noise - shape.threshold + EDGE_SOFTNESS) / (2.0 * EDGE_SOFTNESS), 0.0, 1.0)
    resolved = np.clip(np.asarray(detail, np.float64) / LOD_ANGLE - 1.0, 0.0, 1.0)
    return shape.coverage + (x * x * (3.0 - 2.0 * x) - shape.coverage) * resolved


@functools.lru_cache(maxsize=1)
def _noise_quantiles() -> np.ndarray:
    """The fractal noise's quantiles at full detail (65 of them, 0 to 1), from 2^18 places of
    one period of seed 0's pattern (every seed's noise has the same distribution)."""
    rng = np.random.default_rng(12345)
    noise = cloud_noise(rng.random((1 << 18, 2)) * NOISE_PERIOD, 0)
    return np.quantile(noise, np.linspace(0.0, 1.0, 65))


def coverage_threshold(coverage: float) -> float:
    """The noise's threshold at which ``coverage`` of the sheet lies under cloud: its
    (1 - coverage) quantile, moved by up to the soft edge's width near the ends so that 0 is
    clear sky and 1 overcast (the whole sheet past the edge)."""
    q = _noise_quantiles()
    ends = (1.0 - 2.0 * coverage) ** EDGE_ENDS_POWER   # (the edge's width moved in only near 0 and 1)
    return float(np.interp(1.0 - coverage, np.linspace(0.0, 1.0, q.size), q) + EDGE_SOFTNESS * ends)


def layer_cells(shape: CloudShape, xz: np.ndarray) -> np.ndarray:
    """The sheet's places ``xz`` (..., 2, metres) in first-octave cells of the drifted pattern."""
    return np.asarray(xz, np.float64) / shape.scale + np.array(shape.offset)


def cloud_cover(shape: CloudShape, ways: np.ndarray, sun: np.ndarray, sunlight: np.ndarray,
                overhead: np.ndarray, moon: np.ndarray | None = None,
                moonlight: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """What the clouds do to the sky along unit ``ways`` (..., 3) from the world's origin: the
    share of the sky behind them they hide (...) and their own light (..., 3), lit by the sun
    (``sun`` the unit way towards it, ``sunlight`` its disc's colour), by a moon as the sun
    (``moon``, ``moonlight``: its disc's colour times its phase's share) and the clear sky
    ``overhead`` (its radiance straight up)."""
    d = np.asarray(ways, np.float64)
    t, crossing = layer_distance(np.zeros(3), d, shape.height)
    cosine = np.maximum(crossing, MIN_CROSSING)
    cells = layer_cells(shape, d[..., [0, 2]] * t[..., None])
    detail = shape.scale * np.sqrt(cosine) / np.maximum(t, 1e-6)
    thick = cloud_thickness(shape, cloud_noise(cells, shape.seed, detail), detail)
    hidden = (1.0 - np.exp(-shape.density * thick / cosine)) * np.exp(-t / HAZE_DISTANCE) * (d[..., 1] >= 0.0)
    light = np.asarray(sunlight, np.float64) / np.pi * _lit(shape, cells, detail, thick, d, sun)[..., None] \
        + np.asarray(overhead, np.float64) * (1.0 - 0.5 * thick)[..., None]
    if moonlight is not None and np.any(moonlight):
        lit = _lit(shape, cells, detail, thick, d, moon)
        light = light + np.asarray(moonlight, np.float64) / np.pi * lit[..., None]
    return hidden, np.array(shape.albedo) * light


def _lit(shape: CloudShape, cells: np.ndarray, detail: np.ndarray, thick: np.ndarray, d: np.ndarray,
         towards: np.ndarray) -> np.ndarray:
    """The share of a light from ``towards`` (unit) a cloud seen along ``d`` sends the eye:
    what reaches it through the cloud beside it towards the light (the sheet's depth along
    the light, two reads of its first ``SUN_OCTAVES``), by the silver lining's phase, and 0
    once the light is well below the clouds' horizon."""
    towards = np.asarray(towards, np.float64)
    rise = max(float(towards[1]), 0.1)
    step = towards[[0, 2]] * (shape.thickness / rise / shape.scale)   # the sheet's depth along the light, flat
    beside = sum(cloud_thickness(shape, cloud_noise(cells + step * f, shape.seed, detail, SUN_OCTAVES), detail)
                 for f in (0.5, 1.0)) / 2.0
    depth = shape.density * (thick + beside) / (2.0 * rise)
    through = 0.4 * np.exp(-depth) + 0.6 * np.exp(-depth / 16.0)
    g = SILVER_LINING
    mu = np.clip(d @ towards, -1.0, 1.0)
    phase = 0.6 + 0.4 * (1.0 - g * g) / (1.0 + g * g - 2.0 * g * mu) ** 1.5
    up = np.clip((towards[1] + 0.05) / 0.1, 0.0, 1.0)   # (lit a little after sunset at their height)
    return through * phase * up


def cloud_shadow(shape: CloudShape, points: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """The share of the sun's light (``sun``: unit, towards it) the clouds let reach world
    ``points`` (..., 3): exp(-optical depth) of the cloud on the way, at full detail."""
    p = np.asarray(points, np.float64)
    sun = np.asarray(sun, np.float64)
    t, crossing = layer_distance(p, np.broadcast_to(sun, p.shape), shape.height)
    xz = p[..., [0, 2]] + t[..., None] * sun[[0, 2]]
    thick = cloud_thickness(shape, cloud_noise(layer_cells(shape, xz), shape.seed))
    return np.exp(-shape.density * thick / np.maximum(crossing, MIN_CROSSING))


MAX_CLOUD_STRIDE = 8      # a march reads the clouds' share at least every this many steps
STRIDE_SHARE = 8.0        # ... and a stride spans at most 1/this of the finest octave's cell


def cloud_stride(shape: CloudShape, step_length: float, towards: np.ndarray) -> int:
    """How many of a light shafts' march's steps (``step_length`` metres each, the longest a
    ray takes) lie between two reads of the clouds' share of the sun's light (``towards``: unit,
    towards it), the share taken linearly between: a stride moves the point the way to the sun
    meets the sheet by at most its length times 1 + |horizontal| / vertical of ``towards``, and
    that must stay within 1/``STRIDE_SHARE`` of the finest octave's cell (the sheet's ``scale``
    over 2^(octaves - 1)); 1 to ``MAX_CLOUD_STRIDE``."""
    finest = shape.scale / 2.0 ** (CLOUD_OCTAVES - 1)
    spread = 1.0 + math.hypot(float(towards[0]), float(towards[2])) / max(float(towards[1]), MIN_CROSSING)
    return int(min(max(finest / (STRIDE_SHARE * max(step_length, 1e-6) * spread), 1.0), MAX_CLOUD_STRIDE))


class CloudBlock:
    """The ``Clouds`` uniform block on the GPU (bound at ``CLOUDS_BINDING`` by each pass that
    reads it: ``bind``), written when the shape changes, and the defines of the builds that
    read it: ``CLOUDS`` (the sky's) and ``CLOUD_SHADOWS`` (the scene's, while it shades)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.shape: CloudShape | None = None
        self.ubo = ctx.buffer(reserve=64)
        bind_uniform_block(ctx, self.ubo, CLOUDS_BINDING)   # (through the record: each pass binds it again)
        self.shadow_defines: tuple[tuple[str, str], ...] = ()

    def set(self, shape: CloudShape | None) -> bool:
        """Write ``shape`` (None: no clouds); True when it changed."""
        if shape == self.shape:
            return False
        self.shape = shape
        if shape is not None:
            self.ubo.write(shape.block())
        self.shadow_defines = (("CLOUD_SHADOWS", "1"),) if shape is not None and shape.shadows else ()
        return True

    def bind(self) -> None:
        bind_uniform_block(self.ctx, self.ubo, CLOUDS_BINDING)

    def release(self) -> None:
        self.ubo.release()
