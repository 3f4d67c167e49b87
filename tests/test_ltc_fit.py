"""The LTC table of the GGX specular (engine/render/ltc_fit.py) against ground truths worked out
here or by the module's brute force, which sums ggx.glsl's GGX over a midpoint grid of the
light's area (dA cos_light / dist^2) and never reads the table.

Measured on this file's 60 rectangles (sizes 0.2-2 m, distances 0.5-4 m, tilted, centred near the
mirror direction, views 0-80 degrees, roughness 0.1-1), relative error of the LTC specular where
the light holds over 2% of the lobe (median / 90th percentile / max):

    f0 1 (the fit alone)             views <= 50 deg: 0.5% / 2.7% / 5.6%   past 50: 3.1% / 10% / 15%
    f0 0.04, the table's Fresnel     views <= 50 deg: 1.5% / 5.8% / 16%    past 50: 17% / 64% / 79%
    f0 0.04, light_fresnel           views <= 50 deg: 0.7% / 2.6% / 5.6%   past 50: 2.2% / 9.0% / 15%

and never off by more than 5.3% (f0 1), 15% (table's Fresnel) or 1.9% (light_fresnel) of the
lobe's energy.  The error is the LTC's, not the brute force's (400^2 and 1000^2 samples agree to
1e-5, and the LTC's polygon integral equals the LTC's density summed over the same grid; the exact
cell's fit gives the table's interpolated answer): past 50 degrees the lobe's shape is harder to
fit, and a dielectric's Fresnel, which the table holds as an average over the whole lobe, varies
across it (a light near the horizon at a grazing view sees 3 times the average).  The bounds below
are those measurements with a margin."""
from __future__ import annotations

import math

import numpy as np
import pytest

from engine.render import ltc_fit
from engine.render.environment_brdf import environment_brdf
from engine.render.ltc_fit import (
    LTC_SIZE,
    brute_force_rect_diffuse,
    brute_force_rect_specular,
    ggx_lobe,
    load_table,
    ltc_density,
    ltc_lookup,
    ltc_rect_specular,
    polygon_cosine_integral,
    rect_diffuse_integral,
)

SAMPLES = 400  # per side of the brute force's grid over a light
SCENES = 60


@pytest.fixture(scope="module")
def table() -> np.ndarray:
    return load_table()


def rectangle(centre: np.ndarray, facing: np.ndarray, width: float, height: float, spin: float) -> np.ndarray:
    """The 4 corners of a rectangle whose lit face looks along ``facing``: counter-clockwise as seen
    from in front of it."""
    facing = facing / np.linalg.norm(facing)
    helper = np.array([1.0, 0.0, 0.0]) if abs(facing[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(facing, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(facing, e1)
    e1, e2 = math.cos(spin) * e1 + math.sin(spin) * e2, -math.sin(spin) * e1 + math.cos(spin) * e2
    u, w = e1 * width / 2, e2 * height / 2
    return np.array([centre - u - w, centre + u - w, centre + u + w, centre - u + w])


def rotation(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def sphere_grid(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions of a midpoint (theta, phi) grid over the sphere and their solid angles."""
    theta = (np.arange(count) + 0.5) / count * math.pi
    phi = (np.arange(2 * count) + 0.5) / (2 * count) * 2 * math.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    directions = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    return directions, np.sin(t) * (math.pi / count) ** 2


def scenes(count: int, seed: int) -> list[dict]:
    """Rectangles fully above the surface's horizon, lit face towards the point, near the mirror
    direction, all turned by a random rotation (n is not +Z, v not in the xz-plane)."""
    rng = np.random.default_rng(seed)
    out: list[dict] = []
    while len(out) < count:
        view = math.radians(rng.uniform(0.0, 80.0))
        mirror = np.array([-math.sin(view), 0.0, math.cos(view)])
        direction = mirror + rng.normal(size=3) * rng.uniform(0.0, 0.5)
        direction /= np.linalg.norm(direction)
        distance = rng.uniform(0.5, 4.0)
        facing = -direction + rng.normal(size=3) * 0.4
        corners = rectangle(distance * direction, facing, *rng.uniform(0.2, 2.0, 2), rng.uniform(0, math.pi))
        if np.dot(facing, -direction) < 0.3 or corners[:, 2].min() < 0.05 * distance:
            continue
        turn = rotation(rng)
        out.append(dict(n=turn @ [0.0, 0.0, 1.0], v=turn @ [math.sin(view), 0.0, math.cos(view)],
                        roughness=rng.uniform(0.1, 1.0), corners=corners @ turn.T, view=math.degrees(view)))
    return out


# --- the table -----------------------------------------------------------------------------------
def test_table_loads_with_its_shape_and_sane_values(table):
    assert table.shape == (LTC_SIZE, LTC_SIZE, 6) and table.dtype == np.float32
    assert np.isfinite(table).all()
    m00, m20, m02, m22, magnitude, fresnel = np.moveaxis(table.astype(np.float64), -1, 0)
    assert (m00 * m22 - m02 * m20 > 0).all()          # det M^-1 > 0: the winding is kept
    assert (magnitude > 0).all() and (magnitude <= 1.0 + 1e-3).all()
    assert (fresnel >= 0).all() and (fresnel < magnitude).all()
    # normal incidence: a round lobe, M^-1 = diag(1, 1, m22)
    np.testing.assert_allclose(table[:, 0, 0], 1.0, atol=1e-6)
    np.testing.assert_allclose(table[:, 0, 1:3], 0.0, atol=1e-6)


def test_texture_coordinates_and_glsl_matrix_read_the_table_as_ltc_lookup(table):
    """GL's linear filtering at uv = (t, r) (N-1)/N + 0.5/N (texel centres at (k + 0.5) / N, width
    along t, height along r, clamp to edge) and mat3(vec3(x, 0, y), vec3(0, 1, 0), vec3(z, 0, w))
    (columns) give ltc_lookup's M^-1."""
    size = table.shape[0]
    rng = np.random.default_rng(3)
    for roughness, cos_theta in [(0.0, 1.0), (1.0, 0.0), *rng.uniform(0.0, 1.0, (20, 2))]:
        t = math.sqrt(1.0 - cos_theta)
        u, v = (t * (size - 1) / size + 0.5 / size, roughness * (size - 1) / size + 0.5 / size)
        x, y = u * size - 0.5, v * size - 0.5                  # GL: texel space, centres at integers
        x0, y0 = math.floor(x), math.floor(y)
        texel = 0.0
        for dy, wy in ((0, 1 - (y - y0)), (1, y - y0)):
            for dx, wx in ((0, 1 - (x - x0)), (1, x - x0)):
                row, column = min(max(y0 + dy, 0), size - 1), min(max(x0 + dx, 0), size - 1)
                texel = texel + wx * wy * table[row, column].astype(np.float64)
        columns = [np.array([texel[0], 0.0, texel[1]]), np.array([0.0, 1.0, 0.0]), np.array([texel[2], 0.0, texel[3]])]
        m_inv, magnitude, fresnel = ltc_lookup(table, roughness, cos_theta)
        np.testing.assert_allclose(np.stack(columns, axis=1), m_inv, atol=1e-6)
        # M up to scale, as the docstring gives it for light_fresnel: det(M^-1) inverse(M^-1)
        m00, m20, m02, m22 = texel[:4]
        adjugate = np.array([[m22, 0.0, -m02], [0.0, m00 * m22 - m02 * m20, 0.0], [-m20, 0.0, m00]])
        np.testing.assert_allclose(adjugate, np.linalg.det(m_inv) * np.linalg.inv(m_inv), atol=1e-9)
        assert magnitude == pytest.approx(texel[4], abs=1e-6) and fresnel == pytest.approx(texel[5], abs=1e-6)


def test_magnitude_of_the_roughest_lobe_at_normal_incidence(table):
    light, solid_angle = sphere_grid(800)
    f, fresnel = ggx_lobe(light, np.array([0.0, 0.0, 1.0]), ltc_fit.ggx_a2(1.0))
    assert table[-1, 0, 4] == pytest.approx(np.sum(f * solid_angle), rel=2e-3)
    assert table[-1, 0, 5] == pytest.approx(np.sum(f * fresnel * solid_angle), rel=2e-3)


def test_magnitude_and_fresnel_agree_with_the_split_sum_table(table):
    """The environment BRDF's A and B (engine/render/environment_brdf.py, importance sampled
    along n.h) are magnitude - fresnel and fresnel."""
    rows, columns = np.array([6, 20, 40, 63]), np.array([0, 20, 40, 56])
    roughness = ltc_fit.grid_roughness()[rows][:, None]
    cos_theta = ltc_fit.grid_cos_theta()[columns][None, :]
    split = environment_brdf(roughness, cos_theta, samples=16384)
    cells = table[np.ix_(rows, columns)].astype(np.float64)
    np.testing.assert_allclose(cells[..., 4] - cells[..., 5], split[..., 0], atol=4e-3)
    np.testing.assert_allclose(cells[..., 5], split[..., 1], atol=4e-3)


@pytest.mark.parametrize("row, column", [(63, 0), (40, 20), (30, 50), (20, 40), (63, 63)])
def test_ltc_distribution_integrates_to_one(table, row, column):
    light, solid_angle = sphere_grid(1000)
    total = np.sum(ltc_density(ltc_fit.table_inverse(table[row, column]), light) * solid_angle)
    assert total == pytest.approx(1.0, abs=5e-3)


@pytest.mark.parametrize("row, column", [(40, 30), (20, 45)])
def test_refitting_a_cell_reproduces_the_table(table, row, column):
    """The module's fit, started as fit_table starts it (from the stored neighbour towards normal
    incidence), lands on the stored cell: the file cannot drift away from the code unnoticed."""
    roughness, cos_theta = ltc_fit.grid_roughness()[row], ltc_fit.grid_cos_theta()
    _, _, phi_mean = ltc_fit.lobe_moments(roughness, cos_theta[column - 1])
    start = ltc_fit.params_from_inverse(ltc_fit.table_inverse(table[row, column - 1]), float(phi_mean))
    cell = ltc_fit.fit_cell(roughness, cos_theta[column], start)
    np.testing.assert_allclose(cell, table[row, column], rtol=1e-4, atol=1e-5)


# --- polygon integrals ---------------------------------------------------------------------------
def test_polygon_integral_winding_and_hemisphere():
    horizon = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    assert polygon_cosine_integral(horizon) == pytest.approx(1.0)        # the whole upper hemisphere
    assert polygon_cosine_integral(horizon[::-1]) == pytest.approx(-1.0)
    # a small square straight above: counter-clockwise as seen from the origin, (c1-c0) x (c2-c1) towards it
    square = rectangle(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), 0.02, 0.02, 0.3)
    assert np.dot(np.cross(square[1] - square[0], square[2] - square[1]), -square[0]) > 0
    assert polygon_cosine_integral(square) == pytest.approx(0.02 ** 2 / math.pi, rel=1e-3)
    assert polygon_cosine_integral(square[::-1]) == pytest.approx(-0.02 ** 2 / math.pi, rel=1e-3)
    assert polygon_cosine_integral(-square) == 0.0                        # below the horizon


def test_diffuse_form_factor_matches_brute_force():
    rng = np.random.default_rng(11)
    for _ in range(12):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        direction = normal + rng.normal(size=3) * 0.6
        direction /= np.linalg.norm(direction)
        corners = rectangle(rng.uniform(0.5, 4.0) * direction, -direction + rng.normal(size=3) * 0.3,
                            *rng.uniform(0.2, 2.0, 2), rng.uniform(0, math.pi))
        exact = rect_diffuse_integral(normal, corners)
        assert exact == pytest.approx(brute_force_rect_diffuse(normal, corners, SAMPLES), rel=5e-3)


def test_rectangle_across_the_horizon_is_clipped(table):
    """A wall standing across the surface's plane: the exact form factor counts only its part
    above (the brute force's max(n.l, 0)), and so does the LTC's specular, within its error."""
    n, v = np.array([0.0, 0.0, 1.0]), np.array([math.sin(0.6), 0.0, math.cos(0.6)])
    wall = rectangle(np.array([-1.5, 0.2, 0.3]), np.array([1.0, 0.0, 0.0]), 2.0, 1.6, 0.2)
    assert wall[:, 2].min() < 0 < wall[:, 2].max()
    above = rect_diffuse_integral(n, wall)
    assert above == pytest.approx(brute_force_rect_diffuse(n, wall, SAMPLES), rel=5e-3)
    for roughness, f0 in [(0.3, 1.0), (0.6, 0.04), (0.9, 1.0)]:
        _, magnitude, fresnel = ltc_lookup(table, roughness, v[2])
        energy = f0 * (magnitude - fresnel) + fresnel
        truth = brute_force_rect_specular(n, v, roughness, f0, wall, SAMPLES)
        for surface_clip in (False, True):
            ltc = ltc_rect_specular(n, v, roughness, f0, wall, table, surface_clip=surface_clip)
            assert abs(ltc - truth) < 0.1 * truth + 0.01 * energy, (roughness, surface_clip, ltc, truth)


def test_rectangle_behind_the_surface_or_facing_away_gives_nothing(table):
    n, v = np.array([0.0, 0.0, 1.0]), np.array([0.5, 0.0, math.sqrt(0.75)])
    below = rectangle(np.array([-1.0, 0.0, -1.0]), np.array([1.0, 0.0, 1.0]), 1.0, 1.0, 0.0)
    assert ltc_rect_specular(n, v, 0.5, 1.0, below, table) == 0.0
    assert ltc_rect_specular(n, v, 0.5, 1.0, below, table, two_sided=True) == 0.0
    assert rect_diffuse_integral(n, below) == 0.0
    assert brute_force_rect_specular(n, v, 0.5, 1.0, below, 64) == 0.0
    above = rectangle(np.array([-1.0, 0.0, 1.0]), np.array([1.0, 0.0, -1.0]), 1.0, 1.0, 0.0)
    backwards = above[::-1]                                   # its lit face away from the point
    assert ltc_rect_specular(n, v, 0.5, 1.0, backwards, table) == 0.0
    assert brute_force_rect_specular(n, v, 0.5, 1.0, backwards, 64) == 0.0
    front = ltc_rect_specular(n, v, 0.5, 1.0, above, table)
    assert front > 0 and ltc_rect_specular(n, v, 0.5, 1.0, backwards, table, two_sided=True) == pytest.approx(front)


# --- the specular against the brute force --------------------------------------------------------
def specular_errors(table: np.ndarray, f0: float, light_fresnel: bool = False
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(view angle, relative error, error over the lobe's energy, whether the light holds over 2%
    of the lobe: where the relative error means something) of the LTC specular of each scene."""
    rows = []
    for scene in scenes(SCENES, seed=2016):
        n, v, roughness, corners = scene["n"], scene["v"], scene["roughness"], scene["corners"]
        ltc = ltc_rect_specular(n, v, roughness, f0, corners, table, light_fresnel=light_fresnel)
        truth = brute_force_rect_specular(n, v, roughness, f0, corners, SAMPLES)
        _, magnitude, fresnel = ltc_lookup(table, roughness, float(np.dot(n, v)))
        energy = f0 * (magnitude - fresnel) + fresnel
        rows.append((scene["view"], abs(ltc - truth) / truth, abs(ltc - truth) / energy, truth > 0.02 * energy))
    view, relative, of_energy, seen = np.array(rows).T
    return view, relative, of_energy, seen.astype(bool)


@pytest.mark.parametrize("f0, light_fresnel, near_bounds, far_bounds, energy_bound", [
    # f0 1: Schlick's Fresnel is 1, only the lobe's shape (the fit, the interpolation) counts
    (1.0, False, (0.01, 0.04), (0.045, 0.15), 0.07),
    # f0 0.04 with the table's Fresnel, the lobe's average: past 50 degrees it varies across the
    # lobe, and a light near the horizon sees 3 times the average
    (0.04, False, (0.02, 0.08), (0.25, 0.8), 0.2),
    # f0 0.04, Fresnel at the light's mean direction (light_fresnel)
    (0.04, True, (0.01, 0.04), (0.03, 0.12), 0.03),
])
def test_ltc_specular_matches_brute_force(table, f0, light_fresnel, near_bounds, far_bounds, energy_bound):
    """Median and 90th percentile of the relative error at views up to 50 degrees (near) and past
    them (far), where the light holds over 2% of the lobe; the error over the lobe's energy, all."""
    view, relative, of_energy, seen = specular_errors(table, f0, light_fresnel)
    assert of_energy.max() < energy_bound
    for part, (median, percentile_90) in ((seen & (view <= 50), near_bounds), (seen & (view > 50), far_bounds)):
        assert part.sum() >= 10
        assert np.median(relative[part]) < median and np.percentile(relative[part], 90) < percentile_90
