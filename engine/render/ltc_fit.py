"""Linearly Transformed Cosines for the engine's GGX specular: the fit, its table and numpy
references of rectangular area lights (for the GLSL shading and its tests).

Why: a rectangular light's highlight is the GGX lobe integrated over the rectangle's solid
angle, and no closed form exists.  Heitz, Dupuy, Hill and Neubelt ("Real-Time Polygonal-Light
Shading with Linearly Transformed Cosines", SIGGRAPH 2016) approximate the lobe, for each
roughness and view angle, by a clamped cosine D_o(w) = max(w.z, 0) / pi seen through a 3x3
matrix M:

    D_M(l) = D_o(M^-1 l / |M^-1 l|) |det M^-1| / |M^-1 l|^3,

whose integral over a polygon is the clamped cosine's integral over the polygon with its
corners multiplied by M^-1: a closed form (Lambert's edge sum).  This module fits M to

    f(l) = D(h) V(l, v) max(n.l, 0)

exactly as ``shaders/include/ggx.glsl`` computes them (alpha = max(r^2, 1e-4), a2 = alpha^2,
D = a2 / (pi (n.h^2 a2 + |n x h|^2)^2), the separable Smith visibility over 4 n.l n.v with n.l and
n.v floored at 1e-4), Fresnel left out: the table also holds ``magnitude`` = integral of f over
the hemisphere and ``fresnel`` = integral of f (1 - v.h)^5, so that with Schlick's Fresnel

    specular = (f0 (magnitude - fresnel) + fresnel) * integral of D_o over the polygon M^-1 P.

The frame: n = +Z, the view v = (sin theta, 0, cos theta) in the xz-plane (its tangent part
along +X), so the lobe leans towards -X and is symmetric in y.

The matrix: the general isotropic form (4 numbers up to scale), parameterised for the fit as
M = R(phi + a d) U, U = [[a, 0, a s], [0, c, 0], [0, 0, 1]], R(x) the rotation about y taking +Z to
(sin x, 0, cos x), phi the lobe's mean direction (the mean of f l, computed, not fitted): a and c
the lobe's widths in and across the plane of incidence (fitted as logs, so a near-delta lobe of
alpha 1e-4 is as well scaled as a rough one), s a skew and d the frame's turn away from the mean
direction, both in units of a.  The paper fixes the frame on the mean direction (d = 0, three
parameters); fitting d too halves the error of rectangles at views past 50 degrees (measured: the
Fresnel-free integral over rectangles holding over 10% of the lobe, 90th percentile 10% -> 4.4%,
median 1.9% -> 0.9%).  Rotation and skew nearly undo each other for narrow lobes (a flat valley the
fit would drift along), so the error is multiplied by 1 + 0.05 d^2: the frame stays on the mean
unless turning it pays.  At normal incidence the lobe is round: a = c, s = d = 0 (one parameter).

The fit: each cell minimises the L3 norm of D_M - f / magnitude over the sphere, estimated as
the paper does by multiple importance sampling of both distributions (balance heuristic): a fixed
stratified 24 x 24 grid of the unit square drives GGX's sampling of visible normals (Heitz 2018)
for f and the cosine's sampling pushed through M for D_M, so a near-delta lobe is sampled where it
is and the estimate is a deterministic function of the parameters.  A Nelder-Mead written here
runs for a batch of roughness rows at once; column 0 (normal incidence) starts from a = c =
2 alpha (the exact optimum of a near-delta lobe), each next column starts from the previous one's
solution (the paper's walk from the round lobes at normal incidence outwards).  About 90 s on two
cores (``python -m engine.render.ltc_fit``; the rows split between two processes).

The table (``ltc_ggx.npy``, float32, shape (64, 64, 6)): ``table[i, j]`` for roughness
r_i = i / 63 (r = 0 is the shader's floor alpha = 1e-4, as every r <= 0.01) and t_j = j / 63,
t = sqrt(1 - cos theta) (cos theta = 1 - t^2, floored at 1e-4: column 63 is theta = 89.99 deg).
Channels: (m00, m20, m02, m22, magnitude, fresnel), the 4 numbers of M^-1 scaled so its middle
element is 1 (the scale of M^-1 changes neither the transformed directions nor the edge sum,
which normalises them):

    M^-1 = [[m00, 0, m02], [0, 1, 0], [m20, 0, m22]]   (rows)
    GLSL:  vec4 m = texture(ltc_matrix, uv);
           mat3 Minv = mat3(vec3(m.x, 0.0, m.y), vec3(0.0, 1.0, 0.0), vec3(m.z, 0.0, m.w));  // columns

det M^-1 > 0 in every cell (orientation is kept).  As textures: width 64 along t, height 64 along
r, uploaded row by row from the array (moderngl: ``ctx.texture((64, 64), 4, table[..., :4].tobytes(),
dtype="f4")`` and ``(64, 64), 2`` for channels 4-5), linear filtering, clamp to edge, read at

    uv = vec2(sqrt(1.0 - cos_theta), roughness) * (63.0 / 64.0) + 0.5 / 64.0

(texel centres on the grid points; ``ltc_lookup`` is that bilinear interpolation in numpy).

The polygon integral (``polygon_cosine_integral``): corners relative to the shading point in the
LTC frame, clipped to z >= 0 (Sutherland-Hodgman: a quad gives 3 to 5 corners, or none),
normalised, then

    (1 / 2 pi) * sum over edges (p_i, p_{i+1}) of acos(dot(p_i, p_{i+1})) * normalize(cross(p_{i+1}, p_i)).z

(the negative of the usual cross(p_i, p_{i+1})), positive when the corners run counter-clockwise
as seen from the shading point: the right-hand normal (c1 - c0) x (c2 - c1) of the light points at
the shading point, the side a one-sided light emits from (the other winding gives the negative:
max(., 0) for a one-sided light, abs for a two-sided one).  The whole upper hemisphere gives 1.
The same sum with the whole vector instead of its z is the vector form factor
(``polygon_vector_integral``).  ``ltc_rect_specular`` maps world corners into the frame
T1 = normalize(v - n (v.n)), T2 = cross(n, T1), n (right-handed, so the winding is kept; det M^-1 > 0
keeps it too): p = Minv * transpose(mat3(T1, T2, n)) * (corner - position), then integrates, times
f0 (magnitude - fresnel) + fresnel.  With ``light_fresnel`` the Fresnel is Schlick's at the half
vector of the light's mean direction instead: l = normalize(M * F) in the LTC frame, F the vector
form factor, M = inverse(M^-1) (up to scale [[m22, 0, -m02], [0, m00 m22 - m02 m20, 0], [-m20, 0,
m00]]), taken back to world space as l.x T1 + l.y T2 + l.z n; specular = magnitude * F_schlick(v.h)
* integral.  Measured against the brute force (``tests/test_ltc_fit.py``), relative error where the
light holds over 2% of the lobe, median / 90th percentile: metals 0.5% / 2.7% at views up to 50
degrees, 3% / 10% past them (the fit: the GGX lobe at grazing views is not a linear transform of a
cosine); dielectrics (f0 0.04) with the table's average Fresnel 1.5% / 6% and 17% / 64% (Fresnel
varies across a grazing lobe), with ``light_fresnel`` 0.7% / 2.6% and 2.2% / 9%."""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from engine.render.environment_brdf import fresnel_weight

LTC_SIZE = 64                 # the table's cells along roughness and along t = sqrt(1 - cos theta)
LTC_MIN_COS = 1e-4            # the view's cosine the last column is fitted at (cos theta = 0 there)
LTC_MIN_ALPHA = 1e-4          # ggx.glsl's floor of alpha = roughness^2
FIT_SAMPLES = 24              # per side: 24 x 24 samples of each distribution per error estimate
FIT_POWER = 3.0               # the fit minimises the L3 norm of D_M - f / |f| (the paper's)
MOMENT_SAMPLES = 96           # per side: samples of f for magnitude, fresnel and mean direction
TABLE_FILE = "ltc_ggx.npy"
TABLE_CHANNELS = 6            # m00, m20, m02, m22, magnitude, fresnel
ROTATION_PENALTY = 0.05       # the fit's error times 1 + this d^2 (d: the frame's turn from the mean, in a)


# --- the BRDF ------------------------------------------------------------------------------------
def ggx_a2(roughness: np.ndarray | float) -> np.ndarray:
    """ggx.glsl's alpha^2 for perceptual roughness r: max(r^2, 1e-4)^2."""
    r = np.asarray(roughness, np.float64)
    return np.maximum(r * r, LTC_MIN_ALPHA) ** 2


def grid_roughness(size: int = LTC_SIZE) -> np.ndarray:
    """The roughness of each table row: i / (size - 1)."""
    return np.arange(size) / (size - 1)


def grid_cos_theta(size: int = LTC_SIZE) -> np.ndarray:
    """The view cosine of each table column: 1 - t^2, t = j / (size - 1), floored at LTC_MIN_COS."""
    t = np.arange(size) / (size - 1)
    return np.maximum(1.0 - t * t, LTC_MIN_COS)


def view_vector(cos_theta: np.ndarray | float) -> np.ndarray:
    """v = (sin theta, 0, cos theta): shape (..., 3)."""
    c = np.clip(np.asarray(cos_theta, np.float64), -1.0, 1.0)
    return np.stack([np.sqrt(1.0 - c * c), np.zeros_like(c), c], axis=-1)


def ggx_lobe(light: np.ndarray, view: np.ndarray, a2: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """(f, Fc): f(l) = D(h) V(l, v) max(n.l, 0) as ggx.glsl computes it (n = +Z, Fresnel left out)
    and Schlick's Fresnel weight Fc = (1 - v.h)^5, for unit ``light`` and ``view`` (..., 3)
    broadcast together with ``a2`` (...)."""
    a2 = np.asarray(a2, np.float64)
    half = light + view
    half = half / np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-300)
    nh = np.maximum(half[..., 2], 0.0)
    d = nh * nh * a2 + (half[..., 0] ** 2 + half[..., 1] ** 2)
    distribution = a2 / (np.pi * d * d)
    nl = np.maximum(light[..., 2], 1e-4)
    nv = np.maximum(view[..., 2], 1e-4)
    visibility = 1.0 / ((nl + np.sqrt(a2 + (1.0 - a2) * nl * nl)) * (nv + np.sqrt(a2 + (1.0 - a2) * nv * nv)))
    f = distribution * visibility * np.maximum(light[..., 2], 0.0)
    vh = np.clip(np.sum(view * half, axis=-1), 0.0, 1.0)
    return f, fresnel_weight(vh)


def _smith_g1(cos: np.ndarray, a2: np.ndarray) -> np.ndarray:
    return 2.0 * cos / (cos + np.sqrt(a2 + (1.0 - a2) * cos * cos))


def sample_visible_normals(view: np.ndarray, a2: np.ndarray, u1: np.ndarray, u2: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Light directions l reflected about GGX half vectors drawn from the distribution of normals
    visible from ``view`` (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"), and
    their density in l: G1(v) D(h) / (4 n.v).  ``view`` (..., 3) in the xz-plane, ``a2`` (...),
    u1 and u2 (K,) in [0, 1): results (..., K, 3) and (..., K)."""
    alpha = np.sqrt(a2)[..., None]
    v = view[..., None, :]
    stretched = np.stack([alpha[..., 0] * view[..., 0], np.zeros_like(view[..., 0]), view[..., 2]], axis=-1)
    stretched /= np.linalg.norm(stretched, axis=-1, keepdims=True)
    sx, sz = stretched[..., 0:1], stretched[..., 2:3]
    on_axis = sx <= 0.0
    # T1 = (0, 1, 0) and T2 = stretched x T1 = (-sz, 0, sx); on the axis T1 = (1, 0, 0), T2 = (0, 1, 0)
    t1x, t1y = np.where(on_axis, 1.0, 0.0), np.where(on_axis, 0.0, 1.0)
    t2x, t2y, t2z = np.where(on_axis, 0.0, -sz), np.where(on_axis, 1.0, 0.0), np.where(on_axis, 0.0, sx)
    radius = np.sqrt(u1)
    angle = 2.0 * np.pi * u2
    p1, p2 = radius * np.cos(angle), radius * np.sin(angle)
    blend = 0.5 * (1.0 + sz)
    p2 = (1.0 - blend) * np.sqrt(1.0 - p1 * p1) + blend * p2
    p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    hx = p1 * t1x + p2 * t2x + p3 * sx
    hy = p1 * t1y + p2 * t2y
    hz = p2 * t2z + p3 * sz
    half = np.stack([alpha * hx, alpha * hy, np.maximum(hz, 0.0)], axis=-1)
    half /= np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-300)
    light = 2.0 * np.sum(v * half, axis=-1, keepdims=True) * half - v
    return light, visible_normal_pdf(light, view, a2)


def visible_normal_pdf(light: np.ndarray, view: np.ndarray, a2: np.ndarray | float) -> np.ndarray:
    """The density in l of ``sample_visible_normals``: G1(v) D(h) / (4 n.v), 0 where h.z <= 0.
    ``light`` (..., K, 3), ``view`` (..., 3), ``a2`` (...)."""
    a2 = np.asarray(a2, np.float64)[..., None]
    v = view[..., None, :]
    half = light + v
    half = half / np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-300)
    nh = half[..., 2]
    d = nh * nh * a2 + (half[..., 0] ** 2 + half[..., 1] ** 2)
    nv = v[..., 2]
    pdf = _smith_g1(nv, a2) * a2 / (np.pi * d * d) / (4.0 * nv)
    return np.where(nh > 0.0, pdf, 0.0)


def _unit_square_grid(count: int) -> tuple[np.ndarray, np.ndarray]:
    """The centres of a count x count grid of the unit square (a fixed stratified sample set)."""
    steps = (np.arange(count) + 0.5) / count
    u1, u2 = np.meshgrid(steps, steps, indexing="ij")
    return u1.ravel(), u2.ravel()


def lobe_moments(roughness: np.ndarray | float, cos_theta: np.ndarray | float,
                 samples: int = MOMENT_SAMPLES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(magnitude, fresnel, phi) for each pair (broadcast): the integrals of f and of f (1 - v.h)^5
    over the hemisphere and the angle from +Z (negative: towards -X) of the lobe's mean direction
    (the mean of f l), by sampling visible normals on a samples x samples grid."""
    r, c = np.broadcast_arrays(np.asarray(roughness, np.float64), np.asarray(cos_theta, np.float64))
    a2 = ggx_a2(r)
    view = view_vector(np.clip(c, LTC_MIN_COS, 1.0))
    u1, u2 = _unit_square_grid(samples)
    light, pdf = sample_visible_normals(view, a2, u1, u2)
    f, fc = ggx_lobe(light, view[..., None, :], a2[..., None])
    weight = np.where(pdf > 0.0, f / np.where(pdf > 0.0, pdf, 1.0), 0.0)
    mean = np.mean(weight[..., None] * light, axis=-2)
    return weight.mean(axis=-1), (weight * fc).mean(axis=-1), np.arctan2(mean[..., 0], mean[..., 2])


# --- the matrix ----------------------------------------------------------------------------------
def _full_params(x: np.ndarray) -> np.ndarray:
    """(log a, log c, s, d) from the free parameters of a fit: (log a) for a round lobe (c = a,
    s = d = 0), (log a, log c, s) (d = 0) or all four."""
    x = np.atleast_2d(x)
    zero = np.zeros_like(x[:, :1])
    if x.shape[-1] == 1:
        return np.concatenate([x, x, zero, zero], axis=-1)
    if x.shape[-1] == 3:
        return np.concatenate([x, zero], axis=-1)
    return x


def ltc_matrix(params: np.ndarray, phi: np.ndarray | float) -> np.ndarray:
    """M = R(phi + a d) [[a, 0, a s], [0, c, 0], [0, 0, 1]] for parameters (log a, log c, s, d) (or
    (log a, log c, s): d = 0): shape (..., 3, 3)."""
    p = np.asarray(params, np.float64)
    a, c = np.exp(p[..., 0]), np.exp(p[..., 1])
    turn = a * p[..., 3] if p.shape[-1] > 3 else 0.0
    shape = np.zeros(p.shape[:-1] + (3, 3))
    shape[..., 0, 0], shape[..., 0, 2], shape[..., 1, 1], shape[..., 2, 2] = a, a * p[..., 2], c, 1.0
    return _rotation_y(np.broadcast_to(phi + turn, p.shape[:-1])) @ shape


def _rotation_y(phi: np.ndarray) -> np.ndarray:
    """The rotation about y taking +Z to (sin phi, 0, cos phi)."""
    phi = np.asarray(phi, np.float64)
    cos, sin = np.cos(phi), np.sin(phi)
    r = np.zeros(phi.shape + (3, 3))
    r[..., 0, 0], r[..., 0, 2], r[..., 1, 1], r[..., 2, 0], r[..., 2, 2] = cos, sin, 1.0, -sin, cos
    return r


def normalised_inverse(m: np.ndarray) -> np.ndarray:
    """M^-1 scaled so its middle element is 1 (what the table holds)."""
    m_inv = np.linalg.inv(m)
    return m_inv / m_inv[..., 1:2, 1:2]


def params_from_inverse(m_inv: np.ndarray, phi_mean: float) -> np.ndarray:
    """The parameters (log a, log c, s, d) of M = R(phi_mean + a d) [[a, 0, a s], [0, c, 0], [0, 0, 1]]
    whose inverse is ``m_inv`` (3x3, any scale), ``phi_mean`` the angle of the lobe's mean direction
    (``lobe_moments``): M's xz-block decomposed into a rotation times an upper triangle (a QR)."""
    m = np.linalg.inv(np.asarray(m_inv, np.float64))
    block = m[np.ix_([0, 2], [0, 2])]
    phi = -math.atan2(block[1, 0], block[0, 0])   # the first column is k a R (1, 0, 0)
    cos, sin = math.cos(phi), math.sin(phi)
    upper = np.array([[cos, -sin], [sin, cos]]) @ block  # R^T block = k [[a, a s], [0, 1]]
    k = upper[1, 1]
    a = upper[0, 0] / k
    return np.array([math.log(a), math.log(m[1, 1] / k), upper[0, 1] / k / a, (phi - phi_mean) / a])


def table_inverse(entry: np.ndarray) -> np.ndarray:
    """M^-1 (3x3) from a cell's first 4 channels (m00, m20, m02, m22)."""
    m00, m20, m02, m22 = np.asarray(entry, np.float64)[:4]
    return np.array([[m00, 0.0, m02], [0.0, 1.0, 0.0], [m20, 0.0, m22]])


def ltc_density(m_inv: np.ndarray, light: np.ndarray) -> np.ndarray:
    """D_M(l) = D_o(M^-1 l / |M^-1 l|) |det M^-1| / |M^-1 l|^3 for unit ``light`` (..., 3)."""
    q = light @ np.asarray(m_inv, np.float64).T
    length = np.linalg.norm(q, axis=-1)
    return np.maximum(q[..., 2], 0.0) / np.pi * abs(np.linalg.det(m_inv)) / length ** 4


# --- the fit -------------------------------------------------------------------------------------
class _FitError:
    """The error of the LTC of each cell of a batch against its normalised lobe f / magnitude:
    integral of |D_M - f/|f||^power over the sphere by multiple importance sampling (balance
    heuristic) of f's visible normals (fixed per cell) and of D_M (the cosine's samples pushed
    through M at every evaluation)."""

    def __init__(self, roughness: np.ndarray, cos_theta: np.ndarray, samples: int = FIT_SAMPLES) -> None:
        self.a2 = ggx_a2(roughness)
        self.view = view_vector(np.clip(cos_theta, LTC_MIN_COS, 1.0))
        self.magnitude, self.fresnel, self.phi = lobe_moments(roughness, cos_theta)
        u1, u2 = _unit_square_grid(samples)
        self.brdf_light, self.brdf_pdf = sample_visible_normals(self.view, self.a2, u1, u2)
        f, _ = ggx_lobe(self.brdf_light, self.view[:, None, :], self.a2[:, None])
        self.brdf_target = f / self.magnitude[:, None]
        radius, angle = np.sqrt(u1), 2.0 * np.pi * u2
        self.cosine = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.sqrt(1.0 - u1)], axis=-1)

    def __call__(self, params: np.ndarray, cells: np.ndarray, power: float | None = None) -> np.ndarray:
        """The error of each row of ``params`` (k, 3) (or (k, 1): a round lobe) for cell ``cells`` (k,)."""
        power = FIT_POWER if power is None else power
        p = _full_params(params)
        a, c, skew = np.exp(p[:, 0:1]), np.exp(p[:, 1:2]), p[:, 2:3]
        phi = self.phi[cells][:, None] + a * p[:, 3:4]
        cos, sin = np.cos(phi), np.sin(phi)
        # f's samples: q = U^-1 R^T l, D_M = max(q.z, 0) / (pi |q|^4 a c)
        light = self.brdf_light[cells]
        lx, ly, lz = cos * light[..., 0] - sin * light[..., 2], light[..., 1], sin * light[..., 0] + cos * light[..., 2]
        qx, qy, qz = lx / a - skew * lz, ly / c, lz
        q2 = qx * qx + qy * qy + qz * qz
        ltc_at_brdf = np.maximum(qz, 0.0) / (np.pi * q2 * q2 * a * c)
        target = self.brdf_target[cells]
        error = np.abs(ltc_at_brdf - target) ** power / np.maximum(ltc_at_brdf + self.brdf_pdf[cells], 1e-300)
        # D_M's samples: l = R U w / |U w|, D_M(l) = w.z |U w|^3 / (pi a c)
        w = self.cosine
        ux, uy, uz = a * (w[:, 0] + skew * w[:, 2]), c * w[:, 1], np.broadcast_to(w[:, 2], (a.shape[0], w.shape[0]))
        length = np.sqrt(ux * ux + uy * uy + uz * uz)
        ltc_pdf = w[:, 2] * length ** 3 / (np.pi * a * c)
        light = np.stack([cos * ux + sin * uz, uy, -sin * ux + cos * uz], axis=-1) / length[..., None]
        view, a2 = self.view[cells], self.a2[cells]
        f, _ = ggx_lobe(light, view[:, None, :], a2[:, None])
        brdf_pdf = visible_normal_pdf(light, view, a2)
        target = f / self.magnitude[cells][:, None]
        error_ltc = np.abs(ltc_pdf - target) ** power / np.maximum(ltc_pdf + brdf_pdf, 1e-300)
        return error.mean(axis=-1) + error_ltc.mean(axis=-1)


def nelder_mead(objective: Callable[[np.ndarray, np.ndarray], np.ndarray], start: np.ndarray, step: np.ndarray,
                max_iterations: int = 600, x_tolerance: float = 1e-6, f_tolerance: float = 1e-9
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nelder-Mead's simplex search (reflection 1, expansion 2, contraction 1/2, shrink 1/2) on a
    batch of B independent problems at once: ``objective(x (k, n), rows (k,)) -> (k,)`` evaluates
    row ``rows[i]``'s function at x[i].  Each problem stops when its simplex is within
    ``x_tolerance`` of its best point in every coordinate and its values within ``f_tolerance``
    (relative) of its best.  Returns (best x (B, n), best values (B,), iterations (B,))."""
    start = np.atleast_2d(np.asarray(start, np.float64))
    count, n = start.shape
    simplex = np.repeat(start[:, None, :], n + 1, axis=1)
    simplex[:, 1:, :] += np.eye(n) * np.asarray(step, np.float64)
    values = objective(simplex.reshape(-1, n), np.repeat(np.arange(count), n + 1)).reshape(count, n + 1)
    iterations = np.zeros(count, int)
    for _ in range(max_iterations):
        order = np.argsort(values, axis=1)
        simplex = np.take_along_axis(simplex, order[:, :, None], axis=1)
        values = np.take_along_axis(values, order, axis=1)
        spread = np.max(np.abs(simplex[:, 1:] - simplex[:, :1]), axis=(1, 2))
        done = (spread <= x_tolerance) & (values[:, -1] - values[:, 0] <= f_tolerance * np.abs(values[:, 0]))
        rows = np.flatnonzero(~done)
        if rows.size == 0:
            break
        iterations[rows] += 1
        points, f = simplex[rows], values[rows]
        centroid = points[:, :-1].mean(axis=1)
        worst = points[:, -1]
        reflected = 2.0 * centroid - worst
        f_reflected = objective(reflected, rows)
        expand = f_reflected < f[:, 0]
        contract = f_reflected >= f[:, -2]
        outside = contract & (f_reflected < f[:, -1])
        second = np.where(expand[:, None], 3.0 * centroid - 2.0 * worst,
                          np.where(outside[:, None], 0.5 * (centroid + reflected), 0.5 * (centroid + worst)))
        f_second = np.full(rows.size, np.inf)
        needs = expand | contract
        if needs.any():
            f_second[needs] = objective(second[needs], rows[needs])
        new_point, new_value = reflected, f_reflected
        better = (expand & (f_second < f_reflected)) | (
            contract & (f_second <= np.where(outside, f_reflected, f[:, -1])))
        new_point = np.where(better[:, None], second, new_point)
        new_value = np.where(better, f_second, new_value)
        shrink = contract & ~better
        points[:, -1] = np.where(shrink[:, None], points[:, -1], new_point)
        f[:, -1] = np.where(shrink, f[:, -1], new_value)
        if shrink.any():
            which = np.flatnonzero(shrink)
            moved = 0.5 * (points[which, 1:] + points[which, :1])
            points[which, 1:] = moved
            f[which, 1:] = objective(moved.reshape(-1, n), np.repeat(rows[which], n)).reshape(which.size, n)
        simplex[rows], values[rows] = points, f
    best = np.argmin(values, axis=1)
    return simplex[np.arange(count), best], values[np.arange(count), best], iterations


def fit_column(roughness: np.ndarray, cos_theta: float, start: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit the cells of one view column: ``roughness`` (B,) at ``cos_theta``.  ``start``: the
    parameters (B, 4) to start from (the previous column's), or None at normal incidence (a round
    lobe, one parameter, from a = c = 2 alpha, the optimum of a near-delta lobe).  Returns
    (params (B, 4), the lobe's mean direction phi (B,), magnitude (B,), fresnel (B,))."""
    roughness = np.asarray(roughness, np.float64)
    error = _FitError(roughness, np.full(roughness.shape, cos_theta))
    if start is None:
        error.phi[:] = 0.0  # the round lobe's mean is +Z (the sampled mean is within noise of it)
        guess = np.log(np.minimum(2.0 * np.sqrt(error.a2), 1.0))[:, None]
        params, _, _ = nelder_mead(error, guess, np.array([0.5]))
    else:
        def penalised(x: np.ndarray, cells: np.ndarray) -> np.ndarray:
            return error(x, cells) * (1.0 + ROTATION_PENALTY * x[:, 3] ** 2)
        params, _, _ = nelder_mead(penalised, start, np.array([0.05, 0.05, 0.1, 0.1]))
    return _full_params(params), error.phi.copy(), error.magnitude, error.fresnel


def fit_cell(roughness: float, cos_theta: float, start: np.ndarray | None = None) -> np.ndarray:
    """One cell of the table (its 6 channels, float64), fitted as ``fit_table`` does from ``start``:
    the parameters (log a, log c, s, d) of its neighbour towards normal incidence (None at normal
    incidence; see ``params_from_inverse``)."""
    params, phi, magnitude, fresnel = fit_column(np.array([roughness]), cos_theta,
                                                 None if start is None else np.atleast_2d(start))
    return _table_entries(params, phi, magnitude, fresnel)[0]


def _table_entries(params: np.ndarray, phi: np.ndarray, magnitude: np.ndarray, fresnel: np.ndarray) -> np.ndarray:
    m_inv = normalised_inverse(ltc_matrix(params, phi))
    return np.stack([m_inv[:, 0, 0], m_inv[:, 2, 0], m_inv[:, 0, 2], m_inv[:, 2, 2], magnitude, fresnel], axis=-1)


def walk_rows(roughness: np.ndarray, cos_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fit the rows ``roughness`` (B,) of the table at every view cosine ``cos_theta`` (C,), walking
    the columns outwards from normal incidence, each starting from the one before.  Returns the
    table's entries (B, C, 6) and each cell's L1 error (B, C)."""
    count = len(roughness)
    entries = np.zeros((count, len(cos_theta), TABLE_CHANNELS))
    l1_error = np.zeros((count, len(cos_theta)))
    params = None
    for j, cos in enumerate(cos_theta):
        params, phi, magnitude, fresnel = fit_column(roughness, cos, params)
        entries[:, j] = _table_entries(params, phi, magnitude, fresnel)
        check = _FitError(roughness, np.full(count, cos), samples=2 * FIT_SAMPLES)
        check.phi[:] = phi
        l1_error[:, j] = check(params, np.arange(count), power=1.0)
    return entries, l1_error


def fit_table(size: int = LTC_SIZE, workers: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """The whole table (size, size, 6) float64 and each cell's L1 error, integral of |D_M - f/|f||
    over the sphere (0: exact, 2: disjoint): ``walk_rows`` with the rows split between ``workers``
    processes."""
    roughness = grid_roughness(size)
    cos_theta = grid_cos_theta(size)
    chunks = np.array_split(roughness, max(workers, 1))
    if workers <= 1:
        results = [walk_rows(rows, cos_theta) for rows in chunks]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            results = list(pool.map(walk_rows, chunks, [cos_theta] * len(chunks)))
    return np.concatenate([r[0] for r in results]), np.concatenate([r[1] for r in results])


def table_path() -> Path:
    return Path(__file__).with_name(TABLE_FILE)


def load_table() -> np.ndarray:
    """The fitted table (LTC_SIZE, LTC_SIZE, 6) float32 stored next to this module."""
    table = np.load(table_path())
    if table.shape != (LTC_SIZE, LTC_SIZE, TABLE_CHANNELS) or table.dtype != np.float32:
        raise ValueError(f"{table_path()}: shape {table.shape} {table.dtype}, expected "
                         f"({LTC_SIZE}, {LTC_SIZE}, {TABLE_CHANNELS}) float32: regenerate it with "
                         "python -m engine.render.ltc_fit")
    return table


# --- lookups and polygon integrals ---------------------------------------------------------------
def ltc_lookup(table: np.ndarray, roughness: float, cos_theta: float) -> tuple[np.ndarray, float, float]:
    """(M^-1 (3x3, middle element 1), magnitude, fresnel) interpolated bilinearly between the grid
    points, as GL's linear filtering at uv = (t, r) * (N-1)/N + 0.5/N reads the textures
    (t = sqrt(1 - cos theta), clamped to the table's edges)."""
    size = table.shape[0]
    x = float(np.clip(roughness, 0.0, 1.0)) * (size - 1)
    y = math.sqrt(1.0 - float(np.clip(cos_theta, 0.0, 1.0))) * (size - 1)
    i0, j0 = min(int(x), size - 2), min(int(y), size - 2)
    fx, fy = x - i0, y - j0
    cell = table[i0:i0 + 2, j0:j0 + 2].astype(np.float64)
    value = ((1 - fx) * ((1 - fy) * cell[0, 0] + fy * cell[0, 1]) + fx * ((1 - fy) * cell[1, 0] + fy * cell[1, 1]))
    return table_inverse(value), float(value[4]), float(value[5])


def clip_to_horizon(corners: np.ndarray) -> np.ndarray:
    """The part z >= 0 of the polygon ``corners`` (k, 3) (Sutherland-Hodgman against one plane):
    (m, 3), m = 0 or 3 .. k + 1 for a convex polygon, the winding kept."""
    corners = np.asarray(corners, np.float64)
    out = []
    for k in range(len(corners)):
        p, q = corners[k], corners[(k + 1) % len(corners)]
        if p[2] >= 0.0:
            out.append(p)
        if (p[2] >= 0.0) != (q[2] >= 0.0):
            out.append(p + (q - p) * (p[2] / (p[2] - q[2])))
    return np.array(out).reshape(-1, 3)


def polygon_vector_integral(corners: np.ndarray) -> np.ndarray:
    """The vector form factor of the polygon ``corners`` (k, 3) seen from the origin, clipped to
    z >= 0: (1 / 2 pi) sum over edges (p_i, p_{i+1}) of angle(p_i, p_{i+1}) * normalize(p_{i+1} x p_i)
    (3,).  Its z is ``polygon_cosine_integral``; its direction is the clamped cosine's mean direction
    over the polygon (for a front-facing one)."""
    clipped = clip_to_horizon(corners)
    if len(clipped) < 3:
        return np.zeros(3)
    p = clipped / np.linalg.norm(clipped, axis=-1, keepdims=True)
    q = np.roll(p, -1, axis=0)
    cross = np.cross(q, p)
    sine = np.linalg.norm(cross, axis=-1)
    angle = np.arctan2(sine, np.sum(p * q, axis=-1))   # acos(p.q), exact for near-parallel edges too
    return np.sum(np.where(sine[:, None] > 0.0, angle[:, None] * cross / np.where(sine > 0.0, sine, 1.0)[:, None],
                           0.0), axis=0) / (2.0 * np.pi)


def polygon_cosine_integral(corners: np.ndarray) -> float:
    """Integral of the clamped cosine D_o(w) = max(w.z, 0) / pi over the spherical polygon of
    ``corners`` (k, 3) seen from the origin (not necessarily unit): the polygon is clipped to
    z >= 0, then (1 / 2 pi) sum over edges of angle(p_i, p_{i+1}) * normalize(p_{i+1} x p_i).z.
    Positive when the corners run counter-clockwise as seen from the origin (the right-hand normal
    faces it), negative for the other winding; 1 for a polygon covering the hemisphere."""
    return float(polygon_vector_integral(corners)[2])


def shading_frame(n: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows T1, T2, n: T1 = normalize(v - n (v.n)) (any tangent when v is along n), T2 = n x T1."""
    n = np.asarray(n, np.float64) / np.linalg.norm(n)
    v = np.asarray(v, np.float64) / np.linalg.norm(v)
    t1 = v - n * np.dot(v, n)
    if np.linalg.norm(t1) < 1e-9:
        t1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    t1 /= np.linalg.norm(t1)
    return np.array([t1, np.cross(n, t1), n])


def _one_sided(value: float, two_sided: bool) -> float:
    return abs(value) if two_sided else max(value, 0.0)


def ltc_rect_specular(n: np.ndarray, v: np.ndarray, roughness: float, f0: float | np.ndarray, corners: np.ndarray,
                      table: np.ndarray, two_sided: bool = False, surface_clip: bool = False,
                      light_fresnel: bool = False) -> float | np.ndarray:
    """The GGX specular (with Schlick's Fresnel on v.h) a light of radiance 1 over the polygon
    ``corners`` (k, 3, relative to the shading point; counter-clockwise seen from it for its lit
    face) sends towards ``v`` from a surface of normal ``n``, by the table's LTC as the shader
    computes it: corners into the frame T1, T2, n, times M^-1, the clamped cosine's integral (the
    polygon clipped to z >= 0 after M^-1), times f0 (magnitude - fresnel) + fresnel (the lobe's
    average Fresnel).  One-sided unless ``two_sided``.  ``surface_clip``: clip to the surface's
    horizon before M^-1 as well (drops the LTC's leak below the horizon; a second clip in the
    shader).  ``light_fresnel``: instead of the lobe's average, magnitude times Schlick's Fresnel
    at the half vector of the light's mean direction: the polygon's vector form factor taken back
    through M (M = inverse(M^-1), any scale) into the surface's frame."""
    frame = shading_frame(n, v)
    view = np.asarray(v, np.float64) / np.linalg.norm(v)
    cos_theta = float(np.dot(frame[2], view))
    m_inv, magnitude, fresnel = ltc_lookup(table, roughness, cos_theta)
    local = np.asarray(corners, np.float64) @ frame.T
    f0 = np.asarray(f0, np.float64)
    if surface_clip:
        local = clip_to_horizon(local)
        if len(local) < 3:
            return f0 * 0.0
    vector = polygon_vector_integral(local @ m_inv.T)
    if two_sided and vector[2] < 0.0:
        vector = -vector                               # the back face lit: the same directions
    integral = max(float(vector[2]), 0.0)
    if not light_fresnel or integral == 0.0:
        return (f0 * (magnitude - fresnel) + fresnel) * integral
    light = np.linalg.solve(m_inv, vector) @ frame    # M w, back in world space
    half = light / np.linalg.norm(light) + view
    vh = float(np.clip(np.dot(view, half / np.linalg.norm(half)), 0.0, 1.0))
    return (f0 + (1.0 - f0) * fresnel_weight(vh)) * magnitude * integral


def rect_diffuse_integral(n: np.ndarray, corners: np.ndarray, two_sided: bool = False) -> float:
    """Integral of max(n.l, 0) over the solid angle of the polygon ``corners`` (k, 3, relative to
    the point; its lit face counter-clockwise as seen from it): pi times the clamped cosine's
    integral in a frame with n as z (the irradiance from a light of radiance 1; / pi: the form
    factor)."""
    frame = shading_frame(n, np.cross(n, [1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.cross(n, [0.0, 1.0, 0.0]))
    local = np.asarray(corners, np.float64) @ frame.T
    return np.pi * _one_sided(polygon_cosine_integral(local), two_sided)


# --- brute force: quadrature over the light's area -----------------------------------------------
def _quad_quadrature(corners: np.ndarray, samples: int, chunk: int = 256) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Midpoint rule over the bilinear patch of the 4 ``corners``: yields per chunk of rows the
    unit directions from the origin (m, 3) and the signed weight dA cos_light / dist^2 (m,),
    positive where the patch's right-hand normal (c1 - c0) x (c3 - c0) faces the origin."""
    c0, c1, c2, c3 = np.asarray(corners, np.float64)
    steps = (np.arange(samples) + 0.5) / samples
    for start in range(0, samples, chunk):
        u, w = np.meshgrid(steps, steps[start:start + chunk], indexing="ij")
        u, w = u.ravel()[:, None], w.ravel()[:, None]
        point = (1 - u) * (1 - w) * c0 + u * (1 - w) * c1 + u * w * c2 + (1 - u) * w * c3
        du = (1 - w) * (c1 - c0) + w * (c2 - c3)
        dw = (1 - u) * (c3 - c0) + u * (c2 - c1)
        area = np.cross(du, dw) / samples ** 2
        dist = np.linalg.norm(point, axis=-1)
        light = point / dist[:, None]
        yield light, -np.sum(area * light, axis=-1) / dist ** 2


def brute_force_rect_specular(n: np.ndarray, v: np.ndarray, roughness: float, f0: float, corners: np.ndarray,
                              samples: int = 512, two_sided: bool = False) -> float:
    """The same specular as ``ltc_rect_specular`` from ggx.glsl's GGX (D V F_schlick(v.h) n.l)
    summed over a samples x samples midpoint grid of the light's area (dA cos_light / dist^2):
    the ground truth, no table, no frame.  ``corners``: 4 (a planar quad, its lit face
    counter-clockwise as seen from the point)."""
    n = np.asarray(n, np.float64) / np.linalg.norm(n)
    v = np.asarray(v, np.float64) / np.linalg.norm(v)
    a2 = float(ggx_a2(roughness))
    total = 0.0
    for light, weight in _quad_quadrature(corners, samples):
        weight = np.abs(weight) if two_sided else np.maximum(weight, 0.0)
        half = light + v
        half /= np.maximum(np.linalg.norm(half, axis=-1, keepdims=True), 1e-300)
        nh = np.maximum(half @ n, 0.0)
        nxh = np.cross(n, half)
        d = nh * nh * a2 + np.sum(nxh * nxh, axis=-1)
        distribution = a2 / (np.pi * d * d)
        nl_raw = light @ n
        nl, nv = np.maximum(nl_raw, 1e-4), max(float(np.dot(n, v)), 1e-4)
        visibility = 1.0 / ((nl + np.sqrt(a2 + (1 - a2) * nl * nl)) * (nv + math.sqrt(a2 + (1 - a2) * nv * nv)))
        fresnel = f0 + (1.0 - f0) * fresnel_weight(np.sum(light * half, axis=-1))
        total += float(np.sum(fresnel * distribution * visibility * np.maximum(nl_raw, 0.0) * weight))
    return total


def brute_force_rect_diffuse(n: np.ndarray, corners: np.ndarray, samples: int = 512, two_sided: bool = False) -> float:
    """``rect_diffuse_integral`` by the midpoint rule over the light's area."""
    n = np.asarray(n, np.float64) / np.linalg.norm(n)
    total = 0.0
    for light, weight in _quad_quadrature(corners, samples):
        weight = np.abs(weight) if two_sided else np.maximum(weight, 0.0)
        total += float(np.sum(np.maximum(light @ n, 0.0) * weight))
    return total


# --- regeneration --------------------------------------------------------------------------------
def main() -> None:
    """Fit the table, save it next to this module and print the time and the fit's error."""
    begin = time.perf_counter()
    table, l1_error = fit_table()
    seconds = time.perf_counter() - begin
    np.save(table_path(), table.astype(np.float32))
    roughness, cos_theta = grid_roughness(), grid_cos_theta()
    theta = np.degrees(np.arccos(cos_theta))
    print(f"fitted {LTC_SIZE}x{LTC_SIZE} cells in {seconds:.1f} s -> {table_path()}")
    print("L1 error of the fit, integral of |D_M - f/|f|| over the sphere (0 exact, 2 disjoint):")
    for label, rows in (("roughness < 0.1", roughness < 0.1), ("roughness >= 0.1", roughness >= 0.1)):
        for low, high in ((0, 45), (45, 70), (70, 90.1)):
            part = l1_error[np.ix_(rows, (theta >= low) & (theta < high))]
            print(f"  {label}, view {low}-{high:.0f} deg: median {np.median(part):.4f}, "
                  f"90th percentile {np.percentile(part, 90):.4f}, max {part.max():.4f}")
    worst = np.unravel_index(np.argsort(l1_error, axis=None)[::-1][:3], l1_error.shape)
    for i, j in zip(*worst, strict=True):
        print(f"  worst: roughness {roughness[i]:.3f}, view {theta[j]:.2f} deg: {l1_error[i, j]:.4f}")


if __name__ == "__main__":
    import engine.render.ltc_fit as module  # the workers' function by its importable name, not __main__'s

    module.main()
