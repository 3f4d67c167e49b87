"""Subsurface scattering (``Material.subsurface``; engine/render/subsurface.py,
shaders/include/subsurface.glsl): the pre-integrated table against a Monte Carlo integral of
Burley's profile over a sphere in 3D (a second path: no chord, no closed form over the
azimuth), what a sphere gives back against what it takes in, rendered spheres against the
integral per channel (by a sun, with and without its shadow map, by a lamp's cube and by a
mirror's image of the sun), a flat wall lit as Lambert lights it, a caster's shadow still
falling on it, the light from all round (the band weights against the convolution of a sky
with D integrated directly, and a sphere under a sky against them), the table on the GPU,
bad values and level files."""
from __future__ import annotations

import numpy as np
import pytest
from pyglm import glm

from components import (
    ComponentValueError,
    DirectionalLight,
    Material,
    MeshRef,
    Mirror,
    PointLight,
    Skybox,
    Transform,
    look_rotation,
)
from components.limits import MAX_SUBSURFACE_SCALE
from engine.assets.mesh import box, quad, sphere
from engine.core.cube_faces import face_directions
from engine.render.atmosphere import _fibonacci_sphere
from engine.render.irradiance import evaluate_sh, project_faces, sh_basis
from engine.render.subsurface import (
    ambient_band_weights,
    band_lookup,
    band_rows,
    scattered_diffuse,
    subsurface_table,
    table_lookup,
)
from tests.support import look_from, srgb_to_linear

RADIUS = 0.5
EYE = np.array([0.0, 0.0, 3.0])
FOV = 30.0
SIZE = 112
SKIN = (1.0, 0.2, 0.1)   # subsurface_radius's default


def black_sky() -> Skybox:
    """A sky of black faces: no light from all round (a generated one draws the sun's glow)."""
    return Skybox(faces=np.zeros((6, 4, 4, 3), np.float32))


def profile_mc(nl: float, spread: float, count: int = 400_000, seed: int = 3) -> float:
    """D(n.l, d / r) by Monte Carlo: points spread evenly over a unit sphere, each weighed by
    Burley's profile at its straight distance from the north pole, its Lambert light summed."""
    q = np.random.default_rng(seed).normal(size=(count, 3))
    q /= np.linalg.norm(q, axis=1)[:, None]
    light = np.array([np.sqrt(1.0 - nl * nl), 0.0, nl])
    rho = np.maximum(np.linalg.norm(q - np.array([0.0, 0.0, 1.0]), axis=1), 1e-12)
    weight = (np.exp(-rho / spread) + np.exp(-rho / (3.0 * spread))) / rho
    return float((weight * np.maximum(q @ light, 0.0)).sum() / weight.sum())


@pytest.mark.parametrize("nl,spread", [(0.9, 0.1), (0.3, 0.3), (0.0, 0.3), (-0.3, 1.0), (-0.8, 4.0), (0.5, 2.0)])
def test_the_integral_is_burleys_profile_over_a_sphere(nl, spread):
    assert float(scattered_diffuse(nl, spread)) == pytest.approx(profile_mc(nl, spread), abs=0.004)


@pytest.mark.parametrize("spread", [0.05, 0.3, 1.0, 5.0])
def test_what_a_sphere_gives_back_is_what_it_takes_in(spread):
    """Normals spread evenly over a sphere have n.l evenly spread over [-1, 1]: the mean of
    D over them is the mean of Lambert's max(n.l, 0), a quarter."""
    nl = (np.arange(4000) + 0.5) / 2000.0 - 1.0
    assert float(scattered_diffuse(nl, spread).mean()) == pytest.approx(0.25, abs=0.002)
    assert float(scattered_diffuse(nl, spread)[-1]) < 1.0   # the lit pole gives some away


def test_the_table_read_as_the_shader_reads_it_is_the_integral():
    table = subsurface_table()
    assert not table[0].any()   # a flat surface: Lambert exactly
    rng = np.random.default_rng(0)
    nl, y = rng.uniform(-1.0, 1.0, 3000), rng.uniform(0.0, 0.97, 3000)
    spread = y / (1.0 - y)
    assert np.abs(table_lookup(table, nl, spread) - scattered_diffuse(nl, spread)).max() < 0.006


def sky_radiance(directions: np.ndarray) -> np.ndarray:
    """The tests' sky: a polynomial of degree 2 in the way's height (so order-2 spherical
    harmonics hold it whole), bright above, dim below, a little bluer up high."""
    y = directions[..., 1:2]
    return np.maximum(0.5 + 0.45 * y + 0.3 * y * y, 0.0) * np.array([0.9, 1.0, 1.2])


@pytest.mark.parametrize("spread", [0.1, 0.5, 2.0, 20.0])
def test_the_band_weights_scatter_the_light_from_all_round_as_the_integral_does(spread):
    """A sky's light scattered under a point (the integral over the sphere of its radiance
    times D(n.w, d / r), summed directly over 40,000 ways) against the engine's way: the
    sky's irradiance coefficients, bands 1 and 2 weighed by r_1 and r_2 (and as the shader
    reads them from their rows); r_0 is 1."""
    ways = _fibonacci_sphere(40_000)
    radiance = sky_radiance(ways)
    mu = np.linspace(-1.0, 1.0, 2001)
    kernel = scattered_diffuse(mu, spread)     # (D on a fine grid of n.w, read between its points)
    normals = _fibonacci_sphere(12)
    direct = np.stack([(radiance * np.interp(ways @ n, mu, kernel)[:, None]).sum(0) * 4.0 * np.pi / len(ways)
                       for n in normals])
    # The irradiance's coefficients (Lambert's kernel applied) of the same sky, band by band.
    coefficients = sh_basis(ways).T @ radiance * (4.0 * np.pi / len(ways)) * np.array(
        [np.pi] + [2.0 * np.pi / 3.0] * 3 + [np.pi / 4.0] * 5)[:, None]
    bands = [slice(0, 1), slice(1, 4), slice(4, 9)]
    weights = ambient_band_weights(spread)
    assert weights[0] == pytest.approx(1.0, abs=1e-6)
    # Exact weights: the sum itself (to the quadrature's error); read from the rows: within 0.2%.
    for r, tolerance in ((weights[1:], 1e-5), (band_lookup(band_rows(), spread), 2e-3)):
        scattered = sum(w * (sh_basis(normals)[:, b] @ coefficients[b]) for w, b in zip((1.0, *r), bands, strict=True))
        assert np.abs(scattered - direct).max() < tolerance * direct.max(), np.abs(scattered - direct).max()
    lambert = evaluate_sh(coefficients, normals)
    assert np.abs(lambert - direct).max() > 0.02 * direct.max()   # (scattering does change it)


def test_a_sphere_under_a_sky_scatters_its_light_as_the_band_weights_say(scene):
    """No light but the sky: each channel against the plain material's irradiance scale
    (fitted on the same sphere) times the sky's irradiance with bands 1 and 2 weighed at the
    channel's d / r, the light from above reaching round its underside, red furthest."""
    size = 16
    faces = np.stack([sky_radiance(face_directions(f, size)) for f in range(6)]).astype(np.float32)
    coefficients = project_faces(faces)

    def build(**material):
        def spawn(world):
            look_from(world, tuple(EYE), (0.0, 0.0, 0.0), fov=FOV)
            world.spawn(Skybox(faces=faces))
            world.spawn(Transform(), MeshRef(sphere(RADIUS, 64, 128)),
                        Material(color=(0.8, 0.8, 0.8, 1.0), reflectance=0.0, roughness=1.0,
                                 environment_reflection=0.0, **material))
        return spawn

    scale = 0.15
    plain = _render(scene, build())
    scattered = _render(scene, build(subsurface=1.0, subsurface_scale=scale))
    _, normal, inner = _sphere_normals()
    basis = sh_basis(normal[inner])
    for channel, share in enumerate(SKIN):
        irradiance = basis @ coefficients[:, channel]
        k = (plain[inner][:, channel] / irradiance).mean()
        assert np.abs(plain[inner][:, channel] - k * irradiance).max() < 0.01   # (the plain one: E(n))
        r1, r2 = ambient_band_weights(share * scale / RADIUS)[1:]
        weighed = basis @ (coefficients[:, channel] * np.array([1.0] + [r1] * 3 + [r2] * 5))
        error = np.abs(scattered[inner][:, channel] - k * weighed)
        assert np.percentile(error, 99) < 0.01 and error.max() < 0.02, (channel, error.max())
    # Its underside takes more of the light from above than the plain sphere's (red the most).
    below = inner & (normal[..., 1] < -0.6)
    gained = scattered[below].mean(axis=0) / plain[below].mean(axis=0)
    assert gained[0] > gained[1] > gained[2] > 0.999 and gained[0] > 1.1, gained


# -- rendered ---------------------------------------------------------------------------------
def _sphere_scene(light: str = "sun", shadows: bool = False, blocker: bool = False, **material):
    toward = np.array([1.0, 0.3, 0.2]) / np.linalg.norm([1.0, 0.3, 0.2])

    def build(world):
        look_from(world, tuple(EYE), (0.0, 0.0, 0.0), fov=FOV)
        world.spawn(black_sky())
        if light == "sun":
            world.spawn(DirectionalLight(direction=tuple(-toward), intensity=3.0, shadows=shadows))
        else:   # a lamp (its shadow a cube) or a spot (a perspective map: light_rules.SPOT_MAP_MAX_ANGLE)
            world.spawn(Transform(position=tuple(toward * 4.0), rotation=look_rotation(glm.vec3(*-toward))),
                        PointLight(intensity=40.0, range=30.0, shadows=shadows, shadow_resolution=2048,
                                   spot_angle=30.0 if light == "spot" else 180.0))
        world.spawn(Transform(), MeshRef(sphere(RADIUS, 64, 128)),
                    Material(color=(0.8, 0.8, 0.8, 1.0), reflectance=0.0, roughness=1.0, environment_reflection=0.0,
                             **material))
        if blocker:   # a slab between the light and the sphere's upper half
            world.spawn(Transform(position=tuple(toward * 1.5 + np.array([0.0, 0.45, 0.0]))),
                        MeshRef(box((0.1, 0.5, 2.0))), Material(color=(0.1, 0.1, 0.1)))
    return build, toward


def _render(scene, build) -> np.ndarray:
    runner = scene(build, (SIZE, SIZE))
    runner.engine.renderer.antialias = "off"
    runner.frame()
    return srgb_to_linear(runner.frame())


def _sphere_normals():
    """Each pixel's point on the sphere (where its ray meets it) and whether it is well inside
    the outline (its rays' depth through the sphere over 0.25 m: away from the silhouette)."""
    half = np.tan(np.radians(FOV / 2.0))
    rows, cols = np.mgrid[0:SIZE, 0:SIZE]
    ray = np.stack([((cols + 0.5) / SIZE * 2 - 1) * half, (1 - (rows + 0.5) / SIZE * 2) * half,
                    -np.ones((SIZE, SIZE))], -1)
    ray /= np.linalg.norm(ray, axis=-1)[..., None]
    b = ray @ EYE
    disc = b * b - (EYE @ EYE - RADIUS * RADIUS)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    point = EYE + ray * t[..., None]
    return point, point / RADIUS, np.sqrt(np.maximum(disc, 0.0)) > 0.25


@pytest.mark.parametrize("scale,shadows", [(0.05, False), (0.15, False), (0.15, True)])
def test_a_sphere_by_a_sun_is_lit_as_the_integral_says(scene, scale, shadows):
    """Each channel's light, against the plain material's Lambert scale (fitted on the same
    sphere's lit side) times D(n.l, its distance / the radius), with the sun's shadow map as
    without it (past the terminator its share is shadow-tested where the light reaches the
    sphere: its own shadow does not cut the wrapped light off)."""
    build, toward = _sphere_scene(shadows=shadows)
    plain = _render(scene, build)
    build, _ = _sphere_scene(shadows=shadows, subsurface=1.0, subsurface_scale=scale)
    scattered = _render(scene, build)
    _, normal, inner = _sphere_normals()
    nl = normal @ toward
    lit = inner & (nl > 0.3)
    dark = inner & (nl < -0.4)
    for channel, share in enumerate(SKIN):
        floor = plain[dark][:, channel].mean()   # (the black sky: about 0)
        k = ((plain[lit][:, channel] - floor) / nl[lit]).mean()
        assert np.abs(plain[lit][:, channel] - floor - k * nl[lit]).max() < 0.01   # (the plain one is Lambert)
        predicted = floor + k * scattered_diffuse(nl, share * scale / RADIUS)
        error = np.abs(scattered[inner][:, channel] - predicted[inner])
        assert np.percentile(error, 99) < 0.015 and error.max() < 0.025, (channel, error.max())
    # Past the terminator the red wraps: lit where the plain sphere is dark.
    wrapped = inner & (nl < -0.05) & (nl > -0.2)
    assert scattered[wrapped][:, 0].mean() > 0.02 and plain[wrapped][:, 0].mean() < 0.002


def test_a_flat_wall_is_lit_as_lambert_lights_it(scene):
    def build(**material):
        def make(world):
            look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=40.0)
            world.spawn(DirectionalLight(direction=(-0.6, -0.3, -0.5), intensity=2.0))
            world.spawn(Transform(rotation=look_rotation(glm.vec3(0.3, 0.2, 1.0))), MeshRef(quad(3.0, 3.0)),
                        Material(color=(0.7, 0.6, 0.5, 1.0), roughness=0.6, **material))
        return make
    plain = _render(scene, build())
    scattered = _render(scene, build(subsurface=1.0, subsurface_scale=0.3))
    assert plain.mean() > 0.03
    assert np.abs(scattered - plain).max() < 1.5 / 255.0


def test_a_casters_shadow_still_falls_on_it(scene):
    build, toward = _sphere_scene(shadows=True, blocker=True, subsurface=1.0, subsurface_scale=0.1)
    shaded = _render(scene, build)
    build, _ = _sphere_scene(shadows=True, subsurface=1.0, subsurface_scale=0.1)
    open_sphere = _render(scene, build)
    build, _ = _sphere_scene(shadows=True, blocker=True)
    plain_shaded = _render(scene, build)
    point, normal, inner = _sphere_normals()
    nl = normal @ toward
    # The slab's shadow: points whose ray to the sun passes through it (y above its foot).
    foot = toward * 1.5 + np.array([0.0, 0.45, 0.0]) - np.array([0.0, 0.25, 0.0])
    t = (foot[0] - point[..., 0]) / toward[0]
    crossing = point + toward * t[..., None]
    in_shadow = inner & (nl > 0.3) & (crossing[..., 1] > foot[1] + 0.08) & (crossing[..., 1] < foot[1] + 0.42)
    sunny = inner & (nl > 0.3) & (crossing[..., 1] < foot[1] - 0.08)
    assert in_shadow.sum() > 50 and sunny.sum() > 50
    assert shaded[in_shadow].mean() < 0.15 * open_sphere[in_shadow].mean()
    assert shaded[in_shadow].mean() == pytest.approx(plain_shaded[in_shadow].mean(), abs=0.02)
    np.testing.assert_allclose(shaded[sunny].mean(axis=0), open_sphere[sunny].mean(axis=0), atol=0.01)


@pytest.mark.parametrize("light", ["lamp", "spot"])
def test_a_lamps_wrapped_light_keeps_with_its_shadow_map(scene, light):
    """Past the terminator of a lamp with a shadow cube (a spot with its perspective map) the
    scattered light is what it is without the map (each slot's lookup moved towards its own light)."""
    build, toward = _sphere_scene(light=light, shadows=True, subsurface=1.0, subsurface_scale=0.15)
    cubed = _render(scene, build)
    build, _ = _sphere_scene(light=light, shadows=False, subsurface=1.0, subsurface_scale=0.15)
    bare = _render(scene, build)
    build, _ = _sphere_scene(light=light, shadows=True)
    plain = _render(scene, build)
    point, normal, inner = _sphere_normals()
    to_lamp = toward * 4.0 - point
    nl = (normal * to_lamp).sum(-1) / np.linalg.norm(to_lamp, axis=-1)
    # (past where the lookup's normal offset alone clears the sphere)
    wrapped = inner & (nl < -0.22) & (nl > -0.6)
    assert wrapped.sum() > 200
    assert cubed[wrapped][:, 0].mean() > 0.02 and plain[wrapped][:, 0].mean() < 0.002
    np.testing.assert_allclose(cubed[wrapped].mean(axis=0), bare[wrapped].mean(axis=0), atol=0.006)


def test_a_mirrors_image_of_the_sun_scatters_under_it_too(scene):
    """The sun through a mirror (a virtual light) on a sphere: the light it adds (its frame
    with the mirror throwing light less without) against the plain sphere's times D for the
    image's direction."""
    sun = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    image = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2.0) * np.array([-1.0, 1.0, 1.0])   # towards the sun's image

    def build(**material):
        def make(world):
            look_from(world, tuple(EYE), (0.0, 0.0, 0.0), fov=FOV)
            world.spawn(black_sky())
            world.spawn(DirectionalLight(direction=tuple(sun), intensity=3.0))
            world.spawn(Transform(), MeshRef(sphere(RADIUS, 64, 128)),
                        Material(color=(0.8, 0.8, 0.8, 1.0), reflectance=0.0, roughness=1.0,
                                 environment_reflection=0.0, **material))
            world.resources["mirror"] = world.spawn(
                Transform(position=(2.0, 1.0, 0.0), rotation=look_rotation(glm.vec3(1, 0, 0))),
                MeshRef(quad(8.0, 8.0)), Material(), Mirror())
        return make

    def thrown(**material):
        runner = scene(build(**material), (SIZE, SIZE))
        runner.engine.renderer.antialias = "off"
        mirror = runner.world.get(runner.world.resources["mirror"], Mirror)
        mirror.reflects_light = False
        runner.frame()
        off = srgb_to_linear(runner.frame())
        mirror.reflects_light = True
        runner.frame()
        return srgb_to_linear(runner.frame()) - off

    plain, scattered = thrown(), thrown(subsurface=1.0, subsurface_scale=0.1)
    point, normal, inner = _sphere_normals()
    nl = normal @ image
    direct = normal @ -sun
    only_image = inner & (direct < -0.3)   # the sun itself does not reach these, nor wraps to them
    lit = only_image & (nl > 0.3)
    assert lit.sum() > 100
    k = (plain[lit][:, 0] / nl[lit]).mean()
    assert k > 0.2
    predicted = k * scattered_diffuse(nl, 0.1 / RADIUS)
    error = np.abs(scattered[only_image][:, 0] - predicted[only_image])
    assert np.percentile(error, 99) < 0.03
    wrapped = only_image & (nl < -0.05) & (nl > -0.2)
    assert scattered[wrapped][:, 0].mean() > 0.04 and plain[wrapped][:, 0].mean() < 0.005


def test_the_table_is_on_the_gpu_once_a_subsurface_material_is_drawn(scene):
    from engine.render.environment_brdf import ENVIRONMENT_BRDF_SIZE
    from engine.render.views import MAX_IRRADIANCE_PROBES

    build, _ = _sphere_scene()
    runner = scene(build, (32, 32))
    runner.frame()
    irradiance = runner.engine.renderer.irradiance
    assert not irradiance.has_subsurface
    runner.world.get(runner.world.query_one(Material)[0][0], Material).subsurface = 0.5
    runner.frame()
    assert irradiance.has_subsurface
    width, height = irradiance.table.size
    held = np.frombuffer(irradiance.table.read(), np.float32).reshape(height, width, 4)
    rows = held[MAX_IRRADIANCE_PROBES:MAX_IRRADIANCE_PROBES + ENVIRONMENT_BRDF_SIZE, :ENVIRONMENT_BRDF_SIZE, 3]
    np.testing.assert_array_equal(rows, subsurface_table())


@pytest.mark.parametrize("field,value", [("subsurface", 1.5), ("subsurface", -0.1), ("subsurface_scale", -0.01),
                                         ("subsurface_scale", MAX_SUBSURFACE_SCALE * 2),
                                         ("subsurface_scale", float("nan")), ("subsurface_radius", (1.5, 0.2, 0.1)),
                                         ("subsurface_radius", (-0.1, 0.2, 0.1)), ("subsurface_radius", (1.0, 0.2))])
def test_bad_subsurface_values_are_refused_when_given(field, value):
    with pytest.raises(ComponentValueError, match=f"Material.{field}"):
        Material(**{field: value})
    material = Material()
    with pytest.raises(ComponentValueError, match=f"Material.{field}"):
        setattr(material, field, value)


def test_a_level_file_gives_a_subsurface_material(tmp_path):
    from engine.assets.level_read import load_level
    from engine.core.world import World

    level = tmp_path / "wax.toml"
    level.write_text('[level]\nname = "wax"\n[[entity]]\nname = "candle"\nTransform = {}\n'
                     'MeshRef = { mesh = { sphere = 0.3 } }\n'
                     'Material = { subsurface = 0.8, subsurface_radius = [1.0, 0.8, 0.5], subsurface_scale = 0.02 }\n')
    world = World()
    load_level(level).spawn(world)
    material = world.query_one(Material)[0][1]
    assert material.subsurface == pytest.approx(0.8) and material.subsurface_scale == pytest.approx(0.02)
    assert glm.vec3(material.subsurface_radius) == glm.vec3(1.0, 0.8, 0.5)


def test_a_candle_lit_from_behind_glows_without_an_edge(scene):
    """A standing capsule (curved round, straight up its side: the mean curvature under its
    sharper one) against a low sun behind it: its shaded front lit evenly across, no step where
    its own body's shadow would begin, and never darker than the plain one."""
    import trimesh

    from components import yaw_pitch_rotation
    from engine.assets.mesh import Mesh

    candle = Mesh.from_trimesh(trimesh.creation.capsule(height=0.6, radius=0.25, count=[48, 48]), name="candle")

    def build(**material):
        def make(world):
            look_from(world, (0.0, 0.0, 3.0), (0.0, 0.0, 0.0), fov=FOV)
            world.spawn(black_sky())
            world.spawn(DirectionalLight(direction=(0.15, -0.4, 1.0), intensity=3.0))
            world.spawn(Transform(rotation=yaw_pitch_rotation(0, 90)), MeshRef(candle),
                        Material(color=(0.9, 0.85, 0.7, 1.0), reflectance=0.0, roughness=1.0,
                                 environment_reflection=0.0, **material))
        return make

    plain = _render(scene, build())
    glowing = _render(scene, build(subsurface=1.0, subsurface_scale=0.12))
    rows = slice(SIZE // 2 - 8, SIZE // 2 + 8)
    body = glowing[rows, :, 0]
    inside = np.abs(np.arange(SIZE) - SIZE / 2 + 0.5) < SIZE * 0.12   # the side's middle, away from its outline
    assert (glowing[rows][:, inside] >= plain[rows][:, inside] - 0.003).all()
    assert body[:, inside].mean() > plain[rows][:, inside, 0].mean() + 0.01
    steps = np.abs(np.diff(body[:, inside], axis=1))
    assert steps.max() < 0.012, steps.max()


@pytest.mark.parametrize("way", ["mirror", "portal"])
def test_a_subsurface_ball_in_a_mirror_and_through_a_portal_is_shaded_from_that_views_eye(scene, way):
    """A skin-coloured ball off to the camera's right, seen only in a mirror (or through a
    portal): its light scattered past the terminator (by the curvature each view finds from its
    own pixels) and its highlight are the frame a camera at the mirror's image eye (the eye
    carried through the portal) draws, turned left for right for the mirror
    (tests/test_clearcoat.py's assert_shown_as_from_its_eye); and the scattering is there (the
    plain ball's frame differs)."""
    from tests.test_clearcoat import IMAGE_EYE, SEEN, assert_shown_as_from_its_eye

    def side_lamp(world):   # (across the way to the image eye: the terminator down the ball's middle)
        across = glm.normalize(glm.cross(IMAGE_EYE - SEEN, glm.vec3(0.0, 1.0, 0.0)))
        world.spawn(Transform(position=SEEN - across * 1.5), PointLight(intensity=8.0, range=20.0))
    base = dict(color=(0.9, 0.6, 0.5, 1.0), roughness=0.4)
    assert_shown_as_from_its_eye(scene, dict(base, subsurface=1.0, subsurface_scale=0.3), base, way, extra=side_lamp)
