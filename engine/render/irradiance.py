"""Diffuse image lighting: the irradiance of the sky, of the hemisphere fallback, of each
probe's capture and of each irradiance volume's points as nine spherical-harmonic
coefficients (order 2), and the GPU table the probes' and volumes' coefficients live in.

The representation is Ramamoorthi and Hanrahan's ("An Efficient Representation for
Irradiance Environment Maps", SIGGRAPH 2001): the radiance L(w) arriving from every
direction is projected on the nine real orthonormal spherical harmonics Y_lm of bands 0-2,
L_lm = integral of L(w) Y_lm(w) dw, and the irradiance of a surface of normal n,
E(n) = integral of L(w) max(0, n.w) dw, is then E(n) = sum of A_l L_lm Y_lm(n) with
A_0 = pi, A_1 = 2 pi / 3, A_2 = pi / 4 (the clamped cosine's own bands; the error against
the exact integral is a few percent at most for smooth skies).

**The convention, everywhere in the engine:** the nine coefficients stored (the Lights
block's ``sky_sh``, a row of the irradiance table) are the *irradiance* coefficients
E_lm = A_l L_lm, in the order (l, m) = (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0),
(2,1), (2,2), each an RGB triple; ``shaders/include/ambient.glsl`` evaluates
E(n) = sum E_lm Y_lm(n) with the Y_lm constants below, and a Lambertian surface of albedo a
reflects a E(n) / pi.  A constant sky of radiance L gives E = pi L for every normal, so a
white surface shows L.

Where they come from:
  - a generated sky: in closed form (``generated_sky_sh``: each part of the sky a zonal
    function, projected by the Funk-Hecke theorem), when the Skybox or its sun changes
    (``systems/prepare_system.py``); a Skybox of given faces: ``project_faces`` of them, each
    texel weighted by its solid angle;
  - no Skybox: a ``HemisphereLight`` (``components/ambient.py``; a dim default when there is
    none either), whose upper half of the sphere has radiance ``sky`` and lower half
    ``ground``: ``hemisphere_sh`` in closed form.  Projected to order 2 it is exactly
    E(n) / pi = mix(ground, sky, (1 + n.y) / 2), three.js's HemisphereLight;
  - a probe with an influence box: ``IrradianceTable.project`` after each capture's mip chain,
    on the GPU (``shaders/irradiance_sh.frag`` reads a 16-texel level of the cube and writes
    the probe's row of the table): nothing is read back and nothing waits.

The scene shader blends them per pixel by the engine's probe-blending rule
(``engine.rules.probe_rules.probe_blend``: the two influence boxes weighing most at the
shaded point, each by its linear falloff, normalised only when they sum past 1, the sky
taking the rest), reading the boxes from the Irradiance uniform block
(``irradiance_block``) and their coefficients from the table.  For an object inside its
boxes' full-weight interiors this is exactly its reflection's blend; in a falloff band the
reflection weighs the boxes at the object's origin and the diffuse light at each pixel.

Why per pixel, not per instance (weights and table rows in each instance's row, as
``probe_blend`` gives reflective batches).  Per instance needs two table rows and two
weights in every instance row, whose vertex attributes are all in use (GL 4.1's sixteen),
and ``probe_blend`` worked out on the CPU for every object that moves; per pixel needs
nothing in the rows, lights every object without the extract stage knowing, and lights a
floor or wall spanning two rooms by each room where it lies.  What it costs: llvmpipe runs
a loop's body at least once and both sides of every branch, so the loop over the boxes and
the table's reads are a build of the scene program of their own (``AMBIENT_PROBES``),
drawn only while some box has a capture (``IrradianceTable.bind``).  Measured on llvmpipe
(CPU ms a frame, ``time.process_time``, 640x360, 91 diffuse boxes on a floor under a sky
and a sun, medians of 15 rounds of 3 frames, the machine shared): the old constant ambient
15.6-16.1; the sky's harmonics alone (no box) 16.6-17.3; two boxes holding every pixel
27-28; eight boxes holding none 25.5-26.7; per instance, emulated by the same 18 table reads
with weights from flat inputs and no box loop, about 5.5 ms over the constant ambient
against about 12 per pixel.  The per-pixel price, in worlds with probe boxes only, is
taken for the reasons above; a GPU pays next to nothing for either.
Feedback.  A probe's capture is lit by the sky's irradiance alone: the scene pass binds an
empty Irradiance block while a probe is drawn (``IrradianceTable.bind``), so no probe's
picture depends on any probe's irradiance, and a still scene's probes settle in one capture
(with probe irradiance in captures, each capture would change the next: one more bounce per
capture, never still, and two probes that see each other would recapture each other).
"""
from __future__ import annotations

import functools
import logging
import math
from collections.abc import Iterable
from dataclasses import dataclass

import moderngl
import numpy as np

from components.limits import MAX_IRRADIANCE_VOLUMES, MAX_VOLUME_AXIS_POINTS
from engine.core.cube_faces import face_directions
from engine.render.atmosphere import air_radiance, air_transmittance, space_shown
from engine.render.bindings import (
    CUBE_MIP_UNIT,
    IRRADIANCE_BINDING,
    IRRADIANCE_UNIT,
    PassState,
    apply_pass_state,
    bind_texture,
    bind_uniform_block,
)
from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE, environment_brdf_table, sheen_albedo_table
from engine.render.gpu import Gpu, ProbeCube
from engine.render.ltc_fit import LTC_SIZE, load_table
from engine.render.sky import (
    DISC_EDGE,
    GLOW_COLOR,
    MOON_RADIUS_SINE,
    MOON_RIM,
    SkyModel,
    clear_radiance,
    cloud_hidden,
    disc_strength,
    glow_strength,
    ground_share,
    model_radiance,
    moon_cover,
    moon_phase,
    zenith_share,
)
from engine.render.subsurface import SUBSURFACE_BANDS_COLUMN, band_rows, subsurface_table
from engine.render.targets import release_framebuffer
from engine.render.views import LTC_ROW, MAX_IRRADIANCE_PROBES, VOLUME_ROW, VOLUME_ROWS, VOLUME_SLOT_ROWS

LOG = logging.getLogger("speculum")

SH_COEFFICIENTS = 9
# Y_lm(x, y, z) = SH_CONSTANTS[i] x the i-th polynomial of ``sh_basis`` (real, orthonormal).
_Y0, _Y1 = 0.5 * math.sqrt(1.0 / math.pi), math.sqrt(3.0 / (4.0 * math.pi))
_Y2, _Y20, _Y22 = 0.5 * math.sqrt(15.0 / math.pi), 0.25 * math.sqrt(5.0 / math.pi), 0.25 * math.sqrt(15.0 / math.pi)
SH_CONSTANTS = (_Y0, _Y1, _Y1, _Y1, _Y2, _Y2, _Y20, _Y2, _Y22)
# The clamped cosine's band factors A_l, per coefficient (Ramamoorthi and Hanrahan, eq. 8).
BAND_FACTORS = (math.pi,) + (2.0 * math.pi / 3.0,) * 3 + (math.pi / 4.0,) * 5
PROJECTION_FACE_SIZE = 16    # texels across a face at the cube level the GPU projection reads
IRRADIANCE_BLOCK_BYTES = 16 + 2 * 16 * MAX_IRRADIANCE_PROBES + 3 * 16 * MAX_IRRADIANCE_VOLUMES


def sh_basis(directions: np.ndarray) -> np.ndarray:
    """The nine Y_lm at unit ``directions`` (..., 3): (..., 9), float64."""
    d = np.asarray(directions, np.float64)
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    c = SH_CONSTANTS
    return np.stack([np.full_like(x, c[0]), c[1] * y, c[2] * z, c[3] * x, c[4] * x * y, c[5] * y * z,
                     c[6] * (3.0 * z * z - 1.0), c[7] * x * z, c[8] * (x * x - y * y)], axis=-1)


def texel_solid_angles(size: int) -> np.ndarray:
    """The solid angle of each texel of a cube face of ``size`` texels (size, size): exact,
    from the area of a face's corner region, A(s, t) = atan2(s t, sqrt(s^2 + t^2 + 1)); the
    six faces' texels add up to 4 pi.  The same for every face (and rows or columns)."""
    edges = np.linspace(-1.0, 1.0, size + 1)
    s0, t0 = np.meshgrid(edges[:-1], edges[:-1], indexing="ij")
    s1, t1 = np.meshgrid(edges[1:], edges[1:], indexing="ij")

    def corner(s, t):
        return np.arctan2(s * t, np.sqrt(s * s + t * t + 1.0))

    return corner(s1, t1) - corner(s0, t1) - corner(s1, t0) + corner(s0, t0)


def project_faces(faces: np.ndarray) -> np.ndarray:
    """Irradiance coefficients E_lm (9, 3) of a cube map's six faces (6, n, n, 3) of linear
    radiance, in GL's face order with rows along t (``face_directions``)."""
    faces = np.asarray(faces)[..., :3]
    # Big faces are box-filtered to at most 128 texels first (2 x 2 means, as mips are): nine
    # low-frequency coefficients do not need 25 million texels, and a 2048 sky then takes
    # well under a second.
    while faces.shape[1] > 128 and faces.shape[1] % 2 == 0:
        half = faces.shape[1] // 2
        faces = faces.astype(np.float32).reshape(6, half, 2, half, 2, 3).mean(axis=(2, 4))
    n = faces.shape[1]
    coefficients = np.zeros((SH_COEFFICIENTS, 3))
    rows = max(1, (1 << 20) // (n * SH_COEFFICIENTS))  # a few MB at a time, for 2048-texel faces too
    for face in range(6):
        for start in range(0, n, rows):
            part = slice(start, start + rows)
            basis = _basis(face, n, start, rows)  # (rows, n, 9): each Y_lm times the texel's solid angle
            radiance = faces[face, part, :, :3].reshape(-1, 3).astype(np.float64)
            coefficients += basis.reshape(-1, SH_COEFFICIENTS).T @ radiance
    return coefficients * np.array(BAND_FACTORS)[:, None]


def _basis(face: int, n: int, start: int, rows: int) -> np.ndarray:
    part = slice(start, start + rows)
    return sh_basis(face_directions(face, n)[part]) * texel_solid_angles(n)[part, :, None]


def generated_sky_sh(model: SkyModel) -> np.ndarray:
    """Irradiance coefficients E_lm (9, 3) of the generated sky ``model``, in closed form (no
    cube map, no texel): each part of the sky is a function f of the cosine t of the angle
    from one axis a (the gradient from +y, the glow and the disc from the sun), and such a
    zonal function projects on the harmonics as L_lm = 2 pi F_l Y_lm(a), F_l = integral of
    f(t) P_l(t) dt over [-1, 1] (the Funk-Hecke theorem; P_l the Legendre polynomials).  The
    F_l of each shape are numbers (``_zonal_integrals``), so a sky's light is a few products
    of them with its colours.  Against ``project_faces`` of its 128-texel faces it differs by
    under 1e-4 of the largest coefficient (the faces sample the 2.6-degree disc coarsely).
    An atmosphere's air has no closed form: its sky is projected from ``ATMOSPHERE_FACE``
    texels a face of the CPU's small table (smooth: the nine coefficients need no more), its
    disc in closed form.  A moon's disc is a full moon's (``moon_cover``) times its colour
    and the share of a full moon's light its phase leaves, about the way its lit part's light
    comes from (``moon_phase``)."""
    rise, fall, glow, disc, moon_disc = _zonal_integrals()
    sun_seen, moon_seen, clouds = _cloud_sh(model)
    moon = _moon_sh(model, moon_disc) * moon_seen
    bands = [0, 1, 1, 1, 2, 2, 2, 2, 2]
    sun_disc = np.outer(disc, np.array(model.sun_color, np.float64) * sun_seen)
    if model.atmosphere:
        n = ATMOSPHERE_FACE
        faces = np.stack([model_radiance(model, face_directions(face, n), disc=False, coarse=True)
                          for face in range(6)])
        if model.space is not None:   # what lies beyond the air, through it (above the horizon)
            faces = faces + _space_through_air(model)
        return project_faces(faces) + 2.0 * np.pi * sun_disc[bands] \
            * sh_basis(np.array(model.sun_direction, np.float64))[:, None] * np.array(BAND_FACTORS)[:, None] \
            + moon + clouds
    zenith, horizon, ground = (np.array(colour, np.float64) for colour in (model.zenith, model.horizon, model.ground))
    whole = np.array([2.0, 0.0, 0.0])  # a constant's F_l
    up = np.outer(whole, horizon) + np.outer(rise, zenith - horizon) + np.outer(fall, ground - horizon)
    sun = np.outer(glow, GLOW_COLOR) + sun_disc
    radiance = 2.0 * np.pi * (up[bands] * sh_basis(np.array([0.0, 1.0, 0.0]))[:, None]
                              + sun[bands] * sh_basis(np.array(model.sun_direction, np.float64))[:, None])
    return radiance * np.array(BAND_FACTORS)[:, None] + moon + clouds


def _cloud_sh(model: SkyModel) -> tuple[float, float, np.ndarray]:
    """What ``model``'s clouds do to its light: the share of the sun's disc and of the
    moon's they leave (as at each disc's centre) and the irradiance coefficients (9, 3) they
    add to the clear sky (their light less the sky they hide: projected from
    ``ATMOSPHERE_FACE`` texels a face, smooth enough for nine coefficients; an atmosphere's
    space behind them taken away too).  No clouds: 1, 1 and zeros."""
    if model.clouds is None:
        return 1.0, 1.0, np.zeros((9, 3))
    n = ATMOSPHERE_FACE
    ways = np.stack([face_directions(face, n) for face in range(6)])
    clear = clear_radiance(model, ways, coarse=True)
    hidden, light = cloud_hidden(model, ways, coarse=True)
    change = (light - clear) * hidden[..., None]
    if model.space is not None:
        change = change - _space_through_air(model) * hidden[..., None]
    at = np.array([model.sun_direction, model.moon_direction], np.float64)
    seen = 1.0 - cloud_hidden(model, at, coarse=True)[0]
    return float(seen[0]), float(seen[1]), project_faces(change)


def _moon_sh(model: SkyModel, disc: np.ndarray) -> np.ndarray:
    """The irradiance coefficients (9, 3) of ``model``'s moon disc (0 without one), ``disc``
    a full moon's F_l."""
    colour = np.array(model.moon_color, np.float64)
    if not colour.any():
        return np.zeros((9, 3))
    share, centre = moon_phase(np.array(model.moon_direction, np.float64), np.array(model.sun_direction, np.float64))
    bands = [0, 1, 1, 1, 2, 2, 2, 2, 2]
    light = np.outer(disc, colour * share)[bands]
    return 2.0 * np.pi * light * sh_basis(centre)[:, None] * np.array(BAND_FACTORS)[:, None]


def _space_through_air(model: SkyModel) -> np.ndarray:
    """An atmosphere's space (its given faces, box-filtered to ``ATMOSPHERE_FACE`` texels a
    face, or sampled at the nearest of theirs when smaller) times the share of it the air lets
    through and the share that shows where the air is bright (``space_shown``; the CPU's
    table), above the horizon: (6, n, n, 3)."""
    n = ATMOSPHERE_FACE
    space = np.asarray(model.space, np.float64)
    while space.shape[1] > n and space.shape[1] % 2 == 0:
        half = space.shape[1] // 2
        space = space.reshape(6, half, 2, half, 2, 3).mean(axis=(2, 4))
    if space.shape[1] != n:   # (a size that does not halve to it: its nearest texel)
        pick = np.minimum((np.arange(n) + 0.5) * space.shape[1] // n, space.shape[1] - 1).astype(int)
        space = space[:, pick][:, :, pick]
    sun = np.array(model.sun_direction, np.float64)
    out = np.empty((6, n, n, 3))
    for face in range(6):
        ways = face_directions(face, n)
        out[face] = space[face] * air_transmittance(model.coarse_table, ways, sun) \
            * space_shown(air_radiance(model.coarse_table, ways, sun)) * (ways[..., 1:2] >= 0.0)
    return out


ATMOSPHERE_FACE = 32   # texels a face an atmosphere's sky is projected from (16: 2% off a low sun's)
ZONAL_SAMPLES = 1 << 16  # midpoints an interval of each shape's integrals


@functools.lru_cache(maxsize=1)
def _zonal_integrals() -> tuple[np.ndarray, ...]:
    """F_0..F_2 of the sky's shapes: the rise over [0, 1], the fall over [-1, 0], the glow
    over [0, 1], the sun's disc over [DISC_EDGE, 1] and a full moon's over its rim's outer
    cosine to 1 (each by the midpoint rule)."""

    def integral(shape, low: float, high: float) -> np.ndarray:
        t = low + (np.arange(ZONAL_SAMPLES) + 0.5) * ((high - low) / ZONAL_SAMPLES)
        legendre = np.stack([np.ones_like(t), t, 0.5 * (3.0 * t * t - 1.0)])
        return legendre @ shape(t) * ((high - low) / ZONAL_SAMPLES)

    def full_moon(t: np.ndarray) -> np.ndarray:
        return moon_cover(np.sqrt(1.0 - t * t) / MOON_RADIUS_SINE)

    moon_edge = float(np.sqrt(1.0 - (MOON_RADIUS_SINE * (1.0 + 0.5 * MOON_RIM)) ** 2))
    return (integral(zenith_share, 0.0, 1.0), integral(ground_share, -1.0, 0.0), integral(glow_strength, 0.0, 1.0),
            integral(disc_strength, DISC_EDGE, 1.0), integral(full_moon, moon_edge, 1.0))


def hemisphere_sh(sky: Iterable[float], ground: Iterable[float]) -> np.ndarray:
    """Irradiance coefficients (9, 3) of radiance ``sky`` from every direction above the
    horizon (y > 0) and ``ground`` below, in closed form: with a = (sky + ground) / 2 and
    b = (sky - ground) / 2, L = a + b sign(y) has L_00 = 2 sqrt(pi) a and L_1,-1 =
    2 pi sqrt(3 / (4 pi)) b and nothing else (sign(y) is odd, the band-2 terms even in y), so
    E(n) = pi a + pi b n.y."""
    sky = np.asarray(tuple(sky)[:3], np.float64)
    ground = np.asarray(tuple(ground)[:3], np.float64)
    coefficients = np.zeros((SH_COEFFICIENTS, 3))
    coefficients[0] = math.pi * (sky + ground) / 2.0 / SH_CONSTANTS[0]
    coefficients[1] = math.pi * (sky - ground) / 2.0 / SH_CONSTANTS[1]
    return coefficients


def evaluate_sh(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Irradiance E(n) (..., 3) at unit ``normals`` (..., 3) from coefficients (9, 3)."""
    return sh_basis(normals) @ np.asarray(coefficients, np.float64)


@dataclass(frozen=True)
class VolumeGrid:
    """Where an irradiance volume's grid lies (``components.probe.IrradianceVolume``): its
    box's lowest and highest corners (the corner points), points along x, y and z, the blend
    distance inside its walls, the normal bias and its slot of the table's rows."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]
    points: tuple[int, int, int]
    blend: float = 0.0
    normal_bias: float = 0.0
    slot: int = 0

    @property
    def first_row(self) -> int:
        """Its slot's first row of the table."""
        return VOLUME_ROW + self.slot * VOLUME_SLOT_ROWS

    def position(self, index: tuple[int, int, int]) -> tuple[float, float, float]:
        """Where point ``index`` (i, j, k) of the grid is."""
        return tuple(lo + (hi - lo) * i / (n - 1)
                     for lo, hi, i, n in zip(self.low, self.high, index, self.points, strict=True))

    def texel(self, index: tuple[int, int, int], coefficient: int) -> tuple[int, int]:
        """The table's texel (x, y) holding ``coefficient`` of point ``index``: tile (c, j)
        at columns c x points-along-x, rows j x points-along-z of its slot."""
        i, j, k = index
        nx, _, nz = self.points
        return coefficient * nx + i, self.first_row + j * nz + k


def irradiance_block(boxes: Iterable[tuple[Iterable[float], Iterable[float], float, int]],
                     volumes: Iterable[VolumeGrid] = ()) -> bytes:
    """The std140 Irradiance block (``shaders/include/ambient.glsl``): the counts (boxes,
    volumes), then per box its centre with its blend distance, and its half size with its
    table row; then per volume its lowest corner with its blend distance, its highest with
    its normal bias, and its points along x, y, z with its slot's first row."""
    boxes = list(boxes)[:MAX_IRRADIANCE_PROBES]
    volumes = list(volumes)[:MAX_IRRADIANCE_VOLUMES]
    data = np.zeros(IRRADIANCE_BLOCK_BYTES // 4, np.float32)
    data[0:4] = np.array([len(boxes), len(volumes), 0, 0], np.int32).view(np.float32)
    base = 4
    for i, (centre, half, blend, row) in enumerate(boxes):
        data[base + 4 * i: base + 4 * i + 4] = (*tuple(centre)[:3], blend)
        data[base + 4 * (MAX_IRRADIANCE_PROBES + i): base + 4 * (MAX_IRRADIANCE_PROBES + i) + 4] = \
            (*tuple(half)[:3], float(row))
    base += 8 * MAX_IRRADIANCE_PROBES
    for i, volume in enumerate(volumes):
        data[base + 4 * i:base + 4 * i + 4] = (*volume.low, volume.blend)
        data[base + 4 * (MAX_IRRADIANCE_VOLUMES + i):base + 4 * (MAX_IRRADIANCE_VOLUMES + i) + 4] = \
            (*volume.high, volume.normal_bias)
        data[base + 4 * (2 * MAX_IRRADIANCE_VOLUMES + i):base + 4 * (2 * MAX_IRRADIANCE_VOLUMES + i) + 4] = \
            np.array([*volume.points, volume.first_row], np.int32).view(np.float32)
    return data.tobytes()


class IrradianceTable:
    """The probes' irradiance on the GPU: a texture of ``MAX_IRRADIANCE_PROBES`` rows of nine
    RGBA32F texels (row r, texel i: coefficient E_i of the probe given row r; below them the
    environment BRDF's rows, ``engine/render/environment_brdf.py``, the LTC table's of
    rectangle lights and the irradiance volumes' slots of tiles, ``VolumeGrid.texel``), written
    by ``project`` after each capture (``project_volume_point`` after a volume point's), and
    the Irradiance uniform block of the influence boxes whose rows hold a capture
    (``set_boxes``) and of the volumes baked whole (``set_volume``).  The scene pass binds
    both at the start of each of its passes (``bind``): units 3-5 serve other images in the
    passes between."""

    STATE = PassState()  # no depth test, no blending, no clip distances

    def __init__(self, renderer: Gpu) -> None:
        self.renderer = renderer
        self.ctx = ctx = renderer.ctx
        # The probes' rows, then the split-sum's environment BRDF table (environment_brdf.py:
        # no sampler of its own for the scene shader), read by bilinear filtering (the rows
        # by texelFetch, which filters nothing).
        # Below them the LTC table of rectangle lights (write_ltc), once the first is kept.
        # Made all zeros: the BRDF rows' last texels are filtered with their neighbours to the
        # right and below (weight 0, but a GPU's undefined texel may be a NaN, and NaN x 0 is
        # NaN), which the table's widening for the LTC rows put inside it.
        # Below those the irradiance volume's tiles (VolumeGrid.texel), read by bilinear
        # filtering within each tile.
        width = max(SH_COEFFICIENTS * MAX_VOLUME_AXIS_POINTS, ENVIRONMENT_BRDF_SIZE, LTC_SIZE)
        height = VOLUME_ROW + VOLUME_ROWS
        self.table = ctx.texture((width, height), 4, np.zeros((height, width, 4), np.float32).tobytes(), dtype="f4")
        self.table.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.table.repeat_x = self.table.repeat_y = False
        self._brdf = np.zeros((ENVIRONMENT_BRDF_SIZE, ENVIRONMENT_BRDF_SIZE, 4), np.float32)
        self._brdf[..., :2] = environment_brdf_table()
        self.has_sheen_albedo = False  # blue: the sheen's albedo (write_sheen_albedo), once a sheen is drawn
        self.has_ltc = False           # the LTC rows (write_ltc), once a rectangle light is kept
        self.has_subsurface = False    # alpha: subsurface scattering's table (write_subsurface), once one is drawn
        self.table.write(self._brdf.tobytes(), viewport=(0, MAX_IRRADIANCE_PROBES, ENVIRONMENT_BRDF_SIZE,
                                                         ENVIRONMENT_BRDF_SIZE))
        self.framebuffer = ctx.framebuffer(color_attachments=[self.table])

        # Bound on the table's unit while the table is drawn into: no texture is bound for
        # sampling where it is also the target (a feedback loop is undefined on a GPU).
        self._placeholder = ctx.texture((1, 1), 4, np.zeros(4, np.float32).tobytes(), dtype="f4")
        self.ubo = ctx.buffer(irradiance_block(()))
        self.empty_ubo = ctx.buffer(irradiance_block(()))  # bound while a probe is captured: sky only
        self.rows: dict[int, int] = {}   # probe owner -> its row (a capture was projected into it)
        self._boxes: list[tuple[int, tuple, tuple, float]] = []  # (owner, centre, half size, blend distance)
        self._block = irradiance_block(())
        self.volumes: dict[int, VolumeGrid] = {}  # by slot: the irradiance volumes lighting the scene (set_volume)
        # A volume's bounces (IrradianceVolume.bounces): the table and block as a round of its
        # bake left them (begin_bounce), which its next round's captures are lit by
        # (bounce_lit), while the round writes the table itself.
        self._bounce_table: moderngl.Texture | None = None
        self._bounce_framebuffer: moderngl.Framebuffer | None = None
        self._bounce_ubo: moderngl.Buffer | None = None
        self.bounce_lit = False   # set about a volume point's capture that its grid's last round lights
        self._stale = False
        self._count = 0  # boxes in the block
        self._left_out: frozenset[int] = frozenset()  # the probes last said to get no row (_say_left_out)
        self._vao: moderngl.VertexArray | None = None
        self.projections = 0  # rows written since made (tests and the overlay read it)

    def write_ltc(self) -> None:
        """The LTC table of rectangle lights (``engine/render/ltc_fit.py``) into its rows
        (``LTC_ROW`` on: first each entry's M^-1, then its magnitude and Fresnel share; across
        roughness, down sqrt(1 - n.v): ``shaders/include/rect_lights.glsl`` ``ltc_entry``),
        once: the prepare stage asks for it when the first rectangle light is kept."""
        if self.has_ltc:
            return
        table = load_table()                   # (roughness, sqrt(1 - n.v), 6)
        rows = np.zeros((2 * LTC_SIZE, LTC_SIZE, 4), np.float32)
        rows[:LTC_SIZE] = table[..., :4].transpose(1, 0, 2)
        rows[LTC_SIZE:, :, :2] = table[..., 4:6].transpose(1, 0, 2)
        self._write_rows(rows.tobytes(), viewport=(0, LTC_ROW, LTC_SIZE, 2 * LTC_SIZE))
        self.has_ltc = True

    def write_sheen_albedo(self) -> None:
        """The sheen's albedo E(n.v) (``environment_brdf.sheen_albedo_table``) into the blue
        of the BRDF rows, once: a batch with a sheen (Material.sheen_color) asks for it when
        it is made, so a world without one never computes it."""
        if not self.has_sheen_albedo:
            self._brdf[..., 2] = sheen_albedo_table()
            self._write_rows(self._brdf.tobytes(), viewport=(0, MAX_IRRADIANCE_PROBES, ENVIRONMENT_BRDF_SIZE,
                                                             ENVIRONMENT_BRDF_SIZE))
            self.has_sheen_albedo = True

    def write_subsurface(self) -> None:
        """Subsurface scattering's table (``engine/render/subsurface.py``) into the alpha of
        the BRDF rows, and its band weights for the light from all round (``band_rows``) into
        their column ``SUBSURFACE_BANDS_COLUMN``, once: a batch with ``Material.subsurface``
        asks for them when it is made."""
        if not self.has_subsurface:
            self._brdf[..., 3] = subsurface_table()
            self._write_rows(self._brdf.tobytes(), viewport=(0, MAX_IRRADIANCE_PROBES, ENVIRONMENT_BRDF_SIZE,
                                                             ENVIRONMENT_BRDF_SIZE))
            bands = np.zeros((ENVIRONMENT_BRDF_SIZE, 1, 4), np.float32)
            bands[:, 0, :2] = band_rows()
            self._write_rows(bands.tobytes(), viewport=(SUBSURFACE_BANDS_COLUMN, MAX_IRRADIANCE_PROBES, 1,
                                                        ENVIRONMENT_BRDF_SIZE))
            self.has_subsurface = True

    # --- the boxes -----------------------------------------------------------------------------

    def set_boxes(self, boxes: Iterable[tuple[int, Iterable[float], Iterable[float], float]]) -> None:
        """The influence boxes probes serve: (owner, centre, size, blend distance) each.  Only
        those whose probe has a projected capture reach the shader (a row not written holds
        whatever the GPU left there)."""
        kept = sorted((int(owner), tuple(map(float, centre)), tuple(float(v) / 2.0 for v in size), float(blend))
                      for owner, centre, size, blend in boxes)
        if kept != self._boxes:
            self._boxes = kept
            self._stale = True
            self.renderer.note_scene_change()

    def _write_rows(self, data: bytes, viewport: tuple[int, int, int, int]) -> None:
        """Rows that are not a probe's or a volume's (the BRDF's, the LTC's), into the table and
        the bounce copy alike (a capture lit by the copy reads them there)."""
        self.table.write(data, viewport=viewport)
        if self._bounce_table is not None:
            self._bounce_table.write(data, viewport=viewport)

    def begin_bounce(self) -> None:
        """Keep the table and the volumes as they are now (a round of a volume's bake just
        ended), for the captures of the next round to be lit by (``bounce_lit``)."""
        self._refresh()
        if self._bounce_table is None:
            self._bounce_table = self.ctx.texture(self.table.size, 4, dtype="f4")
            self._bounce_table.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self._bounce_table.repeat_x = self._bounce_table.repeat_y = False
            self._bounce_framebuffer = self.ctx.framebuffer(color_attachments=[self._bounce_table])
            self._bounce_ubo = self.ctx.buffer(irradiance_block(()))
        self._bounce_framebuffer.use()   # (the scissor test bounds a blit: none)
        apply_pass_state(self.ctx, self.STATE, (0, 0, *self.table.size))
        self.ctx.copy_framebuffer(self._bounce_framebuffer, self.framebuffer)
        self._bounce_ubo.write(irradiance_block((), [self.volumes[slot] for slot in sorted(self.volumes)]))

    def end_bounces(self) -> None:
        """No volume's bake has a round to come lit by the last: the copy let go."""
        if self._bounce_table is not None:
            release_framebuffer(self._bounce_framebuffer)
            for obj in (self._bounce_table, self._bounce_ubo):
                obj.release()
            self._bounce_table = self._bounce_framebuffer = self._bounce_ubo = None

    @property
    def bounce_copies(self) -> int:
        """Bounce copies of the table held (0 or 1)."""
        return 0 if self._bounce_table is None else 1

    def set_volume(self, slot: int, grid: VolumeGrid | None) -> None:
        """The irradiance volume whose tiles slot ``slot`` holds, baked whole (None: it lights
        nothing): into the Irradiance block at the next ``bind``."""
        if grid != self.volumes.get(slot):
            if grid is None:
                del self.volumes[slot]
            else:
                self.volumes[slot] = grid
            self._stale = True
            self.renderer.note_scene_change()

    def _row_for(self, owner: int) -> int | None:
        row = self.rows.get(owner)
        if row is None:
            taken = set(self.rows.values())
            free = next((r for r in range(MAX_IRRADIANCE_PROBES) if r not in taken), None)
            if free is None:
                return None
            row = self.rows[owner] = free
            self._stale = True
            self.renderer.note_scene_change()
        return row

    # --- the GPU projection ----------------------------------------------------------------------
    def project(self, owner: int, cube: ProbeCube) -> bool:
        """Project probe ``owner``'s capture (its mip chain built) into its row: one draw of
        nine fragments, each summing one coefficient over the six faces of the cube's
        ``PROJECTION_FACE_SIZE``-texel level, every texel weighted by its solid angle.  False
        when the table is full (the probe lights nothing: said, ``_say_left_out``)."""
        row = self._row_for(owner)
        if row is None:
            self._say_left_out()
            return False
        self._project(cube, [((0, row, SH_COEFFICIENTS, 1), -1)])
        self.projections += 1
        self.renderer.checkpoint("probe irradiance projection")
        return True

    def _say_left_out(self) -> None:
        """Say which probes the full table leaves out of the ambient light (those with an
        influence box and no row: the first ``MAX_IRRADIANCE_PROBES`` projected hold the
        rows), when one is left out that was not when last said."""
        left_out = frozenset(owner for owner, *_ in self._boxes if owner not in self.rows)
        if left_out - self._left_out:
            LOG.warning("speculum: the ambient light's irradiance table (Renderer.irradiance) has rows for "
                        "MAX_IRRADIANCE_PROBES = %d reflection probes and %d have influence boxes: the first %d "
                        "captured hold the rows, so the probes of entities %s are left out and add nothing to the "
                        "ambient light", MAX_IRRADIANCE_PROBES, len(self._boxes), MAX_IRRADIANCE_PROBES,
                        sorted(left_out))
        self._left_out = left_out

    def project_volume_point(self, grid: VolumeGrid, index: tuple[int, int, int], cube: ProbeCube) -> None:
        """Project the capture of the volume's point ``index`` (its mip chain built) into its
        nine texels, one in each coefficient's tile (``VolumeGrid.texel``): a draw of one
        fragment a coefficient."""
        self._project(cube, [((*grid.texel(index, c), 1, 1), c) for c in range(SH_COEFFICIENTS)])
        self.renderer.checkpoint("volume irradiance projection")

    def _project(self, cube: ProbeCube, draws: list[tuple[tuple[int, int, int, int], int]]) -> None:
        """Draw the projection of ``cube`` into each viewport of ``draws`` with its
        coefficient (-1: each fragment's column's, a probe's row of nine)."""
        resolution = cube.resolution
        level = max(0, resolution.bit_length() - 1 - (PROJECTION_FACE_SIZE.bit_length() - 1))
        vao = self._program()
        program = vao.program
        program["source"].value = CUBE_MIP_UNIT  # again each time: a shader hot reload resets uniforms
        program["level"].value = float(level)
        program["level_size"].value = max(1, resolution >> level)
        bind_texture(self.ctx, self._placeholder, IRRADIANCE_UNIT)  # the scene pass binds the table again
        self.framebuffer.use()
        bind_texture(self.ctx, cube.texture, CUBE_MIP_UNIT)
        for viewport, coefficient in draws:
            program["coefficient_index"].value = coefficient
            apply_pass_state(self.ctx, self.STATE, viewport)
            vao.render(moderngl.TRIANGLES, vertices=3)
        bind_texture(self.ctx, self.renderer.sky, CUBE_MIP_UNIT)  # not left bound where the next capture draws into it
        self.renderer.note_scene_change()

    def _program(self) -> moderngl.VertexArray:
        if self._vao is None:
            program = self.renderer.shaders.program("fullscreen.vert", "irradiance_sh.frag")
            self._vao = self.ctx.vertex_array(program, [])
        return self._vao

    def read_row(self, owner: int) -> np.ndarray:
        """Probe ``owner``'s coefficients (9, 3) as the GPU wrote them (tests; reads back)."""
        row = self.rows[owner]
        width, height = self.table.size
        data = np.frombuffer(self.table.read(), np.float32).reshape(height, width, 4)
        return data[row, :SH_COEFFICIENTS, :3].astype(np.float64)

    def read_volume(self, grid: VolumeGrid) -> np.ndarray:
        """The volume's coefficients as the GPU holds them, (x, y, z, 9, 3) by point (tests;
        reads back)."""
        width, height = self.table.size
        data = np.frombuffer(self.table.read(), np.float32).reshape(height, width, 4).astype(np.float64)
        nx, ny, nz = grid.points
        tiles = data[grid.first_row:grid.first_row + ny * nz, :SH_COEFFICIENTS * nx, :3]  # (y z, c x, rgb)
        return tiles.reshape(ny, nz, SH_COEFFICIENTS, nx, 3).transpose(3, 0, 1, 2, 4)

    def read_environment_brdf(self) -> np.ndarray:
        """The environment BRDF rows as the GPU holds them (size, size, 2) (tests; reads back)."""
        width, height = self.table.size
        data = np.frombuffer(self.table.read(), np.float32).reshape(height, width, 4)
        return data[MAX_IRRADIANCE_PROBES:LTC_ROW, :ENVIRONMENT_BRDF_SIZE, :2].astype(np.float64)

    # --- binding -------------------------------------------------------------------------------
    def has_boxes(self) -> bool:
        """Whether any influence box with a projected capture, or a baked irradiance volume,
        lights the scene (the scene pass then draws its AMBIENT_PROBES or IRRADIANCE_VOLUME
        builds outside captures: ``Gpu.ambient_defines``)."""
        self._refresh()
        return bool(self.renderer.ambient_defines)

    def _refresh(self) -> None:
        if self._stale:
            boxes = [(centre, half, blend, self.rows[owner])
                     for owner, centre, half, blend in self._boxes if owner in self.rows]
            block = irradiance_block(boxes, [self.volumes[slot] for slot in sorted(self.volumes)])
            if block != self._block:
                self.ubo.write(block)
                self._block = block
                self.renderer.note_scene_change()
            self._count = min(len(boxes), MAX_IRRADIANCE_PROBES)
            defines = ((("AMBIENT_PROBES", "1"),) if self._count else ()) \
                + ((("IRRADIANCE_VOLUME", "1"),) if self.volumes else ())
            if defines != self.renderer.ambient_defines:
                self.renderer.ambient_defines = defines
                self.renderer.needs_preparing = True  # their builds, made before a mirror needs them
            self._stale = False

    def bind(self, capturing: bool) -> bool:
        """Bind the table and the Irradiance block for a scene pass: the boxes, or none while a
        probe is captured (the module docstring: captures see the sky's irradiance alone).
        Returns whether the pass draws with the table's builds (``Gpu.ambient_defines``:
        ``AMBIENT_PROBES``, the box loop and the table's reads, and ``IRRADIANCE_VOLUME``
        are builds of their own, since llvmpipe runs a loop's body once even when it has
        nothing to do: +25% of a frame of diffuse boxes).  No volume while a probe or a
        volume's point is captured either, but for a volume's bounce round (``bounce_lit``):
        its point's captures read the grids in the table's copy."""
        self._refresh()
        if capturing and self.bounce_lit and self._bounce_table is not None:
            # A volume point's capture in a bounce round: lit by the grids as the last round left them.
            bind_texture(self.ctx, self._bounce_table, IRRADIANCE_UNIT)
            bind_uniform_block(self.ctx, self._bounce_ubo, IRRADIANCE_BINDING)
            return bool(self.renderer.ambient_defines)
        bind_texture(self.ctx, self.table, IRRADIANCE_UNIT)
        bind_uniform_block(self.ctx, self.empty_ubo if capturing else self.ubo, IRRADIANCE_BINDING)
        return not capturing and bool(self.renderer.ambient_defines)

    def drop(self, owner: int) -> None:
        """Probe ``owner`` is gone: its row is free (and no box names it)."""
        if self.rows.pop(owner, None) is not None:
            self._stale = True
            self.renderer.note_scene_change()

    def release(self) -> None:
        if self._vao is not None:
            self._vao.release()
            self._vao = None
        release_framebuffer(self.framebuffer)
        self.end_bounces()
        for obj in (self.table, self._placeholder, self.ubo, self.empty_ubo):
            obj.release()
        self.rows.clear()

