"""Subsurface scattering's diffuse light (``Material.subsurface``): the table the scene shader
reads it by (``shaders/include/subsurface.glsl``).

Light that enters skin, wax, marble or jade wanders under the surface before it leaves, so a
point glows with the light its neighbours took in: the shading softens towards the terminator,
takes the colour of the channel that travels furthest (red in skin) and wraps past it.  This
is pre-integrated subsurface scattering (Penner and Borshukov, "Pre-Integrated Skin Shading",
GPU Pro 2, 2011): the light a point of a curved surface gives back is worked out once for every
angle to the light and every ratio of the scattering's distance to the surface's radius of
curvature, and the shader reads it from a table by the light's n.l and the curvature it finds
from its normal's change across the pixel.  Penner integrates over a ring; here the surface is
a sphere of radius r, and the light each of its points took in (Lambert: max(n_q . l, 0)) is
weighed by Burley's normalized diffusion profile (Christensen and Burley, "Approximate
Reflectance Profiles for Efficient Subsurface Scattering", 2015; Unity HDRP's and Unreal's):

    R(rho) proportional to (exp(-rho / d) + exp(-rho / (3 d))) / rho

at the straight distance rho between the two points, d the profile's distance (a channel's
``subsurface_radius`` x ``subsurface_scale``).  Over the sphere, with rho = 2 r sin(alpha / 2)
at the angle alpha between the points, dA = r^2 sin(alpha) dalpha dphi = rho drho dphi: the
profile's 1 / rho cancels, the integral over the angle becomes one over rho of
exp(-rho / d) + exp(-rho / (3 d)), and the one over the azimuth phi of the clamped cosine has
a closed form (``_around``).  Normalised by the profile's integral over the same sphere, so
what the whole sphere gives back is what it takes in; at d / r -> 0 it is Lambert's max(n.l, 0).

The table holds D(n.l, s) - max(n.l, 0) (s = d / r): 0 on a flat surface, so a flat wall is
lit exactly as Lambert lights it.  Its columns are n.l in two halves (-1 to 0, then 0 to 1, 16
each, the middle at both) so the kink max(n.l, 0) puts in it at 0 is never filtered across;
its rows s / (1 + s) from 0 to 1 (1: d far beyond r).  Read with bilinear filtering it is
within 0.005 of the integral.  It is not a texture of its own: it rides in the alpha of the
environment BRDF's rows (``engine/render/irradiance.py``, as the sheen's albedo rides in
their blue), written once a subsurface material is drawn.

**The light from all round** (the sky's, the probes' and the irradiance volumes' spherical
harmonics) scatters under the surface by the same D: the point gives back the integral of
the radiance round it times D(n.w, s).  D is a function of n.w alone (a zonal kernel), so by
the Funk-Hecke theorem its convolution with spherical harmonics scales each band l by the
kernel's Legendre moment; the engine's coefficients are the irradiance's (Lambert's kernel
max(mu, 0) already applied), so the scattered light is the irradiance with band l weighed by

    r_l(s) = integral of D(mu, s) P_l(mu) over mu in [-1, 1]
             / integral of max(mu, 0) P_l(mu) (1/2, 1/3, 1/8 for l = 0, 1, 2)

(``ambient_band_weights``): r_0 = 1 (what the sphere gives back is what it takes in), r_1
and r_2 fall from 1 on a flat surface to about 0.34 and 0.20 where the light spreads far
(the light from above reaches round to the sides and below, each channel as far as its own
distance).  The same pre-integration Penner's table makes for a light, made for a sky's
bands, as the irradiance volumes of skin renderers weigh theirs.  Its rows (``band_rows``, r_1
and r_2 at the table's rows) ride in one more column of the BRDF rows, beside the table
(``SUBSURFACE_BANDS_COLUMN``)."""
from __future__ import annotations

import functools

import numpy as np

from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE

PROFILE_STEPS = 512  # points along rho each exponential of the profile is integrated at
FAR_SPREAD = 1e6     # the last row's d / r (its s / (1 + s) is 1)
# The BRDF rows' column the band weights ride in (r_1, r_2 in red and green): one past a guard
# column of zeros after the table's own, so a lookup at either's texel centres weighs the other 0.
SUBSURFACE_BANDS_COLUMN = ENVIRONMENT_BRDF_SIZE + 1
BAND_NODES = 32      # Gauss-Legendre nodes on each half of mu's range (D is smooth on each)
LAMBERT_MOMENTS = (0.5, 1.0 / 3.0, 0.125)   # the integral of max(mu, 0) P_l(mu), l = 0, 1, 2


def _around(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The integral over phi in [0, 2 pi) of max(a cos(phi) + b, 0), a >= 0."""
    whole = 2.0 * np.pi * np.maximum(b, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = np.arccos(np.clip(-b / np.where(a > 0.0, a, 1.0), -1.0, 1.0))
        part = 2.0 * (a * np.sin(edge) + b * edge)
    return np.where(a <= np.abs(b), whole, part)


def scattered_diffuse(nl: np.ndarray | float, spread: np.ndarray | float,
                      steps: int = PROFILE_STEPS) -> np.ndarray:
    """D(n.l, s): the light a point of a sphere gives back, per unit of the light arriving
    head on, where the light meets its normal at cosine ``nl`` and ``spread`` is the profile's
    distance over the sphere's radius (d / r; broadcast together).  Each exponential of the
    profile is integrated by the inverse of its own distribution along rho (the midpoints of
    ``steps`` equal shares of it), so a narrow profile is sampled where it lies."""
    nl, spread = np.broadcast_arrays(np.asarray(nl, np.float64), np.asarray(spread, np.float64))
    spread = np.maximum(spread, 1e-9)[..., None]
    sin_l = np.sqrt(np.maximum(1.0 - nl * nl, 0.0))[..., None]
    cos_l = nl[..., None]
    shares = (np.arange(steps) + 0.5) / steps
    given = taken = 0.0
    for d in (spread, 3.0 * spread):
        mass = d[..., 0] * -np.expm1(-2.0 / d[..., 0])   # the integral of exp(-rho / d) over rho in [0, 2]
        rho = -d * np.log1p(-shares * -np.expm1(-2.0 / d))
        alpha = 2.0 * np.arcsin(np.clip(rho / 2.0, 0.0, 1.0))
        given = given + mass * _around(sin_l * np.sin(alpha), cos_l * np.cos(alpha)).mean(axis=-1)
        taken = taken + mass * 2.0 * np.pi
    return given / taken


def table_columns(size: int = ENVIRONMENT_BRDF_SIZE) -> np.ndarray:
    """n.l at each of the table's columns: -1 to 0 over the first half, 0 to 1 over the second."""
    half = size // 2
    return np.concatenate([np.linspace(-1.0, 0.0, half), np.linspace(0.0, 1.0, size - half)])


def table_rows(size: int = ENVIRONMENT_BRDF_SIZE) -> np.ndarray:
    """d / r at each of the table's rows (row j: s / (1 + s) = j / (size - 1))."""
    y = np.linspace(0.0, 1.0, size)
    return np.where(y < 1.0, y / np.maximum(1.0 - y, 1e-12), FAR_SPREAD)


@functools.cache
def subsurface_table(size: int = ENVIRONMENT_BRDF_SIZE) -> np.ndarray:
    """(size, size) float32: row j at d / r = ``table_rows``' j, column i at n.l =
    ``table_columns``' i, D(n.l, d / r) - max(n.l, 0); row 0 (a flat surface) all 0."""
    nl = table_columns(size)
    table = scattered_diffuse(nl[None, :], table_rows(size)[:, None]) - np.maximum(nl, 0.0)[None, :]
    table[0] = 0.0
    return table.astype(np.float32)


def table_lookup(table: np.ndarray, nl: np.ndarray | float, spread: np.ndarray | float) -> np.ndarray:
    """D(n.l, d / r) as the shader reads it from ``table``: the same columns and rows, filtered
    bilinearly (the Python twin of ``subsurface.glsl``'s ``subsurface_delta``, for tests)."""
    nl, spread = np.broadcast_arrays(np.asarray(nl, np.float64), np.asarray(spread, np.float64))
    size = table.shape[0]
    half = size // 2
    x = np.where(nl < 0.0, (nl + 1.0) * (half - 1), half + nl * (size - half - 1))
    y = spread / (1.0 + spread) * (size - 1)
    i = np.clip(np.floor(x).astype(int), 0, size - 2)
    j = np.clip(np.floor(y).astype(int), 0, size - 2)
    fx, fy = x - i, y - j
    value = (table[j, i] * (1 - fx) * (1 - fy) + table[j, i + 1] * fx * (1 - fy)
             + table[j + 1, i] * (1 - fx) * fy + table[j + 1, i + 1] * fx * fy)
    return value + np.maximum(nl, 0.0)


def ambient_band_weights(spread: np.ndarray | float) -> np.ndarray:
    """(r_0, r_1, r_2) at ``spread`` (d / r; shape (..., 3)): D's Legendre moments over
    Lambert's (see the module), each half of mu's range by Gauss-Legendre (D bends sharply at
    mu = 0 on a flat surface, smoothly on either side)."""
    spread = np.asarray(spread, np.float64)
    nodes, weights = np.polynomial.legendre.leggauss(BAND_NODES)
    mu = np.concatenate([(nodes - 1.0) / 2.0, (nodes + 1.0) / 2.0])   # [-1, 0], then [0, 1]
    w = np.concatenate([weights, weights]) / 2.0
    kernel = scattered_diffuse(mu, spread[..., None])                   # (..., 2 x BAND_NODES)
    legendre = np.stack([np.ones_like(mu), mu, 0.5 * (3.0 * mu * mu - 1.0)])
    moments = np.einsum("...m,lm->...l", kernel * w, legendre)
    return moments / np.asarray(LAMBERT_MOMENTS)


@functools.cache
def band_rows(size: int = ENVIRONMENT_BRDF_SIZE) -> np.ndarray:
    """(size, 2) float32: r_1 and r_2 at the table's rows (``table_rows``); row 0 (a flat
    surface) exactly 1."""
    rows = ambient_band_weights(table_rows(size))[:, 1:]
    rows[0] = 1.0
    return rows.astype(np.float32)


def band_lookup(rows: np.ndarray, spread: np.ndarray | float) -> np.ndarray:
    """(r_1, r_2) at ``spread`` as the shader reads them from ``rows``: linearly between the
    rows by s / (1 + s) (the Python twin of ``subsurface.glsl``'s ``subsurface_bands``)."""
    spread = np.asarray(spread, np.float64)
    y = spread / (1.0 + spread) * (len(rows) - 1)
    j = np.clip(np.floor(y).astype(int), 0, len(rows) - 2)
    f = (y - j)[..., None]
    return rows[j] * (1.0 - f) + rows[j + 1] * f
