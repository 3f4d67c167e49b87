"""The split-sum's environment BRDF: the table the scene shader reads the environment's
specular reflection by (``shaders/scene.frag`` environment_specular).

The split-sum approximation (Karis, "Real Shading in Unreal Engine 4", 2013) writes a
surface's reflection of the light from all round as the prefiltered radiance along the
reflected ray times the BRDF integrated against light of 1 from every direction.  With
Schlick's Fresnel that integral is ``f0 A + B`` for the surface's roughness and the cosine
n.v between its normal and the eye, A and B here:

    A = integral of (1 - (1 - v.h)^5) D(h) V(l, v) n.l dl,   B = integral of (1 - v.h)^5 D V n.l dl

over the hemisphere of light directions l (h the half vector), D the GGX distribution and
V the height-correlated Smith visibility, the same ``shaders/include/ggx.glsl`` lights a
surface with (``ggx_distribution``, ``ggx_visibility``: alpha = roughness squared).  Each
entry is integrated by importance sampling the GGX distribution of half vectors along a
Hammersley sequence, as Karis's own table is.  A + B is the surface's directional albedo
(1 at roughness 0; the single-scattering energy rough GGX loses makes it less).

Why a table and not an analytic fit: Karis's fit for mobile (three.js's and Godot's
DFGApprox) fits Unreal's own visibility term, and is 0.1-0.2 below this integral for rough
metals; a table is the integral itself.  It is not a texture of its own: the scene shader's
fullest build already reads 16 samplers (the least GL 4.1 allows a stage), so the table
rides in ``ENVIRONMENT_BRDF_SIZE`` rows of the irradiance table's texture, below the probes'
rows (``engine/render/irradiance.py`` ``IrradianceTable``), read with bilinear filtering."""
from __future__ import annotations

import functools

import numpy as np

ENVIRONMENT_BRDF_SIZE = 32      # entries across n.v (columns) and down roughness (rows)
ENVIRONMENT_BRDF_SAMPLES = 2048  # half vectors an entry is integrated over (within about 0.015 of the integral)


def hammersley(count: int) -> tuple[np.ndarray, np.ndarray]:
    """The Hammersley point set in the unit square: (i + 1/2) / count and the radical
    inverse of i in base 2 (the bits of i mirrored)."""
    i = np.arange(count, dtype=np.uint32)
    bits = ((i << 16) | (i >> 16)) & 0xFFFFFFFF
    bits = ((bits & 0x55555555) << 1) | ((bits & 0xAAAAAAAA) >> 1)
    bits = ((bits & 0x33333333) << 2) | ((bits & 0xCCCCCCCC) >> 2)
    bits = ((bits & 0x0F0F0F0F) << 4) | ((bits & 0xF0F0F0F0) >> 4)
    bits = ((bits & 0x00FF00FF) << 8) | ((bits & 0xFF00FF00) >> 8)
    return (i + 0.5) / count, bits.astype(np.float64) / 2.0 ** 32


def fresnel_weight(vh: np.ndarray | float) -> np.ndarray:
    """Schlick's Fresnel weight (1 - v.h)^5: the reflectance is f0 + (1 - f0) times it (the
    one Python copy of ``shaders/include/ggx.glsl``'s ``schlick_at``)."""
    return (1.0 - np.clip(vh, 0.0, 1.0)) ** 5


def environment_brdf(roughness: np.ndarray | float, nv: np.ndarray | float,
                     samples: int = ENVIRONMENT_BRDF_SAMPLES) -> np.ndarray:
    """(A, B) for each pair of ``roughness`` and n.v (broadcast together): shape (..., 2)."""
    m, cos_v = np.broadcast_arrays(np.asarray(roughness, np.float64), np.asarray(nv, np.float64))
    a2 = np.maximum(m * m, 1e-4) ** 2  # ggx.glsl's alpha squared, its floor too
    cos_v = np.clip(cos_v, 1e-4, 1.0)[..., None]
    a2 = a2[..., None]
    u1, u2 = hammersley(samples)
    cos_h = np.sqrt((1.0 - u1) / (1.0 + (a2 - 1.0) * u1))  # GGX's distribution of half vectors about n
    sin_h = np.sqrt(np.maximum(1.0 - cos_h * cos_h, 0.0))
    phi = 2.0 * np.pi * u2
    sin_v = np.sqrt(1.0 - cos_v * cos_v)
    vh = sin_v * sin_h * np.cos(phi) + cos_v * cos_h   # v = (sin_v, 0, cos_v), n = z
    nl = np.maximum(2.0 * vh * cos_h - cos_v, 0.0)      # l = 2 (v.h) h - v
    visibility = 1.0 / ((nl + np.sqrt(a2 + (1.0 - a2) * nl * nl)) * (cos_v + np.sqrt(a2 + (1.0 - a2) * cos_v ** 2)))
    # The estimator of integral f(l) n.l dl with l's density D(h) n.h / (4 v.h): V n.l 4 v.h / n.h.
    weight = np.where(nl > 0.0, visibility * nl * 4.0 * np.maximum(vh, 0.0) / cos_h, 0.0)
    fresnel = fresnel_weight(vh)
    return np.stack([((1.0 - fresnel) * weight).mean(axis=-1), (fresnel * weight).mean(axis=-1)], axis=-1)


# The sheen layer (Material.sheen_color, glTF's KHR_materials_sheen): the "Charlie"
# distribution of Estevez and Kulla ("Production Friendly Microfacet Sheen BRDF", 2017),
# D(h) = (2 + 1/alpha) sin(theta_h)^(1/alpha) / (2 pi), alpha = sheen_roughness^2 (floored:
# SHEEN_MIN_ALPHA), with Neubelt and Pettineo's visibility V = 1 / (4 (n.l + n.v - n.l n.v))
# ("Crafting a Next-Gen Material Pipeline for The Order: 1886", 2013), as Filament draws it
# (shaders/scene.frag sheen_brdf).  Its directional albedo E(n.v) = integral of D V n.l over
# the hemisphere is the share of light the sheen takes at that angle: the material under it
# keeps 1 - max(sheen_color) E(n.v), and E(n.v) x the sky's or probes' radiance is the
# sheen's reflection of the light from all round (Filament's "DFG" for sheen).
SHEEN_MIN_ALPHA = 0.002
SHEEN_GRID = 64  # midpoints of cos(theta_l) and of phi the albedo is summed over


def charlie_distribution(alpha: np.ndarray | float, cos_h: np.ndarray | float) -> np.ndarray:
    """The Charlie sheen distribution D(h) at the cosine of h's angle to the normal."""
    alpha = np.maximum(np.asarray(alpha, np.float64), SHEEN_MIN_ALPHA)
    sin2 = np.maximum(1.0 - np.asarray(cos_h, np.float64) ** 2, 0.0)
    return (2.0 + 1.0 / alpha) * sin2 ** (0.5 / alpha) / (2.0 * np.pi)


def neubelt_visibility(nl: np.ndarray | float, nv: np.ndarray | float) -> np.ndarray:
    """Neubelt and Pettineo's visibility for the sheen (bounded: V n.l <= 1/4)."""
    nl, nv = np.asarray(nl, np.float64), np.asarray(nv, np.float64)
    return 1.0 / np.maximum(4.0 * (nl + nv - nl * nv), 1e-6)


def sheen_albedo(roughness: np.ndarray | float, nv: np.ndarray | float, grid: int = SHEEN_GRID) -> np.ndarray:
    """E(n.v): the integral of D V n.l over the hemisphere, for each pair of sheen
    ``roughness`` and n.v (broadcast together), by the midpoint rule in cos(theta_l) and phi."""
    r, cos_v = np.broadcast_arrays(np.asarray(roughness, np.float64), np.asarray(nv, np.float64))
    alpha = (r * r)[..., None, None]
    cos_v = np.clip(cos_v, 1e-4, 1.0)[..., None, None]
    cos_l = ((np.arange(grid) + 0.5) / grid)[:, None]
    phi = (np.arange(grid) + 0.5) / grid * np.pi
    sin_l = np.sqrt(1.0 - cos_l * cos_l)
    sin_v = np.sqrt(1.0 - cos_v * cos_v)
    # v = (sin_v, 0, cos_v), l = (sin_l cos phi, sin_l sin phi, cos_l), n = z: h = (l + v) / |l + v|
    # (phi over [0, pi]: the integrand is symmetric about the plane of n and v)
    hx, hy, hz = sin_l * np.cos(phi) + sin_v, sin_l * np.sin(phi) + 0.0 * sin_v, cos_l + cos_v
    cos_h = hz / np.sqrt(hx * hx + hy * hy + hz * hz)
    f = charlie_distribution(alpha, cos_h) * neubelt_visibility(cos_l, cos_v) * cos_l
    return f.mean(axis=(-2, -1)) * 2.0 * np.pi  # d(omega) = d(cos theta) d(phi) over [0, 1] x [0, 2 pi]


@functools.cache
def sheen_albedo_table(size: int = ENVIRONMENT_BRDF_SIZE) -> np.ndarray:
    """(size, size) float32: row j sheen roughness j / (size - 1), column i n.v i / (size - 1),
    held to 1: Neubelt's visibility is not energy-conserving towards grazing angles (a smooth
    sheen's albedo passes 1 below n.v of about 0.1), and a layer cannot take more than all
    of the light from the material under it.  Made when a sheen is first drawn (about a
    second of numpy): a scene without one pays nothing."""
    steps = np.linspace(0.0, 1.0, size)
    return np.minimum(sheen_albedo(steps[:, None], steps[None, :]), 1.0).astype(np.float32)


@functools.cache
def environment_brdf_table(size: int = ENVIRONMENT_BRDF_SIZE) -> np.ndarray:
    """(size, size, 2) float32: row j roughness j / (size - 1), column i n.v i / (size - 1)
    (texel centres at the ends, so a bilinear read of (n.v, roughness) in [0, 1] stays inside)."""
    steps = np.linspace(0.0, 1.0, size)
    return environment_brdf(steps[:, None], steps[None, :]).astype(np.float32)
